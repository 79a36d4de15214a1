//! Tests of the faint-stripe search on rendered frame pairs with noise.
#![allow(clippy::unnecessary_cast)]

extern crate std;
use super::super::tests::{buffers, calibration, frames, render, H, W};
use super::*;
use crate::pipeline::extract_profile;
use crate::pipeline::faint_sums;
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

/// A random 8-bit difference frame of `width × height` and its block sums of 8 columns
/// (block-major), gathered row by row as the stream does.
fn random_table(width: usize, height: usize, seed: u64) -> (Vec<u8>, Vec<u16>) {
    let mut pixels = std::vec![0u8; width * height];
    let mut n = Noise(seed);
    for p in pixels.iter_mut() {
        *p = (n.uniform() * 256.0).min(255.0) as u8;
    }
    let mut table = std::vec![0u16; width.div_ceil(8) * height];
    for y in 0..height {
        faint_sums::gather_row(
            &pixels[y * width..(y + 1) * width],
            8,
            y,
            height,
            &mut table,
        );
    }
    (pixels, table)
}

#[test]
fn table_responses_are_the_plain_correlation_at_every_row_and_edge() {
    let (width, height) = (37usize, 29usize);
    let (pixels, table) = random_table(width, height, 4242);
    let diff = Frame::new(&pixels[..], width, height, width).unwrap();
    for sigma in [0.6 as Real, 1.0, 2.0] {
        let (taps, len) = kernel(sigma);
        let taps = &taps[..len];
        let k = IntKernel::new(taps).expect("every kernel has an integer form");
        for rows in [0..3, 3..12, 20..height, 0..height] {
            for x0 in [0usize, 8, 32] {
                let col = &table[x0 / 8 * height..(x0 / 8 + 1) * height];
                let mut seen = Vec::new();
                faint_sums::column_responses(col, rows.clone(), &k, |v, r| seen.push((v, r)));
                let plain: Vec<(usize, i32)> = rows
                    .clone()
                    .map(|v| (v, plain_response(&diff, x0, 8, v, taps) as i32))
                    .collect();
                assert_eq!(seen, plain, "σ {sigma}, rows {rows:?}, block at {x0}");
                // The noise pass's statistics: Σ|r| and the first strongest positive one.
                let mut expect = faint_sums::ColumnStats::default();
                for &(v, r) in &plain {
                    expect.abs_sum += r.unsigned_abs() as u64;
                    if r > expect.best {
                        (expect.best, expect.best_row) = (r, v);
                    }
                }
                assert_eq!(faint_sums::column_stats(col, rows.clone(), &k), expect);
                // Taken in two parts and merged, as the read-out and the search do.
                let mid = (rows.start + rows.end) / 2;
                let mut parts = faint_sums::column_stats(col, rows.start..mid, &k);
                parts.merge(faint_sums::column_stats(col, mid..rows.end, &k));
                assert_eq!(parts, expect, "σ {sigma}, rows {rows:?}, split at {mid}");
            }
        }
    }
}

#[test]
fn the_read_out_noise_pass_in_steps_is_the_whole_pass() {
    let (width, height) = (37usize, 61usize);
    let blocks = width.div_ceil(8);
    let (_, table) = random_table(width, height, 99);
    let (taps, len) = kernel(1.0);
    let k = IntKernel::new(&taps[..len]).unwrap();
    let band = |blk: usize| (blk * 3)..(height - blk);
    let mut columns = std::vec![faint_sums::FaintColumn::ZERO; blocks];
    let mut pass = faint_sums::FaintReadout::begin(k, blocks, height, &mut columns, band).unwrap();
    // Budgets of 0–3 rows per step, as the rows arrive.
    let per_row = faint_sums::RESPONSE_COST * blocks as u32;
    let overhead = faint_sums::COLUMN_COST * blocks as u32;
    for y in 0..height - 1 {
        pass.step(&table, &mut columns, y, overhead + per_row * (y % 4) as u32);
    }
    let done = pass.rows_done();
    assert!(
        done > 10 && done < height - len / 2,
        "{done} rows in the read-out"
    );
    for (blk, c) in columns.iter().enumerate() {
        let col = &table[blk * height..(blk + 1) * height];
        assert_eq!(c.band(), band(blk));
        let mut stats = c.stats();
        stats.merge(faint_sums::column_stats(
            col,
            done.max(band(blk).start)..band(blk).end,
            &k,
        ));
        assert_eq!(
            stats,
            faint_sums::column_stats(col, band(blk), &k),
            "block {blk}"
        );
    }
}

#[test]
fn the_block_sums_and_the_read_out_pass_change_nothing() {
    let cal = calibration(1);
    let (mut off, mut on) = render(&cal, &[0], 1.8, 250..550, 2.5, 60);
    add_noise(&mut off, &mut on, 1.0, 11);
    let (off_f, on_f) = frames(&off, &on);
    let config = PipelineConfig::default();
    // Everything; no read-out noise pass (the responses after the frame); no table (the
    // responses from the pixels).
    let mut results = Vec::new();
    for case in 0..3 {
        let mut b = buffers(1);
        let mut ws = b.workspace();
        if case >= 1 {
            ws.faint_columns = &mut [];
        }
        if case == 2 {
            ws.block_sums = &mut [];
        }
        let profile = extract_profile(&off_f, &on_f, &cal, &config, &mut ws).unwrap();
        assert!(profile.faint);
        let (s, e) = profile.plane_points[0];
        results.push((profile, ws.curve[s..e].to_vec(), ws.points[s..e].to_vec()));
    }
    assert_eq!(results[0], results[1]);
    assert_eq!(results[0], results[2]);
    // The first case did take most rows in the read-out (the stream as the device runs it).
    let mut b = buffers(1);
    let mut ws = b.workspace();
    ws.diff[..W * H].copy_from_slice(&off);
    let mut stream = crate::pipeline::ProfileStream::begin(&mut ws, &cal, &config, 8).unwrap();
    for block in on.chunks(crate::pipeline::BLOCK_ROWS * W) {
        stream.push_rows(&mut ws, block).unwrap();
    }
    let done = stream.faint_rows_done();
    assert!(done > H / 2, "{done} rows during the read-out");
}

#[test]
fn dual_multiply_accumulate_is_the_lane_arithmetic() {
    let mut n = Noise(5);
    for _ in 0..10_000 {
        let x = [(n.uniform() * 4096.0) as i32, (n.uniform() * 4096.0) as i32];
        let k = [
            (n.uniform() * 2048.0) as i32 - 1024,
            (n.uniform() * 2048.0) as i32 - 1024,
        ];
        let acc = (n.uniform() * 1e6) as i32 - 500_000;
        let pack = |a: [i32; 2]| (a[0] as i16 as u16 as u32) | (a[1] as i16 as u16 as u32) << 16;
        assert_eq!(
            faint_sums::dot2(acc, pack(x), pack(k)),
            acc + x[0] * k[0] + x[1] * k[1]
        );
    }
}
