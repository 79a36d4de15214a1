//! The physics models: alternative, physically defensible photometric chains drawn per
//! capture (`docs/simulator.md`, "Physics models").
//!
//! A model is a name ([`PhysicsModel`]) over parameters the simulator already has a physical
//! meaning for — the surfaces' BRDF, the sheet's cross profile, the lens's f-number, PSF and
//! focus, the laser's linewidth, the bark's roughness and texture scale, the sensor's noise.
//! [`apply`] draws those parameters from the capture's seed within the ranges the docs
//! justify; the geometry (scene, calibration) is never touched, so a model changes only how
//! the stripe and the background look.

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;

use super::laser::SheetProfile;
use super::reflectance::Reflectance;
use super::scene::{splitmix, Scene};
use super::SimSpec;
use crate::truth::PhysicsModel;

/// Stream mixed into the seed for the physics draws (independent of the geometry's draws,
/// which use `splitmix(seed)` directly).
const PHYSICS_STREAM: u64 = 0x5048_5953_4943_5321;

/// The model of a capture drawn from its seed: the models in turn (`seed mod 8`), so any run
/// of consecutive seeds covers them evenly.
pub fn model_for_seed(seed: u64) -> PhysicsModel {
    PhysicsModel::ALL[(seed % PhysicsModel::ALL.len() as u64) as usize]
}

fn uniform(rng: &mut Pcg64, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// Gaussian PSF σ (pixels) of the reference lens at f-number `n`: the reference 0.5 px at
/// f/2.4 is mostly aberrations (0.49 px) plus the Airy core `0.42·λ·N` (0.11 px); stopping
/// down keeps the aberrations and grows the diffraction.
fn psf_sigma_px(n: f64, wavelength_m: f64, pitch_m: f64) -> f64 {
    0.49f64.hypot(0.42 * wavelength_m * n / pitch_m)
}

/// Sets the photometric parameters of `spec` to a draw of `model` from `seed` and records
/// the model in `spec.params.physics`. The reference model leaves the parameters as they are.
pub fn apply(model: PhysicsModel, seed: u64, spec: &mut SimSpec) {
    let mut rng = Pcg64::seed_from_u64(splitmix(seed ^ PHYSICS_STREAM));
    let aspects: [bool; 6] = match model {
        PhysicsModel::Reference => [false; 6],
        PhysicsModel::OrenNayarBark => [true, false, false, false, false, false],
        PhysicsModel::SpecularSheen => [false, true, false, false, false, false],
        PhysicsModel::FlatTopSheet => [false, false, true, false, false, false],
        PhysicsModel::Defocus => [false, false, false, true, false, false],
        PhysicsModel::CoarseSpeckle => [false, false, false, false, true, false],
        PhysicsModel::NoisySensor => [false, false, false, false, false, true],
        PhysicsModel::Mixed => {
            let mut a = [false; 6];
            a.iter_mut().for_each(|x| *x = rng.random::<f64>() < 0.5);
            // The two reflectance alternatives exclude each other.
            if a[0] && a[1] {
                a[rng.random_range(0..2usize)] = false;
            }
            a
        }
    };
    let [rough, glossy, flat_top, defocus, coarse_speckle, noisy] = aspects;
    let focus_depth = scene_depth_on_axis(spec);
    let p = &mut spec.params;
    p.physics = model;
    if rough {
        // Bark: facet slopes of 17–34° RMS, furrows half to twice the nominal size, height
        // roughness 1–3 mm.
        p.reflectance = Reflectance::OrenNayar {
            sigma_rad: uniform(&mut rng, 0.3, 0.6),
        };
        p.texture_scale = 2f64.powf(uniform(&mut rng, -1.0, 1.0));
        p.surface_roughness_m = uniform(&mut rng, 1e-3, 3e-3);
    }
    if glossy {
        // Wet or smooth bark: 3–15 % of the light in a lobe of exponent 10–80.
        p.reflectance = Reflectance::Glossy {
            specular_fraction: uniform(&mut rng, 0.03, 0.15),
            exponent: uniform(&mut rng, 10.0, 80.0),
        };
    }
    if flat_top {
        p.laser.profile = SheetProfile::FlatTop {
            order: uniform(&mut rng, 4.0, 10.0),
        };
    }
    if defocus {
        // Fixed-focus lens focused at 0.8–2 m; blur-disc radius for the object on the
        // optical axis: c/2 = f²·|s − s_f| / (2·N·s·(s_f − f)) on the sensor.
        let s_f = uniform(&mut rng, 0.8, 2.0);
        let pitch = p.sensor.pixel_pitch_m;
        let f = spec.calibration.camera.fx * pitch;
        let s = focus_depth;
        let diameter = f * f * (s - s_f).abs() / (p.optics.f_number * s * (s_f - f));
        p.optics.defocus_radius_px = 0.5 * diameter / pitch;
    }
    if coarse_speckle {
        // A single-longitudinal-mode diode (0.05–0.3 nm) through a lens stopped down to
        // f/4–f/8 (depth of field): grains of 0.3–0.5 px σ, contrast 0.3–0.8.
        p.laser.spectral_width_m = uniform(&mut rng, 0.05e-9, 0.3e-9);
        p.optics.f_number = uniform(&mut rng, 4.0, 8.0);
        p.optics.psf_sigma_px = psf_sigma_px(
            p.optics.f_number,
            p.laser.wavelength_m,
            p.sensor.pixel_pitch_m,
        );
    }
    if noisy {
        // A cheaper global-shutter sensor: 40–60 e⁻ read noise, 0.5–2 % PRNU, 5–20 e⁻ row
        // noise.
        p.sensor.read_noise_e = uniform(&mut rng, 40.0, 60.0);
        p.sensor.prnu = uniform(&mut rng, 0.005, 0.02);
        p.sensor.row_noise_e = uniform(&mut rng, 5.0, 20.0);
    }
}

/// Depth (metres along the optical axis) of the first surface on the optical axis, or 2 m
/// when the axis sees nothing (the middle of the working range).
fn scene_depth_on_axis(spec: &SimSpec) -> f64 {
    let axis = tangent_core::real::Vec3::new(0.0, 0.0, 1.0);
    Scene::new(&spec.objects, spec.params.seed)
        .ok()
        .and_then(|s| s.intersect(tangent_core::real::Vec3::zeros(), axis, f64::INFINITY))
        .map_or(2.0, |h| h.point.z)
}
