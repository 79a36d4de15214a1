//! The whole-arc cylinder fit (`docs/cylinder.md`, "Whole-arc fit"): the two-plane fit with
//! every point weighted by its own σ and robust against real outliers, as the one-plane
//! [`crate::solvers::circle::fit_weighted`].

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec3};

use super::{
    cyl_accumulate, cyl_delta, normalise, CylState, Cylinder, CylinderFit, CylinderProblem,
    Normalised,
};
use crate::solvers::circle::weighted::{LATERAL_FLOOR, SETTLED_CHI2};
use crate::solvers::circle::RobustParams;
use crate::solvers::lm::{self, Evaluated};
use crate::solvers::SolveError;

/// Most curves whose weights [`fit_cylinder_weighted`] keeps in its table (the planes).
const MAX_CURVES: usize = crate::calibration::MAX_PLANES;

/// Reals of `weights` [`fit_cylinder_weighted`] uses per point to keep its tables: the
/// residual, its σ (the round's weight), the point's σ and its unit noise direction.
pub const NOISE_PER_POINT: usize = 6;

/// Result of [`fit_cylinder_weighted`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeightedCylinderFit {
    /// The fit; `sigma_radius` and `sigma_axis` from `(JᵀWJ)⁻¹·max(χ²_ν, 1)`, `rms_residual`
    /// of the points with weight (unweighted), `points` those points.
    pub fit: CylinderFit,
    /// Reduced χ² of the normalised residuals of the points with weight.
    pub chi2_dof: Real,
}

/// σ (normalised units) of the residual of the point `y` about the cylinder `st`, whose noise
/// is `sigma` along the unit `direction`: `σ·√((ρ̂·ĝ)² + f²)` (`ρ̂` the radial direction from
/// the axis, `f` = [`LATERAL_FLOOR`]).
fn residual(st: &CylState, y: Vec3, sigma: Real, direction: Vec3) -> (Real, Real) {
    let w = y - st.p;
    let q = w - st.u * w.dot(&st.u);
    let rho = norm(&q);
    let along = if rho > 0.0 {
        (q / rho).dot(&direction)
    } else {
        1.0
    };
    (
        rho - st.r,
        sigma * sqrt(along * along + LATERAL_FLOOR * LATERAL_FLOOR),
    )
}

/// Tukey's biweight `(1 − u²)²` for `|u| < 1`.
fn tukey(u: Real) -> Real {
    if u.abs() < 1.0 {
        let t = 1.0 - u * u;
        t * t
    } else {
        0.0
    }
}

/// Whole-arc weighted, robust cylinder fit: point `i` of curve `k` has the 1σ noise vector
/// `noise(k, i)` (metres). Iteratively reweighted least squares with weights
/// `tukey(uᵢ/(c·s))/σ_{dᵢ}²`, `uᵢ = dᵢ/σ_{dᵢ}` frozen at the previous round's cylinder, the
/// scale `s = max(1.2533·mean|uᵢ|, 1)` over the previous round's points with weight (no
/// scratch for a median over all curves; the first round's mean includes the outliers, which
/// only makes it more lenient), `c` = `params.tuning`; LM inside each round. Start from
/// [`super::initial_cylinder`]. Converged in the data's own units, as the one-plane fit
/// ([`SETTLED_CHI2`]: the cost is a χ²): an LM step lowering it by less, or a round moving the
/// cylinder by `δ` with `δᵀJᵀWJδ` below it, moves the cylinder by less than 1 % of its model
/// σ. Errors as [`super::fit_cylinder`].
///
/// The weights are frozen within a round, so they are computed once per round into
/// `weights` (one value per point of all curves, in order) and each LM step reads them — as
/// the one-plane fit does (`docs/performance.md`): re-deriving each point's noise direction
/// at every step was half of a tilted stem's solver on the device. Each point's noise is
/// evaluated once per fit into `weights` too. With `weights` shorter than
/// [`NOISE_PER_POINT`] per point, each step computes them again (the same numbers).
pub fn fit_cylinder_weighted(
    curves: &[&[Vec3]],
    noise: impl Fn(usize, usize) -> Vec3,
    initial: Cylinder,
    params: &RobustParams,
    weights: &mut [Real],
) -> Result<WeightedCylinderFit, SolveError> {
    params.lm.validate()?;
    if !(params.tuning.is_finite() && params.tuning > 0.0) || params.max_rounds == 0 {
        return Err(SolveError::InvalidParameter);
    }
    let Normalised {
        mean, scale, start, ..
    } = normalise(curves, initial)?;
    let unit_noise = |k: usize, i: usize| {
        let g = noise(k, i) / scale;
        let s = norm(&g);
        if s > 0.0 && s.is_finite() {
            (s, g / s)
        } else {
            (Real::INFINITY, Vec3::zeros())
        }
    };
    // Where each curve's weights start in `weights`, if they all fit with room for each
    // point's residual and its σ beside them (`weights[total..2·total]`: the scale pass keeps
    // `d` and `σ_d` for the round's weights, which are formed from the same two numbers) and
    // for each point's σ and unit noise direction (`weights[2·total..6·total]`, evaluated once
    // per fit: the noise model's direction was a fifth of a tilted stem's solve when every
    // round evaluated it again).
    let total: usize = curves.iter().map(|c| c.len()).sum();
    let offsets =
        (NOISE_PER_POINT * total <= weights.len() && curves.len() <= MAX_CURVES).then(|| {
            let mut offsets = [0usize; MAX_CURVES];
            let mut at = 0;
            for (o, c) in offsets.iter_mut().zip(curves) {
                *o = at;
                at += c.len();
            }
            offsets
        });
    let (weights, noise_table) = weights.split_at_mut((2 * total).min(weights.len()));
    if offsets.is_some() {
        let mut cells = noise_table.chunks_exact_mut(4);
        for (k, curve) in curves.iter().enumerate() {
            for i in 0..curve.len() {
                if let Some(cell) = cells.next() {
                    let (s, g) = unit_noise(k, i);
                    cell.copy_from_slice(&[s, g.x, g.y, g.z]);
                }
            }
        }
    }
    let noise_table = &*noise_table;
    let point_noise = |k: usize, i: usize| match offsets {
        Some(offsets) => offsets
            .get(k)
            .and_then(|o| noise_table.get(4 * (o + i)..4 * (o + i) + 4))
            .map_or((Real::INFINITY, Vec3::zeros()), |c| {
                (c[0], Vec3::new(c[1], c[2], c[3]))
            }),
        None => unit_noise(k, i),
    };
    let mut st = start;
    let mut cutoff = Real::INFINITY;
    let mut iterations = 0;
    for round in 0..=params.max_rounds {
        // Scale from the previous round's points with weight (all, in the first round).
        let (mut sum, mut k_in) = (0.0, 0usize);
        let (kept_d, kept_sd) = weights.split_at_mut(total.min(weights.len()));
        let (mut kept_d, mut kept_sd) = (kept_d.iter_mut(), kept_sd.iter_mut());
        for (k, curve) in curves.iter().enumerate() {
            for (i, x) in curve.iter().enumerate() {
                let (s, g) = point_noise(k, i);
                let (d, sd) = residual(&st, (x - mean) / scale, s, g);
                if offsets.is_some() {
                    if let (Some(kd), Some(ks)) = (kept_d.next(), kept_sd.next()) {
                        (*kd, *ks) = (d, sd);
                    }
                }
                let u = (d / sd).abs();
                if sd.is_finite() && u < cutoff {
                    sum += u;
                    k_in += 1;
                }
            }
        }
        if k_in < 6 {
            return Err(SolveError::TooFewPoints);
        }
        let s = (1.2533 * sum / k_in as Real).max(1.0);
        cutoff = params.tuning * s;
        let frozen = st;
        let c = cutoff;
        let compute = |k: usize, i: usize, y: Vec3| {
            let (s, g) = point_noise(k, i);
            let (d, sd) = residual(&frozen, y, s, g);
            if !sd.is_finite() {
                return 0.0;
            }
            tukey(d / (sd * c)) / (sd * sd)
        };
        // The round's weights from the scale pass's `d` and `σ_d` (the residuals at this
        // round's frozen cylinder, `y` formed as `cyl_accumulate` forms it): the very values
        // `compute` gives.
        if offsets.is_some() {
            let (kept_d, kept_sd) = weights.split_at_mut(total.min(weights.len()));
            for (w, &sd) in kept_d.iter_mut().zip(kept_sd.iter()) {
                let d = *w;
                *w = if sd.is_finite() {
                    tukey(d / (sd * c)) / (sd * sd)
                } else {
                    0.0
                };
            }
        }
        let table = &*weights;
        let weight = |k: usize, i: usize, y: Vec3| match offsets {
            Some(offsets) => offsets
                .get(k)
                .and_then(|o| table.get(o + i))
                .copied()
                .unwrap_or(0.0),
            None => compute(k, i, y),
        };
        let problem = CylinderProblem {
            curves,
            mean,
            scale,
            weight: &weight,
            settle: SETTLED_CHI2,
        };
        let begin = Evaluated::at(&problem, st)?;
        let (min, it) = lm::minimise(&problem, begin, &params.lm)?;
        iterations = it;
        let next = min.params;
        let change = norm(&(next.p - st.p)) + norm(&(next.u - st.u)) + (next.r - st.r).abs();
        let delta = cyl_delta(&st, &next);
        st = next;
        if change <= params.lm.tolerance * (1.0 + norm(&st.p) + st.r)
            || delta.dot(&(min.normal.jtj * delta)) < SETTLED_CHI2
        {
            break;
        }
        if round == params.max_rounds && change > 1e-3 * st.r {
            return Err(SolveError::NotConverged);
        }
    }
    let frozen = st;
    let weight = |k: usize, i: usize, y: Vec3| {
        let (s, g) = point_noise(k, i);
        let (d, sd) = residual(&frozen, y, s, g);
        if !sd.is_finite() {
            return 0.0;
        }
        tukey(d / (sd * cutoff)) / (sd * sd)
    };
    let (jtj, _, chi2, used) = cyl_accumulate(curves, mean, scale, &st, &weight);
    let r = st.r.abs();
    if !(r > 0.0 && r.is_finite()) || used < 6 {
        return Err(SolveError::Degenerate);
    }
    let chi2_dof = chi2 / (used - 5) as Real;
    let f = chi2_dof.max(1.0);
    let inv = jtj.try_inverse().ok_or(SolveError::Degenerate)?;
    let sigma_radius = sqrt((inv[(4, 4)] * f).max(0.0)) * scale;
    let sigma_axis = sqrt((inv[(2, 2)] * f).max((inv[(3, 3)] * f).max(0.0)));
    // Unweighted RMS of the points with weight.
    let mut ss = 0.0;
    for (k, curve) in curves.iter().enumerate() {
        for (i, x) in curve.iter().enumerate() {
            let y = (x - mean) / scale;
            if weight(k, i, y) > 0.0 {
                let (d, _) = residual(&st, y, 1.0, Vec3::zeros());
                ss += d * d;
            }
        }
    }
    Ok(WeightedCylinderFit {
        fit: CylinderFit {
            cylinder: Cylinder {
                point: mean + st.p * scale,
                axis: st.u,
                radius: r * scale,
            },
            rms_residual: sqrt(ss / used as Real) * scale,
            iterations,
            sigma_radius,
            sigma_axis,
            points: used,
        },
        chi2_dof,
    })
}
