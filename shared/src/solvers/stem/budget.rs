//! The solver's point budget (`docs/error-model.md`, "Point budget"): a long arc has far more
//! points than independent pieces of information — neighbouring columns share the smoothing
//! window and the speckle — so consecutive points are merged into bins, each the
//! inverse-variance weighted mean of its points with σ `(Σσᵢ⁻²)^(−1/2)`. A bin of `k` points
//! spans `k` columns, where the arc's curvature moves the mean off the circle by at most the
//! sagitta `(k·Δ)²/(8R)` (Δ the point spacing): below 1 µm for `k·Δ` = 5 mm on a 2 cm radius
//! — far below the points' σ. The fit's cost is then bounded by the budget whatever the arc's
//! length, and the reading does not move (test `budget_keeps_the_reading`).

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Real, Vec2};

/// Most points of one curve the whole-arc fit uses; a longer curve is binned
/// ([`decimate`]). A 1 m stem at 1 m lights ≈ 700 columns; 128 bins of ≤ 6 columns keep the
/// fit's cost at about a fifth of that with the same reading: a bin's mean sits inside the
/// arc by `(kΔ)²/(24R)` ≈ `d/(12·128²)` = 5 µm on a 1 m stem, and on the evaluation sets the
/// change from 256 moved readings by a median 0.04σ, at most 0.40σ (`docs/error-model.md`
/// §5c; issue 17, session 10).
pub const POINT_BUDGET: usize = 128;

/// Bins `points` (with their 1σ `sigmas`, same length) into at most `budget` consecutive
/// groups of `k = ⌈n/budget⌉` points, in place: bin `j` is written to `points[j]` and its σ to
/// `sigmas_out[j]`. Returns the number of bins `m`. With `n ≤ budget` the points are kept and
/// their σ copied. Points with a non-positive or non-finite σ are left out of their bin; a bin
/// with none keeps its unweighted mean with an infinite σ (no weight in the fit).
pub(super) fn decimate(
    points: &mut [Vec2],
    sigmas: &[Real],
    sigmas_out: &mut [Real],
    budget: usize,
) -> usize {
    let n = points.len().min(sigmas.len());
    let budget = budget.max(1);
    let k = n.div_ceil(budget).max(1);
    let m = n.div_ceil(k);
    if sigmas_out.len() < m {
        return 0;
    }
    for j in 0..m {
        let (lo, hi) = (j * k, ((j + 1) * k).min(n));
        let (mut sum, mut wsum, mut plain) = (Vec2::zeros(), 0.0, Vec2::zeros());
        for i in lo..hi {
            plain += points[i];
            let s = sigmas[i];
            if s > 0.0 && s.is_finite() {
                let w = 1.0 / (s * s);
                sum += points[i] * w;
                wsum += w;
            }
        }
        // `j ≤ lo`: the bin's own points are read before it is written.
        if wsum > 0.0 {
            points[j] = sum / wsum;
            sigmas_out[j] = 1.0 / sqrt(wsum);
        } else {
            points[j] = plain / (hi - lo) as Real;
            sigmas_out[j] = Real::INFINITY;
        }
    }
    m
}
