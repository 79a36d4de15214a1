//! A unit's calibration: its camera and its laser planes (thesis chapter 6).
//!
//! This is what the device stores (serialised with postcard) and what every measurement
//! uses. The host writes it as TOML through its own mirror struct (see `docs/formats.md`).
//! The planes are indexed as the firmware's laser outputs are: plane `i` is the one lit by
//! laser `i`.

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::camera::{Camera, CameraError};
use crate::laser_plane::{LaserPlane, LaserPlaneError};
// `Float` supplies sqrt/atan2/… in `no_std`; with `std` the inherent methods win.
#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{Real, PI};

mod uncertainty;

pub use uncertainty::{PlanesUncertainty, UncertaintyError, PLANE_PARAMS};

/// Most laser planes a calibration holds (the instrument has one or two; four leaves room
/// for a cross-hair or a multi-line head without changing the wire format).
pub const MAX_PLANES: usize = 4;

/// Why a calibration is unusable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CalibrationError {
    /// The camera is invalid.
    Camera(CameraError),
    /// Plane `index` is invalid.
    Plane {
        /// Index of the offending plane.
        index: usize,
        /// What is wrong with it.
        error: LaserPlaneError,
    },
    /// No laser plane was given.
    NoPlanes,
    /// More than [`MAX_PLANES`] planes were given.
    TooManyPlanes(usize),
    /// [`Calibration::plane`] was asked for a plane that does not exist.
    NoSuchPlane {
        /// Requested index.
        index: usize,
        /// Number of planes in the calibration.
        count: usize,
    },
    /// The planes' uncertainty is invalid or does not cover the planes.
    Uncertainty(UncertaintyError),
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CalibrationError::Camera(e) => write!(f, "calibration camera: {e}"),
            CalibrationError::Plane { index, error } => {
                write!(f, "calibration laser plane {index}: {error}")
            }
            CalibrationError::NoPlanes => write!(f, "calibration has no laser plane"),
            CalibrationError::TooManyPlanes(n) => {
                write!(
                    f,
                    "calibration has {n} laser planes, at most {MAX_PLANES} allowed"
                )
            }
            CalibrationError::NoSuchPlane { index, count } => {
                write!(f, "laser plane {index} requested, calibration has {count}")
            }
            CalibrationError::Uncertainty(e) => write!(f, "calibration planes' uncertainty: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CalibrationError {}

/// A unit's calibration: identifier, camera, and 1 to [`MAX_PLANES`] laser planes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Identifier of this calibration (e.g. unit serial number or calibration run), echoed
    /// in measurement results so a reading can be traced to the calibration that made it.
    pub id: u32,
    /// The camera.
    pub camera: Camera,
    /// The laser planes, in the order of the laser outputs.
    pub planes: heapless::Vec<LaserPlane, MAX_PLANES>,
    /// The planes' `(e, δ)` covariance when they were refined against each other on a
    /// reference; `None`: each plane from its own board poses, the planes' errors independent
    /// with the head's budget ([`crate::noise::NoiseModel`]).
    #[serde(default)]
    pub uncertainty: Option<PlanesUncertainty>,
}

impl Calibration {
    /// Builds and validates a calibration.
    pub fn new(id: u32, camera: Camera, planes: &[LaserPlane]) -> Result<Self, CalibrationError> {
        if planes.len() > MAX_PLANES {
            return Err(CalibrationError::TooManyPlanes(planes.len()));
        }
        let planes = heapless::Vec::from_slice(planes)
            .map_err(|_| CalibrationError::TooManyPlanes(planes.len()))?;
        let calibration = Calibration {
            id,
            camera,
            planes,
            uncertainty: None,
        };
        calibration.validate()?;
        Ok(calibration)
    }

    /// The same calibration with the planes' covariance `uncertainty`, which must cover
    /// exactly its planes.
    pub fn with_uncertainty(
        mut self,
        uncertainty: PlanesUncertainty,
    ) -> Result<Self, CalibrationError> {
        self.uncertainty = Some(uncertainty);
        self.validate()?;
        Ok(self)
    }

    /// Checks the camera ([`Camera::validate`]) and every plane ([`LaserPlane::validate`]),
    /// and that there is at least one plane. Call it after deserialising.
    pub fn validate(&self) -> Result<(), CalibrationError> {
        self.camera.validate().map_err(CalibrationError::Camera)?;
        if self.planes.is_empty() {
            return Err(CalibrationError::NoPlanes);
        }
        for (index, plane) in self.planes.iter().enumerate() {
            plane
                .validate()
                .map_err(|error| CalibrationError::Plane { index, error })?;
        }
        if let Some(u) = &self.uncertainty {
            if u.planes() != self.planes.len() {
                return Err(CalibrationError::Uncertainty(
                    UncertaintyError::PlaneCount {
                        covers: u.planes(),
                        planes: self.planes.len(),
                    },
                ));
            }
        }
        Ok(())
    }

    /// Plane `i`, or [`CalibrationError::NoSuchPlane`].
    pub fn plane(&self, i: usize) -> Result<&LaserPlane, CalibrationError> {
        self.planes.get(i).ok_or(CalibrationError::NoSuchPlane {
            index: i,
            count: self.planes.len(),
        })
    }

    /// The nominal reference design — **not a calibrated unit**: use it for simulation,
    /// tests and as the starting point of a calibration, never to measure with a real unit.
    ///
    /// * camera: [`Camera::reference_design`] (MT9V034 752 × 480, 6 µm pixels, 6 mm lens:
    ///   `f = 1000 px`, principal point `(375.5, 239.5)`, no distortion);
    /// * plane 0: laser [`REFERENCE_BASELINE`] = 0.10 m below the camera, tilted so that the
    ///   plane crosses the optical axis at [`REFERENCE_AXIS_CROSSING`] = 1.5 m, i.e.
    ///   `δ = atan(0.10 / 1.5) ≈ 3.81°` (the middle of a caliper's 0.5–3 m working range);
    /// * plane 1: the second, parallel laser of the tilted-cylinder variant,
    ///   [`REFERENCE_PLANE_SPACING`] = 0.05 m farther below (`e = 0.15 m`, same `δ`). The two
    ///   planes are parallel, 0.05·cos δ ≈ 49.9 mm apart.
    ///
    /// `id` is 0.
    pub fn reference_design() -> Self {
        let tilt = reference_tilt();
        let mut planes = heapless::Vec::new();
        for e in [
            REFERENCE_BASELINE,
            REFERENCE_BASELINE + REFERENCE_PLANE_SPACING,
        ] {
            // Both constructions succeed for these constants (checked by the tests); a
            // failure could only come from a broken edit of the constants, and then the
            // plane is left out rather than panicking.
            if let Ok(p) = LaserPlane::from_baseline_tilt(e, tilt) {
                let _ = planes.push(p);
            }
        }
        Calibration {
            id: 0,
            camera: Camera::reference_design(),
            planes,
            uncertainty: None,
        }
    }
}

/// Baseline `e` (metres) of plane 0 of [`Calibration::reference_design`].
pub const REFERENCE_BASELINE: Real = 0.10;
/// Where plane 0 of [`Calibration::reference_design`] crosses the optical axis (metres).
pub const REFERENCE_AXIS_CROSSING: Real = 1.5;
/// Extra baseline of plane 1 of [`Calibration::reference_design`] (metres).
pub const REFERENCE_PLANE_SPACING: Real = 0.05;

/// The reference design's third, crossing laser plane for walls (`docs/building.md`, "The
/// crossing line"; `docs/hardware.md`): a vertical fan [`REFERENCE_BASELINE`] = 0.10 m to the
/// right of the camera, tilted to cross the optical axis at [`REFERENCE_AXIS_CROSSING`] =
/// 1.5 m — plane 0 rolled by −90° about the optical axis, `S = (e, 0, 0)`,
/// `n = (cos δ, 0, sin δ)`. Its line runs down the image and moves along the rows with depth.
pub fn reference_crossing_plane() -> Result<LaserPlane, LaserPlaneError> {
    LaserPlane::from_baseline_tilt_roll(REFERENCE_BASELINE, reference_tilt(), -0.5 * PI)
}

/// Tilt `δ = atan(e / z0)` of the reference design's planes (radians).
pub fn reference_tilt() -> Real {
    (REFERENCE_BASELINE / REFERENCE_AXIS_CROSSING).atan()
}

#[cfg(test)]
// The casts to f64 are no-ops in f64 builds but needed with `--features f32`.
#[allow(clippy::unnecessary_cast)]
mod tests {
    use super::*;
    use crate::camera::Distortion;
    use crate::real::Vec3;

    const EPS: f64 = Real::EPSILON as f64;

    #[test]
    fn reference_design_is_the_documented_nominal_design() {
        let c = Calibration::reference_design();
        assert_eq!(c.validate(), Ok(()));
        assert_eq!(c.planes.len(), 2);
        // f = 6 mm / 6 µm; principal point at the image centre.
        assert_eq!((c.camera.width, c.camera.height), (752, 480));
        assert_eq!(
            (c.camera.fx, c.camera.fy, c.camera.cx, c.camera.cy),
            (1000.0, 1000.0, 375.5, 239.5)
        );
        // Plane 0 crosses the axis at 1.5 m, with e = 0.10 m; plane 1 is parallel, e = 0.15 m.
        let p0 = c.plane(0).unwrap();
        let (e, tilt) = p0.baseline_tilt();
        assert!((e as f64 - 0.10).abs() <= 8.0 * EPS);
        assert!((tilt as f64 - (0.1f64 / 1.5).atan()).abs() <= 8.0 * EPS);
        assert!((p0.axis_crossing().unwrap() as f64 - 1.5).abs() <= 16.0 * EPS * 1.5);
        let p1 = c.plane(1).unwrap();
        assert!(((p1.normal - p0.normal).norm() as f64) <= 4.0 * EPS);
        assert!((p1.baseline_tilt().0 as f64 - 0.15).abs() <= 8.0 * EPS);
        assert!((p1.axis_crossing().unwrap() as f64 - 2.25).abs() <= 16.0 * EPS * 2.25);
        assert_eq!(
            c.plane(2),
            Err(CalibrationError::NoSuchPlane { index: 2, count: 2 })
        );
    }

    #[test]
    fn new_validates() {
        let cam = Camera::reference_design();
        let p = LaserPlane::from_baseline_tilt(0.1, 0.05).unwrap();
        assert_eq!(
            Calibration::new(7, cam, &[]),
            Err(CalibrationError::NoPlanes)
        );
        assert_eq!(
            Calibration::new(7, cam, &[p; 5]),
            Err(CalibrationError::TooManyPlanes(5))
        );
        assert_eq!(
            Calibration::new(7, Camera { fx: 0.0, ..cam }, &[p]),
            Err(CalibrationError::Camera(CameraError::InvalidIntrinsics))
        );
        let bad = LaserPlane {
            source: Vec3::new(0.0, 0.5, 0.0),
            ..p
        };
        assert_eq!(
            Calibration::new(7, cam, &[p, bad]),
            Err(CalibrationError::Plane {
                index: 1,
                error: LaserPlaneError::SourceNotInPlane
            })
        );
        let c = Calibration::new(7, cam, &[p; 4]).unwrap();
        assert_eq!((c.id, c.planes.len()), (7, 4));
    }

    #[test]
    fn postcard_round_trip() {
        let mut c = Calibration::reference_design();
        c.id = 0xDEAD_BEEF;
        c.camera.distortion = Distortion {
            k1: -0.08,
            k2: 0.02,
            k3: 0.0,
            p1: 2e-4,
            p2: -1e-4,
        };
        let mut buf = [0u8; 512];
        let used = postcard::to_slice(&c, &mut buf).unwrap().len();
        let back: Calibration = postcard::from_bytes(&buf[..used]).unwrap();
        // Floats travel bit-exactly.
        assert_eq!(back, c);
        assert_eq!(back.validate(), Ok(()));
    }
}
