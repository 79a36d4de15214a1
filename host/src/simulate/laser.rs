//! The line laser: a Gaussian sheet of light fanned from its source point
//! (`docs/simulator.md`, "Laser").

// `!(x > 0.0)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use serde::{Deserialize, Serialize};
use tangent_core::laser_plane::LaserPlane;
use tangent_core::real::Vec3;

/// Parameters of every line laser of the device (all planes are alike).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaserParams {
    /// Wavelength (metres); sets the speckle size.
    pub wavelength_m: f64,
    /// Optical power of each laser (watts). Class 2 is ≤ 1 mW.
    pub power_w: f64,
    /// Full fan angle (radians); the power is spread uniformly over it (Powell lens).
    pub fan_angle_rad: f64,
    /// `1/e²` half-thickness of the sheet at its waist (metres).
    pub waist_half_width_m: f64,
    /// Growth of the half-thickness with distance from the waist (radians):
    /// `w(r) = √(w0² + (θ·(r − r_w))²)`.
    pub divergence_rad: f64,
    /// Distance `r_w` from the source to the waist (metres): 0 for a collimated module (the
    /// default, not written to `capture.toml`), the working distance for a line focused there
    /// (the road head, `docs/hardware.md`, "Road head").
    #[serde(default, skip_serializing_if = "is_zero")]
    pub waist_distance_m: f64,
    /// Spectral width (metres); with the surface roughness it reduces the speckle contrast
    /// ([`super::sensor::spectral_speckle_contrast`]).
    pub spectral_width_m: f64,
    /// Shape of the sheet's cross profile (Gaussian unless given).
    #[serde(default, skip_serializing_if = "SheetProfile::is_gaussian")]
    pub profile: SheetProfile,
}

/// Cross profile of the light sheet, at the `1/e²` half-width `w(r)` (`docs/simulator.md`,
/// "Physics models").
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum SheetProfile {
    /// `exp(−2 s²/w²)`: a single-transverse-mode beam focused by a cylindrical lens.
    #[default]
    Gaussian,
    /// Super-Gaussian `exp(−2 |s/w|^order)`, `order` > 2: the flat-topped thickness profile
    /// of a multimode diode's slow axis or of a top-hat line generator.
    FlatTop {
        /// Exponent (2 = Gaussian; 4–10 flat-topped).
        order: f64,
    },
}

/// True for a waist at the source (serde's `skip_serializing_if`).
fn is_zero(value: &f64) -> bool {
    *value == 0.0
}

impl SheetProfile {
    /// True for the Gaussian profile (the default, not written to `capture.toml`).
    pub fn is_gaussian(&self) -> bool {
        *self == SheetProfile::Gaussian
    }

    /// Line density of the profile at signed distance `s` from the plane for half-width `w`,
    /// normalised to unit integral over `s`: Gaussian `√(2/π)/w · exp(−2s²/w²)`; super-Gaussian
    /// `exp(−2|s/w|^p) / (2w·Γ(1 + 1/p)·2^(−1/p))` (the same formula, `p = 2`).
    pub fn density(&self, s: f64, w: f64) -> f64 {
        match *self {
            SheetProfile::Gaussian => {
                (2.0 / std::f64::consts::PI).sqrt() / w * (-2.0 * s * s / (w * w)).exp()
            }
            SheetProfile::FlatTop { order: p } => {
                let norm = 2.0 * w * libm::tgamma(1.0 + 1.0 / p) * 2f64.powf(-1.0 / p);
                (-2.0 * (s / w).abs().powf(p)).exp() / norm
            }
        }
    }
}

impl Default for LaserParams {
    /// A 1 mW, 650 nm line laser with a 45° Powell fan (covers the 41° horizontal field of
    /// the reference camera from 0.1 m below it), 0.6 mm waist and 1 mrad thickness
    /// divergence: `w` = 1.2 mm at 1 m, 3.1 mm at 3 m — the "1–3 mm line" of datasheets;
    /// 1 nm spectral width (a multimode diode).
    fn default() -> Self {
        LaserParams {
            wavelength_m: 650e-9,
            power_w: 1e-3,
            fan_angle_rad: 45f64.to_radians(),
            waist_half_width_m: 0.6e-3,
            divergence_rad: 1e-3,
            waist_distance_m: 0.0,
            spectral_width_m: 1e-9,
            profile: SheetProfile::Gaussian,
        }
    }
}

impl LaserParams {
    /// `1/e²` half-thickness at distance `r` from the source (metres).
    pub fn half_width(&self, r: f64) -> f64 {
        let from_waist = r - self.waist_distance_m;
        (self.waist_half_width_m.powi(2) + (self.divergence_rad * from_waist).powi(2)).sqrt()
    }

    /// Irradiance (W/m²) the laser of `plane` puts on a surface at `p` with unit normal
    /// `normal`, ignoring occlusion (the caller checks the segment to the source):
    ///
    /// ```text
    /// E = P/(θ_fan·r) · √(2/π)/w(r) · exp(−2 s²/w(r)²) · cos ι
    /// ```
    ///
    /// (Gaussian sheet; [`SheetProfile::density`] replaces the middle factor for others)
    ///
    /// with `r = |p − S|`, `s` the signed distance from the plane, `ι` the incidence angle
    /// (`docs/simulator.md`, "Laser irradiance"). Zero outside the fan, behind the surface,
    /// and beyond `5 w` from the plane (`exp(−50)` ≈ 2e-22: nothing).
    pub fn irradiance(&self, plane: &LaserPlane, p: Vec3, normal: Vec3) -> f64 {
        let to_source = plane.source - p;
        let r = to_source.norm();
        if !(r > 1e-6) {
            return 0.0;
        }
        let cos_inc = normal.dot(&to_source) / r;
        if cos_inc <= 0.0 {
            return 0.0;
        }
        let w = self.half_width(r);
        let s = plane.signed_distance(p);
        if s.abs() > 5.0 * w {
            return 0.0;
        }
        if !self.in_fan(plane, p) {
            return 0.0;
        }
        let line_density = self.power_w / (self.fan_angle_rad * r);
        line_density * self.profile.density(s, w) * cos_inc
    }

    /// True when `p` (projected onto the plane) is inside the fan: the angle from the fan's
    /// central direction (the in-plane depth axis `b` of [`LaserPlane::plane_axes`]) is at
    /// most half the fan angle.
    pub fn in_fan(&self, plane: &LaserPlane, p: Vec3) -> bool {
        let q = plane.to_plane_coords(p);
        q.y > 0.0 && q.x.atan2(q.y).abs() <= 0.5 * self.fan_angle_rad
    }
}
