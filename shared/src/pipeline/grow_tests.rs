//! Tests of the growth on a rendered glossy-like stripe: a bright middle (the highlight) and
//! faint sides that Otsu's threshold drops.
#![allow(clippy::unnecessary_cast)]

extern crate std;
use super::super::faint::tests::{add_noise, wall_row};
use super::super::tests::{buffers, calibration, frames, render};
use super::*;
use crate::pipeline::{extract_profile, PipelineConfig};

/// Columns 150..600 lit at 25 DN, 300..450 at 200 DN, σ = 1.5 DN per frame.
fn highlight_pair() -> (std::vec::Vec<u8>, std::vec::Vec<u8>, Real) {
    let cal = calibration(1);
    let z = 1.0;
    let (mut off, mut on) = render(&cal, &[0], z, 150..600, 25.0, 20);
    let (_, bright) = render(&cal, &[0], z, 300..450, 200.0, 20);
    for (o, b) in on.iter_mut().zip(&bright) {
        *o = (*o).max(*b);
    }
    add_noise(&mut off, &mut on, 1.5, 3);
    (off, on, z)
}

#[test]
fn the_faint_sides_are_grown_onto_the_curve() {
    let cal = calibration(1);
    let (off, on, z) = highlight_pair();
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let mut ws = b.workspace();
    let cut = extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap();
    let (s, e) = cut.plane_points[0];
    // The threshold keeps the highlight only.
    assert!(e - s <= 160, "{} points without growth", e - s);

    let config = PipelineConfig {
        grow: Some(GrowParams::default()),
        ..PipelineConfig::default()
    };
    let grown = extract_profile(&off_f, &on_f, &cal, &config, &mut ws).unwrap();
    let (s, e) = grown.plane_points[0];
    let curve = &ws.curve[s..e];
    // The whole lit range, in column order, each column once.
    assert!(e - s >= 440, "{} points with growth", e - s);
    assert!(curve[0].column <= 152 && curve[e - s - 1].column >= 597);
    assert!(curve.windows(2).all(|w| w[0].column < w[1].column));
    // The grown points are stripe centres: a 25 DN stripe over a difference noise of
    // ≈ 2.1 DN locates to ≈ 0.1 px; 0.5 px bounds every column (5σ).
    for p in curve {
        let truth = wall_row(&cal, p.column as Real, z);
        assert!(
            (p.row - truth).abs() < 0.5,
            "column {}: {} vs {truth}",
            p.column,
            p.row
        );
    }
}

#[test]
fn noise_beyond_the_stripe_is_not_grown() {
    let cal = calibration(1);
    let z = 1.0;
    let (mut off, mut on) = render(&cal, &[0], z, 300..450, 200.0, 20);
    add_noise(&mut off, &mut on, 1.5, 5);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let mut ws = b.workspace();
    let config = PipelineConfig {
        grow: Some(GrowParams::default()),
        ..PipelineConfig::default()
    };
    let profile = extract_profile(&off_f, &on_f, &cal, &config, &mut ws).unwrap();
    let (s, e) = profile.plane_points[0];
    let curve = &ws.curve[s..e];
    // At most the stripe's own blurred edge column on each side.
    assert!(curve[0].column >= 298 && curve[e - s - 1].column <= 451);
}

/// Where the read-out located a grown column's point, growth takes it (`located`) instead of
/// locating it again; where it did not, the estimator runs.
#[test]
fn growth_takes_the_points_located_during_the_readout() {
    use crate::curve::{CurvePoint, ExtractParams};
    use crate::image::Frame;
    // A level stripe on row 20, 50 DN, columns 0..64 of a 64 × 40 difference frame.
    let (w, h) = (64usize, 40usize);
    let mut diff = std::vec![0u8; w * h];
    for x in 0..w {
        diff[19 * w + x] = 20;
        diff[20 * w + x] = 50;
        diff[21 * w + x] = 20;
    }
    let frame = Frame::new(&diff[..], w, h, w).unwrap();
    let point = |column: u16, row: Real| CurvePoint {
        column,
        row,
        amplitude: 50.0,
        curve: 0,
        saturated: false,
        width: 1.0,
    };
    let grow = |marked: bool| {
        let mut curve = std::vec![point(0, 0.0); 80];
        for (k, x) in (28..36).enumerate() {
            curve[k] = point(x, 20.0);
        }
        let mut planes = [(0usize, 8usize); crate::calibration::MAX_PLANES];
        let n = grow_curves(
            &frame,
            &mut curve,
            8,
            &mut planes,
            1,
            &ExtractParams::default(),
            1.0,
            &GrowParams::default(),
            // Columns below 10 "were located during the read-out" at a marked row.
            |_, x, row, _| (marked && x < 10).then(|| Some(point(x as u16, row as Real + 0.25))),
        );
        curve.truncate(n);
        curve
    };
    let plain = grow(false);
    let marked = grow(true);
    assert_eq!(plain.len(), w, "grown to every column of the frame");
    for (p, m) in plain.iter().zip(&marked) {
        assert_eq!(p.column, m.column);
        if m.column < 10 {
            assert_eq!(m.row, 20.25, "column {}: the read-out's point", m.column);
        } else {
            assert_eq!(m.row, p.row, "column {}: located here", m.column);
        }
    }
    assert!((plain[0].row - 20.0).abs() < 1e-3);
}

/// The grown columns whose stripe was a candidate during the read-out take the point located
/// then (`grow_curves`' `located`): the same points as locating them again after the frame.
#[test]
fn grown_points_from_the_readout_are_those_located_after_the_frame() {
    let cal = calibration(1);
    let (off, on, _) = highlight_pair();
    let (off_f, on_f) = frames(&off, &on);
    let config = PipelineConfig {
        grow: Some(GrowParams::default()),
        ..PipelineConfig::default()
    };
    let mut b = buffers(1);
    let mut ws = b.workspace();
    let early = extract_profile(&off_f, &on_f, &cal, &config, &mut ws).unwrap();
    let (s, e) = early.plane_points[0];
    let early_curve = ws.curve[s..e].to_vec();
    // The faint sides (25 DN) are above the provisional threshold: the read-out located them.
    let located_faint = ws
        .readout_fits
        .iter()
        .filter(|f| f.found && f.amplitude > 10.0 && f.amplitude < 60.0)
        .count();
    assert!(
        located_faint > 100,
        "{located_faint} faint points located early"
    );
    let mut b = buffers(1);
    let mut ws = b.workspace();
    ws.column_tracks = &mut [];
    let late = extract_profile(&off_f, &on_f, &cal, &config, &mut ws).unwrap();
    assert_eq!(early, late);
    assert_eq!(early_curve, ws.curve[s..e].to_vec());
}

/// Moving the grown points through the free tail gives the rotation's order, at either end
/// (reversed or not) and whether or not the tail has room.
#[test]
fn grown_points_go_where_the_rotation_put_them() {
    let point = |i: usize| CurvePoint {
        column: i as u16,
        row: i as Real,
        ..CurvePoint::ZERO
    };
    let (n, g) = (23, 5);
    for reverse in [false, true] {
        for at in [0, 7, n] {
            for len in [n + g, n + 2 * g, n + 3 * g] {
                let mut moved: std::vec::Vec<CurvePoint> = (0..len).map(point).collect();
                let mut rotated = moved.clone();
                insert_grown(&mut moved, at, n, g, reverse);
                if reverse {
                    rotated[n..n + g].reverse();
                }
                rotated[at..n + g].rotate_right(g);
                assert_eq!(moved[..n + g], rotated[..n + g], "at {at}, len {len}");
            }
        }
    }
}
