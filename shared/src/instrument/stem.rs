//! The stem instrument ([`Mode::Cylinder`]): the cylinder solver
//! ([`crate::solvers::stem::solve`]: three-tangent, circle or cylinder fit, chosen by the
//! data) on the points of every plane, with the image's quality flags added.

use crate::measurement::{Axes, Measurement, Mode, StemReading, TiltAngles};
use crate::pipeline::{GrowParams, PipelineConfig, PipelineError};
use crate::solvers::stem::{self, CylinderInput, CylinderParams, CylinderSolution};

use super::{Instrument, Measured, PlanePoints, Scratch};

/// A stem measurement: the cylinder solution and the image summary.
pub type StemMeasurement = Measured<CylinderSolution>;

/// The stem instrument.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stem;

impl Instrument for Stem {
    const MODE: Mode = Mode::Cylinder;
    type Params = CylinderParams;
    type Solution = CylinderSolution;

    /// The curves are grown along the stripe beyond the threshold's cut
    /// ([`crate::pipeline::grow`]): a glossy stem's diffuse sides are part of its arc.
    fn pipeline_config(base: &PipelineConfig) -> PipelineConfig {
        PipelineConfig {
            grow: Some(GrowParams::default()),
            ..*base
        }
    }

    /// A curve that runs off the frame is [`PipelineError::OutsideFrame`]: the stem's
    /// silhouette is not seen. The solution's flags include the [`Profile::image_flags`].
    ///
    /// [`Profile::image_flags`]: crate::pipeline::Profile::image_flags
    fn solve(
        points: &PlanePoints<'_>,
        params: &CylinderParams,
        scratch: Scratch<'_>,
    ) -> Result<CylinderSolution, PipelineError> {
        if points.profile.touches_edge {
            return Err(PipelineError::OutsideFrame);
        }
        // The points' σ up to the profile's extent, the bins' σ after them.
        let extent = points.profile.extent().min(scratch.sigmas.len());
        let (sigmas, bin_sigmas) = scratch.sigmas.split_at_mut(extent);
        let sigmas = points.sigmas(&params.noise, params.focal_px, sigmas)?;
        let curves = points.curves();
        let input = CylinderInput {
            curves,
            sigmas: &sigmas[..curves.len()],
            planes: points.planes(),
            uncertainty: points.uncertainty(),
        };
        let scratch = stem::Scratch {
            points: scratch.points,
            values: scratch.values,
            bins: scratch.bins,
            bin_sigmas,
        };
        let mut solution = stem::solve(&input, params, scratch)?;
        solution
            .flags
            .insert(points.profile.image_flags(points.full_scale));
        Ok(solution)
    }
}

impl From<&CylinderSolution> for Measurement {
    fn from(s: &CylinderSolution) -> Self {
        Measurement::Stem(StemReading {
            diameter: s.diameter,
            uncertainty: s.uncertainty,
            method: s.method,
            distance: s.distance,
            tilt: s.tilt.map(|t| TiltAngles {
                total: t.total,
                theta: t.theta,
                phi: t.phi,
            }),
            axes: s.axes.map(|(major, minor)| Axes { major, minor }),
            flags: s.flags,
            // At most `MAX_EXPOSURES` (16) by `combine_exposures`.
            exposures: u8::try_from(s.exposures).unwrap_or(u8::MAX),
        })
    }
}
