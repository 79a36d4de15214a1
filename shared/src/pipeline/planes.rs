//! Which selected object is which laser plane's curve (`docs/pipeline.md`, "Assigning curves to
//! laser planes").

use crate::calibration::{Calibration, MAX_PLANES};
use crate::curve::MAX_CURVES;
use crate::image::segment::{ObjectFeatures, Run};
use crate::image::select::{self, SelectionReport};
use crate::real::{Real, Vec2, Vec3};

use super::candidate::{Candidate, MAX_CANDIDATES};
use super::fragments;
use super::{PipelineConfig, PipelineError};

/// The selected objects, nearest to the central column first (in sphere mode the arcs before
/// the lines, [`super::arcs`]), each with its plane.
#[derive(Debug, Clone, Copy)]
pub(super) struct Candidates {
    list: [Candidate; MAX_CANDIDATES],
    len: usize,
    /// What the selection found.
    pub report: SelectionReport,
}

/// The curves to extract: labels in extraction order (a curve point's `curve` index) and the
/// plane of each.
#[derive(Debug, Clone, Copy)]
pub(super) struct UsedCurves {
    pub labels: [u16; MAX_CURVES],
    pub planes: [usize; MAX_CURVES],
    pub len: usize,
}

impl UsedCurves {
    /// The plane of curve `curve` (a curve point's `curve` index).
    pub fn plane(&self, curve: u8) -> Option<usize> {
        let i = curve as usize;
        (i < self.len).then(|| self.planes[i])
    }
}

/// How the candidates were used, for the image flags ([`super::Profile`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Usage {
    /// Candidates not used for any plane.
    pub unused: usize,
    /// Pixel count of the largest unused candidate (0 if none).
    pub largest_unused: u32,
    /// Pixel count of the smallest used candidate.
    pub smallest_used: u32,
}

impl Candidates {
    fn as_slice(&self) -> &[Candidate] {
        &self.list[..self.len]
    }

    fn used(&self) -> impl Iterator<Item = &Candidate> {
        self.as_slice().iter().filter(|c| c.plane.is_some())
    }

    /// The curves to extract.
    pub fn used_curves(&self) -> UsedCurves {
        let mut used = UsedCurves {
            labels: [0; MAX_CURVES],
            planes: [0; MAX_CURVES],
            len: 0,
        };
        for c in self.used() {
            if used.len == MAX_CURVES {
                break;
            }
            if let Some(plane) = c.plane {
                used.labels[used.len] = c.label;
                used.planes[used.len] = plane;
                used.len += 1;
            }
        }
        used
    }

    /// How many candidates were left out, the largest of them, the smallest used.
    pub fn usage(&self) -> Usage {
        let smallest_used = self.used().map(|c| c.pixels).min().unwrap_or(0);
        let (unused, largest_unused) = self
            .as_slice()
            .iter()
            .filter(|c| c.plane.is_none())
            .fold((0, 0), |(k, m), c| (k + 1, m.max(c.pixels)));
        Usage {
            unused,
            largest_unused,
            smallest_used,
        }
    }
}

/// Selects the objects that look like laser curves (the per-object criteria, nearest to the
/// central column first, `max_fragments` per plane) and assigns them to planes. The first
/// candidate must get a plane, or there is no curve. `runs` are the segmentation's labelled
/// runs (the depth agreement of [`fragments`] reads the pieces' rows from them).
pub(super) fn select_and_assign(
    objects: &[ObjectFeatures],
    runs: &[Run],
    width: usize,
    calibration: &Calibration,
    config: &PipelineConfig,
) -> Result<Candidates, PipelineError> {
    let n_planes = calibration.planes.len();
    let mut params = config.selection;
    params.max_objects = if config.stacks.is_some() || config.arcs_first {
        MAX_CANDIDATES
    } else {
        (config.max_fragments * n_planes).clamp(1, MAX_CURVES)
    };
    let mut selected = [0u16; MAX_CANDIDATES];
    let report = select::select(objects, width, &params, &mut selected);
    if report.selected == 0 {
        return Err(PipelineError::NoCurve);
    }
    let mut candidates = Candidates {
        list: [Candidate::NONE; MAX_CANDIDATES],
        len: report.selected.min(MAX_CANDIDATES),
        report,
    };
    for (c, &label) in candidates.list.iter_mut().zip(&selected[..candidates.len]) {
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
                plane: None,
            };
        }
    }
    let len = candidates.len;
    if config.arcs_first {
        super::arcs::arcs_first(&mut candidates.list[..len], runs, calibration);
    }
    assign_planes(&mut candidates.list[..len], runs, calibration, config);
    if config.stacks.is_some() {
        keep_nearest_curves(&mut candidates.list[..len]);
    }
    if candidates.list[0].plane.is_none() {
        return Err(PipelineError::NoCurve);
    }
    Ok(candidates)
}

/// Keeps the curves the seed table holds, [`MAX_CURVES`]: the assigned candidates nearest to
/// the central column first, each with the assigned pieces of other planes above or below it
/// (its lines on the same surface) or not at all — one line of a surface is no plane for the
/// wall solver, and a lone piece would take the place of the next surface's pair.
fn keep_nearest_curves(cands: &mut [Candidate]) {
    let n = cands.len().min(MAX_CANDIDATES);
    let mut keep = [false; MAX_CANDIDATES];
    let mut kept = 0;
    for i in 0..n {
        let Some(plane) = cands[i].plane.filter(|_| !keep[i]) else {
            continue;
        };
        let c = cands[i];
        let mut group = [false; MAX_CANDIDATES];
        group[i] = true;
        for (j, o) in cands.iter().enumerate().take(n).skip(i + 1) {
            group[j] = !keep[j]
                && o.plane.is_some_and(|k| k != plane)
                && o.min_x.max(c.min_x) <= o.max_x.min(c.max_x);
        }
        let size = group.iter().filter(|&&g| g).count();
        if kept + size > MAX_CURVES {
            continue;
        }
        for (k, g) in keep.iter_mut().zip(group.iter()) {
            *k |= *g;
        }
        kept += size;
    }
    for (c, &k) in cands.iter_mut().zip(keep.iter()) {
        if !k {
            c.plane = None;
        }
    }
}

/// Assigns candidates (sorted nearest to the central column first; in sphere mode the arcs
/// before the lines) to laser planes.
///
/// The first candidate is the aimed object's curve in some plane. With one plane it is that
/// plane's. With several planes, the candidates overlapping it in columns are the other planes'
/// curves on the same object; they are sorted by mean row and matched to the planes sorted by
/// the row at which each plane is seen on the central column at mid range — parallel planes
/// keep their image order at every depth (docs/pipeline.md). With `config.stacks` (wall
/// mode), the other surfaces' pieces one above the other are assigned next when their depths
/// agree ([`fragments::assign_stacks`]). Then fragments: a remaining candidate whose column
/// span continues an assigned curve's within `max_fragment_gap` columns and whose mean row is
/// within `max_fragment_step` rows joins that plane (in wall mode only if it agrees in depth
/// with the pieces above or below it, [`fragments::agrees_with_partners`]).
pub(super) fn assign_planes(
    cands: &mut [Candidate],
    runs: &[Run],
    calibration: &Calibration,
    config: &PipelineConfig,
) {
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
    let (planes_order, rows) = planes_by_row(calibration, first.mean_row);
    let planes_order = &planes_order[..n_planes.min(MAX_PLANES)];
    if group.len() == n_planes {
        for (&ci, &plane) in group.iter().zip(planes_order.iter()) {
            cands[ci].plane = Some(plane);
        }
    } else if n_planes == 1 {
        cands[0].plane = Some(0);
    } else {
        // Fewer curves than planes on the aimed object: each goes to the plane seen nearest
        // its row; the plane left without a curve is reported as too short by the caller.
        for &ci in group.iter() {
            let mut best = 0;
            let mut best_d = Real::INFINITY;
            for &k in planes_order.iter() {
                let d = (rows[k] - cands[ci].mean_row).abs();
                if d < best_d {
                    best_d = d;
                    best = k;
                }
            }
            cands[ci].plane = Some(best);
        }
    }
    if let Some(stacks) = &config.stacks {
        fragments::assign_stacks(cands, runs, calibration, planes_order, stacks);
    }
    join_fragments(cands, runs, calibration, config);
}

/// The planes sorted by the image row at which each is seen on the central column, at the
/// depth where plane 0 sees a curve at row `row` (the order is the same at every depth for
/// parallel planes), and those rows by plane.
pub(super) fn planes_by_row(
    calibration: &Calibration,
    row: Real,
) -> ([usize; MAX_PLANES], [Real; MAX_PLANES]) {
    let cam = &calibration.camera;
    let depth = cam
        .pixel_to_ray(Vec2::new(cam.cx, row))
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
    let n = calibration.planes.len().min(MAX_PLANES);
    order[..n].sort_unstable_by(|&a, &b| {
        rows[a]
            .partial_cmp(&rows[b])
            .unwrap_or(core::cmp::Ordering::Equal)
    });
    (order, rows)
}

/// Joins the candidates left without a plane that continue an assigned curve: a column gap
/// of at most `max_fragment_gap` and a mean-row step of at most `max_fragment_step` (and, with
/// `config.stacks`, depths that agree with the other planes' pieces in the same columns).
fn join_fragments(
    cands: &mut [Candidate],
    runs: &[Run],
    calibration: &Calibration,
    config: &PipelineConfig,
) {
    let mut changed = true;
    while changed {
        changed = false;
        for i in 0..cands.len() {
            if cands[i].plane.is_some() {
                continue;
            }
            let c = cands[i];
            let join = cands.iter().find_map(|a| {
                let plane = a.plane?;
                let gap = if c.min_x > a.max_x {
                    c.min_x - a.max_x
                } else if a.min_x > c.max_x {
                    a.min_x - c.max_x
                } else {
                    u16::MAX // overlapping columns: another object, not a fragment
                };
                (gap <= config.max_fragment_gap
                    && (c.mean_row - a.mean_row).abs() <= config.max_fragment_step)
                    .then_some(plane)
            });
            let join = join.filter(|&plane| {
                config.stacks.as_ref().is_none_or(|stacks| {
                    fragments::agrees_with_partners(&c, plane, cands, runs, calibration, stacks)
                })
            });
            if let Some(plane) = join {
                cands[i].plane = Some(plane);
                changed = true;
            }
        }
    }
}
