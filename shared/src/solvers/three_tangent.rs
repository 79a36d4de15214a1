//! The three-tangent method (thesis §9.2–9.5, §9.9; `docs/cylinder.md`, "Three-tangent
//! method"): the two rays from the laser source that graze the stem and the tangent at the
//! arc's point nearest the source fix the circle, `r = D·sin α / (1 − sin α)`
//! ([`three_tangent_radius`], [`three_tangent`]); for a tilted stem, the same on the curve
//! projected along the fitted axis ([`generalised_three_tangent`]).
//!
//! In-plane coordinates are those of [`crate::laser_plane::LaserPlane::to_plane_coords`]:
//! origin at the laser source, so the grazing rays are rays from the origin.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec2, Vec3, PI};

use nalgebra::{SMatrix, SVector};

use super::cylinder_fit::project_along_axis;
use super::SolveError;

/// Radius of the circle tangent to two rays from the origin at half-aperture `α` and to the
/// line perpendicular to their bisector at distance `D` from the origin:
/// `r = D·sin α / (1 − sin α)` (`docs/cylinder.md`, "Three-tangent method").
///
/// [`SolveError::Degenerate`] unless `0 < α < π/2` and `D > 0` (both finite).
pub fn three_tangent_radius(alpha: Real, nearest: Real) -> Result<Real, SolveError> {
    if !(alpha.is_finite() && nearest.is_finite()) {
        return Err(SolveError::NonFinite);
    }
    let s = alpha.sin();
    if !(alpha > 0.0 && alpha < 0.5 * PI && nearest > 0.0 && s < 1.0) {
        return Err(SolveError::Degenerate);
    }
    let r = nearest * s / (1.0 - s);
    if r.is_finite() {
        Ok(r)
    } else {
        Err(SolveError::Degenerate)
    }
}

/// Settings of [`three_tangent`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThreeTangentParams {
    /// Angle (radians) added outward to each grazing ray. The last lit column of a
    /// column-wise extraction lies inside the silhouette by about half a column; the
    /// pipeline sets this to `0.5/f` (f in pixels) to remove that bias, or 0.
    pub edge_extension: Real,
    /// Half-width of the window around the nearest point used to locate it, as a fraction
    /// of the radius (0.3: the fitted parabola's model error after the quartic correction
    /// is below 1e-5·r, `docs/cylinder.md`).
    pub nearest_window: Real,
    /// Fewest points in that window (the window widens up to the whole arc to get them).
    pub min_window_points: usize,
}

impl Default for ThreeTangentParams {
    fn default() -> Self {
        ThreeTangentParams {
            edge_extension: 0.0,
            nearest_window: 0.3,
            min_window_points: 6,
        }
    }
}

/// Result of the three-tangent method in one plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThreeTangent {
    /// Radius (same units as the points).
    pub radius: Real,
    /// Centre of the section, `(D + r)·u_c`.
    pub centre: Vec2,
    /// Half-aperture `α` between the two grazing rays (radians).
    pub alpha: Real,
    /// Distance `D` from the source to the tangent at the nearest point.
    pub nearest_distance: Real,
    /// Unit bisector `u_c` of the grazing rays (towards the stem).
    pub bisector: Vec2,
    /// The two grazing rays' angles from the reference direction (radians, after the
    /// edge extension), smaller first.
    pub edge_angles: (Real, Real),
    /// Points used in the nearest-point fit.
    pub window_points: usize,
    /// RMS residual of the nearest-point fit (data-driven point noise along `u_c`).
    pub window_rms: Real,
    /// Variance factor of `D`: `var(D) = factor·σ²` for independent point noise `σ` along
    /// `u_c` (the `[0,0]` element of `(XᵀX)⁻¹` of the parabola fit).
    pub nearest_variance_factor: Real,
}

impl ThreeTangent {
    /// `∂r/∂α` and `∂r/∂D` at this solution (`docs/cylinder.md`, "Sensitivity").
    pub fn partials(&self) -> (Real, Real) {
        let (s, c) = self.alpha.sin_cos();
        let k = 1.0 - s;
        (self.nearest_distance * c / (k * k), s / k)
    }
}

/// Three-tangent method on in-plane points of one laser curve, source at the origin
/// (`docs/cylinder.md`, "Three-tangent method" and "Locating the three tangents").
///
/// * Grazing rays: the extreme polar angles of the points seen from the source. The polar
///   angle is stationary at a tangent point, so the extreme is insensitive to where along
///   the curve the stripe fades; for column-wise extraction it is exact per column.
/// * Nearest tangent: a parabola `w(t)` fitted to the points within
///   `nearest_window·r` of the bisector (`w` along the bisector, `t` across), after removing
///   the circle's known quartic-and-higher terms; its vertex is `D`. Two passes (the first
///   with `r` from the nearest sample).
///
/// Errors: fewer than `min_window_points` (at least 5) points; points not all in one open
/// half-plane in front of the source, or no positive aperture ([`SolveError::Degenerate`]);
/// non-finite input.
pub fn three_tangent(
    points: &[Vec2],
    params: &ThreeTangentParams,
) -> Result<ThreeTangent, SolveError> {
    if !(params.edge_extension.is_finite()
        && params.edge_extension >= 0.0
        && params.nearest_window.is_finite()
        && params.nearest_window > 0.0)
    {
        return Err(SolveError::InvalidParameter);
    }
    let min_pts = params.min_window_points.max(5);
    if points.len() < min_pts {
        return Err(SolveError::TooFewPoints);
    }
    // Reference direction: mean of the unit vectors to the points.
    let mut sum = Vec2::zeros();
    for q in points {
        if !(q.x.is_finite() && q.y.is_finite()) {
            return Err(SolveError::NonFinite);
        }
        let n = norm(q);
        if !(n > 0.0) {
            return Err(SolveError::Degenerate);
        }
        sum += q / n;
    }
    let len = norm(&sum);
    if !(len > 1e-3 * points.len() as Real) {
        return Err(SolveError::Degenerate);
    }
    let fwd = sum / len;
    let side = Vec2::new(fwd.y, -fwd.x);
    // The polar angle `atan2(side, along)` with `along > 0` is `atan(side/along)`, monotone
    // in the ratio: the extremes are found on the ratio and only their two angles computed
    // (an arctangent per point was a tenth of a long arc's solver on the device).
    // Seeded with the first point, so that a ratio that overflows to ±∞ still counts.
    let (mut lowest, mut highest) = ((Real::NAN, 0.0, 1.0), (Real::NAN, 0.0, 1.0));
    for (i, q) in points.iter().enumerate() {
        let along = q.dot(&fwd);
        if !(along > 0.0) {
            return Err(SolveError::Degenerate);
        }
        let across = q.dot(&side);
        let ratio = across / along;
        if i == 0 || ratio < lowest.0 {
            lowest = (ratio, across, along);
        }
        if i == 0 || ratio > highest.0 {
            highest = (ratio, across, along);
        }
    }
    let mut psi_min = lowest.1.atan2(lowest.2);
    let mut psi_max = highest.1.atan2(highest.2);
    psi_min -= params.edge_extension;
    psi_max += params.edge_extension;
    let alpha = 0.5 * (psi_max - psi_min);
    let psi_c = 0.5 * (psi_max + psi_min);
    let (sc, cc) = psi_c.sin_cos();
    let u_c = fwd * cc + side * sc;
    let u_p = side * cc - fwd * sc;
    let mut nearest = Real::INFINITY;
    for q in points {
        nearest = nearest.min(q.dot(&u_c));
    }
    let mut r = three_tangent_radius(alpha, nearest)?;
    let mut out = None;
    for _pass in 0..2 {
        let fit = nearest_parabola(points, u_c, u_p, r, params.nearest_window * r, min_pts)?;
        nearest = fit.0;
        r = three_tangent_radius(alpha, nearest)?;
        out = Some(fit);
    }
    let (d, m, rms, factor) = out.ok_or(SolveError::Degenerate)?;
    Ok(ThreeTangent {
        radius: r,
        centre: u_c * (d + r),
        alpha,
        nearest_distance: d,
        bisector: u_c,
        edge_angles: (psi_min, psi_max),
        window_points: m,
        window_rms: rms,
        nearest_variance_factor: factor,
    })
}

/// Circle terms beyond the parabola: `r − √(r² − t²) − t²/(2r)` (= t⁴/8r³ + …).
fn higher_order(t: Real, r: Real) -> Real {
    let s = r * r - t * t;
    if s > 0.0 {
        r - sqrt(s) - t * t / (2.0 * r)
    } else {
        0.0
    }
}

/// Vertex of the parabola fitted to `(t, w − higher_order)` within `|t| ≤ window`
/// (widened ×2 up to 4 times until `min_pts` points are in): `(D, points, rms, var factor)`.
fn nearest_parabola(
    points: &[Vec2],
    u_c: Vec2,
    u_p: Vec2,
    r: Real,
    window: Real,
    min_pts: usize,
) -> Result<(Real, usize, Real, Real), SolveError> {
    let mut w = window;
    for _ in 0..5 {
        // Normal equations in τ = t/w (conditioned: |τ| ≤ 1).
        let mut xtx = SMatrix::<Real, 3, 3>::zeros();
        let mut xty = SVector::<Real, 3>::zeros();
        let mut m = 0usize;
        for q in points {
            let t = q.dot(&u_p);
            if t.abs() > w {
                continue;
            }
            let y = q.dot(&u_c) - higher_order(t, r);
            let tau = t / w;
            let x = SVector::<Real, 3>::new(1.0, tau, tau * tau);
            xtx += x * x.transpose();
            xty += x * y;
            m += 1;
        }
        if m < min_pts {
            w *= 2.0;
            continue;
        }
        let inv = xtx.try_inverse().ok_or(SolveError::Degenerate)?;
        let c = inv * xty;
        if !(c[2] > 0.0) {
            return Err(SolveError::Degenerate);
        }
        let tau_v = -c[1] / (2.0 * c[2]);
        if !(tau_v.abs() <= 1.0) {
            // The minimum is not inside the window: the arc's nearest part is missing.
            return Err(SolveError::Degenerate);
        }
        let tv = tau_v * w;
        let d = c[0] - c[1] * c[1] / (4.0 * c[2]) + higher_order(tv, r);
        let mut ss = 0.0;
        for q in points {
            let t = q.dot(&u_p);
            if t.abs() > w {
                continue;
            }
            let tau = t / w;
            let y = q.dot(&u_c) - higher_order(t, r);
            let e = y - (c[0] + c[1] * tau + c[2] * tau * tau);
            ss += e * e;
        }
        let rms = if m > 3 {
            sqrt(ss / (m - 3) as Real)
        } else {
            0.0
        };
        if !(d.is_finite() && d > 0.0) {
            return Err(SolveError::Degenerate);
        }
        return Ok((d, m, rms, inv[(0, 0)].max(0.0)));
    }
    Err(SolveError::TooFewPoints)
}

/// Generalised three-tangent method (§9.9): project the curve and the laser source along
/// the cylinder axis onto the plane perpendicular to it; the projected lit arc is an arc of
/// the true circular section and the grazing rays project onto its tangents from the
/// projected source, so [`three_tangent`] applies unchanged (`docs/cylinder.md`,
/// "Generalised three-tangent method").
pub fn generalised_three_tangent(
    curve: &[Vec3],
    source: Vec3,
    axis: Vec3,
    params: &ThreeTangentParams,
    scratch: &mut [Vec2],
) -> Result<ThreeTangent, SolveError> {
    let projected = project_along_axis(curve, source, axis, scratch)?;
    three_tangent(projected.points, params)
}

#[cfg(test)]
// The casts to f64 are no-ops in f64 builds but needed with `--features f32`.
#[allow(clippy::unnecessary_cast)]
pub(crate) mod tests {
    extern crate std;
    use super::*;

    const EPS: Real = Real::EPSILON;

    /// The lit arc of a circle seen from the origin, sampled uniformly in the angle at the
    /// centre between the two analytic tangent points (inclusive).
    pub(crate) fn lit_arc(c: Vec2, r: Real, n: usize, out: &mut [Vec2]) {
        let l = c.norm();
        let beta = (r / l).acos(); // angle at the centre between −c and a tangent point
        let base = (-c.y).atan2(-c.x);
        for (i, o) in out.iter_mut().take(n).enumerate() {
            let t = base - beta + 2.0 * beta * i as Real / (n - 1) as Real;
            *o = c + Vec2::new(t.cos(), t.sin()) * r;
        }
    }

    // -----------------------------------------------------------------------------------
    // Error when the tilt is ignored (§9.6, `docs/cylinder.md`). Analysis only: it checks the
    // documented `1/cos φ` bias that `Flags::TILT_IGNORED` warns about, so it lives with the
    // tests rather than in the instrument.
    // -----------------------------------------------------------------------------------

    /// Unit axis direction, in the plane frame `(a, b, n)`, of a cylinder tilted by `θ` (lean
    /// in the `(b, n)` plane: towards (+) or away from the instrument along the laser fan's
    /// depth direction) and `φ` (lean in the `(a, n)` plane: sideways):
    /// `u ∝ (tan φ, tan θ, 1)` (`docs/cylinder.md`, "Tilt angles").
    pub(crate) fn tilted_axis(theta: Real, phi: Real) -> Result<Vec3, SolveError> {
        if !(theta.is_finite() && phi.is_finite() && theta.abs() < 0.5 * PI && phi.abs() < 0.5 * PI)
        {
            return Err(SolveError::InvalidParameter);
        }
        let v = Vec3::new(phi.tan(), theta.tan(), 1.0);
        Ok(v / norm(&v))
    }

    /// Ratio `r_3T / r` of the three-tangent radius to the true radius when a cylinder tilted by
    /// `(θ, φ)` ([`tilted_axis`]) is treated as transversal, with its axis piercing the plane
    /// at distance `l_over_r·r` from the source along the depth axis `b`
    /// (`docs/cylinder.md`, "Error when the tilt is ignored").
    ///
    /// The section is an ellipse with semi-axes `r/cos Θ` (along the axis' projection) and `r`
    /// (`cos Θ = u·n`); the grazing rays are its tangents from the source (closed form) and the
    /// nearest tangent its support line along their bisector, so the ratio is exact. Far from
    /// the stem it tends to `1/cos φ`, independent of `θ`.
    fn tilt_error_ratio(theta: Real, phi: Real, l_over_r: Real) -> Result<Real, SolveError> {
        let u = tilted_axis(theta, phi)?;
        if !(l_over_r.is_finite() && l_over_r > 1.0) {
            return Err(SolveError::InvalidParameter);
        }
        let r: Real = 1.0;
        let c = Vec2::new(0.0, l_over_r);
        let proj = Vec2::new(u.x, u.y);
        let pn = norm(&proj);
        let (e_maj, e_min) = if pn > 0.0 {
            let e = proj / pn;
            (e, Vec2::new(-e.y, e.x))
        } else {
            (Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0))
        };
        let big = r / u.z; // r / cos Θ
        let small = r;
        let (ia, ib) = (1.0 / (big * big), 1.0 / (small * small));
        // Source in the ellipse frame.
        let p = Vec2::new((-c).dot(&e_maj), (-c).dot(&e_min));
        let g = Vec2::new(ia * p.x, ib * p.y);
        let k = ia * p.x * p.x + ib * p.y * p.y - 1.0;
        // Tangent directions d: dᵀ(g gᵀ − k Q)d = 0.
        let m11 = g.x * g.x - k * ia;
        let m12 = g.x * g.y;
        let m22 = g.y * g.y - k * ib;
        let disc = m12 * m12 - m11 * m22;
        if !(disc > 0.0) {
            return Err(SolveError::Degenerate);
        }
        let sq = sqrt(disc);
        let dirs = if m22.abs() >= m11.abs() {
            [Vec2::new(m22, -m12 + sq), Vec2::new(m22, -m12 - sq)]
        } else {
            [Vec2::new(-m12 + sq, m11), Vec2::new(-m12 - sq, m11)]
        };
        let mut psi = [0.0; 2];
        for (k, d) in dirs.iter().enumerate() {
            let mut v = e_maj * d.x + e_min * d.y;
            if v.dot(&c) < 0.0 {
                v = -v;
            }
            psi[k] = v.x.atan2(v.y);
        }
        let alpha = 0.5 * (psi[0] - psi[1]).abs();
        let psi_c = 0.5 * (psi[0] + psi[1]);
        let u_c = Vec2::new(psi_c.sin(), psi_c.cos());
        // Support function of the ellipse in direction −u_c: min over the ellipse of q·u_c.
        let (ua, ub) = (u_c.dot(&e_maj), u_c.dot(&e_min));
        let d = c.dot(&u_c) - sqrt(big * big * ua * ua + small * small * ub * ub);
        Ok(three_tangent_radius(alpha, d)? / r)
    }

    #[test]
    fn radius_formula_inverts_geometry() {
        // A circle of radius r at centre distance L: sin α = r/L, D = L − r.
        for (r, l) in [(0.05, 0.6), (0.3, 1.5), (0.5, 3.5)] {
            let (r, l): (Real, Real) = (r, l);
            let got = three_tangent_radius((r / l).asin(), l - r).unwrap();
            assert!((got - r).abs() <= 16.0 * EPS * l, "{got} {r}");
        }
        assert_eq!(three_tangent_radius(0.0, 1.0), Err(SolveError::Degenerate));
        assert_eq!(three_tangent_radius(0.3, -1.0), Err(SolveError::Degenerate));
        assert_eq!(
            three_tangent_radius(Real::NAN, 1.0),
            Err(SolveError::NonFinite)
        );
    }

    #[test]
    fn three_tangent_exact_arc() {
        let mut pts = [Vec2::zeros(); 801];
        for (c, r) in [
            (Vec2::new(0.0, 1.7), 0.2),
            (Vec2::new(0.3, 1.0), 0.45),
            (Vec2::new(-0.1, 0.6), 0.03),
        ] {
            lit_arc(c, r, 801, &mut pts);
            let t = three_tangent(&pts, &ThreeTangentParams::default()).unwrap();
            // Exact geometry: only rounding. ψ and the parabola carry ~ε relative errors on
            // O(L) quantities, amplified by ∂r/∂α ≈ D/(1−sin α)² ≤ 4L here and by the
            // window fit's conditioning (≲ 10): 100·ε·L.
            let tol = 100.0 * EPS * c.norm();
            assert!((t.radius - r).abs() < tol, "{t:?} r={r}");
            assert!((t.centre - c).norm() < 10.0 * tol);
            assert!((t.nearest_distance - (c.norm() - r)).abs() < tol);
        }
    }

    #[test]
    fn three_tangent_errors() {
        let p = ThreeTangentParams::default();
        let few = [Vec2::new(0.0, 1.0); 3];
        assert_eq!(
            three_tangent(&few, &p).err(),
            Some(SolveError::TooFewPoints)
        );
        // Points around the source (not in a half-plane in front of it).
        let mut ring = [Vec2::zeros(); 12];
        for (i, q) in ring.iter_mut().enumerate() {
            let t = i as Real * 2.0 * PI / 12.0;
            *q = Vec2::new(t.cos(), t.sin());
        }
        assert_eq!(three_tangent(&ring, &p).err(), Some(SolveError::Degenerate));
        let mut pts = [Vec2::zeros(); 50];
        lit_arc(Vec2::new(0.0, 1.5), 0.2, 50, &mut pts);
        pts[7].x = Real::NAN;
        assert_eq!(three_tangent(&pts, &p).err(), Some(SolveError::NonFinite));
    }

    #[test]
    fn tilt_ratio_against_analytic_ellipse() {
        // No tilt: exact.
        let r0 = tilt_error_ratio(0.0, 0.0, 8.0).unwrap();
        assert!((r0 - 1.0).abs() < 100.0 * EPS);
        // Far field: 1/cos φ whatever θ (docs/cylinder.md); the near-field correction is
        // O(r/L). The tangent construction cancels terms of size (L/r)², so L/r is kept
        // below ε^(-1/3) (1e4 in f64, 150 in f32); tolerance 5·r/L + 1e4·ε.
        let deg = PI / 180.0;
        let l: Real = if EPS > 1e-10 { 150.0 } else { 1e4 };
        for (th, ph) in [(0.0, 20.0), (25.0, 20.0), (30.0, 0.0), (-15.0, 10.0)] {
            let got = tilt_error_ratio(th * deg, ph * deg, l).unwrap();
            let want = 1.0 / (ph * deg).cos();
            assert!(
                (got - want).abs() < 5.0 / l + 1e4 * EPS,
                "{th} {ph}: {got} vs {want}"
            );
        }
        // Near field: the point-based three-tangent on densely sampled lit points of the
        // analytic ellipse. Sampling 40 000 points over the full ellipse: the extreme polar
        // angle misses the tangent by ≤ (Δs)²·κ/(2L) ~ 1e-9; the nearest-point parabola
        // over ±0.1·r assumes a circle's quartic term — for the ellipse the quartic differs
        // by O(r) relative, biasing D by ≈ (3/35)·W⁴/(8ρ³) ≤ 1e-6·r: tolerance 2e-5 (+ f32
        // rounding 1000·ε).
        let mut pts = std::vec::Vec::new();
        for (th, ph, lr) in [(20.0, 0.0, 5.0), (0.0, 25.0, 4.0), (15.0, -20.0, 3.0)] {
            let (th, ph): (Real, Real) = (th * deg, ph * deg);
            let u = tilted_axis(th, ph).unwrap();
            let big = 1.0 / u.z;
            let proj = Vec2::new(u.x, u.y);
            let (em, en) = if proj.norm() > 0.0 {
                let e = proj / proj.norm();
                (e, Vec2::new(-e.y, e.x))
            } else {
                (Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0))
            };
            let c = Vec2::new(0.0, lr);
            pts.clear();
            for i in 0..40000 {
                let t = i as Real * 2.0 * PI / 40000.0;
                let q = c + em * (big * t.cos()) + en * t.sin();
                // Outward normal of the ellipse ∝ (cos t / A, sin t / B) in its frame.
                let nrm = em * (t.cos() / big) + en * t.sin();
                if nrm.dot(&q) < 0.0 {
                    pts.push(q);
                }
            }
            let params = ThreeTangentParams {
                nearest_window: 0.1,
                ..ThreeTangentParams::default()
            };
            let num = three_tangent(&pts, &params).unwrap().radius;
            let ana = tilt_error_ratio(th, ph, lr).unwrap();
            assert!(
                (num - ana).abs() < 2e-5 + 1000.0 * EPS,
                "θ={th} φ={ph}: numeric {num} analytic {ana}"
            );
        }
    }
}
