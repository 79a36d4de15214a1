//! The sphere instrument ([`Mode::Sphere`]): the sphere solver
//! ([`crate::solvers::sphere::solve`]: joint fit, sections or three-tangent) on the points of
//! every plane, with the image's quality flags added (`docs/sphere.md`).

use crate::measurement::{Measurement, Mode, Point, SphereReading};
use crate::noise::NoiseModel;
use crate::pipeline::PipelineError;
use crate::real::Real;
use crate::solvers::sphere::{self, SphereInput, SphereParams, SphereSolution};
use crate::solvers::SolveError;

use super::{Instrument, Measured, PlanePoints, Scratch};

/// A sphere measurement: the solution and the image summary.
pub type SphereMeasurement = Measured<SphereSolution>;

/// The sphere instrument.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sphere;

impl Instrument for Sphere {
    const MODE: Mode = Mode::Sphere;
    type Params = SphereParams;
    type Solution = SphereSolution;

    /// A ball that runs off the frame is still measured (the sections need no silhouette);
    /// the solution's flags include the [`Profile::image_flags`].
    ///
    /// [`Profile::image_flags`]: crate::pipeline::Profile::image_flags
    fn solve(
        points: &PlanePoints<'_>,
        params: &SphereParams,
        scratch: Scratch<'_>,
    ) -> Result<SphereSolution, PipelineError> {
        let noise: &NoiseModel = &params.noise;
        let focal: Real = params.focal_px;
        let sigmas = points.sigmas(noise, focal, scratch.sigmas)?;
        let curves = points.curves();
        let input = SphereInput {
            curves,
            sigmas: &sigmas[..curves.len()],
            planes: points.planes(),
        };
        let scratch = sphere::Scratch {
            points: scratch.points,
            values: scratch.values,
        };
        let mut solution = sphere::solve(&input, params, scratch)?;
        solution
            .flags
            .insert(points.profile.image_flags(points.full_scale));
        Ok(solution)
    }

    /// A plane's curve too short to extract is a ball that one line misses: the radius is
    /// unobservable ([`SolveError::OneSection`], which says what to do).
    fn image_failure(e: PipelineError) -> PipelineError {
        match e {
            PipelineError::CurveTooShort { .. } => PipelineError::Solve(SolveError::OneSection),
            e => e,
        }
    }
}

impl From<&SphereSolution> for Measurement {
    fn from(s: &SphereSolution) -> Self {
        Measurement::Sphere(SphereReading {
            diameter: s.diameter,
            uncertainty: s.uncertainty,
            method: s.method,
            centre: Point {
                x: s.centre.x,
                y: s.centre.y,
                z: s.centre.z,
            },
            distance: s.distance,
            flags: s.flags,
        })
    }
}
