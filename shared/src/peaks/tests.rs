//! Tests of `peaks`.
// Casts between `Real` and f64 are no-ops in f64 builds but needed with `--features f32`.
#![allow(clippy::unnecessary_cast, clippy::type_complexity)]

use super::*;
use crate::real::EPSILON;

/// Pixel-integrated Gaussian of unit peak density, σ `s`, centred on `mu`, at pixel `i`
/// (exact: erf, in f64), scaled by `amp`.
fn integrated(i: usize, mu: f64, s: f64, amp: f64) -> Real {
    let k = s * core::f64::consts::SQRT_2;
    let v = libm::erf((i as f64 + 0.5 - mu) / k) - libm::erf((i as f64 - 0.5 - mu) / k);
    (amp * v / (2.0 * libm::erf(0.5 / k))) as Real
}

fn render(len: usize, mu: f64, s: f64, amp: f64, clip: f64) -> [Real; 41] {
    let mut p = [0.0 as Real; 41];
    for (i, v) in p.iter_mut().enumerate().take(len) {
        *v = integrated(i, mu, s, amp).min(clip as Real);
    }
    p
}

fn argmax(p: &[Real]) -> usize {
    let mut b = 0;
    for (i, &x) in p.iter().enumerate() {
        if x > p[b] {
            b = i;
        }
    }
    plateau_centre(p, b)
}

/// Offsets spanning a full pixel.
fn offsets() -> impl Iterator<Item = f64> {
    (0..20).map(|k| -0.5 + k as f64 / 20.0)
}

#[test]
fn gaussian3_is_exact_on_point_sampled_gaussians() {
    // ln of a point-sampled Gaussian is exactly a parabola, so the 3-point log-parabola
    // recovers μ up to rounding: ln and the division lose a few ulps of the O(1) log
    // values, and the curvature a-2b+c ≥ 1/σ² ≥ 0.25 amplifies them by ≤ 4.
    for s in [0.7, 1.0, 2.0] {
        for off in offsets() {
            let mu = 20.0 + off;
            let p: [Real; 41] = core::array::from_fn(|i| {
                (0.8 * libm::exp(-(i as f64 - mu).powi(2) / (2.0 * s * s))) as Real
            });
            let r = locate(&p, argmax(&p), Estimator::Gaussian3).unwrap();
            assert!(
                (r.position as f64 - mu).abs() < 1e3 * EPSILON as f64,
                "σ {s} μ {mu}: {r:?}"
            );
            assert!((r.sigma.unwrap() as f64 - s).abs() < 1e3 * EPSILON as f64);
        }
    }
}

#[test]
fn parabolic_and_blais_rioux_are_exact_on_parabolas() {
    // On x(i) = A - (i-μ)², the 3-point parabola is the profile itself, and the
    // Blais–Rioux filters are exactly linear: F4(i) = 12(i-μ), F8(i) = 40(i-μ)
    // (docs/subpixel.md §5), so the interpolated zero crossing is μ up to rounding of
    // values of size A = 100 (relative 1e2·ε after the divisions).
    for off in offsets() {
        let mu = 20.0 + off;
        let p: [Real; 41] = core::array::from_fn(|i| (100.0 - (i as f64 - mu).powi(2)) as Real);
        let peak = argmax(&p);
        for e in [
            Estimator::Parabolic,
            Estimator::BlaisRioux4,
            Estimator::BlaisRioux8,
        ] {
            let r = locate(&p, peak, e).unwrap();
            assert!(
                (r.position as f64 - mu).abs() < 1e4 * EPSILON as f64,
                "{e:?} μ {mu}: {r:?}"
            );
        }
    }
}

#[test]
fn centre_of_mass_is_unbiased_when_the_window_holds_the_stripe() {
    // The discrete centre of mass of a pixel-integrated Gaussian is E[round X] for
    // X ~ N(μ, σ²); by Poisson summation |E[round X] − μ| ≤ e^{−2π²σ²}/π ≈ 2e-5 at
    // σ = 0.7, and a ±5 window truncates mass beyond 4.5 px = 6.4σ (< 1e-9).
    // Tolerance 1e-4 (also covers f32 sums of ~11 terms).
    for off in offsets() {
        let mu = 20.0 + off;
        let p = render(41, mu, 0.7, 0.8, f64::INFINITY);
        let r = locate(&p, argmax(&p), Estimator::CentreOfMass { half_window: 5 }).unwrap();
        assert!((r.position as f64 - mu).abs() < 1e-4, "μ {mu}: {r:?}");
    }
    // A window that truncates a wide stripe is biased toward the peak pixel
    // (docs/subpixel.md §3): at σ = 2, ±2, offset 0.25 the estimate moves less than half
    // the offset.
    let p = render(41, 20.25, 2.0, 0.8, f64::INFINITY);
    let r = locate(&p, 20, Estimator::CentreOfMass { half_window: 2 }).unwrap();
    assert!(r.position > 20.0 && r.position < 20.125, "{r:?}");
}

#[test]
fn log_estimators_are_nearly_unbiased_on_pixel_integrated_gaussians() {
    // ln of a pixel-integrated Gaussian is a parabola (variance σ² + 1/12) plus a quartic
    // term −t⁴/(2880σ⁸) (docs/subpixel.md §6). Over the 3 samples (|t| ≤ 1.5) it is
    // ≤ 0.03 at σ = 0.7, against a curvature ≥ 2/(σ²+1/12) ≈ 3.5: the vertex moves by
    // ≤ 0.5·0.03/3.5 ≈ 0.004 px. Tolerance 0.005 px for both log estimators at
    // σ ≥ 0.7 (the weighted fit's quartic residual is weighted down in the tails).
    for s in [0.7, 1.0, 1.5, 2.0, 3.0] {
        for off in offsets() {
            let mu = 20.0 + off;
            let p = render(41, mu, s, 0.8, f64::INFINITY);
            for e in [Estimator::Gaussian3, Estimator::GaussianFit] {
                let r = locate(&p, argmax(&p), e).unwrap();
                assert!(
                    (r.position as f64 - mu).abs() < 0.005,
                    "{e:?} σ {s} μ {mu}: {r:?}"
                );
                assert!(!r.saturated);
            }
        }
    }
}

#[test]
fn gaussian_fit_locates_saturated_peaks() {
    // Peak driven to 1.5× the clipping level. The clipped-model Gauss–Newton uses a
    // point-Gaussian model on pixel-integrated data, whose mismatch is the quartic
    // term above, now over flank samples up to |t| ≈ 3σ: the requirement is 0.02 px with
    // 1 % noise, of which we grant the noise-free model error half: 0.01 px.
    for s in [0.7, 1.0, 1.5, 2.0, 3.0] {
        for off in offsets() {
            let mu = 20.0 + off;
            let p = render(41, mu, s, 1.5, 1.0);
            let peak = argmax(&p);
            let r = locate_with_saturation(&p, peak, Estimator::GaussianFit, 1.0).unwrap();
            assert!(r.saturated);
            assert!((r.position as f64 - mu).abs() < 0.01, "σ {s} μ {mu}: {r:?}");
            // The fit extrapolates the clipped amplitude (1.5 ± the model mismatch).
            assert!(r.amplitude > 1.3 && r.amplitude < 1.7, "{r:?}");
        }
    }
}

#[test]
fn gaussian_fit_removes_a_pedestal() {
    // A DC pedestal of 0.1 keeps the ±12 window above the cut; the end-sample baseline
    // (exactly 0.1 here: the stripe contributes < 1e-9 at 12 px for σ ≤ 2) restores the
    // no-pedestal case, so the same 0.005 px bound as the unpedestalled fit applies.
    for s in [0.7, 1.0, 2.0] {
        for off in offsets() {
            let mu = 20.0 + off;
            let mut p = render(41, mu, s, 0.8, f64::INFINITY);
            p.iter_mut().for_each(|x| *x += 0.1);
            let r = locate(&p, argmax(&p), Estimator::GaussianFit).unwrap();
            assert!(
                (r.position as f64 - mu).abs() < 0.005,
                "σ {s} μ {mu}: {r:?}"
            );
        }
    }
}

#[test]
fn plateau_centre_finds_the_middle() {
    let p = [0.0, 1.0, 5.0, 5.0, 5.0, 5.0, 2.0];
    assert_eq!(plateau_centre(&p, 2), 3);
    assert_eq!(plateau_centre(&p, 5), 3);
    assert_eq!(plateau_centre(&p, 1), 1);
    assert_eq!(plateau_centre(&p, 99), 99);
}

#[test]
fn errors_are_typed() {
    let p: [Real; 9] = [0.0, 0.1, 0.3, 0.7, 1.0, 0.7, 0.3, 0.1, 0.0];
    assert_eq!(
        locate(&p, 9, Estimator::Gaussian3),
        Err(PeakError::PeakOutOfRange { peak: 9, len: 9 })
    );
    assert_eq!(
        locate(&p, 0, Estimator::Parabolic),
        Err(PeakError::Border {
            peak: 0,
            half_window: 1,
            len: 9
        })
    );
    assert_eq!(
        locate(&p, 4, Estimator::BlaisRioux8),
        Err(PeakError::Border {
            peak: 4,
            half_window: 5,
            len: 9
        })
    );
    assert!(locate(&p, 4, Estimator::BlaisRioux4).is_ok());
    for h in [0, MAX_HALF_WINDOW + 1] {
        assert_eq!(
            locate(&p, 4, Estimator::CentreOfMass { half_window: h }),
            Err(PeakError::WindowOutOfRange { half_window: h })
        );
    }
    assert_eq!(
        locate(&p, 3, Estimator::Gaussian3),
        Err(PeakError::NotAMaximum { peak: 3 })
    );
    let mut nan = p;
    nan[5] = Real::NAN;
    assert_eq!(
        locate(&nan, 4, Estimator::Gaussian3),
        Err(PeakError::NonFinite { index: 5 })
    );
    nan[5] = 0.7;
    nan[8] = Real::INFINITY;
    assert_eq!(
        locate(&nan, 4, Estimator::GaussianFit),
        Err(PeakError::NonFinite { index: 8 })
    );
    let zero = [0.0 as Real; 9];
    for e in [
        Estimator::Gaussian3,
        Estimator::Parabolic,
        Estimator::CentreOfMass { half_window: 2 },
        Estimator::BlaisRioux4,
        Estimator::GaussianFit,
    ] {
        assert_eq!(locate(&zero, 4, e), Err(PeakError::Flat), "{e:?}");
    }
    let flat = [3.0 as Real; 9];
    assert_eq!(locate(&flat, 4, Estimator::Parabolic), Err(PeakError::Flat));
    assert_eq!(
        locate(&flat, 4, Estimator::BlaisRioux4),
        Err(PeakError::Flat)
    );
    let cut: [Real; 9] = [0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 0.0, 0.0, 0.0];
    assert_eq!(
        locate(&cut, 4, Estimator::Gaussian3),
        Err(PeakError::NonPositive { index: 3 })
    );
    assert_eq!(
        locate(&cut, 4, Estimator::GaussianFit),
        Err(PeakError::TooFewSamples { found: 2 })
    );
    // Saturation flag: samples at or above the level.
    let r = locate_with_saturation(&p, 4, Estimator::Gaussian3, 1.0).unwrap();
    assert!(r.saturated);
    assert!(!locate(&p, 4, Estimator::Gaussian3).unwrap().saturated);
}
