//! The calibration file: a TOML mirror of [`tangent_core::calibration::Calibration`].
//!
//! Units are in the key names (`fx_px`, `offset_m`, `source_m`), so a file read by a person
//! cannot be misread; unknown keys are rejected (a misspelt `k1` must not silently become
//! zero distortion). The layout, documented in `docs/formats.md`:
//!
//! ```toml
//! id = 0
//!
//! [camera]
//! width_px = 752
//! height_px = 480
//! fx_px = 1000.0
//! fy_px = 1000.0
//! cx_px = 375.5
//! cy_px = 239.5
//!
//! [camera.distortion]          # OpenCV (k1, k2, p1, p2, k3), dimensionless; optional
//! k1 = 0.0
//! k2 = 0.0
//! k3 = 0.0
//! p1 = 0.0
//! p2 = 0.0
//!
//! [[planes]]                   # plane i is lit by laser output i; n·X = offset
//! normal = [0.0, 0.99778, 0.06652]
//! offset_m = 0.099778
//! source_m = [0.0, 0.1, 0.0]
//!
//! [planes_uncertainty]         # `tangent calibrate ball|wall`; optional (docs/calibration.md §14)
//! sigma = [2.0e-4, 1.9e-4, 2.0e-4, 1.9e-4]      # 1σ of e₀ (m), δ₀ (rad), e₁, δ₁, …
//! correlation = [[1.0, 0.1, 0.9, 0.1], [0.1, 1.0, 0.1, 0.95], [0.9, 0.1, 1.0, 0.1], [0.1, 0.95, 0.1, 1.0]]
//!
//! [road]                       # road head only: piezo height-scale calibration; optional
//! height_scale = 0.9901
//!
//! [accelerometer]              # `tangent calibrate accelerometer`; optional
//! bias_m_s2 = [0.21, -0.13, 0.05]
//! bias_sigma_m_s2 = [1.5e-4, 1.4e-4, 1.3e-4]
//! camera_from_sensor_rad = [0.012, -0.004, 0.017]
//! alignment_sigma_rad = [9e-5, 8e-5, 1.1e-4]
//! scale = 1.0021
//! scale_sigma = 2e-5
//! residual_rms_m_s2 = 2.4e-3
//! poses = 12
//! ```

// `Real` is f64 on the host, but the casts keep this file correct if it ever is not.
#![allow(clippy::unnecessary_cast)]

use std::path::Path;

use serde::{Deserialize, Serialize};
use tangent_core::calibration::{
    Calibration, CalibrationError, PlanesUncertainty, UncertaintyError, MAX_PLANES,
};
use tangent_core::camera::{Camera, Distortion};
use tangent_core::laser_plane::LaserPlane;
use tangent_core::real::{Real, Vec3};

/// Why a calibration file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationFileError {
    /// A key the format does not define (often a typo).
    #[error("unknown key `{key}`{}", at(.line))]
    UnknownKey {
        /// The key.
        key: String,
        /// 1-based line of the key in the file, when known.
        line: Option<usize>,
    },
    /// A required key is absent.
    #[error("missing key `{key}`{}", at(.line))]
    MissingKey {
        /// The key.
        key: String,
        /// 1-based line of the enclosing table, when known.
        line: Option<usize>,
    },
    /// No `[[planes]]` entry: a calibration needs at least one laser plane.
    #[error("the calibration has no laser plane (add at least one [[planes]] table)")]
    MissingPlanes,
    /// More `[[planes]]` than the core holds.
    #[error("the calibration has {0} laser planes, at most {MAX_PLANES} are supported")]
    TooManyPlanes(usize),
    /// The TOML is malformed or a value has the wrong type.
    #[error("calibration TOML{}: {message}", at(.line))]
    Syntax {
        /// The parser's message.
        message: String,
        /// 1-based line, when known.
        line: Option<usize>,
    },
    /// A value outside its physical range (the message names the key).
    #[error(transparent)]
    OutOfRange(#[from] crate::calibration_bounds::OutOfRange),
    /// The values parse but do not form a valid calibration (e.g. a normal of zero length).
    #[error("invalid calibration: {0}")]
    Invalid(CalibrationError),
    /// `[planes_uncertainty]` is not a covariance of the planes' `(e, δ)`.
    #[error("[planes_uncertainty]: {0}")]
    Uncertainty(UncertaintyError),
    /// The file could not be read or written (always inside [`CalibrationFileError::File`],
    /// which names it).
    #[error("{0}")]
    Io(std::io::Error),
    /// An error of a calibration file, naming the file: every error of [`read`],
    /// [`read_camera`] and [`write()`] is one, so a message always says which file.
    #[error("{path}: {error}")]
    File {
        /// The file.
        path: String,
        /// What is wrong with it.
        error: Box<CalibrationFileError>,
    },
}

/// Wraps an error of the file at `path` so that its message names the file.
fn in_file(path: &Path) -> impl FnOnce(CalibrationFileError) -> CalibrationFileError + '_ {
    move |error| CalibrationFileError::File {
        path: path.display().to_string(),
        error: Box::new(error),
    }
}

/// Reads a file's text; the error names the file.
fn read_text(path: &Path) -> Result<String, CalibrationFileError> {
    std::fs::read_to_string(path)
        .map_err(CalibrationFileError::Io)
        .map_err(in_file(path))
}

fn at(line: &Option<usize>) -> String {
    line.map(|l| format!(" (line {l})")).unwrap_or_default()
}

/// `[camera.distortion]`: OpenCV's Brown–Conrady coefficients (dimensionless).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DistortionToml {
    /// Radial `r²` coefficient.
    #[serde(default)]
    pub k1: f64,
    /// Radial `r⁴` coefficient.
    #[serde(default)]
    pub k2: f64,
    /// Radial `r⁶` coefficient.
    #[serde(default)]
    pub k3: f64,
    /// Tangential coefficient `p1`.
    #[serde(default)]
    pub p1: f64,
    /// Tangential coefficient `p2`.
    #[serde(default)]
    pub p2: f64,
}

/// `[camera]`: intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraToml {
    /// Image width (pixels).
    pub width_px: u32,
    /// Image height (pixels).
    pub height_px: u32,
    /// Focal length along `u` (pixels).
    pub fx_px: f64,
    /// Focal length along `v` (pixels).
    pub fy_px: f64,
    /// Principal point `u` (pixels).
    pub cx_px: f64,
    /// Principal point `v` (pixels).
    pub cy_px: f64,
    /// Lens distortion; absent means none.
    #[serde(default)]
    pub distortion: DistortionToml,
}

/// One `[[planes]]` entry: `normal·X = offset_m` in the camera frame, with the laser's
/// emission point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaneToml {
    /// Plane normal (normalised on reading; the sign is made to give a positive offset).
    #[serde(deserialize_with = "three")]
    pub normal: [f64; 3],
    /// Distance from the camera centre to the plane along `normal` (metres).
    pub offset_m: f64,
    /// Laser emission point (fan apex), camera frame (metres).
    #[serde(deserialize_with = "three")]
    pub source_m: [f64; 3],
}

/// The whole calibration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationToml {
    /// Calibration identifier (unit serial or calibration run).
    pub id: u32,
    /// The camera.
    pub camera: CameraToml,
    /// The laser planes, in the order of the laser outputs. Required, at least one
    /// (defaulted to empty here only so that its absence gives [`CalibrationFileError::MissingPlanes`];
    /// a camera-only file, [`parse_camera`], has none and does not write the key).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub planes: Vec<PlaneToml>,
    /// The planes' `(e, δ)` covariance from a refinement on a reference
    /// (`tangent calibrate ball` / `wall`); absent for independent board-calibrated planes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub planes_uncertainty: Option<PlanesUncertaintyToml>,
    /// The road head's height-scale calibration (`docs/road.md`); absent on other heads.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub road: Option<RoadToml>,
    /// The accelerometer's calibration (`docs/hardware.md`, "Accelerometer calibration");
    /// absent on a device without one or not yet calibrated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accelerometer: Option<AccelerometerToml>,
}

/// `[planes_uncertainty]`: the 1σ of `e₀, δ₀, e₁, δ₁, …` (metres, radians) and their
/// correlation matrix ([`PlanesUncertainty`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanesUncertaintyToml {
    /// 1σ of each parameter.
    pub sigma: Vec<f64>,
    /// Correlation, one row per parameter.
    pub correlation: Vec<Vec<f64>>,
}

impl PlanesUncertaintyToml {
    /// The table of a core covariance.
    pub fn from_uncertainty(u: &PlanesUncertainty) -> Self {
        let n = u.sigmas().len();
        PlanesUncertaintyToml {
            sigma: u.sigmas().iter().map(|&s| s as f64).collect(),
            correlation: (0..n)
                .map(|i| (0..n).map(|j| u.correlation(i, j) as f64).collect())
                .collect(),
        }
    }

    /// The core covariance, validated; a ragged matrix is refused by its shape.
    pub fn to_uncertainty(&self) -> Result<PlanesUncertainty, CalibrationFileError> {
        let n = self.sigma.len();
        let entries: usize = self.correlation.iter().map(Vec::len).sum();
        if self.correlation.len() != n || self.correlation.iter().any(|row| row.len() != n) {
            return Err(CalibrationFileError::Uncertainty(
                UncertaintyError::CorrelationShape {
                    expected: n * n,
                    got: entries,
                },
            ));
        }
        let sigma: Vec<Real> = self.sigma.iter().map(|&s| s as Real).collect();
        let flat: Vec<Real> = self
            .correlation
            .iter()
            .flatten()
            .map(|&r| r as Real)
            .collect();
        PlanesUncertainty::new(&sigma, &flat).map_err(CalibrationFileError::Uncertainty)
    }
}

/// `[accelerometer]`: bias, scale and the rotation of the sensor's axes into the camera
/// frame, with their 1σ (`tangent_core::accelerometer::AccelCalibration`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelerometerToml {
    /// Bias (sensor axes, m/s²).
    #[serde(deserialize_with = "three")]
    pub bias_m_s2: [f64; 3],
    /// 1σ of the bias per axis (m/s²).
    #[serde(deserialize_with = "three")]
    pub bias_sigma_m_s2: [f64; 3],
    /// Rotation from the sensor's axes into the camera frame (rotation vector, radians).
    #[serde(deserialize_with = "three")]
    pub camera_from_sensor_rad: [f64; 3],
    /// 1σ of that rotation about each camera axis (radians).
    #[serde(deserialize_with = "three")]
    pub alignment_sigma_rad: [f64; 3],
    /// Common scale of the readings (1 for a perfect sensor under standard gravity).
    pub scale: f64,
    /// 1σ of the scale.
    pub scale_sigma: f64,
    /// RMS residual of the poses (m/s²).
    pub residual_rms_m_s2: f64,
    /// Poses the calibration was made from.
    pub poses: usize,
}

impl AccelerometerToml {
    /// The table of a calibration result.
    pub fn from_calibration(c: &tangent_core::accelerometer::AccelCalibration) -> Self {
        AccelerometerToml {
            bias_m_s2: a3(c.bias_m_s2),
            bias_sigma_m_s2: a3(c.bias_sigma_m_s2),
            camera_from_sensor_rad: a3(c.camera_from_sensor_rad),
            alignment_sigma_rad: a3(c.alignment_sigma_rad),
            scale: c.scale as f64,
            scale_sigma: c.scale_sigma as f64,
            residual_rms_m_s2: c.rms_m_s2 as f64,
            poses: c.poses,
        }
    }
}

/// The `[accelerometer]` table of a calibration file, if any; errors name the file.
pub fn read_accelerometer(path: &Path) -> Result<Option<AccelerometerToml>, CalibrationFileError> {
    let text = read_text(path)?;
    let file: CalibrationToml = toml::from_str(&text)
        .map_err(|e| map_toml_error(&e, &text))
        .map_err(in_file(path))?;
    Ok(file.accelerometer)
}

/// Writes `accelerometer` as the `[accelerometer]` table of an existing calibration file,
/// every other key kept; errors name the file.
pub fn write_accelerometer(
    path: &Path,
    accelerometer: &AccelerometerToml,
) -> Result<(), CalibrationFileError> {
    update_file(path, |file| {
        file.accelerometer = Some(accelerometer.clone())
    })
}

/// Writes `calibration`'s laser planes as the `[[planes]]` of an existing calibration file,
/// with their `[planes_uncertainty]` (removed when `calibration` has none), every other key
/// (camera, id, `[road]`, `[accelerometer]`) kept; errors name the file.
pub fn write_planes(path: &Path, calibration: &Calibration) -> Result<(), CalibrationFileError> {
    let CalibrationToml {
        planes,
        planes_uncertainty,
        ..
    } = CalibrationToml::from_calibration(calibration);
    update_file(path, |file| {
        file.planes = planes;
        file.planes_uncertainty = planes_uncertainty;
    })
}

/// Reads the calibration file at `path`, changes it with `change` and writes it back, after
/// checking that what is written reads back (so a file that would not is never left behind).
fn update_file(
    path: &Path,
    change: impl FnOnce(&mut CalibrationToml),
) -> Result<(), CalibrationFileError> {
    let text = read_text(path)?;
    let mut file: CalibrationToml = toml::from_str(&text)
        .map_err(|e| map_toml_error(&e, &text))
        .map_err(in_file(path))?;
    change(&mut file);
    let out = toml::to_string(&file)
        .map_err(|e| CalibrationFileError::Syntax {
            message: e.to_string(),
            line: None,
        })
        .map_err(in_file(path))?;
    parse_road(&out).map_err(in_file(path))?;
    std::fs::write(path, out)
        .map_err(CalibrationFileError::Io)
        .map_err(in_file(path))
}

/// `[road]`: the result of the piezo-stage height-scale calibration of a road head
/// (`docs/road.md`, "Height-scale calibration").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoadToml {
    /// Factor every road height is multiplied by (`1 / gain` of the fit).
    pub height_scale: f64,
    /// RMS of the fit's residuals (metres).
    #[serde(default)]
    pub residual_rms_m: f64,
    /// Steps the stage made.
    #[serde(default)]
    pub steps: usize,
    /// The stage's known positions (metres), in the order measured.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub step_positions_m: Vec<f64>,
    /// Residual of each position after the fitted line (metres).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub residuals_m: Vec<f64>,
}

/// Accepted range of `road.height_scale`: a head whose heights are off by more than 20 % is
/// mis-built or mis-calibrated, not corrected.
pub const HEIGHT_SCALE_RANGE: (f64, f64) = (0.8, 1.25);

/// The `[road]` table of a calibration file's text, if any, checked (`height_scale` within
/// [`HEIGHT_SCALE_RANGE`]).
pub fn parse_road(text: &str) -> Result<Option<RoadToml>, CalibrationFileError> {
    let file: CalibrationToml = toml::from_str(text).map_err(|e| map_toml_error(&e, text))?;
    if let Some(r) = &file.road {
        let (lo, hi) = HEIGHT_SCALE_RANGE;
        if !(lo..=hi).contains(&r.height_scale) {
            return Err(CalibrationFileError::Syntax {
                message: format!(
                    "road.height_scale = {} is outside {lo}–{hi} (a head this far off is mis-built, not corrected)",
                    r.height_scale
                ),
                line: None,
            });
        }
    }
    Ok(file.road)
}

/// Reads the `[road]` table of a calibration file ([`parse_road`]); errors name the file.
pub fn read_road(path: &Path) -> Result<Option<RoadToml>, CalibrationFileError> {
    parse_road(&read_text(path)?).map_err(in_file(path))
}

/// Writes `road` as the `[road]` table of an existing calibration file, every other key kept;
/// errors name the file.
pub fn write_road(path: &Path, road: &RoadToml) -> Result<(), CalibrationFileError> {
    update_file(path, |file| file.road = Some(road.clone()))
}

/// A 3-vector that must have exactly three components: serde's fixed-size array impl reads
/// the first three elements of a longer TOML array and ignores the rest, which would let
/// `normal = [0, 1, 0, 5]` pass silently.
fn three<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    let v = Vec::<f64>::deserialize(d)?;
    <[f64; 3]>::try_from(v.as_slice())
        .map_err(|_| serde::de::Error::invalid_length(v.len(), &"an array of 3 numbers"))
}

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0] as Real, a[1] as Real, a[2] as Real)
}

fn a3(v: Vec3) -> [f64; 3] {
    [v.x as f64, v.y as f64, v.z as f64]
}

impl CalibrationToml {
    /// Mirror of a core calibration.
    pub fn from_calibration(c: &Calibration) -> Self {
        let d = c.camera.distortion;
        CalibrationToml {
            id: c.id,
            camera: CameraToml {
                width_px: c.camera.width,
                height_px: c.camera.height,
                fx_px: c.camera.fx as f64,
                fy_px: c.camera.fy as f64,
                cx_px: c.camera.cx as f64,
                cy_px: c.camera.cy as f64,
                distortion: DistortionToml {
                    k1: d.k1 as f64,
                    k2: d.k2 as f64,
                    k3: d.k3 as f64,
                    p1: d.p1 as f64,
                    p2: d.p2 as f64,
                },
            },
            planes: c
                .planes
                .iter()
                .map(|p| PlaneToml {
                    normal: a3(p.normal),
                    offset_m: p.offset as f64,
                    source_m: a3(p.source),
                })
                .collect(),
            planes_uncertainty: c
                .uncertainty
                .as_ref()
                .map(PlanesUncertaintyToml::from_uncertainty),
            road: None,
            accelerometer: None,
        }
    }

    /// The core calibration, validated ([`Calibration::new`]: normals normalised, sources
    /// projected onto their planes within tolerance, camera checked).
    pub fn to_calibration(&self) -> Result<Calibration, CalibrationFileError> {
        if self.planes.is_empty() {
            return Err(CalibrationFileError::MissingPlanes);
        }
        if self.planes.len() > MAX_PLANES {
            return Err(CalibrationFileError::TooManyPlanes(self.planes.len()));
        }
        let camera = self.camera.unchecked_camera();
        let mut planes = Vec::with_capacity(self.planes.len());
        for (index, p) in self.planes.iter().enumerate() {
            let plane = LaserPlane::new(v3(p.normal), p.offset_m as Real, v3(p.source_m)).map_err(
                |error| CalibrationFileError::Invalid(CalibrationError::Plane { index, error }),
            )?;
            // What the core accepts is then held to physical ranges (the key named).
            crate::calibration_bounds::check_plane(
                index,
                v3(p.normal),
                p.offset_m as f64,
                v3(p.source_m),
            )?;
            planes.push(plane);
        }
        let mut calibration =
            Calibration::new(self.id, camera, &planes).map_err(CalibrationFileError::Invalid)?;
        if let Some(u) = &self.planes_uncertainty {
            calibration =
                calibration
                    .with_uncertainty(u.to_uncertainty()?)
                    .map_err(|e| match e {
                        CalibrationError::Uncertainty(e) => CalibrationFileError::Uncertainty(e),
                        e => CalibrationFileError::Invalid(e),
                    })?;
        }
        crate::calibration_bounds::check_camera(&calibration.camera)?;
        Ok(calibration)
    }
}

impl CameraToml {
    /// The core camera as written, not yet validated (the caller validates it, in the order
    /// its own errors are reported).
    fn unchecked_camera(&self) -> Camera {
        let d = self.distortion;
        Camera {
            width: self.width_px,
            height: self.height_px,
            fx: self.fx_px as Real,
            fy: self.fy_px as Real,
            cx: self.cx_px as Real,
            cy: self.cy_px as Real,
            distortion: Distortion {
                k1: d.k1 as Real,
                k2: d.k2 as Real,
                k3: d.k3 as Real,
                p1: d.p1 as Real,
                p2: d.p2 as Real,
            },
        }
    }

    /// The core camera, validated (`Camera::validate`: positive focal lengths, distortion
    /// one-to-one over the image).
    pub fn to_camera(&self) -> Result<Camera, CalibrationFileError> {
        let camera = self.unchecked_camera();
        camera
            .validate()
            .map_err(|e| CalibrationFileError::Invalid(CalibrationError::Camera(e)))?;
        crate::calibration_bounds::check_camera(&camera)?;
        Ok(camera)
    }
}

/// The camera part of a calibration file: `id` and `[camera]`, with or without
/// `[[planes]]` (`docs/formats.md`, "Camera-only calibration"). This is what
/// `tangent calibrate camera` writes before the laser planes are calibrated, and what
/// `tangent calibrate laser --camera FILE` reads; planes present are parsed and validated
/// too (a broken file is rejected, not half-read) and returned as they are.
pub fn parse_camera(text: &str) -> Result<(u32, Camera, Vec<PlaneToml>), CalibrationFileError> {
    let file: CalibrationToml = toml::from_str(text).map_err(|e| map_toml_error(&e, text))?;
    let camera = file.camera.to_camera()?;
    if !file.planes.is_empty() {
        file.to_calibration()?;
    }
    Ok((file.id, camera, file.planes))
}

/// Reads a camera-only (or complete) calibration file; see [`parse_camera`]. Every error
/// names the file.
pub fn read_camera(path: &Path) -> Result<(u32, Camera, Vec<PlaneToml>), CalibrationFileError> {
    parse_camera(&read_text(path)?).map_err(in_file(path))
}

/// Maps a `toml` deserialisation error to the precise variants.
///
/// serde reports unknown and missing fields only as messages (`unknown field `x`, expected
/// …` / `missing field `x``); the key is the text between the first pair of backticks.
pub(crate) fn map_toml_error(err: &toml::de::Error, text: &str) -> CalibrationFileError {
    let message = err.message().to_string();
    let line = err
        .span()
        .map(|s| text.get(..s.start).map_or(0, |t| t.matches('\n').count()) + 1);
    let key = || message.split('`').nth(1).unwrap_or("").to_string();
    if message.starts_with("unknown field") {
        CalibrationFileError::UnknownKey { key: key(), line }
    } else if message.starts_with("missing field") {
        CalibrationFileError::MissingKey { key: key(), line }
    } else {
        CalibrationFileError::Syntax {
            message: message.trim().to_string(),
            line,
        }
    }
}

/// Parses a calibration from TOML text and validates it. Never panics.
pub fn parse(text: &str) -> Result<Calibration, CalibrationFileError> {
    let file: CalibrationToml = toml::from_str(text).map_err(|e| map_toml_error(&e, text))?;
    file.to_calibration()
}

/// Parses a calibration from an already-parsed TOML table (the inline form of
/// `capture.toml`). Line numbers are not available in this form.
pub fn from_value(value: toml::Value) -> Result<Calibration, CalibrationFileError> {
    let file = CalibrationToml::deserialize(value).map_err(|e| map_toml_error(&e, ""))?;
    file.to_calibration()
}

/// Serialises a calibration as TOML text (the layout of the module documentation).
pub fn to_string(c: &Calibration) -> String {
    // Serialising plain structs of numbers and arrays cannot fail.
    toml::to_string(&CalibrationToml::from_calibration(c)).unwrap_or_default()
}

/// Reads and parses a calibration file; every error names the file.
pub fn read(path: &Path) -> Result<Calibration, CalibrationFileError> {
    parse(&read_text(path)?).map_err(in_file(path))
}

/// Writes a calibration file; the error names the file.
pub fn write(path: &Path, c: &Calibration) -> Result<(), CalibrationFileError> {
    std::fs::write(path, to_string(c))
        .map_err(CalibrationFileError::Io)
        .map_err(in_file(path))
}
