//! The measurement chain end to end: a laser-off / laser-on frame pair and a calibration in,
//! the laser curves as 3-D points per laser plane out; an instrument's solver
//! ([`crate::instrument`]) turns them into one [`crate::measurement::Measurement`].
//!
//! ```text
//! off (stored), on (rows as they arrive) ─► subtract in place + histogram + candidate runs
//!   + curve points of the columns whose rows are in
//!   ─► threshold ─► runs ─► label (union–find over runs) ─► select ─► assign to planes
//!   ─► subpixel curve per column ─► smooth ─► undistort + triangulate ─► 3-D points
//! ```
//!
//! * [`stream`]: the streaming front end, [`ProfileStream`] (`push_rows` as the camera
//!   delivers the laser-on frame, `finish` after its last row), and the front end of a stored
//!   pair, [`extract_profile`] (which feeds it through the stream);
//! * [`readout_fits`]: the curve points located during the read-out, as their rows arrive;
//! * [`profile`]: the stages after the segmentation and the image summary [`Profile`] with its
//!   quality flags;
//! * `planes`: which object is which plane's curve;
//! * [`grow`]: growing each thresholded curve along its stripe beyond where the threshold
//!   cut it (a glossy stem's diffuse sides), with a noise-relative threshold;
//! * [`faint`]: the faint-stripe search (matched filter across the stripe, a track along it)
//!   that takes over when the thresholded chain finds no stripe — too faint for the darkness
//!   test, or broken into clutter (`docs/error-model.md` §7);
//! * [`workspace`] and [`buffers`]: the caller-owned working memory.
//!
//! Every buffer lives in a caller-owned [`Workspace`]; after a call the workspace still holds
//! the intermediate results (difference frame, runs, curve points, 3-D points), so a host can
//! plot them and a device can report them. The steps and the choices made here (threshold
//! floor, plane assignment, fragment merging, frame-edge rule) are derived in
//! `docs/pipeline.md`.

use core::fmt;

use crate::curve::{CurveError, ExtractParams, SmoothParams};
use crate::image::segment::SegmentError;
use crate::image::select::SelectionParams;
use crate::image::threshold::{Floors, ThresholdError, ThresholdMethod};
use crate::image::FrameError;
use crate::laser_plane::TriangulationError;
use crate::measurement::Mode;
use crate::real::Real;
use crate::solvers::road_profile::RoadError;
use crate::solvers::SolveError;

pub mod arcs;
pub mod buffers;
mod candidate;
pub mod crossing;
pub mod faint;
mod faint_sums;
pub mod fragments;
pub mod grow;
mod planes;
pub mod profile;
pub mod readout_fits;
pub mod stream;
pub mod workspace;

#[cfg(any(test, feature = "alloc"))]
pub use buffers::OwnedBuffers;
pub use buffers::{
    Buffers, FaintBuffers, Objects, RunBuffers, SmallBuffers, BLOCK_SUMS_752, FAINT_COLUMNS,
    NO_OBJECTS,
};
pub use faint::FaintParams;
pub use faint_sums::FaintColumn;
pub use fragments::StackParams;
pub use grow::GrowParams;
pub use profile::{point_sigmas, Profile, Stage};
pub use readout_fits::ReadoutBuffers;
pub use stream::{extract_profile, extract_profile_probed, ProfileStream, BLOCK_ROWS};
pub use workspace::{Workspace, WorkspaceSizes};

/// Tunable parameters of the image part of the chain. [`Default`] suits the reference hardware
/// (MT9V034 behind a 650 nm band-pass filter, 752×480, f ≈ 1000 px).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipelineConfig {
    /// How the difference image is thresholded before segmentation.
    pub threshold: ThresholdMethod,
    /// Floors of the darkness test and of the threshold, relative to the difference image's
    /// noise.
    pub floors: Floors,
    /// Object selection (the per-object criteria; how many to keep is set by the pipeline).
    pub selection: SelectionParams,
    /// Candidates kept per plane before merging fragments of a broken curve.
    pub max_fragments: usize,
    /// Largest column gap between two fragments of one curve.
    pub max_fragment_gap: u16,
    /// Largest row difference between the facing ends of two fragments of one curve.
    pub max_fragment_step: Real,
    /// Subpixel extraction.
    pub extract: ExtractParams,
    /// Curve smoothing.
    pub smooth: SmoothParams,
    /// Fewest points a plane's curve must have.
    pub min_points: usize,
    /// A curve whose extreme column is this close to the frame's left or right edge is cut by
    /// the field of view.
    pub edge_margin: u16,
    /// The faint-stripe search that takes over when the thresholded chain finds no stripe
    /// ([`faint`]); `None` disables it.
    pub faint: Option<FaintParams>,
    /// Growing each plane's thresholded curve along its stripe with a noise-relative
    /// threshold ([`grow`]); `None` leaves the curves as the threshold cut them. The stem
    /// instrument turns it on (`Instrument::pipeline_config`).
    pub grow: Option<GrowParams>,
    /// Assigning other surfaces' pieces one above the other to the planes when their depths
    /// agree ([`fragments`]: a niche's front wall beside its back wall); `None` leaves them to
    /// the fragment join. The wall instrument turns it on.
    pub stacks: Option<StackParams>,
    /// Ranking the selected objects that bend like a ball's section before the straight ones
    /// ([`arcs`]: a ball beside the central column on a floor, whose line would otherwise be
    /// the aimed object). The sphere instrument turns it on.
    pub arcs_first: bool,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            threshold: ThresholdMethod::Otsu,
            floors: Floors::default(),
            selection: SelectionParams::default(),
            max_fragments: 4,
            max_fragment_gap: 40,
            max_fragment_step: 6.0,
            extract: ExtractParams::default(),
            smooth: SmoothParams::default(),
            min_points: 12,
            edge_margin: 2,
            faint: Some(FaintParams::default()),
            grow: None,
            stacks: None,
            arcs_first: false,
        }
    }
}

/// Why a frame pair gave no usable laser curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PipelineError {
    /// A frame is malformed or the frames differ in size.
    Frame(FrameError),
    /// The frames do not have the calibrated camera's size.
    FrameSizeMismatch {
        /// Calibrated `(width, height)`.
        calibrated: (u32, u32),
        /// Frame `(width, height)`.
        actual: (usize, usize),
    },
    /// A workspace buffer is too small for this frame size.
    WorkspaceTooSmall {
        /// Which buffer.
        buffer: &'static str,
        /// Entries needed.
        needed: usize,
        /// Entries provided.
        actual: usize,
    },
    /// The laser-on frame is no brighter than the laser-off frame: nothing in range was lit,
    /// or the laser did not fire.
    NoLaserLight {
        /// Brightest difference found.
        max_difference: u32,
    },
    /// The laser-off frame is saturated over most of the image (sun in the lens).
    AmbientSaturated {
        /// Fraction of laser-off pixels at full scale.
        fraction: Real,
    },
    /// Thresholding failed.
    Threshold(ThresholdError),
    /// Segmentation failed (typically: too many objects — clutter, or a threshold too low).
    Segment(SegmentError),
    /// No object looks like a laser curve.
    NoCurve,
    /// A plane's curve has too few points.
    CurveTooShort {
        /// Plane index.
        plane: usize,
        /// Points found.
        points: usize,
    },
    /// Curve extraction failed.
    Curve(CurveError),
    /// The calibration is invalid or lacks a plane.
    Calibration,
    /// A point could not be triangulated.
    Triangulation(TriangulationError),
    /// The aimed object's curve runs off the left or right edge of the frame: its silhouette
    /// (the ends of the lit arc) is not seen, so no diameter can be trusted. Step back.
    OutsideFrame,
    /// The solver found no trustworthy answer.
    Solve(SolveError),
    /// The instrument has no solver yet.
    UnsupportedMode(Mode),
    /// The road instrument refused the profile ([`Mode::Road`]: drop-outs, a wet patch, the
    /// head tilted or out of range; `docs/road.md`, "Bad input").
    Road(RoadError),
}

impl fmt::Display for PipelineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PipelineError::Frame(e) => write!(f, "frame: {e}"),
            PipelineError::FrameSizeMismatch { calibrated, actual } => write!(
                f,
                "frames are {}x{} but the calibration is for {}x{}",
                actual.0, actual.1, calibrated.0, calibrated.1
            ),
            PipelineError::WorkspaceTooSmall { buffer, needed, actual } => {
                write!(f, "workspace buffer `{buffer}` holds {actual}, {needed} needed")
            }
            PipelineError::NoLaserLight { max_difference } => write!(
                f,
                "no laser light: the laser-on frame is at most {max_difference} grey levels brighter than the laser-off frame (nothing in range, or the laser did not fire)"
            ),
            PipelineError::AmbientSaturated { fraction } => write!(
                f,
                "{:.0} % of the laser-off frame is saturated: too much ambient light (sun in view?)",
                fraction * 100.0
            ),
            PipelineError::Threshold(e) => write!(f, "threshold: {e}"),
            PipelineError::Segment(e) => write!(f, "segmentation: {e}"),
            PipelineError::NoCurve => write!(f, "no laser curve found in the image"),
            PipelineError::CurveTooShort { plane, points } => {
                write!(f, "the laser curve of plane {plane} has only {points} points")
            }
            PipelineError::Curve(e) => write!(f, "curve extraction: {e}"),
            PipelineError::Calibration => write!(f, "the calibration is invalid"),
            PipelineError::Triangulation(e) => write!(f, "triangulation: {e}"),
            PipelineError::OutsideFrame => write!(
                f,
                "the stem runs off the edge of the image: its outline is not seen (step back or aim at its centre)"
            ),
            PipelineError::Solve(e) => write!(f, "solver: {e}"),
            PipelineError::UnsupportedMode(mode) => {
                write!(f, "the {} instrument has no solver yet", mode.name())
            }
            PipelineError::Road(e) => write!(f, "road profile: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for PipelineError {}

impl From<FrameError> for PipelineError {
    fn from(e: FrameError) -> Self {
        PipelineError::Frame(e)
    }
}
impl From<ThresholdError> for PipelineError {
    fn from(e: ThresholdError) -> Self {
        PipelineError::Threshold(e)
    }
}
impl From<SegmentError> for PipelineError {
    fn from(e: SegmentError) -> Self {
        PipelineError::Segment(e)
    }
}
impl From<CurveError> for PipelineError {
    fn from(e: CurveError) -> Self {
        match e {
            CurveError::NoCurve => PipelineError::NoCurve,
            e => PipelineError::Curve(e),
        }
    }
}
impl From<SolveError> for PipelineError {
    fn from(e: SolveError) -> Self {
        PipelineError::Solve(e)
    }
}
impl From<RoadError> for PipelineError {
    fn from(e: RoadError) -> Self {
        PipelineError::Road(e)
    }
}
impl From<TriangulationError> for PipelineError {
    fn from(e: TriangulationError) -> Self {
        PipelineError::Triangulation(e)
    }
}

#[cfg(test)]
pub(crate) mod tests;
