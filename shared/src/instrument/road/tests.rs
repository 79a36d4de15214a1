//! The road instrument through the real pipeline, on road profiles rendered analytically for
//! the road head: its MPD against the same chain run on the true profile, and its refusals.
#![allow(clippy::unnecessary_cast)]

extern crate std;
use std::vec;
use std::vec::Vec;

use super::*;
use crate::instrument::measure_with;
use crate::pipeline::tests::{buffers, frames};
use crate::pipeline::PipelineConfig;
use crate::real::{Vec2, PI};

const W: usize = 752;
const H: usize = 480;

/// Renders the road head's stripe on a road `z = standoff + offset − h(x)` for the columns
/// where `lit(u)`: per column, the point of the laser plane on the road (fixed point of
/// `z = z_road − h(x(z))`, `x = (u − cx)·z/f`), its row, and a Gaussian stripe. Returns the
/// frames and the true `(x, h)` of each lit column.
fn render_road(
    cal: &Calibration,
    offset: Real,
    h: impl Fn(Real) -> Real,
    lit: impl Fn(usize) -> bool,
) -> (Vec<u8>, Vec<u8>, Vec<Vec2>) {
    let (cam, plane) = (&cal.camera, cal.planes[0]);
    let off = vec![10u8; W * H];
    let mut on = off.clone();
    let mut truth = Vec::new();
    let sigma = 1.3;
    for u in (0..W).filter(|&u| lit(u)) {
        let mut z = ROAD_HEAD_STANDOFF + offset;
        for _ in 0..50 {
            z = ROAD_HEAD_STANDOFF + offset - h((u as Real - cam.cx) * z / cam.fx);
        }
        let x = (u as Real - cam.cx) * z / cam.fx;
        let y = (plane.offset - plane.normal.x * x - plane.normal.z * z) / plane.normal.y;
        let v0 = cam.cy + cam.fy * y / z;
        truth.push(Vec2::new(x, h(x)));
        for r in 0..H {
            let mut acc = 0.0;
            for s in 0..8 {
                let yy = r as Real - 0.5 + (s as Real + 0.5) / 8.0;
                acc += (-(yy - v0) * (yy - v0) / (2.0 * sigma * sigma)).exp();
            }
            let val = on[r * W + u] as Real + 150.0 * acc / 8.0;
            on[r * W + u] = val.round().min(255.0) as u8;
        }
    }
    (off, on, truth)
}

fn measure_road(off: &[u8], on: &[u8], cal: &Calibration) -> Result<RoadSolution, PipelineError> {
    let (off_f, on_f) = frames(off, on);
    let mut b = buffers(1);
    let config = PipelineConfig::default();
    measure_with::<Road, u8>(
        &off_f,
        &on_f,
        cal,
        &config,
        &RoadParams::default(),
        &mut b.workspace(),
    )
    .map(|m| m.solution)
}

/// The MPD chain on the true profile of the lit columns.
fn true_mpd(truth: &[Vec2]) -> Real {
    let params = RoadParams::default();
    let window: Vec<Vec2> = truth
        .iter()
        .copied()
        .filter(|p| {
            p.x >= params.profile.window_start
                && p.x <= params.profile.window_start + params.profile.window_length
        })
        .collect();
    let mut heights = vec![0.0; window.len()];
    let (mut resampled, mut marks) = (vec![0.0; 400], vec![0.0; 400]);
    let mut segments = [SegmentDepth::default(); MAX_SEGMENTS];
    mpd::mean_profile_depth(
        &window,
        params.profile.window_start,
        params.profile.window_length,
        &params.mpd,
        &mut heights,
        &mut resampled,
        &mut marks,
        &mut segments,
    )
    .unwrap()
    .mpd
}

fn macrotexture(x: Real) -> Real {
    1.5e-3 * (2.0 * PI * x / 0.02 + 0.3).sin()
        + 0.8e-3 * (2.0 * PI * x / 0.007 + 1.1).sin()
        + 0.3e-3 * (2.0 * PI * x / 0.003 + 2.0).sin()
}

#[test]
fn the_road_head_measures_the_mpd_of_the_true_profile() {
    let cal = road_head_calibration(7).unwrap();
    let (off, on, truth) = render_road(&cal, 0.0, macrotexture, |_| true);
    let s = measure_road(&off, &on, &cal).unwrap();
    let expected = true_mpd(&truth);
    assert!(expected > 1e-3, "{expected}");
    assert!(
        (s.depth.mpd - expected).abs() < 0.01e-3,
        "{} vs {expected}",
        s.depth.mpd
    );
    assert_eq!((s.depth.segments, s.depth.valid_segments), (1, 1));
    assert_eq!(s.profile.dropouts, 0);
    // 0.15 mm column footprint; the stand-off is the axis crossing.
    assert!(
        (s.profile.spacing - 0.15e-3).abs() < 0.01e-3,
        "{}",
        s.profile.spacing
    );
    assert!((s.standoff - ROAD_HEAD_STANDOFF).abs() < 1e-6);
    assert!(s.micro.is_some());
}

#[test]
fn a_flat_road_reads_flat_to_well_within_the_resolution_target() {
    let cal = road_head_calibration(7).unwrap();
    let (off, on, _) = render_road(&cal, 0.002, |_| 0.0, |_| true);
    let s = measure_road(&off, &on, &cal).unwrap();
    // Noise-free stripes: only the 8-bit quantisation and the subpixel estimator's bias.
    assert!(s.rms_height < 5e-6, "{}", s.rms_height);
    // 2 mm farther than the stand-off reads −2 mm.
    assert!(
        (s.profile.mean_height + 0.002).abs() < 20e-6,
        "{}",
        s.profile.mean_height
    );
}

#[test]
fn the_uncertainty_carries_the_texture_term_beside_the_column_noise() {
    // A noise-free flat road: the column-noise term is the 8-bit quantisation's alone, so
    // the one segment's 1σ is the texture-tied term's, and without it far below.
    let cal = road_head_calibration(7).unwrap();
    let (off, on, _) = render_road(&cal, 0.0, |_| 0.0, |_| true);
    let s = measure_road(&off, &on, &cal).unwrap();
    assert_eq!(s.depth.valid_segments, 1);
    let t = SEGMENT_TEXTURE_SIGMA;
    assert!(
        s.uncertainty >= t && s.uncertainty < 1.2 * t,
        "{}",
        s.uncertainty
    );
    let noise = sqrt(s.uncertainty * s.uncertainty - t * t);
    assert!(noise < 0.5 * t, "column-noise term {noise}");
}

#[test]
fn a_wet_patch_a_tilted_head_and_a_road_out_of_range_are_refused() {
    let cal = road_head_calibration(7).unwrap();
    // A 20 mm mirror-wet patch in the middle returns nothing. (The pipeline keeps one side
    // of a gap wider than `max_fragment_gap` columns, so the gap reads longer: the other
    // side, up to the window's end.)
    let (off, on, _) = render_road(&cal, 0.0, macrotexture, |u| !(300..433).contains(&u));
    match measure_road(&off, &on, &cal) {
        Err(PipelineError::Road(RoadError::DropoutGap { length, .. })) => {
            assert!(length > 0.019, "{length}")
        }
        other => panic!("{other:?}"),
    }
    // The head tilted 10° across the line.
    let tilt = (10.0 as Real).to_radians().tan();
    let (off, on, _) = render_road(&cal, 0.0, |x| tilt * x, |_| true);
    match measure_road(&off, &on, &cal) {
        Err(PipelineError::Road(RoadError::Tilted { angle })) => {
            assert!((angle.abs().to_degrees() - 10.0).abs() < 0.5, "{angle}")
        }
        other => panic!("{other:?}"),
    }
    // Lifted 25 mm off the road.
    let (off, on, _) = render_road(&cal, 0.025, |_| 0.0, |_| true);
    assert!(matches!(
        measure_road(&off, &on, &cal),
        Err(PipelineError::Road(RoadError::OutOfRange { .. }))
    ));
}

#[test]
fn the_road_instrument_alone_takes_its_curve_unsmoothed_and_in_fragments() {
    use crate::instrument::pipeline_config;
    use crate::measurement::Mode;
    let base = PipelineConfig::default();
    assert!(base.smooth.half_window > 1);
    let road = pipeline_config(Mode::Road, &base);
    assert_eq!(road.smooth.half_window, 0);
    assert_eq!(road.max_fragments, crate::curve::MAX_CURVES);
    // Scattered drop-outs: pieces taller than wide are kept and the curve grown through them.
    assert_eq!(road.selection.max_height_to_width, Real::INFINITY);
    assert!(road.grow.is_some());
    assert_eq!(
        PipelineConfig {
            smooth: base.smooth,
            max_fragments: base.max_fragments,
            selection: base.selection,
            grow: base.grow,
            ..road
        },
        base
    );
    // The stem and the sphere grow their curves along the stripe (`pipeline::grow`); the
    // sphere also ranks arcs before lines (`pipeline::arcs`); nothing else changes.
    for mode in [Mode::Cylinder, Mode::Sphere] {
        let grown = pipeline_config(mode, &base);
        assert!(grown.grow.is_some());
        assert_eq!(grown.arcs_first, mode == Mode::Sphere);
        assert_eq!(
            PipelineConfig {
                grow: base.grow,
                arcs_first: base.arcs_first,
                ..grown
            },
            base
        );
    }
    // The wall assigns other surfaces' pieces by depth agreement (`pipeline::fragments`) and
    // changes nothing else.
    let wall = pipeline_config(Mode::Wall, &base);
    assert!(wall.stacks.is_some());
    assert_eq!(
        PipelineConfig {
            stacks: base.stacks,
            ..wall
        },
        base
    );
}
