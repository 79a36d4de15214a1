//! Tests of the faint-stripe search on rendered frame pairs with noise.
#![allow(clippy::unnecessary_cast)]

extern crate std;
use super::super::tests::{buffers, calibration, frames, render};
use super::*;
use crate::pipeline::extract_profile;
use std::vec::Vec;

/// A reproducible Gaussian noise source (xorshift, Box–Muller).
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> Real {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 11) as Real + 0.5) / (1u64 << 53) as Real
    }
    fn gaussian(&mut self) -> Real {
        let (u, v) = (self.uniform(), self.uniform());
        Float::sqrt(-2.0 * Float::ln(u)) * Float::cos(2.0 * crate::real::PI * v)
    }
}

/// Adds independent Gaussian noise of σ `sigma` (grey levels) to both frames.
pub(crate) fn add_noise(off: &mut [u8], on: &mut [u8], sigma: Real, seed: u64) {
    let mut n = Noise(seed | 1);
    for p in off.iter_mut().chain(on.iter_mut()) {
        let v = *p as Real + sigma * n.gaussian();
        *p = v.round().clamp(0.0, 255.0) as u8;
    }
}

/// True row of plane 0 on a wall at depth `z` (undistorted reference camera).
pub(crate) fn wall_row(cal: &Calibration, u: Real, z: Real) -> Real {
    let cam = &cal.camera;
    let p = cal.planes[0];
    let x = (u - cam.cx) * z / cam.fx;
    let y = (p.offset - p.normal.x * x - p.normal.z * z) / p.normal.y;
    cam.cy + cam.fy * y / z
}

#[test]
fn a_stripe_below_the_darkness_test_is_found() {
    let cal = calibration(1);
    // 4 DN peak over σ = 2 DN of noise per frame: invisible to any threshold.
    let (mut off, mut on) = render(&cal, &[0], 1.8, 250..550, 4.0, 60);
    add_noise(&mut off, &mut on, 2.0, 7);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let mut ws = b.workspace();
    let profile = extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws)
        .expect("the faint search finds the stripe");
    assert_eq!(profile.threshold, 0, "read by the faint search");
    assert!(profile.faint);
    assert!(profile
        .image_flags(on_f.max_value())
        .contains(crate::solvers::result::Flags::FAINT_STRIPE));
    let (s, e) = profile.plane_points[0];
    assert!(e - s > 200, "{} points", e - s);
    let errors: Vec<Real> = ws.curve[s..e]
        .iter()
        .map(|c| c.row - wall_row(&cal, c.column as Real, 1.8))
        .collect();
    let mean = errors.iter().sum::<Real>() / errors.len() as Real;
    let rms = Float::sqrt(errors.iter().map(|e| e * e).sum::<Real>() / errors.len() as Real);
    // On a fronto-parallel wall the stripe has the same subpixel phase in every column, so
    // the 3-point estimator's phase-dependent bias (≈ 0.1 px at this SNR) does not average
    // out as it does along a stem's arc.
    assert!(mean.abs() < 0.2, "bias {mean} px");
    assert!(rms < 0.6, "rms {rms} px");
    // Every point's σ is stated, and covers its error (honest within a factor ~2).
    let sigmas = &mut ws.sigmas[..];
    point_sigmas_for(&profile, &cal, &ws.points[..], &ws.curve[..], sigmas);
    let mean_sigma_px: Real = ws.curve[s..e]
        .iter()
        .map(|c| {
            crate::noise::NoiseModel::reference().stripe_centre_px(
                c.amplitude,
                c.width,
                profile.noise,
            )
        })
        .sum::<Real>()
        / (e - s) as Real;
    assert!(
        mean_sigma_px > 0.5 * rms && mean_sigma_px < 4.0 * rms,
        "stated {mean_sigma_px} px against rms {rms} px"
    );
}

fn point_sigmas_for(
    profile: &Profile,
    cal: &Calibration,
    points: &[crate::real::Vec3],
    curve: &[CurvePoint],
    sigmas: &mut [Real],
) {
    super::super::point_sigmas(
        profile,
        &cal.planes,
        &crate::noise::NoiseModel::reference(),
        cal.camera.fx,
        points,
        curve,
        sigmas,
    )
    .unwrap();
}

#[test]
fn noise_alone_is_still_no_laser_light() {
    let cal = calibration(2);
    for seed in 1..6u64 {
        let (mut off, mut on) = render(&cal, &[0], 1.5, 0..0, 0.0, 80);
        add_noise(&mut off, &mut on, 2.5, seed);
        let (off_f, on_f) = frames(&off, &on);
        let mut b = buffers(2);
        let err = extract_profile(
            &off_f,
            &on_f,
            &cal,
            &PipelineConfig::default(),
            &mut b.workspace(),
        )
        .unwrap_err();
        assert!(
            matches!(err, PipelineError::NoLaserLight { .. }),
            "seed {seed}: {err:?}"
        );
    }
}

#[test]
fn two_faint_planes_are_found_in_image_order() {
    let cal = calibration(2);
    let (mut off, mut on) = render(&cal, &[0, 1], 1.2, 200..560, 5.0, 50);
    add_noise(&mut off, &mut on, 2.0, 11);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(2);
    let mut ws = b.workspace();
    let profile = extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws)
        .expect("both stripes found");
    assert_eq!(profile.threshold, 0);
    // Plane k's points lie on plane k's line (the same wall, 1.2 m).
    for plane in 0..2 {
        let pts = profile.points(&ws.points[..], plane);
        assert!(pts.len() > 150, "plane {plane}: {} points", pts.len());
        let mean_z: Real = pts.iter().map(|p| p.z).sum::<Real>() / pts.len() as Real;
        assert!((mean_z - 1.2).abs() < 0.02, "plane {plane}: z {mean_z}");
    }
}

#[test]
fn switched_off_the_dark_pair_stays_dark() {
    let cal = calibration(1);
    let (mut off, mut on) = render(&cal, &[0], 1.8, 250..550, 4.0, 60);
    add_noise(&mut off, &mut on, 2.0, 7);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let config = PipelineConfig {
        faint: None,
        ..PipelineConfig::default()
    };
    let err = extract_profile(&off_f, &on_f, &cal, &config, &mut b.workspace()).unwrap_err();
    assert!(matches!(err, PipelineError::NoLaserLight { .. }), "{err:?}");
}

#[test]
fn kernel_is_zero_sum_and_peaks_at_its_centre() {
    for sigma in [0.5, 1.0, 1.6, 3.0] {
        let (w, len) = kernel(sigma);
        assert_eq!(len % 2, 1);
        assert_eq!(w[..len].iter().sum::<i64>(), 0);
        assert_eq!(w[..len].iter().max(), Some(&w[len / 2]));
    }
}

/// The response at row `v` as defined (`docs/image-processing.md`, "Faint stripes"): the column
/// sum over the block, rows beyond the frame read at its edge, correlated with the taps, minus
/// the rings' imbalance — computed the plain way, tap by tap.
fn plain_response(diff: &Frame<u8, &[u8]>, x0: usize, b: usize, v: usize, taps: &[i64]) -> Real {
    let (width, height) = (diff.width(), diff.height());
    let half = taps.len() / 2;
    let sum = |k: usize| -> i64 {
        let y = (v + k).saturating_sub(half).min(height - 1);
        diff.row(y)[x0..(x0 + b).min(width)]
            .iter()
            .map(|&p| p as i64)
            .sum()
    };
    let r: i64 = taps.iter().enumerate().map(|(k, &w)| w * sum(k)).sum();
    let ring = RING;
    let upper: i64 = (0..ring).map(sum).sum();
    let lower: i64 = (taps.len() - ring..taps.len()).map(sum).sum();
    (r - taps[0].abs() * (upper - lower).abs()) as Real
}

#[test]
fn block_responses_are_the_plain_correlation_at_every_row_and_edge() {
    let (width, height) = (37usize, 29usize);
    let mut pixels = std::vec![0u8; width * height];
    let mut n = Noise(12345);
    for p in pixels.iter_mut() {
        *p = (n.uniform() * 256.0).min(255.0) as u8;
    }
    let diff = Frame::new(&pixels[..], width, height, width).unwrap();
    let mut sums = std::vec![0.0 as Real; height + MAX_KERNEL];
    let mut responses = std::vec![Real::NAN; height];
    for sigma in [0.6 as Real, 1.0, 2.0] {
        let (taps, len) = kernel(sigma);
        let taps = &taps[..len];
        // The frame's top and bottom (kernel beyond the edges), an inner band, all rows; a
        // block cut by the frame's right edge.
        for rows in [0..3, 3..12, 20..height, 0..height] {
            for x0 in [0usize, 8, 32] {
                block_responses(&diff, None, x0, 8, &rows, taps, &mut sums, &mut responses);
                for v in rows.clone() {
                    assert_eq!(
                        responses[v],
                        plain_response(&diff, x0, 8, v, taps),
                        "σ {sigma}, rows {rows:?}, block at {x0}, row {v}"
                    );
                }
            }
        }
    }
}
