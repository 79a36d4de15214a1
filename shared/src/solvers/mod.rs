//! Solvers: from the 3-D points of one capture to a dimension (thesis chapter 9 onwards).
//!
//! * [`circle`]: algebraic (Kåsa, Taubin, Hyper) and geometric (Levenberg–Marquardt,
//!   robust) circle fits on 2-D points (`docs/cylinder.md`, "Circle fits").
//! * [`cylinder`]: the stem diameter — three-tangent method, full-arc fits, tilted
//!   cylinders from two parallel planes, method choice
//!   (`docs/cylinder.md`).
//!
//! Every solver works on caller-owned slices, never allocates and returns a [`SolveError`]
//! instead of a made-up number when the data cannot support an answer.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::fmt;

use crate::real::Real;

pub mod circle;
pub mod cylinder;
pub mod result;

/// Why a solver could not produce a trustworthy answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveError {
    /// Fewer points than the model needs (3 for a circle, 5 for an ellipse or a cylinder,
    /// more for the local fits of the three-tangent method).
    TooFewPoints,
    /// An input point or parameter is NaN or infinite.
    NonFinite,
    /// The points do not determine the model: collinear or coincident points, a singular
    /// normal matrix, a source inside the section.
    Degenerate,
    /// An iterative fit did not converge within its iteration budget.
    NotConverged,
    /// A caller-provided scratch buffer is shorter than the number of points.
    ScratchTooSmall,
    /// The lit and visible arc is too short (in angle seen from its centre) for the radius
    /// to be trusted (see `docs/cylinder.md`, "Choosing the method").
    ArcTooShort,
    /// The solved radius is outside the plausible range given in the parameters.
    RadiusOutOfRange,
    /// A parameter is out of its documented domain (negative tolerance, zero iterations, …).
    InvalidParameter,
    /// The input has no or too many laser planes for the requested solution.
    PlaneCount,
    /// The section is detectably not round and one view cannot resolve its axes: measure
    /// across two directions (`docs/cylinder.md`, "Elliptic stems").
    NotRound,
}

impl fmt::Display for SolveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            SolveError::TooFewPoints => "too few points for the model",
            SolveError::NonFinite => "non-finite point or parameter",
            SolveError::Degenerate => "points do not determine the model (collinear or singular)",
            SolveError::NotConverged => "iterative fit did not converge",
            SolveError::ScratchTooSmall => "scratch buffer shorter than the point count",
            SolveError::ArcTooShort => "visible arc too short for a trustworthy radius",
            SolveError::RadiusOutOfRange => "radius outside the plausible range",
            SolveError::InvalidParameter => "solver parameter out of range",
            SolveError::PlaneCount => "wrong number of laser planes for this solution",
            SolveError::NotRound => "section not round: measure across two directions",
        };
        f.write_str(s)
    }
}

#[cfg(feature = "std")]
impl std::error::Error for SolveError {}

/// One damped Gauss–Newton (Levenberg–Marquardt) step: solves
/// `(JᵀJ + λ·(diag(JᵀJ) + ε))·δ = −Jᵀr` (Marquardt's diagonal scaling, with a floor so that a
/// zero diagonal still gives a damped step). When the damped matrix is not positive definite,
/// raises `λ` tenfold and returns `Ok(None)` (try again), or `Degenerate` once `λ > 10¹⁶`.
/// Shared by the circle, ellipse and cylinder fits (`docs/cylinder.md`).
pub(crate) fn levenberg_step<const N: usize>(
    jtj: &nalgebra::SMatrix<Real, N, N>,
    jtd: &nalgebra::SVector<Real, N>,
    lambda: &mut Real,
) -> Result<Option<nalgebra::SVector<Real, N>>, SolveError> {
    let mut a = *jtj;
    for k in 0..N {
        a[(k, k)] += *lambda * (jtj[(k, k)] + Real::EPSILON);
    }
    match a.cholesky() {
        Some(ch) => Ok(Some(ch.solve(&(-jtd)))),
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
