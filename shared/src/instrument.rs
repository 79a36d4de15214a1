//! The back half of the chain, generic over the instrument: the 3-D points of each laser
//! plane's curve ([`crate::pipeline`]) → the solver of the capture's [`Mode`] → one
//! [`Measurement`].
//!
//! An instrument is a solver ([`Instrument`]) on the points of every plane ([`PlanePoints`]).
//! Adding one (sphere, wall, road) is: its solver module, an [`Instrument`] impl, a
//! [`Measurement`] variant with a `From` of its solution, and an arm in [`measure`]; the image
//! half and every other instrument stay as they are (see the toy instrument in this module's
//! tests).
//!
//! * [`stem`]: [`Mode::Cylinder`], the stem's diameter.
//! * [`sphere`]: [`Mode::Sphere`], a ball's diameter and centre.
//! * [`road`]: [`Mode::Road`], a road profile's mean profile depth and microtexture.
//! * [`wall`]: [`Mode::Wall`], walls by principal components: orientation, corner angle,
//!   distance between parallel walls, segment length (`docs/building.md`).

use crate::calibration::{Calibration, PlanesUncertainty, MAX_PLANES};
use crate::curve::CurvePoint;
use crate::image::{Frame, Pixel};
use crate::laser_plane::LaserPlane;
use crate::measurement::{Measurement, Mode};
use crate::noise::NoiseModel;
use crate::pipeline::{
    extract_profile, point_sigmas, PipelineConfig, PipelineError, Profile, Workspace,
};
use crate::real::{Real, Vec2, Vec3};
use crate::solvers::sphere::SphereParams;
use crate::solvers::stem::CylinderParams;

pub mod road;
pub mod sphere;
pub mod stem;
pub mod wall;

pub use road::Road;
pub use sphere::Sphere;
pub use stem::Stem;
pub use wall::{Wall, WallInstrumentParams};

/// What an instrument's solver reads: per laser plane, the 3-D points of its curve (camera
/// frame, metres, ordered by image column), the planes themselves, and the image summary.
#[derive(Debug, Clone, Copy)]
pub struct PlanePoints<'a> {
    all: &'a [Vec3],
    /// The curve points beside `all` (amplitude and width give each point's own σ); empty
    /// when unknown (the model's σ then stands).
    curve: &'a [CurvePoint],
    curves: [&'a [Vec3]; MAX_PLANES],
    planes: &'a [LaserPlane],
    uncertainty: Option<&'a PlanesUncertainty>,
    /// The image part of the chain (flags, saturation, frame-edge contact).
    pub profile: &'a Profile,
    /// The laser-on frame's [`Frame::max_value`] (for [`Profile::image_flags`]).
    pub full_scale: u32,
}

impl<'a> PlanePoints<'a> {
    /// The planes' points that [`extract_profile`] left in `points` (`Workspace::points`).
    pub fn new(
        profile: &'a Profile,
        full_scale: u32,
        calibration: &'a Calibration,
        points: &'a [Vec3],
    ) -> Self {
        let n = profile.planes.min(MAX_PLANES).min(calibration.planes.len());
        let mut curves: [&[Vec3]; MAX_PLANES] = [&[]; MAX_PLANES];
        for (k, c) in curves.iter_mut().enumerate().take(n) {
            *c = profile.points(points, k);
        }
        PlanePoints {
            all: points,
            curve: &[],
            curves,
            planes: &calibration.planes[..n],
            uncertainty: calibration.uncertainty.as_ref(),
            profile,
            full_scale,
        }
    }

    /// The same points with their curve points (`Workspace::curve`, same indices as
    /// `points`): each point's σ then comes from its own stripe ([`point_sigmas`]).
    pub fn with_curve(mut self, curve: &'a [CurvePoint]) -> Self {
        self.curve = curve;
        self
    }

    /// Each plane's points, in plane order.
    pub fn curves(&self) -> &[&'a [Vec3]] {
        &self.curves[..self.planes.len()]
    }

    /// The laser planes, in the order of [`PlanePoints::curves`].
    pub fn planes(&self) -> &'a [LaserPlane] {
        self.planes
    }

    /// The calibration's covariance of the planes' `(e, δ)`, indexed as the calibration's
    /// planes (those of [`PlanePoints::planes`] first); `None` when they are independent.
    pub fn uncertainty(&self) -> Option<&'a PlanesUncertainty> {
        self.uncertainty
    }

    /// Each plane's curve points beside [`PlanePoints::curves`] (empty slices without
    /// [`PlanePoints::with_curve`]).
    pub fn curve_points(&self) -> [&'a [CurvePoint]; MAX_PLANES] {
        let mut per_plane: [&[CurvePoint]; MAX_PLANES] = [&[]; MAX_PLANES];
        for (k, c) in per_plane.iter_mut().enumerate().take(self.planes.len()) {
            *c = self.profile.points(self.curve, k);
        }
        per_plane
    }

    /// Writes each point's 1σ into `sigmas` (the workspace's, lent in [`Scratch::sigmas`])
    /// from each point's stripe or the noise model ([`point_sigmas`]) and returns them per plane, in the order of
    /// [`PlanePoints::curves`].
    pub fn sigmas<'s>(
        &self,
        noise: &NoiseModel,
        focal_px: Real,
        sigmas: &'s mut [Real],
    ) -> Result<[&'s [Real]; MAX_PLANES], PipelineError> {
        point_sigmas(
            self.profile,
            self.planes,
            noise,
            focal_px,
            self.all,
            self.curve,
            sigmas,
        )?;
        let sigmas: &'s [Real] = sigmas;
        let mut per_plane: [&[Real]; MAX_PLANES] = [&[]; MAX_PLANES];
        for (k, s) in per_plane.iter_mut().enumerate().take(self.planes.len()) {
            *s = self.profile.points(sigmas, k);
        }
        Ok(per_plane)
    }
}

/// Memory a solver is lent by the workspace ([`lend`]).
#[derive(Debug)]
pub struct Scratch<'a> {
    /// `Workspace::sigmas`: the points' 1σ, for [`PlanePoints::sigmas`] (kept after the
    /// run), as many as the workspace holds (the road instrument's profile trace is longer
    /// than its points).
    pub sigmas: &'a mut [Real],
    /// 2-D points (in-plane or projected), as many as the workspace holds.
    pub points: &'a mut [Vec2],
    /// Values (residuals, weights), as many as the workspace holds.
    pub values: &'a mut [Real],
    /// `Workspace::points` past the profile's ([`Profile::extent`]): 3-D points a solver may
    /// write (the stem's bins of a long curve).
    pub bins: &'a mut [Vec3],
}

/// The points of every plane that [`extract_profile`] left in `ws` ([`PlanePoints`], with
/// their curve points; `full_scale`: the laser-on frame's [`Frame::max_value`]) and the
/// memory their solver is lent: the σ and solver scratch buffers, and the workspace's 3-D
/// points past the profile's.
pub fn lend<'w, P: Pixel>(
    profile: &'w Profile,
    full_scale: u32,
    calibration: &'w Calibration,
    ws: &'w mut Workspace<'_, P>,
) -> (PlanePoints<'w>, Scratch<'w>) {
    let (points, bins) = ws
        .points
        .split_at_mut(profile.extent().min(ws.points.len()));
    let points = PlanePoints::new(profile, full_scale, calibration, points).with_curve(ws.curve);
    let scratch = Scratch {
        sigmas: ws.sigmas,
        points: ws.scratch_points,
        values: ws.scratch_values,
        bins,
    };
    (points, scratch)
}

/// One instrument: a solver from the points of every plane to its solution.
pub trait Instrument {
    /// The capture mode it measures.
    const MODE: Mode;
    /// Its settings.
    type Params;
    /// Its detailed answer (a [`Measurement`] is made `From` it for the wire and the log).
    type Solution;
    /// Solves. Allocation-free: `scratch` is all the memory it may use.
    fn solve(
        points: &PlanePoints<'_>,
        params: &Self::Params,
        scratch: Scratch<'_>,
    ) -> Result<Self::Solution, PipelineError>;

    /// What an image failure means to this instrument (identity unless overridden): the
    /// sphere's missing second line is [`crate::solvers::SolveError::OneSection`], with the
    /// advice that goes with it.
    fn image_failure(e: PipelineError) -> PipelineError {
        e
    }

    /// The image chain's settings this instrument measures with, from the caller's `base`
    /// (`base` unless overridden): the road instrument takes its profile unsmoothed
    /// (`docs/road.md`, "Furrow validation").
    fn pipeline_config(base: &PipelineConfig) -> PipelineConfig {
        *base
    }
}

/// [`Instrument::pipeline_config`] of the instrument of `mode`: every reading path (host and
/// device) extracts its profile with it, so both measure alike.
pub fn pipeline_config(mode: Mode, base: &PipelineConfig) -> PipelineConfig {
    match mode {
        Mode::Cylinder => Stem::pipeline_config(base),
        Mode::Sphere => Sphere::pipeline_config(base),
        Mode::Road => Road::pipeline_config(base),
        Mode::Wall => Wall::pipeline_config(base),
    }
}

/// [`Instrument::image_failure`] of the instrument of `mode`: every reading path (host and
/// device) passes its image failures through it, so both say the same.
pub fn image_failure(mode: Mode, e: PipelineError) -> PipelineError {
    match mode {
        Mode::Cylinder => Stem::image_failure(e),
        Mode::Sphere => Sphere::image_failure(e),
        Mode::Road => Road::image_failure(e),
        Mode::Wall => Wall::image_failure(e),
    }
}

/// An instrument's solution together with the image summary it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured<S> {
    /// The solver's answer.
    pub solution: S,
    /// The image part of the chain.
    pub profile: Profile,
}

/// The settings of every instrument, for [`measure`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InstrumentParams {
    /// [`Mode::Cylinder`] ([`Stem`]).
    pub cylinder: CylinderParams,
    /// [`Mode::Sphere`] ([`Sphere`]).
    pub sphere: SphereParams,
    /// [`Mode::Road`] ([`Road`]).
    pub road: road::RoadParams,
    /// [`Mode::Wall`] ([`Wall`]).
    pub wall: WallInstrumentParams,
}

/// Measures a frame pair with the instrument of `mode`: [`extract_profile`] (with the
/// instrument's [`pipeline_config`] of `config`), then its solver.
/// A mode this build has no solver for is [`PipelineError::UnsupportedMode`] (every mode has
/// one today; see [`supports`]).
///
/// ```
/// use tangent_core::pipeline::WorkspaceSizes;
/// use tangent_core::{measure, Buffers, Calibration, Frame, InstrumentParams, Mode};
/// use tangent_core::{PipelineConfig, PipelineError};
///
/// // The reference design: 752 × 480 8-bit frames, two laser planes.
/// const SIZES: WorkspaceSizes = WorkspaceSizes::new(752, 480, 8, 2);
/// let mut buffers = Box::new(Buffers::<u8, { SIZES.pixels }, { SIZES.points }>::new());
/// let calibration = Calibration::reference_design();
/// let dark = vec![12u8; 752 * 480];
/// let frame = Frame::new(&dark[..], 752, 480, 752)?;
/// let (config, params) = (PipelineConfig::default(), InstrumentParams::default());
/// // Nothing lit: the laser-on frame equals the laser-off one.
/// let reading =
///     measure(Mode::Cylinder, &frame, &frame, &calibration, &config, &params, &mut buffers.workspace());
/// assert_eq!(reading, Err(PipelineError::NoLaserLight { max_difference: 0 }));
/// let reading =
///     measure(Mode::Sphere, &frame, &frame, &calibration, &config, &params, &mut buffers.workspace());
/// assert_eq!(reading, Err(PipelineError::NoLaserLight { max_difference: 0 }));
/// # Ok::<(), tangent_core::image::FrameError>(())
/// ```
pub fn measure<P: Pixel>(
    mode: Mode,
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    config: &PipelineConfig,
    params: &InstrumentParams,
    ws: &mut Workspace<'_, P>,
) -> Result<Measurement, PipelineError> {
    // Refused before the image work: a mode without a solver is a setting, not a scene.
    if !supports(mode) {
        return Err(PipelineError::UnsupportedMode(mode));
    }
    let config = pipeline_config(mode, config);
    let profile =
        extract_profile(off, on, calibration, &config, ws).map_err(|e| image_failure(mode, e))?;
    solve(mode, &profile, on.max_value(), calibration, params, ws)
}

/// Whether this build has a solver for `mode`: the modes [`measure`] and [`solve`] accept
/// (the device refuses to be set to any other).
pub fn supports(mode: Mode) -> bool {
    match mode {
        Mode::Cylinder | Mode::Sphere | Mode::Wall | Mode::Road => true,
    }
}

/// The solver half of [`measure`] for the instrument of `mode` ([`solve_with`] of it, its
/// solution made a [`Measurement`]), on the points [`extract_profile`] left in `ws`. The
/// device calls it after its timed extraction, so every reading path goes through here.
pub fn solve<P: Pixel>(
    mode: Mode,
    profile: &Profile,
    full_scale: u32,
    calibration: &Calibration,
    params: &InstrumentParams,
    ws: &mut Workspace<'_, P>,
) -> Result<Measurement, PipelineError> {
    match mode {
        Mode::Cylinder => {
            solve_with::<Stem, P>(profile, full_scale, calibration, &params.cylinder, ws)
                .map(|s| Measurement::from(&s))
        }
        Mode::Sphere => {
            solve_with::<Sphere, P>(profile, full_scale, calibration, &params.sphere, ws)
                .map(|s| Measurement::from(&s))
        }
        Mode::Road => solve_with::<Road, P>(profile, full_scale, calibration, &params.road, ws)
            .map(|s| Measurement::from(&s)),
        Mode::Wall => solve_with::<Wall, P>(profile, full_scale, calibration, &params.wall, ws)
            .map(|s| Measurement::from(&s)),
    }
}

/// [`measure`] with instrument `I`, keeping its detailed solution and the image summary.
pub fn measure_with<I: Instrument, P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    config: &PipelineConfig,
    params: &I::Params,
    ws: &mut Workspace<'_, P>,
) -> Result<Measured<I::Solution>, PipelineError> {
    let config = I::pipeline_config(config);
    let profile = extract_profile(off, on, calibration, &config, ws).map_err(I::image_failure)?;
    let solution = solve_with::<I, P>(&profile, on.max_value(), calibration, params, ws)?;
    Ok(Measured { solution, profile })
}

/// The solver half of [`measure_with`]: instrument `I` on the points of every plane that
/// [`extract_profile`] left in `ws` (`full_scale`: the laser-on frame's
/// [`Frame::max_value`]). Separate so that the two halves can be timed apart.
pub fn solve_with<I: Instrument, P: Pixel>(
    profile: &Profile,
    full_scale: u32,
    calibration: &Calibration,
    params: &I::Params,
    ws: &mut Workspace<'_, P>,
) -> Result<I::Solution, PipelineError> {
    let (points, scratch) = lend(profile, full_scale, calibration, ws);
    I::solve(&points, params, scratch)
}

#[cfg(test)]
mod tests;
