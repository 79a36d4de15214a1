//! Road scenes for the road head (`docs/road.md`, "Simulated roads"): four surface types with
//! known texture spectra, wet darkening and tyre-polished stones; the piezo stage of the
//! height-scale calibration; the furrow block of the validation; a tilted head. Each comes
//! with its truth (the true profile along the laser sheet, its MPD and the furrow depth).
//!
//! A road is the simulator's heightfield `z = z0 + Σ A sin(2π(x cos φ + y sin φ)/λ + φ0)`
//! (`z` away from the head, so the road's height is `−Σ…`). A surface type is its amplitude
//! spectrum: components at three per octave from 0.5 to 50 mm (macrotexture) with a
//! log-normal envelope about the aggregate's size, and four between 0.12 and 0.45 mm
//! (microtexture), random phases and directions from the seed.

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use tangent_core::calibration::Calibration;
use tangent_core::instrument::road::{
    road_head_calibration, ROAD_HEAD_BASELINE, ROAD_HEAD_STANDOFF,
};

use super::rig::CorpusEntry;
use super::{SimParams, SimSpec};
use crate::capture::Mode;
use crate::truth::{Object, Plane, Road, Texture, Wave};

/// The road surfaces of chapter 12's table of textures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Surface {
    /// Dense asphalt concrete (AC 0/11): aggregate ≈ 8 mm, MPD ≈ 0.5–0.8 mm.
    DenseAsphalt,
    /// Stone mastic asphalt (SMA 0/11): coarser, open surface, MPD ≈ 0.9–1.3 mm.
    StoneMastic,
    /// Surface dressing (chip seal, 10 mm chips): MPD ≈ 1.5–2.5 mm.
    SurfaceDressing,
    /// Worn brushed concrete: fine, shallow texture, MPD ≈ 0.3–0.5 mm.
    WornConcrete,
}

impl Surface {
    /// Every surface type.
    pub const ALL: [Surface; 4] = [
        Surface::DenseAsphalt,
        Surface::StoneMastic,
        Surface::SurfaceDressing,
        Surface::WornConcrete,
    ];

    /// Short name (capture names, tables).
    pub fn name(self) -> &'static str {
        match self {
            Surface::DenseAsphalt => "dense-asphalt",
            Surface::StoneMastic => "stone-mastic",
            Surface::SurfaceDressing => "surface-dressing",
            Surface::WornConcrete => "worn-concrete",
        }
    }

    /// Macrotexture envelope: peak wavelength (m), component amplitude at the peak (m),
    /// log-width (natural-log units); microtexture component amplitude (m); albedo; texture.
    fn spectrum(self) -> (f64, f64, f64, f64, f64, Texture) {
        match self {
            Surface::DenseAsphalt => (8e-3, 0.22e-3, 0.8, 12e-6, 0.12, Texture::Asphalt),
            Surface::StoneMastic => (10e-3, 0.36e-3, 0.7, 15e-6, 0.12, Texture::Asphalt),
            Surface::SurfaceDressing => (14e-3, 0.6e-3, 0.6, 20e-6, 0.14, Texture::Asphalt),
            Surface::WornConcrete => (5e-3, 0.12e-3, 1.0, 6e-6, 0.3, Texture::Stone),
        }
    }
}

/// Condition of a road surface.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Condition {
    /// Wet: a water film darkens the surface (albedo × 0.4: light trapped by total internal
    /// reflection in the film, Lekner & Dorf 1988).
    pub wet: bool,
    /// Tyre-polished stones: the microtexture worn to a fifth and the aggregate's reflectance
    /// pattern faded.
    pub polished: bool,
}

/// The texture components of a surface (seeded).
pub fn surface_waves(surface: Surface, condition: Condition, seed: u64) -> Vec<Wave> {
    let (peak, a_peak, width, a_micro, _, _) = surface.spectrum();
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut waves = Vec::new();
    // Macrotexture: 3 per octave from 0.5 to 50 mm.
    let bands = (3.0 * (50.0f64 / 0.5).log2()).round() as usize;
    for k in 0..=bands {
        let lambda = 0.5e-3 * 2f64.powf(k as f64 / 3.0);
        let l = (lambda / peak).ln() / width;
        let amplitude = a_peak * (-0.5 * l * l).exp();
        if amplitude < 2e-6 {
            continue;
        }
        waves.push(Wave {
            amplitude_m: amplitude,
            wavelength_m: lambda,
            phase_rad: rng.random_range(0.0..std::f64::consts::TAU),
            direction_rad: rng.random_range(0.0..std::f64::consts::PI),
        });
    }
    // Microtexture: 4 components between 0.12 and 0.45 mm.
    let micro = if condition.polished {
        a_micro / 5.0
    } else {
        a_micro
    };
    for k in 0..4 {
        let lambda = 0.12e-3 * (0.45f64 / 0.12).powf(k as f64 / 3.0);
        waves.push(Wave {
            amplitude_m: micro,
            wavelength_m: lambda,
            phase_rad: rng.random_range(0.0..std::f64::consts::TAU),
            direction_rad: rng.random_range(0.0..std::f64::consts::PI),
        });
    }
    waves
}

/// A road of `surface` under the road head, `offset` farther than the stand-off.
pub fn road_object(surface: Surface, condition: Condition, seed: u64, offset: f64) -> Object {
    let (.., albedo, texture) = surface.spectrum();
    Object::Road(Road {
        distance_m: ROAD_HEAD_STANDOFF + offset,
        waves: surface_waves(surface, condition, seed),
        albedo: if condition.wet { albedo * 0.4 } else { albedo },
        texture,
        texture_contrast: if condition.polished { 0.15 } else { 0.5 },
    })
}

/// The road head's calibration (id 12 for the corpus).
pub fn calibration() -> Calibration {
    // The design constants are valid (the core's tests build the same).
    road_head_calibration(12).unwrap_or_else(|_| Calibration::reference_design())
}

/// `1/e²` half-thickness of the road head's laser sheet at its waist, on the road (metres):
/// the sheet's thickness is the road MPD's texture-tied error (`docs/road.md`, "Across the
/// sheet"), so the head's line generator focuses it there, as thin as keeps the stripe ≥ 1 px
/// (σ) in the image for the sub-pixel peak (`docs/road.md`, "The road head").
pub const ROAD_SHEET_WAIST: f64 = 0.25e-3;

/// Simulation settings of the road head: the reference sensor; the reference laser's diode
/// behind a line generator focused on the road (`1/e²` half-width [`ROAD_SHEET_WAIST`] at the
/// source-to-road distance `√(B² + Z²)`, a single-mode Gaussian beam's far-field divergence
/// `θ = λ/(π w0)`: Rayleigh range `π w0²/λ` ≈ 0.30 m against the road's few millimetres,
/// `docs/hardware.md`, "Road head"); the head's shade (its skirt keeps daylight out: a dim
/// diffuse ambient), speckle on.
pub fn params(seed: u64) -> SimParams {
    let mut p = SimParams {
        seed,
        ..SimParams::default()
    };
    p.laser.waist_half_width_m = ROAD_SHEET_WAIST;
    p.laser.divergence_rad = p.laser.wavelength_m / (std::f64::consts::PI * ROAD_SHEET_WAIST);
    p.laser.waist_distance_m = ROAD_HEAD_BASELINE.hypot(ROAD_HEAD_STANDOFF);
    p.lighting.diffuse_w_m2 = 0.05;
    p.lighting.sun_w_m2 = 0.0;
    p
}

/// A road capture's spec.
pub fn road_spec(surface: Surface, condition: Condition, seed: u64) -> SimSpec {
    let mut description = format!("road head on {}", surface.name().replace('-', " "));
    if condition.wet {
        description += ", wet";
    }
    if condition.polished {
        description += ", tyre-polished stones";
    }
    SimSpec {
        mode: Mode::Road,
        description,
        timestamp: "2025-06-03T10:00:00Z".into(),
        calibration: calibration(),
        objects: vec![road_object(surface, condition, seed, 0.0)],
        params: params(seed),
    }
}

/// The piezo stage: a flat matt target `step` nearer than the stand-off (the stage moves it
/// towards the head).
pub fn piezo_spec(step: f64, seed: u64) -> SimSpec {
    SimSpec {
        mode: Mode::Road,
        description: format!("piezo stage: flat target raised {:.3} mm", step * 1e3),
        timestamp: "2025-06-03T11:00:00Z".into(),
        calibration: calibration(),
        objects: vec![Object::Plane(Plane {
            bounds_m: None,
            point_m: [0.0, 0.0, ROAD_HEAD_STANDOFF - step],
            normal: [0.0, 0.0, -1.0],
            albedo: 0.5,
            texture: Texture::Stone,
            texture_contrast: 0.1,
        })],
        params: params(seed),
    }
}

/// Furrow block: 1 mm-wide furrows every [`FURROW_PITCH`] across the line, as the
/// Lanczos-smoothed Fourier series of the rectangular train (harmonics down to 0.14 mm).
pub const FURROW_PITCH: f64 = 4e-3;
/// Width of a furrow.
pub const FURROW_WIDTH: f64 = 1e-3;
const FURROW_HARMONICS: usize = 28;

/// The furrow block's heightfield components for furrows `depth` deep.
pub fn furrow_waves(depth: f64) -> Vec<Wave> {
    // Rectangular train of furrows (value 1 in a furrow) centred on x = 0:
    // f = w/P + Σ 2 sin(nπw/P)/(nπ) cos(2πnx/P); the furrow floor is farther (+z).
    let (p, w) = (FURROW_PITCH, FURROW_WIDTH);
    (1..=FURROW_HARMONICS)
        .map(|n| {
            let nf = n as f64;
            let lanczos = {
                let t = std::f64::consts::PI * nf / (FURROW_HARMONICS as f64 + 1.0);
                t.sin() / t
            };
            Wave {
                amplitude_m: depth * 2.0 * (nf * std::f64::consts::PI * w / p).sin()
                    / (nf * std::f64::consts::PI)
                    * lanczos,
                wavelength_m: p / nf,
                phase_rad: std::f64::consts::FRAC_PI_2,
                direction_rad: 0.0,
            }
        })
        .collect()
}

/// The furrow block's spec (`depth`: 146 µm or 630 µm in the thesis).
pub fn furrow_spec(depth: f64, seed: u64) -> SimSpec {
    SimSpec {
        mode: Mode::Road,
        description: format!(
            "furrow block: 1 mm furrows {:.0} µm deep every 4 mm",
            depth * 1e6
        ),
        timestamp: "2025-06-03T12:00:00Z".into(),
        calibration: calibration(),
        objects: vec![Object::Road(Road {
            distance_m: ROAD_HEAD_STANDOFF - depth * FURROW_WIDTH / FURROW_PITCH,
            waves: furrow_waves(depth),
            albedo: 0.45,
            texture: Texture::Stone,
            texture_contrast: 0.1,
        })],
        params: params(seed),
    }
}

/// The head tilted `degrees` across the line on a flat road.
pub fn tilted_spec(degrees: f64, seed: u64) -> SimSpec {
    let t = degrees.to_radians();
    SimSpec {
        mode: Mode::Road,
        description: format!("road head tilted {degrees:.0}° across the line"),
        timestamp: "2025-06-03T13:00:00Z".into(),
        calibration: calibration(),
        objects: vec![Object::Plane(Plane {
            bounds_m: None,
            point_m: [0.0, 0.0, ROAD_HEAD_STANDOFF],
            normal: [t.sin(), 0.0, -t.cos()],
            albedo: 0.12,
            texture: Texture::Asphalt,
            texture_contrast: 0.5,
        })],
        params: params(seed),
    }
}

/// The road captures of the corpus (`tests/captures/road-*`).
pub fn entries() -> Vec<CorpusEntry> {
    let entry = |name: &str, spec: SimSpec| CorpusEntry {
        name: name.to_string(),
        spec,
    };
    let mut out = Vec::new();
    for (k, s) in Surface::ALL.iter().enumerate() {
        out.push(entry(
            &format!("road-head-{}", s.name()),
            road_spec(*s, Condition::default(), 5000 + k as u64),
        ));
    }
    out.push(entry(
        "road-head-stone-mastic-wet",
        road_spec(
            Surface::StoneMastic,
            Condition {
                wet: true,
                polished: false,
            },
            5010,
        ),
    ));
    out.push(entry(
        "road-head-dense-asphalt-polished",
        road_spec(
            Surface::DenseAsphalt,
            Condition {
                wet: false,
                polished: true,
            },
            5011,
        ),
    ));
    out.push(entry("road-head-piezo-0000um", piezo_spec(0.0, 5020)));
    out.push(entry("road-head-piezo-1000um", piezo_spec(1e-3, 5021)));
    out.push(entry("road-head-furrow-146um", furrow_spec(146e-6, 5030)));
    out.push(entry("road-head-furrow-630um", furrow_spec(630e-6, 5031)));
    out.push(entry("road-head-tilted-10deg", tilted_spec(10.0, 5040)));
    out
}
