//! One capture's result as printed and as JSON: [`Reading`], for every instrument.

use serde::Serialize;
use tangent_core::calibration::Calibration;
use tangent_core::instrument::wall::WallMeasurement;
use tangent_core::pipeline::PipelineError;
use tangent_core::protocol::codes::{self, Failure};

use super::Solved;
use crate::capture::Capture;
use crate::measure_wall::{self, WallReport};
use crate::road::RoadReport;

/// Tilt of the stem, in degrees for people.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TiltReport {
    /// Total angle between the stem axis and the laser plane's normal (degrees).
    pub total_deg: f64,
    /// Lean towards (+) or away from the instrument (degrees).
    pub theta_deg: f64,
    /// Sideways lean (degrees).
    pub phi_deg: f64,
}

/// One capture's result, as printed and as JSON (`--json`). The keys are the stem's; a
/// sphere's reading adds `instrument = "sphere"`, `centre_m` and `sections_diameter_m`, and
/// gives its joint fit as `fit_diameter_m`, its three-tangent construction as
/// `three_tangent_diameter_m` and its centre's distance from the camera as `distance_m`.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Reading {
    /// The capture directory.
    pub capture: String,
    /// The instrument, for every reading but the stem's (`"sphere"`, …).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instrument: Option<&'static str>,
    /// A sphere's centre (camera frame, metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub centre_m: Option<[f64; 3]>,
    /// A sphere's diameter from its circle sections (metres), when they gave one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sections_diameter_m: Option<f64>,
    /// The random part of a sphere's `uncertainty_m` (without the calibration's; metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub random_uncertainty_m: Option<f64>,
    /// Reported diameter (metres), absent on error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub diameter_m: Option<f64>,
    /// 1σ uncertainty of the diameter (metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_m: Option<f64>,
    /// Method of the reported diameter.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub method: Option<&'static str>,
    /// Quality flags.
    pub flags: Vec<&'static str>,
    /// Tilt, when measured (two planes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tilt: Option<TiltReport>,
    /// Major and minor diameters of an elliptic section (metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub axes_m: Option<(f64, f64)>,
    /// Three-tangent diameter (metres), when it succeeded.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub three_tangent_diameter_m: Option<f64>,
    /// Fit diameter (metres), when it succeeded.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_diameter_m: Option<f64>,
    /// 1σ of the fit diameter that the points' own σ and their correlation along the stripe
    /// allow (metres; stems: the single-exposure information bound, `docs/error-model.md` §6).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub information_uncertainty_m: Option<f64>,
    /// The diameter the fit's second-order pull correction removed (metres; stems, 0 when
    /// none was evaluated, `docs/error-model.md` §5e).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pull_correction_m: Option<f64>,
    /// Distance from the laser source to the stem (metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance_m: Option<f64>,
    /// Curve points used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub points: Option<usize>,
    /// Exposure pairs a stem reading combines, when more than one
    /// (`docs/error-model.md` §6, (E7)).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exposures: Option<usize>,
    /// Exposure pairs the capture holds, when more than one (some may give no reading or be
    /// dropped as stray).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exposure_pairs: Option<usize>,
    /// Why no diameter was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The true diameter, for synthetic captures with ground truth (metres).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth_diameter_m: Option<f64>,
    /// Why the capture's optional truth curve was not read (the reading is unaffected).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth_curve_unreadable: Option<String>,
    /// A road capture's reading (`docs/road.md`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub road: Option<RoadReport>,
    /// The wall instrument's readings (captures of mode `wall`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wall: Option<WallReport>,
}

impl Reading {
    /// A reading of `capture` with no key set but the capture's name (the base every
    /// instrument's reading fills in).
    pub(super) fn of_capture(capture: &str, instrument: Option<&'static str>) -> Self {
        Reading {
            capture: capture.to_string(),
            instrument,
            ..Reading::default()
        }
    }

    pub(super) fn from_result(
        capture: &str,
        result: &Result<Solved, PipelineError>,
        calibration: &Calibration,
        truth: Option<f64>,
    ) -> Self {
        match result {
            Ok(Solved::Sphere(m)) => {
                let s = &m.solution;
                Reading {
                    centre_m: Some([s.centre.x, s.centre.y, s.centre.z]),
                    sections_diameter_m: s.sections.map(|e| e.diameter),
                    random_uncertainty_m: Some(s.random_uncertainty),
                    diameter_m: Some(s.diameter),
                    uncertainty_m: Some(s.uncertainty),
                    method: Some(codes::method_name(s.method)),
                    flags: codes::flag_names(s.flags).collect(),
                    three_tangent_diameter_m: s.three_tangent.map(|e| e.diameter),
                    fit_diameter_m: s.joint_fit.map(|e| e.diameter),
                    distance_m: Some(s.distance),
                    points: Some(m.profile.plane_points.iter().map(|(a, b)| b - a).sum()),
                    truth_diameter_m: truth,
                    ..Reading::of_capture(capture, Some("sphere"))
                }
            }
            Ok(Solved::Stem(m)) => {
                let s = &m.solution;
                Reading {
                    diameter_m: Some(s.diameter),
                    uncertainty_m: Some(s.uncertainty),
                    method: Some(codes::method_name(s.method)),
                    flags: codes::flag_names(s.flags).collect(),
                    tilt: s.tilt.map(|t| TiltReport {
                        total_deg: t.total.to_degrees(),
                        theta_deg: t.theta.to_degrees(),
                        phi_deg: t.phi.to_degrees(),
                    }),
                    axes_m: s.axes,
                    three_tangent_diameter_m: s.three_tangent_diameter,
                    fit_diameter_m: s.fit_diameter,
                    information_uncertainty_m: s.information_uncertainty,
                    pull_correction_m: Some(s.pull_correction),
                    distance_m: Some(s.distance),
                    points: Some(s.n_points),
                    exposures: (s.exposures > 1).then_some(s.exposures),
                    truth_diameter_m: truth,
                    ..Reading::of_capture(capture, None)
                }
            }
            // The walls' keys come from `from_wall`; this arm keeps `from_result` total.
            Ok(Solved::Wall(m)) => Reading::from_wall(capture, Ok(m), calibration, None),
            Err(e) => Reading {
                // The sentence the caliper's report of this failure reads as.
                error: Some(Failure::of(e).to_string()),
                truth_diameter_m: truth,
                ..Reading::of_capture(capture, None)
            },
        }
    }

    /// The reading of a wall capture: the walls' report, or the error.
    pub(super) fn from_wall(
        capture: &str,
        result: Result<&WallMeasurement, &PipelineError>,
        calibration: &Calibration,
        loaded: Option<&Capture>,
    ) -> Self {
        let blank = Reading::of_capture(capture, Some("wall"));
        match result {
            Ok(m) => Reading {
                flags: measure_wall::flag_names(m),
                points: Some(m.solution.points),
                wall: Some(WallReport::of(
                    &m.solution,
                    calibration,
                    loaded.and_then(|c| measure_wall::wall_truth(c, &m.solution)),
                )),
                ..blank
            },
            Err(e) => Reading {
                error: Some(Failure::of(e).to_string()),
                ..blank
            },
        }
    }

    /// The reading of a road capture: its report, or the sentence of its failure.
    pub fn road(capture: &str, result: Result<RoadReport, String>) -> Self {
        let (road, error) = match result {
            Ok(r) => (Some(r), None),
            Err(e) => (None, Some(e)),
        };
        Reading {
            error,
            road,
            ..Reading::of_capture(capture, Some("road"))
        }
    }

    /// One line for people: `d = 301.2 mm ± 0.8 mm (circle_fit) [flags]` or the error.
    pub fn summary(&self) -> String {
        let mut line = self.result_text();
        if let Some(e) = &self.truth_curve_unreadable {
            line += &format!(" (truth curve ignored: {e})");
        }
        line
    }

    fn result_text(&self) -> String {
        if let Some(r) = &self.road {
            return r.summary();
        }
        if let Some(w) = &self.wall {
            return w.summary(&self.flags);
        }
        match (self.diameter_m, &self.error) {
            (Some(d), _) if self.instrument == Some("sphere") => {
                // `sphere d = 101.6 mm ± 0.4 mm (joint_fit), centre at 0.82 m`
                let mut s = format!(
                    "sphere d = {:.1} mm ± {:.1} mm ({})",
                    d * 1e3,
                    self.uncertainty_m.unwrap_or(f64::NAN) * 1e3,
                    self.method.unwrap_or("?")
                );
                if let Some(z) = self.distance_m {
                    s += &format!(", centre at {z:.2} m");
                }
                if !self.flags.is_empty() {
                    s += &format!(" [{}]", self.flags.join(", "));
                }
                if let Some(t) = self.truth_diameter_m {
                    s += &format!(" (truth {:.1} mm, error {:+.1} mm)", t * 1e3, (d - t) * 1e3);
                }
                s
            }
            (Some(d), _) => {
                let mut s = format!(
                    "d = {:.1} mm ± {:.1} mm ({})",
                    d * 1e3,
                    self.uncertainty_m.unwrap_or(f64::NAN) * 1e3,
                    self.method.unwrap_or("?")
                );
                if let Some(t) = self.tilt {
                    s += &format!(", tilt {:.1}°", t.total_deg);
                }
                if let Some((a, b)) = self.axes_m {
                    s += &format!(", axes {:.1} × {:.1} mm", a * 1e3, b * 1e3);
                }
                if let Some(z) = self.distance_m {
                    s += &format!(", at {:.2} m", z);
                }
                match (self.exposures.unwrap_or(1), self.exposure_pairs) {
                    (k, Some(n)) if k < n => s += &format!(", {k} of {n} exposures"),
                    (k, Some(_)) => s += &format!(", {k} exposures"),
                    _ => {}
                }
                if !self.flags.is_empty() {
                    s += &format!(" [{}]", self.flags.join(", "));
                }
                if let Some(t) = self.truth_diameter_m {
                    s += &format!(" (truth {:.1} mm, error {:+.1} mm)", t * 1e3, (d - t) * 1e3);
                }
                s
            }
            (None, Some(e)) => format!("no reading: {e}"),
            (None, None) => "no reading".to_string(),
        }
    }
}
