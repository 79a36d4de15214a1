//! The measurement chain end to end: a laser-off / laser-on frame pair and a calibration in,
//! the laser curves as 3-D points per laser plane out (and, for a cylinder, its diameter).
//!
//! ```text
//! off, on ─► subtract ─► histogram ─► threshold ─► segment ─► select ─► assign to planes
//!        ─► subpixel curve per column ─► smooth ─► undistort + triangulate ─► 3-D points
//! ```
//!
//! Every buffer lives in a caller-owned [`Workspace`]; after a call the workspace still holds
//! the intermediate results (difference frame, labels, curve points, 3-D points), so a host can
//! plot them and a device can report them. The steps and the choices made here (threshold
//! floor, plane assignment, fragment merging, frame-edge rule) are derived in
//! `docs/pipeline.md`.

use core::fmt;

mod buffers;

#[cfg(any(test, feature = "alloc"))]
pub use buffers::OwnedBuffers;
pub use buffers::{
    Buffers, Objects, SmallBuffers, BINS_8BIT, LABEL_TABLE_LEN, MAX_OBJECTS, NO_OBJECTS,
};

use crate::calibration::{Calibration, MAX_PLANES};
use crate::curve::{self, CurveError, CurvePoint, ExtractParams, SmoothParams, MAX_CURVES};
use crate::image::segment::{self, Connectivity, ObjectFeatures, SegmentError};
use crate::image::select::{self, SelectionParams};
use crate::image::subtract::{self, SubtractStats};
use crate::image::threshold::{self, Floors, ThresholdError, ThresholdMethod};
use crate::image::{Frame, FrameError, Pixel};
use crate::laser_plane::{triangulate, TriangulationError};
use crate::noise::{self, NoiseModel};
use crate::real::{Real, Vec2, Vec3};
use crate::solvers::cylinder::{self, CylinderInput, CylinderParams, CylinderSolution, Flags};
use crate::solvers::SolveError;

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
impl From<TriangulationError> for PipelineError {
    fn from(e: TriangulationError) -> Self {
        PipelineError::Triangulation(e)
    }
}

/// Caller-owned working memory of the pipeline: borrowed from a [`Buffers`] (static),
/// an `OwnedBuffers` (heap, feature `alloc`), or any slices of the [`WorkspaceSizes`].
#[derive(Debug)]
pub struct Workspace<'a, P: Pixel> {
    /// Difference frame (`width × height`).
    pub diff: &'a mut [P],
    /// Segmentation labels (`width × height`).
    pub labels: &'a mut [u16],
    /// Histogram bins (`2^bit_depth`).
    pub histogram: &'a mut [u32],
    /// Equivalence table of the segmentation.
    pub label_table: &'a mut [u16],
    /// Features of the objects found.
    pub objects: &'a mut [ObjectFeatures],
    /// Curve points, all planes (about `width × planes`).
    pub curve: &'a mut [CurvePoint],
    /// 3-D points, grouped by plane in [`Profile::plane_points`] order (same length as `curve`).
    pub points: &'a mut [Vec3],
    /// 1σ of each 3-D point (metres, along its noise direction; same indexing as `points`),
    /// from [`point_sigmas`]: what the solvers weigh the points by.
    pub sigmas: &'a mut [Real],
    /// Solver scratch: 2-D points (same length as `curve`).
    pub scratch_points: &'a mut [Vec2],
    /// Solver scratch: residuals (same length as `curve`).
    pub scratch_values: &'a mut [Real],
}

/// Buffer lengths a [`Workspace`] needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WorkspaceSizes {
    /// Pixels of `diff` and `labels`.
    pub pixels: usize,
    /// Histogram bins.
    pub histogram: usize,
    /// Equivalence-table entries.
    pub label_table: usize,
    /// Object-feature entries.
    pub objects: usize,
    /// Curve, 3-D point, point-σ and solver-scratch entries.
    pub points: usize,
}

impl WorkspaceSizes {
    /// Sizes for a `width × height` frame of `bit_depth` bits with `planes` laser planes.
    ///
    /// The label table is sized for a cluttered scene (4096 provisional labels), not for the
    /// pathological worst case (a checkerboard needs `width × height / 2`): a scene with more
    /// blobs than that is reported as `Segment(TooManyLabels)` instead of being measured.
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
            label_table: LABEL_TABLE_LEN,
            objects: MAX_OBJECTS,
            points: width * planes * 2,
        }
    }
}

/// Summary of the image part of a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    /// Statistics of the subtraction (ambient level, saturation).
    pub subtract: SubtractStats,
    /// Threshold applied to the difference image.
    pub threshold: u32,
    /// Objects found by the segmentation.
    pub objects: usize,
    /// Objects that passed the selection criteria.
    pub candidates: usize,
    /// Candidates that were not used for any plane (other objects in view).
    pub unused_candidates: usize,
    /// Largest unused candidate, in pixels (0 if none): a second trunk or clutter.
    pub largest_unused: u32,
    /// Pixel count of the smallest object used.
    pub smallest_used: u32,
    /// Number of planes with a curve (`calibration.planes.len()`).
    pub planes: usize,
    /// For each plane, the range `start..end` of its points in `Workspace::points` and
    /// `Workspace::curve` (ordered by column).
    pub plane_points: [(usize, usize); MAX_PLANES],
    /// Curve points whose stripe saturated.
    pub saturated_points: usize,
    /// Some plane's curve reaches the left or right frame edge.
    pub touches_edge: bool,
}

impl Profile {
    /// The entries of plane `plane` in a per-point buffer of the workspace (`points`: its 3-D
    /// points, camera frame, metres, ordered by image column; `sigmas`: their 1σ).
    pub fn points<'w, T>(&self, points: &'w [T], plane: usize) -> &'w [T] {
        match self.plane_points.get(plane) {
            Some(&(s, e)) if s <= e && e <= points.len() => &points[s..e],
            _ => &[],
        }
    }
}

fn need(buffer: &'static str, needed: usize, actual: usize) -> Result<(), PipelineError> {
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

/// Fraction of saturated curve points above which [`Flags::STRIPE_SATURATED`] is set.
pub const SATURATED_FRACTION: Real = 0.10;
/// Laser-off mean, as a fraction of full scale, above which [`Flags::AMBIENT_BRIGHT`] is set.
pub const BRIGHT_AMBIENT_FRACTION: Real = 0.5;
/// An unused candidate at least this fraction of the smallest used curve's pixel count sets
/// [`Flags::OTHER_OBJECTS`]; smaller ones are specks of clutter.
pub const OTHER_OBJECT_FRACTION: Real = 0.25;

/// A stem measurement: the solver's answer, the image summary, and the combined flags.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StemMeasurement {
    /// The solver's answer (diameter, uncertainty, method, tilt, …). Its `flags` include
    /// the image flags below.
    pub solution: CylinderSolution,
    /// The image part of the chain.
    pub profile: Profile,
}

/// Quality flags that the image alone tells (saturation, ambient light, other objects).
pub fn image_flags(profile: &Profile, full_scale: u32) -> Flags {
    let mut flags = Flags::default();
    let total: usize = profile
        .plane_points
        .iter()
        .take(profile.planes)
        .map(|(s, e)| e - s)
        .sum();
    if total > 0 && profile.saturated_points as Real > SATURATED_FRACTION * total as Real {
        flags.insert(Flags::STRIPE_SATURATED);
    }
    if profile.subtract.off_mean > BRIGHT_AMBIENT_FRACTION * full_scale as Real {
        flags.insert(Flags::AMBIENT_BRIGHT);
    }
    if profile.unused_candidates > 0
        && profile.largest_unused as Real >= OTHER_OBJECT_FRACTION * profile.smallest_used as Real
    {
        flags.insert(Flags::OTHER_OBJECTS);
    }
    flags
}

/// Measures a stem: [`extract_profile`], then [`solve_stem`] on its points.
pub fn measure_stem<P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    config: &PipelineConfig,
    params: &CylinderParams,
    ws: &mut Workspace<'_, P>,
) -> Result<StemMeasurement, PipelineError> {
    let profile = extract_profile(off, on, calibration, config, ws)?;
    solve_stem(&profile, on.max_value(), calibration, params, ws)
}

/// The solver half of [`measure_stem`]: the cylinder solver ([`cylinder::solve`]:
/// three-tangent, circle or cylinder fit, chosen by the data) on the points of every plane
/// that [`extract_profile`] left in `ws`, with the [`image_flags`] added (`full_scale`: the
/// laser-on frame's [`Frame::max_value`]). A curve that runs off the frame is
/// [`PipelineError::OutsideFrame`]. Separate so that the two halves can be timed apart.
pub fn solve_stem<P: Pixel>(
    profile: &Profile,
    full_scale: u32,
    calibration: &Calibration,
    params: &CylinderParams,
    ws: &mut Workspace<'_, P>,
) -> Result<StemMeasurement, PipelineError> {
    if profile.touches_edge {
        return Err(PipelineError::OutsideFrame);
    }
    let n_planes = profile.planes.min(MAX_PLANES).min(calibration.planes.len());
    point_sigmas(profile, calibration, &params.noise, params.focal_px, ws)?;
    let mut curves: [&[Vec3]; MAX_PLANES] = [&[]; MAX_PLANES];
    let mut sigmas: [&[Real]; MAX_PLANES] = [&[]; MAX_PLANES];
    for (k, (c, s)) in curves
        .iter_mut()
        .zip(&mut sigmas)
        .enumerate()
        .take(n_planes)
    {
        *c = profile.points(ws.points, k);
        *s = profile.points(ws.sigmas, k);
    }
    let input = CylinderInput {
        curves: &curves[..n_planes],
        sigmas: &sigmas[..n_planes],
        planes: &calibration.planes[..n_planes],
    };
    let scratch = cylinder::Scratch {
        points: &mut *ws.scratch_points,
        values: &mut *ws.scratch_values,
    };
    let mut solution = cylinder::solve(&input, params, scratch)?;
    solution.flags.insert(image_flags(profile, full_scale));
    Ok(StemMeasurement {
        solution,
        profile: *profile,
    })
}

/// Writes each triangulated point's 1σ (metres) into `ws.sigmas`, beside `ws.points`: the
/// stripe-centre noise `noise.image_px()` mapped through `∂X/∂v` of its plane
/// ([`noise::displacement_sigma`], `docs/error-model.md`, "One point"); 0 where the geometry
/// gives none. `focal_px` is the focal length of the noise model ([`CylinderParams::focal_px`]).
pub fn point_sigmas<P: Pixel>(
    profile: &Profile,
    calibration: &Calibration,
    noise: &NoiseModel,
    focal_px: Real,
    ws: &mut Workspace<'_, P>,
) -> Result<(), PipelineError> {
    let sigma_px = noise.image_px();
    for (plane, &(s, e)) in profile.plane_points.iter().enumerate().take(profile.planes) {
        need("sigmas", e, ws.sigmas.len())?;
        let model = calibration
            .plane(plane)
            .map_err(|_| PipelineError::Calibration)?;
        let points = profile.points(ws.points, plane);
        let Some(sigmas) = ws.sigmas.get_mut(s..e) else {
            continue;
        };
        for (sigma, x) in sigmas.iter_mut().zip(points) {
            *sigma = noise::displacement_sigma(model, focal_px, *x, sigma_px).unwrap_or(0.0);
        }
    }
    Ok(())
}

/// One selected object and what the plane assignment needs of it.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    label: u16,
    min_x: u16,
    max_x: u16,
    mean_row: Real,
    pixels: u32,
    /// Plane it was assigned to, or `usize::MAX`.
    plane: usize,
}

/// Runs the image part of the chain and triangulates the curves: `off` and `on` are the
/// laser-off and laser-on frames (all of the calibration's planes lit in `on`).
///
/// On success the workspace holds the difference frame, the labels, the curve points and the
/// 3-D points; the returned [`Profile`] says where each plane's points are.
pub fn extract_profile<P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    config: &PipelineConfig,
    ws: &mut Workspace<'_, P>,
) -> Result<Profile, PipelineError> {
    extract_profile_probed(off, on, calibration, config, ws, |_| {})
}

/// A point of [`extract_profile`] that its probe is told about, each when its stage is done.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Subtraction, histogram and the darkness tests.
    Subtracted,
    /// Threshold chosen.
    Thresholded,
    /// Segmentation and object features.
    Segmented,
    /// Selection and plane assignment.
    Selected,
    /// Subpixel curve extracted.
    Extracted,
    /// Curves smoothed and triangulated: the profile is complete.
    Triangulated,
}

/// [`extract_profile`] that calls `probe` as each [`Stage`] completes (the firmware's
/// instruction-count benchmark time-stamps them; `docs/performance.md`). With an empty
/// closure it compiles to [`extract_profile`].
pub fn extract_profile_probed<P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    config: &PipelineConfig,
    ws: &mut Workspace<'_, P>,
    mut probe: impl FnMut(Stage),
) -> Result<Profile, PipelineError> {
    calibration
        .validate()
        .map_err(|_| PipelineError::Calibration)?;
    let cam = &calibration.camera;
    let (width, height) = (on.width(), on.height());
    if (cam.width as usize, cam.height as usize) != (width, height) {
        return Err(PipelineError::FrameSizeMismatch {
            calibrated: (cam.width, cam.height),
            actual: (width, height),
        });
    }
    on.check_same_size(off)?;
    let pixels = width * height;
    need("diff", pixels, ws.diff.len())?;
    need("labels", pixels, ws.labels.len())?;
    let n_planes = calibration.planes.len();

    // 1. Subtraction (thesis §5.3.1).
    let mut diff =
        Frame::new(&mut ws.diff[..pixels], width, height, width)?.with_bit_depth(on.bit_depth())?;
    // One pass writes the difference, its statistics and its histogram (`ws.histogram`,
    // exactly `threshold::histogram` of the difference).
    let stats = subtract::subtract_with_histogram(on, off, &mut diff, ws.histogram).map_err(
        |e| match e {
            ThresholdError::Frame(e) => PipelineError::Frame(e),
            e => PipelineError::Threshold(e),
        },
    )?;
    let full_scale = on.max_value();
    // The noise of the difference image, from its histogram (needed for both tests below).
    let hist_len = threshold::histogram_len(&diff).min(ws.histogram.len());
    let noise = threshold::difference_noise(&ws.histogram[..hist_len]);
    if !config.floors.is_lit(stats.max_difference, noise) {
        return Err(PipelineError::NoLaserLight {
            max_difference: stats.max_difference,
        });
    }
    // The off frame's mean at full scale means most of it is clipped: nothing can be seen.
    if stats.off_mean >= 0.9 * full_scale as Real {
        return Err(PipelineError::AmbientSaturated {
            fraction: stats.off_mean / full_scale as Real,
        });
    }

    probe(Stage::Subtracted);

    // 2. Threshold (§5.3.2), floored so that sensor noise never becomes foreground: at
    //    least `threshold_snr` noise σ's and `min_threshold` grey levels.
    let auto = config.threshold.threshold(&ws.histogram[..hist_len])?;
    let t = config.floors.apply(auto, stats.max_difference, noise);

    probe(Stage::Thresholded);

    // 3. Segmentation with the 2×2 mask (§5.4) and feature extraction (§5.5).
    let mut labels = Frame::new(&mut ws.labels[..pixels], width, height, width)?;
    let seg = segment::segment(
        &diff,
        t,
        &mut labels,
        ws.label_table,
        ws.objects,
        Connectivity::Eight,
    )?;
    let objects = &ws.objects[..seg.objects.min(ws.objects.len())];

    probe(Stage::Segmented);

    // 4. Selection (§5.6): the per-object criteria, nearest to the central column first.
    let mut sel_params = config.selection;
    let keep = (config.max_fragments * n_planes).clamp(1, MAX_CURVES);
    sel_params.max_objects = keep;
    let mut selected = [0u16; MAX_CURVES];
    let report = select::select(objects, width, &sel_params, &mut selected);
    if report.selected == 0 {
        return Err(PipelineError::NoCurve);
    }
    let mut cands = [Candidate {
        label: 0,
        min_x: 0,
        max_x: 0,
        mean_row: 0.0,
        pixels: 0,
        plane: usize::MAX,
    }; MAX_CURVES];
    let n_cand = report.selected.min(MAX_CURVES);
    for (c, &label) in cands.iter_mut().zip(&selected[..n_cand]) {
        if let Some(f) = objects.iter().find(|f| f.label == label) {
            *c = Candidate {
                label,
                min_x: f.min_x,
                max_x: f.max_x,
                mean_row: f
                    .geometric_centroid()
                    .map(|(_, y)| y)
                    .unwrap_or(f.min_y as Real),
                pixels: f.pixel_count,
                plane: usize::MAX,
            };
        }
    }
    let cands = &mut cands[..n_cand];

    // 5. Assign candidates to planes (docs/pipeline.md §plane assignment).
    assign_planes(cands, calibration, config);
    let used: usize = cands.iter().filter(|c| c.plane != usize::MAX).count();
    if cands.iter().take(1).all(|c| c.plane == usize::MAX) {
        return Err(PipelineError::NoCurve);
    }

    probe(Stage::Selected);

    // 6. Subpixel curve extraction (§5.7.1) of the used candidates, then per plane: sort by
    //    column (extraction is column-major, so points already are), smooth and triangulate.
    let mut labels_used = [0u16; MAX_CURVES];
    let mut plane_of_curve = [usize::MAX; MAX_CURVES];
    let mut n_used = 0;
    for c in cands.iter().filter(|c| c.plane != usize::MAX) {
        labels_used[n_used] = c.label;
        plane_of_curve[n_used] = c.plane;
        n_used += 1;
    }
    let mut extract_params = config.extract;
    if extract_params.saturation.is_none() {
        // A clipped laser-on pixel shows as full scale minus the ambient level (see ExtractParams).
        extract_params.saturation = Some(full_scale.saturating_sub(stats.off_mean as u32 + 1));
    }
    // Only the union of the used objects' bounding boxes holds their labels: scanning it
    // instead of every column's `height` labels gives the same points (curve::extract_window).
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0usize, usize::MAX, 0usize);
    for &label in &labels_used[..n_used] {
        // features[i].label == i + 1 (segment::Segmentation).
        if let Some(f) = objects
            .get((label as usize).wrapping_sub(1))
            .filter(|f| f.pixel_count > 0)
        {
            x0 = x0.min(f.min_x as usize);
            x1 = x1.max(f.max_x as usize + 1);
            y0 = y0.min(f.min_y as usize);
            y1 = y1.max(f.max_y as usize + 1);
        }
    }
    let n = curve::extract_window(
        &diff,
        &labels,
        &labels_used[..n_used],
        x0..x1,
        y0..y1,
        &extract_params,
        ws.curve,
    )?;
    need("points", n, ws.points.len())?;
    probe(Stage::Extracted);

    // Reorder in place so that each plane's points are contiguous and ordered by column:
    // a stable partition by plane (curve points are already column-major).
    let curve_pts = &mut ws.curve[..n];
    let mut plane_points = [(0usize, 0usize); MAX_PLANES];
    let mut start = 0;
    for (plane, range) in plane_points.iter_mut().enumerate().take(n_planes) {
        let mut end = start;
        for i in start..n {
            let p = curve_pts[i];
            if plane_of_curve.get(p.curve as usize).copied() == Some(plane) {
                // Rotate the point to `end`, keeping the order of the others.
                curve_pts[end..=i].rotate_right(1);
                end += 1;
            }
        }
        *range = (start, end);
        start = end;
    }

    let mut saturated_points = 0;
    let mut touches_edge = false;
    let mut smallest_used = u32::MAX;
    for c in cands.iter().filter(|c| c.plane != usize::MAX) {
        smallest_used = smallest_used.min(c.pixels);
    }
    for (plane, &(s, e)) in plane_points.iter().enumerate().take(n_planes) {
        let pts = &mut curve_pts[s..e];
        if pts.len() < config.min_points {
            return Err(PipelineError::CurveTooShort {
                plane,
                points: pts.len(),
            });
        }
        curve::smooth(pts, &config.smooth)?;
        let (first, last) = (pts[0].column, pts[pts.len() - 1].column);
        if first <= config.edge_margin
            || (last as usize) + (config.edge_margin as usize) + 1 >= width
        {
            touches_edge = true;
        }
        let plane_model = calibration
            .plane(plane)
            .map_err(|_| PipelineError::Calibration)?;
        for (cp, xyz) in pts.iter().zip(ws.points[s..e].iter_mut()) {
            saturated_points += cp.saturated as usize;
            *xyz = triangulate(cam, plane_model, Vec2::new(cp.column as Real, cp.row))?;
        }
    }

    probe(Stage::Triangulated);

    let (unused_candidates, largest_unused) = cands
        .iter()
        .filter(|c| c.plane == usize::MAX)
        .fold((0, 0), |(k, m), c| (k + 1, m.max(c.pixels)));
    Ok(Profile {
        subtract: stats,
        threshold: t,
        objects: seg.objects,
        candidates: report.candidates,
        unused_candidates: unused_candidates + report.candidates.saturating_sub(report.selected),
        largest_unused,
        smallest_used: if used == 0 { 0 } else { smallest_used },
        planes: n_planes,
        plane_points,
        saturated_points,
        touches_edge,
    })
}

/// Assigns candidates (sorted nearest to the central column first) to laser planes.
///
/// The first candidate is the aimed object's curve in some plane. With one plane it is that
/// plane's. With several planes, the candidates overlapping it in columns are the other planes'
/// curves on the same object; they are sorted by mean row and matched to the planes sorted by
/// the row at which each plane is seen on the central column at mid range — parallel planes
/// keep their image order at every depth (docs/pipeline.md). Then fragments: a remaining
/// candidate whose column span continues an assigned curve's within `max_fragment_gap` columns
/// and whose mean row is within `max_fragment_step` rows joins that plane.
fn assign_planes(cands: &mut [Candidate], calibration: &Calibration, config: &PipelineConfig) {
    let n_planes = calibration.planes.len();
    let Some(first) = cands.first().copied() else {
        return;
    };
    // Candidates that share columns with the first one (including itself), by mean row.
    let mut group = [usize::MAX; MAX_PLANES];
    let mut g = 0;
    for (i, c) in cands.iter().enumerate() {
        let overlap = c.min_x.max(first.min_x) <= c.max_x.min(first.max_x);
        if overlap && g < n_planes && g < MAX_PLANES {
            group[g] = i;
            g += 1;
        }
    }
    let group = &mut group[..g];
    group.sort_unstable_by(|&a, &b| {
        cands[a]
            .mean_row
            .partial_cmp(&cands[b].mean_row)
            .unwrap_or(core::cmp::Ordering::Equal)
    });
    // Planes by image row on the central column, at the depth where plane 0 sees the first
    // candidate (the order is the same at every depth for parallel planes).
    let cam = &calibration.camera;
    let depth = cam
        .pixel_to_ray(Vec2::new(cam.cx, first.mean_row))
        .ok()
        .and_then(|ray| {
            calibration
                .planes
                .first()
                .and_then(|p0| p0.intersect_ray(ray).ok())
        })
        .map(|p| p.z)
        .unwrap_or(1.5);
    let mut order = [0usize; MAX_PLANES];
    let mut rows = [Real::INFINITY; MAX_PLANES];
    for (k, plane) in calibration.planes.iter().enumerate().take(MAX_PLANES) {
        order[k] = k;
        // The point of plane k with x = 0 at that depth: n.y·y = offset − n.z·depth.
        let n = plane.normal;
        if n.y.abs() > 1e-6 {
            let y = (plane.offset - n.z * depth) / n.y;
            if let Ok(px) = cam.project(Vec3::new(0.0, y, depth)) {
                rows[k] = px.y;
            }
        }
    }
    let planes_order = &mut order[..n_planes.min(MAX_PLANES)];
    planes_order.sort_unstable_by(|&a, &b| {
        rows[a]
            .partial_cmp(&rows[b])
            .unwrap_or(core::cmp::Ordering::Equal)
    });
    if group.len() == n_planes {
        for (&ci, &plane) in group.iter().zip(planes_order.iter()) {
            cands[ci].plane = plane;
        }
    } else if n_planes == 1 {
        cands[0].plane = 0;
    } else {
        // Fewer curves than planes on the aimed object: each goes to the plane seen nearest
        // its row; the plane left without a curve is reported as too short by the caller.
        for &ci in group.iter() {
            // The nearest plane by row.
            let mut best = 0;
            let mut best_d = Real::INFINITY;
            for &k in planes_order.iter() {
                let d = (rows[k] - cands[ci].mean_row).abs();
                if d < best_d {
                    best_d = d;
                    best = k;
                }
            }
            cands[ci].plane = best;
        }
    }
    // Fragments: join remaining candidates that continue an assigned curve.
    let mut changed = true;
    while changed {
        changed = false;
        for i in 0..cands.len() {
            if cands[i].plane != usize::MAX {
                continue;
            }
            let c = cands[i];
            let mut join = usize::MAX;
            for a in cands.iter().filter(|a| a.plane != usize::MAX) {
                let gap = if c.min_x > a.max_x {
                    c.min_x - a.max_x
                } else if a.min_x > c.max_x {
                    a.min_x - c.max_x
                } else {
                    u16::MAX // overlapping columns: another object, not a fragment
                };
                if gap <= config.max_fragment_gap
                    && (c.mean_row - a.mean_row).abs() <= config.max_fragment_step
                {
                    join = a.plane;
                    break;
                }
            }
            if join != usize::MAX {
                cands[i].plane = join;
                changed = true;
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unnecessary_cast)]
mod tests {
    extern crate std;
    use super::*;
    use crate::camera::Camera;
    use crate::laser_plane::LaserPlane;
    use std::vec;
    use std::vec::Vec;

    const W: usize = 752;
    const H: usize = 480;

    fn buffers(planes: usize) -> OwnedBuffers<u8> {
        OwnedBuffers::for_frame(W, H, 8, planes)
    }

    fn calibration(planes: usize) -> Calibration {
        let full = Calibration::reference_design();
        let list: Vec<LaserPlane> = full.planes.iter().copied().take(planes).collect();
        Calibration::new(1, Camera::reference_design(), &list).unwrap()
    }

    /// The row where `plane` crosses column `u` on a fronto-parallel wall at depth `z`
    /// (undistorted reference camera): the ray through (u, v) hits the wall at
    /// (x, y) = (u − cx, v − cy)·z/f, and the plane n·X = d gives y analytically.
    fn wall_row(cal: &Calibration, plane: usize, u: Real, z: Real) -> Real {
        let cam = &cal.camera;
        let p = cal.planes[plane];
        let x = (u - cam.cx) * z / cam.fx;
        let y = (p.offset - p.normal.x * x - p.normal.z * z) / p.normal.y;
        cam.cy + cam.fy * y / z
    }

    /// Renders the stripes of the given planes on a wall at depth `z` over columns
    /// `cols`: a Gaussian profile integrated over each pixel (erf-free: 8 sub-samples per
    /// pixel), amplitude `amp` over an ambient `ambient`.
    fn render(
        cal: &Calibration,
        planes: &[usize],
        z: Real,
        cols: core::ops::Range<usize>,
        amp: Real,
        ambient: u8,
    ) -> (Vec<u8>, Vec<u8>) {
        let off = vec![ambient; W * H];
        let mut on = off.clone();
        let sigma = 1.3;
        for &k in planes {
            for u in cols.clone() {
                let v0 = wall_row(cal, k, u as Real, z);
                for r in 0..H {
                    let mut acc = 0.0;
                    for s in 0..8 {
                        let y = r as Real - 0.5 + (s as Real + 0.5) / 8.0;
                        acc += (-(y - v0) * (y - v0) / (2.0 * sigma * sigma)).exp();
                    }
                    let val = on[r * W + u] as Real + amp * acc / 8.0;
                    on[r * W + u] = val.round().min(255.0) as u8;
                }
            }
        }
        (off, on)
    }

    fn frames<'a>(off: &'a [u8], on: &'a [u8]) -> (Frame<u8, &'a [u8]>, Frame<u8, &'a [u8]>) {
        (
            Frame::new(off, W, H, W).unwrap(),
            Frame::new(on, W, H, W).unwrap(),
        )
    }

    #[test]
    fn wall_points_lie_on_the_wall() {
        let cal = calibration(1);
        let z = 1.2;
        let (off, on) = render(&cal, &[0], z, 150..600, 150.0, 12);
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(1);
        let mut ws = b.workspace();
        let prof =
            extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap();
        let pts = prof.points(ws.points, 0);
        // Every column of the stripe gives a point (the estimator needs the window inside the
        // frame, which holds here).
        assert_eq!(pts.len(), 450);
        // Depth error: the estimator's bias (≤ 0.02 px) plus 8-bit rounding of a 150-level
        // stripe (≈ 0.3/150·σ ≈ 0.003 px) times ∂z/∂v = z²/(e·f) = 14.4 mm/px gives ≤ 0.35 mm.
        let tol = 0.35e-3;
        for p in pts {
            assert!((p.z - z).abs() < tol, "z = {} at x = {}", p.z, p.x);
        }
        // Lateral extent: columns 150 and 599 at depth z.
        let cam = &cal.camera;
        assert!((pts[0].x - (150.0 - cam.cx) * z / cam.fx).abs() < 1e-4);
        assert!(!prof.touches_edge);
        assert_eq!(prof.saturated_points, 0);
    }

    #[test]
    fn two_planes_are_assigned_in_image_order() {
        let cal = calibration(2);
        let z = 0.9;
        let (off, on) = render(&cal, &[0, 1], z, 200..500, 120.0, 5);
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(2);
        let mut ws = b.workspace();
        let prof =
            extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap();
        for k in 0..2 {
            let pts = prof.points(ws.points, k);
            assert_eq!(pts.len(), 300, "plane {k}");
            for p in pts {
                // Points of the right plane triangulate onto the wall; with the planes
                // swapped they would land centimetres away (the planes are 5 cm apart).
                assert!((p.z - z).abs() < 0.5e-3, "plane {k}: z = {}", p.z);
            }
        }
    }

    #[test]
    fn dark_pair_is_no_laser_light() {
        let cal = calibration(1);
        let (off, on) = render(&cal, &[0], 1.0, 100..101, 0.0, 30);
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(1);
        let err = extract_profile(
            &off_f,
            &on_f,
            &cal,
            &PipelineConfig::default(),
            &mut b.workspace(),
        )
        .unwrap_err();
        assert_eq!(err, PipelineError::NoLaserLight { max_difference: 0 });
    }

    #[test]
    fn saturated_ambient_is_reported() {
        let cal = calibration(1);
        let off = vec![255u8; W * H];
        let on = off.clone();
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(1);
        let cfg = PipelineConfig {
            floors: Floors {
                min_contrast: 0,
                ..Floors::default()
            },
            ..PipelineConfig::default()
        };
        let err = extract_profile(&off_f, &on_f, &cal, &cfg, &mut b.workspace()).unwrap_err();
        assert!(
            matches!(err, PipelineError::AmbientSaturated { .. }),
            "{err:?}"
        );
    }

    #[test]
    fn a_vertical_blob_is_not_a_curve() {
        let cal = calibration(1);
        let off = vec![10u8; W * H];
        let mut on = off.clone();
        for r in 100..300 {
            for c in 370..376 {
                on[r * W + c] = 200;
            }
        }
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(1);
        let err = extract_profile(
            &off_f,
            &on_f,
            &cal,
            &PipelineConfig::default(),
            &mut b.workspace(),
        )
        .unwrap_err();
        assert_eq!(err, PipelineError::NoCurve);
    }

    #[test]
    fn curve_cut_by_the_frame_edge_is_flagged() {
        let cal = calibration(1);
        let (off, on) = render(&cal, &[0], 1.0, 0..300, 100.0, 10);
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(1);
        let mut ws = b.workspace();
        let prof =
            extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap();
        assert!(prof.touches_edge);
    }

    #[test]
    fn wrong_sizes_and_small_workspaces_are_errors() {
        let cal = calibration(1);
        let small = vec![0u8; 100 * 100];
        let f = Frame::new(&small, 100, 100, 100).unwrap();
        let mut b = buffers(1);
        let err = extract_profile(&f, &f, &cal, &PipelineConfig::default(), &mut b.workspace())
            .unwrap_err();
        assert_eq!(
            err,
            PipelineError::FrameSizeMismatch {
                calibrated: (752, 480),
                actual: (100, 100)
            }
        );

        let (off, on) = render(&cal, &[0], 1.0, 100..400, 100.0, 10);
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(1);
        let mut ws = b.workspace();
        ws.points = &mut core::mem::take(&mut ws.points)[..10];
        let err =
            extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap_err();
        assert!(
            matches!(
                err,
                PipelineError::WorkspaceTooSmall {
                    buffer: "points",
                    ..
                }
            ),
            "{err:?}"
        );
    }

    /// A dim stripe (12 DN) over noise σ ≈ 0.8 DN passes the noise-relative darkness test
    /// (`threshold::Floors::is_lit`); the same noise alone does not.
    #[test]
    fn contrast_test_is_relative_to_the_noise() {
        let cal = calibration(1);
        let (off, mut on) = render(&cal, &[0], 2.5, 300..450, 12.0, 4);
        // ±1 DN noise on the laser-on frame (σ ≈ 0.8 DN).
        for (i, v) in on.iter_mut().enumerate() {
            let n = ((i * 2_654_435_761usize) >> 7) % 3;
            *v = (*v as i32 + n as i32 - 1).clamp(0, 255) as u8;
        }
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(1);
        let mut ws = b.workspace();
        // With the absolute floor lowered (the default keeps 20 DN, see PipelineConfig), the
        // noise-relative test alone decides: 13 DN over σ̂ < 1 DN is light.
        let cfg = PipelineConfig {
            floors: Floors {
                min_contrast: 8,
                ..Floors::default()
            },
            ..PipelineConfig::default()
        };
        let prof = extract_profile(&off_f, &on_f, &cal, &cfg, &mut ws).unwrap();
        assert!(
            prof.points(ws.points, 0).len() >= 140,
            "{:?}",
            prof.plane_points
        );
        // Pure noise of the same level is dark.
        let (off_f, _) = frames(&off, &on);
        let noisy: Vec<u8> = off
            .iter()
            .enumerate()
            .map(|(i, &v)| (v as i32 + (((i * 2_654_435_761usize) >> 7) % 3) as i32 - 1) as u8)
            .collect();
        let noisy_f = Frame::new(&noisy, W, H, W).unwrap();
        let err = extract_profile(&off_f, &noisy_f, &cal, &cfg, &mut ws).unwrap_err();
        assert!(matches!(err, PipelineError::NoLaserLight { .. }), "{err:?}");
    }
}
