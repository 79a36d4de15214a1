//! The pipeline's working memory, assembled once for everyone: a const-constructible set for
//! statics ([`Buffers`], or its parts [`SmallBuffers`], [`RunBuffers`] and [`NO_OBJECTS`] for
//! a board that spreads them over RAM regions) and, with the `alloc` feature, a heap set sized
//! at run time (`OwnedBuffers`). Each lends the pipeline a [`Workspace`].
//!
//! Only one buffer grows with the pixels: the laser-off frame, which becomes the difference
//! frame (`pipeline::stream`). The segmentation's memory grows with the lit runs.

use crate::curve::{CurvePoint, MAX_CURVES};
use crate::image::segment::{ObjectFeatures, Run};
use crate::image::Pixel;
use crate::real::{Real, Vec2, Vec3};

use super::faint_sums::FaintColumn;
use super::readout_fits::ReadoutBuffers;
use super::Workspace;

/// Block-sum entries for frames of the reference size: 752 / 8 = 94 blocks of 8 columns ×
/// 480 rows (90,240 bytes), the faint search's column sums gathered during the read-out
/// ([`FaintBuffers`]).
pub const BLOCK_SUMS_752: usize = 752usize.div_ceil(8) * 480;

/// Entries of each run table ([`super::WorkspaceSizes::new`]): 64 KB each. A laser image has
/// a few hundred runs above the threshold (a 1 m stem's 559-column stripe: ≈ 600); the
/// candidate table also holds the specks of noise above the streaming's provisional
/// threshold, and when it fills the pipeline rescans the difference frame instead.
pub const MAX_RUNS: usize = 8192;
/// Seed entries for frames of the reference width (752 columns × [`MAX_CURVES`]).
pub const SEEDS_752: usize = 752 * MAX_CURVES;
/// Object-feature entries ([`super::WorkspaceSizes::new`]).
pub const MAX_OBJECTS: usize = 1024;
/// Histogram bins of 8-bit frames (the default of the const sets' `BINS`).
pub const BINS_8BIT: usize = 256;

/// The object-feature buffer (≈ 57 KB).
pub type Objects = [ObjectFeatures; MAX_OBJECTS];

/// An all-zero [`Objects`] buffer: a static initialised with it lands in `.bss`, not in
/// `.data` with a 57 KB image in flash (the segmentation initialises every entry it uses).
#[allow(clippy::large_const_arrays)] // only used to initialise statics (zeroed, in .bss)
pub const NO_OBJECTS: Objects = [ObjectFeatures::ZERO; MAX_OBJECTS];

/// The segmentation's tables: candidate runs, labelled runs and the `SEEDS` column seeds
/// (`width × MAX_CURVES`). All-zero and const-constructible.
#[derive(Debug)]
pub struct RunBuffers<const SEEDS: usize = SEEDS_752> {
    candidates: [Run; MAX_RUNS],
    runs: [Run; MAX_RUNS],
    seeds: [u16; SEEDS],
}

impl<const SEEDS: usize> RunBuffers<SEEDS> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        RunBuffers {
            candidates: [Run::ZERO; MAX_RUNS],
            runs: [Run::ZERO; MAX_RUNS],
            seeds: [0; SEEDS],
        }
    }
}

impl<const SEEDS: usize> Default for RunBuffers<SEEDS> {
    fn default() -> Self {
        Self::new()
    }
}

/// Every buffer but the frame, the run tables and the object features: the histogram
/// (`BINS` bins) and `POINTS` entries of curve points, 3-D points, their σ and solver
/// scratch. All-zero and const-constructible, so a board can place it in a static of its
/// choice (`#[link_section]`).
#[derive(Debug)]
pub struct SmallBuffers<const POINTS: usize, const BINS: usize = BINS_8BIT> {
    histogram: [u32; BINS],
    curve: [CurvePoint; POINTS],
    points: [Vec3; POINTS],
    sigmas: [Real; POINTS],
    scratch_points: [Vec2; POINTS],
    scratch_values: [Real; POINTS],
}

impl<const POINTS: usize, const BINS: usize> SmallBuffers<POINTS, BINS> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        SmallBuffers {
            histogram: [0; BINS],
            curve: [CurvePoint::ZERO; POINTS],
            points: [Vec3::new(0.0, 0.0, 0.0); POINTS],
            sigmas: [0.0; POINTS],
            scratch_points: [Vec2::new(0.0, 0.0); POINTS],
            scratch_values: [0.0; POINTS],
        }
    }
}

/// Blocks of the faint search the read-out's responses serve: 752 / 8 = 94, with room.
pub const FAINT_COLUMNS: usize = 128;

/// The faint search's table of block sums (`SUMS` entries: blocks × rows of the difference
/// frame, [`Workspace::block_sums`]) and the noise statistics of each block's responses
/// ([`Workspace::faint_columns`]), filled during the read-out. All-zero and
/// const-constructible, so a board can place it in a RAM region of its choice.
#[derive(Debug)]
pub struct FaintBuffers<const SUMS: usize = BLOCK_SUMS_752> {
    block_sums: [u16; SUMS],
    columns: [FaintColumn; FAINT_COLUMNS],
}

impl<const SUMS: usize> FaintBuffers<SUMS> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        FaintBuffers {
            block_sums: [0; SUMS],
            columns: [FaintColumn::ZERO; FAINT_COLUMNS],
        }
    }
}

impl<const SUMS: usize> Default for FaintBuffers<SUMS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const POINTS: usize, const BINS: usize> Default for SmallBuffers<POINTS, BINS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<'a, P: Pixel> Workspace<'a, P> {
    /// A workspace over buffers placed apart: the laser-off / difference frame
    /// (`width × height`), the object features, the [`RunBuffers`], the [`SmallBuffers`],
    /// the [`ReadoutBuffers`] and the [`FaintBuffers`].
    pub fn from_parts<
        const POINTS: usize,
        const BINS: usize,
        const SEEDS: usize,
        const COLUMNS: usize,
        const FITS: usize,
        const SUMS: usize,
    >(
        diff: &'a mut [P],
        objects: &'a mut [ObjectFeatures],
        runs: &'a mut RunBuffers<SEEDS>,
        small: &'a mut SmallBuffers<POINTS, BINS>,
        readout: &'a mut ReadoutBuffers<COLUMNS, FITS>,
        faint: &'a mut FaintBuffers<SUMS>,
    ) -> Self {
        Workspace {
            diff,
            histogram: &mut small.histogram,
            candidate_runs: &mut runs.candidates,
            runs: &mut runs.runs,
            seeds: &mut runs.seeds,
            objects,
            column_tracks: &mut readout.columns,
            readout_fits: &mut readout.fits,
            curve: &mut small.curve,
            points: &mut small.points,
            sigmas: &mut small.sigmas,
            scratch_points: &mut small.scratch_points,
            scratch_values: &mut small.scratch_values,
            block_sums: &mut faint.block_sums,
            faint_columns: &mut faint.columns,
        }
    }
}

/// The whole working memory for frames of up to `PIXELS` pixels and `POINTS` curve points
/// (size them with [`super::WorkspaceSizes::new`], which is `const`), const-constructible and
/// all-zero: one `static` (in `.bss`) holds it on a device.
///
/// ```
/// use tangent_core::pipeline::{Buffers, WorkspaceSizes};
///
/// const SIZES: WorkspaceSizes = WorkspaceSizes::new(64, 48, 8, 1);
/// // In firmware: `static mut BUFFERS: Buffers<u8, …> = Buffers::new();` (or a `StaticCell`).
/// let mut buffers = Box::new(Buffers::<u8, { SIZES.pixels }, { SIZES.points }>::new());
/// let workspace = buffers.workspace();
/// assert_eq!(workspace.diff.len(), 64 * 48);
/// assert_eq!(workspace.points.len(), SIZES.points);
/// assert!(workspace.seeds.len() >= SIZES.seeds);
/// ```
#[derive(Debug)]
pub struct Buffers<
    P: Pixel,
    const PIXELS: usize,
    const POINTS: usize,
    const BINS: usize = BINS_8BIT,
    const SEEDS: usize = SEEDS_752,
> {
    diff: [P; PIXELS],
    objects: Objects,
    runs: RunBuffers<SEEDS>,
    small: SmallBuffers<POINTS, BINS>,
    readout: ReadoutBuffers,
    faint: FaintBuffers,
}

impl<P: Pixel, const PIXELS: usize, const POINTS: usize, const BINS: usize, const SEEDS: usize>
    Buffers<P, PIXELS, POINTS, BINS, SEEDS>
{
    /// Zeroed buffers.
    pub const fn new() -> Self {
        Buffers {
            diff: [P::ZERO; PIXELS],
            objects: NO_OBJECTS,
            runs: RunBuffers::new(),
            small: SmallBuffers::new(),
            readout: ReadoutBuffers::new(),
            faint: FaintBuffers::new(),
        }
    }

    /// The pipeline's view of these buffers.
    pub fn workspace(&mut self) -> Workspace<'_, P> {
        Workspace::from_parts(
            &mut self.diff,
            &mut self.objects,
            &mut self.runs,
            &mut self.small,
            &mut self.readout,
            &mut self.faint,
        )
    }
}

impl<P: Pixel, const PIXELS: usize, const POINTS: usize, const BINS: usize, const SEEDS: usize>
    Default for Buffers<P, PIXELS, POINTS, BINS, SEEDS>
{
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(any(test, feature = "alloc"))]
pub use owned::OwnedBuffers;

#[cfg(any(test, feature = "alloc"))]
mod owned {
    extern crate alloc;
    use alloc::vec;
    use alloc::vec::Vec;

    use super::super::faint_sums::FaintColumn;
    use super::super::readout_fits::{ColumnTrack, ReadoutFit};
    use super::super::{Workspace, WorkspaceSizes};
    use crate::curve::CurvePoint;
    use crate::image::segment::{ObjectFeatures, Run};
    use crate::image::Pixel;
    use crate::real::{Real, Vec2, Vec3};

    /// The working memory on the heap, sized at run time for a frame (feature `alloc`): what a
    /// host uses. After a run it still holds the intermediate results (for plots).
    ///
    /// ```
    /// use tangent_core::pipeline::OwnedBuffers;
    ///
    /// let mut buffers = OwnedBuffers::<u16>::for_frame(752, 480, 10, 2);
    /// assert_eq!(buffers.workspace().histogram.len(), 1024);
    /// ```
    #[derive(Debug)]
    pub struct OwnedBuffers<P: Pixel> {
        diff: Vec<P>,
        histogram: Vec<u32>,
        candidate_runs: Vec<Run>,
        runs: Vec<Run>,
        seeds: Vec<u16>,
        objects: Vec<ObjectFeatures>,
        column_tracks: Vec<ColumnTrack>,
        readout_fits: Vec<ReadoutFit>,
        curve: Vec<CurvePoint>,
        points: Vec<Vec3>,
        sigmas: Vec<Real>,
        scratch_points: Vec<Vec2>,
        scratch_values: Vec<Real>,
        block_sums: Vec<u16>,
        faint_columns: Vec<FaintColumn>,
    }

    impl<P: Pixel> OwnedBuffers<P> {
        /// Buffers of the given sizes.
        pub fn new(sizes: WorkspaceSizes) -> Self {
            OwnedBuffers {
                diff: vec![P::ZERO; sizes.pixels],
                histogram: vec![0; sizes.histogram],
                candidate_runs: vec![Run::ZERO; sizes.runs],
                runs: vec![Run::ZERO; sizes.runs],
                seeds: vec![0; sizes.seeds],
                objects: vec![ObjectFeatures::ZERO; sizes.objects],
                column_tracks: vec![ColumnTrack::EMPTY; sizes.columns],
                readout_fits: vec![ReadoutFit::ZERO; sizes.readout_fits],
                curve: vec![CurvePoint::ZERO; sizes.points],
                points: vec![Vec3::zeros(); sizes.points],
                sigmas: vec![0.0; sizes.points],
                scratch_points: vec![Vec2::zeros(); sizes.points],
                scratch_values: vec![0.0; sizes.points],
                block_sums: vec![0; sizes.block_sums],
                faint_columns: vec![FaintColumn::ZERO; sizes.faint_columns],
            }
        }

        /// Buffers for a `width × height` frame of `bit_depth` bits and `planes` laser planes.
        pub fn for_frame(width: usize, height: usize, bit_depth: u8, planes: usize) -> Self {
            Self::new(WorkspaceSizes::new(width, height, bit_depth, planes))
        }

        /// The pipeline's view of these buffers.
        pub fn workspace(&mut self) -> Workspace<'_, P> {
            Workspace {
                diff: &mut self.diff,
                histogram: &mut self.histogram,
                candidate_runs: &mut self.candidate_runs,
                runs: &mut self.runs,
                seeds: &mut self.seeds,
                objects: &mut self.objects,
                column_tracks: &mut self.column_tracks,
                readout_fits: &mut self.readout_fits,
                curve: &mut self.curve,
                points: &mut self.points,
                sigmas: &mut self.sigmas,
                scratch_points: &mut self.scratch_points,
                scratch_values: &mut self.scratch_values,
                block_sums: &mut self.block_sums,
                faint_columns: &mut self.faint_columns,
            }
        }

        /// The difference frame of the last run.
        pub fn diff(&self) -> &[P] {
            &self.diff
        }
        /// The curve points of the last run (all planes; see `Profile::plane_points`).
        pub fn curve(&self) -> &[CurvePoint] {
            &self.curve
        }
        /// The 3-D points of the last run (all planes; see `Profile::plane_points`).
        pub fn points(&self) -> &[Vec3] {
            &self.points
        }
    }
}
