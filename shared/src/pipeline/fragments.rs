//! Fragments of other surfaces assigned to planes by depth agreement (wall mode:
//! `docs/building.md`, "Niches: fragments assigned by depth agreement").
//!
//! The aimed object's curves are assigned first (`planes::assign_planes`); the fragment join
//! then adds the pieces that continue them within `max_fragment_step` rows. A surface at
//! another depth — a niche's front wall either side of its back wall, a reveal, a cable —
//! moves every line by `f e_k (1/z − 1/z′)` rows, more than any step that a curve broken by
//! texture needs, and with two planes the moved piece of line 0 may even land within a few
//! rows of line 1's curve. Such a surface is recognised by itself instead: its lines are
//! pieces one above the other in the same columns (a **stack**), and assigned to the planes
//! in the planes' row order they triangulate to one surface. Each piece's depth is taken
//! over the columns the stack shares, from its mean row there, so the comparison is at one
//! place on the surface.
//!
//! Agreement (derivation in the doc): pieces `a` and `b` on planes `k_a`, `k_b` give points
//! `X_a`, `X_b`; on one surface their depths differ by the surface's slope over the distance
//! between them plus the pieces' row errors turned into depth,
//!
//! ```text
//! |z_a − z_b| ≤ s_max · |(X_a − X_b)_xy| + t_row · (|∂z/∂v|_a + |∂z/∂v|_b)
//! ```
//!
//! with `s_max` = [`StackParams::max_slope`] and `t_row` = [`StackParams::row_tolerance_px`];
//! `∂z/∂v` is the depth change of one row on that plane at that pixel (`z²/(f e_k)` for a
//! plane at baseline `e_k`). The wrong pairing — a piece of line 0 of one surface with a
//! piece of line 1 of another — misses by the surfaces' depth difference, which is what
//! moved the piece out of the fragment join's reach in the first place.

use crate::calibration::Calibration;
use crate::image::segment::Run;
use crate::laser_plane::triangulate;
// `Float` supplies abs/sqrt in `no_std`; with `std` the inherent methods win.
#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{Real, Vec2, Vec3};

use super::candidate::{Candidate, MAX_CANDIDATES};

/// Settings of the depth-agreement assignment ([`super::PipelineConfig::stacks`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StackParams {
    /// Bound on a piece's mean row over the shared columns against its stripe's centre
    /// (pixels): the thresholded pixels of a symmetric stripe are centred on it within half
    /// a pixel per column; one pixel leaves as much again for a stripe made asymmetric by
    /// texture or a glossy lobe.
    pub row_tolerance_px: Real,
    /// Steepest slope of a surface's depth per unit of distance across it (`tan` of its
    /// angle to the image plane) between the two lines' points: the lines are
    /// `Δy` = 5 cm apart on the reference head, so the default, `tan 30°`, allows a
    /// 29 mm difference for a wall tilted 30° from facing the camera.
    pub max_slope: Real,
    /// Shortest shared column span of a stack, as a fraction of its narrower piece: the
    /// lines of one surface are cut by the same edges (to within the camera's roll over
    /// the lines' separation, a few columns).
    pub min_overlap: Real,
}

impl Default for StackParams {
    fn default() -> Self {
        StackParams {
            row_tolerance_px: 1.0,
            max_slope: 0.577,
            min_overlap: 0.5,
        }
    }
}

/// Where a piece is on its plane over a column range, and how far one row moves it in
/// depth.
#[derive(Debug, Clone, Copy)]
struct PieceDepth {
    point: Vec3,
    dz_per_row: Real,
}

/// The mean pixel `(column, row)` of `label`'s runs over columns `x0..=x1`, or `None` when it
/// has no pixel there.
fn mean_pixel(runs: &[Run], label: u16, x0: u16, x1: u16) -> Option<Vec2> {
    let (mut n, mut sx, mut sy) = (0u64, 0.0 as Real, 0.0 as Real);
    for r in runs.iter().filter(|r| r.label == label) {
        // Runs are half-open `start..end`.
        let a = r.start.max(x0);
        let b = r.end.min(x1.saturating_add(1));
        if a >= b {
            continue;
        }
        let k = (b - a) as u64;
        n += k;
        // Σ x over a..b−1 = k (a + b − 1)/2.
        sx += k as Real * (a as Real + b as Real - 1.0) * 0.5;
        sy += k as Real * r.row as Real;
    }
    (n > 0).then(|| Vec2::new(sx / n as Real, sy / n as Real))
}

/// The piece's point on `plane` at `pixel` and the depth change of one row there.
fn piece_depth(calibration: &Calibration, plane: usize, pixel: Vec2) -> Option<PieceDepth> {
    let p = calibration.plane(plane).ok()?;
    let cam = &calibration.camera;
    let point = triangulate(cam, p, pixel).ok()?;
    let up = triangulate(cam, p, Vec2::new(pixel.x, pixel.y - 0.5)).ok()?;
    let down = triangulate(cam, p, Vec2::new(pixel.x, pixel.y + 0.5)).ok()?;
    Some(PieceDepth {
        point,
        dz_per_row: (down.z - up.z).abs(),
    })
}

/// How far two pieces' depths disagree, in units of what one surface allows (≤ 1: they
/// agree; see the module's inequality).
fn disagreement(a: &PieceDepth, b: &PieceDepth, params: &StackParams) -> Real {
    let dx = a.point.x - b.point.x;
    let dy = a.point.y - b.point.y;
    let across = (dx * dx + dy * dy).sqrt();
    let allowed =
        params.max_slope * across + params.row_tolerance_px * (a.dz_per_row + b.dz_per_row);
    if allowed > 0.0 {
        (a.point.z - b.point.z).abs() / allowed
    } else {
        Real::INFINITY
    }
}

/// The shared columns of two pieces when they are one above the other
/// ([`StackParams::min_overlap`]).
fn shared_columns(a: &Candidate, b: &Candidate, params: &StackParams) -> Option<(u16, u16)> {
    let (x0, x1) = (a.min_x.max(b.min_x), a.max_x.min(b.max_x));
    if x0 > x1 {
        return None;
    }
    let shared = (x1 - x0) as Real + 1.0;
    let narrower =
        (a.max_x.saturating_sub(a.min_x)).min(b.max_x.saturating_sub(b.min_x)) as Real + 1.0;
    (shared >= params.min_overlap * narrower).then_some((x0, x1))
}

/// How well pieces `a` and `b` (unassigned) make one surface's pair of lines on the two
/// planes of `planes_order` (the planes sorted by image row): the disagreement (≤ 1 agrees)
/// and the planes of `a` and `b`, or `None` when they are not one above the other.
fn pair_fit(
    a: &Candidate,
    b: &Candidate,
    runs: &[Run],
    calibration: &Calibration,
    planes_order: &[usize],
    params: &StackParams,
) -> Option<(Real, usize, usize)> {
    let (x0, x1) = shared_columns(a, b, params)?;
    let pa = mean_pixel(runs, a.label, x0, x1)?;
    let pb = mean_pixel(runs, b.label, x0, x1)?;
    let (&upper, &lower) = (planes_order.first()?, planes_order.get(1)?);
    // Parallel planes keep their image order at every depth (docs/pipeline.md §4).
    let (ka, kb) = if pa.y <= pb.y {
        (upper, lower)
    } else {
        (lower, upper)
    };
    let da = piece_depth(calibration, ka, pa)?;
    let db = piece_depth(calibration, kb, pb)?;
    Some((disagreement(&da, &db, params), ka, kb))
}

/// Assigns the unassigned candidates that pair up as one surface's two lines, in the planes'
/// row order, when their depths agree: the pairs sharing the most columns first (a surface's
/// two lines share nearly all of theirs; a short piece beside a corner shares a few columns
/// with the next wall's long one), each piece in one pair at most, and neither plane already
/// lit in those columns ([`occupied`]). Only for two planes across the image (the reference
/// head's); with more, nothing is assigned here. Returns whether any candidate was assigned.
pub(super) fn assign_stacks(
    cands: &mut [Candidate],
    runs: &[Run],
    calibration: &Calibration,
    planes_order: &[usize],
    params: &StackParams,
) -> bool {
    if calibration.planes.len() != 2 || planes_order.len() != 2 {
        return false;
    }
    let n = cands.len().min(MAX_CANDIDATES);
    // Bit `j` of `tried[i]`: the pair (i, j) was tested and refused.
    let mut tried = [0u16; MAX_CANDIDATES];
    let mut changed = false;
    loop {
        // The untried pair of unassigned pieces sharing the most columns.
        let mut widest: Option<(u16, usize, usize)> = None;
        for i in 0..n {
            if cands[i].plane.is_some() {
                continue;
            }
            for j in i + 1..n {
                if cands[j].plane.is_some() || tried[i] & (1 << j) != 0 {
                    continue;
                }
                if let Some((x0, x1)) = shared_columns(&cands[i], &cands[j], params) {
                    if widest.is_none_or(|w| x1 - x0 > w.0) {
                        widest = Some((x1 - x0, i, j));
                    }
                }
            }
        }
        let Some((_, i, j)) = widest else {
            return changed;
        };
        let fit = pair_fit(
            &cands[i],
            &cands[j],
            runs,
            calibration,
            planes_order,
            params,
        )
        .filter(|&(d, ki, kj)| {
            d <= 1.0
                && !occupied(cands, ki, &cands[i], params)
                && !occupied(cands, kj, &cands[j], params)
        });
        match fit {
            Some((_, ki, kj)) => {
                cands[i].plane = Some(ki);
                cands[j].plane = Some(kj);
                changed = true;
            }
            None => tried[i] |= 1 << j,
        }
    }
}

/// Whether plane `plane` already has an assigned piece above or below `c`. A laser plane
/// whose source lies on the camera's `y` axis (the heads' baselines are vertical) meets each
/// column's plane of sight in one ray from its source, which lights one point: one plane's
/// curve has one row per column, so a second piece in the same columns is another plane's.
fn occupied(cands: &[Candidate], plane: usize, c: &Candidate, params: &StackParams) -> bool {
    cands
        .iter()
        .any(|o| o.plane == Some(plane) && shared_columns(c, o, params).is_some())
}

/// Whether candidate `c` may join plane `plane` as a fragment: no assigned piece of that
/// plane lies above or below it ([`occupied`]), and it triangulates on `plane` to the depth
/// of every assigned piece of another plane above or below it (its partner line on the same
/// surface: a front wall's line-0 piece that a niche moved next to the back wall's line 1
/// misses its line-1 partner by the niche's depth). A piece without a partner cannot be
/// checked and may join.
pub(super) fn agrees_with_partners(
    c: &Candidate,
    plane: usize,
    cands: &[Candidate],
    runs: &[Run],
    calibration: &Calibration,
    params: &StackParams,
) -> bool {
    !occupied(cands, plane, c, params)
        && cands.iter().all(|o| {
            let Some(k) = o.plane.filter(|&k| k != plane) else {
                return true;
            };
            let Some((x0, x1)) = shared_columns(c, o, params) else {
                return true;
            };
            let (Some(pc), Some(po)) = (
                mean_pixel(runs, c.label, x0, x1),
                mean_pixel(runs, o.label, x0, x1),
            ) else {
                return true;
            };
            match (
                piece_depth(calibration, plane, pc),
                piece_depth(calibration, k, po),
            ) {
                (Some(dc), Some(dp)) => disagreement(&dc, &dp, params) <= 1.0,
                _ => false,
            }
        })
}

#[cfg(test)]
#[path = "fragments_tests.rs"]
mod tests;
