//! The whole-arc circle fit (`docs/cylinder.md`, "Whole-arc fit"): every point weighted by
//! its own σ, robust against real outliers (branches, background) without trimming the arc's
//! noisy ends, with the radius σ from the points' σ, the data's χ² and the correlation of the
//! residuals along the stripe (`docs/error-model.md`, "A point's own σ" and "Correlation
//! along the stripe").

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{self, sqrt, Mat3, Real, Vec2, Vec3};
use crate::solvers::correlation::autocorrelation;

use super::pull::{expected_bias, FittedArc};
use super::{
    accumulate, finish, finish_with, lm, normalised_start, tukey, Circle, CircleFit, Normalisation,
};
use super::{RobustParams, SolveError};

/// Floor of a point's orthogonal-residual σ as a fraction of its σ along its noise direction
/// (`docs/cylinder.md`, "Whole-arc fit"): near the silhouette the noise direction runs along
/// the circle and `nᵢ·ĝᵢ → 0`; the floor keeps those points' weight at most `1/FLOOR²` = 25
/// times what their own σ gives, so that what the noise model does not describe there (bark
/// relief, the stripe's fade) cannot dominate the fit.
pub const LATERAL_FLOOR: Real = 0.2;

pub use crate::solvers::correlation::MAX_CORRELATION_LAG;

/// Convergence of [`fit_weighted`] in the data's own units (`docs/cylinder.md`, "Whole-arc
/// fit", convergence): the cost `Σwᵢdᵢ²` is a χ² (weights `1/σ²`), so an LM step that lowers it
/// by less than this, or a reweighting round that moves the circle by `Δθ` with
/// `ΔθᵀJᵀWJΔθ` below it, moves the circle by less than 1 % of its model σ — instead of
/// iterating to the last bits of the arithmetic (the other fits' step tolerance).
pub const SETTLED_CHI2: Real = 1e-4;

/// Result of [`fit_weighted`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeightedFit {
    /// The circle, its residual RMS (of the points with weight, unweighted), iterations and
    /// inliers ([`CircleFit::covariance`] is the weighted one scaled by the reduced χ²).
    pub fit: CircleFit,
    /// Radius σ if the points' σ are right and independent: `√[(JᵀWJ)⁻¹]_rr`.
    pub model_sigma_radius: Real,
    /// Radius σ from the points' own residuals with the fit's weights, the sandwich
    /// `√[A⁻¹(Σwᵢ²dᵢ²JᵢJᵢᵀ)A⁻¹]_rr` (`A = JᵀWJ`): the fit's spread when the points' errors are
    /// independent, whether or not their σ model is right (`docs/error-model.md` §6, (E6)).
    pub sandwich_sigma_radius: Real,
    /// Reduced χ² of the normalised residuals `dᵢ/σᵢ` of the inliers.
    pub chi2_dof: Real,
    /// Correlation length of the normalised residuals along the curve (points):
    /// `L = 1 + 2 Σ_k ρ_k`, summed while `ρ_k > 0` up to [`MAX_CORRELATION_LAG`].
    pub correlation_length: Real,
    /// Radius σ: `model_sigma_radius · √max(χ²_ν·L, 1)` (`docs/error-model.md`,
    /// "Correlation along the stripe").
    pub sigma_radius: Real,
    /// Expected bias of `fit.circle.radius` under the points' own noise along their noise
    /// directions, to second order (`docs/error-model.md` §5e, "The pull to second order"):
    /// `E[r̂] − r`, evaluated at the fitted circle with the residuals' own variance and autocorrelation;
    /// 0 when it cannot be evaluated or was not asked for ([`Pull::Skip`]). The fit's radius
    /// is not corrected here: subtracting it is the caller's choice.
    pub radius_pull: Real,
}

/// Whether [`fit_weighted`] evaluates [`WeightedFit::radius_pull`]: the second-order expansion
/// costs as much as two rounds of the fit (`docs/performance.md`), and a caller that only
/// takes the fit's σ (the two-plane solve's projected sections) has no use for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pull {
    /// Evaluate the expected bias of the radius.
    Evaluate,
    /// Leave it at 0.
    Skip,
}

/// σ of point `i`'s orthogonal residual (normalised units) about a circle centred at `centre`.
fn residual_sigma(q: Vec2, centre: Vec2, sigma: Real, direction: Vec2) -> Real {
    let d = q - centre;
    let len = real::norm(&d);
    let along = if len > 0.0 {
        (d / len).dot(&direction)
    } else {
        1.0
    };
    sigma * sqrt(along * along + LATERAL_FLOOR * LATERAL_FLOOR)
}

/// Reals of scratch [`fit_weighted`] needs per point: each point's σ and unit noise direction
/// (computed once per fit), and one value per point for the robust scale's median and then the
/// round's weights.
pub const WEIGHTED_SCRATCH_PER_POINT: usize = 4;

/// Whole-arc weighted, robust geometric circle fit.
///
/// Point `i` has the 1σ noise vector `noise(i)` (same units as the points): σᵢ along the unit
/// direction ĝᵢ; its orthogonal residual `dᵢ` then has σ `σᵢ·√((nᵢ·ĝᵢ)² + f²)` (`f` =
/// [`LATERAL_FLOOR`]). Iteratively reweighted least squares: weights `tukey(uᵢ/(c·s))/σ_{dᵢ}²`
/// with `uᵢ = dᵢ/σ_{dᵢ}`, `s = max(1.4826·median|uᵢ|, 1)` (the data are not taken to be
/// quieter than their own σ), `c` = `params.tuning`, frozen at the previous round's circle,
/// LM ([`super::super::lm`]) inside each round. `params.min_scale` is not used (the σ's set
/// the scale). `scratch` (at least [`WEIGHTED_SCRATCH_PER_POINT`]` × points.len()`) holds
/// each point's σ and direction, evaluated once (`noise` is called once per point), and the
/// `|uᵢ|` for the median, then the round's weights: frozen within a round, each LM step reads
/// them instead of evaluating the noise model again (`docs/performance.md`).
///
/// Points with a non-positive or non-finite σ are left out. `pull` says whether the radius's
/// expected bias is evaluated. Errors as [`super::fit_robust`].
pub fn fit_weighted(
    points: &[Vec2],
    noise: impl Fn(usize) -> Vec2,
    initial: Circle,
    params: &RobustParams,
    pull: Pull,
    scratch: &mut [Real],
) -> Result<WeightedFit, SolveError> {
    weighted(points, noise, initial, params, pull, true, scratch)
}

/// [`fit_weighted`]'s assessment of a given `circle` without moving it: the robust scale and
/// weights about `circle`, its residual RMS, reduced χ², correlation length and radius σ, as
/// if a fit had converged there (`iterations` 0, no pull). For a circle fixed by other data
/// (the two-plane cylinder's section, `docs/cylinder.md`, "Data-driven σ of the two-plane
/// result"), where a fit of its own would cost as much and move the circle by less than its σ.
pub fn weighted_at(
    points: &[Vec2],
    noise: impl Fn(usize) -> Vec2,
    circle: Circle,
    params: &RobustParams,
    scratch: &mut [Real],
) -> Result<WeightedFit, SolveError> {
    weighted(points, noise, circle, params, Pull::Skip, false, scratch)
}

/// [`fit_weighted`] (`iterate`) or [`weighted_at`] (not).
fn weighted(
    points: &[Vec2],
    noise: impl Fn(usize) -> Vec2,
    initial: Circle,
    params: &RobustParams,
    pull: Pull,
    iterate: bool,
    scratch: &mut [Real],
) -> Result<WeightedFit, SolveError> {
    params.lm.validate()?;
    if !(params.tuning.is_finite() && params.tuning > 0.0) || params.max_rounds == 0 {
        return Err(SolveError::InvalidParameter);
    }
    let norm = Normalisation::of(points, 3)?;
    let n = points.len();
    let scratch = scratch
        .get_mut(..WEIGHTED_SCRATCH_PER_POINT * n)
        .ok_or(SolveError::ScratchTooSmall)?;
    let (sigmas, rest) = scratch.split_at_mut(n);
    let (dir_x, rest) = rest.split_at_mut(n);
    let (dir_y, buf) = rest.split_at_mut(n);
    let inv_scale = 1.0 / norm.scale;
    // Each point's σ (normalised units; infinite: no weight) and unit noise direction.
    for (i, ((s, dx), dy)) in sigmas
        .iter_mut()
        .zip(dir_x.iter_mut())
        .zip(dir_y.iter_mut())
        .enumerate()
    {
        let g = noise(i);
        let len = real::norm(&g);
        let sigma = len * inv_scale;
        *s = if sigma > 0.0 && sigma.is_finite() {
            sigma
        } else {
            Real::INFINITY
        };
        let d = if len > 0.0 { g / len } else { Vec2::zeros() };
        (*dx, *dy) = (d.x, d.y);
    }
    let points_noise = PointNoise {
        sigmas,
        dir_x,
        dir_y,
    };
    let mut theta = normalised_start(&initial, &norm)?;
    let mut last_it = 0;
    let mut cs = params.tuning;
    for round in 0..=params.max_rounds {
        let centre = Vec2::new(theta.x, theta.y);
        let r = theta.z;
        let mut k = 0;
        for (i, p) in points.iter().enumerate() {
            let q = norm.apply(*p);
            let s = points_noise.residual_sigma(i, q, centre);
            if s.is_finite() {
                buf[k] = ((real::norm(&(q - centre)) - r) / s).abs();
                k += 1;
            }
        }
        if k < 3 {
            return Err(SolveError::TooFewPoints);
        }
        let mid = k / 2;
        let (_, median, _) = buf[..k].select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        let scale = (1.4826 * *median).max(1.0);
        if !scale.is_finite() {
            return Err(SolveError::Degenerate);
        }
        cs = params.tuning * scale;
        if !iterate {
            break;
        }
        points_noise.weights(points, &norm, theta, cs, buf);
        let weights: &[Real] = buf;
        let weight = |i: usize, _: Vec2| weights.get(i).copied().unwrap_or(0.0);
        let (next, it, jtj) = lm(points, &norm, theta, &params.lm, &weight, SETTLED_CHI2)?;
        last_it = it;
        let delta = next - theta;
        let change = real::norm(&delta);
        theta = next;
        if change <= params.lm.tolerance * (1.0 + real::norm(&theta))
            || delta.dot(&(jtj * delta)) < SETTLED_CHI2
        {
            break;
        }
        // The last allowed round must have settled to within the noise.
        if round == params.max_rounds && change > 1e-3 * theta.z {
            return Err(SolveError::NotConverged);
        }
    }
    let centre = Vec2::new(theta.x, theta.y);
    let r = theta.z;
    points_noise.weights(points, &norm, theta, cs, buf);
    let weights: &[Real] = buf;
    let weight = |i: usize, _: Vec2| weights.get(i).copied().unwrap_or(0.0);
    let sums = accumulate(points, &norm, theta, &weight);
    let (jtj, _, chi2, _, used) = sums;
    // With `r > 0` (the usual case) `finish` would form the same sums again.
    let mut fit = if theta.z > 0.0 {
        finish_with(&norm, theta, last_it, sums)?
    } else {
        finish(points, &norm, theta, last_it, &weight)?
    };
    // One pass over the inliers: their unweighted RMS (metres), as the unweighted fits
    // report, and the sandwich's B = Σ wᵢ²dᵢ²JᵢJᵢᵀ: the spread the points' own residuals give
    // with these weights, whatever their σ model (`docs/error-model.md` §6, (E6)).
    let (mut ss, mut count) = (0.0, 0usize);
    let mut meat = Mat3::zeros();
    for (p, &w) in points.iter().zip(weights) {
        if !(w > 0.0) {
            continue;
        }
        let q = norm.apply(*p) - centre;
        let rho = real::norm(&q);
        let d = rho - r;
        ss += d * d;
        count += 1;
        if rho > 0.0 {
            let j = Vec3::new(-q.x / rho, -q.y / rho, -1.0);
            meat += j * j.transpose() * ((w * d) * (w * d));
        }
    }
    fit.rms_residual = if count > 0 {
        sqrt(ss / count as Real) * norm.scale
    } else {
        0.0
    };
    let dof = used.saturating_sub(3).max(1) as Real;
    let chi2_dof = chi2 / dof;
    let inv = jtj.try_inverse().ok_or(SolveError::Degenerate)?;
    let model = sqrt(inv[(2, 2)].max(0.0)) * norm.scale;
    // The sandwich A⁻¹BA⁻¹.
    let sandwich = sqrt((inv * meat * inv)[(2, 2)].max(0.0)) * norm.scale;
    fit.covariance = inv * (chi2_dof * norm.scale * norm.scale);
    fit.std_dev = Vec3::new(
        sqrt(fit.covariance[(0, 0)].max(0.0)),
        sqrt(fit.covariance[(1, 1)].max(0.0)),
        sqrt(fit.covariance[(2, 2)].max(0.0)),
    );
    let mut rho = [0.0; MAX_CORRELATION_LAG + 1];
    let correlation = correlation_length(points, &norm, theta, buf, &mut rho);
    let radius_pull = match pull {
        Pull::Skip => 0.0,
        Pull::Evaluate => {
            // The weights again (the correlation overwrote them) for the pull's expansion.
            points_noise.weights(points, &norm, theta, cs, buf);
            let arc = FittedArc {
                points,
                norm: &norm,
                theta,
                sigmas: points_noise.sigmas,
                dir_x: points_noise.dir_x,
                dir_y: points_noise.dir_y,
                weights: buf,
                rho: &rho[..correlation.1],
                lateral_floor: LATERAL_FLOOR,
            };
            expected_bias(&arc).map_or(0.0, |b| b.z * norm.scale)
        }
    };
    let correlation = correlation.0;
    let factor = (chi2_dof * correlation).max(1.0);
    let sigma_radius = model * sqrt(factor);
    if !(sigma_radius.is_finite() && fit.circle.radius.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    Ok(WeightedFit {
        fit,
        model_sigma_radius: model,
        sandwich_sigma_radius: sandwich,
        chi2_dof,
        correlation_length: correlation,
        sigma_radius,
        radius_pull,
    })
}

/// Each point's σ (normalised units) and unit noise direction, as [`fit_weighted`] evaluates
/// them once per fit.
struct PointNoise<'a> {
    sigmas: &'a [Real],
    dir_x: &'a [Real],
    dir_y: &'a [Real],
}

impl PointNoise<'_> {
    /// σ of point `i`'s orthogonal residual about a circle centred at `centre` (`q` the
    /// point, normalised); infinite for a point without σ.
    fn residual_sigma(&self, i: usize, q: Vec2, centre: Vec2) -> Real {
        match (self.sigmas.get(i), self.dir_x.get(i), self.dir_y.get(i)) {
            (Some(s), Some(x), Some(y)) => residual_sigma(q, centre, *s, Vec2::new(*x, *y)),
            _ => Real::INFINITY,
        }
    }

    /// The weights `tukey(dᵢ/(σ_{dᵢ}·cs))/σ_{dᵢ}²` about the circle `theta` (normalised) into
    /// `out[i]`; 0 for a point without σ.
    fn weights(
        &self,
        points: &[Vec2],
        norm: &Normalisation,
        theta: Vec3,
        cs: Real,
        out: &mut [Real],
    ) {
        let centre = Vec2::new(theta.x, theta.y);
        for (i, (p, w)) in points.iter().zip(out.iter_mut()).enumerate() {
            let q = norm.apply(*p);
            let s = self.residual_sigma(i, q, centre);
            *w = if s.is_finite() {
                tukey((real::norm(&(q - centre)) - theta.z) / (s * cs)) / (s * s)
            } else {
                0.0
            };
        }
    }
}

/// Correlation length of the inliers' normalised residuals `uᵢ = dᵢ·√wᵢ` in curve order
/// (`docs/error-model.md`, "Correlation along the stripe"): `1 + 2 Σ_{k≥1} ρ_k` while
/// `ρ_k > 0`, `k ≤` [`MAX_CORRELATION_LAG`] and `k < n/4`; at least 1; with the number of
/// `ρ_k` kept in `rho` (`rho[0] = 1`). `buf` holds the weights `wᵢ` on entry and is
/// overwritten with the `uᵢ` (the `n`-th inlier's `u` goes to `buf[n]`, `n ≤ i`: each weight
/// is read before its entry is reused).
fn correlation_length(
    points: &[Vec2],
    norm: &Normalisation,
    theta: Vec3,
    buf: &mut [Real],
    rho: &mut [Real; MAX_CORRELATION_LAG + 1],
) -> (Real, usize) {
    let centre = Vec2::new(theta.x, theta.y);
    let mut n = 0;
    for (i, p) in points.iter().enumerate() {
        let Some(&w) = buf.get(i) else { break };
        if w > 0.0 {
            let q = norm.apply(*p);
            buf[n] = (real::norm(&(q - centre)) - theta.z) * sqrt(w);
            n += 1;
        }
    }
    let kept = autocorrelation(&buf[..n], rho);
    // Summed in lag order, as `solvers::correlation::correlation_length`.
    let length = rho[1..kept].iter().fold(1.0, |l, r| l + 2.0 * r);
    (length, kept)
}

/// Radius σ of a circle fit with per-point σ along directions, as [`fit_weighted`] weighs
/// them, for points with correlated noise of correlation length `correlation` points
/// (`docs/error-model.md`, "Correlation along the stripe"): `√([(JᵀWJ)⁻¹]_rr · L)`. For the
/// error model's predictions, where no data exist.
pub fn weighted_radius_sigma<I: Iterator<Item = (Vec2, Real, Vec2)>>(
    c: &Circle,
    points: I,
    correlation: Real,
) -> Real {
    let mut a = Mat3::zeros();
    for (q, sigma, direction) in points {
        let d = q - c.centre;
        let len = real::norm(&d);
        if !(len > 0.0 && sigma > 0.0) {
            continue;
        }
        let nn = d / len;
        let s = residual_sigma(q, c.centre, sigma, direction);
        let j = Vec3::new(-nn.x, -nn.y, -1.0);
        a += j * j.transpose() / (s * s);
    }
    match a.try_inverse() {
        Some(inv) => sqrt(inv[(2, 2)].max(0.0) * correlation.max(1.0)),
        None => Real::INFINITY,
    }
}
