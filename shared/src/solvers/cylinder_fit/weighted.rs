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

/// Reals of scratch [`fit_cylinder_weighted`] needs per point: its normalised coordinates, its
/// σ and unit noise direction, its residual (then its weight) and the residual's σ.
pub const CYLINDER_SCRATCH_PER_POINT: usize = 9;

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

/// A point's weight in the fit: `tukey(d/(σ_d·cutoff))/σ_d²` for its residual `d` of σ `σ_d`
/// (0 for a point without a finite σ).
fn point_weight(d: Real, sd: Real, cutoff: Real) -> Real {
    if sd.is_finite() {
        tukey(d / (sd * cutoff)) / (sd * sd)
    } else {
        0.0
    }
}

/// The points' weights at the result of the [`fit_cylinder_weighted`] of `points` points that
/// last used `scratch`, in the curves' order (a point's weight `tukey(dᵢ/(σ_{dᵢ}·c))/σ_{dᵢ}²`
/// in the fit's normalised units: a common scale, which cancels in what is solved with them).
/// Read them before `scratch` is used again. `None` when `scratch` is too short.
pub fn fit_weights(scratch: &[Real], points: usize) -> Option<&[Real]> {
    scratch.get(7 * points..8 * points)
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
/// σ. Errors as [`super::fit_cylinder`]; [`SolveError::ScratchTooSmall`] when `scratch` holds
/// fewer than [`CYLINDER_SCRATCH_PER_POINT`] values per point.
///
/// Everything a point contributes that does not change within the fit or within a round is
/// evaluated once into `scratch` — as the one-plane fit does (`docs/performance.md`): its
/// normalised coordinates and its noise (σ and unit direction) once per fit, its weight once
/// per round; each LM step reads them. Re-deriving a point's noise direction at every step was
/// half of a tilted stem's solver on the device.
pub fn fit_cylinder_weighted(
    curves: &[&[Vec3]],
    noise: impl Fn(usize, usize) -> Vec3,
    initial: Cylinder,
    params: &RobustParams,
    scratch: &mut [Real],
) -> Result<WeightedCylinderFit, SolveError> {
    params.lm.validate()?;
    if !(params.tuning.is_finite() && params.tuning > 0.0) || params.max_rounds == 0 {
        return Err(SolveError::InvalidParameter);
    }
    let Normalised {
        mean, scale, start, ..
    } = normalise(curves, initial)?;
    let total: usize = curves.iter().map(|c| c.len()).sum();
    let scratch = scratch
        .get_mut(..CYLINDER_SCRATCH_PER_POINT * total)
        .ok_or(SolveError::ScratchTooSmall)?;
    // Per point: `y` (3), σ and unit noise direction (4), the residual `d` at the round's
    // frozen cylinder and then the round's weight (1), the residual's σ (1).
    let (ys, rest) = scratch.split_at_mut(3 * total);
    let (noises, rest) = rest.split_at_mut(4 * total);
    let (weights, residual_sigmas) = rest.split_at_mut(total);
    {
        let mut cells = ys.chunks_exact_mut(3).zip(noises.chunks_exact_mut(4));
        for (k, curve) in curves.iter().enumerate() {
            for (i, x) in curve.iter().enumerate() {
                let Some((y, cell)) = cells.next() else { break };
                let v = (x - mean) / scale;
                y.copy_from_slice(&[v.x, v.y, v.z]);
                let g = noise(k, i) / scale;
                let s = norm(&g);
                let (s, g) = if s > 0.0 && s.is_finite() {
                    (s, g / s)
                } else {
                    (Real::INFINITY, Vec3::zeros())
                };
                cell.copy_from_slice(&[s, g.x, g.y, g.z]);
            }
        }
    }
    let (ys, noises) = (&*ys, &*noises);
    // Each point's `y`, σ and unit noise direction from the tables (a plain zip: mapped, the
    // iterator's element was a call per point on the device).
    let points = || ys.chunks_exact(3).zip(noises.chunks_exact(4));
    let unpack = |y: &[Real], c: &[Real]| {
        (
            Vec3::new(y[0], y[1], y[2]),
            c[0],
            Vec3::new(c[1], c[2], c[3]),
        )
    };
    let mut st = start;
    let mut cutoff = Real::INFINITY;
    let mut iterations = 0;
    for round in 0..=params.max_rounds {
        // Scale from the previous round's points with weight (all, in the first round); the
        // residuals and their σ at this round's frozen cylinder kept for its weights.
        let (mut sum, mut k_in) = (0.0, 0usize);
        for (((y, c), d_out), sd_out) in points()
            .zip(weights.iter_mut())
            .zip(residual_sigmas.iter_mut())
        {
            let (y, s, g) = unpack(y, c);
            let (d, sd) = residual(&st, y, s, g);
            (*d_out, *sd_out) = (d, sd);
            let u = (d / sd).abs();
            if sd.is_finite() && u < cutoff {
                sum += u;
                k_in += 1;
            }
        }
        if k_in < 6 {
            return Err(SolveError::TooFewPoints);
        }
        let s = (1.2533 * sum / k_in as Real).max(1.0);
        cutoff = params.tuning * s;
        for (w, &sd) in weights.iter_mut().zip(residual_sigmas.iter()) {
            *w = point_weight(*w, sd, cutoff);
        }
        let table = &*weights;
        let problem = CylinderProblem {
            points: || ys.chunks_exact(3).zip(table.iter()),
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
    // The weights at the result (the last round's cutoff), and the unweighted RMS of the
    // points with weight.
    let mut ss = 0.0;
    for ((y, c), w) in points().zip(weights.iter_mut()) {
        let (y, s, g) = unpack(y, c);
        let (d, sd) = residual(&st, y, s, g);
        *w = point_weight(d, sd, cutoff);
        if *w > 0.0 {
            ss += d * d;
        }
    }
    let table = &*weights;
    let (jtj, _, chi2, used) = cyl_accumulate(ys.chunks_exact(3).zip(table.iter()), &st);
    let r = st.r.abs();
    if !(r > 0.0 && r.is_finite()) || used < 6 {
        return Err(SolveError::Degenerate);
    }
    let chi2_dof = chi2 / (used - 5) as Real;
    let f = chi2_dof.max(1.0);
    let inv = jtj.try_inverse().ok_or(SolveError::Degenerate)?;
    let sigma_radius = sqrt((inv[(4, 4)] * f).max(0.0)) * scale;
    let sigma_axis = sqrt((inv[(2, 2)] * f).max((inv[(3, 3)] * f).max(0.0)));
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
