//! The readings taken from the fitted walls (`docs/building.md`, "From planes to readings"):
//! the corner between two walls, the distance between parallel ones, and the aimed wall's
//! segment along a laser line with its ends.

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec3, PI};

use super::super::plane_pca::{normal_angle, parallel_distance, plane_intersection, Estimate};
use super::{column, Corner, EndKind, Run, Segment, Wall, WallInput, WallParams};

/// The corner between the two largest walls more than 30° apart.
pub(super) fn corner(walls: &[Wall]) -> Option<Corner> {
    for a in 0..walls.len() {
        for b in a + 1..walls.len() {
            let (pa, pb) = (&walls[a].plane, &walls[b].plane);
            let between = normal_angle(pa, pb);
            if between.value < PI / 6.0 {
                continue;
            }
            return Some(Corner {
                walls: (a, b),
                angle: Estimate {
                    value: PI - between.value,
                    sigma: between.sigma,
                },
                // A receding (room) corner puts each wall on the camera's side of the other.
                convex: pa.signed_distance(pb.centroid) > 0.0,
            });
        }
    }
    None
}

/// Distance between the two largest parallel walls.
pub(super) fn parallel(walls: &[Wall], params: &WallParams) -> Option<Estimate> {
    for a in 0..walls.len() {
        for b in a + 1..walls.len() {
            let (pa, pb) = (&walls[a].plane, &walls[b].plane);
            if normal_angle(pa, pb).value <= params.parallel_max {
                return Some(parallel_distance(pa, pb));
            }
        }
    }
    None
}

/// The aimed wall's segment along the lowest curve across the image that lights it: its
/// points' first and
/// last run, each end at the next wall (corner), at the edge where the line leaves the plane,
/// or at the frame's side (`docs/building.md`, "Segment length").
pub(super) fn segment(
    input: &WallInput<'_>,
    params: &WallParams,
    runs: &[Run],
    walls: &[Wall],
    aimed: usize,
) -> Option<Segment> {
    let wall = &walls[aimed];
    // A line across the image (the column-wise edge below needs one): not the crossing line.
    let curve = (0..input.planes.len())
        .find(|&k| wall.lines & (1 << k) != 0 && !input.planes[k].is_row_wise())?;
    let plane = &input.planes[curve];
    let mine = |r: &&Run| r.curve as usize == curve && r.wall == Some(aimed as u8);
    let first = runs.iter().filter(mine).min_by_key(|r| r.start)?;
    let last = runs.iter().filter(mine).max_by_key(|r| r.end)?;
    let (origin, dir) = plane_intersection(
        wall.plane.normal,
        wall.plane.offset,
        plane.normal,
        plane.offset,
    )?;
    let pts = input.curves[curve];
    let mut ends = [Vec3::zeros(); 2];
    let mut kinds = [EndKind::Edge; 2];
    let mut var = 0.0;
    for side in 0..2 {
        let (inner, outer) = if side == 0 {
            (first.start as usize, (first.start as usize).checked_sub(1))
        } else {
            (
                last.end as usize - 1,
                Some(last.end as usize).filter(|&i| i < pts.len()),
            )
        };
        let u_in = column(pts[inner], params);
        // The neighbouring run on the same curve, if it is another wall's and adjoins.
        let next = runs.iter().find(|r| {
            r.curve as usize == curve
                && r.wall.is_some_and(|w| w as usize != aimed)
                && if side == 0 {
                    r.end as usize + 2 * params.trim_points + 2 >= first.start as usize
                        && r.end <= first.start
                } else {
                    r.start as usize <= last.end as usize + 2 * params.trim_points + 2
                        && r.start >= last.end
                }
        });
        let corner_end = next.and_then(|r| {
            let other = &walls[r.wall? as usize].plane;
            let along = dir.dot(&other.normal);
            // A parallel wall beyond a jump (a niche's front wall seen past a jamb too thin
            // to fit) meets the line nowhere near: that end is an edge, not a corner.
            if along.abs() < params.parallel_max.sin() {
                return None;
            }
            let t = (other.offset - other.normal.dot(&origin)) / along;
            let p = origin + dir * t;
            Some((p, other.sigma_at(p) / along.abs()))
        });
        if let Some((p, s)) = corner_end {
            ends[side] = p;
            kinds[side] = EndKind::Corner;
            var += s * s;
            continue;
        }
        // The plane's stripe is seen up to its last column and not in the next: the edge is
        // within that column's outer half-pixel whatever follows (a deeper surface, a gap of
        // unlit columns), uniform: σ = 1/√12 px (docs/building.md, "Segment length"; the
        // pixel's centre instead read every segment 1 px short on the tuning rooms).
        let at_side = if side == 0 {
            u_in < params.edge_margin_px
        } else {
            u_in > params.width_px - 1.0 - params.edge_margin_px
        };
        if outer.is_none() && at_side {
            kinds[side] = EndKind::FrameSide;
        }
        let sign = if side == 0 { -1.0 } else { 1.0 };
        let (u_edge, sigma_u) = (u_in + 0.5 * sign, 1.0 / sqrt(12.0));
        let at = |u: Real| -> Option<Real> {
            let a = u - params.principal_u;
            let den = params.focal_px * dir.x - a * dir.z;
            (den.abs() > 1e-9).then(|| (a * origin.z - params.focal_px * origin.x) / den)
        };
        let t = at(u_edge)?;
        let dt = (at(u_edge + 0.5)? - at(u_edge - 0.5)?).abs();
        ends[side] = origin + dir * t;
        var += (dt * sigma_u) * (dt * sigma_u);
    }
    let length = norm(&(ends[1] - ends[0]));
    // The wall's depth scales the segment: δL/L = δz/z.
    let scale = wall.plane.centroid_sigma / wall.plane.offset.max(1e-3);
    var += (length * scale) * (length * scale);
    Some(Segment {
        curve,
        ends,
        kinds,
        length: Estimate {
            value: length,
            sigma: sqrt(var),
        },
    })
}
