//! The readings taken from the fitted walls (`docs/building.md`, "From planes to readings"):
//! the corner between two walls, the distance between parallel ones, and the aimed wall's
//! segment along a laser line with its ends.

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, normal_cdf, sqrt, Real, Vec3, PI};

use super::super::plane_pca::{
    normal_angle, parallel_distance, plane_intersection, Estimate, PlaneFit,
};
use super::{column, Corner, EndKind, Run, Segment, Wall, WallInput, WallParams};
use crate::curve::CurvePoint;

/// The corner between the two largest walls more than 30° apart.
pub(super) fn corner(walls: &[Wall]) -> Option<Corner> {
    for a in 0..walls.len() {
        for b in a + 1..walls.len() {
            if normal_angle(&walls[a].plane, &walls[b].plane).value < PI / 6.0 {
                continue;
            }
            return Some(corner_between(walls, a, b));
        }
    }
    None
}

/// The corner between walls `a` and `b` (indices into `walls`).
pub(super) fn corner_between(walls: &[Wall], a: usize, b: usize) -> Corner {
    let (pa, pb) = (&walls[a].plane, &walls[b].plane);
    let between = normal_angle(pa, pb);
    Corner {
        walls: (a, b),
        angle: Estimate {
            value: PI - between.value,
            sigma: between.sigma,
        },
        // A receding (room) corner puts each wall on the camera's side of the other.
        convex: pa.signed_distance(pb.centroid) > 0.0,
    }
}

/// Distance between the two largest parallel walls.
pub(super) fn parallel(walls: &[Wall], params: &WallParams) -> Option<Estimate> {
    parallel_pair(walls, params).map(|(a, b)| parallel_distance(&walls[a].plane, &walls[b].plane))
}

/// The two largest parallel walls (indices into `walls`).
pub(super) fn parallel_pair(walls: &[Wall], params: &WallParams) -> Option<(usize, usize)> {
    for a in 0..walls.len() {
        for b in a + 1..walls.len() {
            if normal_angle(&walls[a].plane, &walls[b].plane).value <= params.parallel_max {
                return Some((a, b));
            }
        }
    }
    None
}

/// Points inward from a segment's end whose stripe amplitudes are the reference for the
/// end pixel's lit part ([`lit_fraction`]).
const EDGE_REFERENCE: usize = 9;

/// Least σ of an edge located from the lit part of its pixel (pixels): the amplitude's
/// proportionality to the lit part holds for a sharp image of a uniform sheet; a blurred
/// edge or a sheet varying over a pixel departs from it by a fraction of the pixel.
const EDGE_SIGMA_FLOOR_PX: Real = 0.1;

/// The part `f` of the end point `inner`'s pixel lit by the wall, from its stripe amplitude
/// against the median of the `inward` points' (the wall's own brightness there), and its
/// σ from their scatter (`docs/building.md`, (B9)), and that median (the wall's stripe
/// amplitude): `None` when the stripes are unknown, fewer than 5 references, one is
/// saturated (its amplitude is clipped), or an amplitude is not finite.
fn lit_fraction(
    stripe: &[CurvePoint],
    inner: usize,
    inward: impl Iterator<Item = usize>,
) -> Option<(Real, Real, Real)> {
    let end = stripe.get(inner).filter(|p| !p.saturated)?;
    let mut reference = [0.0 as Real; EDGE_REFERENCE];
    let mut n = 0;
    for i in inward {
        let p = stripe.get(i).filter(|p| !p.saturated)?;
        if let Some(slot) = reference.get_mut(n) {
            *slot = p.amplitude;
            n += 1;
        }
    }
    if n < 5 {
        return None;
    }
    let reference = &mut reference[..n];
    reference.sort_unstable_by(|a, b| a.total_cmp(b));
    let median = reference[n / 2];
    if !(median > 0.0) {
        return None;
    }
    // Scatter of one amplitude about the median (1.4826·MAD), relative.
    let mut deviations = [0.0 as Real; EDGE_REFERENCE];
    for (d, a) in deviations.iter_mut().zip(reference.iter()) {
        *d = (a - median).abs();
    }
    let deviations = &mut deviations[..n];
    deviations.sort_unstable_by(|a, b| a.total_cmp(b));
    let relative = 1.4826 * deviations[n / 2] / median;
    let f = (end.amplitude / median).clamp(0.0, 1.0);
    // f = a/A: the end's own scatter and the median's (≈ 1.25/√n of one).
    let sigma_f = f * relative * sqrt(1.0 + 1.57 / n as Real);
    // A NaN amplitude is no measurement (`clamp` keeps NaN).
    (f.is_finite() && sigma_f.is_finite()).then_some((f, sigma_f, median))
}

/// The part of a pixel centred `δ` pixels inside a wall's edge that the wall's blurred
/// image lights: the step blurred by the lens's PSF (`σ` px) integrated over the pixel,
/// `σ·[ψ((δ+½)/σ) − ψ((δ−½)/σ)]`, `ψ(z) = zΦ(z) + φ(z)` (`docs/building.md`, (B9)); and
/// its derivative in `δ`, `Φ((δ+½)/σ) − Φ((δ−½)/σ)`.
fn blurred_coverage(delta: Real, sigma: Real) -> (Real, Real) {
    let psi = |z: Real| {
        let density = (-0.5 * z * z).exp() / sqrt(2.0 * PI);
        z * normal_cdf(z) + density
    };
    let (hi, lo) = ((delta + 0.5) / sigma, (delta - 0.5) / sigma);
    (sigma * (psi(hi) - psi(lo)), normal_cdf(hi) - normal_cdf(lo))
}

/// Where the edge is past the end pixel's centre (pixels, outwards) for a lit part `f` of
/// its 1σ `sigma_f` ([`lit_fraction`]), with its σ: the `δ` whose [`blurred_coverage`] is
/// `f`, by bisection (it rises monotonically), within the end pixel (`|δ| ≤ ½`) and with at
/// most the σ of an edge anywhere in it, `1/√12`.
///
/// An end pixel as bright as an edge at its outer side gives says only that the edge is
/// there or beyond: near `δ = ½` the blurred coverage hardly changes with `δ`. How far beyond
/// is bounded by the next column, which was not seen: its lit part `c(δ − 1)` stayed below
/// `detect`, the detection threshold over the wall's stripe amplitude, so the edge is
/// anywhere in `½ ≤ δ < 1 + c⁻¹(detect)` — the middle of that range, with its uniform σ
/// (`docs/building.md`, (B9b)). With `detect` unknown (0), or not below `c(½)` (a stripe
/// barely above the threshold says nothing of the next column), the outer side with `1/√12`,
/// as without the stripes. `None` for a PSF σ that is not positive.
fn edge_offset(f: Real, sigma_f: Real, detect: Real, params: &WallParams) -> Option<(Real, Real)> {
    let sigma = params.psf_sigma_px;
    if !(sigma > 0.0) {
        return None;
    }
    let uniform = 1.0 / sqrt(12.0);
    let outer = blurred_coverage(0.5, sigma).0;
    if f >= outer {
        if !(detect > 0.0 && detect < outer) {
            return Some((0.5, uniform));
        }
        // The next column's centre is `δ − 1` inside the edge: unseen while c(δ − 1) < detect.
        let beyond = 1.0 + coverage_inverse(detect, sigma);
        let width = (beyond - 0.5).max(0.0);
        return Some((0.5 + 0.5 * width, uniform));
    }
    let delta = coverage_inverse(f, sigma);
    let slope = blurred_coverage(delta, sigma).1.max(1e-3);
    Some((delta, (sigma_f / slope).clamp(EDGE_SIGMA_FLOOR_PX, uniform)))
}

/// The `δ` in `[−½, ½]` whose [`blurred_coverage`] is `f` (clamped to that range), by
/// bisection: the coverage rises monotonically in `δ`.
fn coverage_inverse(f: Real, sigma: Real) -> Real {
    let (mut lo, mut hi) = (-0.5 as Real, 0.5 as Real);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if blurred_coverage(mid, sigma).0 < f {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The aimed wall's line on one curve, for following it past clutter in front of the wall.
struct LineOnWall<'a> {
    input: &'a WallInput<'a>,
    params: &'a WallParams,
    runs: &'a [Run],
    aimed: usize,
    plane: &'a PlaneFit,
    curve: usize,
}

/// Where a segment's end is once followed past clutter ([`LineOnWall::reach`]).
struct Reach {
    /// The end point's index on the curve.
    end: usize,
    /// The innermost point of the stretch on the wall that ends there (reference points for
    /// [`lit_fraction`] lie between the two).
    limit: usize,
    /// A nearer object hides the end: the line goes on behind it, and is not seen on the wall
    /// again.
    occluded: bool,
}

/// Fewest points of a stretch of the line on the wall past an object in front of it.
const MIN_STRETCH: usize = 3;

impl LineOnWall<'_> {
    /// How point `i` lies against the wall: on it (within `split_sigmas`·σ + `split_floor`),
    /// in front of it (`Some(true)`), or behind it (`Some(false)`); `None` when it is on it.
    fn off_wall(&self, i: usize) -> Option<bool> {
        let p = self.input.curves[self.curve][i];
        let sigma = self.input.sigmas[self.curve].get(i).copied().unwrap_or(0.0);
        let tolerance = self.params.split_sigmas * sigma + self.params.split_floor;
        let d = self.plane.signed_distance(p);
        // The camera (the origin) is in front of the wall.
        let front = -self.plane.offset;
        (d.abs() > tolerance).then_some(d * front > 0.0)
    }

    /// Whether point `i` is in a run of another wall.
    fn other_wall(&self, i: usize) -> bool {
        self.runs.iter().any(|r| {
            r.curve as usize == self.curve
                && r.wall.is_some_and(|w| w as usize != self.aimed)
                && (r.start as usize..r.end as usize).contains(&i)
        })
    }

    /// Point `i + step` if the curve has it.
    fn next(&self, i: usize, step: isize) -> Option<usize> {
        i.checked_add_signed(step)
            .filter(|&j| j < self.input.curves[self.curve].len())
    }

    /// Whether the step from point `i` to point `j` is a jump, as [`super::split_curve`]
    /// cuts runs at: farther than `gap_px` pixels' worth of distance and the points' σ.
    fn jump(&self, i: usize, j: usize) -> bool {
        let (pts, sig) = (self.input.curves[self.curve], self.input.sigmas[self.curve]);
        let step = norm(&(pts[j] - pts[i]));
        let spacing = self.params.gap_px * norm(&pts[j]) / self.params.focal_px;
        let sigmas = sig.get(i).copied().unwrap_or(0.0) + sig.get(j).copied().unwrap_or(0.0);
        !(step <= spacing + self.params.split_sigmas * sigmas)
    }

    /// Follows the line outwards (`step` −1: left, +1: right) from its end point `end` (the
    /// stretch on the wall from `limit`): across an object in front of the wall no wider than
    /// `max_occluder_px` (a cable, a pipe: a jump towards the camera to at least
    /// [`MIN_STRETCH`] points in front of the wall, in no other wall's run, then the wall
    /// again for at least [`MIN_STRETCH`] points), as often as there is one. Such an object
    /// behind which the wall is not seen again, before another wall's run, a surface behind
    /// the wall or the curve's end, hides the end (`docs/building.md`, "Segment length").
    /// Points in front of the wall without a jump (a jamb the line runs onto) or fewer than
    /// [`MIN_STRETCH`] (the kink's smeared points) are no object: the end stays an edge.
    fn reach(&self, end: usize, limit: usize, step: isize) -> Reach {
        let mut reach = Reach {
            end,
            limit,
            occluded: false,
        };
        let column_of = |i: usize| column(self.input.curves[self.curve][i], self.params);
        while let Some(first_out) = self.next(reach.end, step) {
            if self.off_wall(first_out) != Some(true)
                || self.other_wall(first_out)
                || !self.jump(reach.end, first_out)
            {
                break;
            }
            // Across the object in front to the first point on the wall again.
            let u_end = column_of(reach.end);
            let (mut i, mut in_front) = (first_out, 0);
            let resumed = loop {
                if (column_of(i) - u_end).abs() > self.params.max_occluder_px || self.other_wall(i)
                {
                    break None;
                }
                match self.off_wall(i) {
                    None => break Some(i),
                    Some(false) => break None,
                    Some(true) => in_front += 1,
                }
                match self.next(i, step) {
                    Some(j) => i = j,
                    None => break None,
                }
            };
            if in_front < MIN_STRETCH {
                break;
            }
            // The stretch on the wall from there.
            let stretch = resumed.map(|start| {
                let (mut last, mut count) = (start, 1);
                while let Some(j) = self.next(last, step) {
                    if self.off_wall(j).is_some() || self.other_wall(j) {
                        break;
                    }
                    (last, count) = (j, count + 1);
                }
                (start, last, count)
            });
            match stretch {
                Some((start, last, count)) if count >= MIN_STRETCH => {
                    reach.end = last;
                    reach.limit = start;
                }
                _ => {
                    reach.occluded = true;
                    break;
                }
            }
        }
        reach
    }
}

/// The aimed wall's segment along the lowest curve across the image that lights it: its
/// points' first and last run, each followed past clutter in front of the wall
/// ([`LineOnWall::reach`]), each end at the next wall (corner), at the edge where the line
/// leaves the plane (placed within its pixel, [`lit_fraction`], [`edge_offset`]), hidden by
/// the clutter, or at the frame's side (`docs/building.md`, "Segment length").
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
    let line = LineOnWall {
        input,
        params,
        runs,
        aimed,
        plane: &wall.plane,
        curve,
    };
    for side in 0..2 {
        // Each end past the clutter in front of the wall that the line shows it beyond.
        let reach = if side == 0 {
            line.reach(first.start as usize, first.end as usize - 1, -1)
        } else {
            line.reach(last.end as usize - 1, last.start as usize, 1)
        };
        let inner = reach.end;
        let outer = if side == 0 {
            inner.checked_sub(1)
        } else {
            Some(inner + 1).filter(|&i| i < pts.len())
        };
        let u_in = column(pts[inner], params);
        // The neighbouring run on the same curve, if it is another wall's and adjoins.
        let next = runs.iter().find(|r| {
            r.curve as usize == curve
                && r.wall.is_some_and(|w| w as usize != aimed)
                && if side == 0 {
                    r.end as usize + 2 * params.trim_points + 2 >= inner && r.end as usize <= inner
                } else {
                    r.start as usize <= inner + 1 + 2 * params.trim_points + 2
                        && r.start as usize > inner
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
        // within that column, where the part of the pixel the wall fills ends. Its stripe's
        // amplitude against its neighbours' is that part, `f` (docs/building.md, "Segment
        // length", (B9)); without the stripes, the outer half-pixel, uniform: σ = 1/√12 px
        // (the pixel's centre instead read every segment 1 px short on the tuning rooms).
        let at_side = if side == 0 {
            u_in < params.edge_margin_px
        } else {
            u_in > params.width_px - 1.0 - params.edge_margin_px
        };
        if outer.is_none() && at_side {
            kinds[side] = EndKind::FrameSide;
        }
        let sign = if side == 0 { -1.0 } else { 1.0 };
        if reach.occluded {
            kinds[side] = EndKind::Occluded;
        }
        let stripe = input.stripes.get(curve).copied().unwrap_or(&[]);
        let lit = if side == 0 {
            lit_fraction(
                stripe,
                inner,
                (inner + 1..=reach.limit).take(EDGE_REFERENCE),
            )
        } else {
            lit_fraction(
                stripe,
                inner,
                (reach.limit..inner).rev().take(EDGE_REFERENCE),
            )
        };
        // Only an edge has an unseen next column: past the frame's side there is none, and
        // an occluder's column is seen (a lower bound stays at the last lit column's side).
        let detect = if kinds[side] == EndKind::Edge {
            input.threshold
        } else {
            0.0
        };
        let located =
            lit.and_then(|(f, s, amplitude)| edge_offset(f, s, detect / amplitude, params));
        let (u_edge, sigma_u) = match located {
            Some((offset, sigma)) => (u_in + sign * offset, sigma),
            None => (u_in + 0.5 * sign, 1.0 / sqrt(12.0)),
        };
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

#[cfg(test)]
mod tests {
    use super::*;

    fn stripe(amplitudes: &[Real]) -> [CurvePoint; 12] {
        let mut s = [CurvePoint::ZERO; 12];
        for (p, &a) in s.iter_mut().zip(amplitudes) {
            p.amplitude = a;
        }
        s
    }

    /// The blurred coverage is the pixel's lit part: ½ with the edge at its centre, the box
    /// `δ + ½` for a sharp image, the derivative its slope; the edge found from a lit part
    /// gives that part back.
    #[test]
    fn the_blurred_coverage_places_the_edge() {
        // Rounding of the core's precision (f32 on the device): a few hundred ulps of the
        // erf-based coverage; the central difference's step and error scale with it.
        let tol = (1e-9 as Real).max(300.0 * Real::EPSILON);
        let h = (1e-5 as Real).max(1e3 * Real::EPSILON).sqrt() * 0.1;
        assert!((blurred_coverage(0.0, 0.5).0 - 0.5).abs() < tol);
        for delta in [-0.4, -0.1, 0.2, 0.45] {
            let (sharp, slope) = blurred_coverage(delta, 0.01);
            assert!(
                (sharp - (delta + 0.5)).abs() < 1e-6 + tol,
                "{delta}: {sharp}"
            );
            assert!((slope - 1.0).abs() < 1e-6 + tol, "{delta}: {slope}");
            let (blurred, slope) = blurred_coverage(delta, 0.5);
            let numeric = (blurred_coverage(delta + h, 0.5).0 - blurred_coverage(delta - h, 0.5).0)
                / (2.0 * h);
            assert!((slope - numeric).abs() < 10.0 * h * h + tol / h, "{delta}");
            let params = WallParams::default();
            let (found, sigma) = edge_offset(blurred, 0.02, 0.0, &params).unwrap();
            if blurred < blurred_coverage(0.5, 0.5).0 {
                assert!((found - delta).abs() < 10.0 * tol, "{delta}: {found}");
                let want = (0.02 / slope).max(EDGE_SIGMA_FLOOR_PX);
                assert!(
                    (sigma - want).abs() < 10.0 * tol * want,
                    "{sigma} vs {want}"
                );
            }
        }
        // A pixel as bright as its neighbours: the outer side, with the uniform σ.
        let (found, sigma) = edge_offset(1.0, 0.02, 0.0, &WallParams::default()).unwrap();
        assert_eq!(found, 0.5);
        assert!((sigma - 1.0 / sqrt(12.0)).abs() < tol);
    }

    /// A fully lit end pixel: the edge is past its outer side by up to where the unseen next
    /// column's lit part reaches the detection threshold — the middle of that range. A
    /// threshold at half the wall's amplitude allows the whole next half pixel (`c(0)` = ½):
    /// ¾ px past the end pixel's centre; unknown or no lower than `c(½)`, the outer side.
    #[test]
    fn past_a_fully_lit_end_pixel_the_edge_is_where_the_next_column_stays_unseen() {
        let params = WallParams::default();
        let uniform = 1.0 / sqrt(12.0);
        let tol = (1e-6 as Real).max(300.0 * Real::EPSILON);
        let (at, sigma) = edge_offset(1.0, 0.02, 0.5, &params).unwrap();
        assert!((at - 0.75).abs() < tol, "{at}");
        assert!((sigma - uniform).abs() < tol);
        // A lower threshold leaves less of the next column unseen.
        let (low, _) = edge_offset(0.95, 0.02, 0.2, &params).unwrap();
        let c = blurred_coverage(2.0 * low - 0.5 - 1.0, params.psf_sigma_px).0;
        assert!(low > 0.5 && low < 0.75, "{low}");
        assert!(
            (c - 0.2).abs() < 1e-4,
            "the range ends where the next column reaches it: {c}"
        );
        for detect in [0.0, 0.85, 1.5] {
            let (at, _) = edge_offset(1.0, 0.02, detect, &params).unwrap();
            assert_eq!(at, 0.5, "{detect}");
        }
        // A partly lit end pixel is placed by its own lit part, whatever the threshold.
        let (partial, _) = edge_offset(0.5, 0.02, 0.3, &params).unwrap();
        assert!(partial.abs() < tol, "{partial}");
    }

    /// The end's amplitude against the median of its neighbours', with the σ of their
    /// scatter; nothing without enough unsaturated neighbours.
    #[test]
    fn the_lit_fraction_is_the_end_amplitude_over_its_neighbours() {
        let s = stripe(&[20.0, 38.0, 42.0, 40.0, 39.0, 41.0, 40.0, 40.0, 44.0, 36.0]);
        let (f, sigma, _) = lit_fraction(&s, 0, 1..10).unwrap();
        assert!((f - 0.5).abs() < 1e-12, "{f}");
        assert!(sigma > 0.0 && sigma < 0.05, "{sigma}");
        assert!(lit_fraction(&s, 0, 1..4).is_none(), "3 references");
        assert!(lit_fraction(&[], 0, 1..10).is_none(), "no stripes");
        let mut clipped = s;
        clipped[4].saturated = true;
        assert!(
            lit_fraction(&clipped, 0, 1..10).is_none(),
            "a clipped reference"
        );
        let mut broken = s;
        broken[0].amplitude = Real::NAN;
        assert!(lit_fraction(&broken, 0, 1..10).is_none(), "a NaN amplitude");
    }
}
