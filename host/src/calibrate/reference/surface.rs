//! The reference surfaces and their fits with each point's residual along its stripe's
//! displacement line (`docs/calibration.md`, (B2) and (B4)): a ball's sphere, a flat wall's
//! plane, each re-fitted for every correction by the shared Levenberg–Marquardt.

// `!(x > 0.0)` is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use nalgebra::{SMatrix, SVector};
use tangent_core::real::Vec3;
use tangent_core::solvers::lm::{minimise, Evaluated, LeastSquares, LmParams, NormalEquations};
use tangent_core::solvers::sphere_sections::Sphere;
use tangent_core::solvers::SolveError;

/// The reference surface of a view: a ball's sphere or a flat wall's plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Surface {
    /// A ball.
    Sphere(Sphere),
    /// A flat wall, `z = a·x + b·y + c` (camera frame, metres): a wall faces the camera.
    Plane {
        /// `∂z/∂x`.
        a: f64,
        /// `∂z/∂y`.
        b: f64,
        /// Depth on the optical axis (metres).
        c: f64,
    },
}

impl Surface {
    /// Distance of `x` from the surface (metres; for the report).
    pub(super) fn distance(&self, x: &Vec3) -> f64 {
        match self {
            Surface::Sphere(s) => (x - s.centre).norm() - s.radius,
            Surface::Plane { a, b, c } => {
                (a * x.x + b * x.y + c - x.z) / (a * a + b * b + 1.0).sqrt()
            }
        }
    }

    /// The size the report shows: a sphere's diameter, a plane's depth on the axis (metres).
    pub(super) fn size(&self) -> f64 {
        match self {
            Surface::Sphere(s) => 2.0 * s.radius,
            Surface::Plane { c, .. } => *c,
        }
    }

    /// Distance of the surface's point nearest the camera's axis (metres).
    pub(super) fn range(&self) -> f64 {
        match self {
            Surface::Sphere(s) => s.centre.norm(),
            Surface::Plane { c, .. } => *c,
        }
    }
}

/// A known ball diameter (a reference sphere's certificate), which makes the common scale
/// observable as well.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownDiameter {
    /// The diameter (metres).
    pub diameter: f64,
    /// Its 1σ (metres, positive).
    pub sigma: f64,
}

/// A point as the inner fit reads it: where it is, the unit direction `L` in which its
/// stripe's error moves it (its plane's line in the image column's plane through it), and
/// the 1σ of that move.
#[derive(Debug, Clone, Copy)]
pub(super) struct Observed {
    pub(super) x: Vec3,
    pub(super) along: Vec3,
    pub(super) sigma: f64,
}

/// The signed distance `t` along `L` from `x` to the sphere (the root of
/// `|x + tL − C|² = R²` nearest 0), with `∂t/∂(C, R)`; where the line misses the sphere, the
/// closest approach `t = −L·(x − C)`. This is the stripe's own error, so the residual `t/σ`
/// is Gaussian where a point's distance to the surface is not: near a section's limb `L`
/// runs along the surface and a move `t` puts the point `t²/2R` outside it, always outward
/// (`docs/calibration.md`, section 12).
fn along_line(p: &Observed, c: &Vec3, radius: f64) -> (f64, SVector<f64, 4>) {
    let v = p.x - c;
    let b = p.along.dot(&v);
    let cc = v.norm_squared() - radius * radius;
    let disc = b * b - cc;
    if disc < 0.0 {
        let j = SVector::<f64, 4>::new(p.along.x, p.along.y, p.along.z, 0.0);
        return (-b, j);
    }
    let q = b + b.signum() * disc.sqrt();
    let t = if q != 0.0 { -cc / q } else { 0.0 };
    // |x + tL − C|² = R² differentiated: (P − C)·(L dt − dC) = R dR.
    let pc = v + p.along * t;
    let den = pc.dot(&p.along);
    if den == 0.0 {
        return (t, SVector::<f64, 4>::zeros());
    }
    let j = SVector::<f64, 4>::new(pc.x / den, pc.y / den, pc.z / den, radius / den);
    (t, j)
}

/// The signed distance `t` along `L` from `p.x` to the plane `z = ax + by + c`, with
/// `∂t/∂(a, b, c)`: `F(X) = ax + by + c − z` vanishes at `X + tL`, so `t = −F(X)/(aL_x + bL_y −
/// L_z)` and, with `P = X + tL`, `∂t/∂(a, b, c) = −(P_x, P_y, 1)/(aL_x + bL_y − L_z)`.
fn along_line_plane(p: &Observed, q: &SVector<f64, 3>) -> (f64, SVector<f64, 3>) {
    let (a, b, c) = (q[0], q[1], q[2]);
    let den = a * p.along.x + b * p.along.y - p.along.z;
    if den == 0.0 {
        return (0.0, SVector::<f64, 3>::zeros());
    }
    let t = -(a * p.x.x + b * p.x.y + c - p.x.z) / den;
    let at = p.x + p.along * t;
    (t, SVector::<f64, 3>::new(-at.x, -at.y, -1.0) / den)
}

/// A plane through fixed points, each residual its distance along `L` over its σ: the inner
/// problem of a flat wall.
struct FixedPlane<'a> {
    points: &'a [Observed],
}

impl LeastSquares<3> for FixedPlane<'_> {
    type Params = SVector<f64, 3>;
    type Extra = ();

    fn evaluate(&self, q: &Self::Params) -> Result<(NormalEquations<3>, ()), SolveError> {
        let mut jtj = SMatrix::<f64, 3, 3>::zeros();
        let mut jtr = SVector::<f64, 3>::zeros();
        let mut cost = 0.0;
        for o in self.points {
            let (t, j) = along_line_plane(o, q);
            let (j, r) = (j / o.sigma, t / o.sigma);
            jtj += j * j.transpose();
            jtr += j * r;
            cost += r * r;
        }
        if !cost.is_finite() {
            return Err(SolveError::Degenerate);
        }
        Ok((NormalEquations { jtj, jtr, cost }, ()))
    }

    fn step(&self, q: &Self::Params, delta: &SVector<f64, 3>) -> Self::Params {
        q + delta
    }

    fn step_scale(&self, q: &Self::Params) -> f64 {
        1.0 + q.norm()
    }

    /// As [`FixedSphere::settled`].
    fn settled(&self, before: f64, after: f64) -> bool {
        before - after < 1e-10
    }
}

/// Sphere through fixed points, each residual its distance along `L` over its σ: the
/// inner problem of a ball.
struct FixedSphere<'a> {
    points: &'a [Observed],
    known: Option<KnownDiameter>,
}

impl LeastSquares<4> for FixedSphere<'_> {
    type Params = SVector<f64, 4>;
    type Extra = ();

    fn evaluate(&self, p: &Self::Params) -> Result<(NormalEquations<4>, ()), SolveError> {
        let c = Vec3::new(p[0], p[1], p[2]);
        let mut jtj = SMatrix::<f64, 4, 4>::zeros();
        let mut jtr = SVector::<f64, 4>::zeros();
        let mut cost = 0.0;
        let mut add = |j: SVector<f64, 4>, r: f64| {
            jtj += j * j.transpose();
            jtr += j * r;
            cost += r * r;
        };
        for o in self.points {
            let (t, j) = along_line(o, &c, p[3]);
            add(j / o.sigma, t / o.sigma);
        }
        if let Some(k) = self.known {
            let r = (p[3] - 0.5 * k.diameter) / (0.5 * k.sigma);
            add(
                SVector::<f64, 4>::new(0.0, 0.0, 0.0, 1.0 / (0.5 * k.sigma)),
                r,
            );
        }
        if !cost.is_finite() || !(p[3] > 0.0) {
            return Err(SolveError::Degenerate);
        }
        Ok((NormalEquations { jtj, jtr, cost }, ()))
    }

    fn step(&self, p: &Self::Params, delta: &SVector<f64, 4>) -> Self::Params {
        p + delta
    }

    fn step_scale(&self, p: &Self::Params) -> f64 {
        1e-3 + p.norm()
    }

    /// Settled when the cost (χ², σ units) drops by less than 10⁻¹⁰: the sphere is then
    /// within ~10⁻⁵ of its σ of the minimum, far below the outer Jacobian's steps, and a
    /// last ulp of a flat valley is not chased into `NotConverged`.
    fn settled(&self, before: f64, after: f64) -> bool {
        before - after < 1e-10
    }
}

/// The best surface through `points` from `start` (of its kind), and the residuals `t/σ`
/// appended to `out` (and, for a ball of known diameter, its radius's).
pub(super) fn fit_fixed(
    points: &[Observed],
    known: Option<KnownDiameter>,
    start: &Surface,
    out: &mut Vec<f64>,
) -> Result<Surface, SolveError> {
    match start {
        Surface::Sphere(s) => fit_sphere_fixed(points, known, s, out).map(Surface::Sphere),
        Surface::Plane { a, b, c } => {
            let problem = FixedPlane { points };
            let begin = Evaluated::at(&problem, SVector::<f64, 3>::new(*a, *b, *c))?;
            let (min, _) = minimise(&problem, begin, &LmParams::default())?;
            out.extend(
                points
                    .iter()
                    .map(|o| along_line_plane(o, &min.params).0 / o.sigma),
            );
            let q = min.params;
            Ok(Surface::Plane {
                a: q[0],
                b: q[1],
                c: q[2],
            })
        }
    }
}

/// [`fit_fixed`] for a ball.
fn fit_sphere_fixed(
    points: &[Observed],
    known: Option<KnownDiameter>,
    start: &Sphere,
    out: &mut Vec<f64>,
) -> Result<Sphere, SolveError> {
    let problem = FixedSphere { points, known };
    let begin = Evaluated::at(&problem, start.params())?;
    let (min, _) = minimise(&problem, begin, &LmParams::default())?;
    let sphere = Sphere::of_params(&min.params);
    out.extend(
        points
            .iter()
            .map(|o| along_line(o, &sphere.centre, sphere.radius).0 / o.sigma),
    );
    if let Some(k) = known {
        out.push((sphere.radius - 0.5 * k.diameter) / (0.5 * k.sigma));
    }
    Ok(sphere)
}
