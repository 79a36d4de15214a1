//! Tests of the laser curve extraction (`super`).

// Casts between `Real` and f64 are no-ops in f64 builds but needed with `--features f32`.
#![allow(clippy::unnecessary_cast, clippy::type_complexity)]

use super::*;
extern crate std;

const W: usize = 40;
const H: usize = 48;
const SIGMA: f64 = 1.2;
const AMP: f64 = 800.0; // 10-bit sensor

/// Pixel-integrated Gaussian across rows (exact, erf) with unit centre pixel at σ.
fn integrated(y: usize, mu: f64, amp: f64) -> f64 {
    let k = SIGMA * core::f64::consts::SQRT_2;
    let v = libm::erf((y as f64 + 0.5 - mu) / k) - libm::erf((y as f64 - 0.5 - mu) / k);
    amp * v / (2.0 * libm::erf(0.5 / k))
}

/// Stripe rows as a function of the column: a sinusoid (known analytically).
fn row_a(x: usize) -> f64 {
    14.0 + 4.5 * libm::sin(2.0 * core::f64::consts::PI * x as f64 / 23.0)
}
fn row_b(x: usize) -> f64 {
    33.3 + 0.05 * x as f64
}

/// Renders the stripes (10-bit, rounded) and labels pixels above 10 % with their label.
fn scene(stripes: &[(u16, fn(usize) -> f64, f64)]) -> ([u16; W * H], [u16; W * H]) {
    let mut diff = [0u16; W * H];
    let mut labels = [0u16; W * H];
    for y in 0..H {
        for x in 0..W {
            for &(label, row, amp) in stripes {
                let v = integrated(y, row(x), amp);
                let q = libm::round(v).min(1023.0) as u16;
                diff[y * W + x] = diff[y * W + x].saturating_add(q).min(1023);
                if v > 0.1 * AMP {
                    labels[y * W + x] = label;
                }
            }
        }
    }
    (diff, labels)
}

fn frames<'a>(d: &'a [u16], l: &'a [u16]) -> (Frame<u16, &'a [u16]>, Frame<u16, &'a [u16]>) {
    (
        Frame::new(d, W, H, W).unwrap().with_bit_depth(10).unwrap(),
        Frame::new(l, W, H, W).unwrap(),
    )
}

// Tolerance of a row: the default estimator's bias on a noise-free pixel-integrated
// Gaussian (≤ 0.005 px, peaks tests) plus the quantisation: rounding to 1 DN is noise
// of 1/√12 DN ≈ 0.29 DN on an 800 DN stripe, which moves a Gaussian fit by about
// σ·(0.29/800)·√(2/N) ≈ 3e-4 px; 0.01 px leaves a wide margin for f32 rounding.
const TOL: Real = 0.01;

#[test]
fn extracts_a_sinusoidal_stripe_at_its_analytic_rows() {
    let (d, l) = scene(&[(7, row_a, AMP)]);
    let (diff, labels) = frames(&d, &l);
    let mut out = [CurvePoint::ZERO; 64];
    let n = extract(&diff, &labels, &[7], &ExtractParams::default(), &mut out).unwrap();
    assert_eq!(n, W);
    for (x, p) in out[..n].iter().enumerate() {
        assert_eq!(p.column as usize, x);
        assert_eq!(p.curve, 0);
        assert!(!p.saturated);
        assert!(
            (p.row - row_a(x) as Real).abs() < TOL,
            "column {x}: {p:?} vs {}",
            row_a(x)
        );
        assert!(
            (p.amplitude - AMP as Real).abs() < 0.02 * AMP as Real,
            "{p:?}"
        );
    }
}

#[test]
fn extracts_two_curves_per_column_in_selection_order() {
    let (d, l) = scene(&[(3, row_a, AMP), (5, row_b, 0.6 * AMP)]);
    let (diff, labels) = frames(&d, &l);
    let mut out = [CurvePoint::ZERO; 128];
    // Label 5 first: curve 0 is the lower stripe.
    let n = extract(&diff, &labels, &[5, 3], &ExtractParams::default(), &mut out).unwrap();
    assert_eq!(n, 2 * W);
    for x in 0..W {
        let (p0, p1) = (out[2 * x], out[2 * x + 1]);
        assert_eq!((p0.column as usize, p0.curve), (x, 0));
        assert_eq!((p1.column as usize, p1.curve), (x, 1));
        // The stripes are ≥ 10σ apart, so each profile holds one stripe.
        assert!((p0.row - row_b(x) as Real).abs() < TOL, "{p0:?}");
        assert!((p1.row - row_a(x) as Real).abs() < TOL, "{p1:?}");
    }
}

#[test]
fn window_over_the_labels_gives_the_same_points() {
    let (d, l) = scene(&[(3, row_a, AMP), (5, row_b, 0.6 * AMP)]);
    let (diff, labels) = frames(&d, &l);
    let blank = CurvePoint::ZERO;
    let params = ExtractParams::default();
    let mut full = [blank; 128];
    let n = extract(&diff, &labels, &[5, 3], &params, &mut full).unwrap();
    // The labels' bounding box, found independently by scanning the label frame.
    let (mut y0, mut y1) = (H, 0);
    for (i, &lab) in l.iter().enumerate() {
        if lab == 3 || lab == 5 {
            y0 = y0.min(i / W);
            y1 = y1.max(i / W + 1);
        }
    }
    assert!(
        y0 > 0 && y1 < H,
        "the box must be a real restriction: {y0}..{y1}"
    );
    let mut win = [blank; 128];
    let m = extract_window(&diff, &labels, &[5, 3], 0..W, y0..y1, &params, &mut win).unwrap();
    assert_eq!(&win[..m], &full[..n]);
    // Columns outside the window give no point; the others are unchanged. A window
    // reaching past the frame is clamped to it.
    let m = extract_window(
        &diff,
        &labels,
        &[5, 3],
        10..W + 5,
        y0..H + 9,
        &params,
        &mut win,
    )
    .unwrap();
    assert_eq!(&win[..m], &full[20..n]);
    // A window that misses every label finds no curve.
    assert_eq!(
        extract_window(&diff, &labels, &[5, 3], 0..W, 0..y0, &params, &mut win),
        Err(CurveError::NoCurve)
    );
}

#[test]
fn flags_saturated_columns_and_still_locates_them() {
    fn row_c(x: usize) -> f64 {
        20.0 + 0.137 * x as f64
    }
    let (d, l) = scene(&[(1, row_c, 1.5 * 1023.0)]);
    let (diff, labels) = frames(&d, &l);
    let mut out = [CurvePoint::ZERO; 64];
    let n = extract(&diff, &labels, &[1], &ExtractParams::default(), &mut out).unwrap();
    assert_eq!(n, W);
    for (x, p) in out[..n].iter().enumerate() {
        assert!(p.saturated, "{p:?}");
        // Saturated-peak bound of the peaks tests (0.01 px) plus quantisation (as TOL).
        assert!(
            (p.row - row_c(x) as Real).abs() < 0.01 + TOL,
            "{p:?} vs {}",
            row_c(x)
        );
    }
}

#[test]
fn error_cases() {
    let (d, l) = scene(&[(7, row_a, AMP)]);
    let (diff, labels) = frames(&d, &l);
    let params = ExtractParams::default();
    let mut small = [CurvePoint::ZERO; 5];
    assert_eq!(
        extract(&diff, &labels, &[7], &params, &mut small),
        Err(CurveError::OutputFull { capacity: 5 })
    );
    // The points written before the buffer filled are valid.
    assert!((small[4].row - row_a(4) as Real).abs() < TOL);
    let mut out = [small[0]; 64];
    assert_eq!(
        extract(&diff, &labels, &[8], &params, &mut out),
        Err(CurveError::NoCurve)
    );
    assert_eq!(
        extract(&diff, &labels, &[], &params, &mut out),
        Err(CurveError::NoCurve)
    );
    assert_eq!(
        extract(
            &diff,
            &labels,
            &[1, 2, 3, 4, 5, 6, 7, 8, 9],
            &params,
            &mut out
        ),
        Err(CurveError::TooManyCurves { selected: 9 })
    );
    let bad = ExtractParams {
        half_window: 0,
        ..params
    };
    assert_eq!(
        extract(&diff, &labels, &[7], &bad, &mut out),
        Err(CurveError::WindowOutOfRange { half_window: 0 })
    );
    let small_labels = Frame::new(&l[..W * 10], W, 10, W).unwrap();
    assert!(matches!(
        extract(&diff, &small_labels, &[7], &params, &mut out),
        Err(CurveError::Frame(FrameError::SizeMismatch { .. }))
    ));
    assert_eq!(
        smooth(
            &mut out,
            &SmoothParams {
                half_window: MAX_SMOOTH_HALF_WINDOW + 1,
                max_row_jump: 1.0
            }
        ),
        Err(CurveError::WindowOutOfRange {
            half_window: MAX_SMOOTH_HALF_WINDOW + 1
        })
    );
}

fn pt(column: u16, row: Real, curve: u8) -> CurvePoint {
    CurvePoint {
        column,
        row,
        amplitude: 1.0,
        curve,
        saturated: false,
        width: 1.0,
    }
}

/// A curve's run smoothed alone (consecutive points: `smooth_contiguous`) and interleaved with
/// another curve (the index ring of `smooth_run`) gets the same rows, bit for bit, for every
/// half window and run length, the short runs whose windows are never full included.
#[test]
fn consecutive_and_interleaved_runs_are_smoothed_alike() {
    let row = |x: u16| 10.0 + 0.3 * x as Real + 0.37 * libm::sin(x as f64 * 1.7) as Real;
    for half_window in 2..=MAX_SMOOTH_HALF_WINDOW {
        for len in [1u16, 3, 5, 6, 9, 17, 40] {
            let params = SmoothParams {
                half_window,
                max_row_jump: 2.0,
            };
            let mut alone: std::vec::Vec<CurvePoint> = (0..len).map(|x| pt(x, row(x), 0)).collect();
            let mut mixed: std::vec::Vec<CurvePoint> = (0..len)
                .flat_map(|x| [pt(x, row(x), 0), pt(x, 30.0, 1)])
                .collect();
            smooth(&mut alone, &params).unwrap();
            smooth(&mut mixed, &params).unwrap();
            let rows = |v: &[CurvePoint]| -> std::vec::Vec<u64> {
                v.iter()
                    .filter(|p| p.curve == 0)
                    .map(|p| p.row.to_bits() as u64)
                    .collect()
            };
            assert_eq!(
                rows(&alone),
                rows(&mixed),
                "half window {half_window}, {len} points"
            );
        }
    }
}

#[test]
fn smoothing_keeps_parabolas_removes_jitter_and_respects_gaps() {
    // Two interleaved curves: curve 0 a parabola with ±0.1 px alternating jitter over
    // columns 0..30, curve 1 a constant row 5 for columns 0..10 and 20 for 11..20 (a
    // jump: two runs).
    let mut pts = [pt(0, 0.0, 0); 51];
    let parabola = |x: Real| 10.0 + 0.3 * x - 0.01 * x * x;
    let mut k = 0;
    for x in 0..31u16 {
        let jitter = if x % 2 == 0 { 0.1 } else { -0.1 };
        pts[k] = pt(x, parabola(x as Real) + jitter, 0);
        k += 1;
        if x < 20 {
            pts[k] = pt(x, if x <= 10 { 5.0 } else { 20.0 }, 1);
            k += 1;
        }
    }
    assert_eq!(k, 51);
    smooth(
        &mut pts,
        &SmoothParams {
            half_window: 4,
            max_row_jump: 2.0,
        },
    )
    .unwrap();
    for p in &pts {
        if p.curve == 1 {
            // A quadratic filter reproduces constants exactly; a filter that crossed the
            // jump would pull the rows next to it toward the other level.
            let want = if p.column <= 10 { 5.0 } else { 20.0 };
            assert!((p.row - want).abs() < 1e-4, "{p:?}");
        } else {
            let x = p.column as Real;
            // Savitzky–Golay keeps the parabola exactly; the ±0.1 alternation is scaled by
            // |Σ_j c_j (−1)^j| of the window used: with c_j = 3(3m²+3m−1−5j²) /
            // ((2m+1)(4m²+4m−3)) this is 41/231 for m = 4, 25/105 for m = 3, 13/35 for
            // m = 2, and 1 (unfiltered) for m ≤ 1, the window shrinking at the run's ends.
            let last = 30u16;
            let m = 4.min(p.column).min(last - p.column);
            let gain: Real = match m {
                4 => 41.0 / 231.0,
                3 => 25.0 / 105.0,
                2 => 13.0 / 35.0,
                _ => 1.0,
            };
            let bound = 0.1 * gain;
            assert!(
                (p.row - parabola(x)).abs() <= bound + 1e-4,
                "{p:?} vs {}",
                parabola(x)
            );
        }
    }
}
