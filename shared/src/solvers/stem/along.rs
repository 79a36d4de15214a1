//! The circle that explains each point by a move along its own noise direction
//! (`docs/cylinder.md`, "Residuals along the noise direction"; `docs/error-model.md` §5e).
//!
//! A stripe point is wrong only along one line: a row error moves its 3-D point along the
//! displacement field's direction `gᵢ` (nearly the viewing ray far away). The weighted fit
//! measures each point's distance to the circle along the circle's *normal* and divides by
//! `σᵢ` projected on it. Where the arc turns away from the camera, `gᵢ` is nearly tangent to
//! the circle; a point moved along it by `δ` lands outside the circle by `δ²/2R`, which the
//! normal residual reads as a real (and, weighted by the small projected σ, heavy) outward
//! miss. The fit then pulls the circle in: at 2.5–3 m, where `σ_z` reaches 10 mm a point, it
//! reads stems 2–9 % small (Monte Carlo and the tuning seeds, `docs/error-model.md` §5e).
//! Measuring the residual *along* `gᵢ` — how far the point must slide along its own line to
//! reach the circle — is the likelihood of that one-dimensional error, and has no such pull.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{self, sqrt, Real, Vec2, Vec3};
use nalgebra::{SMatrix, SVector};

use crate::solvers::circle::weighted::LATERAL_FLOOR;
use crate::solvers::circle::{self, Circle};
use crate::solvers::lm::{minimise, Evaluated, LeastSquares, LmParams, NormalEquations};
use crate::solvers::SolveError;

/// Robust rounds (Tukey weights recomputed from the residuals of the round before).
const ROUNDS: usize = 3;

/// Residual of the point `p` (unit noise direction `g`, 1σ `s`) against the circle
/// `(c, r)`: `(along, miss)` in units of `s` and `∂/∂(cₓ, c_y, r)` of each. `along` is the
/// signed slide along `g` to the nearest crossing with the circle; where the line misses the
/// circle, the slide to its closest approach, and `miss` (the gap left there, over the
/// lateral σ `LATERAL_FLOOR·s`) carries the rest — both are continuous where the line
/// grazes the circle.
fn residual(p: Vec2, g: Vec2, s: Real, c: Vec2, r: Real) -> (Real, Real, Vec3, Vec3) {
    let d = p - c;
    let b = d.dot(&g);
    let q = d.dot(&d) - b * b; // squared distance of the line from the centre
    let disc = r * r - q;
    if disc >= 0.0 {
        let root = sqrt(disc);
        // Nearest crossing: t = −b ± √disc with the sign that keeps |t| small.
        let sign = if b >= 0.0 { 1.0 } else { -1.0 };
        let t = -b + sign * root;
        // F(t) = |d + t·g|² − r² = 0: dt/dθ = −F_θ/F_t with F_t = 2(b + t) = ±2√disc,
        // floored where the line grazes (the lateral σ bounds what a graze can tell).
        let ft = sign * root.max(LATERAL_FLOOR * s);
        let x = d + g * t; // crossing point relative to the centre
        let dt = Vec3::new(x.x / ft, x.y / ft, r / ft);
        (t / s, 0.0, dt / s, Vec3::zeros())
    } else {
        let t = -b;
        let dist = sqrt(q.max(0.0));
        let miss = dist - r;
        // ∂t/∂c = g; ∂dist/∂c = −(d − b·g)/dist; ∂miss/∂r = −1.
        let dt = Vec3::new(g.x, g.y, 0.0);
        let perp = d - g * b;
        let dm = if dist > 0.0 {
            Vec3::new(-perp.x / dist, -perp.y / dist, -1.0)
        } else {
            Vec3::new(0.0, 0.0, -1.0)
        };
        let lateral = LATERAL_FLOOR * s;
        (t / s, miss / lateral, dt / s, dm / lateral)
    }
}

/// The least-squares problem in the start circle's frame (centre at the origin, radius 1).
struct AlongFit<'a, N: Fn(usize) -> Vec2> {
    points: &'a [Vec2],
    noise: &'a N,
    origin: Vec2,
    scale: Real,
    /// Tukey cut-off (in σ) of the round, `∞` for none.
    cutoff: Real,
    /// Circle of the round's weights (scaled frame).
    weights_at: Vec3,
}

impl<N: Fn(usize) -> Vec2> AlongFit<'_, N> {
    /// Point `i` in the scaled frame, its unit noise direction and σ (`None`: no σ).
    fn point(&self, i: usize) -> Option<(Vec2, Vec2, Real)> {
        let g = (self.noise)(i);
        let s = real::norm(&g);
        if !(s > 0.0 && s.is_finite()) {
            return None;
        }
        Some((
            (self.points[i] - self.origin) / self.scale,
            g / s,
            s / self.scale,
        ))
    }

    fn weight(&self, p: Vec2, g: Vec2, s: Real) -> Real {
        if !self.cutoff.is_finite() {
            return 1.0;
        }
        let w = self.weights_at;
        let (a, m, _, _) = residual(p, g, s, Vec2::new(w.x, w.y), w.z);
        circle::tukey(a.hypot(m) / self.cutoff)
    }
}

impl<N: Fn(usize) -> Vec2> LeastSquares<3> for AlongFit<'_, N> {
    type Params = Vec3;
    type Extra = usize;

    fn evaluate(&self, th: &Vec3) -> Result<(NormalEquations<3>, usize), SolveError> {
        if !(th.z > 0.0) {
            return Err(SolveError::Degenerate);
        }
        let (mut jtj, mut jtr, mut cost, mut used) = (
            SMatrix::<Real, 3, 3>::zeros(),
            SVector::<Real, 3>::zeros(),
            0.0,
            0,
        );
        let c = Vec2::new(th.x, th.y);
        for i in 0..self.points.len() {
            let Some((p, g, s)) = self.point(i) else {
                continue;
            };
            let w = self.weight(p, g, s);
            if !(w > 0.0) {
                continue;
            }
            let (a, m, ja, jm) = residual(p, g, s, c, th.z);
            jtj += (ja * ja.transpose() + jm * jm.transpose()) * w;
            jtr += (ja * a + jm * m) * w;
            cost += (a * a + m * m) * w;
            used += 1;
        }
        if used < 4 || !cost.is_finite() {
            return Err(SolveError::TooFewPoints);
        }
        Ok((NormalEquations { jtj, jtr, cost }, used))
    }

    fn step(&self, th: &Vec3, delta: &SVector<Real, 3>) -> Vec3 {
        th + delta
    }

    fn step_scale(&self, th: &Vec3) -> Real {
        1.0 + real::norm(th)
    }
}

/// The circle whose residuals run along each point's noise direction (`noise(i)`: 1σ
/// vector of point `i`), robust by Tukey weights at `tuning` times the residuals' own scale
/// (floored at 1σ), started from `start` (the weighted fit). Returns the circle, its model
/// radius σ (from the weighted normal equations, before any inflation) and the points used.
/// An error when the fit does not converge or too few points carry a σ.
pub(super) fn fit_along(
    points: &[Vec2],
    noise: &impl Fn(usize) -> Vec2,
    start: Circle,
    tuning: Real,
    lm: &LmParams,
    scratch: &mut [Real],
) -> Result<(Circle, Real, usize), SolveError> {
    if !(start.radius > 0.0 && start.radius.is_finite()) || !(tuning > 0.0) {
        return Err(SolveError::InvalidParameter);
    }
    let buf = scratch
        .get_mut(..points.len())
        .ok_or(SolveError::ScratchTooSmall)?;
    let mut problem = AlongFit {
        points,
        noise,
        origin: start.centre,
        scale: start.radius,
        cutoff: Real::INFINITY,
        weights_at: Vec3::new(0.0, 0.0, 1.0),
    };
    let mut th = Vec3::new(0.0, 0.0, 1.0);
    let mut used = 0;
    for _ in 0..ROUNDS {
        // Robust scale of the residuals at the current circle (MAD, floored at 1σ).
        let c = Vec2::new(th.x, th.y);
        let mut k = 0;
        for i in 0..points.len() {
            if let Some((p, g, s)) = problem.point(i) {
                let (a, m, _, _) = residual(p, g, s, c, th.z);
                buf[k] = a.hypot(m);
                k += 1;
            }
        }
        if k < 4 {
            return Err(SolveError::TooFewPoints);
        }
        let (_, median, _) = buf[..k].select_nth_unstable_by(k / 2, |a, b| a.total_cmp(b));
        let scale = (1.4826 * *median).max(1.0);
        problem.cutoff = tuning * scale;
        problem.weights_at = th;
        let start = Evaluated::at(&problem, th)?;
        let (min, _) = minimise(&problem, start, lm)?;
        th = min.params;
        used = min.extra;
    }
    let end = Evaluated::at(&problem, th)?;
    let inv = end.normal.jtj.try_inverse().ok_or(SolveError::Degenerate)?;
    let model_sigma = sqrt(inv[(2, 2)].max(0.0)) * problem.scale;
    let circle = Circle {
        centre: problem.origin + Vec2::new(th.x, th.y) * problem.scale,
        radius: th.z * problem.scale,
    };
    if !(circle.radius.is_finite() && model_sigma.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    Ok((circle, model_sigma, used))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points of a circle seen from the origin (the camera), each moved along its viewing ray
    /// by a deterministic ±σ pattern: the along-ray fit recovers the radius where the
    /// normal-residual pull would read it small.
    #[test]
    fn recovers_a_far_arc_with_noise_along_the_rays() {
        let (c, r) = (Vec2::new(0.0, 2.8), 0.08);
        let half = (r / real::norm(&c)).acos();
        let n = 60;
        let sigma = 0.011;
        let mut pts = [Vec2::zeros(); 60];
        let mut dirs = [Vec2::zeros(); 60];
        for i in 0..n {
            let a = -half + 2.0 * half * i as Real / (n - 1) as Real;
            let p = c + Vec2::new(a.sin(), -a.cos()) * r;
            let g = p / real::norm(&p);
            // Zero-mean ±1σ pattern uncorrelated with the arc's shape.
            let e = if (i * 7) % 3 == 0 { 1.0 } else { -0.5 } * sigma;
            pts[i] = p + g * e;
            dirs[i] = g * sigma;
        }
        let noise = |i: usize| dirs[i];
        let start = Circle {
            centre: c + Vec2::new(0.0, -0.01),
            radius: r * 0.9,
        };
        let mut scratch = [0.0 as Real; 60];
        let (fit, s, used) = fit_along(
            &pts,
            &noise,
            start,
            4.685,
            &LmParams::default(),
            &mut scratch,
        )
        .unwrap();
        assert_eq!(used, n);
        assert!(
            (fit.radius - r).abs() < 0.1 * r,
            "{} against {r}",
            fit.radius
        );
        assert!(s > 0.0 && s < r);
    }

    /// Exact points give the exact circle, and a point far off its line is rejected.
    #[test]
    fn exact_points_and_an_outlier() {
        let (c, r) = (Vec2::new(0.1, 1.5), 0.2);
        let mut pts = [Vec2::zeros(); 40];
        let mut dirs = [Vec2::zeros(); 40];
        for (i, (p, d)) in pts.iter_mut().zip(dirs.iter_mut()).enumerate() {
            let a = -1.0 + 2.0 * i as Real / 39.0;
            *p = c + Vec2::new(a.sin(), -a.cos()) * r;
            *d = *p / real::norm(p) * 1e-3;
        }
        pts[20] += dirs[20] * 80.0;
        let noise = |i: usize| dirs[i];
        let start = Circle {
            centre: c + Vec2::new(0.01, 0.02),
            radius: r * 1.1,
        };
        let mut scratch = [0.0 as Real; 40];
        let (fit, _, used) = fit_along(
            &pts,
            &noise,
            start,
            4.685,
            &LmParams::default(),
            &mut scratch,
        )
        .unwrap();
        assert!((fit.radius - r).abs() < 1e-4, "{}", fit.radius);
        assert!(real::norm(&(fit.centre - c)) < 1e-4);
        assert_eq!(used, 39);
    }

    #[test]
    fn bad_start_is_an_error() {
        let pts = [Vec2::zeros(); 4];
        let noise = |_: usize| Vec2::new(0.0, 1.0);
        let start = Circle {
            centre: Vec2::zeros(),
            radius: 0.0,
        };
        let mut scratch = [0.0 as Real; 4];
        assert!(fit_along(
            &pts,
            &noise,
            start,
            4.685,
            &LmParams::default(),
            &mut scratch
        )
        .is_err());
    }
}
