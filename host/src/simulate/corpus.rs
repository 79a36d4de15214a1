//! The committed capture corpus (`tests/captures/`) and random envelope scenes.
//!
//! [`entries`] is the single source of the corpus: `tangent simulate corpus --out
//! tests/captures` renders every entry, and a test regenerates one and compares bytes.
//! Distances in names are to the stem's front surface on the optical axis (`z150` =
//! 1.50 m), diameters in millimetres (`d300` = 300 mm). See `tests/README.md`.

use std::path::Path;

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use tangent_core::calibration::Calibration;
use tangent_core::camera::Distortion;

use super::render::{HandMotion, Lighting};
pub use super::rig::{lab_light, one_plane_calibration, two_plane_calibration, CorpusEntry};
use super::{simulate, Exposure, SimError, SimParams, SimSpec};
use crate::capture::Mode;
use crate::truth::{Board, Cylinder, Object, Plane, Road, Sphere, Texture, Wave};

/// A plausible calibrated unit: principal point off-centre, barrel distortion, slightly
/// unequal focal lengths (one plane), id 3.
pub fn distorted_calibration() -> Calibration {
    let mut c = one_plane_calibration();
    c.id = 3;
    c.camera.fx = 1003.2;
    c.camera.fy = 1001.7;
    c.camera.cx = 381.4;
    c.camera.cy = 235.2;
    c.camera.distortion = Distortion {
        k1: -0.12,
        k2: 0.09,
        k3: 0.0,
        p1: 4e-4,
        p2: -3e-4,
    };
    c
}

/// Axis direction of a stem tilted by `tilt_deg` from vertical towards the azimuth
/// `azimuth_deg` (0 = leaning right (+x), 90 = leaning away (+z), 180 = left, 270 = towards
/// the camera). `y` is down, so "up" along the stem is `−y`; the direction is returned
/// pointing down (+y), which is the same axis.
pub fn tilted_axis(tilt_deg: f64, azimuth_deg: f64) -> [f64; 3] {
    let (t, a) = (tilt_deg.to_radians(), azimuth_deg.to_radians());
    [-t.sin() * a.cos(), t.cos(), -t.sin() * a.sin()]
}

/// A bark-textured stem of diameter `d_mm` whose front surface is `z_m` ahead on the
/// optical axis (axis at `x = x_m`, `z = z_m + r`).
pub fn stem(d_mm: f64, z_m: f64, x_m: f64, axis: [f64; 3]) -> Object {
    let r = d_mm * 1e-3 / 2.0;
    Object::Cylinder(Cylinder {
        axis_point_m: [x_m, 0.0, z_m + r],
        axis_direction: axis,
        radius_m: Some(r),
        semi_axes_m: None,
        major_axis_direction: None,
        extent_m: None,
        albedo: 0.3,
        texture: Texture::Bark,
        texture_contrast: 0.5,
    })
}

/// Forest floor 1.3 m below the camera (breast height).
pub fn ground() -> Object {
    Object::Plane(Plane {
        point_m: [0.0, 1.3, 0.0],
        normal: [0.0, -1.0, 0.0],
        albedo: 0.15,
        texture: Texture::Stone,
        texture_contrast: 0.6,
        bounds_m: None,
    })
}

const VERTICAL: [f64; 3] = [0.0, 1.0, 0.0];

/// Full sun in the 650 nm band (≈ 15 W/m² direct, 2 W/m² diffuse), from behind the
/// camera's left shoulder so the stems' fronts are lit.
pub fn sun(fraction: f64) -> Lighting {
    Lighting {
        diffuse_w_m2: 0.3 + 1.7 * fraction,
        sun_w_m2: 15.0 * fraction,
        sun_direction: [-0.5, -0.6, -0.6],
        background_w_m2: 0.06 + 0.5 * fraction,
    }
}

/// Dusk under canopy: 0.03 W/m² diffuse.
pub fn dark() -> Lighting {
    Lighting {
        diffuse_w_m2: 0.03,
        sun_w_m2: 0.0,
        sun_direction: [0.0, -1.0, 0.0],
        background_w_m2: 0.006,
    }
}

struct Builder {
    entries: Vec<CorpusEntry>,
}

impl Builder {
    fn add(
        &mut self,
        name: &str,
        mode: Mode,
        description: &str,
        calibration: Calibration,
        objects: Vec<Object>,
        f: impl FnOnce(&mut SimParams),
    ) {
        let n = self.entries.len();
        self.add_at(n, name, mode, description, calibration, objects, f);
    }

    /// [`Builder::add`] with the capture's index (its seed and timestamp) given.
    #[allow(clippy::too_many_arguments)]
    fn add_at(
        &mut self,
        n: usize,
        name: &str,
        mode: Mode,
        description: &str,
        calibration: Calibration,
        objects: Vec<Object>,
        f: impl FnOnce(&mut SimParams),
    ) {
        let mut params = SimParams {
            seed: 1000 + n as u64,
            ..SimParams::default()
        };
        if calibration.planes.len() > 1 {
            params.lit_planes = (0..calibration.planes.len()).collect();
        }
        f(&mut params);
        let timestamp = format!("2025-06-02T{:02}:{:02}:00Z", 9 + n / 60, n % 60);
        self.entries.push(CorpusEntry {
            name: name.to_string(),
            spec: SimSpec {
                mode,
                description: description.to_string(),
                timestamp,
                calibration,
                objects,
                params,
            },
        });
    }

    fn stem(
        &mut self,
        name: &str,
        description: &str,
        d_mm: f64,
        z_m: f64,
        f: impl FnOnce(&mut SimParams),
    ) {
        self.add(
            name,
            Mode::Cylinder,
            description,
            one_plane_calibration(),
            vec![stem(d_mm, z_m, 0.0, VERTICAL), ground()],
            f,
        );
    }

    fn tilted(
        &mut self,
        name: &str,
        description: &str,
        d_mm: f64,
        z_m: f64,
        tilt: f64,
        azimuth: f64,
    ) {
        let objects = vec![stem(d_mm, z_m, 0.0, tilted_axis(tilt, azimuth)), ground()];
        self.add(
            name,
            Mode::Cylinder,
            description,
            two_plane_calibration(),
            objects,
            |_| {},
        );
    }
}

fn elliptic(a_mm: f64, b_mm: f64, z_m: f64, axis: [f64; 3], major: [f64; 3]) -> Object {
    // Front surface at z_m for a major axis across (x); for other orientations the axis
    // sits at z_m + b (approximately the front, exactly when the minor axis faces the camera).
    Object::Cylinder(Cylinder {
        axis_point_m: [0.0, 0.0, z_m + b_mm * 1e-3 / 2.0],
        axis_direction: axis,
        radius_m: None,
        semi_axes_m: Some([a_mm * 1e-3 / 2.0, b_mm * 1e-3 / 2.0]),
        major_axis_direction: Some(major),
        extent_m: None,
        albedo: 0.3,
        texture: Texture::Bark,
        texture_contrast: 0.5,
    })
}

fn branch(from: [f64; 3], dir: [f64; 3], length: f64, d_mm: f64) -> Object {
    Object::Cylinder(Cylinder {
        axis_point_m: from,
        axis_direction: dir,
        radius_m: Some(d_mm * 1e-3 / 2.0),
        semi_axes_m: None,
        major_axis_direction: None,
        extent_m: Some([0.0, length]),
        albedo: 0.25,
        texture: Texture::Bark,
        texture_contrast: 0.4,
    })
}

/// The index (seed `1000 + index`, timestamp) of the first room of `wall_corpus`.
const FIRST_ROOM_INDEX: usize = 73;

/// Every corpus capture, in a fixed order (the order sets each capture's seed).
pub fn entries() -> Vec<CorpusEntry> {
    let mut b = Builder {
        entries: Vec::new(),
    };
    // --- transversal (vertical) stems, forest shade, one laser plane ---------------------
    for (d, z) in [
        (50.0, 0.5),
        (50.0, 1.5),
        (50.0, 3.0),
        (100.0, 1.0),
        (200.0, 0.5),
        (300.0, 0.5),
        (300.0, 1.5),
        (300.0, 3.0),
        (450.0, 1.0),
        (500.0, 2.5),
        (600.0, 1.5),
        (1000.0, 1.0),
        (1000.0, 3.0),
    ] {
        let name = format!("cyl-d{:03}-z{:03}-shade", d as u32, (z * 100.0) as u32);
        let desc = format!("vertical stem {d} mm at {z} m, forest shade, one laser plane");
        b.stem(&name, &desc, d, z, |_| {});
    }
    // --- partly outside the frame ---------------------------------------------------------
    b.stem(
        "cyl-d1000-z050-partly-outside",
        "1 m stem at 0.5 m: wider than the field of view, both edges outside the frame",
        1000.0,
        0.5,
        |_| {},
    );
    b.add(
        "cyl-d400-z100-frame-edge",
        Mode::Cylinder,
        "400 mm stem at 1.0 m centred 0.4 m right: its right edge is outside the frame",
        one_plane_calibration(),
        vec![stem(400.0, 1.0, 0.4, VERTICAL), ground()],
        |_| {},
    );
    // --- light ------------------------------------------------------------------------------
    b.stem(
        "cyl-d300-z150-sun",
        "300 mm stem at 1.5 m in full sun (15 W/m² in band): weak stripe over bright bark",
        300.0,
        1.5,
        |p| p.lighting = sun(1.0),
    );
    b.stem(
        "cyl-d300-z100-sunfleck",
        "300 mm stem at 1.0 m, sun through the canopy at 30 %",
        300.0,
        1.0,
        |p| p.lighting = sun(0.3),
    );
    b.stem(
        "cyl-d200-z250-sun",
        "200 mm stem at 2.5 m in full sun",
        200.0,
        2.5,
        |p| p.lighting = sun(1.0),
    );
    b.stem(
        "cyl-d300-z150-dusk",
        "300 mm stem at 1.5 m at dusk under canopy (0.03 W/m²)",
        300.0,
        1.5,
        |p| p.lighting = dark(),
    );
    b.stem(
        "cyl-d300-z070-saturated",
        "300 mm stem at 0.7 m with a fixed 25 ms exposure: the stripe saturates",
        300.0,
        0.7,
        |p| p.exposure = Exposure::Fixed { seconds: 0.025 },
    );
    b.stem(
        "cyl-d300-z150-10bit",
        "300 mm stem at 1.5 m, 10-bit frames (16-bit PGM, maxval 1023)",
        300.0,
        1.5,
        |p| p.sensor.bit_depth = 10,
    );
    // --- calibrated unit with distortion; hand motion ------------------------------------
    b.add("cyl-d300-z150-distorted", Mode::Cylinder, "300 mm stem at 1.5 m seen by a unit with barrel distortion and an off-centre principal point", distorted_calibration(), vec![stem(300.0, 1.5, 0.05, VERTICAL), ground()], |_| {});
    b.stem(
        "cyl-d300-z150-handmotion",
        "300 mm stem at 1.5 m; the hand moved 2 mrad / 1 mm between the off and on frames",
        300.0,
        1.5,
        |p| {
            p.hand_motion = Some(HandMotion {
                rotation_rad: [0.002, -0.0015, 0.0005],
                translation_m: [0.001, -0.0005, 0.0],
            });
        },
    );
    // --- tilted stems, two laser planes ---------------------------------------------------
    b.tilted(
        "cyl-d300-z150-vertical-2p",
        "vertical 300 mm stem at 1.5 m, two laser planes",
        300.0,
        1.5,
        0.0,
        0.0,
    );
    b.tilted(
        "cyl-d300-z150-tilt10-right-2p",
        "300 mm stem at 1.5 m leaning 10° right, two planes",
        300.0,
        1.5,
        10.0,
        0.0,
    );
    b.tilted(
        "cyl-d300-z150-tilt20-away-2p",
        "300 mm stem at 1.5 m leaning 20° away from the camera, two planes",
        300.0,
        1.5,
        20.0,
        90.0,
    );
    b.tilted(
        "cyl-d300-z150-tilt30-towards-2p",
        "300 mm stem at 1.5 m leaning 30° towards the camera, two planes",
        300.0,
        1.5,
        30.0,
        270.0,
    );
    b.tilted(
        "cyl-d300-z100-tilt30-left-2p",
        "300 mm stem at 1.0 m leaning 30° left, two planes",
        300.0,
        1.0,
        30.0,
        180.0,
    );
    b.tilted(
        "cyl-d500-z200-tilt15-diagonal-2p",
        "500 mm stem at 2.0 m leaning 15° right and away (azimuth 45°), two planes",
        500.0,
        2.0,
        15.0,
        45.0,
    );
    b.tilted(
        "cyl-d150-z100-tilt25-away-left-2p",
        "150 mm stem at 1.0 m leaning 25° at azimuth 135° (away, left), two planes",
        150.0,
        1.0,
        25.0,
        135.0,
    );
    b.add("cyl-d300-z150-tilt20-right-1p", Mode::Cylinder, "300 mm stem at 1.5 m leaning 20° right seen with one plane (tilt error of the transversal method)", one_plane_calibration(), vec![stem(300.0, 1.5, 0.0, tilted_axis(20.0, 0.0)), ground()], |_| {});
    b.add(
        "cyl-d300-z150-separate-frames-2p",
        Mode::Cylinder,
        "vertical 300 mm stem at 1.5 m, two planes lit in separate frames",
        two_plane_calibration(),
        vec![stem(300.0, 1.5, 0.0, VERTICAL), ground()],
        |p| p.separate_frames = true,
    );
    // --- elliptic stems ---------------------------------------------------------------------
    b.add(
        "ell-a400-b300-z150-across",
        Mode::Cylinder,
        "elliptic stem 400 × 300 mm at 1.5 m, major axis across the view",
        one_plane_calibration(),
        vec![
            elliptic(400.0, 300.0, 1.5, VERTICAL, [1.0, 0.0, 0.0]),
            ground(),
        ],
        |_| {},
    );
    b.add(
        "ell-a350-b250-z200-rot45",
        Mode::Cylinder,
        "elliptic stem 350 × 250 mm at 2.0 m, major axis at 45°",
        one_plane_calibration(),
        vec![
            elliptic(350.0, 250.0, 2.0, VERTICAL, [1.0, 0.0, 1.0]),
            ground(),
        ],
        |_| {},
    );
    b.add(
        "ell-a300-b200-z100-tilt15-2p",
        Mode::Cylinder,
        "elliptic stem 300 × 200 mm at 1.0 m leaning 15° right, two planes",
        two_plane_calibration(),
        vec![
            elliptic(300.0, 200.0, 1.0, tilted_axis(15.0, 0.0), [1.0, 0.0, 0.0]),
            ground(),
        ],
        |_| {},
    );
    // --- several objects, clutter, range -------------------------------------------------
    b.add(
        "two-trunks-d300-z120-d200-z250",
        Mode::Cylinder,
        "two stems: 300 mm at 1.2 m left, 200 mm at 2.5 m right",
        one_plane_calibration(),
        vec![
            stem(300.0, 1.2, -0.25, VERTICAL),
            stem(200.0, 2.5, 0.45, VERTICAL),
            ground(),
        ],
        |_| {},
    );
    b.add(
        "cyl-d300-z150-branches",
        Mode::Cylinder,
        "300 mm stem at 1.5 m with two thin branches crossing in front at 1.0–1.2 m",
        one_plane_calibration(),
        vec![
            stem(300.0, 1.5, 0.0, VERTICAL),
            branch([-0.5, 0.05, 1.0], [1.0, -0.35, 0.1], 0.55, 25.0),
            branch([0.35, -0.2, 1.2], [-0.3, 1.0, 0.05], 0.5, 15.0),
            ground(),
        ],
        |_| {},
    );
    b.add(
        "cyl-d250-z150-background-trunks",
        Mode::Cylinder,
        "250 mm stem at 1.5 m with three stems behind at 3.5–6 m",
        one_plane_calibration(),
        vec![
            stem(250.0, 1.5, 0.0, VERTICAL),
            stem(350.0, 3.5, -0.9, VERTICAL),
            stem(300.0, 4.5, 0.9, VERTICAL),
            stem(400.0, 6.0, 0.3, VERTICAL),
            ground(),
        ],
        |_| {},
    );
    b.add(
        "nothing-in-range",
        Mode::Cylinder,
        "no object in range: stems at 8–12 m and the forest floor",
        one_plane_calibration(),
        vec![
            stem(400.0, 8.0, -1.5, VERTICAL),
            stem(300.0, 10.0, 1.2, VERTICAL),
            stem(500.0, 12.0, 0.2, VERTICAL),
            ground(),
        ],
        |_| {},
    );
    b.stem(
        "cyl-d400-z500-beyond-range",
        "400 mm stem at 5 m, beyond the 3 m working range",
        400.0,
        5.0,
        |_| {},
    );
    // --- spheres -----------------------------------------------------------------------------
    let ball = |d_mm: f64, z: f64, x: f64| {
        Object::Sphere(Sphere {
            centre_m: [x, 0.0, z + d_mm * 5e-4],
            radius_m: d_mm * 5e-4,
            albedo: 0.5,
            texture: Texture::Stone,
            texture_contrast: 0.2,
            specular: None,
            stretch: None,
        })
    };
    b.add(
        "sphere-d200-z100",
        Mode::Sphere,
        "sphere 200 mm at 1.0 m",
        one_plane_calibration(),
        vec![ball(200.0, 1.0, 0.0)],
        |_| {},
    );
    b.add(
        "sphere-d400-z150-offcentre",
        Mode::Sphere,
        "sphere 400 mm at 1.5 m, 0.15 m right of the axis",
        one_plane_calibration(),
        vec![ball(400.0, 1.5, 0.15)],
        |_| {},
    );
    // --- walls -------------------------------------------------------------------------------
    let wall = |point: [f64; 3], normal: [f64; 3]| {
        Object::Plane(Plane {
            point_m: point,
            normal,
            albedo: 0.6,
            texture: Texture::Stone,
            texture_contrast: 0.15,
            bounds_m: None,
        })
    };
    b.add(
        "wall-z150-frontal",
        Mode::Wall,
        "plaster wall perpendicular to the optical axis at 1.5 m",
        two_plane_calibration(),
        vec![wall([0.0, 0.0, 1.5], [0.0, 0.0, -1.0])],
        // The accelerometer draws from its own stream: the frames are as before it.
        |p| p.accelerometer = Some(super::accelerometer::AccelerometerSim::reference()),
    );
    b.add(
        "wall-corner-z200",
        Mode::Wall,
        "concave corner of two perpendicular walls, 2.0 m away on the axis",
        two_plane_calibration(),
        vec![
            wall([0.0, 0.0, 2.0], [1.0, 0.0, -1.0]),
            wall([0.0, 0.0, 2.0], [-1.0, 0.0, -1.0]),
        ],
        // The accelerometer draws from its own stream: the frames are as before it.
        |p| p.accelerometer = Some(super::accelerometer::AccelerometerSim::reference()),
    );
    // --- road ----------------------------------------------------------------------------------
    let road = |waves: Vec<Wave>| {
        Object::Road(Road {
            distance_m: 0.5,
            waves,
            albedo: 0.12,
            texture: Texture::Asphalt,
            texture_contrast: 0.5,
        })
    };
    let wave = |a_mm: f64, l_mm: f64, ph: f64, dir_deg: f64| Wave {
        amplitude_m: a_mm * 1e-3,
        wavelength_m: l_mm * 1e-3,
        phase_rad: ph,
        direction_rad: dir_deg.to_radians(),
    };
    b.add(
        "road-z050-macrotexture",
        Mode::Road,
        "road surface at 0.5 m: macrotexture (1.5 mm at 20 mm, 0.8 mm at 7 mm, 0.3 mm at 3 mm)",
        one_plane_calibration(),
        vec![road(vec![
            wave(1.5, 20.0, 0.3, 5.0),
            wave(0.8, 7.0, 1.1, -20.0),
            wave(0.3, 3.0, 2.0, 40.0),
            wave(0.1, 1.3, 0.5, 80.0),
        ])],
        |_| {},
    );
    // --- laser calibration: the chessboard at six poses, two planes in separate frames ---------
    for (k, pose) in BOARD_POSES.iter().enumerate() {
        b.add(
            &format!("board-pose-{:02}", k + 1),
            Mode::Wall,
            &format!(
                "9x6 chessboard (25 mm) centred {:.2} m ahead, rotated ({:.0}°, {:.0}°, {:.0}°), \
                 lab light, two planes in separate frames (laser calibration)",
                pose[2], pose[3], pose[4], pose[5]
            ),
            two_plane_calibration(),
            vec![calibration_board(pose), lab_wall()],
            |p| {
                p.separate_frames = true;
                p.lighting = lab_light();
            },
        );
    }
    // --- spheres on two planes (`sphere_corpus`; seeds of their own, so the order above is
    // untouched) ---------------------------------------------------------------------------
    b.entries.extend(super::sphere_corpus::entries());
    // --- the road head (`docs/road.md`): own calibration and seeds -------------------------
    b.entries.extend(super::road_corpus::entries());
    // --- rooms: appended last so that no older capture's seed changes; their indices are
    // fixed (the first room is index 73), so that a capture added to the sphere or road corpora
    // does not re-seed them --------------------------------------------------------------------
    for (i, w) in super::wall_corpus::entries().into_iter().enumerate() {
        let params = super::wall_corpus::wall_params;
        b.add_at(
            FIRST_ROOM_INDEX + i,
            w.name,
            Mode::Wall,
            &w.description,
            w.calibration,
            w.objects,
            params,
        );
    }
    b.entries
}

/// The corpus's board poses: centre `(x, y, z)` (metres, camera frame) and rotation
/// `(rx, ry, rz)` (degrees, [`nalgebra::Rotation3::from_euler_angles`] order). Depths
/// 0.8–1.25 m and tilts up to 30° about both in-plane axes (a plane is fixed by several
/// non-parallel stripe lines; depth spread fixes its tilt); each centre is placed between
/// the two reference planes' stripes (`y ≈ 0.125 − z/15`), so both cross the board.
pub const BOARD_POSES: [[f64; 6]; 6] = [
    [0.0, 0.072, 0.80, 0.0, 0.0, 0.0],
    [-0.05, 0.065, 0.90, 25.0, 0.0, 5.0],
    [0.05, 0.058, 1.00, -20.0, 25.0, 0.0],
    [0.0, 0.052, 1.10, 10.0, -30.0, -8.0],
    [-0.08, 0.042, 1.25, -10.0, 15.0, 10.0],
    [0.08, 0.068, 0.85, 30.0, -15.0, 0.0],
];

/// The calibration chessboard of the corpus (9 × 6 inner corners, 25 mm squares, 15 mm
/// border) at a pose of [`BOARD_POSES`].
pub fn calibration_board(pose: &[f64; 6]) -> Object {
    let [x, y, z, rx, ry, rz] = *pose;
    let r =
        nalgebra::Rotation3::from_euler_angles(rx.to_radians(), ry.to_radians(), rz.to_radians());
    let (cols, rows, s) = (9usize, 6usize, 0.025);
    let centre_b = nalgebra::Vector3::new(
        (cols - 1) as f64 * s / 2.0,
        (rows - 1) as f64 * s / 2.0,
        0.0,
    );
    let origin = nalgebra::Vector3::new(x, y, z) - r * centre_b;
    let (ax, ay) = (r * nalgebra::Vector3::x(), r * nalgebra::Vector3::y());
    Object::Board(Board {
        origin_m: [origin.x, origin.y, origin.z],
        x_axis: [ax.x, ax.y, ax.z],
        y_axis: [ay.x, ay.y, ay.z],
        square_m: s,
        inner_corners: [cols, rows],
        border_m: 0.015,
        albedo: 0.8,
        dark_albedo: 0.05,
    })
}

/// A plaster wall 1.8 m ahead, behind the calibration board (the stripe runs on past the
/// board; the calibration must keep only the points on the board).
pub fn lab_wall() -> Object {
    Object::Plane(Plane {
        point_m: [0.0, 0.0, 1.8],
        normal: [0.0, 0.0, -1.0],
        albedo: 0.5,
        texture: Texture::Stone,
        texture_contrast: 0.2,
        bounds_m: None,
    })
}

/// A random stem in the product's envelope (for Monte-Carlo and accuracy runs, not the
/// corpus): diameter log-uniform in 50–1000 mm, front distance uniform in 0.5–3 m,
/// redrawn until the stem's silhouette fits in the horizontal field with 5 % margin; forest
/// light between dusk and sunflecks; `tilt_max_deg` > 0 gives a random lean (uniform
/// azimuth) and two laser planes.
pub fn random_stem(seed: u64, tilt_max_deg: f64) -> SimSpec {
    let mut rng = Pcg64::seed_from_u64(super::scene::splitmix(seed));
    let cal = if tilt_max_deg > 0.0 {
        two_plane_calibration()
    } else {
        one_plane_calibration()
    };
    let half_fov = ((cal.camera.width as f64 / 2.0) / cal.camera.fx).atan();
    let (d_mm, z) = loop {
        let d = 50.0 * (20f64).powf(rng.random::<f64>());
        let z = 0.5 + 2.5 * rng.random::<f64>();
        let r = d * 5e-4;
        if (r / (z + r)).asin() < 0.95 * half_fov {
            break (d, z);
        }
    };
    let tilt = tilt_max_deg * rng.random::<f64>();
    let azimuth = 360.0 * rng.random::<f64>();
    let light = rng.random::<f64>();
    let lighting = if light < 0.15 {
        dark()
    } else if light < 0.85 {
        Lighting::shade()
    } else {
        sun(0.3)
    };
    let mut params = SimParams {
        seed: seed & (u64::MAX >> 1),
        lighting,
        ..SimParams::default()
    };
    params.lit_planes = (0..cal.planes.len()).collect();
    SimSpec {
        mode: Mode::Cylinder,
        description: format!(
            "random stem {d_mm:.1} mm at {z:.3} m, tilt {tilt:.1}° azimuth {azimuth:.0}°"
        ),
        timestamp: "2025-06-03T12:00:00Z".into(),
        calibration: cal,
        objects: vec![stem(d_mm, z, 0.0, tilted_axis(tilt, azimuth)), ground()],
        params,
    }
}

/// Renders `entries` into `out/<name>/`. Returns the names written.
pub fn write_entries(entries: &[CorpusEntry], out: &Path) -> Result<Vec<String>, SimError> {
    let mut names = Vec::new();
    for e in entries {
        let (capture, _) = simulate(&e.spec)?;
        let dir = out.join(&e.name);
        // A capture's errors name its files relative to it; put the directory in front.
        capture
            .write(&dir)
            .map_err(|err| SimError::Capture(format!("{}: {err}", dir.display())))?;
        names.push(e.name.clone());
    }
    Ok(names)
}
