//! Stem diameter from one or two laser curves (thesis chapter 9; derivations in
//! `docs/cylinder.md`).
//!
//! * [`three_tangent`]: the three-tangent method in one laser plane — the two rays from
//!   the laser source that graze the stem and the tangent at the arc's point nearest the
//!   source fix the circle: `r = D·sin α / (1 − sin α)` ([`three_tangent_radius`]).
//! * [`tilt_error_ratio`]: what the three-tangent method returns, relative to the true
//!   radius, for a cylinder tilted by `(θ, φ)` and treated as transversal (§9.6).
//! * [`fit_cylinder`]: Levenberg–Marquardt fit of a cylinder (axis, radius) to the 3-D points
//!   of two (or more) laser curves (§9.7–9.10), with [`generalised_three_tangent`] on the
//!   points projected along the fitted axis.
//! * [`solve`]: the whole decision — methods, their uncertainties from
//!   [`crate::error_model`], the choice of the reported diameter, quality [`Flags`], and a
//!   specific [`SolveError`] when nothing is trustworthy.
//!
//! In-plane coordinates are those of [`LaserPlane::to_plane_coords`]: origin at the laser
//! source, so the grazing rays are rays from the origin.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec2, Vec3, PI};

use nalgebra::{SMatrix, SVector};

use super::circle::{self, LmParams, RobustParams};
pub use super::result::{Flags, Method, Tilt};
use super::{levenberg_step, SolveError};
use crate::error_model;
use crate::laser_plane::LaserPlane;
use crate::noise::{self, NoiseModel};

// ---------------------------------------------------------------------------------------
// Three-tangent method
// ---------------------------------------------------------------------------------------

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
    let (mut psi_min, mut psi_max) = (Real::INFINITY, Real::NEG_INFINITY);
    for q in points {
        let along = q.dot(&fwd);
        if !(along > 0.0) {
            return Err(SolveError::Degenerate);
        }
        let psi = q.dot(&side).atan2(along);
        psi_min = psi_min.min(psi);
        psi_max = psi_max.max(psi);
    }
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

// ---------------------------------------------------------------------------------------
// Tilt ignored (§9.6)
// ---------------------------------------------------------------------------------------

/// Unit axis direction, in the plane frame `(a, b, n)`, of a cylinder tilted by `θ` (lean
/// in the `(b, n)` plane: towards (+) or away from the instrument along the laser fan's
/// depth direction) and `φ` (lean in the `(a, n)` plane: sideways):
/// `u ∝ (tan φ, tan θ, 1)` (`docs/cylinder.md`, "Tilt angles").
pub fn tilted_axis(theta: Real, phi: Real) -> Result<Vec3, SolveError> {
    if !(theta.is_finite() && phi.is_finite() && theta.abs() < 0.5 * PI && phi.abs() < 0.5 * PI) {
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
pub fn tilt_error_ratio(theta: Real, phi: Real, l_over_r: Real) -> Result<Real, SolveError> {
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

// ---------------------------------------------------------------------------------------
// Cylinder fit (§9.7–9.10)
// ---------------------------------------------------------------------------------------

/// A cylinder: a point on its axis, the unit axis direction, the radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cylinder {
    /// A point on the axis (metres, camera frame).
    pub point: Vec3,
    /// Unit axis direction.
    pub axis: Vec3,
    /// Radius (metres).
    pub radius: Real,
}

impl Cylinder {
    /// Signed distance of `x` from the surface: distance to the axis minus the radius.
    pub fn distance(&self, x: Vec3) -> Real {
        let w = x - self.point;
        norm(&(w - self.axis * w.dot(&self.axis))) - self.radius
    }
}

/// Result of [`fit_cylinder`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CylinderFit {
    /// The fitted cylinder; `point` is the axis point nearest the data centroid.
    pub cylinder: Cylinder,
    /// RMS of the residuals (distance to axis − r).
    pub rms_residual: Real,
    /// LM iterations.
    pub iterations: u32,
    /// 1σ of the radius (Gauss–Newton covariance, `σ̂² = SSR/(n − 5)`).
    pub sigma_radius: Real,
    /// 1σ of the axis direction (radians): the larger of the two angle deviations.
    pub sigma_axis: Real,
    /// Points used.
    pub points: usize,
}

type M5 = SMatrix<Real, 5, 5>;
type V5 = SVector<Real, 5>;

/// Two unit vectors completing `u` to an orthonormal basis.
fn basis(u: Vec3) -> (Vec3, Vec3) {
    let helper = if u.x.abs() < 0.6 {
        Vec3::new(1.0, 0.0, 0.0)
    } else {
        Vec3::new(0.0, 1.0, 0.0)
    };
    let e1 = u.cross(&helper);
    let e1 = e1 / norm(&e1);
    (e1, u.cross(&e1))
}

struct CylState {
    p: Vec3,
    u: Vec3,
    r: Real,
}

fn cyl_accumulate(
    curves: &[&[Vec3]],
    mean: Vec3,
    scale: Real,
    st: &CylState,
) -> (M5, V5, Real, usize) {
    let (e1, e2) = basis(st.u);
    let mut jtj = M5::zeros();
    let mut jtd = V5::zeros();
    let mut cost = 0.0;
    let mut n = 0;
    for curve in curves {
        for x in curve.iter() {
            let y = (x - mean) / scale;
            let w = y - st.p;
            let wu = w.dot(&st.u);
            let q = w - st.u * wu;
            let rho = norm(&q);
            let g = if rho > 0.0 { q / rho } else { Vec3::zeros() };
            let (g1, g2) = (g.dot(&e1), g.dot(&e2));
            let j = V5::new(-g1, -g2, -wu * g1, -wu * g2, -1.0);
            let d = rho - st.r;
            jtj += j * j.transpose();
            jtd += j * d;
            cost += d * d;
            n += 1;
        }
    }
    (jtj, jtd, cost, n)
}

fn cyl_step(st: &CylState, step: &V5) -> CylState {
    let (e1, e2) = basis(st.u);
    let u = st.u + e1 * step[2] + e2 * step[3];
    let u = u / norm(&u);
    let p = st.p + e1 * step[0] + e2 * step[1];
    // Keep the axis point canonical: nearest the (normalised) centroid, the origin.
    let p = p - u * p.dot(&u);
    CylState {
        p,
        u,
        r: st.r + step[4],
    }
}

/// Geometric cylinder fit: minimises `Σ (dist(xᵢ, axis) − r)²` over all points of all
/// curves by Levenberg–Marquardt, parametrised by 2 axis angles, 2 axis-point offsets
/// (perpendicular to the axis) and `r` (`docs/cylinder.md`, "Cylinder fit").
///
/// Points are centred and scaled first (f32). Start from [`initial_cylinder`]. Needs at
/// least 6 points, over at least two curves in different planes for a well-posed axis.
pub fn fit_cylinder(
    curves: &[&[Vec3]],
    initial: Cylinder,
    params: &LmParams,
) -> Result<CylinderFit, SolveError> {
    if params.max_iterations == 0 || !(params.tolerance >= 0.0) {
        return Err(SolveError::InvalidParameter);
    }
    let mut sum = Vec3::zeros();
    let mut n = 0usize;
    for c in curves {
        for x in c.iter() {
            if !(x.x.is_finite() && x.y.is_finite() && x.z.is_finite()) {
                return Err(SolveError::NonFinite);
            }
            sum += x;
            n += 1;
        }
    }
    if n < 6 {
        return Err(SolveError::TooFewPoints);
    }
    let mean = sum / n as Real;
    let mut ss = 0.0;
    for c in curves {
        for x in c.iter() {
            ss += (x - mean).norm_squared();
        }
    }
    let scale = sqrt(ss / n as Real);
    if !(scale > 0.0 && scale.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    let an = norm(&initial.axis);
    if !(an > 0.0 && initial.radius > 0.0 && an.is_finite() && initial.radius.is_finite()) {
        return Err(SolveError::InvalidParameter);
    }
    let u = initial.axis / an;
    let p = (initial.point - mean) / scale;
    let mut st = CylState {
        p: p - u * p.dot(&u),
        u,
        r: initial.radius / scale,
    };
    let (mut jtj, mut jtd, mut cost, _) = cyl_accumulate(curves, mean, scale, &st);
    let mut lambda = params.initial_lambda;
    let mut iterations = 0;
    let mut converged = false;
    for it in 1..=params.max_iterations {
        iterations = it;
        let Some(step) = levenberg_step(&jtj, &jtd, &mut lambda)? else {
            continue;
        };
        let cand = cyl_step(&st, &step);
        let (jtj2, jtd2, cost2, _) = cyl_accumulate(curves, mean, scale, &cand);
        let rounding = 8.0 * Real::EPSILON * cost;
        let better = cost2 < cost || (cost2 <= cost + rounding && norm(&jtd2) < norm(&jtd));
        if cost2.is_finite() && better {
            let small = norm(&step) <= params.tolerance * (1.0 + norm(&st.p) + st.r);
            st = cand;
            jtj = jtj2;
            jtd = jtd2;
            cost = cost2;
            lambda = (lambda * 0.1).max(1e-12);
            if small {
                converged = true;
                break;
            }
        } else {
            lambda = (lambda * 10.0).max(Real::EPSILON);
            if lambda > 1e16 {
                converged = true;
                break;
            }
        }
    }
    if !converged {
        return Err(SolveError::NotConverged);
    }
    let r = st.r.abs();
    if !(r > 0.0 && r.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    let s2 = if n > 5 { cost / (n - 5) as Real } else { 0.0 };
    let (sr, sa) = match jtj.try_inverse() {
        Some(inv) => (
            sqrt((inv[(4, 4)] * s2).max(0.0)) * scale,
            sqrt((inv[(2, 2)] * s2).max((inv[(3, 3)] * s2).max(0.0))),
        ),
        None => return Err(SolveError::Degenerate),
    };
    Ok(CylinderFit {
        cylinder: Cylinder {
            point: mean + st.p * scale,
            axis: st.u,
            radius: r * scale,
        },
        rms_residual: sqrt(cost / n as Real) * scale,
        iterations,
        sigma_radius: sr,
        sigma_axis: sa,
        points: n,
    })
}

/// Initial cylinder from two or more planes' curves: a Hyper circle fit in each plane gives
/// a point near the axis (the centre of the best circle through an elliptic arc is near the
/// ellipse centre, and the bias is the same in parallel planes); the axis is the line
/// through the first and last centres, the radius the mean of the circle radii
/// (`docs/cylinder.md`, "Cylinder fit").
///
/// `scratch` holds one curve's in-plane points (length ≥ the longest curve).
pub fn initial_cylinder(
    curves: &[&[Vec3]],
    planes: &[LaserPlane],
    scratch: &mut [Vec2],
) -> Result<Cylinder, SolveError> {
    if curves.len() < 2 || planes.len() != curves.len() {
        return Err(SolveError::PlaneCount);
    }
    let mut first = Vec3::zeros();
    let mut last = Vec3::zeros();
    let mut rsum = 0.0;
    for (k, (curve, plane)) in curves.iter().zip(planes).enumerate() {
        let pts = to_plane(curve, plane, scratch)?;
        let c = circle::fit_hyper(pts)?;
        let centre = plane.from_plane_coords(c.centre);
        if k == 0 {
            first = centre;
        }
        last = centre;
        rsum += c.radius;
    }
    let mut axis = last - first;
    let len = norm(&axis);
    if !(len > 0.0 && len.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    axis /= len;
    if axis.dot(&planes[0].normal) < 0.0 {
        axis = -axis;
    }
    Ok(Cylinder {
        point: 0.5 * (first + last),
        axis,
        radius: rsum / curves.len() as Real,
    })
}

fn to_plane<'s>(
    curve: &[Vec3],
    plane: &LaserPlane,
    scratch: &'s mut [Vec2],
) -> Result<&'s [Vec2], SolveError> {
    let out = scratch
        .get_mut(..curve.len())
        .ok_or(SolveError::ScratchTooSmall)?;
    for (o, x) in out.iter_mut().zip(curve) {
        if !(x.x.is_finite() && x.y.is_finite() && x.z.is_finite()) {
            return Err(SolveError::NonFinite);
        }
        *o = plane.to_plane_coords(*x);
    }
    Ok(out)
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
    let an = norm(&axis);
    if !(an > 0.0 && an.is_finite()) {
        return Err(SolveError::InvalidParameter);
    }
    let (e1, e2) = basis(axis / an);
    let out = scratch
        .get_mut(..curve.len())
        .ok_or(SolveError::ScratchTooSmall)?;
    for (o, x) in out.iter_mut().zip(curve) {
        let w = x - source;
        *o = Vec2::new(w.dot(&e1), w.dot(&e2));
    }
    three_tangent(out, params)
}

// ---------------------------------------------------------------------------------------
// The decision
// ---------------------------------------------------------------------------------------

/// Input of [`solve`]: the laser curves of one capture.
#[derive(Debug, Clone, Copy)]
pub struct CylinderInput<'a> {
    /// Per plane, the triangulated points (metres, camera frame), in image-column order.
    pub curves: &'a [&'a [Vec3]],
    /// Per plane, each point's 1σ (metres, along its noise direction
    /// [`noise::DisplacementField`]), same indexing as `curves` (the pipeline writes them
    /// beside the points: [`crate::pipeline::point_sigmas`]).
    pub sigmas: &'a [&'a [Real]],
    /// The laser planes, same order as `curves`.
    pub planes: &'a [LaserPlane],
}

/// Settings of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CylinderParams {
    /// Smallest plausible radius (metres).
    pub min_radius: Real,
    /// Largest plausible radius (metres).
    pub max_radius: Real,
    /// Working range: nearest distance from the source (metres), min and max.
    pub range: (Real, Real),
    /// Arc angle (radians, seen from the centre) below which the fit is flagged
    /// [`Flags::ARC_TOO_SHORT`] and not preferred.
    pub min_arc_angle: Real,
    /// Largest tilt (radians) before [`Flags::LARGE_TILT`].
    pub max_tilt: Real,
    /// Fraction of rejected points above which [`Flags::SEVERAL_OBJECTS`] is set.
    pub max_outlier_fraction: Real,
    /// Three-tangent settings.
    pub three_tangent: ThreeTangentParams,
    /// Robust circle fit settings (its `min_scale` is raised to the predicted point noise).
    pub robust: RobustParams,
    /// Cylinder fit settings.
    pub lm: LmParams,
    /// Image and calibration noise (for the uncertainties).
    pub noise: NoiseModel,
    /// Focal length along the image rows' normal (`fy`, pixels), for the noise model.
    pub focal_px: Real,
    /// Non-roundness test: smallest F statistic of circle against ellipse
    /// ([`circle::EllipseFit::f_statistic`]) for [`Flags::ELLIPTIC`].
    pub elliptic_min_f: Real,
    /// Non-roundness test: smallest relative axis difference `(a − b)/(a + b)` for
    /// [`Flags::ELLIPTIC`] (smaller ones are within what a round stem's bark and the stripe
    /// extraction's coherent bending produce; `docs/cylinder.md`, "Elliptic stems").
    pub elliptic_min_eccentricity: Real,
}

/// Default [`CylinderParams::elliptic_min_f`]: far above the 1e-6 tail of `F(2, n − 5)`
/// (≈ 14 for n ≥ 100) because the residuals are not independent (coherent bending, bark): the
/// statistic only screens, the eccentricity decides (`docs/cylinder.md`, "Elliptic stems").
pub const ELLIPTIC_MIN_F: Real = 30.0;

/// Fraction of [`CylinderParams::elliptic_min_f`] below which the score-test F
/// ([`circle::ellipse_score_f`]) settles the non-roundness test without fitting the ellipse.
const ELLIPTIC_SCREEN: Real = 0.5;

/// Iteration budget of the ellipse fit in the non-roundness test.
const ELLIPSE_MAX_ITERATIONS: u32 = 1000;

/// Default [`CylinderParams::elliptic_min_eccentricity`]: 4 % (axis ratio 1.08).
pub const ELLIPTIC_MIN_ECCENTRICITY: Real = 0.04;

impl Default for CylinderParams {
    /// The reference caliper: radii 1–60 cm, range 0.3–3.5 m, min arc 40°, max tilt 35°,
    /// f = 1000 px, [`NoiseModel::reference`].
    fn default() -> Self {
        CylinderParams {
            min_radius: 0.01,
            max_radius: 0.6,
            range: (0.3, 3.5),
            min_arc_angle: 40.0 * PI / 180.0,
            max_tilt: 35.0 * PI / 180.0,
            max_outlier_fraction: 0.3,
            three_tangent: ThreeTangentParams::default(),
            robust: RobustParams::default(),
            lm: LmParams::default(),
            noise: NoiseModel::reference(),
            focal_px: 1000.0,
            elliptic_min_f: ELLIPTIC_MIN_F,
            elliptic_min_eccentricity: ELLIPTIC_MIN_ECCENTRICITY,
        }
    }
}

/// Caller-owned working memory of [`solve`]: both at least as long as the longest curve.
pub struct Scratch<'a> {
    /// In-plane / projected points.
    pub points: &'a mut [Vec2],
    /// Residual magnitudes (robust scale).
    pub values: &'a mut [Real],
}

/// The diameter of one capture, with how it was obtained and how far to trust it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CylinderSolution {
    /// Reported diameter (metres).
    pub diameter: Real,
    /// Method of the reported diameter.
    pub method: Method,
    /// 1σ uncertainty of `diameter` (metres): random (point noise, edges) and calibration,
    /// from [`crate::error_model`] and the data.
    pub uncertainty: Real,
    /// Stem tilt, when two planes measured it.
    pub tilt: Option<Tilt>,
    /// Quality flags.
    pub flags: Flags,
    /// RMS residual of the fit (metres), 0 if it failed.
    pub fit_rms: Real,
    /// Points used (all curves).
    pub n_points: usize,
    /// Three-tangent diameter (plane 0, or generalised), if it succeeded.
    pub three_tangent_diameter: Option<Real>,
    /// Its 1σ.
    pub three_tangent_uncertainty: Option<Real>,
    /// Fit diameter (circle or cylinder), if it succeeded.
    pub fit_diameter: Option<Real>,
    /// Its 1σ.
    pub fit_uncertainty: Option<Real>,
    /// Distance from the source of plane 0 to the stem (nearest point, metres).
    pub distance: Real,
    /// Centre of the section in plane 0 (camera frame, metres).
    pub centre: Vec3,
    /// Major and minor diameters (metres) of an elliptic section ([`Flags::ELLIPTIC`]).
    pub axes: Option<(Real, Real)>,
}

/// Angle subtended at `centre` by the points (the arc's extent, radians).
fn arc_angle(points: &[Vec2], centre: Vec2) -> Real {
    let mut sum = Vec2::zeros();
    for q in points {
        let d = q - centre;
        let n = norm(&d);
        if n > 0.0 {
            sum += d / n;
        }
    }
    let len = norm(&sum);
    if !(len > 0.0) {
        return 2.0 * PI;
    }
    let f = sum / len;
    let s = Vec2::new(f.y, -f.x);
    let (mut lo, mut hi) = (Real::INFINITY, Real::NEG_INFINITY);
    for q in points {
        let d = q - centre;
        let a = d.dot(&s).atan2(d.dot(&f));
        lo = lo.min(a);
        hi = hi.max(a);
    }
    hi - lo
}

/// Point noise (1σ, in-plane vector, metres) of the in-plane point `q` of `plane`.
fn noise_vector(plane: &LaserPlane, q: Vec2, params: &CylinderParams) -> Vec2 {
    let x = plane.from_plane_coords(q);
    let g =
        noise::displacement_per_pixel(plane, params.focal_px, x).unwrap_or_else(|_| Vec3::zeros());
    let (a, b) = plane.plane_axes();
    Vec2::new(g.dot(&a), g.dot(&b)) * params.noise.image_px()
}

/// One-plane result (internal): both methods with their σ.
struct PlaneResult {
    tt: Option<(ThreeTangent, Real)>,
    fit: Option<(circle::CircleFit, Real, Real)>, // fit, σ_r, arc angle
    ellipse: Option<circle::EllipseFit>,
    flags: Flags,
    n: usize,
}

fn solve_plane(
    curve: &[Vec3],
    sigmas: &[Real],
    plane: &LaserPlane,
    params: &CylinderParams,
    scratch: &mut Scratch<'_>,
) -> Result<PlaneResult, SolveError> {
    let pts = to_plane(curve, plane, scratch.points)?;
    let mut flags = Flags::default();
    let cal = |r: Real, centre: Vec2| {
        noise::calibration_relative_sigma(
            plane,
            plane.from_plane_coords(centre),
            &params.noise,
            params.focal_px,
        ) * r
    };
    // Three-tangent with σ from the edges (model) and from D (max of model and data).
    let tt = match three_tangent(pts, &params.three_tangent) {
        Ok(t) => {
            let (dr_da, dr_dd) = t.partials();
            let s_alpha = params.noise.edge_angle_sigma(params.focal_px) / sqrt(2.0);
            let near = t.bisector * t.nearest_distance;
            let s_point = noise_vector(plane, near, params).dot(&t.bisector).abs();
            let s_d = sqrt(t.nearest_variance_factor) * s_point.max(t.window_rms);
            let random = sqrt((dr_da * s_alpha).powi(2) + (dr_dd * s_d).powi(2));
            let s = sqrt(random * random + cal(t.radius, t.centre).powi(2));
            Some((t, s))
        }
        Err(_) => {
            flags.insert(Flags::THREE_TANGENT_FAILED);
            None
        }
    };
    // Robust fit, scale floor = predicted point noise at the arc's nearest point.
    let mut ellipse = None;
    let fit = match circle::fit_hyper(pts) {
        Ok(init) => {
            let mut rp = params.robust;
            let near = init.centre - init.centre / norm(&init.centre) * init.radius;
            let s_point = norm(&noise_vector(plane, near, params));
            rp.min_scale = rp.min_scale.max(s_point);
            match circle::fit_robust(pts, init, &rp, scratch.values) {
                Ok(f) => {
                    // Each point's noise vector: its stored σ along the field's direction.
                    let field = noise::DisplacementField::of(plane);
                    let noise_of = |i: usize| field.direction_in_plane(pts[i]) * sigmas[i];
                    let model = error_model::circle_radius_sigma(
                        &f.circle,
                        (0..pts.len()).map(|i| (pts[i], noise_of(i))),
                    );
                    // Data-driven sandwich: the dim ends of a far curve are several times
                    // noisier than the model's per-point σ (docs/error-model.md).
                    let cutoff = rp.tuning * f.rms_residual.max(rp.min_scale);
                    let data = error_model::circle_radius_sigma_residuals(&f.circle, pts, cutoff);
                    let data = if data.is_finite() { data } else { 0.0 };
                    let bend = bending_sigma(&f, pts, noise_of);
                    let random = f.std_dev.z.max(model).max(data).hypot(bend);
                    let s = sqrt(random * random + cal(f.circle.radius, f.circle.centre).powi(2));
                    let arc = arc_angle(pts, f.circle.centre);
                    let rejected = 1.0 - f.inliers as Real / pts.len() as Real;
                    if rejected > params.max_outlier_fraction {
                        flags.insert(Flags::SEVERAL_OBJECTS);
                    }
                    if f.rms_residual > 3.0 * s_point.max(params.robust.min_scale) || rejected > 0.2
                    {
                        flags.insert(Flags::POOR_FIT);
                    }
                    if arc < params.min_arc_angle {
                        flags.insert(Flags::ARC_TOO_SHORT);
                    }
                    ellipse = non_round(pts, &f, cutoff, params);
                    Some((f, s, arc))
                }
                Err(_) => None,
            }
        }
        Err(_) => None,
    };
    if fit.is_none() {
        flags.insert(Flags::FIT_FAILED);
    }
    // Edge bias of the three-tangent method (docs/cylinder.md, "Stripe fade-out"): the
    // stripe fades as cos ι → 0 towards the silhouette and the last extracted column lies
    // inside it, so `α` is biased low by an amount the image noise model does not contain.
    // The fit does not need the ends; its grazing half-aperture `asin(R/|C|)` estimates the
    // true one, and the difference (with the fit's own σ on it) is added to the
    // three-tangent's σ as a bias term.
    let tt = match (tt, fit.as_ref()) {
        (Some((t, s)), Some((f, sf, _))) => Some((t, s.hypot(edge_bias_sigma(&t, &f.circle, *sf)))),
        (tt, _) => tt,
    };
    Ok(PlaneResult {
        tt,
        fit,
        ellipse,
        flags,
        n: pts.len(),
    })
}

/// The ellipse fitted to the circle fit's inliers when the section is detectably not round
/// (`docs/cylinder.md`, "Elliptic stems"): F statistic above `elliptic_min_f` and relative
/// axis difference above `elliptic_min_eccentricity`. `None` for a round section or when the
/// ellipse fit fails (then the circle stands).
fn non_round(
    pts: &[Vec2],
    fit: &circle::CircleFit,
    cutoff: Real,
    params: &CylinderParams,
) -> Option<circle::EllipseFit> {
    // The ellipse's valley is long and flat (size against shape along the line of sight):
    // LM needs a few hundred steps from the circle (measured: ≤ 220 on the corpus).
    let lm = LmParams {
        max_iterations: params.robust.lm.max_iterations.max(ELLIPSE_MAX_ITERATIONS),
        ..params.robust.lm
    };
    // Screening (`docs/cylinder.md`, "Screening"): the score-test F costs one pass over the
    // points; the fitted F never exceeded it by more than 14 % on the corpus and 367
    // evaluation curves, so below half the threshold the fit cannot flag the stem.
    if circle::ellipse_score_f(pts, &fit.circle, cutoff).ok()?
        < ELLIPTIC_SCREEN * params.elliptic_min_f
    {
        return None;
    }
    let e = circle::fit_ellipse(pts, &fit.circle, cutoff, &lm).ok()?;
    (e.f_statistic() > params.elliptic_min_f && e.eccentricity() > params.elliptic_min_eccentricity)
        .then_some(e)
}

/// Diameter and 1σ of an elliptic section (`docs/cylinder.md`, "Elliptic stems"): the mean
/// of the fitted axes `a + b`; σ² = fit σ² + (a − b)² (the unseen back may differ from the
/// front's continuation by as much as the front's own non-roundness) + calibration.
/// [`SolveError::NotRound`] when the fit does not resolve the axes (its σ on `a + b`
/// exceeds their difference `2(a − b)`: nothing distinguishes the ellipse's size from its
/// shape).
fn elliptic_diameter(e: &circle::EllipseFit, cal_rel: Real) -> Result<(Real, Real), SolveError> {
    let (a, b) = e.semi_axes;
    let d = a + b;
    if !(e.sigma_mean_diameter < 2.0 * (a - b)) {
        return Err(SolveError::NotRound);
    }
    let s = sqrt(e.sigma_mean_diameter.powi(2) + (a - b).powi(2) + (cal_rel * d).powi(2));
    Ok((d, s))
}

/// Share of the fit's residual RMS (in pixels of stripe position) that bends the curve
/// coherently — ends against middle (`docs/error-model.md`, "Coherent bending"). Measured
/// on simulated captures against their true curves (development seeds 5000–5039, not the
/// evaluation's): the mean row error of the outer fifths minus that of the middle reaches
/// about half the per-point RMS on dim, far stripes.
pub const BENDING_FRACTION: Real = 0.5;

/// 1σ of the fit radius from a coherent bending of the curve: every point displaced along its
/// noise vector `gᵢ` (1σ, `noise(i)` for point `i`) by `s·P₂(τ)/ḡ`, `τ ∈ [−1, 1]` its position
/// along the curve, `P₂ = (3τ² − 1)/2` (ends against middle), `ḡ` the mean `|gᵢ|`, `s` =
/// [`BENDING_FRACTION`] × the fit's residual RMS (a bend of that many RMS in units of the mean
/// point noise). Propagated through the linearised geometric fit
/// (`Δθ = A⁻¹ Σ Jᵢ (nᵢ·gᵢ) δᵢ`, `docs/error-model.md`).
fn bending_sigma(fit: &circle::CircleFit, pts: &[Vec2], noise: impl Fn(usize) -> Vec2) -> Real {
    let n = pts.len();
    if n < 4 {
        return 0.0;
    }
    let c = fit.circle;
    let mut a = crate::real::Mat3::zeros();
    let mut b = Vec3::zeros();
    let mut sigma_sum = 0.0;
    for (i, q) in pts.iter().enumerate() {
        let d = q - c.centre;
        let len = norm(&d);
        if !(len > 0.0) {
            continue;
        }
        let nn = d / len;
        let j = Vec3::new(-nn.x, -nn.y, -1.0);
        let g = noise(i);
        sigma_sum += norm(&g);
        let tau = 2.0 * i as Real / (n - 1) as Real - 1.0;
        let p2 = 0.5 * (3.0 * tau * tau - 1.0);
        a += j * j.transpose();
        b += j * (nn.dot(&g) * p2);
    }
    let mean_sigma = sigma_sum / n as Real;
    if !(mean_sigma > 0.0) {
        return 0.0;
    }
    let s = BENDING_FRACTION * fit.rms_residual / mean_sigma;
    match a.try_inverse() {
        Some(inv) => {
            let out = ((inv * b)[2] * s).abs();
            if out.is_finite() {
                out
            } else {
                0.0
            }
        }
        None => 0.0,
    }
}

/// Radius error (1σ) of the three-tangent solution `t` due to the fade-out of its edges, judged
/// against a fitted `circle` whose radius has 1σ `sigma_fit` (`docs/cylinder.md`, "Stripe
/// fade-out"): the fit's grazing half-aperture `α_f = asin(R/|C|)` minus the three-tangent's
/// `α`, through `∂r/∂α`, in quadrature with the fit's own uncertainty on `α_f` mapped the
/// same way (`∂α_f/∂R = 1/(|C| cos α_f)`). Zero when the circle does not enclose a grazing
/// geometry (source inside it).
pub fn edge_bias_sigma(t: &ThreeTangent, circle: &circle::Circle, sigma_fit: Real) -> Real {
    let l = norm(&circle.centre);
    if !(l > circle.radius && circle.radius > 0.0) {
        return 0.0;
    }
    let alpha_f = (circle.radius / l).asin();
    let (dr_da, _) = t.partials();
    let gap = alpha_f - t.alpha;
    let s_alpha_f = sigma_fit / (l * alpha_f.cos());
    let out = dr_da * gap.hypot(s_alpha_f);
    if out.is_finite() {
        out
    } else {
        Real::INFINITY
    }
}

/// Choice between a three-tangent radius and a fit radius (`docs/cylinder.md`, "Choosing
/// the method"): `(use_fit, inconsistent)`.
fn choose(tt: Option<(Real, Real)>, fit: Option<(Real, Real, bool)>) -> Option<(bool, bool)> {
    match (tt, fit) {
        (None, None) => None,
        // The three-tangent alone has no check on the fade-out of its edges (docs/cylinder.md
        // §5b: biased low by up to tens of percent, and a fragment of the curve looks like a
        // small stem): without a fit to judge it there is no trustworthy answer.
        (Some(_), None) => None,
        (None, Some((_, _, short))) => {
            if short {
                None
            } else {
                Some((true, false))
            }
        }
        (Some((rt, st)), Some((rf, sf, short))) => {
            let inconsistent = (rt - rf).abs() > 3.0 * sqrt(st * st + sf * sf);
            if short {
                Some((false, inconsistent))
            } else if inconsistent {
                Some((true, true))
            } else {
                Some((sf < st, false))
            }
        }
    }
}

/// Solves the stem diameter of one capture (`docs/cylinder.md`, "Choosing the method").
///
/// * One plane: three-tangent and robust circle fit; [`Flags::TILT_IGNORED`].
/// * Two or more planes: cylinder fit (axis and radius) and the generalised three-tangent
///   method on each curve projected along the axis; [`CylinderSolution::tilt`] is set. If the
///   cylinder fit fails, falls back to the one-plane solution of plane 0
///   ([`Flags::TILT_FIT_FAILED`]).
///
/// The reported diameter is the method with the smaller 1σ, except: the fit when the two
/// disagree beyond 3σ ([`Flags::INCONSISTENT`], occluded edge), the three-tangent when the
/// arc is too short for the fit. Errors: [`SolveError::PlaneCount`] (no curve, or
/// curves ≠ planes), [`SolveError::ScratchTooSmall`], [`SolveError::ArcTooShort`] (fit
/// ill-conditioned and three-tangent failed), [`SolveError::RadiusOutOfRange`], and the
/// [`SolveError::NotConverged`] when both methods fail.
pub fn solve(
    input: &CylinderInput<'_>,
    params: &CylinderParams,
    mut scratch: Scratch<'_>,
) -> Result<CylinderSolution, SolveError> {
    if input.curves.is_empty()
        || input.curves.len() != input.planes.len()
        || input.sigmas.len() != input.curves.len()
    {
        return Err(SolveError::PlaneCount);
    }
    if input
        .curves
        .iter()
        .zip(input.sigmas)
        .any(|(c, s)| c.len() != s.len())
    {
        return Err(SolveError::InvalidParameter);
    }
    if !(params.min_radius > 0.0
        && params.max_radius > params.min_radius
        && params.focal_px > 0.0
        && params.focal_px.is_finite())
    {
        return Err(SolveError::InvalidParameter);
    }
    let longest = input.curves.iter().map(|c| c.len()).max().unwrap_or(0);
    if scratch.points.len() < longest || scratch.values.len() < longest {
        return Err(SolveError::ScratchTooSmall);
    }
    let plane0 = &input.planes[0];
    let one = solve_plane(
        input.curves[0],
        input.sigmas[0],
        plane0,
        params,
        &mut scratch,
    )?;
    let mut sol = if input.curves.len() >= 2 {
        match solve_tilted(input, params, &mut scratch, &one) {
            Ok(s) => s,
            Err(_) => {
                let mut s = finish_plane(&one, plane0, params)?;
                s.flags.insert(Flags::TILT_FIT_FAILED);
                s.flags.insert(Flags::TILT_IGNORED);
                s
            }
        }
    } else {
        let mut s = finish_plane(&one, plane0, params)?;
        s.flags.insert(Flags::TILT_IGNORED);
        s
    };
    let r = 0.5 * sol.diameter;
    if !(r >= params.min_radius && r <= params.max_radius) {
        return Err(SolveError::RadiusOutOfRange);
    }
    if !(sol.distance >= params.range.0 && sol.distance <= params.range.1) {
        sol.flags.insert(Flags::RANGE_LIMIT);
    }
    Ok(sol)
}

fn finish_plane(
    one: &PlaneResult,
    plane: &LaserPlane,
    params: &CylinderParams,
) -> Result<CylinderSolution, SolveError> {
    if let (Some(e), Some((f, _, _))) = (one.ellipse, one.fit) {
        let cal_rel = noise::calibration_relative_sigma(
            plane,
            plane.from_plane_coords(e.centre),
            &params.noise,
            params.focal_px,
        );
        let (d, s) = elliptic_diameter(&e, cal_rel)?;
        let mut flags = one.flags;
        flags.insert(Flags::ELLIPTIC);
        let c = f.circle.centre;
        return Ok(CylinderSolution {
            diameter: d,
            method: Method::CircleFit,
            uncertainty: s,
            tilt: None,
            flags,
            fit_rms: f.rms_residual,
            n_points: one.n,
            three_tangent_diameter: one.tt.map(|(t, _)| 2.0 * t.radius),
            three_tangent_uncertainty: one.tt.map(|(_, s)| 2.0 * s),
            fit_diameter: Some(2.0 * f.circle.radius),
            fit_uncertainty: one.fit.map(|(_, s, _)| 2.0 * s),
            distance: norm(&c) - f.circle.radius,
            centre: plane.from_plane_coords(e.centre),
            axes: Some((2.0 * e.semi_axes.0, 2.0 * e.semi_axes.1)),
        });
    }
    let short = one.flags.contains(Flags::ARC_TOO_SHORT);
    let tt = one.tt.map(|(t, s)| (t.radius, s));
    let fit = one.fit.map(|(f, s, _)| (f.circle.radius, s, short));
    let (use_fit, inconsistent) = match choose(tt, fit) {
        Some(c) => c,
        None => {
            return Err(if one.fit.is_some() {
                SolveError::ArcTooShort
            } else {
                SolveError::NotConverged
            })
        }
    };
    let mut flags = one.flags;
    if inconsistent {
        flags.insert(Flags::INCONSISTENT);
    }
    let (radius, sigma, method, centre, distance) = if use_fit {
        let (f, s, _) = one.fit.ok_or(SolveError::NotConverged)?;
        let c = f.circle.centre;
        (
            f.circle.radius,
            s,
            Method::CircleFit,
            c,
            norm(&c) - f.circle.radius,
        )
    } else {
        let (t, s) = one.tt.ok_or(SolveError::NotConverged)?;
        (
            t.radius,
            s,
            Method::ThreeTangent,
            t.centre,
            t.nearest_distance,
        )
    };
    Ok(CylinderSolution {
        diameter: 2.0 * radius,
        method,
        uncertainty: 2.0 * sigma,
        tilt: None,
        flags,
        fit_rms: one.fit.map(|(f, _, _)| f.rms_residual).unwrap_or(0.0),
        n_points: one.n,
        three_tangent_diameter: one.tt.map(|(t, _)| 2.0 * t.radius),
        three_tangent_uncertainty: one.tt.map(|(_, s)| 2.0 * s),
        fit_diameter: one.fit.map(|(f, _, _)| 2.0 * f.circle.radius),
        fit_uncertainty: one.fit.map(|(_, s, _)| 2.0 * s),
        distance,
        centre: plane.from_plane_coords(centre),
        axes: None,
    })
}

fn solve_tilted(
    input: &CylinderInput<'_>,
    params: &CylinderParams,
    scratch: &mut Scratch<'_>,
    one: &PlaneResult,
) -> Result<CylinderSolution, SolveError> {
    let init = initial_cylinder(input.curves, input.planes, scratch.points)?;
    let fit = fit_cylinder(input.curves, init, &params.lm)?;
    let cyl = fit.cylinder;
    let plane0 = &input.planes[0];
    // Generalised three-tangent on every curve; mean radius, σ of the mean of the
    // per-curve model σ's (independent curves).
    let mut rsum = 0.0;
    let mut s2sum = 0.0;
    let mut k = 0;
    // Σ of the per-curve data-driven radius variances of the projected circle fits.
    let mut fit_s2sum = 0.0;
    let mut kf = 0;
    // Σ of the per-curve edge-fade bias σ's: a bias, common to the curves, so it is
    // averaged, not reduced as independent noise.
    let mut edge_sum = 0.0;
    for ((curve, sigmas), plane) in input.curves.iter().zip(input.sigmas).zip(input.planes) {
        // The data-driven terms of the one-plane path on the projected curve
        // (docs/cylinder.md, "Data-driven σ of the two-plane result").
        let extra = projected_data_sigma(curve, sigmas, plane, cyl.axis, params, scratch);
        if let Some((_, sf, _)) = extra {
            fit_s2sum += sf * sf;
            kf += 1;
        }
        if let Ok(t) = generalised_three_tangent(
            curve,
            plane.source,
            cyl.axis,
            &params.three_tangent,
            scratch.points,
        ) {
            let (dr_da, dr_dd) = t.partials();
            let s_alpha = params.noise.edge_angle_sigma(params.focal_px) / sqrt(2.0);
            let s_point = one_point_sigma(plane, params, t.nearest_distance);
            let s_d = sqrt(t.nearest_variance_factor) * t.window_rms.max(s_point);
            // Fade-out of the projected edges, judged against the projected fit.
            let edge = extra.map_or(0.0, |(c, sf, _)| edge_bias_sigma(&t, &c, sf));
            rsum += t.radius;
            s2sum += (dr_da * s_alpha).powi(2) + (dr_dd * s_d).powi(2);
            edge_sum += edge;
            k += 1;
        }
    }
    // Where the axis meets plane 0.
    let denom = plane0.normal.dot(&cyl.axis);
    let centre = if denom.abs() > 1e-6 {
        cyl.point + cyl.axis * ((plane0.offset - plane0.normal.dot(&cyl.point)) / denom)
    } else {
        return Err(SolveError::Degenerate);
    };
    let cal_rel = noise::calibration_relative_sigma(plane0, centre, &params.noise, params.focal_px);
    // The cylinder fit's own σ assumes independent, equal point noise; the dim ends of a far
    // curve and coherent bending break that as in one plane. σ of the mean of the per-curve
    // data-driven terms (independent curves) is the floor, as `max` in `solve_plane`.
    let data_sigma = if kf > 0 {
        sqrt(fit_s2sum / (kf * kf) as Real)
    } else {
        0.0
    };
    let fit_sigma = sqrt(fit.sigma_radius.max(data_sigma).powi(2) + (cal_rel * cyl.radius).powi(2));
    let tt = if k > 0 {
        let r = rsum / k as Real;
        let edge = edge_sum / k as Real;
        let s = sqrt(s2sum / (k * k) as Real + edge * edge + (cal_rel * r).powi(2));
        Some((r, s))
    } else {
        None
    };
    let mut flags = Flags::default();
    if tt.is_none() {
        flags.insert(Flags::THREE_TANGENT_FAILED);
    }
    let short = one.flags.contains(Flags::ARC_TOO_SHORT);
    if short {
        flags.insert(Flags::ARC_TOO_SHORT);
    }
    let (use_fit, inconsistent) =
        choose(tt, Some((cyl.radius, fit_sigma, short))).ok_or(SolveError::ArcTooShort)?;
    if inconsistent {
        flags.insert(Flags::INCONSISTENT);
    }
    let tilt = Tilt::of(cyl.axis, plane0, fit.sigma_axis);
    if tilt.total > params.max_tilt {
        flags.insert(Flags::LARGE_TILT);
    }
    let point_sigma = one_point_sigma(plane0, params, norm(&(centre - plane0.source)) - cyl.radius);
    if fit.rms_residual > 3.0 * point_sigma.max(params.robust.min_scale) {
        flags.insert(Flags::POOR_FIT);
    }
    let (radius, sigma, method) = match (use_fit, tt) {
        (false, Some((r, s))) => (r, s, Method::GeneralisedThreeTangent),
        _ => (cyl.radius, fit_sigma, Method::CylinderFit),
    };
    let c0 = plane0.to_plane_coords(centre);
    // Non-roundness in the plane perpendicular to the fitted axis (where a round stem's
    // section is a circle whatever the tilt), on plane 0's curve.
    if let Some(e) = projected_non_round(
        input.curves[0],
        plane0.source,
        cyl.axis,
        params,
        scratch,
        point_sigma,
    ) {
        let (d, s) = elliptic_diameter(&e, cal_rel)?;
        flags.insert(Flags::ELLIPTIC);
        return Ok(CylinderSolution {
            diameter: d,
            method: Method::CylinderFit,
            uncertainty: s,
            tilt: Some(tilt),
            flags,
            fit_rms: fit.rms_residual,
            n_points: fit.points,
            three_tangent_diameter: tt.map(|(r, _)| 2.0 * r),
            three_tangent_uncertainty: tt.map(|(_, s)| 2.0 * s),
            fit_diameter: Some(2.0 * cyl.radius),
            fit_uncertainty: Some(2.0 * fit_sigma),
            distance: norm(&c0) - cyl.radius,
            centre,
            axes: Some((2.0 * e.semi_axes.0, 2.0 * e.semi_axes.1)),
        });
    }
    Ok(CylinderSolution {
        diameter: 2.0 * radius,
        method,
        uncertainty: 2.0 * sigma,
        tilt: Some(tilt),
        flags,
        fit_rms: fit.rms_residual,
        n_points: fit.points,
        three_tangent_diameter: tt.map(|(r, _)| 2.0 * r),
        three_tangent_uncertainty: tt.map(|(_, s)| 2.0 * s),
        fit_diameter: Some(2.0 * cyl.radius),
        fit_uncertainty: Some(2.0 * fit_sigma),
        distance: norm(&c0) - cyl.radius,
        centre,
        axes: None,
    })
}

/// [`non_round`] on `curve` projected along `axis` onto the plane perpendicular to it (origin
/// at `source`, as [`generalised_three_tangent`]), with a robust circle fit whose scale
/// floor is `point_sigma`.
fn projected_non_round(
    curve: &[Vec3],
    source: Vec3,
    axis: Vec3,
    params: &CylinderParams,
    scratch: &mut Scratch<'_>,
    point_sigma: Real,
) -> Option<circle::EllipseFit> {
    let an = norm(&axis);
    if !(an > 0.0 && an.is_finite()) {
        return None;
    }
    let (e1, e2) = basis(axis / an);
    let out = scratch.points.get_mut(..curve.len())?;
    for (o, x) in out.iter_mut().zip(curve) {
        let w = x - source;
        *o = Vec2::new(w.dot(&e1), w.dot(&e2));
    }
    let pts: &[Vec2] = out;
    let init = circle::fit_hyper(pts).ok()?;
    let mut rp = params.robust;
    rp.min_scale = rp.min_scale.max(point_sigma);
    let f = circle::fit_robust(pts, init, &rp, scratch.values).ok()?;
    let cutoff = rp.tuning * f.rms_residual.max(rp.min_scale);
    non_round(pts, &f, cutoff, params)
}

/// Data-driven radius σ of one curve projected along `axis` onto the plane perpendicular to
/// it (origin at `plane.source`, as [`generalised_three_tangent`]; the projected lit arc is
/// an arc of the true section): robust circle fit, then the larger of its Gauss–Newton σ and
/// the residual sandwich σ ([`error_model::circle_radius_sigma_residuals`]), in quadrature
/// with the coherent-bending term ([`bending_sigma`]) — the one-plane path's terms
/// (`docs/cylinder.md`, "Data-driven σ of the two-plane result"). Returns the projected
/// circle, that σ and the fit's RMS residual; `None` when the projection or fit fails.
fn projected_data_sigma(
    curve: &[Vec3],
    sigmas: &[Real],
    plane: &LaserPlane,
    axis: Vec3,
    params: &CylinderParams,
    scratch: &mut Scratch<'_>,
) -> Option<(circle::Circle, Real, Real)> {
    let an = norm(&axis);
    if !(an > 0.0 && an.is_finite()) {
        return None;
    }
    let u = axis / an;
    let (e1, e2) = basis(u);
    let source = plane.source;
    let out = scratch.points.get_mut(..curve.len())?;
    for (o, x) in out.iter_mut().zip(curve) {
        let w = x - source;
        *o = Vec2::new(w.dot(&e1), w.dot(&e2));
    }
    let pts: &[Vec2] = out;
    // Back from the projection to the laser plane: `x = s + q₁e₁ + q₂e₂ + t·u` with
    // `n·(x − s) = 0` (the source lies in the plane).
    let nu = plane.normal.dot(&u);
    if !(nu.abs() > 1e-6) {
        return None;
    }
    let noise_at = |q: Vec2| {
        let w = e1 * q.x + e2 * q.y;
        let x = source + w - u * (plane.normal.dot(&w) / nu);
        let g = noise::displacement_per_pixel(plane, params.focal_px, x)
            .unwrap_or_else(|_| Vec3::zeros());
        Vec2::new(g.dot(&e1), g.dot(&e2)) * params.noise.image_px()
    };
    // A data point's noise vector: its stored σ along the field's direction, projected.
    let field = noise::DisplacementField::of(plane);
    let noise_of = |i: usize| {
        let g = field.direction(curve[i]) * sigmas[i];
        Vec2::new(g.dot(&e1), g.dot(&e2))
    };
    let init = circle::fit_hyper(pts).ok()?;
    let cn = norm(&init.centre);
    if !(cn > 0.0) {
        return None;
    }
    let near = init.centre - init.centre / cn * init.radius;
    let mut rp = params.robust;
    rp.min_scale = rp.min_scale.max(norm(&noise_at(near)));
    let f = circle::fit_robust(pts, init, &rp, scratch.values).ok()?;
    let cutoff = rp.tuning * f.rms_residual.max(rp.min_scale);
    let data = error_model::circle_radius_sigma_residuals(&f.circle, pts, cutoff);
    let data = if data.is_finite() { data } else { 0.0 };
    let bend = bending_sigma(&f, pts, noise_of);
    let s = f.std_dev.z.max(data).hypot(bend);
    s.is_finite().then_some((f.circle, s, f.rms_residual))
}

/// Model σ of one point (metres, along the viewing direction) at in-plane distance
/// `distance` straight ahead of the source.
fn one_point_sigma(plane: &LaserPlane, params: &CylinderParams, distance: Real) -> Real {
    norm(&noise_vector(
        plane,
        Vec2::new(0.0, distance.max(0.0)),
        params,
    ))
}

#[cfg(test)]
#[allow(clippy::unnecessary_cast)]
mod tests {
    extern crate std;
    use super::*;
    use crate::calibration::Calibration;
    use crate::camera::Camera;
    use crate::error_model::sample_columns;
    use crate::solvers::circle::tests::Rng;
    use crate::solvers::circle::Circle;

    const EPS: Real = Real::EPSILON;

    fn planes() -> (LaserPlane, LaserPlane) {
        let cal = Calibration::reference_design();
        (cal.planes[0], cal.planes[1])
    }

    /// The lit arc of a circle seen from the origin, sampled uniformly in the angle at the
    /// centre between the two analytic tangent points (inclusive).
    fn lit_arc(c: Vec2, r: Real, n: usize, out: &mut [Vec2]) {
        let l = c.norm();
        let beta = (r / l).acos(); // angle at the centre between −c and a tangent point
        let base = (-c.y).atan2(-c.x);
        for (i, o) in out.iter_mut().take(n).enumerate() {
            let t = base - beta + 2.0 * beta * i as Real / (n - 1) as Real;
            *o = c + Vec2::new(t.cos(), t.sin()) * r;
        }
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

    /// Lit (from the plane's source) and visible (from the camera at the origin) points of
    /// the cylinder's section by `plane`, `n` samples of the angle around the axis.
    fn section(cyl: &Cylinder, plane: &LaserPlane, n: usize, out: &mut std::vec::Vec<Vec3>) {
        section_seen(cyl, plane, n, true, out)
    }

    fn section_seen(
        cyl: &Cylinder,
        plane: &LaserPlane,
        n: usize,
        camera_visibility: bool,
        out: &mut std::vec::Vec<Vec3>,
    ) {
        let (e1, e2) = basis(cyl.axis);
        out.clear();
        for i in 0..n {
            let t = i as Real * 2.0 * PI / n as Real;
            let nrm = e1 * t.cos() + e2 * t.sin();
            let base = cyl.point + nrm * cyl.radius;
            let s = (plane.offset - plane.normal.dot(&base)) / plane.normal.dot(&cyl.axis);
            let x = base + cyl.axis * s;
            if nrm.dot(&(plane.source - x)) > 0.0 && (!camera_visibility || nrm.dot(&(-x)) > 0.0) {
                out.push(x);
            }
        }
    }

    fn tilted_cylinder(theta: Real, phi: Real, r: Real, at: Vec2, plane: &LaserPlane) -> Cylinder {
        let u = tilted_axis(theta, phi).unwrap();
        let (a, b) = plane.plane_axes();
        let axis = a * u.x + b * u.y + plane.normal * u.z;
        Cylinder {
            point: plane.from_plane_coords(at),
            axis,
            radius: r,
        }
    }

    #[test]
    fn cylinder_fit_recovers_tilted_stem() {
        let (p0, p1) = planes();
        let deg = PI / 180.0;
        let truth = tilted_cylinder(15.0 * deg, 20.0 * deg, 0.15, Vec2::new(0.05, 1.4), &p0);
        let (mut c0, mut c1) = (std::vec::Vec::new(), std::vec::Vec::new());
        section(&truth, &p0, 2000, &mut c0);
        section(&truth, &p1, 2000, &mut c1);
        assert!(c0.len() > 100 && c1.len() > 100);
        let mut scratch = std::vec![Vec2::zeros(); 2000];
        // Exact points: rounding only (1e4·ε·|X| allows for the conditioning of a
        // 5-parameter fit on two short arcs).
        {
            let curves: [&[Vec3]; 2] = [&c0, &c1];
            let init = initial_cylinder(&curves, &[p0, p1], &mut scratch).unwrap();
            let fit = fit_cylinder(&curves, init, &LmParams::default()).unwrap();
            let tol = 1e4 * EPS * 1.5;
            assert!((fit.cylinder.radius - 0.15).abs() < tol, "{fit:?}");
            assert!(fit.cylinder.axis.cross(&truth.axis).norm() < tol * 10.0);
        }
        // Lit but not necessarily visible: the grazing rays' ends (the camera, 10 cm
        // above the source, sees a slightly different limb of a tilted stem — a second-
        // order effect of ~4e-5 m here, see docs/cylinder.md).
        let mut exact0 = std::vec::Vec::new();
        section_seen(&truth, &p0, 2000, false, &mut exact0);
        // Noise: 0.5 mm isotropic, Gaussian. Radius within 4σ of the fit's own covariance
        // (whose calibration is tested for circles in circle.rs).
        let mut rng = Rng::new(4242);
        for x in c0.iter_mut().chain(c1.iter_mut()) {
            *x += Vec3::new(
                rng.gauss() as Real,
                rng.gauss() as Real,
                rng.gauss() as Real,
            ) * 5e-4;
        }
        let curves: [&[Vec3]; 2] = [&c0, &c1];
        let init = initial_cylinder(&curves, &[p0, p1], &mut scratch).unwrap();
        let fit = fit_cylinder(&curves, init, &LmParams::default()).unwrap();
        assert!(
            (fit.cylinder.radius - 0.15).abs() < 4.0 * fit.sigma_radius,
            "{fit:?}"
        );
        let ang = fit.cylinder.axis.cross(&truth.axis).norm().asin();
        assert!(
            ang < 4.0 * fit.sigma_axis * Real::sqrt(2.0),
            "{ang} {}",
            fit.sigma_axis
        );
        let tilt = Tilt::of(fit.cylinder.axis, &p0, fit.sigma_axis);
        assert!((tilt.theta - 15.0 * deg).abs() < 4.0 * fit.sigma_axis * 2.0);
        assert!((tilt.phi - 20.0 * deg).abs() < 4.0 * fit.sigma_axis * 2.0);
        // Generalised three-tangent on the exact curve projected along the true axis: the
        // projection is exact (docs/cylinder.md), so only rounding remains (100·ε·L as in
        // `three_tangent_exact_arc`, ×10 for the sampled rather than analytic tangent
        // points: 2000 samples put the last lit one within Δs ≈ 0.5 mm of the tangent,
        // where the polar angle deficit is ~(Δs)²/(2rL) ≈ 6e-7 rad → 1e-6 m in r).
        // Isotropic noise would not do here: lateral noise biases the extreme polar
        // angles outwards, which real column-wise data does not have (docs/cylinder.md).
        let g = generalised_three_tangent(
            &exact0,
            p0.source,
            truth.axis,
            &ThreeTangentParams::default(),
            &mut scratch,
        )
        .unwrap();
        assert!((g.radius - 0.15).abs() < 2e-6 + 1000.0 * EPS * 1.5, "{g:?}");
    }

    fn noisy_columns(
        plane: &LaserPlane,
        c: &Circle,
        sigma_px: Real,
        rng: &mut Rng,
        out: &mut std::vec::Vec<Vec3>,
    ) {
        let cam = Camera::reference_design();
        let mut buf = [Vec2::zeros(); 800];
        let (n, _) = sample_columns(plane, &cam, c, &mut buf).unwrap();
        out.clear();
        for q in &buf[..n] {
            let x = plane.from_plane_coords(*q);
            let g = noise::displacement_per_pixel(plane, cam.fy, x).unwrap();
            out.push(x + g * (sigma_px * rng.gauss() as Real));
        }
    }

    /// Each point's 1σ, as the pipeline writes it ([`crate::pipeline::point_sigmas`]).
    fn sigmas_of(
        curve: &[Vec3],
        plane: &LaserPlane,
        params: &CylinderParams,
    ) -> std::vec::Vec<Real> {
        let px = params.noise.image_px();
        curve
            .iter()
            .map(|x| noise::displacement_sigma(plane, params.focal_px, *x, px).unwrap_or(0.0))
            .collect()
    }

    #[test]
    fn solve_transversal_stem() {
        let (p0, _) = planes();
        let params = CylinderParams::default();
        let mut rng = Rng::new(1);
        let mut curve = std::vec::Vec::new();
        let mut pts = std::vec![Vec2::zeros(); 800];
        let mut vals = std::vec![0.0; 800];
        for (d, diam) in [(1.5, 0.3), (0.8, 0.12), (2.5, 0.5)] {
            let (d, diam): (Real, Real) = (d, diam);
            let c = Circle::new(Vec2::new(0.02, d + diam / 2.0), diam / 2.0);
            noisy_columns(&p0, &c, params.noise.image_px(), &mut rng, &mut curve);
            let sol = solve(
                &CylinderInput {
                    curves: &[&curve],
                    sigmas: &[&sigmas_of(&curve, &p0, &params)],
                    planes: &[p0],
                },
                &params,
                Scratch {
                    points: &mut pts,
                    values: &mut vals,
                },
            )
            .unwrap();
            // The uncertainty includes calibration (systematic, absent here) so it bounds
            // the random error from above; 4σ.
            assert!(
                (sol.diameter - diam).abs() < 4.0 * sol.uncertainty,
                "{sol:?}"
            );
            assert!(sol.flags.contains(Flags::TILT_IGNORED));
            // Round: never flagged elliptic (docs/cylinder.md, "Elliptic stems").
            assert!(
                !sol.flags.contains(Flags::ELLIPTIC) && sol.axes.is_none(),
                "{sol:?}"
            );
            assert!(sol.tilt.is_none());
            assert!(sol.three_tangent_diameter.is_some() && sol.fit_diameter.is_some());
            assert_eq!(sol.n_points, curve.len());
            assert!((sol.distance - d).abs() < 0.01);
        }
    }

    #[test]
    fn solve_tilted_stem_two_planes() {
        let (p0, p1) = planes();
        let deg = PI / 180.0;
        let params = CylinderParams::default();
        let truth = tilted_cylinder(-10.0 * deg, 25.0 * deg, 0.2, Vec2::new(0.0, 1.6), &p0);
        let (mut c0, mut c1) = (std::vec::Vec::new(), std::vec::Vec::new());
        section(&truth, &p0, 1500, &mut c0);
        section(&truth, &p1, 1500, &mut c1);
        let mut rng = Rng::new(9);
        for x in c0.iter_mut().chain(c1.iter_mut()) {
            *x += Vec3::new(
                rng.gauss() as Real,
                rng.gauss() as Real,
                rng.gauss() as Real,
            ) * 3e-4;
        }
        let mut pts = std::vec![Vec2::zeros(); 1500];
        let mut vals = std::vec![0.0; 1500];
        let sol = solve(
            &CylinderInput {
                curves: &[&c0, &c1],
                sigmas: &[&sigmas_of(&c0, &p0, &params), &sigmas_of(&c1, &p1, &params)],
                planes: &[p0, p1],
            },
            &params,
            Scratch {
                points: &mut pts,
                values: &mut vals,
            },
        )
        .unwrap();
        let tilt = sol.tilt.unwrap();
        assert!(
            (sol.diameter - 0.4).abs() < 4.0 * sol.uncertainty,
            "{sol:?}"
        );
        assert!((tilt.phi - 25.0 * deg).abs() < 2.0 * deg, "{tilt:?}");
        assert!((tilt.theta + 10.0 * deg).abs() < 2.0 * deg, "{tilt:?}");
        assert!(!sol.flags.contains(Flags::TILT_IGNORED));
        // The one-plane answer would have been inflated by ≈ 1/cos 25° = +10 %.
        let one = solve(
            &CylinderInput {
                curves: &[&c0],
                sigmas: &[&sigmas_of(&c0, &p0, &params)],
                planes: &[p0],
            },
            &params,
            Scratch {
                points: &mut pts,
                values: &mut vals,
            },
        )
        .unwrap();
        assert!(one.diameter > 0.4 * 1.05, "{one:?}");
    }

    #[test]
    fn solve_errors() {
        let (p0, p1) = planes();
        let params = CylinderParams::default();
        let mut pts = [Vec2::zeros(); 4];
        let mut vals = [0.0; 4];
        let curve = [Vec3::new(0.0, 0.0, 1.0); 10];
        let r = solve(
            &CylinderInput {
                curves: &[&curve],
                sigmas: &[&sigmas_of(&curve, &p0, &params)],
                planes: &[p0, p1],
            },
            &params,
            Scratch {
                points: &mut pts,
                values: &mut vals,
            },
        );
        assert_eq!(r.err(), Some(SolveError::PlaneCount));
        let r = solve(
            &CylinderInput {
                curves: &[&curve],
                sigmas: &[&sigmas_of(&curve, &p0, &params)],
                planes: &[p0],
            },
            &params,
            Scratch {
                points: &mut pts,
                values: &mut vals,
            },
        );
        assert_eq!(r.err(), Some(SolveError::ScratchTooSmall));
        // A 1.4 m stem: outside the plausible range (max radius 0.6 m).
        let mut rng = Rng::new(3);
        let mut big = std::vec::Vec::new();
        noisy_columns(
            &p0,
            &Circle::new(Vec2::new(0.0, 3.5), 0.7),
            0.0,
            &mut rng,
            &mut big,
        );
        let mut pts = std::vec![Vec2::zeros(); 800];
        let mut vals = std::vec![0.0; 800];
        let r = solve(
            &CylinderInput {
                curves: &[&big],
                sigmas: &[&sigmas_of(&big, &p0, &params)],
                planes: &[p0],
            },
            &params,
            Scratch {
                points: &mut pts,
                values: &mut vals,
            },
        );
        assert_eq!(r.err(), Some(SolveError::RadiusOutOfRange));
    }

    /// The fade-out bias term: a three-tangent solution whose edges stop short of the true
    /// grazing rays by `g` radians (each side) gets `∂r/∂α·g` from an exact fitted circle
    /// (σ_fit = 0), and the fit's σ adds in quadrature through `∂α_f/∂R = 1/(L cos α_f)`.
    #[test]
    fn edge_bias_sigma_measures_the_fade_gap() {
        let (c, r) = (Vec2::new(0.05, 2.0), 0.15);
        let mut pts = std::vec![Vec2::zeros(); 400];
        lit_arc(c, r, 400, &mut pts);
        let l = c.norm();
        let alpha_true = (r / l).asin();
        // Drop the outer points until the aperture has lost about 1 % of α on each side.
        let keep: std::vec::Vec<Vec2> = pts
            .iter()
            .copied()
            .filter(|q| {
                let psi = (q.x * c.y - q.y * c.x).atan2(q.dot(&c));
                psi.abs() <= 0.99 * alpha_true
            })
            .collect();
        let t = three_tangent(&keep, &ThreeTangentParams::default()).unwrap();
        let gap = alpha_true - t.alpha;
        assert!(gap > 0.0);
        let (dr_da, _) = t.partials();
        let exact = circle::Circle::new(c, r);
        let b = edge_bias_sigma(&t, &exact, 0.0);
        assert!(
            (b - dr_da * gap).abs() <= 1e-6 * b + 64.0 * EPS,
            "{b} vs {}",
            dr_da * gap
        );
        // The three-tangent radius really is short by about that much.
        assert!(
            ((r - t.radius) - b).abs() < 0.05 * b,
            "short by {} vs {b}",
            r - t.radius
        );
        let sf = 1e-3;
        let with_fit = edge_bias_sigma(&t, &exact, sf);
        let s_af = sf / (l * alpha_true.cos());
        assert!((with_fit - dr_da * gap.hypot(s_af)).abs() <= 1e-6 * with_fit);
        // Source inside the circle: no grazing geometry, no term.
        assert_eq!(
            edge_bias_sigma(&t, &circle::Circle::new(Vec2::new(0.0, 0.1), 0.2), 0.0),
            0.0
        );
    }
}
