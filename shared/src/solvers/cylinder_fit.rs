//! Cylinder fit to the 3-D points of two or more laser curves (thesis §9.7–9.10;
//! `docs/cylinder.md`, "Randomly tilted stem, two parallel planes"): the initial cylinder from
//! a circle per plane ([`initial_cylinder`]), the Levenberg–Marquardt fit of axis and radius
//! ([`fit_cylinder`]), and the projection of a curve along the axis onto the plane
//! perpendicular to it, where a tilted stem's section is a circle ([`project_along_axis`]).

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec2, Vec3};

use nalgebra::{SMatrix, SVector};

use super::circle;
use super::lm::{self, Evaluated, LeastSquares, LmParams, NormalEquations};
use super::SolveError;
use crate::laser_plane::LaserPlane;

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

mod calibration;
mod weighted;
pub use calibration::calibration_sigma_radius;
pub use weighted::{
    fit_cylinder_weighted, fit_weights, WeightedCylinderFit, CYLINDER_SCRATCH_PER_POINT,
};

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

#[derive(Clone, Copy)]
struct CylState {
    p: Vec3,
    u: Vec3,
    r: Real,
}

/// A normalised point with its weight, as [`cyl_accumulate`] reads it: a pair, or a row of
/// the weighted fit's tables read in place (mapping the tables into pairs was a call per point
/// on the device).
trait WeightedPoint {
    /// The point `y` and its weight.
    fn get(self) -> (Vec3, Real);
}

impl WeightedPoint for (Vec3, Real) {
    #[inline(always)]
    fn get(self) -> (Vec3, Real) {
        self
    }
}

impl WeightedPoint for (&[Real], &Real) {
    #[inline(always)]
    fn get(self) -> (Vec3, Real) {
        let (y, w) = self;
        (Vec3::new(y[0], y[1], y[2]), *w)
    }
}

/// The normal equations `JᵀWJ`, `JᵀWd`, the cost `Σwd²` and the number of points with
/// weight, over normalised points `y` with their weights `w` (points without weight skipped).
fn cyl_accumulate<T: WeightedPoint>(
    points: impl Iterator<Item = T>,
    st: &CylState,
) -> (M5, V5, Real, usize) {
    let (e1, e2) = basis(st.u);
    let mut jtj = M5::zeros();
    let mut jtd = V5::zeros();
    let mut cost = 0.0;
    let mut n = 0;
    for point in points {
        let (y, weight) = point.get();
        if !(weight > 0.0) {
            continue;
        }
        let w = y - st.p;
        let wu = w.dot(&st.u);
        let q = w - st.u * wu;
        let rho = norm(&q);
        let g = if rho > 0.0 { q / rho } else { Vec3::zeros() };
        let (g1, g2) = (g.dot(&e1), g.dot(&e2));
        let j = V5::new(-g1, -g2, -wu * g1, -wu * g2, -1.0);
        let d = rho - st.r;
        // The upper triangle of `j·jᵀ·w` (each entry the very product `(jₐ·j_b)·w` the
        // full outer product forms, `jₐ·j_b = j_b·jₐ` exactly), mirrored below: 15
        // entries per point instead of 25.
        for a in 0..5 {
            for b in a..5 {
                jtj[(a, b)] += j[a] * j[b] * weight;
            }
        }
        jtd += j * (weight * d);
        cost += weight * d * d;
        n += 1;
    }
    for a in 0..5 {
        for b in 0..a {
            jtj[(a, b)] = jtj[(b, a)];
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

/// The cylinder fit as a [`LeastSquares`] problem on the centred, scaled points: `points()`
/// yields each point with its weight ([`cyl_accumulate`]).
struct CylinderProblem<P> {
    points: P,
    /// An accepted step lowering the cost by less than this ends the fit (0: only a short
    /// step does); see [`LeastSquares::settled`].
    settle: Real,
}

impl<P: Fn() -> I, I: Iterator<Item = T>, T: WeightedPoint> LeastSquares<5> for CylinderProblem<P> {
    type Params = CylState;
    type Extra = ();

    fn evaluate(&self, st: &CylState) -> Result<(NormalEquations<5>, ()), SolveError> {
        let (jtj, jtr, cost, n) = cyl_accumulate((self.points)(), st);
        if n < 6 {
            return Err(SolveError::TooFewPoints);
        }
        Ok((NormalEquations { jtj, jtr, cost }, ()))
    }

    fn step(&self, st: &CylState, delta: &V5) -> CylState {
        cyl_step(st, delta)
    }

    /// `1 + |p| + r` (the axis direction is a unit vector).
    fn step_scale(&self, st: &CylState) -> Real {
        1.0 + norm(&st.p) + st.r
    }

    fn settled(&self, before: Real, after: Real) -> bool {
        before - after < self.settle
    }
}

/// The step `δ` (in [`cyl_step`]'s coordinates at `from`) that moves `from` to `to`, to first
/// order: the axis point's and direction's moves on `from`'s basis and the radius's change.
fn cyl_delta(from: &CylState, to: &CylState) -> V5 {
    let (e1, e2) = basis(from.u);
    let (dp, du) = (to.p - from.p, to.u - from.u);
    V5::new(
        dp.dot(&e1),
        dp.dot(&e2),
        du.dot(&e1),
        du.dot(&e2),
        to.r - from.r,
    )
}

/// The points centred on their centroid and scaled to unit RMS distance, and the initial
/// cylinder in those units.
struct Normalised {
    mean: Vec3,
    scale: Real,
    start: CylState,
    n: usize,
}

fn normalise(curves: &[&[Vec3]], initial: Cylinder) -> Result<Normalised, SolveError> {
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
    let st = CylState {
        p: p - u * p.dot(&u),
        u,
        r: initial.radius / scale,
    };
    Ok(Normalised {
        mean,
        scale,
        start: st,
        n,
    })
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
    let Normalised {
        mean,
        scale,
        start: st,
        n,
    } = normalise(curves, initial)?;
    let problem = CylinderProblem {
        points: || {
            curves
                .iter()
                .flat_map(|c| c.iter())
                .map(move |x| ((x - mean) / scale, 1.0))
        },
        settle: 0.0,
    };
    let start = Evaluated::at(&problem, st)?;
    let (min, iterations) = lm::minimise(&problem, start, params)?;
    let (st, jtj, cost) = (min.params, min.normal.jtj, min.normal.cost);
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

/// The in-plane coordinates of `curve` on `plane`, written into `scratch`.
pub(crate) fn to_plane<'s>(
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

/// A curve projected along a cylinder axis ([`project_along_axis`]).
#[derive(Debug)]
pub struct AxisProjection<'s> {
    /// The projected points, in curve order.
    pub points: &'s [Vec2],
    /// Unit axis.
    pub axis: Vec3,
    /// The projection plane's axes (`(e₁, e₂, axis)` orthonormal).
    pub e1: Vec3,
    /// See `e1`.
    pub e2: Vec3,
}

/// Projects `curve` along `axis` onto the plane perpendicular to it, origin at `origin` (the
/// laser source for the generalised three-tangent method): `qᵢ = ((xᵢ − o)·e₁, (xᵢ − o)·e₂)`,
/// written into `scratch` (`docs/cylinder.md`, "Generalised three-tangent method"). A lit arc
/// of a cylinder projects onto an arc of its circular section, whatever the tilt.
///
/// Errors: [`SolveError::InvalidParameter`] for a zero or non-finite axis,
/// [`SolveError::ScratchTooSmall`].
pub fn project_along_axis<'s>(
    curve: &[Vec3],
    origin: Vec3,
    axis: Vec3,
    scratch: &'s mut [Vec2],
) -> Result<AxisProjection<'s>, SolveError> {
    let an = norm(&axis);
    if !(an > 0.0 && an.is_finite()) {
        return Err(SolveError::InvalidParameter);
    }
    let u = axis / an;
    let (e1, e2) = basis(u);
    let out = scratch
        .get_mut(..curve.len())
        .ok_or(SolveError::ScratchTooSmall)?;
    for (o, x) in out.iter_mut().zip(curve) {
        let w = x - origin;
        *o = Vec2::new(w.dot(&e1), w.dot(&e2));
    }
    Ok(AxisProjection {
        points: out,
        axis: u,
        e1,
        e2,
    })
}

#[cfg(test)]
// The casts to f64 are no-ops in f64 builds but needed with `--features f32`.
#[allow(clippy::unnecessary_cast)]
pub(crate) mod tests {
    extern crate std;
    use super::*;
    use crate::calibration::Calibration;
    use crate::real::PI;
    use crate::solvers::circle::tests::Rng;
    use crate::solvers::result::Tilt;
    use crate::solvers::three_tangent::tests::tilted_axis;
    use crate::solvers::three_tangent::{generalised_three_tangent, ThreeTangentParams};

    const EPS: Real = Real::EPSILON;

    pub(crate) fn planes() -> (LaserPlane, LaserPlane) {
        let cal = Calibration::reference_design();
        (cal.planes[0], cal.planes[1])
    }

    /// Lit (from the plane's source) and visible (from the camera at the origin) points of
    /// the cylinder's section by `plane`, `n` samples of the angle around the axis.
    pub(crate) fn section(
        cyl: &Cylinder,
        plane: &LaserPlane,
        n: usize,
        out: &mut std::vec::Vec<Vec3>,
    ) {
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

    pub(crate) fn tilted_cylinder(
        theta: Real,
        phi: Real,
        r: Real,
        at: Vec2,
        plane: &LaserPlane,
    ) -> Cylinder {
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
}
