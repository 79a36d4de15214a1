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
