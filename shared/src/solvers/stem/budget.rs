//! The solver's point budget (`docs/error-model.md`, "Point budget"): a long arc has far more
//! points than independent pieces of information — neighbouring columns share the smoothing
//! window and the speckle — so consecutive points are merged into bins, each the
//! inverse-variance weighted mean of its points with σ `(Σσᵢ⁻²)^(−1/2)`. A bin of `k` points
//! spans `kΔ` of the arc (Δ the point spacing), where the curvature moves its mean inside the
//! circle by `(kΔ)²/(24R)`, a third of the chord's sagitta; a long curve's bins span
//! `kΔ ≈ d/budget` of a stem of diameter `d`, so the shift is `d/(12·budget²)`: 13 µm on a
//! 1 m stem, 1.3 µm on a 10 cm one at the budget of 80 — far below the points' σ (a curve
//! within the budget is not binned at all). Every method of the solver (three-tangent, circle and cylinder
//! fits, the projected sections, the non-roundness test) then works on at most the budget per
//! curve whatever the arc's length, and the reading does not move (tests
//! `budget_keeps_the_reading`, `budget_on_two_planes_keeps_the_reading`).

use crate::calibration::MAX_PLANES;
#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Real, Vec3};

/// Most points of one curve the solver uses; a longer curve is binned ([`bin_curves`]). A
/// 1 m stem at 1 m lights ≈ 700 columns: 80 bins of ≤ 9 columns each, and a bin's mean sits
/// inside the arc by `(kΔ)²/(24R)` ≈ `d/(12·80²)` = 13 µm. Chosen on the tuning set
/// (`docs/error-model.md` §5c; issue 17, session 12) for the device's ≤ 1 M instructions on
/// a 1 m stem: against 128 the MAE per distance bin moved by at most 0.15 mm (0.06 mm up
/// to 1 m), readings by a median 0.03σ (transversal) and 0.07σ (tilted), within 1 % and
/// within 2σ unchanged; at 64 a 1 m stem moves by more than 0.2σ
/// (`budget_keeps_the_reading`).
pub const POINT_BUDGET: usize = 80;

/// Fewest bins a budget may ask for: the two ends and one between them.
const MIN_BUDGET: usize = 3;

/// Per curve, the points (and their 1σ) the solver works on.
pub(super) type Curves<'a> = ([&'a [Vec3]; MAX_PLANES], [&'a [Real]; MAX_PLANES]);

/// Each curve of `curves` (with its points' 1σ `sigmas`, same lengths; at most
/// [`MAX_PLANES`]) longer than `budget` binned into `bins` and `bin_sigmas`, one after the
/// other ([`bin_curve`]); a curve within the budget, or one there is no room left for, is
/// taken as it is, and so is every curve with a budget of 0.
pub(super) fn bin_curves<'a>(
    curves: &[&'a [Vec3]],
    sigmas: &[&'a [Real]],
    budget: usize,
    mut bins: &'a mut [Vec3],
    mut bin_sigmas: &'a mut [Real],
) -> Curves<'a> {
    let budget = if budget == 0 {
        usize::MAX
    } else {
        budget.max(MIN_BUDGET)
    };
    let mut out: Curves<'a> = ([&[]; MAX_PLANES], [&[]; MAX_PLANES]);
    for (k, (&curve, &sigma)) in curves.iter().zip(sigmas).enumerate().take(MAX_PLANES) {
        let n = curve.len().min(sigma.len());
        let m = binned_len(n, budget);
        if m < n && m <= bins.len() && m <= bin_sigmas.len() {
            let (points, rest) = core::mem::take(&mut bins).split_at_mut(m);
            let (point_sigmas, rest_sigmas) = core::mem::take(&mut bin_sigmas).split_at_mut(m);
            bin_curve(&curve[..n], &sigma[..n], points, point_sigmas);
            (bins, bin_sigmas) = (rest, rest_sigmas);
            out.0[k] = points;
            out.1[k] = point_sigmas;
        } else {
            out.0[k] = curve;
            out.1[k] = sigma;
        }
    }
    out
}

/// Number of points a curve of `n` points is binned to under `budget` (at least 3):
/// `min(n, budget)`.
fn binned_len(n: usize, budget: usize) -> usize {
    n.min(budget.max(MIN_BUDGET))
}

/// Bins `points` (1σ `sigmas`) into `out` (and the bins' σ into `out_sigmas`; `m` of each,
/// `3 ≤ m ≤ n`). The first and last points stay bins of their own: the three-tangent
/// method's grazing rays are the arc's extreme polar angles, which lie at its ends, and a
/// bin there would move them inwards by half its width. The `n − 2` points between go into
/// the `m − 2` bins between, bin `j` starting at point `1 + ⌊j(n−2)/(m−2)⌋` — `⌊(n−2)/(m−2)⌋`
/// points or one more each, so that a curve just over the budget keeps nearly every point
/// apart. Points with a non-positive or non-finite σ are left out of their bin; a bin with
/// none keeps its unweighted mean with an infinite σ (no weight in the fits).
fn bin_curve(points: &[Vec3], sigmas: &[Real], out: &mut [Vec3], out_sigmas: &mut [Real]) {
    let n = points.len().min(sigmas.len());
    let m = out.len().min(out_sigmas.len());
    if n < m || m < MIN_BUDGET {
        return;
    }
    let mut bin = |j: usize, lo: usize, hi: usize| {
        let (mut sum, mut wsum) = (Vec3::zeros(), 0.0);
        for (p, &s) in points[lo..hi].iter().zip(&sigmas[lo..hi]) {
            if s > 0.0 && s.is_finite() {
                let w = 1.0 / (s * s);
                sum += p * w;
                wsum += w;
            }
        }
        if wsum > 0.0 {
            out[j] = sum / wsum;
            out_sigmas[j] = 1.0 / sqrt(wsum);
        } else {
            let plain: Vec3 = points[lo..hi].iter().sum();
            out[j] = plain / (hi - lo) as Real;
            out_sigmas[j] = Real::INFINITY;
        }
    };
    bin(0, 0, 1);
    let (inner, between) = (n - 2, m - 2);
    for j in 0..between {
        bin(
            1 + j,
            1 + j * inner / between,
            1 + (j + 1) * inner / between,
        );
    }
    bin(m - 1, n - 1, n);
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// `n` points along x with σ alternating 1, 2.
    fn line(n: usize) -> (Vec<Vec3>, Vec<Real>) {
        let points = (0..n).map(|i| Vec3::new(i as Real, 0.0, 1.0)).collect();
        let sigmas = (0..n).map(|i| 1.0 + (i % 2) as Real).collect();
        (points, sigmas)
    }

    /// Σσ⁻²: the information a set of points carries along its noise direction.
    fn information(sigmas: &[Real]) -> Real {
        sigmas.iter().map(|s| 1.0 / (s * s)).sum()
    }

    /// The ends stay themselves, the bins between hold ⌊(n−2)/(m−2)⌋ points or one more, in
    /// order, every point in exactly one bin (the information Σσ⁻² is kept), and a bin is the
    /// inverse-variance mean of its points with σ `(Σσ⁻²)^(−1/2)`.
    #[test]
    fn bins_keep_the_ends_and_weigh_by_inverse_variance() {
        for (n, budget) in [(301, 128), (130, 128), (700, 80), (83, 80)] {
            let (points, sigmas) = line(n);
            let m = binned_len(n, budget);
            assert_eq!(m, budget);
            let mut out = std::vec![Vec3::zeros(); m];
            let mut out_s = std::vec![0.0; m];
            bin_curve(&points, &sigmas, &mut out, &mut out_s);
            assert_eq!((out[0], out[m - 1]), (points[0], points[n - 1]));
            assert_eq!((out_s[0], out_s[m - 1]), (sigmas[0], sigmas[n - 1]));
            let kept = information(&out_s) / information(&sigmas);
            assert!((kept - 1.0).abs() < 1e-5, "{n} into {m}: {kept}");
            assert!(out.windows(2).all(|w| w[0].x < w[1].x), "{n} into {m}");
            // With every σ 1, a bin's Σσ⁻² is its count: ⌊(n−2)/(m−2)⌋ or one more, n − 2 in all.
            let ones = std::vec![1.0; n];
            bin_curve(&points, &ones, &mut out, &mut out_s);
            let small = (n - 2) / (m - 2);
            let counts: Vec<usize> = out_s[1..m - 1]
                .iter()
                .map(|s| (1.0 / (s * s)).round() as usize)
                .collect();
            assert!(
                counts.iter().all(|&c| c == small || c == small + 1),
                "{n} into {m}"
            );
            assert_eq!(counts.iter().sum::<usize>(), n - 2);
        }
        // 299 points into 126 bins of 2 or 3: bin 1 holds points 1, 2 (σ 2, 1), bin 3 points
        // 5, 6, 7 (σ 2, 1, 2; it starts at 1 + ⌊2·299/126⌋ = 5).
        let (points, sigmas) = line(301);
        let mut out = std::vec![Vec3::zeros(); 128];
        let mut out_s = std::vec![0.0; 128];
        bin_curve(&points, &sigmas, &mut out, &mut out_s);
        let mean = (1.0 * 0.25 + 2.0 * 1.0) / 1.25;
        assert!((out[1].x - mean).abs() < 1e-5, "{:?}", out[1]);
        assert!((out_s[1] - 1.0 / sqrt(1.25)).abs() < 1e-6);
        let mean = (5.0 * 0.25 + 6.0 * 1.0 + 7.0 * 0.25) / 1.5;
        assert!((out[3].x - mean).abs() < 1e-5, "{:?}", out[3]);
        assert!((out_s[3] - 1.0 / sqrt(1.5)).abs() < 1e-6);
    }

    /// Two long curves are binned one after the other into the lent buffers; a short one, one
    /// without room, and any curve under a budget of 0 are taken as they are.
    #[test]
    fn curves_share_the_lent_buffers() {
        let (long, long_s) = line(500);
        let (short, short_s) = line(60);
        let (mut bins, mut bs) = (std::vec![Vec3::zeros(); 200], std::vec![0.0; 200]);
        let (c, s) = bin_curves(&[&long, &long], &[&long_s, &long_s], 80, &mut bins, &mut bs);
        assert_eq!(
            (c[0].len(), c[1].len(), s[0].len(), s[1].len()),
            (80, 80, 80, 80)
        );
        assert_eq!(c[0], c[1]);
        assert_eq!(c[1].as_ptr(), bins[80..].as_ptr());
        let (mut bins, mut bs) = (std::vec![Vec3::zeros(); 100], std::vec![0.0; 100]);
        let (c, _) = bin_curves(
            &[&short, &long, &long],
            &[&short_s, &long_s, &long_s],
            80,
            &mut bins,
            &mut bs,
        );
        assert_eq!((c[0].len(), c[1].len(), c[2].len()), (60, 80, 500));
        let (c, _) = bin_curves(&[&long], &[&long_s], 0, &mut bins, &mut bs);
        assert_eq!(c[0].len(), 500);
    }

    /// A bin whose points have no usable σ keeps their plain mean and carries no weight.
    #[test]
    fn a_bin_without_sigma_has_no_weight() {
        let points = [Vec3::new(0.0, 0.0, 1.0); 10];
        let sigmas = [0.0; 10];
        let m = binned_len(10, 4);
        let mut out = std::vec![Vec3::zeros(); m];
        let mut out_s = std::vec![0.0; m];
        bin_curve(&points, &sigmas, &mut out, &mut out_s);
        assert!(out.iter().all(|p| *p == points[0]));
        assert!(out_s.iter().all(|s| s.is_infinite()));
    }
}
