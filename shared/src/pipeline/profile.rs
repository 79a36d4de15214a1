//! The image half of the chain, stage by stage: a frame pair in, the 3-D points of each laser
//! plane's curve and a [`Profile`] summarising the image out.

use crate::calibration::{Calibration, MAX_PLANES};
use crate::curve::{self, CurvePoint};
use crate::image::segment::{self, Connectivity, ObjectFeatures};
use crate::image::subtract::{self, SubtractStats};
use crate::image::threshold::{self, ThresholdError};
use crate::image::{Frame, Pixel};
use crate::laser_plane::{triangulate, LaserPlane};
use crate::noise::{self, NoiseModel};
use crate::real::{Real, Vec2, Vec3};
use crate::solvers::result::Flags;

use super::planes::{self, UsedCurves};
use super::workspace::need;
use super::{PipelineConfig, PipelineError, Workspace};

/// Summary of the image part of a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    /// Statistics of the subtraction (ambient level, saturation).
    pub subtract: SubtractStats,
    /// Threshold applied to the difference image.
    pub threshold: u32,
    /// Noise σ of the difference image (grey levels, `threshold::difference_noise`): with a
    /// point's amplitude and width it gives the point's own σ ([`point_sigmas`]).
    pub noise: Real,
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

    /// Quality flags that the image alone tells (saturation, ambient light, other objects);
    /// `full_scale` is the laser-on frame's [`Frame::max_value`].
    pub fn image_flags(&self, full_scale: u32) -> Flags {
        let mut flags = Flags::default();
        let total: usize = self
            .plane_points
            .iter()
            .take(self.planes)
            .map(|(s, e)| e - s)
            .sum();
        if total > 0 && self.saturated_points as Real > SATURATED_FRACTION * total as Real {
            flags.insert(Flags::STRIPE_SATURATED);
        }
        if self.subtract.off_mean > BRIGHT_AMBIENT_FRACTION * full_scale as Real {
            flags.insert(Flags::AMBIENT_BRIGHT);
        }
        if self.unused_candidates > 0
            && self.largest_unused as Real >= OTHER_OBJECT_FRACTION * self.smallest_used as Real
        {
            flags.insert(Flags::OTHER_OBJECTS);
        }
        flags
    }
}

/// Writes each triangulated point's 1σ (metres) into `sigmas`, beside `points` (the
/// workspace's, same indices): the point's own stripe-centre σ from its amplitude and width
/// against the difference image's noise ([`NoiseModel::stripe_centre_px`], `curve` the
/// workspace's curve points, same indices), or the model's `noise.image_px()` where `curve`
/// does not cover the point, mapped through `∂X/∂v` of its plane
/// ([`noise::displacement_sigma`], `docs/error-model.md`, "One point" and "A point's own σ");
/// 0 where the geometry gives none. `focal_px` is the focal length of the noise model.
pub fn point_sigmas(
    profile: &Profile,
    planes: &[LaserPlane],
    noise: &NoiseModel,
    focal_px: Real,
    points: &[Vec3],
    curve: &[CurvePoint],
    sigmas: &mut [Real],
) -> Result<(), PipelineError> {
    for (plane, &(s, e)) in profile.plane_points.iter().enumerate().take(profile.planes) {
        need("sigmas", e, sigmas.len())?;
        let model = planes.get(plane).ok_or(PipelineError::Calibration)?;
        let points = profile.points(points, plane);
        let curve = curve.get(s..e).unwrap_or(&[]);
        let Some(sigmas) = sigmas.get_mut(s..e) else {
            continue;
        };
        for (i, (sigma, x)) in sigmas.iter_mut().zip(points).enumerate() {
            let sigma_px = curve.get(i).map_or(noise.image_px(), |c| {
                noise.stripe_centre_px(c.amplitude, c.width, profile.noise)
            });
            *sigma = noise::displacement_sigma(model, focal_px, *x, sigma_px).unwrap_or(0.0);
        }
    }
    Ok(())
}

/// Fraction of saturated curve points above which [`Flags::STRIPE_SATURATED`] is set.
pub const SATURATED_FRACTION: Real = 0.10;
/// Laser-off mean, as a fraction of full scale, above which [`Flags::AMBIENT_BRIGHT`] is set.
pub const BRIGHT_AMBIENT_FRACTION: Real = 0.5;
/// An unused candidate at least this fraction of the smallest used curve's pixel count sets
/// [`Flags::OTHER_OBJECTS`]; smaller ones are specks of clutter.
pub const OTHER_OBJECT_FRACTION: Real = 0.25;

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
    let (width, height) = check_inputs(off, on, calibration, ws)?;
    let pixels = width * height;

    let mut diff =
        Frame::new(&mut ws.diff[..pixels], width, height, width)?.with_bit_depth(on.bit_depth())?;
    let light = subtract_pair(on, off, &mut diff, ws.histogram, config)?;
    probe(Stage::Subtracted);

    let histogram = &ws.histogram[..light.histogram_len];
    let automatic = config.threshold.threshold(histogram)?;
    let t = config
        .floors
        .apply(automatic, light.stats.max_difference, light.noise);
    probe(Stage::Thresholded);

    // Segmentation with the 2×2 mask (thesis §5.4) and feature extraction (§5.5).
    let mut labels = Frame::new(&mut ws.labels[..pixels], width, height, width)?;
    let segmentation = segment::segment(
        &diff,
        t,
        &mut labels,
        ws.label_table,
        ws.objects,
        Connectivity::Eight,
    )?;
    let objects = &ws.objects[..segmentation.objects.min(ws.objects.len())];
    probe(Stage::Segmented);

    // Selection (§5.6) and plane assignment (docs/pipeline.md).
    let candidates = planes::select_and_assign(objects, width, calibration, config)?;
    let used = candidates.used_curves();
    probe(Stage::Selected);

    let n = extract_curves(
        &diff,
        &labels,
        objects,
        &used,
        &light.stats,
        config,
        ws.curve,
    )?;
    need("points", n, ws.points.len())?;
    probe(Stage::Extracted);

    let plane_points = group_by_plane(&mut ws.curve[..n], &used, calibration.planes.len());
    let (saturated_points, touches_edge) = smooth_and_triangulate(
        &mut ws.curve[..n],
        &plane_points,
        calibration,
        config,
        width,
        ws.points,
    )?;
    probe(Stage::Triangulated);

    let usage = candidates.usage();
    let report = candidates.report;
    Ok(Profile {
        subtract: light.stats,
        threshold: t,
        noise: light.noise,
        objects: segmentation.objects,
        candidates: report.candidates,
        unused_candidates: usage.unused + report.candidates.saturating_sub(report.selected),
        largest_unused: usage.largest_unused,
        smallest_used: usage.smallest_used,
        planes: calibration.planes.len(),
        plane_points,
        saturated_points,
        touches_edge,
    })
}

/// A valid calibration whose camera has the frames' size, and room for them in the
/// workspace. Returns `(width, height)`.
fn check_inputs<P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    ws: &Workspace<'_, P>,
) -> Result<(usize, usize), PipelineError> {
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
    need("diff", width * height, ws.diff.len())?;
    need("labels", width * height, ws.labels.len())?;
    Ok((width, height))
}

/// What the subtraction found: its statistics, the histogram's length and the difference
/// image's noise.
struct Light {
    stats: SubtractStats,
    histogram_len: usize,
    noise: Real,
}

/// Subtraction (thesis §5.3.1) and the two "is there anything to see?" tests: enough laser
/// light above the noise, and an ambient that does not blind the sensor. One pass writes the
/// difference, its statistics and its histogram (`histogram`, exactly `threshold::histogram`
/// of the difference).
// Inlined into the orchestrator, the subtraction's per-row loop keeps the frames' layout in
// registers: 8 % fewer instructions on the device than as a call (QEMU bench,
// docs/performance.md); the other stages are indifferent.
#[inline(always)]
fn subtract_pair<P: Pixel>(
    on: &Frame<P, impl AsRef<[P]>>,
    off: &Frame<P, impl AsRef<[P]>>,
    diff: &mut Frame<P, &mut [P]>,
    histogram: &mut [u32],
    config: &PipelineConfig,
) -> Result<Light, PipelineError> {
    let stats =
        subtract::subtract_with_histogram(on, off, diff, histogram).map_err(|e| match e {
            ThresholdError::Frame(e) => PipelineError::Frame(e),
            e => PipelineError::Threshold(e),
        })?;
    let full_scale = on.max_value();
    let histogram_len = threshold::histogram_len(diff).min(histogram.len());
    let noise = threshold::difference_noise(&histogram[..histogram_len]);
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
    Ok(Light {
        stats,
        histogram_len,
        noise,
    })
}

/// Subpixel curve extraction (thesis §5.7.1) of the used objects into `out`; returns the
/// number of points (column-major: each column's points in curve order).
fn extract_curves<P: Pixel>(
    diff: &Frame<P, &mut [P]>,
    labels: &Frame<u16, &mut [u16]>,
    objects: &[ObjectFeatures],
    used: &UsedCurves,
    stats: &SubtractStats,
    config: &PipelineConfig,
    out: &mut [CurvePoint],
) -> Result<usize, PipelineError> {
    let mut params = config.extract;
    if params.saturation.is_none() {
        // A clipped laser-on pixel shows as full scale minus the ambient level (see
        // ExtractParams).
        params.saturation = Some(diff.max_value().saturating_sub(stats.off_mean as u32 + 1));
    }
    // Only the union of the used objects' bounding boxes holds their labels: scanning it
    // instead of every column's `height` labels gives the same points (curve::extract_window).
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0usize, usize::MAX, 0usize);
    for &label in &used.labels[..used.len] {
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
    Ok(curve::extract_window(
        diff,
        labels,
        &used.labels[..used.len],
        x0..x1,
        y0..y1,
        &params,
        out,
    )?)
}

/// Reorders the curve points in place so that each plane's are contiguous and ordered by
/// column (a stable partition by plane: the points are already column-major); returns each
/// plane's range.
fn group_by_plane(
    points: &mut [CurvePoint],
    used: &UsedCurves,
    n_planes: usize,
) -> [(usize, usize); MAX_PLANES] {
    let mut plane_points = [(0usize, 0usize); MAX_PLANES];
    let mut start = 0;
    for (plane, range) in plane_points.iter_mut().enumerate().take(n_planes) {
        let mut end = start;
        for i in start..points.len() {
            if used.plane(points[i].curve) == Some(plane) {
                // Rotate the point to `end`, keeping the order of the others.
                points[end..=i].rotate_right(1);
                end += 1;
            }
        }
        *range = (start, end);
        start = end;
    }
    plane_points
}

/// Per plane: checks the curve's length, smooths it, notes whether it reaches the frame's
/// left or right edge, and triangulates it into `out` (same indices). Returns the number of
/// saturated points and whether some curve touches the edge.
fn smooth_and_triangulate(
    curve: &mut [CurvePoint],
    plane_points: &[(usize, usize); MAX_PLANES],
    calibration: &Calibration,
    config: &PipelineConfig,
    width: usize,
    out: &mut [Vec3],
) -> Result<(usize, bool), PipelineError> {
    let mut saturated_points = 0;
    let mut touches_edge = false;
    for (plane, &(s, e)) in plane_points
        .iter()
        .enumerate()
        .take(calibration.planes.len())
    {
        let pts = &mut curve[s..e];
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
        for (cp, xyz) in pts.iter().zip(out[s..e].iter_mut()) {
            saturated_points += cp.saturated as usize;
            *xyz = triangulate(
                &calibration.camera,
                plane_model,
                Vec2::new(cp.column as Real, cp.row),
            )?;
        }
    }
    Ok((saturated_points, touches_edge))
}
