//! The pipeline's working memory as it sees it: borrowed slices, and the lengths they need.

use crate::calibration::MAX_PLANES;
use crate::curve::{CurvePoint, MAX_CURVES};
use crate::image::segment::{ObjectFeatures, Run};
use crate::image::Pixel;
use crate::real::{Real, Vec2, Vec3};

use super::buffers::{MAX_OBJECTS, MAX_RUNS};
use super::readout_fits::{ColumnTrack, ReadoutFit, MAX_READOUT_FITS};
use super::PipelineError;

/// Caller-owned working memory of the pipeline: borrowed from a [`Buffers`](super::Buffers) (static),
/// an `OwnedBuffers` (heap, feature `alloc`), or any slices of the [`WorkspaceSizes`].
#[derive(Debug)]
pub struct Workspace<'a, P: Pixel> {
    /// The laser-off frame (`width × height`), which the streamed subtraction turns into the
    /// difference frame in place (`pipeline::stream`).
    pub diff: &'a mut [P],
    /// Histogram bins (`2^bit_depth`).
    pub histogram: &'a mut [u32],
    /// Runs above the streaming's provisional threshold, found as the rows arrive.
    pub candidate_runs: &'a mut [Run],
    /// Runs above the threshold, labelled by the segmentation.
    pub runs: &'a mut [Run],
    /// Each column's brightest pixel of each used curve (`width × MAX_CURVES`), for the
    /// subpixel extraction.
    pub seeds: &'a mut [u16],
    /// Features of the objects found.
    pub objects: &'a mut [ObjectFeatures],
    /// Each column's candidate segment and points during the read-out (`width` entries; a
    /// shorter table turns the read-out extraction off: same points, all after the frame).
    pub column_tracks: &'a mut [ColumnTrack],
    /// Curve points located during the read-out (`pipeline::readout_fits`).
    pub readout_fits: &'a mut [ReadoutFit],
    /// Curve points, all planes (about `width × planes`).
    pub curve: &'a mut [CurvePoint],
    /// 3-D points, grouped by plane in [`Profile::plane_points`](super::Profile::plane_points) order (same length as `curve`).
    pub points: &'a mut [Vec3],
    /// 1σ of each 3-D point (metres, along its noise direction; same indexing as `points`),
    /// from [`super::point_sigmas`]: what the solvers weigh the points by.
    pub sigmas: &'a mut [Real],
    /// Solver scratch: 2-D points (same length as `curve`).
    pub scratch_points: &'a mut [Vec2],
    /// Solver scratch: residuals (same length as `curve`).
    pub scratch_values: &'a mut [Real],
    /// The faint search's column sums of the difference frame, one per block of
    /// `FaintParams::block_columns` columns and row, block-major (`block × height + row`),
    /// gathered as the rows arrive (`pipeline::stream`); a table shorter than
    /// `blocks × height` turns that off (same results, the search then reads the pixels).
    pub block_sums: &'a mut [u16],
    /// Each block's faint-search noise statistics, from the responses computed during the
    /// read-out where its budget allowed (`pipeline::faint_sums`); shorter than the blocks
    /// turns that off (same results, the responses are then all computed after the frame).
    pub faint_columns: &'a mut [super::faint_sums::FaintColumn],
}

/// Buffer lengths a [`Workspace`] needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WorkspaceSizes {
    /// Pixels of `diff`.
    pub pixels: usize,
    /// Histogram bins.
    pub histogram: usize,
    /// Entries of each of the two run tables (candidate runs, labelled runs).
    pub runs: usize,
    /// Seed entries (`width × MAX_CURVES`).
    pub seeds: usize,
    /// Object-feature entries.
    pub objects: usize,
    /// Column tracks of the read-out extraction (`width`).
    pub columns: usize,
    /// Points located during the read-out.
    pub readout_fits: usize,
    /// Curve, 3-D point, point-σ and solver-scratch entries.
    pub points: usize,
    /// Block sums of the faint search (blocks of 8 columns × rows).
    pub block_sums: usize,
    /// Blocks of the faint search (of 8 columns).
    pub faint_columns: usize,
}

impl WorkspaceSizes {
    /// Sizes for a `width × height` frame of `bit_depth` bits with `planes` laser planes.
    ///
    /// The run tables are sized for a cluttered scene ([`MAX_RUNS`] runs), not for the
    /// pathological worst case (a checkerboard has `width × height / 2`): a scene with more
    /// runs than that is reported as `Segment(TooManyLabels)` instead of being measured.
    pub const fn new(width: usize, height: usize, bit_depth: u8, planes: usize) -> Self {
        // `Ord::min`/`clamp` are not `const`.
        let bits = if bit_depth > 16 { 16 } else { bit_depth };
        let planes = if planes < 1 {
            1
        } else if planes > MAX_PLANES {
            MAX_PLANES
        } else {
            planes
        };
        WorkspaceSizes {
            pixels: width * height,
            histogram: 1usize << bits,
            runs: MAX_RUNS,
            seeds: width * MAX_CURVES,
            objects: MAX_OBJECTS,
            columns: width,
            readout_fits: MAX_READOUT_FITS,
            points: width * planes * 2,
            block_sums: width.div_ceil(8) * height,
            faint_columns: width.div_ceil(8),
        }
    }
}

/// `Err(WorkspaceTooSmall)` unless `actual ≥ needed`.
pub(crate) fn need(
    buffer: &'static str,
    needed: usize,
    actual: usize,
) -> Result<(), PipelineError> {
    if actual < needed {
        Err(PipelineError::WorkspaceTooSmall {
            buffer,
            needed,
            actual,
        })
    } else {
        Ok(())
    }
}
