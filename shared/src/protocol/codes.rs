//! The device contract in numbers and words: what the codes and bits of the protocol mean,
//! to both ends and to the person holding the caliper.
//!
//! * the ids and limits both ends rely on ([`USB_VID`], [`USB_PID`], [`HISTORY_LEN`]);
//! * the names of the quality flags and methods, as printed, exported and logged
//!   ([`FLAG_NAMES`], [`flag_names`], [`method_name`]);
//! * why a measurement failed ([`Failure`]): the map from the pipeline's
//!   [`PipelineError`] to the number the device sends, and from that number back to the
//!   sentence a forester reads. The host prints the same [`Failure`] for a capture it measured
//!   itself, so a failure reads the same whether it came from a file or from the caliper;
//! * the sentence for every device error ([`DeviceError`]'s `Display`).

use core::fmt;

use crate::curve::CurveError;
use crate::image::segment::SegmentError;
use crate::image::threshold::ThresholdError;
use crate::measurement::Mode;
use crate::pipeline::PipelineError;
use crate::solvers::result::{Flags, Method};
use crate::solvers::road_profile::RoadError;
use crate::solvers::SolveError;

use super::{DeviceError, ErrorCode};

/// USB vendor id of the Tangent: pid.codes, the vendor id shared by open-hardware projects.
pub const USB_VID: u16 = 0x1209;
/// USB product id of the Tangent, allocated under [`USB_VID`] by pid.codes.
pub const USB_PID: u16 = 0x7A6E;

/// Detail of [`ErrorCode::CameraFailure`] when a board has no memory for a stored frame pair
/// (the H743 streams the laser-on frame through the measurement and keeps only the laser-off
/// frame, which becomes the difference frame: `docs/hardware.md`, "Memory map"), so
/// [`Request::CaptureFrames`](super::Request::CaptureFrames) cannot be served.
pub const CAMERA_NO_FRAME_STORE: u32 = 6;

/// Detail of [`AccelReading::Failed`](super::AccelReading::Failed): an I²C transaction with
/// the accelerometer failed after it had answered (bus error, a lost acknowledge).
pub const ACCEL_BUS: u32 = 1;
/// Detail of [`AccelReading::Failed`](super::AccelReading::Failed): the part at the
/// accelerometer's address is not the expected one (identity registers).
pub const ACCEL_WRONG_PART: u32 = 2;
/// Detail of [`AccelReading::Failed`](super::AccelReading::Failed): the accelerometer
/// produced no new sample in time.
pub const ACCEL_TIMEOUT: u32 = 3;

/// What an [`AccelReading::Failed`](super::AccelReading::Failed) detail means to people.
pub fn accel_failure(code: u32) -> &'static str {
    match code {
        ACCEL_BUS => "an I²C transaction failed",
        ACCEL_WRONG_PART => "the part at its address is not an ADXL355",
        ACCEL_TIMEOUT => "no new sample came in time",
        _ => "unknown failure code",
    }
}

/// Readings the device keeps for [`Request::History`](super::Request::History): a host that
/// lost the link recovers the readings made meanwhile, up to this many.
pub const HISTORY_LEN: usize = 64;

/// Every quality flag with its name as printed, exported and logged (stable: exports and
/// scripts read them).
pub const FLAG_NAMES: [(Flags, &str); 17] = [
    (Flags::ARC_TOO_SHORT, "arc_too_short"),
    (Flags::POOR_FIT, "poor_fit"),
    (Flags::TILT_IGNORED, "tilt_ignored"),
    (Flags::INCONSISTENT, "inconsistent"),
    (Flags::THREE_TANGENT_FAILED, "three_tangent_failed"),
    (Flags::FIT_FAILED, "fit_failed"),
    (Flags::RANGE_LIMIT, "range_limit"),
    (Flags::TILT_FIT_FAILED, "tilt_fit_failed"),
    (Flags::LARGE_TILT, "large_tilt"),
    (Flags::SEVERAL_OBJECTS, "several_objects"),
    (Flags::STRIPE_SATURATED, "stripe_saturated"),
    (Flags::AMBIENT_BRIGHT, "ambient_bright"),
    (Flags::OTHER_OBJECTS, "other_objects"),
    (Flags::ELLIPTIC, "elliptic"),
    (Flags::NEAR_POLE, "near_pole"),
    (Flags::NOT_SPHERICAL, "not_spherical"),
    (Flags::FAINT_STRIPE, "faint_stripe"),
];

/// The names of the flags set in `flags`, in bit order (bits without a name are skipped:
/// `flags.0 & !known_flags()` gives them).
pub fn flag_names(flags: Flags) -> impl Iterator<Item = &'static str> {
    FLAG_NAMES
        .iter()
        .filter(move |(f, _)| flags.contains(*f))
        .map(|(_, name)| *name)
}

/// Every flag that has a name.
pub fn known_flags() -> Flags {
    Flags(FLAG_NAMES.iter().fold(0, |bits, (f, _)| bits | f.0))
}

/// Name of a solver method as printed, exported and logged.
pub fn method_name(method: Method) -> &'static str {
    match method {
        Method::ThreeTangent => "three_tangent",
        Method::CircleFit => "circle_fit",
        Method::CylinderFit => "cylinder_fit",
        Method::GeneralisedThreeTangent => "generalised_three_tangent",
        Method::JointFit => "joint_fit",
        Method::SphereSections => "sections",
        Method::SphereThreeTangent => "sphere_three_tangent",
        Method::MeanProfileDepth => "mean_profile_depth",
        Method::PlanePca => "plane_pca",
    }
}

/// Why a measurement gave no reading: what the device sends as the `detail` of
/// [`ErrorCode::MeasurementFailed`], and what both ends print (its `Display` is the sentence
/// for the forester).
///
/// On the wire it is one `u32` ([`Failure::detail`]): the failure's code in bits 0–7 and the
/// number its sentence quotes in bits 8–31 (saturated), so the message types did not change
/// for it. The codes are listed in `docs/protocol.md`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// Code 1: a frame is malformed, or the two frames differ in size.
    Frame,
    /// Code 2: the frames are not the size the calibration is for.
    FrameSize,
    /// Code 3: the working memory is too small for the frames.
    Workspace,
    /// Code 4: nothing was lit by the laser.
    NoLaserLight {
        /// Largest laser-on minus laser-off difference (grey levels).
        max_difference: u32,
    },
    /// Code 5: the laser-off frame is mostly saturated.
    AmbientSaturated {
        /// Saturated share of the laser-off frame (%, rounded).
        percent: u32,
    },
    /// Code 6: the laser lines cannot be told from the background.
    Threshold,
    /// Code 7: more objects than the feature table holds.
    TooManyObjects {
        /// Objects the table holds.
        capacity: u32,
    },
    /// Code 8: no object looks like a laser curve.
    NoCurve,
    /// Code 9: a plane's curve has too few points.
    CurveTooShort {
        /// Points found.
        points: u32,
    },
    /// Code 10: curve extraction ran out of room.
    Curve,
    /// Code 11: the calibration is invalid or lacks a plane.
    Calibration,
    /// Code 12: a curve point could not be triangulated.
    Triangulation,
    /// Code 13: the stem runs off the edge of the image.
    OutsideFrame,
    /// Code 14: the solver found no trustworthy answer (the number is the [`SolveError`]).
    Solve(SolveError),
    /// Code 15: more provisional labels than the segmentation table holds.
    TooManyLabels {
        /// Labels the table holds.
        capacity: u32,
    },
    /// Code 16: the instrument of this mode has no solver yet (the number is the [`Mode`]:
    /// 0 cylinder, 1 sphere, 2 wall, 3 road).
    UnsupportedMode(Mode),
    /// Code 17: the road instrument refused the profile (the number is
    /// [`RoadError::wire`]: drop-outs, a wet patch, the head tilted or out of range).
    Road {
        /// [`RoadError::wire`].
        detail: u32,
    },
    /// A code this version does not know (a newer firmware).
    Unknown {
        /// The code.
        code: u8,
        /// The number sent with it.
        argument: u32,
    },
}

/// Largest number a [`Failure::detail`] carries (24 bits).
const ARGUMENT_MAX: u32 = (1 << 24) - 1;

/// `n` as a wire argument, saturated.
fn argument(n: usize) -> u32 {
    n.min(ARGUMENT_MAX as usize) as u32
}

impl Failure {
    /// The failure the device reports for a pipeline error. Errors nested in a stage that
    /// come from a malformed frame read as [`Failure::Frame`], whichever stage found them.
    pub fn of(e: &PipelineError) -> Failure {
        match e {
            PipelineError::Frame(_) => Failure::Frame,
            PipelineError::FrameSizeMismatch { .. } => Failure::FrameSize,
            PipelineError::WorkspaceTooSmall { .. } => Failure::Workspace,
            PipelineError::NoLaserLight { max_difference } => Failure::NoLaserLight {
                max_difference: (*max_difference).min(ARGUMENT_MAX),
            },
            PipelineError::AmbientSaturated { fraction } => Failure::AmbientSaturated {
                // `as` saturates and maps NaN to 0.
                percent: (*fraction * 100.0 + 0.5) as u32,
            },
            PipelineError::Threshold(ThresholdError::Frame(_)) => Failure::Frame,
            PipelineError::Threshold(_) => Failure::Threshold,
            PipelineError::Segment(SegmentError::TooManyObjects { capacity }) => {
                Failure::TooManyObjects {
                    capacity: argument(*capacity),
                }
            }
            PipelineError::Segment(SegmentError::TooManyLabels { capacity }) => {
                Failure::TooManyLabels {
                    capacity: argument(*capacity),
                }
            }
            PipelineError::Segment(SegmentError::Frame(_))
            | PipelineError::Segment(SegmentError::FrameTooLarge { .. }) => Failure::Frame,
            PipelineError::NoCurve => Failure::NoCurve,
            PipelineError::CurveTooShort { points, .. } => Failure::CurveTooShort {
                points: argument(*points),
            },
            PipelineError::Curve(CurveError::Frame(_)) => Failure::Frame,
            PipelineError::Curve(CurveError::NoCurve) => Failure::NoCurve,
            PipelineError::Curve(_) => Failure::Curve,
            PipelineError::Calibration => Failure::Calibration,
            PipelineError::Triangulation(_) => Failure::Triangulation,
            PipelineError::OutsideFrame => Failure::OutsideFrame,
            PipelineError::Solve(e) => Failure::Solve(*e),
            PipelineError::UnsupportedMode(mode) => Failure::UnsupportedMode(*mode),
            PipelineError::Road(e) => Failure::Road {
                detail: e.wire() & ARGUMENT_MAX,
            },
        }
    }

    /// The failure's code (bits 0–7 of [`Failure::detail`]).
    pub fn code(&self) -> u8 {
        match self {
            Failure::Frame => 1,
            Failure::FrameSize => 2,
            Failure::Workspace => 3,
            Failure::NoLaserLight { .. } => 4,
            Failure::AmbientSaturated { .. } => 5,
            Failure::Threshold => 6,
            Failure::TooManyObjects { .. } => 7,
            Failure::NoCurve => 8,
            Failure::CurveTooShort { .. } => 9,
            Failure::Curve => 10,
            Failure::Calibration => 11,
            Failure::Triangulation => 12,
            Failure::OutsideFrame => 13,
            Failure::Solve(_) => 14,
            Failure::TooManyLabels { .. } => 15,
            Failure::UnsupportedMode(_) => 16,
            Failure::Road { .. } => 17,
            Failure::Unknown { code, .. } => *code,
        }
    }

    /// The number the failure's sentence quotes (bits 8–31 of [`Failure::detail`]).
    fn argument(&self) -> u32 {
        match *self {
            Failure::NoLaserLight { max_difference: n }
            | Failure::AmbientSaturated { percent: n }
            | Failure::TooManyObjects { capacity: n }
            | Failure::CurveTooShort { points: n }
            | Failure::TooManyLabels { capacity: n }
            | Failure::Road { detail: n }
            | Failure::Unknown { argument: n, .. } => n.min(ARGUMENT_MAX),
            Failure::Solve(e) => solve_error_number(e),
            Failure::UnsupportedMode(mode) => mode_number(mode),
            Failure::Frame
            | Failure::FrameSize
            | Failure::Workspace
            | Failure::Threshold
            | Failure::NoCurve
            | Failure::Curve
            | Failure::Calibration
            | Failure::Triangulation
            | Failure::OutsideFrame => 0,
        }
    }

    /// The `detail` of an [`ErrorCode::MeasurementFailed`] error.
    pub fn detail(&self) -> u32 {
        u32::from(self.code()) | self.argument() << 8
    }

    /// The failure a `detail` of [`ErrorCode::MeasurementFailed`] carries.
    pub fn from_detail(detail: u32) -> Failure {
        let code = (detail & 0xFF) as u8;
        let n = detail >> 8;
        match code {
            1 => Failure::Frame,
            2 => Failure::FrameSize,
            3 => Failure::Workspace,
            4 => Failure::NoLaserLight { max_difference: n },
            5 => Failure::AmbientSaturated { percent: n },
            6 => Failure::Threshold,
            7 => Failure::TooManyObjects { capacity: n },
            8 => Failure::NoCurve,
            9 => Failure::CurveTooShort { points: n },
            10 => Failure::Curve,
            11 => Failure::Calibration,
            12 => Failure::Triangulation,
            13 => Failure::OutsideFrame,
            14 => match solve_error_of_number(n) {
                Some(e) => Failure::Solve(e),
                None => Failure::Unknown { code, argument: n },
            },
            15 => Failure::TooManyLabels { capacity: n },
            16 => match mode_of_number(n) {
                Some(mode) => Failure::UnsupportedMode(mode),
                None => Failure::Unknown { code, argument: n },
            },
            17 => match RoadError::from_wire(n) {
                Some(_) => Failure::Road { detail: n },
                None => Failure::Unknown { code, argument: n },
            },
            _ => Failure::Unknown { code, argument: n },
        }
    }

    /// The device error that reports this failure.
    pub fn device_error(&self) -> DeviceError {
        DeviceError {
            code: ErrorCode::MeasurementFailed,
            detail: self.detail(),
        }
    }
}

/// The number of a [`Mode`] in a [`Failure::UnsupportedMode`] detail.
fn mode_number(mode: Mode) -> u32 {
    match mode {
        Mode::Cylinder => 0,
        Mode::Sphere => 1,
        Mode::Wall => 2,
        Mode::Road => 3,
    }
}

/// The [`Mode`] of a number ([`mode_number`]'s inverse).
fn mode_of_number(n: u32) -> Option<Mode> {
    Some(match n {
        0 => Mode::Cylinder,
        1 => Mode::Sphere,
        2 => Mode::Wall,
        3 => Mode::Road,
        _ => return None,
    })
}

/// The number of a [`SolveError`] in a [`Failure::Solve`] detail.
fn solve_error_number(e: SolveError) -> u32 {
    match e {
        SolveError::TooFewPoints => 0,
        SolveError::NonFinite => 1,
        SolveError::Degenerate => 2,
        SolveError::NotConverged => 3,
        SolveError::ScratchTooSmall => 4,
        SolveError::ArcTooShort => 5,
        SolveError::RadiusOutOfRange => 6,
        SolveError::InvalidParameter => 7,
        SolveError::PlaneCount => 8,
        SolveError::NotRound => 9,
        SolveError::OneSection => 10,
        SolveError::NotSpherical => 11,
        SolveError::TwoObjects => 12,
        SolveError::Unbounded => 13,
        // The wall solver's (numbers from 20 keep clear of other instruments').
        SolveError::SingleLine => 20,
        SolveError::NotPlanar => 21,
    }
}

/// The [`SolveError`] of a number ([`solve_error_number`]'s inverse).
fn solve_error_of_number(n: u32) -> Option<SolveError> {
    Some(match n {
        0 => SolveError::TooFewPoints,
        1 => SolveError::NonFinite,
        2 => SolveError::Degenerate,
        3 => SolveError::NotConverged,
        4 => SolveError::ScratchTooSmall,
        5 => SolveError::ArcTooShort,
        6 => SolveError::RadiusOutOfRange,
        7 => SolveError::InvalidParameter,
        8 => SolveError::PlaneCount,
        9 => SolveError::NotRound,
        10 => SolveError::OneSection,
        11 => SolveError::NotSpherical,
        12 => SolveError::TwoObjects,
        13 => SolveError::Unbounded,
        20 => SolveError::SingleLine,
        21 => SolveError::NotPlanar,
        _ => return None,
    })
}

/// The sentence the forester reads.
impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Failure::Frame => write!(f, "the frames are malformed or differ in size"),
            Failure::FrameSize => write!(
                f,
                "the frames are not the size the calibration is for (a calibration of another camera?)"
            ),
            Failure::Workspace => write!(
                f,
                "the working memory is too small for these frames (a software fault: please report it)"
            ),
            Failure::NoLaserLight { max_difference } => write!(
                f,
                "no laser light: the laser-on frame is at most {max_difference} grey levels brighter than the laser-off frame (nothing in range, or the laser did not fire)"
            ),
            Failure::AmbientSaturated { percent } => write!(
                f,
                "{percent} % of the laser-off frame is saturated: too much ambient light (sun in view?)"
            ),
            Failure::Threshold => write!(
                f,
                "threshold: the laser lines cannot be told from the background (flat or dark frames)"
            ),
            Failure::TooManyObjects { capacity } => write!(
                f,
                "segmentation: image has more than {capacity} objects (image too cluttered)"
            ),
            Failure::NoCurve => write!(f, "no laser curve found in the image"),
            Failure::CurveTooShort { points } => write!(
                f,
                "a laser curve has only {points} points (aim the lines at the stem, 0.5–3 m away)"
            ),
            Failure::Curve => write!(
                f,
                "curve extraction: more candidate lines or points than the buffers hold (image too cluttered)"
            ),
            Failure::Calibration => write!(f, "the calibration is invalid"),
            Failure::Triangulation => write!(
                f,
                "triangulation: a curve point misses its laser plane (check the calibration)"
            ),
            Failure::OutsideFrame => write!(
                f,
                "the stem runs off the edge of the image: its outline is not seen (step back or aim at its centre)"
            ),
            Failure::Solve(e) => write!(f, "solver: {e}"),
            Failure::TooManyLabels { capacity } => write!(
                f,
                "segmentation: more than {capacity} provisional labels needed (image too cluttered)"
            ),
            Failure::UnsupportedMode(mode) => write!(
                f,
                "the {} instrument has no solver yet (update the software)",
                mode.name()
            ),
            Failure::Road { detail } => match RoadError::from_wire(*detail) {
                Some(e) => write!(f, "road profile: {e}"),
                None => write!(f, "road profile refused (detail {detail})"),
            },
            Failure::Unknown { code, argument } => write!(
                f,
                "the measurement failed (code {code}, detail {argument}: unknown to this version, update the host software)"
            ),
        }
    }
}

/// The sentence for a device error, with what to do about it.
impl fmt::Display for DeviceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let d = self.detail;
        match self.code {
            ErrorCode::UnsupportedVersion => {
                write!(
                    f,
                    "it does not speak protocol version {d} (update one side)"
                )
            }
            ErrorCode::NoCalibration => write!(
                f,
                "it has no calibration (push one with `tangent device-calibration push --port P FILE`)"
            ),
            ErrorCode::InvalidCalibration => match d {
                2 => write!(f, "the calibration does not match the device's sensor size"),
                4 => write!(
                    f,
                    "the calibration's planes' uncertainty is not a covariance of its planes \
                     (refine the planes again with `tangent calibrate ball` or `wall`)"
                ),
                _ => write!(
                    f,
                    "the calibration is invalid (check it with `tangent calibrate`)"
                ),
            },
            ErrorCode::StorageFailure => write!(
                f,
                "its flash storage failed (board code {d}): nothing was stored and the setting stays as it was"
            ),
            ErrorCode::CameraTimeout => write!(f, "the camera delivered no frame in time"),
            ErrorCode::CameraFailure if d == CAMERA_NO_FRAME_STORE => write!(
                f,
                "it cannot store a raw frame pair: it streams the laser-on frame through the measurement and has memory for one frame only (raw captures need a board with two frame buffers, such as the emulated one)"
            ),
            ErrorCode::CameraFailure => write!(f, "the camera failed (driver code {d})"),
            ErrorCode::LaserTimeout => {
                write!(f, "a laser stayed on too long and was forced off")
            }
            ErrorCode::MeasurementFailed => {
                write!(f, "no stem was measured: {}", Failure::from_detail(d))
            }
            ErrorCode::NoFrames => write!(f, "no frame pair has been captured yet"),
            ErrorCode::StaleCapture => {
                write!(f, "a newer capture replaced the one being read")
            }
            ErrorCode::OutOfRange => write!(f, "the read went past the end of the frame"),
            ErrorCode::Busy => write!(f, "it is busy (e.g. streaming); try again"),
            ErrorCode::InvalidSetting => {
                write!(f, "it does not accept the value {d} for this setting")
            }
        }
    }
}

#[cfg(test)]
mod tests;
