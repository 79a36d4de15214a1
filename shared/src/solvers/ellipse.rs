//! Ellipse fit for non-round sections (`docs/cylinder.md`, "Elliptic stems"): a geometric fit
//! of the polar ellipse model to the points a circle fit accepted ([`fit_ellipse`]), and the
//! one-pass score test that screens most round sections out before it ([`ellipse_score_f`]).

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Real, Vec2};

use super::circle::{Circle, Normalisation};
use super::lm::{self, Evaluated, LeastSquares, LmParams, NormalEquations};
use super::SolveError;

/// Result of [`fit_ellipse`]: an ellipse fitted to the points a circle fit accepted, and the
/// comparison of the two fits (`docs/cylinder.md`, "Elliptic stems").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EllipseFit {
    /// Centre of the ellipse.
    pub centre: Vec2,
    /// Semi-axes `(major, minor)`.
    pub semi_axes: (Real, Real),
    /// Direction of the major axis (radians from the first coordinate axis, in `(−π/2, π/2]`).
    pub angle: Real,
    /// 1σ of the mean diameter `a + b` (semi-axes sum, i.e. the mean of the two diameters),
    /// from the fit: the larger of the Gauss–Newton and the residual-sandwich estimates.
    pub sigma_mean_diameter: Real,
    /// Sum of squared radial residuals of the ellipse.
    pub ssr: Real,
    /// Sum of squared residuals of the starting circle over the same points.
    pub ssr_circle: Real,
    /// Points used (circle residual within the cutoff).
    pub points: usize,
    /// LM iterations.
    pub iterations: u32,
}

impl EllipseFit {
    /// Mean diameter `a + b` of the two semi-axes (what cross-calipering reports).
    pub fn mean_diameter(&self) -> Real {
        self.semi_axes.0 + self.semi_axes.1
    }
    /// Relative non-roundness `(a − b)/(a + b)`.
    pub fn eccentricity(&self) -> Real {
        let s = self.semi_axes.0 + self.semi_axes.1;
        if s > 0.0 {
            (self.semi_axes.0 - self.semi_axes.1) / s
        } else {
            0.0
        }
    }
    /// F statistic of the circle against the ellipse (2 extra parameters):
    /// `((SSR_c − SSR_e)/2) / (SSR_e/(n − 5))`. Large when the circle leaves a systematic
    /// pattern the ellipse explains.
    pub fn f_statistic(&self) -> Real {
        if self.points <= 5 || !(self.ssr > 0.0) {
            return Real::INFINITY;
        }
        0.5 * (self.ssr_circle - self.ssr) / (self.ssr / (self.points - 5) as Real)
    }
}

/// Relative cost decrease below which [`fit_ellipse`] stops (1e-9, or 100·ε in `f32`).
const COST_SETTLED: Real = if 100.0 * Real::EPSILON > 1e-9 {
    100.0 * Real::EPSILON
} else {
    1e-9
};

type M5 = nalgebra::SMatrix<Real, 5, 5>;
type V5 = nalgebra::SVector<Real, 5>;

/// Polar equation of an ellipse about its centre: `1/r² = A + B cos 2θ + C sin 2θ`
/// (`docs/cylinder.md`, "Elliptic stems"). Residual `|d| − r(θ)` and its gradient in
/// `(c_x, c_y, A, B, C)`; `None` where `g = 1/r² ≤ 0` or at the centre.
fn ellipse_residual(q: Vec2, p: &V5) -> Option<(Real, V5)> {
    let d = q - Vec2::new(p[0], p[1]);
    let l2 = d.norm_squared();
    if !(l2 > 0.0) {
        return None;
    }
    let l = sqrt(l2);
    let (cth, sth) = (d.x / l, d.y / l);
    let (c2, s2) = (cth * cth - sth * sth, 2.0 * sth * cth);
    let g = p[2] + p[3] * c2 + p[4] * s2;
    if !(g > 0.0) {
        return None;
    }
    let r = 1.0 / sqrt(g);
    let h = 0.5 * r * r * r; // −∂r/∂g
                             // ∂r/∂θ = −½ g^(−3/2) ∂g/∂θ, ∂g/∂θ = −2B sin 2θ + 2C cos 2θ.
    let dr_dth = -h * (-2.0 * p[3] * s2 + 2.0 * p[4] * c2);
    // θ = atan2(d_y, d_x): ∂θ/∂c_x = d_y/|d|², ∂θ/∂c_y = −d_x/|d|².
    let j = V5::new(
        -cth - dr_dth * d.y / l2,
        -sth + dr_dth * d.x / l2,
        h,
        h * c2,
        h * s2,
    );
    Some((l - r, j))
}

fn ellipse_accumulate(
    points: &[Vec2],
    keep: impl Fn(Vec2) -> bool,
    norm: &Normalisation,
    p: &V5,
) -> Option<(M5, V5, M5, Real, usize)> {
    let mut jtj = M5::zeros();
    let mut jtd = V5::zeros();
    let mut meat = M5::zeros();
    let mut cost = 0.0;
    let mut n = 0;
    for q in points {
        if !keep(*q) {
            continue;
        }
        let (d, j) = ellipse_residual(norm.apply(*q), p)?;
        let jj = j * j.transpose();
        jtj += jj;
        meat += jj * (d * d);
        jtd += j * d;
        cost += d * d;
        n += 1;
    }
    Some((jtj, jtd, meat, cost, n))
}

/// The ellipse fit as a [`LeastSquares`] problem: radial residuals of the points kept at the
/// start (within `cutoff` of `circle`), in normalised coordinates. A candidate outside the
/// ellipses (`A ≤ √(B² + C²)`), with an undefined residual or keeping another number of
/// points is out of the domain; the cost counts as settled once its relative decrease is
/// below [`COST_SETTLED`].
struct EllipseProblem<'a> {
    points: &'a [Vec2],
    circle: &'a Circle,
    cutoff: Real,
    norm: &'a Normalisation,
    kept: usize,
}

impl LeastSquares<5> for EllipseProblem<'_> {
    type Params = V5;
    type Extra = M5;

    fn evaluate(&self, p: &V5) -> Result<(NormalEquations<5>, M5), SolveError> {
        if !(p[2] > sqrt(p[3] * p[3] + p[4] * p[4])) {
            return Err(SolveError::Degenerate);
        }
        let keep = |q: Vec2| self.circle.distance(q).abs() <= self.cutoff;
        match ellipse_accumulate(self.points, keep, self.norm, p) {
            Some((jtj, jtr, meat, cost, n)) if n == self.kept => {
                Ok((NormalEquations { jtj, jtr, cost }, meat))
            }
            _ => Err(SolveError::Degenerate),
        }
    }

    fn step(&self, p: &V5, delta: &V5) -> V5 {
        p + delta
    }

    fn step_scale(&self, p: &V5) -> Real {
        1.0 + crate::real::norm(p)
    }

    /// Also stop when the cost has settled: the F statistic and the axes' σ need it to far
    /// better than their own noise, not to the last ulp of a valley that is flat along the
    /// unseen back's extrapolation.
    fn settled(&self, before: Real, after: Real) -> bool {
        before - after <= COST_SETTLED * before
    }
}

/// The ellipse model at `circle` (`B = C = 0`, in the points' normalised coordinates) and its
/// normal equations over the points within `cutoff` of the circle: the start of
/// [`fit_ellipse`] and the whole of [`ellipse_score_f`]. At least 8 points must be kept.
#[allow(clippy::type_complexity)]
fn ellipse_at_circle(
    points: &[Vec2],
    circle: &Circle,
    cutoff: Real,
) -> Result<(Normalisation, V5, (M5, V5, M5, Real, usize)), SolveError> {
    if !(cutoff > 0.0 && circle.radius > 0.0 && circle.radius.is_finite()) {
        return Err(SolveError::InvalidParameter);
    }
    let keep = |q: Vec2| circle.distance(q).abs() <= cutoff;
    let norm = Normalisation::of(points, 8)?;
    let c0 = norm.apply(circle.centre);
    let r0 = circle.radius / norm.scale;
    let p = V5::new(c0.x, c0.y, 1.0 / (r0 * r0), 0.0, 0.0);
    let sums = ellipse_accumulate(points, keep, &norm, &p).ok_or(SolveError::Degenerate)?;
    if sums.4 < 8 {
        return Err(SolveError::TooFewPoints);
    }
    Ok((norm, p, sums))
}

/// Score-test (Lagrange-multiplier) form of [`EllipseFit::f_statistic`] at the circle, without
/// fitting the ellipse (`docs/cylinder.md`, "Screening"): the cost decrease one Gauss–Newton
/// step of the ellipse model predicts from `circle`, `Δ = gᵀ(JᵀJ)⁻¹g` (`g = Jᵀd` over the
/// points within `cutoff` of the circle, the set [`fit_ellipse`] uses), as
/// `(Δ/2) / ((SSR_c − Δ)/(n − 5))`. One pass over the points, where the ellipse fit needs up
/// to hundreds (its valley is long and flat); close to the fitted `F` when the section is
/// nearly round, and large whenever the circle leaves a pattern the ellipse explains.
///
/// Errors: as [`fit_ellipse`] for the data (fewer than 8 points kept, non-finite values,
/// singular normal matrix).
pub fn ellipse_score_f(points: &[Vec2], circle: &Circle, cutoff: Real) -> Result<Real, SolveError> {
    let (_, _, (jtj, jtd, _, cost, n)) = ellipse_at_circle(points, circle, cutoff)?;
    let inv = jtj.try_inverse().ok_or(SolveError::Degenerate)?;
    let decrease = (jtd.transpose() * inv * jtd)[(0, 0)].clamp(0.0, cost);
    let rest = cost - decrease;
    if !(rest > 0.0) {
        return Ok(Real::INFINITY);
    }
    let f = 0.5 * decrease / (rest / (n - 5) as Real);
    if f.is_finite() {
        Ok(f)
    } else {
        Err(SolveError::Degenerate)
    }
}

/// Geometric ellipse fit (radial residuals about the centre) to the points whose orthogonal
/// distance from `circle` is at most `cutoff` (the circle fit's inliers), started from that
/// circle (`docs/cylinder.md`, "Elliptic stems").
///
/// The ellipse is `1/r(θ)² = A + B cos 2θ + C sin 2θ` about its centre `c` — exact for any
/// ellipse, smooth through the circle (`B = C = 0`), so a Levenberg–Marquardt fit of
/// `(c, A, B, C)` starts at the circle fit. Semi-axes `1/√(A ∓ √(B² + C²))`. The radial
/// residual differs from the orthogonal one by the cosine of the angle between radius and
/// normal (≥ 0.98 for axis ratios up to 1.5), which is second order for the comparison.
///
/// Errors: fewer than 8 points kept, non-finite data, a singular normal matrix or a
/// parameter vector leaving the ellipses (`A ≤ √(B² + C²)`), no convergence.
pub fn fit_ellipse(
    points: &[Vec2],
    circle: &Circle,
    cutoff: Real,
    params: &LmParams,
) -> Result<EllipseFit, SolveError> {
    params.validate()?;
    let (norm, p0, (jtj, jtd, meat, cost, n)) = ellipse_at_circle(points, circle, cutoff)?;
    let ssr_circle = cost * norm.scale * norm.scale;
    let problem = EllipseProblem {
        points,
        circle,
        cutoff,
        norm: &norm,
        kept: n,
    };
    let start = Evaluated {
        params: p0,
        normal: NormalEquations {
            jtj,
            jtr: jtd,
            cost,
        },
        extra: meat,
    };
    let (min, iterations) = lm::minimise(&problem, start, params)?;
    let (p, jtj, meat, cost) = (min.params, min.normal.jtj, min.extra, min.normal.cost);
    let (aa, m) = (p[2], sqrt(p[3] * p[3] + p[4] * p[4]));
    if !(aa > m) {
        return Err(SolveError::Degenerate);
    }
    let major = 1.0 / sqrt(aa - m);
    let minor = 1.0 / sqrt(aa + m);
    // Gradient of a + b in (A, B, C): ∂a/∂A = −a³/2, ∂a/∂m = a³/2, ∂b/∂A = ∂b/∂m = −b³/2,
    // ∂m/∂(B, C) = (B, C)/m (the m-derivative of a + b vanishes at m = 0).
    let (a3, b3) = (major * major * major, minor * minor * minor);
    let dm = 0.5 * (a3 - b3);
    let (mb, mc) = if m > 0.0 {
        (p[3] / m, p[4] / m)
    } else {
        (0.0, 0.0)
    };
    let grad = V5::new(0.0, 0.0, -0.5 * (a3 + b3), dm * mb, dm * mc);
    let inv = jtj.try_inverse().ok_or(SolveError::Degenerate)?;
    let dof = (n - 5).max(1) as Real;
    let gn = (grad.transpose() * inv * grad)[(0, 0)] * cost / dof;
    let sandwich = (grad.transpose() * (inv * meat * inv) * grad)[(0, 0)] * n as Real / dof;
    let sigma = sqrt(gn.max(sandwich).max(0.0)) * norm.scale;
    // Major axis direction: 1/r² is smallest there, i.e. cos 2(θ − φ) = −(B, C)/m.
    let angle = if m > 0.0 {
        0.5 * (-p[4]).atan2(-p[3])
    } else {
        0.0
    };
    let centre = norm.mean + Vec2::new(p[0], p[1]) * norm.scale;
    if !(sigma.is_finite() && centre.x.is_finite() && centre.y.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    Ok(EllipseFit {
        centre,
        semi_axes: (major * norm.scale, minor * norm.scale),
        angle,
        sigma_mean_diameter: sigma,
        ssr: cost * norm.scale * norm.scale,
        ssr_circle,
        points: n,
        iterations,
    })
}

#[cfg(test)]
// The casts to f64 are no-ops in f64 builds but needed with `--features f32`.
#[allow(clippy::unnecessary_cast)]
mod tests {
    extern crate std;
    use super::*;
    use crate::real::PI;
    use crate::solvers::circle::tests::Rng;
    use crate::solvers::circle::{fit_geometric, fit_hyper};

    /// The lit front of an ellipse (semi-axes `a ≥ b`, major axis at `phi`, centre `c`) seen
    /// from the origin, `n` samples of the parametric angle, plus isotropic noise `sigma`.
    fn ellipse_front(
        c: Vec2,
        (a, b): (Real, Real),
        phi: Real,
        n: usize,
        sigma: Real,
        rng: &mut Rng,
    ) -> std::vec::Vec<Vec2> {
        let (sp, cp) = phi.sin_cos();
        let (ea, eb) = (Vec2::new(cp, sp), Vec2::new(-sp, cp));
        let mut out = std::vec::Vec::new();
        for i in 0..n {
            let t = i as Real * 2.0 * PI / n as Real;
            let q = c + ea * (a * t.cos()) + eb * (b * t.sin());
            // Outward normal ∝ (cos t / a, sin t / b) in the ellipse frame; lit iff it faces
            // the source at the origin.
            let nrm = ea * (t.cos() / a) + eb * (t.sin() / b);
            if nrm.dot(&q) < 0.0 {
                let g = Vec2::new(rng.gauss() as Real, rng.gauss() as Real);
                out.push(q + g * sigma);
            }
        }
        out
    }

    #[test]
    fn ellipse_fit_recovers_front_arc_and_tells_round_from_elliptic() {
        let mut rng = Rng::new(77);
        let lm = LmParams {
            max_iterations: 1000,
            ..LmParams::default()
        };
        let start = |pts: &[Vec2]| fit_geometric(pts, fit_hyper(pts).unwrap(), &lm).unwrap();
        // Exact front arc (~half the ellipse): the polar model is exact, so only rounding and
        // the stopping rule remain (cost settled to 1e-9 relative ⇒ parameters to ~3e-5 of
        // the spread in the flattest direction): 1e-4 of the axes, plus 1e4·ε·|c| in f32.
        let tol = 1e-4 + 1e4 * Real::EPSILON * 1.6;
        for phi in [0.0, 0.25 * PI, 0.5 * PI] {
            let pts = ellipse_front(Vec2::new(0.02, 1.6), (0.2, 0.15), phi, 2000, 0.0, &mut rng);
            let c = start(&pts);
            let e = fit_ellipse(&pts, &c.circle, 1.0, &lm).unwrap();
            assert!((e.semi_axes.0 - 0.2).abs() < tol * 0.2, "{phi}: {e:?}");
            assert!((e.semi_axes.1 - 0.15).abs() < tol * 0.2, "{phi}: {e:?}");
            assert!(
                (e.centre - Vec2::new(0.02, 1.6)).norm() < tol,
                "{phi}: {e:?}"
            );
        }
        // Noisy (0.3 mm, about the point noise at 1.5 m): the mean diameter within 4 of its
        // stated σ, and the non-roundness test far above its threshold (F ≫ 30, e ≈ 0.14).
        let pts = ellipse_front(Vec2::new(0.0, 1.6), (0.2, 0.15), 0.0, 600, 3e-4, &mut rng);
        let c = start(&pts);
        let e = fit_ellipse(&pts, &c.circle, 5e-3, &lm).unwrap();
        assert!(
            (e.mean_diameter() - 0.35).abs() < 4.0 * e.sigma_mean_diameter,
            "{e:?}"
        );
        assert!(
            e.f_statistic() > 100.0 && (e.eccentricity() - 1.0 / 7.0).abs() < 0.03,
            "{e:?}"
        );
        // A round section with the same noise: the circle explains it; F follows F(2, n − 5),
        // whose 1e-6 tail is below 14 for n ≈ 300 (a false alarm here would be a real bug).
        let pts = ellipse_front(Vec2::new(0.0, 1.6), (0.17, 0.17), 0.0, 600, 3e-4, &mut rng);
        let c = start(&pts);
        let e = fit_ellipse(&pts, &c.circle, 5e-3, &lm).unwrap();
        assert!(e.f_statistic() < 14.0, "{e:?}");
    }

    #[test]
    fn ellipse_score_test_follows_the_f_distribution_and_the_fitted_f() {
        let mut rng = Rng::new(4242);
        let lm = LmParams {
            max_iterations: 1000,
            ..LmParams::default()
        };
        // Round sections, independent noise: the score statistic is F(2, n − 5) under the
        // null, mean m/(m − 2) ≈ 1 and standard deviation ≈ 1, so the mean of 100 trials is
        // 1 ± 0.1 (0.35 = 3.5 standard errors). The fitted F agrees with it closely where
        // the ellipse model is nearly linear (near the circle).
        let trials = 100;
        let mut sum = 0.0;
        for _ in 0..trials {
            let pts = ellipse_front(Vec2::new(0.0, 1.6), (0.17, 0.17), 0.0, 600, 3e-4, &mut rng);
            let c = fit_geometric(&pts, fit_hyper(&pts).unwrap(), &lm).unwrap();
            let score = ellipse_score_f(&pts, &c.circle, 5e-3).unwrap();
            let fitted = fit_ellipse(&pts, &c.circle, 5e-3, &lm)
                .unwrap()
                .f_statistic();
            assert!(
                (fitted - score).abs() <= 0.1 * score + 0.05,
                "{score} {fitted}"
            );
            sum += score;
        }
        let mean = sum / trials as Real;
        assert!((mean - 1.0).abs() < 0.35, "mean score F {mean}");
        // An elliptic section (axes 0.2 × 0.15 m): far above any screening level.
        let pts = ellipse_front(Vec2::new(0.0, 1.6), (0.2, 0.15), 0.0, 600, 3e-4, &mut rng);
        let c = fit_geometric(&pts, fit_hyper(&pts).unwrap(), &lm).unwrap();
        assert!(ellipse_score_f(&pts, &c.circle, 5e-3).unwrap() > 100.0);
        assert_eq!(
            ellipse_score_f(&pts[..7], &c.circle, 5e-3),
            Err(SolveError::TooFewPoints)
        );
        assert_eq!(
            ellipse_score_f(&pts, &c.circle, 0.0),
            Err(SolveError::InvalidParameter)
        );
    }
}
