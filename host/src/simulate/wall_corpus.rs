//! Rooms for the wall instrument (`docs/building.md`, "Simulated rooms"): walls of plaster,
//! concrete, brick and wood, room corners of 80–100°, niches and door openings (segments),
//! a column (a curved surface) — the committed wall captures ([`entries`], appended to
//! [`super::corpus::entries`]) and random rooms for `tangent evaluate walls`
//! ([`random_room`]).

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use tangent_core::calibration::Calibration;

use super::accelerometer::AccelerometerSim;
use super::reflectance::Reflectance;
use super::render::Lighting;
use super::rig::{
    lab_light, one_plane_calibration, three_plane_calibration, two_plane_calibration,
};
use super::{SimParams, SimSpec};
use crate::capture::Mode;
use crate::truth::{Cylinder, Object, Plane, Texture};

/// A wall surface: albedo at 650 nm and the texture's depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Name in descriptions.
    pub name: &'static str,
    /// Lambertian albedo at 650 nm.
    pub albedo: f64,
    /// Contrast of the stone-like texture.
    pub contrast: f64,
}

/// White plaster.
pub const PLASTER: Material = Material {
    name: "plaster",
    albedo: 0.7,
    contrast: 0.1,
};
/// Grey concrete.
pub const CONCRETE: Material = Material {
    name: "concrete",
    albedo: 0.35,
    contrast: 0.3,
};
/// Red brick (dark at 650 nm less than in the visible: red reflects red).
pub const BRICK: Material = Material {
    name: "brick",
    albedo: 0.3,
    contrast: 0.5,
};
/// Varnished wood panelling.
pub const WOOD: Material = Material {
    name: "wood",
    albedo: 0.4,
    contrast: 0.4,
};
/// The materials of [`random_room`].
pub const MATERIALS: [Material; 4] = [PLASTER, CONCRETE, BRICK, WOOD];

/// Far enough to stand for "unbounded" in a box (metres).
const FAR: f64 = 100.0;

/// A flat wall through `point` with `normal` (pointing either way), cut to `bounds`.
pub fn wall(
    point: [f64; 3],
    normal: [f64; 3],
    bounds: Option<[[f64; 3]; 2]>,
    m: Material,
) -> Object {
    Object::Plane(Plane {
        point_m: point,
        normal,
        albedo: m.albedo,
        texture: Texture::Stone,
        texture_contrast: m.contrast,
        bounds_m: bounds,
    })
}

/// A room's (concave) corner: its edge vertical through `(x, 0, z)`, the walls `opening_deg`
/// apart, their bisector turned `turn_deg` to the right of facing the camera.
pub fn corner(x: f64, z: f64, opening_deg: f64, turn_deg: f64, m: Material) -> Vec<Object> {
    let half = opening_deg.to_radians() / 2.0;
    let turn = turn_deg.to_radians();
    // Each wall runs from the edge towards the camera at ±half from the bisector.
    [turn + half, turn - half]
        .into_iter()
        .map(|a| {
            let dir = [-a.sin(), 0.0, -a.cos()];
            wall([x, 0.0, z], [dir[2], 0.0, -dir[0]], None, m)
        })
        .collect()
}

/// A wall facing the camera at `z` with a recess `width` wide and `depth` deep centred at
/// `x`: the front wall either side, the recess's back wall and its two jambs. `depth` of a
/// few metres makes a door opening into the next room.
pub fn niche(x: f64, z: f64, width: f64, depth: f64, m: Material) -> Vec<Object> {
    let (l, r) = (x - width / 2.0, x + width / 2.0);
    let face = |lo: f64, hi: f64| Some([[lo, -FAR, z - 0.01], [hi, FAR, z + 0.01]]);
    let jamb = |at: f64| Some([[at - 0.01, -FAR, z], [at + 0.01, FAR, z + depth]]);
    vec![
        wall([0.0, 0.0, z], [0.0, 0.0, -1.0], face(-FAR, l), m),
        wall([0.0, 0.0, z], [0.0, 0.0, -1.0], face(r, FAR), m),
        wall([x, 0.0, z + depth], [0.0, 0.0, -1.0], None, m),
        wall([l, 0.0, z], [1.0, 0.0, 0.0], jamb(l), m),
        wall([r, 0.0, z], [-1.0, 0.0, 0.0], jamb(r), m),
    ]
}

/// A wall at `z` on the axis turned `yaw_deg` (its right-hand part nearer) and tilted
/// `pitch_deg` (its lower part nearer): the instrument's yaw and pitch
/// (`tangent_core::solvers::plane_pca::Orientation`).
pub fn turned_wall(z: f64, yaw_deg: f64, pitch_deg: f64, m: Material) -> Object {
    let (y, p) = (yaw_deg.to_radians(), pitch_deg.to_radians());
    wall(
        [0.0, 0.0, z],
        [y.sin() * p.cos(), p.sin(), y.cos() * p.cos()],
        None,
        m,
    )
}

/// Room light: 0.5 W/m² diffuse in the laser's band (a lit interior through the filter).
pub fn room_light() -> Lighting {
    Lighting {
        diffuse_w_m2: 0.5,
        sun_w_m2: 0.0,
        sun_direction: [0.0, -1.0, 0.0],
        background_w_m2: 0.1,
    }
}

/// One committed wall capture.
pub struct WallEntry {
    /// Directory name.
    pub name: &'static str,
    /// Description.
    pub description: String,
    /// The head: two parallel lines (the reference) or one.
    pub calibration: Calibration,
    /// The scene.
    pub objects: Vec<Object>,
}

/// The committed wall captures beyond the first two (`corpus::entries` appends them, after
/// every older entry so that no older capture's seed changes).
pub fn entries() -> Vec<WallEntry> {
    let two = two_plane_calibration;
    vec![
        WallEntry {
            name: "wall-z300-yaw25-concrete",
            description: "concrete wall 3.0 m away on the axis, turned 25° (right part nearer)"
                .into(),
            calibration: two(),
            objects: vec![turned_wall(3.0, 25.0, 0.0, CONCRETE)],
        },
        WallEntry {
            name: "wall-corner-z150-a100-brick",
            description:
                "room corner of 100° in brick, edge 1.5 m away 0.1 m right of the axis, turned 10°"
                    .into(),
            calibration: two(),
            objects: corner(0.1, 1.5, 100.0, 10.0, BRICK),
        },
        WallEntry {
            name: "wall-niche-z200-w600-d150",
            description:
                "plaster wall 2.0 m away with a niche 600 mm wide and 150 mm deep on the axis"
                    .into(),
            calibration: two(),
            objects: niche(0.0, 2.0, 0.6, 0.15, PLASTER),
        },
        WallEntry {
            name: "wall-door-z150-w900",
            description:
                "wooden wall 1.5 m away with a door opening 900 mm wide into a room 2 m deeper"
                    .into(),
            calibration: two(),
            objects: niche(0.05, 1.5, 0.9, 2.0, WOOD),
        },
        WallEntry {
            name: "wall-z200-one-line",
            description: "plaster wall 2.0 m away seen by a one-line head (no plane: refused)"
                .into(),
            calibration: one_plane_calibration(),
            objects: vec![turned_wall(2.0, 0.0, 0.0, PLASTER)],
        },
        WallEntry {
            name: "wall-column-d800-z150",
            description: "round plaster column 800 mm across, 1.5 m away (curved: refused)".into(),
            calibration: two(),
            objects: vec![Object::Cylinder(Cylinder {
                axis_point_m: [0.0, 0.0, 1.9],
                axis_direction: [0.0, 1.0, 0.0],
                radius_m: Some(0.4),
                semi_axes_m: None,
                major_axis_direction: None,
                extent_m: None,
                albedo: PLASTER.albedo,
                texture: Texture::Stone,
                texture_contrast: PLASTER.contrast,
            })],
        },
        WallEntry {
            name: "wall-z250-pitch3-crossing",
            description: "plaster wall 2.5 m away turned 10° and tilted 3° (lower part nearer), \
                          seen by the three-line head (the crossing line in its own frame)"
                .into(),
            calibration: three_plane_calibration(),
            objects: vec![turned_wall(2.5, 10.0, 3.0, PLASTER)],
        },
        WallEntry {
            name: "wall-corner-z200-crossing",
            description: "room corner of 90° in concrete, edge 2.0 m away on the axis, turned \
                          −5°, seen by the three-line head"
                .into(),
            calibration: three_plane_calibration(),
            objects: corner(0.0, 2.0, 90.0, -5.0, CONCRETE),
        },
    ]
}

/// The simulation settings of every wall capture: indoor light, the surface's roughness, the
/// reference accelerometer.
pub fn wall_params(params: &mut SimParams) {
    params.lighting = room_light();
    params.surface_roughness_m = 3e-4;
    params.accelerometer = Some(AccelerometerSim::reference());
}

/// View `i` (0–5) of a calibration session on a flat wall (`docs/calibration.md`, section
/// 13): matt plaster at 1.0–3.0 m, turned ±15° and tilted ±5° differently each time, room
/// light, every line of the head lit (`crossing`: the three-line head); `session` seeds the
/// rendering's noise.
pub fn reference_wall_spec(i: u64, session: u64, crossing: bool) -> SimSpec {
    let z = 1.0 + 0.4 * i as f64;
    let yaw = [12.0, -15.0, 6.0, -8.0, 15.0, -4.0][(i % 6) as usize];
    let pitch = [-5.0, 3.0, 5.0, -2.0, -4.0, 4.0][(i % 6) as usize];
    let mut params = SimParams {
        seed: super::scene::splitmix(session.wrapping_mul(0x9E37_79B9) ^ (i + 101))
            & ((1 << 62) - 1),
        lit_planes: if crossing { vec![0, 1, 2] } else { vec![0, 1] },
        ..SimParams::default()
    };
    wall_params(&mut params);
    params.accelerometer = None;
    SimSpec {
        mode: Mode::Wall,
        description: format!(
            "reference wall, view {i} at {z:.1} m, turned {yaw}°, tilted {pitch}°"
        ),
        timestamp: "2025-06-02T12:00:00Z".into(),
        calibration: if crossing {
            three_plane_calibration()
        } else {
            two_plane_calibration()
        },
        objects: vec![turned_wall(z, yaw, pitch, PLASTER)],
        params,
    }
}

/// What a random room shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RoomKind {
    /// One wall, turned and tilted (orientation, plumb).
    Wall,
    /// A room corner (angle, plumb).
    Corner,
    /// A niche (segment and parallel distance).
    Niche,
}

impl RoomKind {
    /// The kind of seed `seed` in an evaluation: the three in turn.
    pub fn of_seed(seed: u64) -> Self {
        [RoomKind::Wall, RoomKind::Corner, RoomKind::Niche][(seed % 3) as usize]
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            RoomKind::Wall => "wall",
            RoomKind::Corner => "corner",
            RoomKind::Niche => "niche",
        }
    }
}

/// What [`random_room`] drew, beside the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct RoomDraw {
    /// What the room shows.
    pub kind: RoomKind,
    /// Distance of the wall (the corner's edge, the niche's front) along the axis (m).
    pub distance_m: f64,
    /// The surface.
    pub material: Material,
    /// Glossy paint or varnish (a specular lobe beside the diffuse part), else matt.
    pub glossy: bool,
    /// A cable or pipe hangs in front of the wall.
    pub clutter: bool,
    /// The scene, for people.
    pub description: String,
}

/// A random room in the instrument's envelope (for `tangent evaluate --walls`, not the
/// corpus): `kind`, distance uniform in `range` (metres), a random material, matt or glossy
/// (half each: Blinn–Phong lobe of 5–25 % of the energy, exponent 10–60), corners of 80–100°
/// turned up to ±15°, single walls turned ±30° and tilted ±10°, niches 0.1–1.0 m wide (the
/// segment) and 0.05–0.5 m deep, a vertical cable or pipe (6–40 mm) in front of the wall in a
/// third of the rooms, the camera tilted up to ±5° in pitch and roll (the accelerometer's
/// gravity), indoor or lab light. `crossing`: the head with the third, crossing line
/// (fired in its own frame); the draws and the parallel pair's frame are otherwise those of
/// the two-line head.
pub fn random_room(
    seed: u64,
    kind: RoomKind,
    range: (f64, f64),
    crossing: bool,
) -> (SimSpec, RoomDraw) {
    let mut rng = Pcg64::seed_from_u64(super::scene::splitmix(seed ^ 0x5741_4c4c));
    let z = rng.random_range(range.0..range.1);
    let m = MATERIALS[rng.random_range(0..MATERIALS.len())];
    let (mut objects, what) = match kind {
        RoomKind::Wall => {
            let yaw = rng.random_range(-30.0..30.0);
            let pitch = rng.random_range(-10.0..10.0);
            (
                vec![turned_wall(z, yaw, pitch, m)],
                format!("wall turned {yaw:.1}°, tilted {pitch:.1}°"),
            )
        }
        RoomKind::Corner => {
            let opening = rng.random_range(80.0..100.0);
            let turn = rng.random_range(-15.0..15.0);
            let x = rng.random_range(-0.1..0.1) * z;
            (
                corner(x, z, opening, turn, m),
                format!("corner of {opening:.1}° turned {turn:.1}°"),
            )
        }
        RoomKind::Niche => {
            // The segment must fit in the view (±0.37 z) with margin.
            let width = rng.random_range(0.1..(0.6 * z).min(1.0));
            let depth = rng.random_range(0.05..0.5);
            (
                niche(0.0, z, width, depth, m),
                format!(
                    "niche {:.0} mm wide, {:.0} mm deep",
                    width * 1e3,
                    depth * 1e3
                ),
            )
        }
    };
    let glossy = rng.random_bool(0.5);
    let clutter = rng.random_bool(1.0 / 3.0);
    let mut what = what;
    if clutter {
        // A vertical cable or pipe 10–30 % of the way to the wall, off the aimed column.
        let radius = rng.random_range(0.003..0.02);
        let along = rng.random_range(0.7..0.9) * z;
        let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let x = side * rng.random_range(0.12..0.3) * along;
        objects.push(Object::Cylinder(Cylinder {
            axis_point_m: [x, 0.0, along],
            axis_direction: [0.0, 1.0, 0.0],
            radius_m: Some(radius),
            semi_axes_m: None,
            major_axis_direction: None,
            extent_m: None,
            albedo: 0.5,
            texture: Texture::Stone,
            texture_contrast: 0.1,
        }));
        what += &format!(", a {:.0} mm cable at {along:.2} m", 2e3 * radius);
    }
    let (tilt, roll): (f64, f64) = (
        rng.random_range(-5f64..5.0).to_radians(),
        rng.random_range(-5f64..5.0).to_radians(),
    );
    let mut params = SimParams {
        seed: seed & ((1 << 62) - 1),
        lit_planes: vec![0, 1],
        ..SimParams::default()
    };
    wall_params(&mut params);
    if let Some(a) = params.accelerometer.as_mut() {
        // Camera pitched by `tilt` and rolled by `roll`: gravity leaves the image's +y.
        a.gravity_camera = [
            -roll.sin() * tilt.cos(),
            roll.cos() * tilt.cos(),
            -tilt.sin(),
        ];
    }
    if glossy {
        params.reflectance = Reflectance::Glossy {
            specular_fraction: rng.random_range(0.05..0.25),
            exponent: rng.random_range(10.0..60.0),
        };
    }
    if rng.random_bool(0.3) {
        params.lighting = lab_light();
    }
    if crossing {
        params.lit_planes.push(2);
    }
    let description = format!(
        "{} {} {what}, {:.2} m away",
        if glossy { "glossy" } else { "matt" },
        m.name,
        z
    );
    let draw = RoomDraw {
        kind,
        distance_m: z,
        material: m,
        glossy,
        clutter,
        description: description.clone(),
    };
    (
        SimSpec {
            mode: Mode::Wall,
            description,
            timestamp: "2025-06-02T12:00:00Z".into(),
            calibration: if crossing {
                three_plane_calibration()
            } else {
                two_plane_calibration()
            },
            objects,
            params,
        },
        draw,
    )
}
