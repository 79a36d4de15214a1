//! Sphere scenes (`docs/sphere.md`, "Simulated spheres"): the sphere captures of the corpus
//! and random balls for the accuracy evaluation, on the two-plane reference head.
//!
//! A ball is measured when both laser planes cut it; the reference planes are parallel,
//! 50 mm apart, and descend by `z/15` with distance (`y = e − z·e₀/z₀`), so a ball is placed
//! with its centre between the two planes' lines at its distance (`y ≈ 0.125 − z/15`),
//! shifted by a fraction of the free play `R − 25 mm` so that the sections differ.

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;

use super::render::Lighting;
use super::rig::{two_plane_calibration, CorpusEntry};
use super::{Exposure, SimParams, SimSpec};
use crate::capture::Mode;
use crate::truth::{Cylinder, Disc, Object, Plane, SpecularLobe, Sphere, Texture};

/// The finish of a ball.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Finish {
    /// Stone or painted: diffuse, textured.
    Matt,
    /// Polished steel: a specular lobe (glints) over a weak diffuse reflection, untextured,
    /// smooth (fully developed speckle); [`STEEL`].
    Shiny,
}

/// Steel's specular lobe: ≈ 55 % of the light reflected at 650 nm (iron's normal-incidence
/// reflectance) in a lobe of exponent 500 (≈ 2.5°: a polished ball worn by use).
pub const STEEL: SpecularLobe = SpecularLobe {
    fraction: 0.55,
    exponent: 500.0,
};

/// Body albedo of steel under its lobe: the scratched surface's diffuse reflection
/// `(1 − 0.55)·0.3 ≈ 0.14`, against a matt ball's 0.5.
const STEEL_BODY_ALBEDO: f64 = 0.3;

/// Height `y` (metres, down) midway between the two reference planes at distance `z`.
pub fn mid_plane_y(z: f64) -> f64 {
    let cal = two_plane_calibration();
    let y = |k: usize| {
        let p = &cal.planes[k];
        (p.offset - p.normal.z * z) / p.normal.y
    };
    0.5 * (y(0) + y(1))
}

/// A ball of diameter `d_mm` whose centre is `z` ahead, `x` to the right and `shift` (as a
/// fraction of `R`) below the mid-plane between the lasers.
pub fn ball(d_mm: f64, z: f64, x: f64, shift: f64, finish: Finish) -> Object {
    let r = d_mm * 5e-4;
    let (albedo, texture, contrast, specular) = match finish {
        Finish::Matt => (0.5, Texture::Stone, 0.2, None),
        Finish::Shiny => (STEEL_BODY_ALBEDO, Texture::Stone, 0.02, Some(STEEL)),
    };
    Object::Sphere(Sphere {
        centre_m: [x, mid_plane_y(z) + shift * r, z],
        radius_m: r,
        albedo,
        texture,
        texture_contrast: contrast,
        specular,
        stretch: None,
    })
}

/// The floor a ball at `(centre, r)` rests on.
pub fn floor_under(centre_y: f64, r: f64) -> Object {
    Object::Plane(Plane {
        bounds_m: None,
        point_m: [0.0, centre_y + r, 0.0],
        normal: [0.0, -1.0, 0.0],
        albedo: 0.2,
        texture: Texture::Stone,
        texture_contrast: 0.5,
    })
}

/// Height of the instrument above the floor a random ball rests on (metres): a hand held at
/// 0.7 × the ball's distance from the camera, at most 0.8 m (waist height), and never less
/// than the ball needs to be seen resting there ([`floor_seen_from`]).
fn instrument_height(centre: [f64; 3], r: f64) -> f64 {
    let distance = (centre[0] * centre[0] + centre[1] * centre[1] + centre[2] * centre[2]).sqrt();
    (0.7 * distance).min(0.8).max(r + 0.2)
}

/// The floor a ball at `(centre, r)` rests on, seen by an instrument `height` above it and
/// pitched down as it must be to aim its lines at the ball: the plane tangent to the ball at
/// its lowest point along the floor's down direction `g = (0, cos θ, sin θ)` (camera frame),
/// `g·p = height`, θ solving `g·centre + r = height`. A level floor (θ = 0, [`floor_under`])
/// under a ball the lines cut is above the lower laser's exit beyond ≈ 0.8 m (the planes
/// rise with distance), so the floor would hide the lines from the ball.
pub fn floor_seen_from(centre: [f64; 3], r: f64, height: f64) -> Object {
    // g·c = A cos(θ − φ), A = |(c_y, c_z)|, φ = atan2(c_z, c_y); the smaller pitch that
    // solves A cos(θ − φ) = height − r.
    let a = centre[1].hypot(centre[2]);
    let phi = centre[2].atan2(centre[1]);
    let theta = phi - ((height - r) / a).clamp(-1.0, 1.0).acos();
    let g = [0.0, theta.cos(), theta.sin()];
    Object::Plane(Plane {
        bounds_m: None,
        point_m: [
            centre[0] + g[0] * r,
            centre[1] + g[1] * r,
            centre[2] + g[2] * r,
        ],
        normal: [-g[0], -g[1], -g[2]],
        albedo: 0.2,
        texture: Texture::Stone,
        texture_contrast: 0.5,
    })
}

fn params(seed: u64, finish: Finish) -> SimParams {
    let mut p = SimParams {
        seed,
        lit_planes: vec![0, 1],
        ..SimParams::default()
    };
    if finish == Finish::Shiny {
        // A polished surface: speckle without the spectral averaging of a rough one.
        p.surface_roughness_m = 2e-6;
        // The glint is hundreds of times the stripe: exposed for the stripe's typical
        // column, it saturates (a peak-driven exposure would leave the stripe in the noise).
        p.exposure = Exposure::AutoMedianColumn {
            peak_fraction: 0.7,
            max_s: 0.03,
        };
    }
    p
}

fn entry(
    name: &str,
    description: &str,
    objects: Vec<Object>,
    seed: u64,
    finish: Finish,
) -> CorpusEntry {
    CorpusEntry {
        name: name.to_string(),
        spec: SimSpec {
            mode: Mode::Sphere,
            description: description.to_string(),
            timestamp: "2025-06-04T10:00:00Z".to_string(),
            calibration: two_plane_calibration(),
            objects,
            params: params(seed, finish),
        },
    }
}

/// The sphere captures of the corpus (two planes; seeds 3000 + index): balls of 60–400 mm
/// at 0.6–2 m, centred and off-centre, matt and shiny, in the air and on a floor, and objects
/// that are not one ball (an elliptic post, a wall, two balls) that must be refused or
/// flagged.
pub fn entries() -> Vec<CorpusEntry> {
    let mut out = Vec::new();
    let mut add = |name: &str, description: &str, objects: Vec<Object>, finish: Finish| {
        let seed = 3000 + out.len() as u64;
        out.push(entry(name, description, objects, seed, finish));
    };
    for (d, z, x, finish, tag) in [
        (100.0, 0.8, 0.0, Finish::Matt, "matt"),
        (200.0, 1.2, 0.0, Finish::Matt, "matt"),
        (400.0, 2.0, 0.0, Finish::Matt, "matt"),
        (60.0, 0.6, 0.0, Finish::Matt, "matt"),
        (150.0, 1.0, 0.12, Finish::Matt, "offcentre"),
        (120.0, 1.0, 0.0, Finish::Shiny, "shiny"),
        (250.0, 1.5, -0.15, Finish::Shiny, "shiny-offcentre"),
    ] {
        let name = format!(
            "sphere-d{:03}-z{:03}-{tag}-2p",
            d as u32,
            (z * 100.0) as u32
        );
        let description = format!(
            "{} ball {d:.0} mm, centre {z:.1} m ahead{}, two planes",
            if finish == Finish::Shiny {
                "steel"
            } else {
                "matt"
            },
            if x != 0.0 {
                format!(", {x:+.2} m across")
            } else {
                String::new()
            }
        );
        add(
            &name,
            &description,
            vec![ball(d, z, x, 0.2, finish)],
            finish,
        );
    }
    // On a floor: the ball rests on it, the floor's stripe beside the ball's.
    let b = ball(160.0, 1.0, 0.0, 0.2, Finish::Matt);
    let Object::Sphere(s) = &b else {
        unreachable!("ball() makes a sphere")
    };
    let floor = floor_under(s.centre_m[1], s.radius_m);
    add(
        "sphere-d160-z100-floor-2p",
        "matt ball 160 mm resting on a floor, centre 1.0 m ahead, two planes",
        vec![b, floor],
        Finish::Matt,
    );
    // Not one ball.
    add(
        "notsphere-elliptic-post-z100-2p",
        "an upright post of elliptic section 240 × 160 mm (major axis across), 1.0 m ahead, in \
         sphere mode: its sections are ellipses",
        vec![Object::Cylinder(Cylinder {
            axis_point_m: [0.0, 0.0, 1.1],
            axis_direction: [0.0, 1.0, 0.0],
            radius_m: None,
            semi_axes_m: Some([0.12, 0.08]),
            major_axis_direction: Some([1.0, 0.0, 0.0]),
            extent_m: None,
            albedo: 0.4,
            texture: Texture::Stone,
            texture_contrast: 0.2,
        })],
        Finish::Matt,
    );
    add(
        "notsphere-wall-z120-2p",
        "a flat wall 1.2 m ahead in sphere mode: straight sections",
        vec![Object::Plane(Plane {
            bounds_m: None,
            point_m: [0.0, 0.0, 1.2],
            normal: [0.3, 0.0, -1.0],
            albedo: 0.5,
            texture: Texture::Stone,
            texture_contrast: 0.2,
        })],
        Finish::Matt,
    );
    add(
        "notsphere-two-balls-z100-2p",
        "two matt balls of 80 mm side by side at different heights, 1.0 m ahead, one laser \
         on each",
        vec![
            ball(80.0, 1.0, -0.06, -1.125, Finish::Matt),
            ball(80.0, 1.0, 0.06, 1.125, Finish::Matt),
        ],
        Finish::Matt,
    );
    // Added later (seeds after the older entries'): glints in the sun, and two more
    // non-spheres.
    let mut sunny = entry(
        "sphere-d100-z080-steel-sun-2p",
        "steel ball 100 mm in direct sun (a saturated sun glint beside the stripes), centre \
         0.8 m ahead, two planes",
        vec![ball(100.0, 0.8, 0.03, 0.2, Finish::Shiny)],
        3000 + out.len() as u64,
        Finish::Shiny,
    );
    sunny.spec.params.lighting = Lighting {
        sun_w_m2: 15.0,
        sun_direction: [0.25, -1.0, -0.6],
        diffuse_w_m2: 1.5,
        ..Lighting::shade()
    };
    out.push(sunny);
    // The laser's own glint: a plane passing the ball's specular point (the normal bisecting
    // the directions to the camera and to the laser) saturates a few columns of its stripe.
    out.push(entry(
        "sphere-d300-z100-steel-glint-2p",
        "steel ball 300 mm, centre 1.0 m ahead midway between the lasers: the upper line \
         crosses the specular point (a saturated glint on the stripe), two planes",
        vec![ball(300.0, 1.0, 0.0, 0.0, Finish::Shiny)],
        3000 + out.len() as u64,
        Finish::Shiny,
    ));
    let mut add = |name: &str, description: &str, objects: Vec<Object>| {
        let seed = 3000 + out.len() as u64;
        out.push(entry(name, description, objects, seed, Finish::Matt));
    };
    let Object::Sphere(mut egg) = ball(160.0, 1.0, 0.0, 0.2, Finish::Matt) else {
        unreachable!("ball() makes a sphere")
    };
    egg.stretch = Some([1.5, 1.0, 1.0]);
    add(
        "notsphere-ellipsoid-z100-2p",
        "an ellipsoid 240 × 160 × 160 mm (long axis across), 1.0 m ahead, in sphere mode: \
         its sections are ellipses",
        vec![Object::Sphere(egg)],
    );
    add(
        "notsphere-cylinder-end-z100-2p",
        "the end of a cylinder 100 mm across, 100 mm long (a cylpeb), its axis 36° off the line \
         of sight, 1.0 m ahead, in sphere mode: flat end face and elliptic sides",
        cylinder_with_ends(0.05, 0.1, [0.0, mid_plane_y(1.0), 1.0], [0.3, -0.5, 0.8]),
    );
    add(
        "two-balls-d120-z100-2p",
        "two matt balls of 120 mm side by side, 0.2 m apart, 1.0 m ahead, both laser lines \
         across both",
        vec![
            ball(120.0, 1.0, -0.1, 0.2, Finish::Matt),
            ball(120.0, 1.0, 0.1, 0.2, Finish::Matt),
        ],
    );
    // A ball beside the aim on a floor: the floor's lines cross the central column, the ball
    // does not (its sections are ranked first for bending, `pipeline::arcs`).
    let b = ball(80.0, 0.9, 0.09, 0.2, Finish::Matt);
    let Object::Sphere(s) = &b else {
        unreachable!("ball() makes a sphere")
    };
    let floor = floor_seen_from(
        s.centre_m,
        s.radius_m,
        instrument_height(s.centre_m, s.radius_m),
    );
    add(
        "sphere-d080-z090-floor-offcentre-2p",
        "matt ball 80 mm resting on a floor beside the aim (centre 0.9 m ahead, 0.09 m across: \
         the floor's lines cross the central column, the ball does not), two planes",
        vec![b, floor],
    );
    // A small ball whose lines both cut it near its poles, in few columns: a short section's
    // circle misses the sphere's axis while one sphere fits every point (`docs/sphere.md`,
    // "Sections that miss the axis").
    add(
        "sphere-d055-z120-nearpole-2p",
        "matt ball 55 mm, centre 1.2 m ahead, +0.08 m across, midway between the lasers: each \
         line cuts it about 10 mm from a pole, in ≈ 20 columns, two planes",
        vec![ball(55.0, 1.2, 0.08, 0.0, Finish::Matt)],
    );
    out
}

/// A closed cylinder of radius `r` and length `len` (a cylpeb): its side and two end discs,
/// the near end centred at `end` and the axis along `axis` (away from that end).
pub fn cylinder_with_ends(r: f64, len: f64, end: [f64; 3], axis: [f64; 3]) -> Vec<Object> {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let a = axis.map(|x| x / n);
    let far = [0, 1, 2].map(|k| end[k] + a[k] * len);
    let disc = |centre_m: [f64; 3]| {
        Object::Disc(Disc {
            centre_m,
            normal: a,
            radius_m: r,
            albedo: 0.4,
            texture: Texture::Stone,
            texture_contrast: 0.2,
        })
    };
    vec![
        Object::Cylinder(Cylinder {
            axis_point_m: end,
            axis_direction: a,
            radius_m: Some(r),
            semi_axes_m: None,
            major_axis_direction: None,
            extent_m: Some([0.0, len]),
            albedo: 0.4,
            texture: Texture::Stone,
            texture_contrast: 0.2,
        }),
        disc(end),
        disc(far),
    ]
}

/// A random ball for the accuracy evaluation (not the corpus): diameter log-uniform in
/// View `i` (0–5) of a calibration session with a reference ball (`docs/calibration.md`,
/// section 12): a matt 145 mm sphere (the size of a laser scanner's reference sphere) at
/// 0.6–1.6 m, alternately left and right of the axis and stepped across the free play
/// between the lines; `session` seeds the rendering's noise.
pub fn reference_ball_spec(i: u64, session: u64) -> SimSpec {
    let z = 0.6 + 0.2 * i as f64;
    let x = if i.is_multiple_of(2) {
        0.08 * z
    } else {
        -0.06 * z
    };
    let shift = 0.1 * (i as f64 - 2.5);
    SimSpec {
        mode: Mode::Sphere,
        description: format!("reference ball 145 mm, view {i} at {z:.1} m"),
        timestamp: "2025-06-04T12:00:00Z".into(),
        calibration: two_plane_calibration(),
        objects: vec![ball(145.0, z, x, shift, Finish::Matt)],
        params: params(splitmix_session(session, i), Finish::Matt),
    }
}

/// A seed per (session, view) for [`reference_ball_spec`]'s noise.
fn splitmix_session(session: u64, i: u64) -> u64 {
    super::scene::splitmix(session.wrapping_mul(0x9E37_79B9) ^ (i + 1)) & (u64::MAX >> 1)
}

/// 20–400 mm, centre 0.3–2 m ahead, across the central half of the view, up to ±0.5 of the
/// free play off the mid-plane, matt or shiny, on a floor one time in three; the two-plane
/// reference head.
pub fn random_sphere(seed: u64) -> SimSpec {
    RandomBall::draw(seed).spec()
}

/// What [`random_sphere`] drew for one seed (the evaluation tabulates by it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RandomBall {
    /// The seed.
    pub seed: u64,
    /// Diameter (mm).
    pub d_mm: f64,
    /// Centre's distance ahead (m).
    pub z: f64,
    /// Centre's offset across (m).
    pub x: f64,
    /// Offset below the mid-plane between the lasers, as a fraction of `R`.
    pub shift: f64,
    /// Matt or steel.
    pub finish: Finish,
    /// Resting on a floor.
    pub on_floor: bool,
}

impl RandomBall {
    /// The ball of `seed` (module documentation).
    pub fn draw(seed: u64) -> RandomBall {
        let mut rng = Pcg64::seed_from_u64(super::scene::splitmix(seed ^ 0x5a5a_5a5a));
        let d_mm = 20.0 * (20f64).powf(rng.random::<f64>());
        let z = 0.3 + 1.7 * rng.random::<f64>();
        let r = d_mm * 5e-4;
        let x = (rng.random::<f64>() - 0.5) * 0.35 * z;
        let play = ((r - 0.025) / r).max(0.0);
        let shift = (rng.random::<f64>() - 0.5) * play;
        let finish = if rng.random::<f64>() < 0.3 {
            Finish::Shiny
        } else {
            Finish::Matt
        };
        let on_floor = rng.random::<f64>() < 1.0 / 3.0;
        RandomBall {
            seed,
            d_mm,
            z,
            x,
            shift,
            finish,
            on_floor,
        }
    }

    /// The scene.
    pub fn spec(&self) -> SimSpec {
        let RandomBall {
            seed,
            d_mm,
            z,
            x,
            shift,
            finish,
            on_floor,
        } = *self;
        let b = ball(d_mm, z, x, shift, finish);
        let mut objects = vec![b.clone()];
        if on_floor {
            if let Object::Sphere(s) = &b {
                let height = instrument_height(s.centre_m, s.radius_m);
                objects.push(floor_seen_from(s.centre_m, s.radius_m, height));
            }
        }
        SimSpec {
            mode: Mode::Sphere,
            description: format!(
                "random ball {d_mm:.1} mm, centre {z:.3} m ahead, {x:+.3} m across, {}{}",
                if finish == Finish::Shiny {
                    "steel"
                } else {
                    "matt"
                },
                if on_floor { ", on a floor" } else { "" }
            ),
            timestamp: "2025-06-04T12:00:00Z".into(),
            calibration: two_plane_calibration(),
            objects,
            params: params(seed & (u64::MAX >> 1), finish),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The floor a random ball rests on touches the ball, faces the camera, and has the
    /// camera and both laser exits above it, `height` above for the camera. (A level floor
    /// under the ball, `floor_under`, fails the exits' check from the first seed on.)
    #[test]
    fn the_floor_is_under_the_ball_and_below_the_instrument() {
        let cal = two_plane_calibration();
        for seed in 2_000_000..2_000_200 {
            let ball = RandomBall::draw(seed);
            let Object::Sphere(s) = super::ball(ball.d_mm, ball.z, ball.x, ball.shift, ball.finish)
            else {
                unreachable!("ball() makes a sphere")
            };
            let (c, r) = (s.centre_m, s.radius_m);
            let height = instrument_height(c, r);
            let Object::Plane(floor) = floor_seen_from(c, r, height) else {
                unreachable!("a plane")
            };
            let n = floor.normal;
            let above = |p: [f64; 3]| {
                (0..3)
                    .map(|i| (p[i] - floor.point_m[i]) * n[i])
                    .sum::<f64>()
            };
            assert!((above(c) - r).abs() < 1e-9, "seed {seed}: tangent");
            assert!(
                (above([0.0; 3]) - height).abs() < 1e-9,
                "seed {seed}: the camera"
            );
            for plane in &cal.planes {
                let exit = plane.source;
                assert!(
                    above([exit.x, exit.y, exit.z]) > 0.0,
                    "seed {seed}: a laser exit below the floor"
                );
            }
        }
    }
}
