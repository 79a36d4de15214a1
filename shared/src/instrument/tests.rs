//! A toy instrument added in a few lines, run through the real pipeline: the place the
//! sphere, wall and road instruments take.
#![allow(clippy::unnecessary_cast)]

use super::*;
use crate::pipeline::tests::{buffers, calibration, frames, render};
use crate::real::sqrt;

/// "How far is what the laser lights": the mean distance of the lit points from the camera.
struct MeanDistance;

impl Instrument for MeanDistance {
    const MODE: Mode = Mode::Wall;
    type Params = ();
    type Solution = Real;

    fn solve(
        points: &PlanePoints<'_>,
        _params: &(),
        scratch: Scratch<'_>,
    ) -> Result<Real, PipelineError> {
        // Distances into the scratch first, to show the solver's memory is lent to it.
        let mut n = 0;
        for p in points.curves().iter().flat_map(|c| c.iter()) {
            let slot = scratch.values.get_mut(n).ok_or(PipelineError::NoCurve)?;
            *slot = sqrt(p.dot(p));
            n += 1;
        }
        if n == 0 {
            return Err(PipelineError::NoCurve);
        }
        Ok(scratch.values[..n].iter().sum::<Real>() / n as Real)
    }
}

#[test]
fn a_toy_instrument_measures_through_the_real_pipeline() {
    let cal = calibration(1);
    let z = 1.2;
    let (off, on) = render(&cal, &[0], z, 300..450, 150.0, 12);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let config = PipelineConfig::default();
    let m = measure_with::<MeanDistance, u8>(&off_f, &on_f, &cal, &config, &(), &mut b.workspace())
        .unwrap();
    // The lit points lie on the wall z = 1.2 m within 0.35 mm (pipeline tests), 0.1–0.3 m
    // either side of the optical axis: their mean distance is between z and √(z² + 0.3²).
    assert!(
        m.solution > z - 0.35e-3 && m.solution < sqrt(z * z + 0.09),
        "{}",
        m.solution
    );
    assert_eq!(m.profile.points(b.points(), 0).len(), 150);
    assert_eq!(MeanDistance::MODE, Mode::Wall);
    // The toy is not in the dispatch: `measure` runs the real wall instrument, which needs
    // two lines on a wall and says so instead of guessing.
    let params = InstrumentParams::default();
    let err = measure(
        Mode::Wall,
        &off_f,
        &on_f,
        &cal,
        &config,
        &params,
        &mut b.workspace(),
    );
    assert_eq!(
        err,
        Err(PipelineError::Solve(crate::solvers::SolveError::SingleLine))
    );
}

#[test]
fn the_wall_instrument_measures_a_frontal_wall_through_the_real_pipeline() {
    // Both reference lines on a wall 1.2 m away, facing the camera, over 450 columns.
    let cal = calibration(2);
    let z = 1.2;
    let (off, on) = render(&cal, &[0, 1], z, 150..600, 150.0, 12);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(2);
    let config = PipelineConfig::default();
    let params = WallInstrumentParams::default();
    let m = measure_with::<Wall, u8>(&off_f, &on_f, &cal, &config, &params, &mut b.workspace())
        .unwrap();
    let s = &m.solution;
    assert_eq!(s.walls.len(), 1);
    let o = s.orientation;
    assert!((o.axis_distance.value - z).abs() < 1e-3, "{o:?}");
    assert!(
        o.yaw.value.abs() < 1e-3 && o.pitch.value.abs() < 0.02,
        "{o:?}"
    );
    // The lit part of the wall ends inside the frame at both sides: a bounded segment of
    // 450 columns at 1.2 m, i.e. 0.54 m.
    let seg = s.segment.unwrap();
    assert!(seg.bounded());
    assert!((seg.length.value - 0.54).abs() < 2e-3, "{seg:?}");
    // Through the dispatch: the same solution as a `Measurement::Wall`.
    let all = InstrumentParams::default();
    let reading = measure(
        Mode::Wall,
        &off_f,
        &on_f,
        &cal,
        &config,
        &all,
        &mut b.workspace(),
    );
    assert_eq!(reading, Ok(Measurement::from(s)));
    assert_eq!(reading.map(|r| r.kind()), Ok("wall"));
    // With one plane there is no wall to measure.
    let cal1 = calibration(1);
    let (off, on) = render(&cal1, &[0], z, 150..600, 150.0, 12);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let err = measure_with::<Wall, u8>(&off_f, &on_f, &cal1, &config, &params, &mut b.workspace());
    assert_eq!(
        err.map(|_| ()),
        Err(PipelineError::Solve(crate::solvers::SolveError::SingleLine))
    );
}

/// In sphere mode a plane whose curve is too short means a line missed the ball: the
/// sphere's refusal (with its advice), not the stem's "aim the lines at the stem"; the
/// other modes keep the image failure.
#[test]
fn a_missing_line_is_the_spheres_one_section_refusal() {
    use crate::solvers::SolveError;
    let short = PipelineError::CurveTooShort {
        plane: 1,
        points: 0,
    };
    assert_eq!(
        image_failure(Mode::Sphere, short),
        PipelineError::Solve(SolveError::OneSection)
    );
    for mode in [Mode::Cylinder, Mode::Road, Mode::Wall] {
        assert_eq!(image_failure(mode, short), short, "{mode:?}");
    }
    let dark = PipelineError::NoLaserLight { max_difference: 3 };
    assert_eq!(image_failure(Mode::Sphere, dark), dark);
    let mut advice = heapless::String::<256>::new();
    core::fmt::Write::write_fmt(&mut advice, format_args!("{}", SolveError::OneSection))
        .expect("fits");
    assert!(
        advice.contains("centre the ball between the two lines"),
        "{advice}"
    );
}

/// What `lend` lends: the points up to the profile's extent, the 3-D points past it as the
/// solver's bins, and the σ and scratch buffers whole (the road's profile trace is longer
/// than its points).
#[test]
fn lend_splits_the_points_at_the_profile_and_lends_the_rest_whole() {
    let cal = calibration(1);
    let (off, on) = render(&cal, &[0], 1.2, 300..450, 150.0, 12);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let mut ws = b.workspace();
    let (points_len, sigmas_len, values_len) =
        (ws.points.len(), ws.sigmas.len(), ws.scratch_values.len());
    let profile =
        extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap();
    assert_eq!(profile.extent(), 150);
    let (points, scratch) = lend(&profile, on_f.max_value(), &cal, &mut ws);
    assert_eq!(points.curves()[0].len(), 150);
    assert_eq!(scratch.bins.len(), points_len - 150);
    assert_eq!(scratch.sigmas.len(), sigmas_len);
    assert_eq!(scratch.values.len(), values_len);
}
