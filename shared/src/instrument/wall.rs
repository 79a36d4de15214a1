//! The wall instrument ([`Mode::Wall`]): the wall solver ([`crate::solvers::walls::solve`]:
//! walls by principal components, and the corner, parallel distance, segment and plumb
//! readings) on the points of every plane, with the image's quality flags added
//! (`docs/building.md`).

use crate::calibration::{Calibration, PlanesUncertainty, MAX_PLANES};
use crate::image::{Frame, Pixel};
use crate::laser_plane::LaserPlane;
use crate::measurement::{Measurement, Mode, ValueSigma, WallReading};
use crate::noise::NoiseModel;
use crate::pipeline::crossing::{transposed_calibration, untranspose_points};
use crate::pipeline::{extract_profile, PipelineConfig, PipelineError, Profile, Workspace};
use crate::real::{Real, Vec3};
use crate::solvers::plane_pca::Estimate;
use crate::solvers::result::Method;
use crate::solvers::walls::{self, WallInput, WallParams, WallSolution};

use super::{Instrument, Measured, PlanePoints, Scratch};

/// A wall measurement: the walls' solution and the image summary.
pub type WallMeasurement = Measured<WallSolution>;

/// The wall instrument's settings: the solver's and the noise model for the points' σ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallInstrumentParams {
    /// The wall solver's settings.
    pub walls: WallParams,
    /// Image noise, for each point's σ.
    pub noise: NoiseModel,
    /// Focal length along the image rows' normal (`fy`, pixels), for the noise model.
    pub focal_px: Real,
}

impl Default for WallInstrumentParams {
    /// The reference head: [`WallParams::default`], [`NoiseModel::reference`], f = 1000 px.
    fn default() -> Self {
        WallInstrumentParams {
            walls: WallParams::default(),
            noise: NoiseModel::reference(),
            focal_px: 1000.0,
        }
    }
}

/// The wall instrument.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wall;

impl Instrument for Wall {
    const MODE: Mode = Mode::Wall;
    type Params = WallInstrumentParams;
    type Solution = WallSolution;

    /// The pipeline with the other surfaces' pieces assigned by depth agreement
    /// ([`PipelineConfig::stacks`]: a niche's front wall beside its back wall,
    /// `docs/building.md`, "Niches"); nothing else changes.
    fn pipeline_config(base: &PipelineConfig) -> PipelineConfig {
        PipelineConfig {
            stacks: Some(base.stacks.unwrap_or_default()),
            ..*base
        }
    }

    /// Unlike a stem, a wall may run off the frame: a segment that does is reported as open
    /// ([`walls::EndKind::FrameSide`]). The solution's flags include the
    /// [`Profile::image_flags`].
    ///
    /// [`Profile::image_flags`]: crate::pipeline::Profile::image_flags
    fn solve(
        points: &PlanePoints<'_>,
        params: &WallInstrumentParams,
        scratch: Scratch<'_>,
    ) -> Result<WallSolution, PipelineError> {
        solve_walls(points, None, params, scratch)
    }
}

/// The crossing line's points (`docs/building.md`, "The crossing line"), extracted from its
/// own frame pair by [`extract_crossing`]: camera frame, ordered down the image.
#[derive(Debug, Clone, Copy)]
pub struct Crossing<'a> {
    /// Its laser plane (camera frame).
    pub plane: LaserPlane,
    /// Its points.
    pub points: &'a [Vec3],
    /// Each point's 1σ along its noise direction.
    pub sigmas: &'a [Real],
    /// The whole calibration's covariance of the planes' `(e, δ)` (the planes across the
    /// image, then this one), `None` when they are independent.
    pub uncertainty: Option<&'a PlanesUncertainty>,
}

/// Extracts the crossing line, plane `plane` of `calibration`, from its own frame pair
/// given **transposed** (`pipeline::crossing::transpose_frame`: its rows are the image's
/// columns): the column-wise pipeline on the transposed pair with the transposed
/// calibration, each point's σ, the points brought back to the camera frame. Leaves them in
/// `ws.points` and their σ in `ws.sigmas` and returns their index range there.
pub fn extract_crossing<P: Pixel>(
    off_t: &Frame<P, impl AsRef<[P]>>,
    on_t: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    plane: usize,
    config: &PipelineConfig,
    params: &WallInstrumentParams,
    ws: &mut Workspace<'_, P>,
) -> Result<(usize, usize), PipelineError> {
    let transposed = transposed_calibration(calibration, plane)?;
    let profile = extract_profile(off_t, on_t, &transposed, config, ws)?;
    let (start, end) = profile.plane_points[0];
    if !(start <= end && end <= ws.points.len() && end <= ws.sigmas.len()) {
        return Err(PipelineError::NoCurve);
    }
    {
        let points = PlanePoints::new(&profile, on_t.max_value(), &transposed, ws.points)
            .with_curve(ws.curve);
        // σ along each point's noise direction: a length, the same in either frame.
        points.sigmas(&params.noise, params.focal_px, ws.sigmas)?;
    }
    untranspose_points(&mut ws.points[start..end]);
    Ok((start, end))
}

/// The wall solver on the points of every plane across the image (`points`) and, when the
/// head has one, the crossing line's (`crossing`, appended as the last curve). The
/// solution's flags include the [`Profile::image_flags`] of `points`.
pub fn solve_walls(
    points: &PlanePoints<'_>,
    crossing: Option<Crossing<'_>>,
    params: &WallInstrumentParams,
    scratch: Scratch<'_>,
) -> Result<WallSolution, PipelineError> {
    let sigmas = points.sigmas(&params.noise, params.focal_px, scratch.sigmas)?;
    let n = points.curves().len();
    let mut curves: [&[Vec3]; MAX_PLANES] = [&[]; MAX_PLANES];
    let mut curve_sigmas: [&[Real]; MAX_PLANES] = [&[]; MAX_PLANES];
    let mut planes: heapless::Vec<LaserPlane, MAX_PLANES> = heapless::Vec::new();
    for k in 0..n {
        curves[k] = points.curves()[k];
        curve_sigmas[k] = sigmas[k];
        planes
            .push(points.planes()[k])
            .map_err(|_| PipelineError::Calibration)?;
    }
    let mut count = n;
    if let Some(c) = crossing {
        planes
            .push(c.plane)
            .map_err(|_| PipelineError::Calibration)?;
        curves[n] = c.points;
        curve_sigmas[n] = c.sigmas;
        count += 1;
    }
    // The crossing line's stripes are its transposed frame's, and no segment is taken on it.
    let stripes = points.curve_points();
    let input = WallInput {
        curves: &curves[..count],
        sigmas: &curve_sigmas[..count],
        planes: &planes,
        stripes: &stripes[..n],
        // A faint-search profile's curves were not cut by a threshold.
        threshold: if points.profile.faint {
            0.0
        } else {
            points.profile.threshold as Real
        },
    };
    let mut solution = walls::solve(&input, &params.walls)?;
    // With the crossing line the whole calibration's covariance, whose planes are the
    // curves in order (the planes across, then the crossing one; `docs/building.md`, (B10)).
    let uncertainty = match crossing {
        Some(c) => c.uncertainty,
        None => points.uncertainty(),
    };
    walls::add_calibration_sigma(
        &input,
        &params.walls,
        &mut solution,
        &params.noise,
        uncertainty,
    )?;
    solution
        .flags
        .insert(points.profile.image_flags(points.full_scale));
    Ok(solution)
}

/// Measures a wall capture of the three-line head: the parallel pair's frames (`off`,
/// `on`, `calibration_across`: the planes across the image) through the pipeline, the
/// crossing line's transposed pair through [`extract_crossing`] in a workspace of its own
/// (`crossing_ws`: transposed frame size, one plane), then [`solve_walls`] on all of them.
/// Also returns where the crossing line's points are in `crossing_ws.points`. `config` is
/// the base configuration: both extractions use the wall instrument's
/// ([`Instrument::pipeline_config`]).
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn measure_with_crossing<P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration_across: &Calibration,
    off_t: &Frame<P, impl AsRef<[P]>>,
    on_crossing_t: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    crossing_plane: usize,
    config: &PipelineConfig,
    params: &WallInstrumentParams,
    ws: &mut Workspace<'_, P>,
    crossing_ws: &mut Workspace<'_, P>,
) -> Result<(Measured<WallSolution>, (usize, usize)), PipelineError> {
    let config = &Wall::pipeline_config(config);
    let profile: Profile = extract_profile(off, on, calibration_across, config, ws)?;
    let (s, e) = extract_crossing(
        off_t,
        on_crossing_t,
        calibration,
        crossing_plane,
        config,
        params,
        crossing_ws,
    )?;
    let crossing = Crossing {
        plane: *calibration
            .plane(crossing_plane)
            .map_err(|_| PipelineError::Calibration)?,
        points: &crossing_ws.points[s..e],
        sigmas: &crossing_ws.sigmas[s..e],
        uncertainty: calibration.uncertainty.as_ref(),
    };
    let (points, scratch) = super::lend(&profile, on.max_value(), calibration_across, ws);
    let solution = solve_walls(&points, Some(crossing), params, scratch)?;
    Ok((Measured { solution, profile }, (s, e)))
}

fn value_sigma(e: Estimate) -> ValueSigma {
    ValueSigma {
        value: e.value,
        sigma: e.sigma,
    }
}

impl From<&WallSolution> for Measurement {
    fn from(s: &WallSolution) -> Self {
        let aimed = s.walls.get(s.aimed);
        let o = &s.orientation;
        Measurement::Wall(WallReading {
            walls: s.walls.len() as u8,
            distance: o.axis_distance.value,
            distance_sigma: o.axis_distance.sigma,
            yaw: value_sigma(o.yaw),
            pitch: value_sigma(o.pitch),
            quality: aimed.map_or(0.0, |w| w.plane.quality),
            rms: aimed.map_or(0.0, |w| w.plane.rms),
            corner: s.corner.map(|c| value_sigma(c.angle)),
            parallel: s.parallel.map(value_sigma),
            segment: s.segment.map(|g| (value_sigma(g.length), g.bounded())),
            plumb: s.plumb.map(value_sigma),
            method: Method::PlanePca,
            flags: s.flags,
        })
    }
}
