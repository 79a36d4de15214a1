//! Tests of the MPD chain: the filter against SciPy's, each step on profiles whose answer is
//! known, and the refusals.
#![allow(clippy::unnecessary_cast)]
// Reference values from SciPy, printed in f64.
#![allow(clippy::excessive_precision)]

use super::*;

const N: usize = 800;

/// A profile over [0, 100 mm] at `step`, heights `h(s)`, drop-outs where `drop(i)`.
fn profile(
    step: Real,
    h: impl Fn(Real) -> Real,
    drop: impl Fn(usize) -> bool,
) -> ([Vec2; N], usize) {
    let mut out = [Vec2::zeros(); N];
    let n = ((0.1 / step) as usize).min(N);
    for (i, p) in out.iter_mut().enumerate().take(n) {
        let s = 0.07e-3 + step * i as Real;
        *p = Vec2::new(s, if drop(i) { Real::NAN } else { h(s) });
    }
    (out, n)
}

fn run(p: &[Vec2]) -> Result<(MeanProfileDepth, [SegmentDepth; 2]), RoadError> {
    let mut heights = [0.0; N];
    let mut resampled = [0.0; 400];
    let mut marks = [0.0; 400];
    let mut segments = [SegmentDepth::default(); 2];
    let params = MpdParams::default();
    let m = mean_profile_depth(
        p,
        0.0,
        0.1,
        &params,
        &mut heights,
        &mut resampled,
        &mut marks,
        &mut segments,
    )?;
    Ok((m, segments))
}

#[test]
fn the_filter_is_scipys_butterworth_run_forwards_and_backwards() {
    let f = Biquad::butterworth_lowpass(0.5e-3, 2.4e-3);
    // scipy.signal.butter(2, (1/2.4)/(0.5/0.5), output="sos") (SciPy 1.17).
    let expected_b = [0.2201947, 0.4403894, 0.2201947];
    let expected_a = [-0.30756636, 0.18834516];
    for (x, e) in
        f.b.iter()
            .chain(&f.a)
            .zip(expected_b.iter().chain(&expected_a))
    {
        assert!((x - e).abs() < 1e-6, "{x} vs {e}");
    }
    let mut x = [
        0.0, 1.0, 0.5, -0.3, 2.0, 1.5, 1.0, 0.2, -0.5, -1.0, 0.0, 0.8, 1.2, 0.4, 0.1, -0.2, 0.3,
        0.9, 1.1, 0.7,
    ];
    // scipy.signal.sosfiltfilt(sos, x) of the same input.
    let y = [
        0.000109391,
        0.391430805,
        0.481995514,
        0.703366694,
        1.240391704,
        1.485265588,
        1.033795568,
        0.178523794,
        -0.533232928,
        -0.632545535,
        -0.054090526,
        0.675002879,
        0.914424080,
        0.568927266,
        0.096370260,
        -0.016133406,
        0.326630922,
        0.786363241,
        0.931615395,
        0.700101521,
    ];
    filter_zero_phase(&f, &mut x).unwrap();
    for (a, b) in x.iter().zip(&y) {
        assert!((a - b).abs() < 2e-5, "{a} vs {b}");
    }
    // Noise gain: white noise through the forward–backward filter keeps G of its variance
    // (checked against the direct sum of the squared zero-phase response).
    let g = f.noise_gain();
    let mut impulse = [0.0; 201];
    impulse[100] = 1.0;
    filter_zero_phase(&f, &mut impulse).unwrap();
    let direct: Real = impulse.iter().map(|v| v * v).sum();
    assert!((g - direct).abs() < 1e-4 * direct, "{g} vs {direct}");
    assert!(g > 0.1 && g < 0.5, "{g}");
    // Too short to extend.
    assert!(filter_zero_phase(&f, &mut [0.0; FILTER_PAD]).is_err());
}

#[test]
fn a_sine_of_20_mm_has_an_msd_of_its_amplitude() {
    // 5 periods in 100 mm, amplitude 1 mm: both halves peak at +1 mm, the mean is 0, the
    // regression line is flat (a cosine over whole periods); the filter passes 20 mm at
    // |H|² = 1/(1 + (2.4/20)⁴) ≈ 0.9998. (A sine would not: its regression slope tilts the
    // crests by ±0.19 mm and the MSD reads 1.055 mm — the standard's slope suppression.)
    let (p, n) = profile(0.15e-3, |s| 1e-3 * (2.0 * PI * s / 0.02).cos(), |_| false);
    let (m, seg) = run(&p[..n]).unwrap();
    assert_eq!((m.segments, m.valid_segments, m.resampled), (1, 1, 200));
    assert!((m.mpd - 1e-3).abs() < 0.01e-3, "{}", m.mpd);
    assert!((m.etd - (0.2e-3 + 0.8 * m.mpd)).abs() < 1e-12);
    // The peaks sit on crests (s = 0, 20, 40 … mm); one in each half.
    assert!(seg[0].peaks[0].x < 0.05 && seg[0].peaks[1].x >= 0.05);
    for peak in seg[0].peaks {
        let phase = (peak.x * 1e3 + 10.0) % 20.0 - 10.0;
        assert!(phase.abs() < 0.6, "{:?}", seg[0].peaks);
    }
}

#[test]
fn the_slope_is_suppressed_and_fine_texture_filtered() {
    // A 3 % ramp adds nothing; a 0.3 mm ripple of 1.2 mm wavelength (below the 2.4 mm
    // cut-off) reads about half its amplitude: the filter alone would leave
    // |H(1.2 mm)|² ≈ 1/17 of it, but the 0.5 mm bin averaging of 0.15 mm samples (3 or 4 to
    // a bin) aliases part of it to long wavelengths. captif-slp reads 0.1516 mm on the same
    // profile (`tools/road_crosscheck.py`).
    let (p, n) = profile(
        0.15e-3,
        |s| 0.03 * s + 1e-3 * (2.0 * PI * s / 0.02).cos(),
        |_| false,
    );
    let (m, _) = run(&p[..n]).unwrap();
    assert!((m.mpd - 1e-3).abs() < 0.01e-3, "{}", m.mpd);
    let (p, n) = profile(
        0.15e-3,
        |s| 0.3e-3 * (2.0 * PI * s / 1.2e-3).sin(),
        |_| false,
    );
    let (m, _) = run(&p[..n]).unwrap();
    assert!((m.mpd - 0.1516e-3).abs() < 0.5e-6, "{}", m.mpd);
}

#[test]
fn dropouts_are_corrected_and_counted_within_the_limit_and_refused_beyond() {
    let h = |s: Real| 1e-3 * (2.0 * PI * s / 0.02).sin() + 0.4e-3 * (2.0 * PI * s / 0.007).sin();
    let (clean, n) = profile(0.15e-3, h, |_| false);
    let reference = run(&clean[..n]).unwrap().0.mpd;
    // 5 % scattered drop-outs: the MPD barely moves.
    let (p, n) = profile(0.15e-3, h, |i| i % 20 == 7);
    let (m, seg) = run(&p[..n]).unwrap();
    assert!((m.mpd - reference).abs() < 5e-6, "{} vs {reference}", m.mpd);
    assert!((seg[0].dropout_fraction - 0.05).abs() < 0.003);
    // 15 %: refused, with the share.
    let (p, n) = profile(0.15e-3, h, |i| i % 20 < 3);
    match run(&p[..n]) {
        Err(RoadError::TooManyDropouts { fraction, .. }) => {
            assert!((fraction - 0.15).abs() < 0.01)
        }
        other => panic!("{other:?}"),
    }
    // Every sample missing.
    let (p, n) = profile(0.15e-3, h, |_| true);
    assert!(matches!(
        run(&p[..n]),
        Err(RoadError::TooManyDropouts { .. })
    ));
}

#[test]
fn a_spike_is_removed_not_averaged_in() {
    let h = |s: Real| 1e-3 * (2.0 * PI * s / 0.02).cos();
    let (clean, n) = profile(0.15e-3, h, |_| false);
    let reference = run(&clean[..n]).unwrap().0.mpd;
    let mut spiky = clean;
    // A 5 mm spike over 0.6 mm (a stone's specular glint read as a height).
    for p in spiky[300..304].iter_mut() {
        p.y += 5e-3;
    }
    let (m, _) = run(&spiky[..n]).unwrap();
    assert!(m.spikes >= 2, "{}", m.spikes);
    assert!(
        (m.mpd - reference).abs() < 0.02e-3,
        "{} vs {reference}",
        m.mpd
    );
    // Uncorrected, the spike would have been a peak of the first half.
    assert!(reference + 1e-3 < 5e-3);
}

#[test]
fn resampling_averages_each_bin_and_fills_empty_ones() {
    let p = [
        Vec2::new(0.0, 1.0),
        Vec2::new(0.2e-3, 3.0),
        Vec2::new(0.6e-3, 5.0),
        Vec2::new(1.8e-3, 9.0),
    ];
    let h = [1.0, 3.0, 5.0, 9.0];
    let mut out = [0.0; 10];
    let (n, filled) = resample(&p, &h, 0.0, 2e-3, 0.5e-3, &mut out).unwrap();
    // Bins (0, 0.5] ∪ {0}: 1, 3 → 2; (0.5, 1]: 5; (1, 1.5]: empty; (1.5, 2]: 9.
    assert_eq!((n, filled), (4, 1));
    assert_eq!(&out[..4], &[2.0, 5.0, 7.0, 9.0]);
    let mut gaps = [Real::NAN, 1.0, Real::NAN, Real::NAN, 4.0, Real::NAN];
    assert_eq!(fill_gaps(&mut gaps), 4);
    assert_eq!(gaps, [1.0, 1.0, 2.0, 3.0, 4.0, 4.0]);
}

#[test]
fn microtexture_on_a_peak_reads_the_fine_ripple_and_the_tops_curvature() {
    // A macrotexture crest of curvature 100 /m (radius 10 mm) carrying a 0.2 mm ripple of
    // 10 µm amplitude: RMS ≈ 10/√2 µm (the ±0.25 mm mean removes the crest, and nearly all
    // of a ripple of 2.5 periods).
    let ripple = 10e-6;
    let (p, n) = profile(
        0.02e-3,
        |s| -50.0 * (s - 0.008) * (s - 0.008) + ripple * (2.0 * PI * s / 0.2e-3).sin(),
        |_| false,
    );
    let heights: [Real; N] = core::array::from_fn(|i| p[i].y);
    let m = microtexture(&p[..n], &heights[..n], 0.008, &MpdParams::default()).unwrap();
    assert!(
        (m.rms_height - ripple / sqrt(2.0)).abs() < 0.15 * ripple,
        "{}",
        m.rms_height
    );
    assert!((m.curvature - 100.0).abs() < 15.0, "{}", m.curvature);
    assert!((m.peak - 0.008).abs() < 0.3e-3);
    // Without the ripple the RMS is the crest's residual to its ±0.25 mm mean: tiny.
    let (p, n) = profile(0.02e-3, |s| -50.0 * (s - 0.008) * (s - 0.008), |_| false);
    let heights: [Real; N] = core::array::from_fn(|i| p[i].y);
    let m = microtexture(&p[..n], &heights[..n], 0.008, &MpdParams::default()).unwrap();
    assert!(m.rms_height < 1e-6, "{}", m.rms_height);
    assert!((m.curvature - 100.0).abs() < 1.0, "{}", m.curvature);
}
