//! The wall instrument ([`Mode::Wall`]): the wall solver ([`crate::solvers::walls::solve`]:
//! walls by principal components, and the corner, parallel distance, segment and plumb
//! readings) on the points of every plane, with the image's quality flags added
//! (`docs/building.md`).

use crate::measurement::{Measurement, Mode, ValueSigma, WallReading};
use crate::noise::NoiseModel;
use crate::pipeline::PipelineError;
use crate::real::Real;
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
        let sigmas = points.sigmas(&params.noise, params.focal_px, scratch.sigmas)?;
        let curves = points.curves();
        let input = WallInput {
            curves,
            sigmas: &sigmas[..curves.len()],
            planes: points.planes(),
        };
        let mut solution = walls::solve(&input, &params.walls)?;
        solution
            .flags
            .insert(points.profile.image_flags(points.full_scale));
        Ok(solution)
    }
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
