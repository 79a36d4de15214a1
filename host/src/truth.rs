//! Ground truth: what a scene really holds, in the words both the capture format and the
//! simulator use.
//!
//! A synthetic or reference capture stores the exact scene (`[[truth.objects]]` in
//! `capture.toml`, the serde form of [`Object`]) and the exact laser curve
//! (`truth-curve.csv`, rows of [`TruthPoint`]); the simulator renders from the same types,
//! so the truth of a capture is exactly what was rendered. This module sits below both
//! [`crate::capture`] (which reads and writes it) and [`crate::simulate`] (which ray-casts
//! it): neither imports the other for it. Every object is given in the camera frame of the
//! laser-on frame (metres); `docs/formats.md` documents the keys.

use serde::{Deserialize, Serialize};

/// Procedural reflectance pattern of a surface (multiplies the albedo; geometry unaffected).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Texture {
    /// Uniform albedo.
    #[default]
    None,
    /// Bark: furrows along the axis (cylinders) — elongated value noise, darker grooves.
    Bark,
    /// Isotropic multi-scale noise (stone, concrete, plaster).
    Stone,
    /// Fine-grained isotropic noise (asphalt aggregate, ~5 mm grains).
    Asphalt,
}

fn default_albedo() -> f64 {
    0.3
}

fn default_contrast() -> f64 {
    0.5
}

/// A (possibly elliptic, possibly finite) cylinder: a stem or a branch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cylinder {
    /// A point on the axis (metres).
    pub axis_point_m: [f64; 3],
    /// Axis direction (normalised on use).
    pub axis_direction: [f64; 3],
    /// Radius of a circular section (metres). Give either this or `semi_axes_m`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<f64>,
    /// Semi-axes `(a, b)` of an elliptic section (metres); `a` lies along
    /// `major_axis_direction`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub semi_axes_m: Option<[f64; 2]>,
    /// Direction of the semi-axis `a` (made perpendicular to the axis on use). Required with
    /// `semi_axes_m`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub major_axis_direction: Option<[f64; 3]>,
    /// Axial extent `[s0, s1]` (metres along the axis from `axis_point_m`); absent = infinite.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extent_m: Option<[f64; 2]>,
    /// Lambertian albedo at 650 nm (0–1).
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// Reflectance pattern.
    #[serde(default)]
    pub texture: Texture,
    /// Depth of the pattern (0 = uniform, 1 = grooves black).
    #[serde(default = "default_contrast")]
    pub texture_contrast: f64,
}

/// A sphere.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sphere {
    /// Centre (metres).
    pub centre_m: [f64; 3],
    /// Radius (metres).
    pub radius_m: f64,
    /// Lambertian albedo at 650 nm.
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// Reflectance pattern.
    #[serde(default)]
    pub texture: Texture,
    /// Depth of the pattern.
    #[serde(default = "default_contrast")]
    pub texture_contrast: f64,
    /// A surface reflection besides the body's diffuse one (polished steel); absent = the
    /// scene's BRDF (`docs/sphere.md`, "Steel balls").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub specular: Option<SpecularLobe>,
    /// Factors along the camera's `x, y, z` that stretch the ball into an ellipsoid of
    /// semi-axes `radius_m·factor` (a non-sphere for the sphere test); absent = a sphere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stretch: Option<[f64; 3]>,
}

impl Sphere {
    /// The true diameter when the object is a sphere (not stretched).
    pub fn diameter_m(&self) -> Option<f64> {
        self.stretch
            .is_none_or(|f| f == [1.0; 3])
            .then_some(2.0 * self.radius_m)
    }
}

/// A specular lobe: `fraction` of the reflected light leaves in a normalised Blinn–Phong
/// lobe of exponent `exponent` about the mirror direction, the rest is the body's diffuse
/// reflection of the object's albedo (the simulator's `Reflectance::Glossy` for this object).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpecularLobe {
    /// Share of the reflected light in the lobe (steel at 650 nm: ≈ 0.55).
    pub fraction: f64,
    /// Blinn–Phong exponent (larger = sharper; a lobe of ≈ `1/√exponent` radians).
    pub exponent: f64,
}

/// An infinite plane (a wall, the ground).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plane {
    /// A point of the plane (metres).
    pub point_m: [f64; 3],
    /// Normal (normalised on use; either sign).
    pub normal: [f64; 3],
    /// Lambertian albedo at 650 nm.
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// Reflectance pattern.
    #[serde(default)]
    pub texture: Texture,
    /// Depth of the pattern.
    #[serde(default = "default_contrast")]
    pub texture_contrast: f64,
    /// The part of the plane that exists: inside this box `[min, max]` (metres, camera
    /// frame); absent = the whole plane. A wall ending at a door jamb or a corner.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounds_m: Option<[[f64; 3]; 2]>,
}

/// One sinusoidal component of a road profile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wave {
    /// Amplitude (metres).
    pub amplitude_m: f64,
    /// Wavelength (metres).
    pub wavelength_m: f64,
    /// Phase (radians).
    pub phase_rad: f64,
    /// Direction of the wave vector in the `x–y` plane, from `x` towards `y` (radians).
    pub direction_rad: f64,
}

/// A road surface facing the camera: `z = distance_m + Σ A·sin(2π(x cos φ + y sin φ)/λ + φ0)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Road {
    /// Mean distance of the surface along the optical axis (metres).
    pub distance_m: f64,
    /// The profile's components.
    pub waves: Vec<Wave>,
    /// Lambertian albedo at 650 nm.
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// Reflectance pattern.
    #[serde(default)]
    pub texture: Texture,
    /// Depth of the pattern.
    #[serde(default = "default_contrast")]
    pub texture_contrast: f64,
}

/// A planar chessboard calibration target: a finite rectangle of `(cols + 1) × (rows + 1)`
/// alternating dark and light squares with a light border (`docs/simulator.md`, "Scene").
///
/// Board frame: inner corner `(i, j)` is at `origin_m + s·i·x + s·j·y` (`s` = `square_m`,
/// `x`, `y` the unit axes), the same convention as `calibrate::Board::point`, so a capture's
/// truth gives the board pose directly. Square `(a, b) = (⌊X/s⌋, ⌊Y/s⌋)`,
/// `a ∈ −1..=cols−1`, `b ∈ −1..=rows−1`, is dark when `a + b` is even (the corner square
/// `(−1, −1)` is dark, as on OpenCV's pattern).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Board {
    /// Position of inner corner `(0, 0)` (metres).
    pub origin_m: [f64; 3],
    /// Direction of the board's `x` axis, along the `cols` inner corners (normalised on use).
    pub x_axis: [f64; 3],
    /// Direction of the board's `y` axis (made perpendicular to `x_axis` on use).
    pub y_axis: [f64; 3],
    /// Side of one square (metres).
    pub square_m: f64,
    /// Inner corners `[cols, rows]` (`[9, 6]` is OpenCV's 10 × 7-square pattern).
    pub inner_corners: [usize; 2],
    /// Width of the light border around the squares (metres).
    pub border_m: f64,
    /// Albedo of the light squares and the border at 650 nm.
    #[serde(default = "default_board_light")]
    pub albedo: f64,
    /// Albedo of the dark squares (printer black ≈ 0.05).
    #[serde(default = "default_board_dark")]
    pub dark_albedo: f64,
}

fn default_board_light() -> f64 {
    0.8
}

fn default_board_dark() -> f64 {
    0.05
}

/// A scene object (`kind = "cylinder" | "sphere" | "plane" | "road" | "board"` in TOML).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Object {
    /// A stem or branch.
    Cylinder(Cylinder),
    /// A sphere.
    Sphere(Sphere),
    /// A plane.
    Plane(Plane),
    /// A road surface.
    Road(Road),
    /// A chessboard calibration target.
    Board(Board),
    /// A flat disc (the end face of a finite cylinder).
    Disc(Disc),
}

/// A flat disc: the end face that closes a finite cylinder (a cylpeb's end).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Disc {
    /// Centre (metres).
    pub centre_m: [f64; 3],
    /// Normal (normalised on use; either sign).
    pub normal: [f64; 3],
    /// Radius (metres).
    pub radius_m: f64,
    /// Lambertian albedo at 650 nm.
    #[serde(default = "default_albedo")]
    pub albedo: f64,
    /// Reflectance pattern.
    #[serde(default)]
    pub texture: Texture,
    /// Depth of the pattern.
    #[serde(default = "default_contrast")]
    pub texture_contrast: f64,
}

/// One point of the true laser curve (a row of the capture's `truth-curve.csv`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthPoint {
    /// Laser plane index.
    pub plane: usize,
    /// Image column `u` (the curve is sampled at pixel-centre columns).
    pub column: u32,
    /// Subpixel row `v` of the curve's centre in that column (pixels).
    pub row_px: f64,
    /// The 3-D point on the object (camera frame, metres).
    pub point_m: [f64; 3],
    /// Index of the lit object in `truth.objects`.
    pub object: usize,
}

/// Name of the physics a synthetic capture was rendered with (`docs/simulator.md`,
/// "Physics models"): a label over the photometric parameters of the `[simulation]` table
/// (reflectance, sheet profile, PSF, speckle, bark texture scale, sensor noise), recorded in
/// `[truth]` so an evaluation can group its captures by it. The geometry never depends on it.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default, Serialize, Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum PhysicsModel {
    /// Lambertian surfaces, Gaussian sheet, Gaussian PSF, fine speckle, the MT9V034's noise.
    #[default]
    Reference,
    /// Rough diffuse bark (Oren–Nayar), coarser or finer bark texture.
    OrenNayarBark,
    /// Wet or smooth bark: a Lambertian body plus a specular lobe.
    SpecularSheen,
    /// A flat-topped (super-Gaussian) sheet cross profile.
    FlatTopSheet,
    /// A defocused lens: a uniform blur disc on top of the Gaussian PSF.
    Defocus,
    /// A narrow-linewidth laser through a stopped-down lens: high-contrast, coarse speckle.
    CoarseSpeckle,
    /// A noisier sensor: more read noise, pixel response non-uniformity, row noise.
    NoisySensor,
    /// Every aspect above drawn independently (reference or alternative).
    Mixed,
}

impl PhysicsModel {
    /// Every model, in table order.
    pub const ALL: [PhysicsModel; 8] = [
        PhysicsModel::Reference,
        PhysicsModel::OrenNayarBark,
        PhysicsModel::SpecularSheen,
        PhysicsModel::FlatTopSheet,
        PhysicsModel::Defocus,
        PhysicsModel::CoarseSpeckle,
        PhysicsModel::NoisySensor,
        PhysicsModel::Mixed,
    ];

    /// The snake-case name used in `capture.toml` and the tables.
    pub fn name(self) -> &'static str {
        match self {
            PhysicsModel::Reference => "reference",
            PhysicsModel::OrenNayarBark => "oren_nayar_bark",
            PhysicsModel::SpecularSheen => "specular_sheen",
            PhysicsModel::FlatTopSheet => "flat_top_sheet",
            PhysicsModel::Defocus => "defocus",
            PhysicsModel::CoarseSpeckle => "coarse_speckle",
            PhysicsModel::NoisySensor => "noisy_sensor",
            PhysicsModel::Mixed => "mixed",
        }
    }

    /// The model of that name, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}
