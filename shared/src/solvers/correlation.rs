//! Correlation of a fit's residuals along a laser curve (`docs/error-model.md`, "Correlation
//! along the stripe"): neighbouring points share speckle, the smoothing window and defocus,
//! so `n` correlated residuals carry the information of fewer independent ones and a fit's
//! covariance from independent points must be inflated.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::real::Real;

/// Longest lag (points) of the residual autocorrelation summed into the correlation length.
pub const MAX_CORRELATION_LAG: usize = 64;

/// Correlation length of residuals `u` in curve order: the integrated autocorrelation
/// `L = 1 + 2 Σ_{k≥1} ρ_k`, summed while `ρ_k > 0`, `k ≤` [`MAX_CORRELATION_LAG`] and
/// `k < n/4`; 1 for fewer than 8 residuals or all zero. A least-squares fit over `n ≫ L`
/// such points has the variance of one over `n/L` independent points.
pub fn correlation_length(u: &[Real]) -> Real {
    let mut rho = [0.0; MAX_CORRELATION_LAG + 1];
    let kept = autocorrelation(u, &mut rho);
    // Summed in lag order, as the reading has always been computed.
    rho[1..kept].iter().fold(1.0, |length, r| length + 2.0 * r)
}

/// The autocorrelation `ρ_k` of residuals `u` in curve order that [`correlation_length`]
/// sums: `rho[0] = 1`, then `ρ_k` for `k = 1, 2, …` while `ρ_k > 0`, `k ≤`
/// [`MAX_CORRELATION_LAG`] and `k < n/4`. Returns how many entries of `rho` are set (at least
/// 1: fewer than 8 residuals or all zero count as uncorrelated).
pub fn autocorrelation(u: &[Real], rho: &mut [Real; MAX_CORRELATION_LAG + 1]) -> usize {
    rho[0] = 1.0;
    let n = u.len();
    let c0: Real = u.iter().map(|x| x * x).sum();
    if !(c0 > 0.0) || n < 8 {
        return 1;
    }
    let mut kept = 1;
    for k in 1..=MAX_CORRELATION_LAG.min(n / 4) {
        let ck: Real = u.iter().zip(&u[k..]).map(|(a, b)| a * b).sum();
        let r = ck / c0;
        if !(r > 0.0) {
            break;
        }
        rho[k] = r;
        kept = k + 1;
    }
    kept
}

/// Variance inflation `(1 + ρ₁)/(1 − ρ₁)` (at least 1, at most 24) for residuals with lag-one
/// correlation `ρ₁` along the curve, the correlation length of an AR(1) sequence. Points
/// whose residual exceeds `cutoff` (outliers) are skipped. `residuals` come in curve order.
///
/// Needs no buffer, but over-corrects residuals whose correlation dies faster than
/// geometrically (a smoothing window: `ρ₁` near 0.9, `L` near 3); [`correlation_length`]
/// measures `L` itself (the sphere's evaluation, `docs/accuracy.md`, "Spheres").
pub fn correlation_inflation(residuals: impl Iterator<Item = Real>, cutoff: Real) -> Real {
    let (mut sxx, mut sxy) = (0.0, 0.0);
    let mut previous: Option<Real> = None;
    for d in residuals {
        if !(d.abs() <= cutoff) {
            previous = None;
            continue;
        }
        sxx += d * d;
        if let Some(prev) = previous {
            sxy += d * prev;
        }
        previous = Some(d);
    }
    if !(sxx > 0.0) {
        return 1.0;
    }
    let rho = (sxy / sxx).clamp(0.0, 0.92);
    (1.0 + rho) / (1.0 - rho)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// White noise has `L ≈ 1`; a 7-point moving average of it `L ≈ 7` — where the AR(1)
    /// factor of its `ρ₁ = 6/7` says 13.
    #[test]
    fn correlation_length_of_white_and_averaged_noise() {
        // A fixed pseudo-random sequence (xorshift), uniform in [-1, 1).
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut white = [0.0 as Real; 4000];
        for w in white.iter_mut() {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            *w = (state >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0;
        }
        let l_white = correlation_length(&white);
        assert!((0.8..1.3).contains(&l_white), "{l_white}");
        let mut averaged = [0.0 as Real; 3994];
        for (i, a) in averaged.iter_mut().enumerate() {
            *a = white[i..i + 7].iter().sum::<Real>() / 7.0;
        }
        let l_avg = correlation_length(&averaged);
        assert!((5.5..8.5).contains(&l_avg), "{l_avg}");
        let ar1 = correlation_inflation(averaged.iter().copied(), Real::INFINITY);
        assert!(ar1 > 11.0, "{ar1}");
        assert_eq!(correlation_length(&white[..7]), 1.0);
        assert_eq!(correlation_length(&[0.0; 20]), 1.0);
    }
}
