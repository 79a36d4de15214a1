//! One Levenberg–Marquardt minimiser for every geometric fit (`docs/cylinder.md`, "Geometric
//! fit").
//!
//! A fit states its problem by implementing [`LeastSquares`] with `N` free parameters: the
//! normal equations at a parameter value ([`LeastSquares::evaluate`]: `JᵀJ`, `Jᵀr`, `Σr²`), how
//! a step moves the parameters ([`LeastSquares::step`]: plain addition, or a move on a manifold
//! such as the cylinder's unit axis) and the scale of the relative step tolerance. [`minimise`]
//! runs the damped Gauss–Newton iteration with the rules every fit shares:
//!
//! * the step solves `(JᵀJ + λ·(diag(JᵀJ) + ε))·δ = −Jᵀr` (Marquardt's scaling, with a floor so
//!   that a zero diagonal still gives a damped step); a damped matrix that is not positive
//!   definite raises `λ` tenfold ([`SolveError::Degenerate`] beyond `λ = 10¹⁶`);
//! * a candidate is accepted when its cost is finite and lower — or equal to within the
//!   cost's own rounding (`8ε·cost`) with a smaller gradient: near the minimum of a flat valley
//!   the cost changes by less than its rounding while the gradient is still resolved, and this
//!   reaches `ε/λ_min` instead of `√(ε/λ_min)`, which matters in `f32`. Then `λ ← max(λ/10,
//!   10⁻¹²)`; a rejected or out-of-domain candidate sets `λ ← max(10λ, ε)`;
//! * a step whose predicted gain `−2δᵀJᵀr − δᵀJᵀJδ` the problem calls settled
//!   ([`LeastSquares::settled`]) ends the iteration at the current parameters before it is
//!   evaluated (it would move them by less than the problem resolves; a rejected step's
//!   successors only shorten it, and in `f32` the cost's own rounding, `8ε·cost`, can exceed
//!   the settling gain, so each would be one more evaluation to reach λ > 10¹⁶);
//! * it stops converged after an accepted step shorter than `tolerance·scale(θ)` (or one the
//!   problem calls [`LeastSquares::settled`]), or when `λ > 10¹⁶` after a rejection (every
//!   direction raises the cost even with a vanishing step: the minimum to rounding), and fails
//!   with [`SolveError::NotConverged`] after `max_iterations` steps (accepted or not).
//!
//! Used by the circle ([`super::circle`]), ellipse ([`super::ellipse`]) and cylinder
//! ([`super::cylinder_fit`]) fits. A new fit (a sphere, a plane) implements the trait on
//! normalised data, as in this one-parameter example — the mean as a least-squares fit:
//!
//! ```
//! use tangent_core::real::Real;
//! use tangent_core::solvers::lm::{minimise, Evaluated, LeastSquares, LmParams, NormalEquations};
//! use tangent_core::solvers::SolveError;
//! use nalgebra::{SMatrix, SVector};
//!
//! struct Mean<'a>(&'a [Real]);
//! impl LeastSquares<1> for Mean<'_> {
//!     type Params = SVector<Real, 1>;
//!     type Extra = ();
//!     fn evaluate(&self, p: &Self::Params) -> Result<(NormalEquations<1>, ()), SolveError> {
//!         // r_i = p − y_i, J_i = 1.
//!         let (mut jtr, mut cost) = (0.0, 0.0);
//!         for y in self.0 {
//!             jtr += p[0] - y;
//!             cost += (p[0] - y) * (p[0] - y);
//!         }
//!         let jtj = SMatrix::<Real, 1, 1>::new(self.0.len() as Real);
//!         Ok((NormalEquations { jtj, jtr: SVector::<Real, 1>::new(jtr), cost }, ()))
//!     }
//!     fn step(&self, p: &Self::Params, delta: &SVector<Real, 1>) -> Self::Params {
//!         p + delta
//!     }
//!     fn step_scale(&self, p: &Self::Params) -> Real {
//!         1.0 + p.norm()
//!     }
//! }
//!
//! let data = [1.0, 2.0, 6.0];
//! let problem = Mean(&data);
//! let start = Evaluated::at(&problem, SVector::<Real, 1>::new(0.0))?;
//! let (min, _iterations) = minimise(&problem, start, &LmParams::default())?;
//! assert!((min.params[0] - 3.0).abs() < 1e-4);
//! # Ok::<(), SolveError>(())
//! ```

// `!(x > 0.0)` is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use nalgebra::{SMatrix, SVector};

use super::SolveError;
use crate::real::{norm, sqrt, Real};

/// Settings of the Levenberg–Marquardt iteration (every fit: circle, ellipse, cylinder).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmParams {
    /// Most iterations (accepted or rejected steps).
    pub max_iterations: u32,
    /// Convergence when an accepted step is shorter than `tolerance·(1 + |θ|)`, in the
    /// normalised coordinates (unit RMS spread of the data).
    pub tolerance: Real,
    /// Initial damping `λ` (relative to the diagonal of `JᵀJ`).
    pub initial_lambda: Real,
}

impl Default for LmParams {
    /// 100 iterations, `λ₀ = 1e-3`, tolerance `16·ε` (f64: 3.6e-15, f32: 1.9e-6 of the data's
    /// spread): a step below it changes the parameters by a few ulps of the rounding noise
    /// the cost function itself carries (`n` terms each rounded to `ε`).
    fn default() -> Self {
        LmParams {
            max_iterations: 100,
            tolerance: 16.0 * Real::EPSILON,
            initial_lambda: 1e-3,
        }
    }
}

impl LmParams {
    /// [`SolveError::InvalidParameter`] unless there is at least one iteration and the
    /// tolerance and initial damping are finite and non-negative.
    pub(crate) fn validate(&self) -> Result<(), SolveError> {
        if self.max_iterations == 0
            || !(self.tolerance.is_finite() && self.tolerance >= 0.0)
            || !(self.initial_lambda.is_finite() && self.initial_lambda >= 0.0)
        {
            return Err(SolveError::InvalidParameter);
        }
        Ok(())
    }
}

/// The normal equations of a least-squares problem at one parameter value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalEquations<const N: usize> {
    /// `JᵀJ` (`JᵀWJ` for a weighted problem).
    pub jtj: SMatrix<Real, N, N>,
    /// `Jᵀr` (`JᵀWr`).
    pub jtr: SVector<Real, N>,
    /// The cost `Σr²` (`Σw·r²`).
    pub cost: Real,
}

/// A least-squares problem with `N` free parameters, for [`minimise`].
pub trait LeastSquares<const N: usize> {
    /// The parameters: an `SVector<Real, N>` for a flat parameter space, or a richer state
    /// when a step moves on a manifold (a unit axis).
    type Params: Copy;
    /// What an evaluation yields besides the normal equations (a sandwich's middle matrix),
    /// `()` if nothing.
    type Extra;
    /// The normal equations at `p`. An error means `p` is outside the model's domain (or
    /// leaves too few points): [`minimise`] rejects such a candidate; at the start
    /// ([`Evaluated::at`]) the error is the fit's.
    fn evaluate(&self, p: &Self::Params) -> Result<(NormalEquations<N>, Self::Extra), SolveError>;
    /// The parameters after the step `delta`.
    fn step(&self, p: &Self::Params, delta: &SVector<Real, N>) -> Self::Params;
    /// The scale of `p` for the step tolerance: converged when `|δ| ≤ tolerance·scale`
    /// (typically `1 + |θ|`).
    fn step_scale(&self, p: &Self::Params) -> Real;
    /// Whether an accepted step from cost `before` to `after` ends the iteration although it
    /// is not small (a fit that needs the cost settled, not the last ulp of a flat valley);
    /// also asked for each step before it is evaluated, with `after` its predicted cost.
    /// Default: never.
    fn settled(&self, _before: Real, _after: Real) -> bool {
        false
    }
}

/// Parameters with their normal equations (a start for, or the result of, [`minimise`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evaluated<P, E, const N: usize> {
    /// The parameters.
    pub params: P,
    /// The normal equations there.
    pub normal: NormalEquations<N>,
    /// The problem's extra output there.
    pub extra: E,
}

impl<P: Copy, E, const N: usize> Evaluated<P, E, N> {
    /// `problem` evaluated at `params`.
    pub fn at<L: LeastSquares<N, Params = P, Extra = E>>(
        problem: &L,
        params: P,
    ) -> Result<Self, SolveError> {
        let (normal, extra) = problem.evaluate(&params)?;
        Ok(Evaluated {
            params,
            normal,
            extra,
        })
    }
}

/// [`Evaluated`] parameters of the problem `L`.
pub type EvaluatedOf<L, const N: usize> =
    Evaluated<<L as LeastSquares<N>>::Params, <L as LeastSquares<N>>::Extra, N>;

/// Minimises `problem` from `start` by Levenberg–Marquardt with the rules of the module
/// documentation. Returns the minimum with its normal equations and the iterations used.
pub fn minimise<const N: usize, L: LeastSquares<N>>(
    problem: &L,
    start: EvaluatedOf<L, N>,
    params: &LmParams,
) -> Result<(EvaluatedOf<L, N>, u32), SolveError> {
    let mut current = start;
    let mut lambda = params.initial_lambda;
    for it in 1..=params.max_iterations {
        let Some(delta) = levenberg_step(&current.normal.jtj, &current.normal.jtr, &mut lambda)?
        else {
            continue;
        };
        // A step whose predicted gain the problem already calls settled is not worth its
        // evaluation: taken, it would move the parameters by less than the problem resolves
        // (for a χ² cost, a fraction of their σ), and it would end the iteration anyway.
        let gain = predicted_gain(&current.normal, &delta);
        if problem.settled(current.normal.cost, current.normal.cost - gain) {
            return Ok((current, it));
        }
        let candidate = problem.step(&current.params, &delta);
        let accepted = match problem.evaluate(&candidate) {
            Ok((normal, extra)) if improves(&current.normal, &normal) => Some(Evaluated {
                params: candidate,
                normal,
                extra,
            }),
            _ => None,
        };
        match accepted {
            Some(next) => {
                let small = problem.settled(current.normal.cost, next.normal.cost)
                    || norm(&delta) <= params.tolerance * problem.step_scale(&current.params);
                current = next;
                lambda = (lambda * 0.1).max(1e-12);
                if small {
                    return Ok((current, it));
                }
            }
            None => {
                lambda = (lambda * 10.0).max(Real::EPSILON);
                if lambda > 1e16 {
                    return Ok((current, it));
                }
            }
        }
    }
    Err(SolveError::NotConverged)
}

/// The decrease of the cost `Σr²` the Gauss–Newton model predicts for the step `delta`:
/// `−2δᵀJᵀr − δᵀJᵀJδ` (positive for a damped step).
fn predicted_gain<const N: usize>(normal: &NormalEquations<N>, delta: &SVector<Real, N>) -> Real {
    -2.0 * delta.dot(&normal.jtr) - delta.dot(&(normal.jtj * delta))
}

/// The acceptance rule: a finite cost that is lower, or equal to within its rounding
/// (`8ε·cost`) with a smaller gradient (module documentation).
fn improves<const N: usize>(current: &NormalEquations<N>, next: &NormalEquations<N>) -> bool {
    let rounding = 8.0 * Real::EPSILON * current.cost;
    let better = next.cost < current.cost
        || (next.cost <= current.cost + rounding && norm(&next.jtr) < norm(&current.jtr));
    next.cost.is_finite() && better
}

/// One damped Gauss–Newton step: solves `(JᵀJ + λ·(diag(JᵀJ) + ε))·δ = −Jᵀr`. When the damped
/// matrix is not positive definite, raises `λ` tenfold and returns `Ok(None)` (try again), or
/// [`SolveError::Degenerate`] once `λ > 10¹⁶`.
fn levenberg_step<const N: usize>(
    jtj: &SMatrix<Real, N, N>,
    jtr: &SVector<Real, N>,
    lambda: &mut Real,
) -> Result<Option<SVector<Real, N>>, SolveError> {
    let mut a = *jtj;
    for k in 0..N {
        a[(k, k)] += *lambda * (jtj[(k, k)] + Real::EPSILON);
    }
    match a.cholesky() {
        Some(ch) => Ok(Some(ch.solve(&(-jtr)))),
        None => {
            *lambda = (*lambda * 10.0).max(Real::EPSILON);
            if *lambda > 1e16 {
                Err(SolveError::Degenerate)
            } else {
                Ok(None)
            }
        }
    }
}

/// Inverse of a symmetric positive-definite matrix (a normal matrix `JᵀWJ`), scaled to unit
/// diagonal first: `A⁻¹ = D (D A D)⁻¹ D`, `D = diag(1/√Aᵢᵢ)`, the scaled one by Cholesky.
/// Why not `try_inverse`: nalgebra's closed-form inverse of a 4 × 4 divides by the
/// determinant, and a normal matrix weighted by `1/σ²` of sub-millimetre σ has entries of
/// 10¹⁰ and a determinant beyond `f32`'s range — in `f32` the inverse came out as zeros
/// (the sphere's joint fit of a small near-pole ball: a zero covariance, σ 0). `None` when a diagonal entry is not positive or the matrix is not positive definite.
pub fn spd_inverse<const N: usize>(a: &SMatrix<Real, N, N>) -> Option<SMatrix<Real, N, N>> {
    let mut d = SVector::<Real, N>::zeros();
    for k in 0..N {
        let v = a[(k, k)];
        if !(v > 0.0 && v.is_finite()) {
            return None;
        }
        d[k] = 1.0 / sqrt(v);
    }
    let scaled = SMatrix::<Real, N, N>::from_fn(|i, j| a[(i, j)] * d[i] * d[j]);
    let inverse = scaled.cholesky()?.inverse();
    let out = SMatrix::<Real, N, N>::from_fn(|i, j| inverse[(i, j)] * d[i] * d[j]);
    out.iter().all(|v| v.is_finite()).then_some(out)
}

#[cfg(test)]
mod spd_tests {
    use super::*;

    /// A normal matrix weighted by `1/σ²` of 10 µm: entries of 10¹⁰, a determinant beyond
    /// `f32`'s range; the scaled Cholesky inverse is still the inverse.
    #[test]
    fn a_normal_matrix_of_small_sigmas_is_inverted_in_either_precision() {
        let base = SMatrix::<Real, 4, 4>::new(
            4.0, 1.0, 0.5, 0.2, 1.0, 3.0, 0.4, 0.1, 0.5, 0.4, 2.0, 0.3, 0.2, 0.1, 0.3, 1.0,
        );
        let a = base * 1e10;
        let inverse = spd_inverse(&a).expect("positive definite");
        let identity = a * inverse;
        for i in 0..4 {
            for j in 0..4 {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((identity[(i, j)] - want).abs() < 1e-4, "{identity}");
            }
        }
        assert!(spd_inverse(&(-a)).is_none());
    }
}
