//! The sphere instrument ([`Mode::Sphere`]): the sphere solver
//! ([`crate::solvers::sphere::solve`]: joint fit, sections or three-tangent) on the points of
//! every plane, with the image's quality flags added (`docs/sphere.md`).

use crate::measurement::{Measurement, Mode, Point, SphereReading};
use crate::noise::NoiseModel;
use crate::pipeline::{GrowParams, PipelineConfig, PipelineError};
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

    /// The curves are grown along the stripe beyond the threshold's cut
    /// ([`crate::pipeline::grow`]): a speckled steel stripe breaks into pieces under the
    /// threshold, and a section that keeps one piece is too short an arc (`docs/sphere.md`,
    /// "Grown sections and the points' own σ").
    fn pipeline_config(base: &PipelineConfig) -> PipelineConfig {
        PipelineConfig {
            grow: Some(GrowParams::default()),
            arcs_first: true,
            ..*base
        }
    }

    /// A ball that runs off the frame is still measured (the sections need no silhouette);
    /// the solution's flags include the [`Profile::image_flags`].
    ///
    /// [`Profile::image_flags`]: crate::pipeline::Profile::image_flags
    fn solve(
        points: &PlanePoints<'_>,
        params: &SphereParams,
        scratch: Scratch<'_>,
    ) -> Result<SphereSolution, PipelineError> {
        // Each point's σ is the subpixel estimator's own term, without the noise model's
        // speckle floor: on grown sections the floor over-weights the faint grown ends against
        // the bright points, and the floor a ball's surface really has (≈ 0 matt, ≈ 0.17 px
        // steel) is carried by the joint fit's scaling by its own residuals
        // (`docs/sphere.md`, "Grown sections and the points' own σ").
        let noise: &NoiseModel = &NoiseModel {
            speckle_contrast: 0.0,
            ..params.noise
        };
        let focal: Real = params.focal_px;
        let sigmas = points.sigmas(noise, focal, scratch.sigmas)?;
        let curves = points.curves();
        let input = SphereInput {
            curves,
            sigmas: &sigmas[..curves.len()],
            planes: points.planes(),
            uncertainty: points.uncertainty(),
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
