//! How well a unit's laser planes are known: the covariance of every plane's baseline `e`
//! and tilt `δ` (`docs/calibration.md` §14).
//!
//! A board calibration fits each plane from its own poses, so its planes' errors are
//! independent, each with the head's budget ([`crate::noise::NoiseModel`]'s `baseline` and
//! `tilt`); a calibration without a [`PlanesUncertainty`] means exactly that. Refining the
//! planes against each other on a reference (`tangent calibrate ball` / `wall`) leaves them
//! correlated: their difference is known far better than either plane, their common part
//! no better than before. The refinement's posterior is what a reading's calibration σ must
//! then use, and it is stored here as each parameter's 1σ and their correlation, in the
//! order `e₀, δ₀, e₁, δ₁, …` (metres, radians).

use serde::{Deserialize, Serialize};

use super::MAX_PLANES;
// `Float` supplies sqrt/abs in `no_std`; with `std` the inherent methods win.
#[allow(unused_imports)]
use crate::real::Float;
use crate::real::Real;
use nalgebra::SMatrix;

/// Parameters per plane (`e`, `δ`) times the most planes a calibration holds.
pub const PLANE_PARAMS: usize = 2 * MAX_PLANES;

/// How far a stored correlation may be from symmetric, or its diagonal from 1: the wire
/// carries it in `f32`.
const CORRELATION_TOLERANCE: Real = 1e-4;

/// Why a planes' uncertainty is unusable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UncertaintyError {
    /// The σ do not hold two values (`e`, `δ`) for each of 1 to [`MAX_PLANES`] planes.
    Length(usize),
    /// The correlation has `got` entries where `n` σ need `n²` (`expected`).
    CorrelationShape {
        /// `n²`.
        expected: usize,
        /// Entries given.
        got: usize,
    },
    /// σ number `index` is negative or not finite.
    Sigma(usize),
    /// Correlation entry (`row`, `col`) is not finite, outside [−1, 1], differs from its
    /// mirror, or is a diagonal entry other than 1.
    Correlation {
        /// Row.
        row: usize,
        /// Column.
        col: usize,
    },
    /// The correlation is not positive semi-definite (no covariance has it).
    NotPositive,
    /// It covers `covers` planes; the calibration has `planes`.
    PlaneCount {
        /// Planes the uncertainty covers.
        covers: usize,
        /// Planes the calibration has.
        planes: usize,
    },
}

impl core::fmt::Display for UncertaintyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            UncertaintyError::Length(n) => write!(
                f,
                "{n} σ given: two per plane (e, δ) for 1 to {MAX_PLANES} planes expected"
            ),
            UncertaintyError::CorrelationShape { expected, got } => {
                write!(f, "correlation has {got} entries, {expected} expected")
            }
            UncertaintyError::Sigma(i) => write!(f, "σ {i} is negative or not finite"),
            UncertaintyError::Correlation { row, col } => write!(
                f,
                "correlation ({row}, {col}) is not finite, outside [-1, 1], not symmetric or \
                 (on the diagonal) not 1"
            ),
            UncertaintyError::NotPositive => {
                write!(f, "correlation is not positive semi-definite")
            }
            UncertaintyError::PlaneCount { covers, planes } => write!(
                f,
                "uncertainty covers {covers} planes, the calibration has {planes}"
            ),
        }
    }
}

/// The covariance of the planes' `(e, δ)`, as 1σ and correlation (module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlanesUncertainty {
    planes: usize,
    sigma: [Real; PLANE_PARAMS],
    correlation: [[Real; PLANE_PARAMS]; PLANE_PARAMS],
}

impl PlanesUncertainty {
    /// From the σ of `e₀, δ₀, e₁, δ₁, …` (metres, radians) and their correlation (row-major,
    /// `n × n` for `n` σ), validated: two σ per plane for 1 to [`MAX_PLANES`] planes, each
    /// finite and ≥ 0; the correlation symmetric, within [−1, 1], 1 on the diagonal and
    /// positive semi-definite.
    pub fn new(sigma: &[Real], correlation: &[Real]) -> Result<Self, UncertaintyError> {
        let n = sigma.len();
        if n == 0 || !n.is_multiple_of(2) || n > PLANE_PARAMS {
            return Err(UncertaintyError::Length(n));
        }
        if correlation.len() != n * n {
            return Err(UncertaintyError::CorrelationShape {
                expected: n * n,
                got: correlation.len(),
            });
        }
        let mut out = PlanesUncertainty {
            planes: n / 2,
            sigma: [0.0; PLANE_PARAMS],
            correlation: [[0.0; PLANE_PARAMS]; PLANE_PARAMS],
        };
        for (i, &s) in sigma.iter().enumerate() {
            if !(s.is_finite() && s >= 0.0) {
                return Err(UncertaintyError::Sigma(i));
            }
            out.sigma[i] = s;
        }
        for row in 0..n {
            for col in 0..n {
                let r = correlation[row * n + col];
                let mirror = correlation[col * n + row];
                let ok = r.is_finite()
                    && r.abs() <= 1.0 + CORRELATION_TOLERANCE
                    && (r - mirror).abs() <= CORRELATION_TOLERANCE
                    && (row != col || (r - 1.0).abs() <= CORRELATION_TOLERANCE);
                if !ok {
                    return Err(UncertaintyError::Correlation { row, col });
                }
                // Stored symmetric, so the quadratic form is the same whichever half is read.
                out.correlation[row][col] = if row == col { 1.0 } else { 0.5 * (r + mirror) };
            }
        }
        // Positive semi-definite within the stored precision: Cholesky of the matrix with
        // the tolerance added to its diagonal (the unused block is the identity).
        let mut m = SMatrix::<Real, PLANE_PARAMS, PLANE_PARAMS>::identity();
        for row in 0..n {
            for col in 0..n {
                m[(row, col)] = out.correlation[row][col];
            }
            m[(row, row)] += CORRELATION_TOLERANCE;
        }
        if m.cholesky().is_none() {
            return Err(UncertaintyError::NotPositive);
        }
        Ok(out)
    }

    /// The covariance of the first `planes` planes alone (a Gaussian's marginal: the
    /// leading block), for a calibration cut to those planes; `Length` when it covers
    /// fewer or `planes` is 0.
    pub fn leading(&self, planes: usize) -> Result<Self, UncertaintyError> {
        if planes == 0 || planes > self.planes {
            return Err(UncertaintyError::Length(2 * planes));
        }
        let mut out = *self;
        out.planes = planes;
        for i in 0..PLANE_PARAMS {
            for j in 0..PLANE_PARAMS {
                if i >= 2 * planes || j >= 2 * planes {
                    out.correlation[i][j] = 0.0;
                }
            }
            if i >= 2 * planes {
                out.sigma[i] = 0.0;
            }
        }
        Ok(out)
    }

    /// Planes covered.
    pub fn planes(&self) -> usize {
        self.planes
    }

    /// The σ of `e₀, δ₀, e₁, δ₁, …` (metres, radians).
    pub fn sigmas(&self) -> &[Real] {
        &self.sigma[..2 * self.planes]
    }

    /// Plane `k`'s `(σ_e, σ_δ)`; zeros beyond the planes covered.
    pub fn plane_sigma(&self, k: usize) -> (Real, Real) {
        if k < self.planes {
            (self.sigma[2 * k], self.sigma[2 * k + 1])
        } else {
            (0.0, 0.0)
        }
    }

    /// Correlation of parameters `i` and `j` (0 beyond those covered).
    pub fn correlation(&self, i: usize, j: usize) -> Real {
        let n = 2 * self.planes;
        if i < n && j < n {
            self.correlation[i][j]
        } else {
            0.0
        }
    }

    /// [`PlanesUncertainty::spread`] under `uncertainty`, or with the parameters independent
    /// (`√Σ shift²`, the board calibration's planes) without one.
    pub fn spread_under(uncertainty: Option<&Self>, shift: &[Real]) -> Real {
        match uncertainty {
            Some(u) => u.spread(shift),
            None => shift.iter().map(|s| s * s).sum::<Real>().sqrt(),
        }
    }

    /// The standard deviation of a quantity that moves by `shift[i]` when parameter `i` moves
    /// by its own 1σ (`gᵀ ρ g`, `g` in σ units): what a reading's calibration σ is under this
    /// covariance. Entries beyond the parameters covered are ignored.
    pub fn spread(&self, shift: &[Real]) -> Real {
        let n = (2 * self.planes).min(shift.len());
        let mut variance = 0.0;
        for i in 0..n {
            for j in 0..n {
                variance += shift[i] * self.correlation[i][j] * shift[j];
            }
        }
        // A positive semi-definite form is ≥ 0; rounding can leave it a hair below.
        variance.max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_valid_covariance_is_kept_and_read_back() {
        let u = PlanesUncertainty::new(
            &[2e-4, 2e-4, 1e-4, 5e-5],
            &[
                1.0, 0.1, 0.9, 0.0, //
                0.1, 1.0, 0.0, 0.95, //
                0.9, 0.0, 1.0, 0.0, //
                0.0, 0.95, 0.0, 1.0,
            ],
        )
        .unwrap();
        assert_eq!(u.planes(), 2);
        assert_eq!(u.plane_sigma(1), (1e-4, 5e-5));
        assert_eq!(u.plane_sigma(2), (0.0, 0.0));
        assert_eq!(u.correlation(1, 3), 0.95);
        assert_eq!(u.correlation(1, 4), 0.0);
        // Two tilts moving a reading in opposite directions: their correlation cancels most.
        let opposed = u.spread(&[0.0, 1.0, 0.0, -1.0]);
        assert!((opposed - (2.0 - 2.0 * 0.95 as Real).sqrt()).abs() < 1e-6);
        let together = u.spread(&[0.0, 1.0, 0.0, 1.0]);
        assert!((together - (2.0 + 2.0 * 0.95 as Real).sqrt()).abs() < 1e-6);
        // The first plane's marginal keeps its block and forgets the other plane.
        let first = u.leading(1).unwrap();
        assert_eq!(first.planes(), 1);
        assert_eq!(first.plane_sigma(0), (2e-4, 2e-4));
        assert_eq!(first.correlation(0, 1), 0.1);
        assert_eq!(first.correlation(0, 2), 0.0);
        assert_eq!(first.spread(&[0.0, 1.0, 0.0, -1.0]), 1.0);
        assert_eq!(u.leading(3), Err(UncertaintyError::Length(6)));
    }

    #[test]
    fn what_no_covariance_can_be_is_refused_by_name() {
        let one = [1.0, 0.0, 0.0, 1.0];
        assert_eq!(
            PlanesUncertainty::new(&[1e-4; 3], &[1.0; 9]),
            Err(UncertaintyError::Length(3))
        );
        assert_eq!(
            PlanesUncertainty::new(&[1e-4; 2], &[1.0; 3]),
            Err(UncertaintyError::CorrelationShape {
                expected: 4,
                got: 3
            })
        );
        assert_eq!(
            PlanesUncertainty::new(&[1e-4, -1e-4], &one),
            Err(UncertaintyError::Sigma(1))
        );
        assert_eq!(
            PlanesUncertainty::new(&[1e-4, 1e-4], &[1.0, 0.5, 0.4, 1.0]),
            Err(UncertaintyError::Correlation { row: 0, col: 1 })
        );
        assert_eq!(
            PlanesUncertainty::new(&[1e-4, 1e-4], &[0.9, 0.0, 0.0, 1.0]),
            Err(UncertaintyError::Correlation { row: 0, col: 0 })
        );
        // Three parameters each perfectly anti-correlated with the others: no covariance.
        let anti = [
            1.0, -0.9, -0.9, 0.0, //
            -0.9, 1.0, -0.9, 0.0, //
            -0.9, -0.9, 1.0, 0.0, //
            0.0, 0.0, 0.0, 1.0,
        ];
        assert_eq!(
            PlanesUncertainty::new(&[1e-4; 4], &anti),
            Err(UncertaintyError::NotPositive)
        );
    }
}
