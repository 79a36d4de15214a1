//! Circle fits on 2-D points (`docs/cylinder.md`, "Circle fits").
//!
//! * Algebraic fits — [`fit_hyper`], [`fit_kasa`] — minimise `Σ (A·z + B·x + C·y + D)²`
//!   (`z = x² + y²`) under a normalisation constraint; they are closed-form (one small
//!   polynomial root). Hyper (Al-Sharadqah & Chernov 2009) has no second-order essential bias
//!   and is the initial value of the geometric fits; Kåsa, biased towards small radii on short
//!   arcs, is kept as the naive baseline that evaluations compare against.
//! * [`fit_geometric`]: Levenberg–Marquardt ([`super::lm`]) on the orthogonal distances
//!   `|p − c| − r`, with the parameter covariance.
//! * [`fit_robust`]: the same, iteratively reweighted with Tukey's biweight and a MAD scale,
//!   for stripes with bark, branches or a second object.
//! * [`fit_weighted`] ([`weighted`]): the whole-arc fit the stem solver uses — each point
//!   weighted by its own σ, robust on the normalised residuals, with the radius σ from the
//!   points' σ, the χ² and the residuals' correlation along the stripe.
//! * The radius σ of a geometric fit beyond its equal-noise covariance: from each point's
//!   noise vector ([`circle_radius_sigma`]) or from the residuals themselves
//!   ([`circle_radius_sigma_residuals`]) (`docs/error-model.md`).
//!
//! Every fit first centres the data on its centroid and scales it to unit RMS distance from
//! it, so that the moments are `O(1)` whatever the units — in `f32` the raw moments of
//! points ~1.5 m from the origin would cancel catastrophically (`docs/cylinder.md`,
//! "Conditioning").
//!
//! Hand-written rather than taken from a crate: the circle-fit crates on crates.io allocate
//! (`Vec`/`DMatrix`) and are `std`; these are a few dozen lines on fixed-size `nalgebra`
//! matrices.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

// `Float` supplies sqrt/atan2/… in `no_std`.
#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{self, sqrt, Mat3, Real, Vec2, Vec3};

use super::lm::{self, Evaluated, LeastSquares, LmParams, NormalEquations};
use super::SolveError;

mod pull;
pub mod weighted;
pub use weighted::{
    fit_weighted, weighted_at, weighted_radius_sigma, Pull, WeightedFit, WEIGHTED_SCRATCH_PER_POINT,
};

/// A circle: centre and radius (same units as the points).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle {
    /// Centre.
    pub centre: Vec2,
    /// Radius (positive).
    pub radius: Real,
}

impl Circle {
    /// A circle from its centre and radius.
    pub fn new(centre: Vec2, radius: Real) -> Self {
        Circle { centre, radius }
    }

    /// Signed orthogonal distance of `p` from the circle: `|p − c| − r` (positive outside).
    pub fn distance(&self, p: Vec2) -> Real {
        real::norm(&(p - self.centre)) - self.radius
    }
}

/// Result of a geometric circle fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CircleFit {
    /// The fitted circle.
    pub circle: Circle,
    /// RMS of the (weighted) orthogonal residuals `|p − c| − r` of the points used.
    pub rms_residual: Real,
    /// LM iterations used (the last call of a robust fit).
    pub iterations: u32,
    /// Covariance of `(c_x, c_y, r)`: `σ̂²·(JᵀWJ)⁻¹` with `σ̂² = Σw·d²/(Σw − 3)` — the
    /// Gauss–Newton estimate for independent, equal noise on the orthogonal residuals.
    pub covariance: Mat3,
    /// `√diag(covariance)` for `(c_x, c_y, r)`.
    pub std_dev: Vec3,
    /// Points with non-zero weight (all points for [`fit_geometric`]).
    pub inliers: usize,
}

/// Centroid and RMS spread of the data: the map `q = (p − mean)/scale` used by every fit.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Normalisation {
    pub(crate) mean: Vec2,
    pub(crate) scale: Real,
}

impl Normalisation {
    /// Checks `n ≥ min_points` finite points with a non-zero spread.
    pub(crate) fn of(points: &[Vec2], min_points: usize) -> Result<Self, SolveError> {
        if points.len() < min_points {
            return Err(SolveError::TooFewPoints);
        }
        let mut sum = Vec2::zeros();
        for p in points {
            if !(p.x.is_finite() && p.y.is_finite()) {
                return Err(SolveError::NonFinite);
            }
            sum += p;
        }
        let n = points.len() as Real;
        let mean = sum / n;
        let mut ss = 0.0;
        for p in points {
            ss += (p - mean).norm_squared();
        }
        let scale = sqrt(ss / n);
        if !(scale.is_finite() && scale > 0.0) {
            return Err(if scale.is_finite() {
                SolveError::Degenerate
            } else {
                SolveError::NonFinite
            });
        }
        Ok(Normalisation { mean, scale })
    }

    pub(crate) fn apply(&self, p: Vec2) -> Vec2 {
        (p - self.mean) / self.scale
    }
}

/// Second moments of centred, scaled data (`z = x² + y²`); `mz = mxx + myy = 1` up to
/// rounding.
struct Moments {
    mxx: Real,
    myy: Real,
    mxy: Real,
    mxz: Real,
    myz: Real,
    mzz: Real,
    mz: Real,
}

fn moments(points: &[Vec2], norm: &Normalisation) -> Moments {
    let mut m = Moments {
        mxx: 0.0,
        myy: 0.0,
        mxy: 0.0,
        mxz: 0.0,
        myz: 0.0,
        mzz: 0.0,
        mz: 0.0,
    };
    for p in points {
        let q = norm.apply(*p);
        let z = q.x * q.x + q.y * q.y;
        m.mxx += q.x * q.x;
        m.myy += q.y * q.y;
        m.mxy += q.x * q.y;
        m.mxz += q.x * z;
        m.myz += q.y * z;
        m.mzz += z * z;
    }
    let n = points.len() as Real;
    m.mxx /= n;
    m.myy /= n;
    m.mxy /= n;
    m.mxz /= n;
    m.myz /= n;
    m.mzz /= n;
    m.mz = m.mxx + m.myy;
    m
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Algebraic {
    Kasa,
    Hyper,
}

/// Kåsa's fit: least squares on `z + B·x + C·y + D` (the constraint `A = 1`).
///
/// Closed form, unbiased for full circles with little noise, but biased towards smaller
/// radii on short arcs (`docs/cylinder.md`, "Circle fits"). Needs 3 non-collinear points.
pub fn fit_kasa(points: &[Vec2]) -> Result<Circle, SolveError> {
    fit_algebraic(points, Algebraic::Kasa)
}

/// Al-Sharadqah & Chernov's "Hyper" fit (2009): the constraint `2·Taubin − Pratt`, which
/// removes the second-order essential bias (`docs/cylinder.md`, "Circle fits"). The
/// recommended initial value for [`fit_geometric`].
pub fn fit_hyper(points: &[Vec2]) -> Result<Circle, SolveError> {
    fit_algebraic(points, Algebraic::Hyper)
}

fn fit_algebraic(points: &[Vec2], kind: Algebraic) -> Result<Circle, SolveError> {
    let norm = Normalisation::of(points, 3)?;
    let m = moments(points, &norm);
    // Characteristic polynomial −det(M − ηN) with the constant-row/column eliminated
    // (docs/cylinder.md, "Circle fits": Taubin is a cubic, Hyper a quartic without cubic
    // term; Kåsa is η = 0).
    let cov_xy = m.mxx * m.myy - m.mxy * m.mxy;
    let var_z = m.mzz - m.mz * m.mz;
    let a1 = var_z * m.mz + 4.0 * cov_xy * m.mz - m.mxz * m.mxz - m.myz * m.myz;
    let a0 = m.mxz * (m.mxz * m.myy - m.myz * m.mxy) + m.myz * (m.myz * m.mxx - m.mxz * m.mxy)
        - var_z * cov_xy;
    let eta = match kind {
        Algebraic::Kasa => 0.0,
        Algebraic::Hyper => {
            let a2 = 4.0 * cov_xy - 3.0 * m.mz * m.mz - m.mzz;
            smallest_root(|x| {
                (
                    a0 + x * (a1 + x * (a2 + 4.0 * x * x)),
                    a1 + x * (2.0 * a2 + 16.0 * x * x),
                )
            })?
        }
    };
    // (M − ηN)θ = 0 with A = 1: the 2×2 system for (B, C), then D from the last row.
    let det = eta * eta - eta * m.mz + cov_xy;
    // In normalised data cov_xy ∈ [0, 1/4] is the product of the two principal variances;
    // below 64ε the points are collinear to rounding and the centre is undetermined.
    if !(det.abs() > 64.0 * Real::EPSILON) {
        return Err(SolveError::Degenerate);
    }
    let xc = (m.mxz * (m.myy - eta) - m.myz * m.mxy) / (2.0 * det);
    let yc = (m.myz * (m.mxx - eta) - m.mxz * m.mxy) / (2.0 * det);
    let r2 = xc * xc
        + yc * yc
        + match kind {
            Algebraic::Hyper => m.mz - 2.0 * eta,
            _ => m.mz,
        };
    if !(r2.is_finite() && r2 > 0.0) {
        return Err(SolveError::Degenerate);
    }
    let circle = Circle::new(
        norm.mean + Vec2::new(xc, yc) * norm.scale,
        sqrt(r2) * norm.scale,
    );
    if !(circle.centre.x.is_finite() && circle.centre.y.is_finite() && circle.radius.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    Ok(circle)
}

/// Newton from `η = 0` towards the smallest non-negative root of the characteristic
/// polynomial (`f` returns value and derivative), stopping when `|f|` stops decreasing —
/// Chernov's scheme: `f(0) ≤ 0` and `f` increases up to the first root, so Newton from the
/// left converges monotonically.
fn smallest_root<F: Fn(Real) -> (Real, Real)>(f: F) -> Result<Real, SolveError> {
    let mut x: Real = 0.0;
    let (mut y, _) = f(x);
    if !y.is_finite() {
        return Err(SolveError::NonFinite);
    }
    for _ in 0..100 {
        let (_, dy) = f(x);
        if dy == 0.0 || !dy.is_finite() {
            break;
        }
        let xn = x - y / dy;
        let (yn, _) = f(xn);
        if !(xn.is_finite() && yn.is_finite()) || yn.abs() >= y.abs() {
            break;
        }
        x = xn;
        y = yn;
    }
    // For data on an exact circle the root is 0 and rounding (ε in the normalised,
    // O(1) moments) may put it slightly below: clamp those; a clearly negative root means
    // Newton went to the wrong branch.
    if !(x.is_finite() && x >= -1000.0 * Real::EPSILON) {
        return Err(SolveError::Degenerate);
    }
    Ok(x.max(0.0))
}

/// Normal equations of the (weighted) orthogonal-distance problem at `(a, b, r)`
/// (normalised coordinates): `JᵀWJ`, `JᵀWd`, `Σw·d²`, `Σw`, points with `w > 0`.
///
/// The Jacobian row is `(−uₓ, −u_y, −1)` (`u` the unit normal), so the six distinct entries of
/// `JᵀWJ` and the three of `JᵀWd` are summed as scalars — each term the same product
/// (`(jₐ·j_b)·w`, `jₐ·(w·d)`) the outer product `j·jᵀ·w` forms, the `−1`s exact — instead of
/// a 3×3 temporary per point: the same sums to the bit, at a fraction of the instructions
/// (the LM's hot loop on the device, `docs/performance.md`).
fn accumulate<W: Fn(usize, Vec2) -> Real>(
    points: &[Vec2],
    norm: &Normalisation,
    theta: Vec3,
    weight: &W,
) -> (Mat3, Vec3, Real, Real, usize) {
    // Σw·uₓ², Σw·uₓu_y, Σw·uₓ, Σw·u_y², Σw·u_y, Σw; Σ(w·d)·uₓ, Σ(w·d)·u_y, Σw·d; Σw·d².
    let (mut xx, mut xy, mut x, mut yy, mut y, mut wsum) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut dx_sum, mut dy_sum, mut d_sum, mut cost) = (0.0, 0.0, 0.0, 0.0);
    let mut used = 0;
    for (i, p) in points.iter().enumerate() {
        let q = norm.apply(*p);
        let w = weight(i, q);
        if !(w > 0.0) {
            continue;
        }
        let (dx, dy) = (q.x - theta.x, q.y - theta.y);
        let rho = sqrt(dx * dx + dy * dy);
        // A point exactly at the centre has no defined normal; its residual −r still pulls
        // on r only.
        let (ux, uy) = if rho > 0.0 {
            (dx / rho, dy / rho)
        } else {
            (0.0, 0.0)
        };
        let d = rho - theta.z;
        let wd = w * d;
        xx += ux * ux * w;
        xy += ux * uy * w;
        x += ux * w;
        yy += uy * uy * w;
        y += uy * w;
        wsum += w;
        dx_sum -= ux * wd;
        dy_sum -= uy * wd;
        d_sum -= wd;
        cost += wd * d;
        used += 1;
    }
    let jtj = Mat3::new(xx, xy, x, xy, yy, y, x, y, wsum);
    (jtj, Vec3::new(dx_sum, dy_sum, d_sum), cost, wsum, used)
}

/// The (weighted) orthogonal-distance problem in normalised coordinates, parameters
/// `θ = (a, b, r)`; fewer than 3 points of non-zero weight are out of the domain.
struct CircleProblem<'a, W> {
    points: &'a [Vec2],
    norm: &'a Normalisation,
    weight: &'a W,
    /// An accepted step that lowers the cost by less than this ends the iteration
    /// ([`LeastSquares::settled`]); 0: never.
    settle: Real,
}

impl<W: Fn(usize, Vec2) -> Real> LeastSquares<3> for CircleProblem<'_, W> {
    type Params = Vec3;
    type Extra = ();

    fn evaluate(&self, theta: &Vec3) -> Result<(NormalEquations<3>, ()), SolveError> {
        let (jtj, jtr, cost, _, used) = accumulate(self.points, self.norm, *theta, self.weight);
        if used < 3 {
            return Err(SolveError::TooFewPoints);
        }
        Ok((NormalEquations { jtj, jtr, cost }, ()))
    }

    fn step(&self, theta: &Vec3, delta: &Vec3) -> Vec3 {
        theta + delta
    }

    fn step_scale(&self, theta: &Vec3) -> Real {
        1.0 + real::norm(theta)
    }

    fn settled(&self, before: Real, after: Real) -> bool {
        before - after < self.settle
    }
}

/// Levenberg–Marquardt ([`lm::minimise`]) on normalised coordinates; returns
/// `(θ, iterations, JᵀWJ at θ)`. An accepted step that lowers the cost by less than `settle`
/// ends it (0: only a short step does).
fn lm<W: Fn(usize, Vec2) -> Real>(
    points: &[Vec2],
    norm: &Normalisation,
    start: Vec3,
    params: &LmParams,
    weight: &W,
    settle: Real,
) -> Result<(Vec3, u32, Mat3), SolveError> {
    let problem = CircleProblem {
        points,
        norm,
        weight,
        settle,
    };
    let start = Evaluated::at(&problem, start)?;
    if !start.normal.cost.is_finite() {
        return Err(SolveError::NonFinite);
    }
    let (min, iterations) = lm::minimise(&problem, start, params)?;
    Ok((min.params, iterations, min.normal.jtj))
}

fn finish<W: Fn(usize, Vec2) -> Real>(
    points: &[Vec2],
    norm: &Normalisation,
    theta: Vec3,
    iterations: u32,
    weight: &W,
) -> Result<CircleFit, SolveError> {
    // A negative radius is the same circle with the residual's sign flipped; report |r|.
    let r = theta.z.abs();
    if !(r > 0.0 && r.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    let theta = Vec3::new(theta.x, theta.y, r);
    finish_with(
        norm,
        theta,
        iterations,
        accumulate(points, norm, theta, weight),
    )
}

/// [`finish`] from the normal equations `sums` ([`accumulate`]) already formed at `theta`
/// (with `r > 0`).
fn finish_with(
    norm: &Normalisation,
    theta: Vec3,
    iterations: u32,
    sums: (Mat3, Vec3, Real, Real, usize),
) -> Result<CircleFit, SolveError> {
    let r = theta.z;
    if !(r > 0.0 && r.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    let (jtj, _, cost, wsum, used) = sums;
    let dof = wsum - 3.0;
    let s2 = if dof > 0.0 { cost / dof } else { 0.0 };
    let s = norm.scale;
    let cov = jtj
        .try_inverse()
        .map(|inv| inv * (s2 * s * s))
        .unwrap_or_else(|| Mat3::from_element(Real::INFINITY));
    let std_dev = Vec3::new(
        sqrt(cov[(0, 0)].max(0.0)),
        sqrt(cov[(1, 1)].max(0.0)),
        sqrt(cov[(2, 2)].max(0.0)),
    );
    let rms = if wsum > 0.0 {
        sqrt(cost / wsum) * s
    } else {
        0.0
    };
    Ok(CircleFit {
        circle: Circle::new(norm.mean + Vec2::new(theta.x, theta.y) * s, r * s),
        rms_residual: rms,
        iterations,
        covariance: cov,
        std_dev,
        inliers: used,
    })
}

fn normalised_start(initial: &Circle, norm: &Normalisation) -> Result<Vec3, SolveError> {
    let c = norm.apply(initial.centre);
    let r = initial.radius / norm.scale;
    if !(c.x.is_finite() && c.y.is_finite() && r.is_finite()) {
        return Err(SolveError::NonFinite);
    }
    if !(r > 0.0) {
        return Err(SolveError::InvalidParameter);
    }
    Ok(Vec3::new(c.x, c.y, r))
}

/// Geometric (orthogonal-distance) fit: minimises `Σ (|pᵢ − c| − r)²` by
/// Levenberg–Marquardt from `initial` (use [`fit_hyper`]).
///
/// Returns the circle, the RMS residual and the Gauss–Newton covariance
/// (`docs/cylinder.md`, "Geometric fit"). Errors: fewer than 3 points, non-finite data,
/// collinear data (singular normal equations), no convergence.
pub fn fit_geometric(
    points: &[Vec2],
    initial: Circle,
    params: &LmParams,
) -> Result<CircleFit, SolveError> {
    params.validate()?;
    let norm = Normalisation::of(points, 3)?;
    let start = normalised_start(&initial, &norm)?;
    let unit = |_: usize, _: Vec2| 1.0;
    let (theta, it, _) = lm(points, &norm, start, params, &unit, 0.0)?;
    finish(points, &norm, theta, it, &unit)
}

/// Settings of [`fit_robust`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobustParams {
    /// The inner Levenberg–Marquardt settings.
    pub lm: LmParams,
    /// Tukey biweight constant `c` in units of the robust scale: 4.685 gives 95 % efficiency
    /// on Gaussian residuals.
    pub tuning: Real,
    /// Floor of the robust scale (same units as the points): keeps exact or nearly exact
    /// data from getting a zero scale (which would reject every point). Set it to the
    /// expected point noise (e.g. from [`crate::noise`]).
    pub min_scale: Real,
    /// Most reweighting rounds.
    pub max_rounds: u32,
}

impl Default for RobustParams {
    fn default() -> Self {
        RobustParams {
            lm: LmParams::default(),
            tuning: 4.685,
            min_scale: 1e-4,
            max_rounds: 20,
        }
    }
}

/// Tukey's biweight `w(u) = (1 − u²)²` for `|u| < 1`, else 0.
pub(crate) fn tukey(u: Real) -> Real {
    if u.abs() < 1.0 {
        let t = 1.0 - u * u;
        t * t
    } else {
        0.0
    }
}

/// Outlier-robust geometric fit: iteratively reweighted least squares with Tukey's biweight
/// on the orthogonal residuals, scale `s = max(1.4826·median|dᵢ|, min_scale)`, weights
/// frozen at the previous round's circle, LM inside each round (`docs/cylinder.md`,
/// "Robust fit").
///
/// `scratch` (at least `points.len()` long) holds the absolute residuals for the median.
/// Points farther than `tuning·s` from the circle get zero weight; [`CircleFit::inliers`]
/// counts the others. Tukey's weights redescend, so the start must be inside the basin of
/// the inliers: start from [`fit_hyper`] when outliers are a minority.
pub fn fit_robust(
    points: &[Vec2],
    initial: Circle,
    params: &RobustParams,
    scratch: &mut [Real],
) -> Result<CircleFit, SolveError> {
    params.lm.validate()?;
    let tuning_ok = params.tuning.is_finite() && params.tuning > 0.0;
    let scale_ok = params.min_scale.is_finite() && params.min_scale >= 0.0;
    if !tuning_ok || !scale_ok || params.max_rounds == 0 {
        return Err(SolveError::InvalidParameter);
    }
    let norm = Normalisation::of(points, 3)?;
    let buf = scratch
        .get_mut(..points.len())
        .ok_or(SolveError::ScratchTooSmall)?;
    let mut theta = normalised_start(&initial, &norm)?;
    let min_scale = params.min_scale / norm.scale;
    let mut last_it = 0;
    for _ in 0..params.max_rounds {
        let centre = Vec2::new(theta.x, theta.y);
        let r = theta.z;
        for (b, p) in buf.iter_mut().zip(points) {
            *b = (real::norm(&(norm.apply(*p) - centre)) - r).abs();
        }
        let mid = buf.len() / 2;
        let (_, median, _) = buf.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        let scale = (1.4826 * *median).max(min_scale);
        if !(scale > 0.0 && scale.is_finite()) {
            return Err(SolveError::Degenerate);
        }
        let cs = params.tuning * scale;
        let weight = move |_: usize, q: Vec2| tukey((real::norm(&(q - centre)) - r) / cs);
        let (next, it, _) = lm(points, &norm, theta, &params.lm, &weight, 0.0)?;
        last_it = it;
        let change = real::norm(&(next - theta));
        theta = next;
        if change <= params.lm.tolerance * (1.0 + real::norm(&theta)) {
            let weight = move |_: usize, q: Vec2| tukey((real::norm(&(q - centre)) - r) / cs);
            return finish(points, &norm, theta, last_it, &weight);
        }
    }
    // The weights still moved at the last round: report the last state only if it is
    // stable to the noise level (change below the scale), else no convergence.
    let centre = Vec2::new(theta.x, theta.y);
    let r = theta.z;
    for (b, p) in buf.iter_mut().zip(points) {
        *b = (real::norm(&(norm.apply(*p) - centre)) - r).abs();
    }
    let mid = buf.len() / 2;
    let (_, median, _) = buf.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    let scale = (1.4826 * *median).max(min_scale);
    let cs = params.tuning * scale;
    let weight = move |_: usize, q: Vec2| tukey((real::norm(&(q - centre)) - r) / cs);
    let (next, it, _) = lm(points, &norm, theta, &params.lm, &weight, 0.0)?;
    if real::norm(&(next - theta)) > scale {
        return Err(SolveError::NotConverged);
    }
    finish(points, &norm, next, it.max(last_it), &weight)
}

/// σ of the radius of a geometric circle fit estimated from the data's own residuals: the
/// heteroscedasticity-consistent sandwich `A⁻¹BA⁻¹` with `B = Σ dᵢ²JᵢJᵢᵀ·n/(n − 3)`
/// (`dᵢ = |qᵢ − c| − r`, `J = (−nᵢ, −1)`; White 1980, with the `n/(n − 3)` small-sample
/// correction). Unlike `σ̂²(JᵀJ)⁻¹` it does not assume equal noise on every point, so the
/// noisy, dim ends of a curve count with the noise they really have
/// (`docs/error-model.md`, "Data-driven fit uncertainty"). Points with `|dᵢ| > cutoff`
/// (the robust fit's rejected outliers) are left out. Infinite if `A` is singular or fewer
/// than 4 points remain.
pub fn circle_radius_sigma_residuals(c: &Circle, points: &[Vec2], cutoff: Real) -> Real {
    let mut a = Mat3::zeros();
    let mut b = Mat3::zeros();
    let mut n = 0usize;
    for q in points {
        let d = q - c.centre;
        let len = real::norm(&d);
        if !(len > 0.0) {
            continue;
        }
        let res = len - c.radius;
        if !(res.abs() <= cutoff) {
            continue;
        }
        let nn = d / len;
        let j = Vec3::new(-nn.x, -nn.y, -1.0);
        let jj = j * j.transpose();
        a += jj;
        b += jj * (res * res);
        n += 1;
    }
    if n < 4 {
        return Real::INFINITY;
    }
    let k = n as Real / (n - 3) as Real;
    match a.try_inverse() {
        Some(inv) => {
            let cov = inv * b * inv;
            sqrt((cov[(2, 2)] * k).max(0.0))
        }
        None => Real::INFINITY,
    }
}

/// σ of the radius of a geometric circle fit (unweighted least squares, as
/// [`fit_geometric`]) when each point `qᵢ` has an independent error along the
/// vector `gᵢ` (1σ): the sandwich `A⁻¹BA⁻¹`, `A = ΣJJᵀ`, `B = Σ(nᵢ·gᵢ)²JJᵀ`,
/// `J = (−nᵢ, −1)` (`docs/error-model.md`, "Circle fit"). Infinite if `A` is singular.
pub fn circle_radius_sigma<I: Iterator<Item = (Vec2, Vec2)>>(c: &Circle, points: I) -> Real {
    let mut a = Mat3::zeros();
    let mut b = Mat3::zeros();
    for (q, g) in points {
        let d = q - c.centre;
        let n = real::norm(&d);
        if !(n > 0.0) {
            continue;
        }
        let nn = d / n;
        let j = Vec3::new(-nn.x, -nn.y, -1.0);
        let jj = j * j.transpose();
        let s = nn.dot(&g);
        a += jj;
        b += jj * (s * s);
    }
    match a.try_inverse() {
        Some(inv) => {
            let cov = inv * b * inv;
            sqrt(cov[(2, 2)].max(0.0))
        }
        None => Real::INFINITY,
    }
}

#[cfg(test)]
pub(crate) mod tests;
