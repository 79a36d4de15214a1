//! A reference view from a capture: a ball's (sphere mode) or a flat wall's (wall mode),
//! each plane's points as the calibration being refined triangulated them.

use tangent_core::calibration::Calibration;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::real::Vec3;
use tangent_core::solvers::sphere_sections::Sphere;
use tangent_core::solvers::stem::CylinderParams;

use super::super::CalibrateError;
use super::Surface;
use crate::capture::{Capture, Mode};
use crate::measure::{measure_loaded, Outcome, Solved};

/// One capture of the reference: each plane's 3-D points as the calibration being refined
/// triangulated them, and that calibration's surface as the start.
#[derive(Debug, Clone)]
pub struct ReferenceView {
    /// Where the view came from (capture directory), for messages and the report.
    pub name: String,
    /// Plane `k`'s points (camera frame, metres, in image-column order).
    pub planes: Vec<Vec<Vec3>>,
    /// The surface measured with the calibration being refined.
    pub start: Surface,
}

/// `capture` measured with `calibration` by its own instrument, which must be `mode`
/// (`word` in the refusal); errors name the capture.
fn measured(
    capture: &Capture,
    calibration: &Calibration,
    name: &str,
    mode: Mode,
    word: &'static str,
) -> Result<Outcome, CalibrateError> {
    if capture.meta.mode != mode {
        return Err(CalibrateError::NotAReferenceCapture(name.to_string(), word));
    }
    measure_loaded(
        capture,
        name,
        Some(calibration),
        &PipelineConfig::default(),
        &CylinderParams::default(),
    )
    .map_err(|e| CalibrateError::Refinement(format!("{name}: {e}")))
}

impl ReferenceView {
    /// The view of `capture` (a sphere-mode capture of the ball) measured with
    /// `calibration`, the one being refined. Errors name the capture: not a sphere capture,
    /// frames that do not read, no sphere.
    pub fn of_ball(
        capture: &Capture,
        calibration: &Calibration,
        name: &str,
    ) -> Result<ReferenceView, CalibrateError> {
        let refuse = |why: String| CalibrateError::Refinement(format!("{name}: {why}"));
        let outcome = measured(capture, calibration, name, Mode::Sphere, "sphere")?;
        let m = match &outcome.result {
            Ok(Solved::Sphere(m)) => m,
            Ok(_) => return Err(refuse("not measured as a sphere".into())),
            Err(e) => return Err(refuse(format!("no sphere: {e}"))),
        };
        let planes = (0..calibration.planes.len())
            .map(|k| m.profile.points(&outcome.points, k).to_vec())
            .collect();
        Ok(ReferenceView {
            name: name.to_string(),
            planes,
            start: Surface::Sphere(Sphere {
                centre: m.solution.centre,
                radius: 0.5 * m.solution.diameter,
            }),
        })
    }

    /// The view of `capture` (a wall-mode capture of a flat wall, every line on it) measured
    /// with `calibration`. The start is the least-squares plane `z = ax + by + c` of all its
    /// points. Errors name the capture: not a wall capture, frames that do not read, a line
    /// with no points.
    pub fn of_wall(
        capture: &Capture,
        calibration: &Calibration,
        name: &str,
    ) -> Result<ReferenceView, CalibrateError> {
        let refuse = |why: String| CalibrateError::Refinement(format!("{name}: {why}"));
        let outcome = measured(capture, calibration, name, Mode::Wall, "wall")?;
        let profile = match &outcome.result {
            Ok(solved) => solved.profile(),
            Err(e) => return Err(refuse(format!("no wall: {e}"))),
        };
        let planes: Vec<Vec<Vec3>> = (0..calibration.planes.len())
            .map(|k| profile.points(&outcome.points, k).to_vec())
            .collect();
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut atz = nalgebra::Vector3::<f64>::zeros();
        for x in planes.iter().flatten() {
            let row = nalgebra::Vector3::new(x.x, x.y, 1.0);
            ata += row * row.transpose();
            atz += row * x.z;
        }
        let abc = ata
            .try_inverse()
            .map(|inv| inv * atz)
            .ok_or_else(|| refuse("its points do not span a plane".into()))?;
        Ok(ReferenceView {
            name: name.to_string(),
            planes,
            start: Surface::Plane {
                a: abc.x,
                b: abc.y,
                c: abc.z,
            },
        })
    }
}
