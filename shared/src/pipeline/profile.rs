//! The image half of the chain, stage by stage: a frame pair in, the 3-D points of each laser
//! plane's curve and a [`Profile`] summarising the image out.

use crate::calibration::{Calibration, MAX_PLANES};
use crate::curve::{self, CurvePoint, MAX_CURVES, NO_SEED};
use crate::image::segment::{ObjectFeatures, Run};
use crate::image::subtract::SubtractStats;
use crate::image::{Frame, Pixel};
use crate::laser_plane::{triangulate, LaserPlane};
use crate::noise::{self, NoiseModel};
use crate::real::{Real, Vec2, Vec3};
use crate::solvers::result::Flags;

use super::planes::{self, UsedCurves};
use super::readout_fits::ReadoutFits;
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
    /// The faint-stripe search read the curves ([`super::faint`]): no threshold separated
    /// the stripe from the noise ([`Flags::FAINT_STRIPE`]).
    pub faint: bool,
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

    /// Where the planes' points end in the workspace's per-point buffers: every entry past it
    /// is free for the solver.
    pub fn extent(&self) -> usize {
        self.plane_points
            .iter()
            .take(self.planes)
            .map(|&(_, end)| end)
            .max()
            .unwrap_or(0)
    }

    /// Quality flags that the image alone tells (saturation, ambient light, other objects, a
    /// stripe only the faint search found);
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
        if self.faint {
            flags.insert(Flags::FAINT_STRIPE);
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
    // Per point only what depends on the point (the same operations as
    // `stripe_centre_px` and `displacement_sigma`).
    let centre = noise.stripe_centre(profile.noise);
    for (plane, &(s, e)) in profile.plane_points.iter().enumerate().take(profile.planes) {
        need("sigmas", e, sigmas.len())?;
        let model = planes.get(plane).ok_or(PipelineError::Calibration)?;
        let per_pixel = noise::PerPixel::of(model, focal_px);
        let points = profile.points(points, plane);
        let curve = curve.get(s..e).unwrap_or(&[]);
        let Some(sigmas) = sigmas.get_mut(s..e) else {
            continue;
        };
        for (i, (sigma, x)) in sigmas.iter_mut().zip(points).enumerate() {
            let sigma_px = curve
                .get(i)
                .map_or(centre.image_px(), |c| centre.px(c.amplitude, c.width));
            *sigma = per_pixel.sigma(*x, sigma_px).unwrap_or(0.0);
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
    /// Curves grown along their stripes (`grow`; immediate when the configuration does not
    /// grow them).
    Grown,
    /// Curves smoothed and triangulated: the profile is complete.
    Triangulated,
    /// The faint-stripe search (`faint`) ran after the thresholded chain found no stripe
    /// (probed only when it ran; it follows whichever stage the thresholded chain reached).
    FaintSearched,
}

/// What the streaming front end knows of the pair once the laser-on frame is subtracted: the
/// difference frame's layout (in `Workspace::diff`) and the subtraction's statistics. The
/// thresholded chain ([`Segmented`]) and the faint search (`faint`) both start from it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Subtracted {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) bit_depth: u8,
    pub(super) stats: SubtractStats,
    /// Noise σ of the difference image (grey levels).
    pub(super) noise: Real,
    /// Block width of the faint search's block sums gathered during the read-out
    /// (`Workspace::block_sums`), 0 when none were.
    pub(super) block_sums: usize,
    /// Rows of every block's band whose faint-search responses the read-out took into
    /// `Workspace::faint_columns` (0: none).
    pub(super) faint_rows: usize,
}

/// What the streamed front end hands the rest of the chain ([`after_segmentation`]): the
/// subtracted pair, the threshold, and the objects and labelled runs of the segmentation (in
/// `Workspace::objects` and `Workspace::runs`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Segmented {
    pub(super) pair: Subtracted,
    pub(super) threshold: u32,
    pub(super) objects: usize,
    pub(super) runs: usize,
    /// The points located during the read-out (in `Workspace::readout_fits`).
    pub(super) readout: ReadoutFits,
}

/// The chain after the segmentation: selection and plane assignment, subpixel curve,
/// smoothing and triangulation.
pub(super) fn after_segmentation<P: Pixel>(
    ws: &mut Workspace<'_, P>,
    seg: Segmented,
    calibration: &Calibration,
    config: &PipelineConfig,
    mut probe: impl FnMut(Stage),
) -> Result<Profile, PipelineError> {
    let (width, height) = (seg.pair.width, seg.pair.height);
    let diff = Frame::new(&ws.diff[..width * height], width, height, width)?
        .with_bit_depth(seg.pair.bit_depth)?;
    let objects = &ws.objects[..seg.objects.min(ws.objects.len())];

    // Selection (§5.6) and plane assignment (docs/pipeline.md).
    let candidates = planes::select_and_assign(
        objects,
        &ws.runs[..seg.runs.min(ws.runs.len())],
        width,
        calibration,
        config,
    )?;
    let used = candidates.used_curves();
    probe(Stage::Selected);

    // The points located during the read-out, for the extraction and the growth alike.
    let readout_tables = (&*ws.column_tracks, &*ws.readout_fits);
    let located = |params: &curve::ExtractParams, x: usize, row: u16, saturation: Real| {
        seg.readout
            .lookup(readout_tables, params, x, row, saturation)
    };
    let n = extract_curves(
        &diff,
        &ws.runs[..seg.runs.min(ws.runs.len())],
        objects,
        &used,
        &seg.pair.stats,
        config,
        ws.seeds,
        ws.curve,
        located,
    )?;
    need("points", n, ws.points.len())?;
    probe(Stage::Extracted);

    let mut plane_points = group_by_plane(ws.curve, n, &used, calibration.planes.len());
    let n = match &config.grow {
        Some(grow) => super::grow::grow_curves(
            &diff,
            ws.curve,
            n,
            &mut plane_points,
            calibration.planes.len(),
            &extract_params(config, &diff, &seg.pair.stats),
            seg.pair.noise,
            grow,
            located,
        ),
        None => n,
    };
    probe(Stage::Grown);
    need("points", n, ws.points.len())?;
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
        subtract: seg.pair.stats,
        threshold: seg.threshold,
        noise: seg.pair.noise,
        objects: seg.objects,
        candidates: report.candidates,
        unused_candidates: usage.unused + report.candidates.saturating_sub(report.selected),
        largest_unused: usage.largest_unused,
        smallest_used: usage.smallest_used,
        planes: calibration.planes.len(),
        plane_points,
        saturated_points,
        touches_edge,
        faint: false,
    })
}

/// Subpixel curve extraction (thesis §5.7.1) of the used objects into `out`; returns the
/// number of points (column-major: each column's points in curve order).
///
/// Each column's brightest pixel of each used object (the seed the estimator starts from) is
/// found from the objects' runs, in raster order so that the first of equally bright pixels
/// from the top wins, over the union of the used objects' column ranges only
/// (`docs/pipeline.md`, "Streaming"). The points located during the read-out are taken from
/// `known(params, x, row, saturation)` ([`curve::extract_seeded_with`]).
#[allow(clippy::too_many_arguments)]
fn extract_curves<P: Pixel>(
    diff: &Frame<P, &[P]>,
    runs: &[Run],
    objects: &[ObjectFeatures],
    used: &UsedCurves,
    stats: &SubtractStats,
    config: &PipelineConfig,
    seeds: &mut [u16],
    out: &mut [CurvePoint],
    known: impl Fn(&curve::ExtractParams, usize, u16, Real) -> Option<Option<CurvePoint>>,
) -> Result<usize, PipelineError> {
    let params = extract_params(config, diff, stats);
    let labels = &used.labels[..used.len];
    let curves = labels.len();
    let (mut x0, mut x1) = (usize::MAX, 0usize);
    for &label in labels {
        // features[i].label == i + 1 (segment::Segmentation).
        if let Some(f) = objects
            .get((label as usize).wrapping_sub(1))
            .filter(|f| f.pixel_count > 0)
        {
            x0 = x0.min(f.min_x as usize);
            x1 = x1.max(f.max_x as usize + 1);
        }
    }
    if x0 >= x1 || curves == 0 {
        return Err(PipelineError::NoCurve);
    }
    let seeds = seeds
        .get_mut(..(x1 - x0) * curves)
        .ok_or(PipelineError::WorkspaceTooSmall {
            buffer: "seeds",
            needed: (x1 - x0) * curves,
            actual: 0,
        })?;
    seeds.fill(NO_SEED);
    for run in runs {
        let Some(k) = labels.iter().position(|&l| l == run.label) else {
            continue;
        };
        let row = diff.row(run.row as usize);
        for x in run.start as usize..run.end as usize {
            let (Some(&v), Some(slot)) = (row.get(x), seeds.get_mut((x - x0) * curves + k)) else {
                continue;
            };
            let v: u32 = v.into();
            let better = *slot == NO_SEED
                || diff
                    .get(x, *slot as usize)
                    .is_some_and(|b| Into::<u32>::into(b) < v);
            if better {
                *slot = run.row;
            }
        }
    }
    Ok(curve::extract_seeded_with(
        diff,
        seeds,
        curves,
        x0..x1,
        &params,
        out,
        |x, row, saturation| known(&params, x, row, saturation),
    )?)
}

/// The subpixel extraction's parameters with the saturation level resolved: a clipped
/// laser-on pixel shows as full scale minus the ambient level (see [`curve::ExtractParams`]).
fn extract_params<P: Pixel>(
    config: &PipelineConfig,
    diff: &Frame<P, &[P]>,
    stats: &SubtractStats,
) -> curve::ExtractParams {
    let mut params = config.extract;
    if params.saturation.is_none() {
        params.saturation = Some(diff.max_value().saturating_sub(stats.off_mean as u32 + 1));
    }
    params
}

/// Reorders the curve points `curve[..n]` in place so that each plane's are contiguous and
/// ordered by column (a stable partition by plane: the points are already column-major);
/// returns each plane's range. The free tail `curve[n..]` parks the other planes' points
/// while a plane's are moved forward, in one pass; with two planes interleaved column by
/// column, rotating each point into place instead moved ≈ n²/8 points (0.7 M instructions for
/// a 600-point pair of curves on the device, `docs/performance.md`). Where the tail is too
/// short, the rotation is the fallback (same order).
fn group_by_plane(
    curve: &mut [CurvePoint],
    n: usize,
    used: &UsedCurves,
    n_planes: usize,
) -> [(usize, usize); MAX_PLANES] {
    let (points, spare) = curve.split_at_mut(n.min(curve.len()));
    let mut plane_points = [(0usize, 0usize); MAX_PLANES];
    let mut start = 0;
    for (plane, range) in plane_points.iter_mut().enumerate().take(n_planes) {
        // The plane's curves as a bit mask (`used.plane(c) == Some(plane)`): the test of
        // every point is a shift, not a bounds-checked table lookup (issue 17).
        let mine = (0..MAX_CURVES as u8)
            .filter(|&c| used.plane(c) == Some(plane))
            .fold(0u32, |m, c| m | 1 << c);
        let is_mine = |p: &CurvePoint| mine.checked_shr(p.curve as u32).unwrap_or(0) & 1 != 0;
        let rest = points.get_mut(start..).unwrap_or(&mut []);
        // The plane's leading points stay where they are; with room in the tail for all the
        // points after them, the others need not be counted first.
        let lead = rest.iter().position(|p| !is_mine(p)).unwrap_or(rest.len());
        let room = spare.len() >= rest.len() - lead;
        let others = if room {
            rest.len() - lead
        } else {
            rest[lead..].iter().filter(|p| !is_mine(p)).count()
        };
        let mut end = lead;
        if lead == rest.len() {
            // One plane, or the last: nothing to move.
        } else if let Some(parking) = spare.get_mut(..others) {
            // Each slot written (`end ≤ i`) has already been read.
            let mut parked = 0;
            for i in lead..rest.len() {
                let p = rest[i];
                if is_mine(&p) {
                    rest[end] = p;
                    end += 1;
                } else {
                    parking[parked] = p;
                    parked += 1;
                }
            }
            for (slot, p) in rest.iter_mut().skip(end).zip(parking.iter()) {
                *slot = *p;
            }
        } else {
            for i in lead..rest.len() {
                if is_mine(&rest[i]) {
                    // Rotate the point to `end`, keeping the order of the others.
                    rest[end..=i].rotate_right(1);
                    end += 1;
                }
            }
        }
        *range = (start, start + end);
        start += end;
    }
    plane_points
}

/// Per plane: checks the curve's length, smooths it, notes whether it reaches the frame's
/// left or right edge, and triangulates it into `out` (same indices). Returns the number of
/// saturated points and whether some curve touches the edge.
pub(super) fn smooth_and_triangulate(
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

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// Three curves on two planes, interleaved column by column, and an unassigned one.
    fn interleaved(n: usize) -> (std::vec::Vec<CurvePoint>, UsedCurves) {
        let points = (0..n)
            .map(|i| CurvePoint {
                column: (i / 4) as u16,
                row: i as Real,
                amplitude: 1.0,
                curve: [0, 1, 2, 3][i % 4],
                saturated: false,
                width: 1.0,
            })
            .collect();
        let mut used = UsedCurves {
            labels: [0; MAX_CURVES],
            planes: [0; MAX_CURVES],
            len: 3,
        };
        used.planes[..3].copy_from_slice(&[1, 0, 1]);
        (points, used)
    }

    /// The one-pass partition (with a free tail) and the rotation (without) give the same
    /// order: each plane's points contiguous, in their original order, the unassigned last.
    #[test]
    fn grouping_by_plane_is_a_stable_partition_with_or_without_a_tail() {
        let n = 203;
        let (points, used) = interleaved(n);
        let mut roomy = points.clone();
        roomy.resize(2 * n, points[0]);
        // Room for plane 0's other points only: they are counted first.
        let mut snug = points.clone();
        snug.resize(n + 152, points[0]);
        let mut tight = points.clone();
        let ranges_roomy = group_by_plane(&mut roomy, n, &used, 2);
        let ranges_snug = group_by_plane(&mut snug, n, &used, 2);
        let ranges_tight = group_by_plane(&mut tight, n, &used, 2);
        assert_eq!(ranges_roomy, ranges_tight);
        assert_eq!(ranges_snug, ranges_tight);
        assert_eq!(roomy[..n], tight[..n]);
        assert_eq!(snug[..n], tight[..n]);
        let expected: std::vec::Vec<CurvePoint> = [Some(0), Some(1), None]
            .iter()
            .flat_map(|&plane| {
                points
                    .iter()
                    .filter(move |p| used.plane(p.curve) == plane)
                    .copied()
            })
            .collect();
        assert_eq!(tight[..n], expected[..]);
        assert_eq!(ranges_tight[0], (0, 51));
        assert_eq!(ranges_tight[1], (51, 153));
    }
}
