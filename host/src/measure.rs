//! Replaying captures through the measurement core: a capture in, a [`Reading`] out.
//!
//! The capture's mode selects the instrument; the host runs exactly the core's
//! `instrument::measure_with` that the firmware runs, with its buffers on the heap
//! (`OwnedBuffers`); this module only picks the frames, converts units for people
//! (millimetres, degrees) and names the flags (`protocol::codes`).

use std::borrow::Cow;
use std::path::Path;

use tangent_core::calibration::Calibration;
use tangent_core::curve::CurvePoint;
use tangent_core::image::{Frame, Pixel};
use tangent_core::instrument::road::RoadParams;
use tangent_core::instrument::sphere::SphereMeasurement;
use tangent_core::instrument::stem::StemMeasurement;
use tangent_core::instrument::wall::WallMeasurement;
use tangent_core::instrument::{
    self, Instrument, Measured, Road, Sphere, Stem, Wall, WallInstrumentParams,
};
use tangent_core::pipeline::{OwnedBuffers, PipelineConfig, PipelineError, Profile};
use tangent_core::real::Vec3;
use tangent_core::solvers::sphere::SphereParams;
use tangent_core::solvers::stem::{combine_exposures, CylinderParams};

use crate::capture::{Capture, CaptureError, Mode};
use crate::pgm::{Pgm, PgmSamples};
use crate::road::RoadOutcome;
use crate::truth::Object;

mod reading;
pub use reading::{Reading, TiltReport};

type Vec3d = nalgebra::Vector3<f64>;

/// Why a capture could not be measured (as opposed to a measurement that failed, which is a
/// [`Reading`] with an error).
#[derive(Debug, thiserror::Error)]
pub enum MeasureError {
    /// The capture could not be read.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// The capture is not of a mode this command measures.
    #[error("capture mode {0:?} is not measured here (cylinder, sphere and wall captures are; road captures by `measure_road`)")]
    UnsupportedMode(Mode),
    /// No frame lit every plane of the calibration.
    #[error("no laser-on frame lights all {0} planes of the calibration")]
    NoFullFrame(usize),
    /// A wall capture whose laser planes across the image are lit only in frames of their
    /// own: a laser-calibration capture (a chessboard's stripes), not a wall measurement.
    #[error("a laser-calibration capture (each laser plane in a frame of its own, as for the chessboard poses of `tangent calibrate`), not a wall measurement: walls are measured from a capture that lights the parallel lines in one frame")]
    CalibrationCapture,
    /// The off and on frames differ in bit depth.
    #[error("the laser-off and laser-on frames differ in bit depth")]
    MixedDepth,
    /// The capture's `[accelerometer]` table gives no vertical reference.
    #[error("capture.toml [accelerometer]: {0}")]
    Accelerometer(String),
    /// The calibration's `[planes_uncertainty]` does not cover the planes across the image
    /// of a three-line wall capture.
    #[error("calibration [planes_uncertainty]: {0}")]
    Uncertainty(tangent_core::calibration::UncertaintyError),
}

/// The core's detailed solution of one capture, by instrument.
// The stem's solution is kept inline (the common case); the walls' is boxed.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum Solved {
    /// A stem ([`Mode::Cylinder`]).
    Stem(StemMeasurement),
    /// A sphere ([`Mode::Sphere`]).
    Sphere(SphereMeasurement),
    /// Walls ([`Mode::Wall`]; boxed: four planes and the runs are large beside a stem).
    Wall(Box<WallMeasurement>),
}

impl Solved {
    /// The image summary the solution came from.
    pub fn profile(&self) -> &Profile {
        match self {
            Solved::Stem(m) => &m.profile,
            Solved::Sphere(m) => &m.profile,
            Solved::Wall(m) => &m.profile,
        }
    }
}

/// What a measurement of one capture produced, with the buffers for plots.
pub struct Outcome {
    /// The result, for printing and JSON.
    pub reading: Reading,
    /// The core's result.
    pub result: Result<Solved, PipelineError>,
    /// The difference frame (as 16-bit, whatever the sensor depth) and its size.
    pub diff: Vec<u16>,
    /// The curve points (all planes).
    pub curve: Vec<CurvePoint>,
    /// The 3-D points (all planes).
    pub points: Vec<Vec3>,
    /// The calibration used.
    pub calibration: Calibration,
}

/// The laser-off frame and a laser-on frame lighting every plane of `planes`: the capture's
/// own when one frame lit them all (how the device captures), otherwise the composite of its
/// per-plane frames (see [`composite_on_frame`]).
fn frame_pair(capture: &Capture, planes: usize) -> Result<(&Pgm, Cow<'_, Pgm>), MeasureError> {
    let off = capture.off_frame();
    if let Some((_, on)) = capture
        .on_frames()
        .find(|(lit, _)| (0..planes).all(|k| lit.contains(&k)))
    {
        return Ok((off, Cow::Borrowed(on)));
    }
    composite_on_frame(capture, planes)
        .map(|on| (off, Cow::Owned(on)))
        .ok_or(MeasureError::NoFullFrame(planes))
}

/// Builds the laser-on frame of all `planes` from frames that lit them separately:
/// `off + Σ_k (on_k − off)`, clamped to the sensor range. Each difference carries one plane's
/// stripe; adding them keeps the ambient level of `off` and so the pipeline's subtraction
/// returns both stripes, unbiased (the noise of the frames adds, as two exposures do).
/// `None` when some plane is in no frame or the frames differ in size or depth.
pub fn composite_on_frame(capture: &Capture, planes: usize) -> Option<Pgm> {
    let off = capture.off_frame();
    let mut chosen: Vec<&Pgm> = Vec::new();
    for k in 0..planes {
        let (_, f) = capture.on_frames().find(|(lit, _)| lit.contains(&k))?;
        if !chosen.iter().any(|c| std::ptr::eq(*c, f)) {
            chosen.push(f);
        }
    }
    let off_px = off.to_u16();
    let mut acc: Vec<i64> = off_px.iter().map(|&v| v as i64).collect();
    for f in &chosen {
        if (f.width, f.height, f.maxval) != (off.width, off.height, off.maxval) {
            return None;
        }
        for ((a, &on), &o) in acc.iter_mut().zip(f.to_u16().iter()).zip(&off_px) {
            *a += on as i64 - o as i64;
        }
    }
    let max = off.maxval as i64;
    let clamp = |v: i64| v.clamp(0, max);
    match off.samples {
        PgmSamples::U8(_) => Pgm::from_u8(
            off.width,
            off.height,
            off.maxval as u8,
            acc.iter().map(|&v| clamp(v) as u8).collect(),
        )
        .ok(),
        PgmSamples::U16(_) => Pgm::from_u16(
            off.width,
            off.height,
            off.maxval,
            acc.iter().map(|&v| clamp(v) as u16).collect(),
        )
        .ok(),
    }
}

fn run<I: Instrument, P: Pixel>(
    off: &[P],
    on: &[P],
    pgm: &Pgm,
    calibration: &Calibration,
    config: &PipelineConfig,
    params: &I::Params,
) -> (
    Result<Measured<I::Solution>, PipelineError>,
    OwnedBuffers<P>,
) {
    let planes = calibration.planes.len();
    let mut hw = OwnedBuffers::<P>::for_frame(pgm.width, pgm.height, pgm.bit_depth(), planes);
    let result = (|| {
        let off =
            Frame::new(off, pgm.width, pgm.height, pgm.width)?.with_bit_depth(pgm.bit_depth())?;
        let on =
            Frame::new(on, pgm.width, pgm.height, pgm.width)?.with_bit_depth(pgm.bit_depth())?;
        instrument::measure_with::<I, P>(
            &off,
            &on,
            calibration,
            config,
            params,
            &mut hw.workspace(),
        )
    })();
    (result, hw)
}

/// The sphere solver's settings with the noise model and focal length of the stem's (one
/// head, one noise model).
pub fn sphere_params(params: &CylinderParams) -> SphereParams {
    SphereParams {
        noise: params.noise,
        focal_px: params.focal_px,
        ..SphereParams::default()
    }
}

/// The true diameter of the ball of a synthetic sphere capture: the sphere whose centre is
/// nearest the optical axis.
pub fn truth_sphere_diameter(capture: &Capture) -> Option<f64> {
    let objects = &capture.meta.truth.as_ref()?.objects;
    objects
        .iter()
        .filter_map(|o| match o {
            Object::Sphere(s) => Some((s.centre_m[0].hypot(s.centre_m[1]), s.diameter_m()?)),
            _ => None,
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, d)| d)
}

/// The true diameter of the aimed stem of a synthetic capture, when it carries ground truth:
/// the cylinder whose axis passes nearest the optical axis; its diameter is `2r`, or for an
/// elliptic section the mean of its two axes `a + b` (what cross-calipering reports).
pub fn truth_diameter(capture: &Capture) -> Option<f64> {
    let objects = &capture.meta.truth.as_ref()?.objects;
    objects
        .iter()
        .filter_map(|o| match o {
            Object::Cylinder(c) => {
                let d = c
                    .radius_m
                    .map(|r| 2.0 * r)
                    .or(c.semi_axes_m.map(|[a, b]| a + b))?;
                Some((axis_offset(c.axis_point_m, c.axis_direction), d))
            }
            _ => None,
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, d)| d)
}

/// Distance between a line (point `p`, direction `u`) and the optical axis (the z axis).
fn axis_offset(p: [f64; 3], u: [f64; 3]) -> f64 {
    let (p, u, z) = (Vec3d::from(p), Vec3d::from(u), Vec3d::z());
    let n = u.cross(&z);
    if n.norm() < 1e-12 {
        (p.x * p.x + p.y * p.y).sqrt()
    } else {
        p.dot(&n).abs() / n.norm()
    }
}

/// Measures one capture directory with the core pipeline. `calibration` overrides the
/// capture's own.
pub fn measure_capture(
    dir: &Path,
    calibration: Option<&Calibration>,
    config: &PipelineConfig,
    params: &CylinderParams,
) -> Result<Outcome, MeasureError> {
    let capture = Capture::read(dir)?;
    measure_loaded(
        &capture,
        &dir.display().to_string(),
        calibration,
        config,
        params,
    )
}

/// Measures a capture already in memory (e.g. fresh from the simulator); `name` labels the
/// reading.
pub fn measure_loaded(
    capture: &Capture,
    name: &str,
    calibration: Option<&Calibration>,
    config: &PipelineConfig,
    params: &CylinderParams,
) -> Result<Outcome, MeasureError> {
    let calibration = calibration
        .cloned()
        .unwrap_or_else(|| capture.calibration.clone());
    // The instruments the host reports on: each one's detailed solution feeds its keys of
    // `Reading`.
    let (result, mut reading, buffers) = match capture.meta.mode {
        Mode::Cylinder => {
            let (r, buffers) = solve_stem(capture, &calibration, config, params)?;
            let r = r.map(Solved::Stem);
            let mut reading = Reading::from_result(name, &r, &calibration, truth_diameter(capture));
            reading.exposure_pairs = (capture.pairs() > 1).then_some(capture.pairs());
            (r, reading, buffers)
        }
        Mode::Sphere => {
            let params = sphere_params(params);
            let (r, buffers) = solve_capture::<Sphere>(capture, &calibration, config, &params)?;
            let r = r.map(Solved::Sphere);
            let reading =
                Reading::from_result(name, &r, &calibration, truth_sphere_diameter(capture));
            (r, reading, buffers)
        }
        Mode::Wall => {
            if is_calibration_capture(capture, &calibration) {
                return Err(MeasureError::CalibrationCapture);
            }
            let mut params = wall_params(&calibration, params);
            // The vertical reference, when the device recorded one (docs/building.md §6).
            if let Some(a) = &capture.meta.accelerometer {
                let (g, sigma) = a.gravity_camera().map_err(MeasureError::Accelerometer)?;
                params.walls.gravity = Some((Vec3::new(g[0], g[1], g[2]), sigma));
            }
            let (r, buffers) = match crossing_plane(capture, &calibration) {
                Some(k) => solve_wall_crossing(capture, &calibration, k, config, &params)?,
                None => solve_capture::<Wall>(capture, &calibration, config, &params)?,
            };
            let reading = Reading::from_wall(name, r.as_ref(), &calibration, Some(capture));
            (r.map(|m| Solved::Wall(Box::new(m))), reading, buffers)
        }
        mode @ Mode::Road => return Err(MeasureError::UnsupportedMode(mode)),
    };
    reading.truth_curve_unreadable = capture.truth_curve_unreadable.clone();
    let (diff, curve, points) = buffers;
    Ok(Outcome {
        reading,
        result,
        diff,
        curve,
        points,
        calibration,
    })
}

/// Measures a road capture with the core's [`Road`] instrument (the device's code), through
/// the same frame pair and buffers as every instrument, and rebuilds its raw profile for
/// plots and cross-checks. `calibration` overrides the capture's own; `params` carries the
/// head's height-scale correction (`docs/road.md`).
pub fn measure_road(
    capture: &Capture,
    calibration: Option<&Calibration>,
    config: &PipelineConfig,
    params: &RoadParams,
) -> Result<RoadOutcome, MeasureError> {
    let calibration = calibration
        .cloned()
        .unwrap_or_else(|| capture.calibration.clone());
    let (result, (_, _, points)) = solve_capture::<Road>(capture, &calibration, config, params)?;
    Ok(RoadOutcome::new(
        capture,
        result,
        &points,
        calibration,
        params,
    ))
}

/// Reads and measures a road capture directory ([`measure_road`]).
pub fn measure_road_dir(
    dir: &Path,
    calibration: Option<&Calibration>,
    config: &PipelineConfig,
    params: &RoadParams,
) -> Result<RoadOutcome, MeasureError> {
    measure_road(&Capture::read(dir)?, calibration, config, params)
}

/// The wall instrument's settings for `calibration`'s camera, with the stem's noise model.
pub fn wall_params(calibration: &Calibration, params: &CylinderParams) -> WallInstrumentParams {
    let mut p = WallInstrumentParams {
        noise: params.noise,
        focal_px: calibration.camera.fy,
        ..WallInstrumentParams::default()
    };
    p.walls.focal_px = calibration.camera.fx;
    p.walls.principal_u = calibration.camera.cx;
    p.walls.width_px = calibration.camera.width as f64;
    p
}

/// Whether a wall capture lights its planes across the image only one by one (the laser
/// calibration's board poses): the device lights the parallel pair in one frame.
fn is_calibration_capture(capture: &Capture, calibration: &Calibration) -> bool {
    let across: Vec<usize> = (0..calibration.planes.len())
        .filter(|&k| !calibration.planes[k].is_row_wise())
        .collect();
    across.len() > 1
        && !capture
            .on_frames()
            .any(|(lit, _)| across.iter().all(|k| lit.contains(k)))
}

/// The crossing line of a wall capture (`docs/building.md`, "The crossing line"): the last
/// plane of `calibration`, when it is row-wise and a frame of the capture lit it alone.
fn crossing_plane(capture: &Capture, calibration: &Calibration) -> Option<usize> {
    let k = calibration.planes.len().checked_sub(1)?;
    (k > 0 && calibration.planes[k].is_row_wise() && capture.on_frames().any(|(lit, _)| lit == [k]))
        .then_some(k)
}

/// The wall instrument on a three-line capture: the planes across the image from their frame
/// (or the composite of theirs), the crossing plane `k` from its own, transposed
/// ([`instrument::wall::measure_with_crossing`]). The plot buffers are the parallel pair's.
#[allow(clippy::type_complexity)]
fn solve_wall_crossing(
    capture: &Capture,
    calibration: &Calibration,
    k: usize,
    config: &PipelineConfig,
    params: &WallInstrumentParams,
) -> SolvedFrames<WallMeasurement> {
    let mut across = calibration.clone();
    across.planes.truncate(k);
    // The planes across keep their share of the covariance; the whole one reaches the
    // wall solver with the crossing line (`instrument::wall::Crossing`).
    across.uncertainty = match &calibration.uncertainty {
        Some(u) => Some(u.leading(k).map_err(MeasureError::Uncertainty)?),
        None => None,
    };
    let (off, on) = frame_pair(capture, k)?;
    let on_crossing = capture
        .on_frames()
        .find(|(lit, _)| *lit == [k])
        .map(|(_, f)| f)
        .ok_or(MeasureError::NoFullFrame(k + 1))?;
    Ok(match (&off.samples, &on.samples, &on_crossing.samples) {
        (PgmSamples::U8(a), PgmSamples::U8(b), PgmSamples::U8(c)) => {
            run_crossing(a, b, c, &on, calibration, &across, k, config, params)
        }
        (PgmSamples::U16(a), PgmSamples::U16(b), PgmSamples::U16(c)) => {
            run_crossing(a, b, c, &on, calibration, &across, k, config, params)
        }
        _ => return Err(MeasureError::MixedDepth),
    })
}

#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn run_crossing<P: Pixel>(
    off: &[P],
    on: &[P],
    on_crossing: &[P],
    pgm: &Pgm,
    calibration: &Calibration,
    across: &Calibration,
    k: usize,
    config: &PipelineConfig,
    params: &WallInstrumentParams,
) -> (Result<WallMeasurement, PipelineError>, PlotBuffers) {
    use tangent_core::pipeline::crossing::transpose_frame;
    let (w, h) = (pgm.width, pgm.height);
    let mut hw = OwnedBuffers::<P>::for_frame(w, h, pgm.bit_depth(), k);
    let mut hw_t = OwnedBuffers::<P>::for_frame(h, w, pgm.bit_depth(), 1);
    let result = (|| {
        let mut off_t = vec![P::default(); w * h];
        let mut on_t = vec![P::default(); w * h];
        transpose_frame(off, w, h, &mut off_t)?;
        transpose_frame(on_crossing, w, h, &mut on_t)?;
        let depth = pgm.bit_depth();
        let off_f = Frame::new(off, w, h, w)?.with_bit_depth(depth)?;
        let on_f = Frame::new(on, w, h, w)?.with_bit_depth(depth)?;
        let off_tf = Frame::new(&off_t[..], h, w, h)?.with_bit_depth(depth)?;
        let on_tf = Frame::new(&on_t[..], h, w, h)?.with_bit_depth(depth)?;
        instrument::wall::measure_with_crossing(
            &off_f,
            &on_f,
            across,
            &off_tf,
            &on_tf,
            calibration,
            k,
            config,
            params,
            &mut hw.workspace(),
            &mut hw_t.workspace(),
        )
    })();
    let diff = hw.diff().iter().map(|&v| v.into() as u16).collect();
    let mut points = hw.points().to_vec();
    // The crossing line's points after the others', where the profile says (for plots and
    // the evaluation's baseline): `profile.points(points, k)` finds them.
    let result = result.map(|(mut m, (s, e))| {
        let first = points.len();
        points.extend_from_slice(&hw_t.points()[s..e]);
        if let Some(slot) = m.profile.plane_points.get_mut(k) {
            *slot = (first, points.len());
        }
        m
    });
    (result, (diff, hw.curve().to_vec(), points))
}

/// The buffers a plot shows: the difference frame (16-bit), the curve points, the 3-D points.
type PlotBuffers = (Vec<u16>, Vec<CurvePoint>, Vec<Vec3>);

/// A solver's result on one capture with its plot buffers, or why the frames could not be
/// measured at all.
type SolvedFrames<S> = Result<(Result<S, PipelineError>, PlotBuffers), MeasureError>;

/// Runs instrument `I` on the capture's frame pair.
#[allow(clippy::type_complexity)]
/// A stem capture's reading: its exposure pair's, or with several pairs the combination of
/// every pair's reading ([`combine_exposures`], `docs/error-model.md` §6, (E7)); the buffers (for
/// plots) are those of the first pair that read. With no pair reading, the first pair's
/// error.
fn solve_stem(
    capture: &Capture,
    calibration: &Calibration,
    config: &PipelineConfig,
    params: &CylinderParams,
) -> SolvedFrames<StemMeasurement> {
    if capture.pairs() == 1 {
        return solve_capture::<Stem>(capture, calibration, config, params);
    }
    let mut first: Option<(Result<StemMeasurement, PipelineError>, PlotBuffers)> = None;
    let mut solutions = Vec::with_capacity(capture.pairs());
    for pair in (0..capture.pairs()).filter_map(|k| capture.exposure_pair(k)) {
        let (result, buffers) = solve_capture::<Stem>(&pair, calibration, config, params)?;
        if let Ok(m) = &result {
            solutions.push(m.solution);
        }
        // The first pair that read, else the first pair's failure.
        match (&first, &result) {
            (None, _) | (Some((Err(_), _)), Ok(_)) => first = Some((result, buffers)),
            _ => {}
        }
    }
    // `first` is set: every pair below `pairs()` exists and each one returns a result.
    let (result, buffers) = first.ok_or(MeasureError::NoFullFrame(calibration.planes.len()))?;
    let result = result.and_then(|m| {
        let solution = combine_exposures(&solutions).map_err(PipelineError::Solve)?;
        Ok(Measured { solution, ..m })
    });
    Ok((result, buffers))
}

fn solve_capture<I: Instrument>(
    capture: &Capture,
    calibration: &Calibration,
    config: &PipelineConfig,
    params: &I::Params,
) -> SolvedFrames<Measured<I::Solution>> {
    let (off, on) = frame_pair(capture, calibration.planes.len())?;
    Ok(match (&off.samples, &on.samples) {
        (PgmSamples::U8(a), PgmSamples::U8(b)) => {
            let (r, hw) = run::<I, u8>(a, b, &on, calibration, config, params);
            (
                r,
                (
                    hw.diff().iter().map(|&v| v as u16).collect(),
                    hw.curve().to_vec(),
                    hw.points().to_vec(),
                ),
            )
        }
        (PgmSamples::U16(a), PgmSamples::U16(b)) => {
            let (r, hw) = run::<I, u16>(a, b, &on, calibration, config, params);
            (
                r,
                (
                    hw.diff().to_vec(),
                    hw.curve().to_vec(),
                    hw.points().to_vec(),
                ),
            )
        }
        _ => return Err(MeasureError::MixedDepth),
    })
}
