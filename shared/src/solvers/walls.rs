//! The walls of one capture (`docs/building.md`, "Finding the walls" and "From planes to
//! readings"): each laser curve is cut into straight runs (split at kinks and jumps), runs of
//! different curves that share a plane seed a wall, the other runs of that plane join it, and
//! each wall is fitted by [`super::plane_pca`]. From the walls: the aimed wall's orientation,
//! the corner angle between the two largest non-parallel walls, the distance between parallel
//! ones, the length of the aimed wall's segment along a laser line and, given gravity, its
//! deviation from the plumb.
//!
//! Fixed capacities ([`MAX_SEGMENTS`], [`MAX_WALLS`]); no allocation, no scratch memory.

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec3, PI};

use crate::curve::CurvePoint;
use crate::laser_plane::LaserPlane;
use crate::noise::{displacement_per_pixel, DisplacementField};

use super::plane_pca::{
    add_line_bias, fit_plane, normal_angle, orientation, plane_intersection, plumb_deviation,
    Estimate, Orientation, PlaneFit,
};
use super::result::Flags;
use super::SolveError;

mod calibration;
mod readings;
pub use calibration::add_calibration_sigma;
use readings::{corner, parallel, segment};

/// Most straight runs kept over all curves of one capture.
pub const MAX_SEGMENTS: usize = 24;
/// Most walls reported from one capture.
pub const MAX_WALLS: usize = 4;
/// Depth of the splitting recursion's explicit stack.
const SPLIT_STACK: usize = 48;

/// Settings of the wall solver. [`Default`] suits the reference head (f = 1000 px, 752 px
/// wide, `docs/building.md`, "Settings").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallParams {
    /// Focal length (pixels), for columns of points and the edge σ.
    pub focal_px: Real,
    /// Principal point column (pixels).
    pub principal_u: Real,
    /// Image width (pixels): a run ending within `edge_margin_px` of a side is cut by the
    /// field of view, not by an edge.
    pub width_px: Real,
    /// See `width_px`.
    pub edge_margin_px: Real,
    /// A run is straight while every point is within `split_sigmas`·σ + `split_floor` of its
    /// chord.
    pub split_sigmas: Real,
    /// See `split_sigmas` (metres).
    pub split_floor: Real,
    /// Two neighbouring points farther apart than this many pixels' worth of distance
    /// (`gap_px`·|X|/f) start a new run (a jump: door frame, cable, step).
    pub gap_px: Real,
    /// Fewest points of a run (shorter ones are clutter or the stripe's ends).
    pub min_segment_points: usize,
    /// Points dropped at each end of a run before the plane fit (the kink or jump smears
    /// them).
    pub trim_points: usize,
    /// Surface roughness allowed beside the point noise (metres, 1σ along the normal).
    pub roughness: Real,
    /// Runs share a plane when their χ² per point about it is below this.
    pub coplanar_chi2: Real,
    /// … or their rms distance from it is below this (metres).
    pub coplanar_rms: Real,
    /// A wall needs runs at least this far apart across them (metres): `√λ₂` of its points.
    pub min_width: Real,
    /// Normals within this angle make two walls parallel (radians).
    pub parallel_max: Real,
    /// Two walls adjoining without a jump at less than this angle are facets of a curved
    /// surface, not a corner (radians).
    pub curved_max: Real,
    /// A wall whose rms distance from its plane exceeds this, and its χ² per point
    /// `coplanar_chi2`, is not flat (metres).
    pub max_rms: Real,
    /// 1σ of the stripe-row bias common to all points of one laser line (pixels): the peak
    /// estimator's phase-dependent bias with 8-bit samples and speckle, 0.006–0.011 px
    /// (`docs/subpixel-study.md`), 0.009 px measured on the frontal wall capture
    /// (`docs/building.md`, "The pitch bias"). 0 leaves it out.
    pub line_bias_px: Real,
    /// Widest object in front of a wall (columns) that a segment is followed across, to the
    /// wall seen again beyond it: a cable or a pipe; wider clutter hides the segment's end.
    pub max_occluder_px: Real,
    /// σ of the lens's point spread (pixels; the reference lens: 0.5 px at f/2.4,
    /// `docs/simulator.md` §4): it blurs a wall's edge across the end pixel of its stripe, whose
    /// amplitude places the edge (`docs/building.md`, (B9)).
    pub psf_sigma_px: Real,
    /// Gravity in the camera frame (pointing down, any length) and its direction's 1σ
    /// (radians), when the instrument knows it: enables [`WallSolution::plumb`].
    pub gravity: Option<(Vec3, Real)>,
}

impl Default for WallParams {
    fn default() -> Self {
        WallParams {
            focal_px: 1000.0,
            principal_u: 375.5,
            width_px: 752.0,
            edge_margin_px: 3.0,
            split_sigmas: 4.0,
            split_floor: 1.5e-3,
            gap_px: 4.0,
            min_segment_points: 12,
            trim_points: 6,
            roughness: 2e-4,
            coplanar_chi2: 9.0,
            coplanar_rms: 2.0e-3,
            min_width: 0.01,
            parallel_max: 2.0 * PI / 180.0,
            curved_max: 30.0 * PI / 180.0,
            max_rms: 6.0e-3,
            line_bias_px: 0.01,
            max_occluder_px: 120.0,
            psf_sigma_px: 0.5,
            gravity: None,
        }
    }
}

/// The solver's input: per laser plane, its curve's 3-D points (ordered by image column) and
/// each point's 1σ along its noise direction, and the planes.
#[derive(Debug, Clone, Copy)]
pub struct WallInput<'a> {
    /// Points per plane.
    pub curves: &'a [&'a [Vec3]],
    /// 1σ per point, same layout.
    pub sigmas: &'a [&'a [Real]],
    /// The laser planes, in curve order.
    pub planes: &'a [LaserPlane],
    /// Each point's stripe in the image, same layout as `curves` (a curve's slice empty, or
    /// shorter than its points, when unknown): a segment's end point's amplitude against its
    /// neighbours' places the edge within its pixel (`docs/building.md`, "Segment length").
    pub stripes: &'a [&'a [CurvePoint]],
    /// The segmentation's detection threshold on the difference image, in the stripes'
    /// amplitude units (0 when unknown): a column whose stripe peaks below it is not seen, so
    /// past a fully lit end pixel the edge may run into the next column by as much as keeps
    /// that column's lit part below it (`docs/building.md`, "Segment length", (B9b)).
    pub threshold: Real,
}

/// A straight run of one curve: points `start..end` of curve `curve`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Run {
    /// The curve (laser plane) index.
    pub curve: u8,
    /// First point.
    pub start: u16,
    /// One past the last point.
    pub end: u16,
    /// The wall it belongs to, if any.
    pub wall: Option<u8>,
}

impl Run {
    fn len(&self) -> usize {
        (self.end - self.start) as usize
    }
}

/// One wall: its plane and which curves lit it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    /// The fitted plane.
    pub plane: PlaneFit,
    /// Bit `k` set when curve `k` has points on it.
    pub lines: u8,
}

/// The corner between two walls.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Indices of the two walls in [`WallSolution::walls`].
    pub walls: (usize, usize),
    /// Angle between the walls, `π − ∠(n_a, n_b)` (π/2 for a square corner, inside or out).
    pub angle: Estimate,
    /// The corner projects towards the camera (a pillar's edge), rather than receding (a room's
    /// corner).
    pub convex: bool,
}

/// How one end of a segment was located.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndKind {
    /// Where the laser line meets the next wall (three planes).
    Corner,
    /// Where the line leaves its plane (a jump, the wall's edge), to subpixel.
    Edge,
    /// The frame's side: the wall goes on beyond the view, the length is a lower bound.
    FrameSide,
    /// Hidden by an object in front of the wall (a cable, a pipe) behind which the line is
    /// not seen on the wall again: the length is a lower bound.
    Occluded,
}

/// A segment of a wall along a laser line, between two ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// The curve (laser plane) it lies on.
    pub curve: usize,
    /// End points (metres, camera frame), left then right in the image.
    pub ends: [Vec3; 2],
    /// How each end was found.
    pub kinds: [EndKind; 2],
    /// Length between the ends and its 1σ (metres).
    pub length: Estimate,
}

impl Segment {
    /// Both ends are edges or corners (not the frame's side, not hidden by clutter).
    pub fn bounded(&self) -> bool {
        !self
            .kinds
            .iter()
            .any(|k| matches!(k, EndKind::FrameSide | EndKind::Occluded))
    }
}

/// The walls of one capture and the readings taken from them.
#[derive(Debug, Clone, PartialEq)]
pub struct WallSolution {
    /// The walls found, most points first.
    pub walls: heapless::Vec<Wall, MAX_WALLS>,
    /// The wall at the image centre (index into `walls`).
    pub aimed: usize,
    /// Its orientation seen from the instrument.
    pub orientation: Orientation,
    /// The corner between the two largest non-parallel walls.
    pub corner: Option<Corner>,
    /// Distance between the two largest parallel walls, when two are.
    pub parallel: Option<Estimate>,
    /// The aimed wall's segment along the first line that lights it.
    pub segment: Option<Segment>,
    /// The aimed wall's deviation from the plumb (with gravity in the parameters).
    pub plumb: Option<Estimate>,
    /// Points used in the wall fits.
    pub points: usize,
    /// The straight runs each curve was cut into, left to right per curve, with their wall.
    pub runs: heapless::Vec<Run, MAX_SEGMENTS>,
    /// Quality flags.
    pub flags: Flags,
}

/// Finds the walls and takes the readings (`docs/building.md`).
///
/// Errors: `PlaneCount` without curves; `SingleLine` when every straight run lies on one
/// laser line (a plane needs two); `NotPlanar` when runs of different lines share no plane or
/// the surface is curved; `TooFewPoints` when no run is long enough.
pub fn solve(input: &WallInput<'_>, params: &WallParams) -> Result<WallSolution, SolveError> {
    let n_curves = input
        .curves
        .len()
        .min(input.sigmas.len())
        .min(input.planes.len());
    if n_curves == 0 {
        return Err(SolveError::PlaneCount);
    }
    if !(params.focal_px > 0.0) || params.min_segment_points < 3 {
        return Err(SolveError::InvalidParameter);
    }
    let mut runs: heapless::Vec<Run, MAX_SEGMENTS> = heapless::Vec::new();
    let mut flags = Flags::default();
    for k in 0..n_curves {
        if split_curve(input, k, params, &mut runs).is_err() {
            flags.insert(Flags::SEVERAL_OBJECTS);
        }
    }
    if runs.is_empty() {
        return Err(SolveError::TooFewPoints);
    }
    let mut walls = group(input, params, &mut runs)?;
    reassign(input, params, &mut runs, &mut walls);
    check_not_curved(input, params, &runs, &walls)?;
    let mut walls_out: heapless::Vec<Wall, MAX_WALLS> = heapless::Vec::new();
    let mut points = 0;
    for (w, wall) in walls.iter().enumerate() {
        let plane = refit(input, params, &runs, &walls, w, &wall.plane)?;
        // Far walls scatter by millimetres: only scatter the noise does not explain is
        // a surface that is not flat.
        if plane.rms > params.max_rms && plane.chi2 > params.coplanar_chi2 {
            return Err(SolveError::NotPlanar);
        }
        if plane.chi2 > params.coplanar_chi2 {
            flags.insert(Flags::POOR_FIT);
        }
        points += plane.points;
        let _ = walls_out.push(Wall {
            plane,
            lines: wall.lines,
        });
    }
    if runs
        .iter()
        .any(|r| r.wall.is_none() && r.len() >= 4 * params.min_segment_points)
    {
        // A long straight run on no wall: another object, or a wall lit by one line only.
        flags.insert(Flags::SEVERAL_OBJECTS);
    }
    let aimed = aimed_wall(input, params, &runs);
    let aimed_plane = walls_out[aimed].plane;
    let orientation = orientation(&aimed_plane).ok_or(SolveError::Degenerate)?;
    let corner = corner(&walls_out);
    let parallel = parallel(&walls_out, params);
    let segment = segment(input, params, &runs, &walls_out, aimed);
    let plumb = params
        .gravity
        .and_then(|(g, s)| plumb_deviation(&aimed_plane, g, s));
    Ok(WallSolution {
        walls: walls_out,
        aimed,
        orientation,
        corner,
        parallel,
        segment,
        plumb,
        points,
        runs,
        flags,
    })
}

/// The image column of a point (pinhole; the points are undistorted already).
fn column(p: Vec3, params: &WallParams) -> Real {
    params.focal_px * p.x / p.z + params.principal_u
}

/// Cuts curve `k` into straight runs (Douglas–Peucker with a σ-scaled tolerance, after
/// cutting at jumps); `Err` when [`MAX_SEGMENTS`] overflowed (the rest is dropped).
fn split_curve(
    input: &WallInput<'_>,
    k: usize,
    params: &WallParams,
    runs: &mut heapless::Vec<Run, MAX_SEGMENTS>,
) -> Result<(), ()> {
    let pts = input.curves[k];
    let sig = input.sigmas[k];
    let n = pts.len().min(sig.len()).min(u16::MAX as usize);
    let mut stack: heapless::Vec<(usize, usize), SPLIT_STACK> = heapless::Vec::new();
    // Jumps first: each gap-free stretch onto the stack.
    let mut start = 0;
    for i in 1..=n {
        let jump = i == n || {
            let step = norm(&(pts[i] - pts[i - 1]));
            let spacing = params.gap_px * norm(&pts[i]) / params.focal_px;
            !(step <= spacing + params.split_sigmas * (sig[i] + sig[i - 1]))
        };
        if jump {
            if i - start >= params.min_segment_points {
                stack.push((start, i)).map_err(|_| ())?;
            }
            start = i;
        }
    }
    // Reverse so that runs come out left to right.
    stack.reverse();
    while let Some((s, e)) = stack.pop() {
        let (a, b) = (pts[s], pts[e - 1]);
        let chord = b - a;
        let len = norm(&chord);
        let mut worst = (0.0 as Real, s);
        if len > 0.0 {
            let dir = chord / len;
            for i in s + 1..e - 1 {
                let d = pts[i] - a;
                let off = norm(&(d - dir * d.dot(&dir)));
                let tol = params.split_sigmas * sig[i] + params.split_floor;
                let excess = off / tol;
                if excess > worst.0 {
                    worst = (excess, i);
                }
            }
        }
        if worst.0 > 1.0 {
            let i = worst.1;
            // Right half pushed first so that the left one is handled first.
            for (s2, e2) in [(i, e), (s, i)] {
                if e2 - s2 >= params.min_segment_points {
                    stack.push((s2, e2)).map_err(|_| ())?;
                }
            }
        } else {
            runs.push(Run {
                curve: k as u8,
                start: s as u16,
                end: e as u16,
                wall: None,
            })
            .map_err(|_| ())?;
        }
    }
    Ok(())
}

/// The points of `runs` selected by `take`, with each point's σ along `normal` (its noise
/// direction projected, with the roughness added), trimmed by `trim` at each run's ends.
fn samples<'a>(
    input: &'a WallInput<'a>,
    runs: &'a [Run],
    take: impl Fn(usize, &Run) -> bool + Clone + 'a,
    normal: Option<Vec3>,
    trim: usize,
    roughness: Real,
) -> impl Iterator<Item = (Vec3, Real)> + Clone + 'a {
    line_samples(input, runs, take, normal, trim, roughness).map(|(_, p, s)| (p, s))
}

/// [`samples`] with each point's laser line (curve index).
fn line_samples<'a>(
    input: &'a WallInput<'a>,
    runs: &'a [Run],
    take: impl Fn(usize, &Run) -> bool + Clone + 'a,
    normal: Option<Vec3>,
    trim: usize,
    roughness: Real,
) -> impl Iterator<Item = (usize, Vec3, Real)> + Clone + 'a {
    runs.iter()
        .enumerate()
        .filter(move |(i, r)| take(*i, r))
        .flat_map(move |(_, r)| {
            let k = r.curve as usize;
            let field = DisplacementField::of(&input.planes[k]);
            let t = trim.min(r.len().saturating_sub(3) / 2);
            let range = r.start as usize + t..r.end as usize - t;
            input.curves[k][range.clone()]
                .iter()
                .zip(&input.sigmas[k][range])
                .map(move |(&p, &s)| {
                    let along = match normal {
                        Some(n) => s * field.direction(p).dot(&n).abs(),
                        None => s,
                    };
                    (k, p, sqrt(along * along + roughness * roughness))
                })
        })
}

/// A wall being grouped: its plane so far and its curves.
#[derive(Debug, Clone, Copy)]
struct Group {
    plane: PlaneFit,
    lines: u8,
}

/// Whether the points of run `run` lie on `plane` (χ² or rms test).
fn on_plane(input: &WallInput<'_>, params: &WallParams, run: &Run, plane: &PlaneFit) -> bool {
    let (chi2, rms) = run_fit(input, params, run, plane);
    chi2 <= params.coplanar_chi2 || rms <= params.coplanar_rms
}

/// χ² per point and rms distance of run `run`'s points about `plane` (σ along its normal);
/// infinite for an empty run.
fn run_fit(
    input: &WallInput<'_>,
    params: &WallParams,
    run: &Run,
    plane: &PlaneFit,
) -> (Real, Real) {
    let one = [*run];
    let (mut chi2, mut sq, mut n) = (0.0 as Real, 0.0 as Real, 0usize);
    for (p, s) in samples(
        input,
        &one,
        |_, _| true,
        Some(plane.normal),
        0,
        params.roughness,
    ) {
        let r = plane.signed_distance(p);
        chi2 += (r / s) * (r / s);
        sq += r * r;
        n += 1;
    }
    if n == 0 {
        return (Real::INFINITY, Real::INFINITY);
    }
    (chi2 / n as Real, sqrt(sq / n as Real))
}

/// The unweighted plane of wall `w`'s runs, leaving run `skip` out (`usize::MAX`: none);
/// `None` when what is left is no plane (one line, or narrower than `min_width`).
fn group_plane(
    input: &WallInput<'_>,
    params: &WallParams,
    runs: &[Run],
    w: u8,
    skip: usize,
) -> Option<PlaneFit> {
    let take = move |k: usize, r: &Run| k != skip && r.wall == Some(w);
    let fit = fit_plane(samples(input, runs, take, None, 0, params.roughness)).ok()?;
    (sqrt(fit.spread[1]) >= params.min_width).then_some(fit)
}

/// Moves each run to the wall whose plane it fits best, each wall's plane taken without the
/// run (`docs/building.md` §2, step 2b). Grouping seeds a wall with the pair of runs with the
/// most points: a long run near a corner's edge (the crossing line running down the image
/// beside it) passes the coplanarity test of either wall there — its points' σ is
/// millimetres at 2–3 m — and joins the wall whose other run is longer, then tilts that
/// wall's plane towards itself (its 480 points outweigh the rest). Against the other runs
/// alone the wrong wall's plane misses it by far more than the right one's.
fn reassign(input: &WallInput<'_>, params: &WallParams, runs: &mut [Run], walls: &mut [Group]) {
    for i in 0..runs.len() {
        let Some(w) = runs[i].wall else { continue };
        // A run its wall cannot do without stays.
        let Some(without) = group_plane(input, params, runs, w, i) else {
            continue;
        };
        let mut best = (run_fit(input, params, &runs[i], &without).0, w);
        for (v, g) in walls.iter().enumerate() {
            if v == w as usize {
                continue;
            }
            let (chi2, rms) = run_fit(input, params, &runs[i], &g.plane);
            let fits = chi2 <= params.coplanar_chi2 || rms <= params.coplanar_rms;
            if fits && chi2 < best.0 {
                best = (chi2, v as u8);
            }
        }
        if best.1 == w {
            continue;
        }
        runs[i].wall = Some(best.1);
        for moved in [w, best.1] {
            let g = &mut walls[moved as usize];
            g.plane = group_plane(input, params, runs, moved, usize::MAX).unwrap_or(g.plane);
            g.lines = runs
                .iter()
                .filter(|r| r.wall == Some(moved))
                .fold(0u8, |m, r| m | (1 << r.curve));
        }
    }
}

/// Groups the runs into walls: the pair of runs of different curves with the most points that
/// share a plane seeds a wall, every run on that plane joins it; repeated on what is left.
fn group(
    input: &WallInput<'_>,
    params: &WallParams,
    runs: &mut [Run],
) -> Result<heapless::Vec<Group, MAX_WALLS>, SolveError> {
    let mut walls: heapless::Vec<Group, MAX_WALLS> = heapless::Vec::new();
    while walls.len() < MAX_WALLS {
        // Seeds of two lines across the image first (a pair of them spans a wall by
        // itself), then the largest: the crossing line runs down the image beside a corner's
        // edge and, paired with the other wall's longer run, passes as a plane that is
        // neither wall (docs/building.md §2, step 2b).
        let mut best: Option<(usize, usize, (bool, usize), PlaneFit)> = None;
        for i in 0..runs.len() {
            for j in i + 1..runs.len() {
                let (a, b) = (runs[i], runs[j]);
                if a.wall.is_some() || b.wall.is_some() || a.curve == b.curve {
                    continue;
                }
                let across = !input.planes[a.curve as usize].is_row_wise()
                    && !input.planes[b.curve as usize].is_row_wise();
                let count = (across, a.len() + b.len());
                if best.is_some_and(|(_, _, c, _)| c >= count) {
                    continue;
                }
                let pair = samples(
                    input,
                    runs,
                    move |k, _| k == i || k == j,
                    None,
                    0,
                    params.roughness,
                );
                let Ok(fit) = fit_plane(pair) else { continue };
                if sqrt(fit.spread[1]) < params.min_width {
                    continue;
                }
                if on_plane(input, params, &a, &fit) && on_plane(input, params, &b, &fit) {
                    best = Some((i, j, count, fit));
                }
            }
        }
        let Some((i, j, _, seed)) = best else { break };
        let w = walls.len() as u8;
        runs[i].wall = Some(w);
        runs[j].wall = Some(w);
        let mut plane = seed;
        // Join every other free run on the plane, refitting as the wall grows.
        for k in 0..runs.len() {
            if runs[k].wall.is_none() && on_plane(input, params, &runs[k], &plane) {
                runs[k].wall = Some(w);
                let all = samples(
                    input,
                    runs,
                    move |_, r| r.wall == Some(w),
                    None,
                    0,
                    params.roughness,
                );
                plane = fit_plane(all)?;
            }
        }
        let lines = runs
            .iter()
            .filter(|r| r.wall == Some(w))
            .fold(0u8, |m, r| m | (1 << r.curve));
        let _ = walls.push(Group { plane, lines });
    }
    if walls.is_empty() {
        let first = runs[0].curve;
        return Err(if runs.iter().all(|r| r.curve == first) {
            SolveError::SingleLine
        } else {
            SolveError::NotPlanar
        });
    }
    // Most points first; the runs' wall indices follow.
    let mut order: heapless::Vec<(usize, usize), MAX_WALLS> = heapless::Vec::new();
    for (w, g) in walls.iter().enumerate() {
        let _ = order.push((g.plane.points, w));
    }
    order.sort_unstable_by_key(|o| core::cmp::Reverse(o.0));
    let mut sorted: heapless::Vec<Group, MAX_WALLS> = heapless::Vec::new();
    for &(_, w) in &order {
        let _ = sorted.push(walls[w]);
    }
    for r in runs.iter_mut() {
        if let Some(w) = r.wall {
            r.wall = order
                .iter()
                .position(|&(_, o)| o == w as usize)
                .map(|p| p as u8);
        }
    }
    Ok(sorted)
}

/// Two walls that adjoin along a curve without a jump, at a shallow angle, are facets of a
/// curved surface (a column, a vault): `NotPlanar`.
fn check_not_curved(
    input: &WallInput<'_>,
    params: &WallParams,
    runs: &[Run],
    walls: &[Group],
) -> Result<(), SolveError> {
    for pair in runs.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let (Some(wa), Some(wb)) = (a.wall, b.wall) else {
            continue;
        };
        if a.curve != b.curve || wa == wb || b.start != a.end {
            continue;
        }
        let angle = normal_angle(&walls[wa as usize].plane, &walls[wb as usize].plane).value;
        let pts = input.curves[a.curve as usize];
        let step = norm(&(pts[b.start as usize] - pts[a.end as usize - 1]));
        let spacing = params.gap_px * norm(&pts[a.end as usize - 1]) / params.focal_px;
        if angle < params.curved_max && angle > params.parallel_max && step <= spacing {
            return Err(SolveError::NotPlanar);
        }
    }
    Ok(())
}

/// The edges between wall `w` and the other walls that are not parallel to it, as lines
/// (a point and a unit direction).
fn edges(walls: &[Group], w: usize, params: &WallParams) -> heapless::Vec<(Vec3, Vec3), MAX_WALLS> {
    let mut out = heapless::Vec::new();
    let a = &walls[w].plane;
    for (v, g) in walls.iter().enumerate() {
        if v == w || normal_angle(a, &g.plane).value <= params.parallel_max {
            continue;
        }
        if let Some(line) = plane_intersection(a.normal, a.offset, g.plane.normal, g.plane.offset) {
            let _ = out.push(line);
        }
    }
    out
}

/// Whether point `p` of a row-wise (crossing) line lies within `trim_points` columns of one
/// of `edges`, measured along its image row: its stripe straddles the kink there and its
/// peak is pulled off the wall, as at the trimmed ends of the other lines' runs. A crossing
/// line runs down the image beside a corner's edge, parallel to it, so trimming its ends
/// does not remove these points (`docs/building.md` §2, step 4).
fn beside_edge(p: Vec3, edges: &[(Vec3, Vec3)], params: &WallParams) -> bool {
    edges.iter().any(|&(o, d)| {
        // The edge's point seen on p's row: (o + t d).y/(o + t d).z = p.y/p.z.
        let den = p.z * d.y - p.y * d.z;
        if den.abs() < 1e-9 {
            return false;
        }
        let q = o + d * ((p.y * o.z - p.z * o.y) / den);
        q.z > 0.0 && (params.focal_px * (p.x / p.z - q.x / q.z)).abs() < params.trim_points as Real
    })
}

/// The points of the runs `take` selects for a wall's final fit, with their line and σ along
/// `normal` (see [`refit`]).
fn kept_lines<'a>(
    input: &'a WallInput<'a>,
    params: &'a WallParams,
    runs: &'a [Run],
    take: impl Fn(usize, &Run) -> bool + Clone + 'a,
    normal: Vec3,
    edges: &'a [(Vec3, Vec3)],
) -> impl Iterator<Item = (usize, Vec3, Real)> + Clone + 'a {
    line_samples(
        input,
        runs,
        take,
        Some(normal),
        params.trim_points,
        params.roughness,
    )
    .filter(move |&(k, p, _)| !(input.planes[k].is_row_wise() && beside_edge(p, edges, params)))
}

/// Final fit of wall `w`: its runs trimmed at their ends and the crossing line's points
/// beside another wall's edge left out, each point's σ along the wall's normal.
fn refit(
    input: &WallInput<'_>,
    params: &WallParams,
    runs: &[Run],
    walls: &[Group],
    w: usize,
    first: &PlaneFit,
) -> Result<PlaneFit, SolveError> {
    let mut edges = edges(walls, w, params);
    let w = w as u8;
    let take = move |_: usize, r: &Run| r.wall == Some(w);
    let fit = |edges: &[(Vec3, Vec3)]| -> Result<PlaneFit, SolveError> {
        let mut plane = *first;
        for _ in 0..2 {
            plane = fit_plane(
                kept_lines(input, params, runs, take, plane.normal, edges).map(|(_, p, s)| (p, s)),
            )?;
        }
        Ok(plane)
    };
    // A wall that is no plane without those points (the crossing line was its second line)
    // keeps them.
    let mut plane = match fit(&edges) {
        Ok(p) => p,
        Err(_) => {
            edges.clear();
            fit(&edges)?
        }
    };
    // docs/building.md, eq. (B3b): the stripe-row bias shared by each line's points.
    let lines = kept_lines(input, params, runs, take, plane.normal, &edges).map(|(k, p, s)| {
        let dxdv = displacement_per_pixel(&input.planes[k], params.focal_px, p)
            .unwrap_or_else(|_| Vec3::zeros());
        (k, p, s, dxdv)
    });
    add_line_bias(&mut plane, lines, params.line_bias_px);
    Ok(plane)
}

/// The wall whose run comes nearest the principal point's column.
fn aimed_wall(input: &WallInput<'_>, params: &WallParams, runs: &[Run]) -> usize {
    let mut best = (Real::INFINITY, 0usize);
    for r in runs {
        let Some(w) = r.wall else { continue };
        // The crossing line runs down the image: its column says nothing of the aim.
        if input.planes[r.curve as usize].is_row_wise() {
            continue;
        }
        let pts = &input.curves[r.curve as usize][r.start as usize..r.end as usize];
        for &p in pts {
            let off = (column(p, params) - params.principal_u).abs();
            if off < best.0 {
                best = (off, w as usize);
            }
        }
    }
    best.1
}

#[cfg(test)]
#[path = "walls_tests.rs"]
mod tests;
