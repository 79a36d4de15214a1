//! Surface reflectance models (BRDFs) of the physics models (`docs/simulator.md`,
//! "Physics models"): Lambertian, Oren–Nayar rough diffuse, and a Lambertian body with a
//! normalised Blinn–Phong specular lobe. Each is given as `π·f_r` ("albedo-like", so a
//! Lambertian surface of albedo `ρ` returns `ρ`) and multiplies the irradiance `E·cos ι`.

use serde::{Deserialize, Serialize};
use tangent_core::real::Vec3;

/// The BRDF shared by every surface of a scene; the object's (textured) albedo scales it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Reflectance {
    /// `f_r = ρ/π`.
    #[default]
    Lambertian,
    /// Oren–Nayar (1994, qualitative model): V-cavity microfacets with Gaussian slope
    /// distribution of RMS `sigma_rad`; brighter towards retro-reflection, flatter than
    /// Lambert towards the limb.
    OrenNayar {
        /// RMS facet slope angle (radians); bark ≈ 0.3–0.6.
        sigma_rad: f64,
    },
    /// `f_r = (1 − k_s)·ρ/π + k_s·(m + 8)/(8π)·cos^m θ_h` (a water film or polished bark: a
    /// dielectric surface reflection whose strength does not follow the body albedo).
    Glossy {
        /// Share `k_s` of the reflected energy in the lobe.
        specular_fraction: f64,
        /// Blinn–Phong exponent `m` (larger = sharper).
        exponent: f64,
    },
}

impl Reflectance {
    /// True for the Lambertian model (the default, not written to `capture.toml`).
    pub fn is_lambertian(&self) -> bool {
        *self == Reflectance::Lambertian
    }

    /// `π·f_r(l, v)` for a surface of albedo `rho` with unit normal `n`, unit direction
    /// `l` towards the light and unit direction `v` towards the viewer (0 when either is
    /// behind the surface).
    pub fn pi_brdf(&self, rho: f64, n: Vec3, l: Vec3, v: Vec3) -> f64 {
        let (cos_i, cos_r) = (n.dot(&l), n.dot(&v));
        if cos_i <= 0.0 || cos_r <= 0.0 {
            return 0.0;
        }
        match *self {
            Reflectance::Lambertian => rho,
            Reflectance::OrenNayar { sigma_rad } => {
                let s2 = sigma_rad * sigma_rad;
                let a = 1.0 - 0.5 * s2 / (s2 + 0.33);
                let b = 0.45 * s2 / (s2 + 0.09);
                let (theta_i, theta_r) = (cos_i.min(1.0).acos(), cos_r.min(1.0).acos());
                let (alpha, beta) = (theta_i.max(theta_r), theta_i.min(theta_r));
                // cos(φ_r − φ_i): the azimuths are the tangent-plane projections of l and v.
                let (lt, vt) = (l - n * cos_i, v - n * cos_r);
                let norms = lt.norm() * vt.norm();
                let cos_phi = if norms > 1e-12 {
                    lt.dot(&vt) / norms
                } else {
                    0.0
                };
                rho * (a + b * cos_phi.max(0.0) * alpha.sin() * beta.tan())
            }
            Reflectance::Glossy {
                specular_fraction: ks,
                exponent: m,
            } => {
                let h = (l + v).normalize();
                let cos_h = n.dot(&h).max(0.0);
                (1.0 - ks) * rho + ks * (m + 8.0) / 8.0 * cos_h.powf(m)
            }
        }
    }

    /// `π·f_r` averaged over a uniform sky (the diffuse ambient term): the body albedo, plus
    /// for the glossy model the lobe's share (its hemispherical reflectance is ≈ 1, so a
    /// uniform sky adds `k_s`). Oren–Nayar under a uniform sky is taken as Lambertian (the
    /// retro-reflective excess and the limb deficit average out to within a few %).
    pub fn diffuse_factor(&self, rho: f64) -> f64 {
        match *self {
            Reflectance::Lambertian | Reflectance::OrenNayar { .. } => rho,
            Reflectance::Glossy {
                specular_fraction: ks,
                ..
            } => (1.0 - ks) * rho + ks,
        }
    }
}
