//! The road instrument on the host (`docs/road.md`): the report people read of the core's
//! road solution, the raw profile behind it, the simulator's truth (the true profile along
//! the laser sheet, its MPD), and around them the furrow depth and the piezo height-scale
//! calibration ([`height_scale`]), the ambulatory section ([`section`]), the cross-check
//! against captif-slp ([`crosscheck`]) and the plot ([`plot`]). Captures are measured by
//! `measure::measure_road` (the one way frames are loaded and run through the core); the
//! evaluation is `evaluate_road`.

use serde::Serialize;
use tangent_core::calibration::Calibration;
use tangent_core::instrument::road::{RoadParams, RoadSolution, MAX_SEGMENTS};
use tangent_core::instrument::Measured;
use tangent_core::pipeline::PipelineError;
use tangent_core::real::{Vec2, Vec3};
use tangent_core::solvers::mpd::{self, MeanProfileDepth, SegmentDepth};
use tangent_core::solvers::road_profile::{self, RoadError};

use crate::capture::Capture;
use crate::simulate::scene::road_height;
use crate::truth::Object;

pub mod crosscheck;
pub mod height_scale;
pub mod plot;
pub mod section;

/// A road reading as people read it (millimetres, degrees) and as `--json` prints it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RoadReport {
    /// Mean profile depth (mm).
    pub mpd_mm: f64,
    /// Its predicted 1σ (mm; `docs/road.md`, "Uncertainty").
    pub mpd_uncertainty_mm: f64,
    /// Estimated texture depth `0.2 + 0.8·MPD` (mm).
    pub etd_mm: f64,
    /// Mean segment depth of each segment (mm).
    pub msd_mm: Vec<f64>,
    /// Profile samples in the window, drop-outs included.
    pub samples: usize,
    /// Drop-outs among them.
    pub dropouts: usize,
    /// Spikes removed after resampling.
    pub spikes: usize,
    /// Sample spacing (mm).
    pub spacing_mm: f64,
    /// RMS height of the filtered profile (mm).
    pub rms_height_mm: f64,
    /// Mean height relative to the stand-off (mm, + nearer).
    pub mean_height_mm: f64,
    /// Tilt of the road against the head (degrees).
    pub tilt_deg: f64,
    /// Microtexture RMS height on the highest peak (µm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub micro_rms_um: Option<f64>,
    /// Curvature of that peak's top (1/mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_curvature_per_mm: Option<f64>,
    /// Position of the peak along the line (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_mm: Option<f64>,
    /// The true surface's MPD, for synthetic captures (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth_mpd_mm: Option<f64>,
}

impl RoadReport {
    /// The report of a solution; `truth_mpd` from [`true_mpd`].
    pub fn new(s: &RoadSolution, truth_mpd: Option<f64>) -> Self {
        RoadReport {
            mpd_mm: s.depth.mpd * 1e3,
            mpd_uncertainty_mm: s.uncertainty * 1e3,
            etd_mm: s.depth.etd * 1e3,
            msd_mm: s.segments[..s.depth.segments.min(MAX_SEGMENTS)]
                .iter()
                .map(|g| g.msd * 1e3)
                .collect(),
            samples: s.profile.samples,
            dropouts: s.profile.dropouts,
            spikes: s.depth.spikes,
            spacing_mm: s.profile.spacing * 1e3,
            rms_height_mm: s.rms_height * 1e3,
            mean_height_mm: s.profile.mean_height * 1e3,
            tilt_deg: s.profile.tilt.to_degrees(),
            micro_rms_um: s.micro.map(|m| m.rms_height * 1e6),
            peak_curvature_per_mm: s.micro.map(|m| m.curvature * 1e-3),
            peak_mm: s.micro.map(|m| m.peak * 1e3),
            truth_mpd_mm: truth_mpd.map(|t| t * 1e3),
        }
    }

    /// One line: MPD, ETD, profile statistics, microtexture, truth.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "MPD = {:.3} mm ± {:.3} mm, ETD = {:.3} mm; profile {} samples at {:.2} mm, {} drop-outs ({:.1} %), {} spikes, RMS {:.3} mm, tilt {:.1}°, height {:+.2} mm",
            self.mpd_mm,
            self.mpd_uncertainty_mm,
            self.etd_mm,
            self.samples,
            self.spacing_mm,
            self.dropouts,
            100.0 * self.dropouts as f64 / self.samples.max(1) as f64,
            self.spikes,
            self.rms_height_mm,
            self.tilt_deg,
            self.mean_height_mm
        );
        if let (Some(r), Some(c)) = (self.micro_rms_um, self.peak_curvature_per_mm) {
            s += &format!("; microtexture on the peak: RMS {r:.1} µm, curvature {c:.2} /mm");
        }
        if let Some(t) = self.truth_mpd_mm {
            s += &format!(" (truth MPD {:.3} mm, error {:+.3} mm)", t, self.mpd_mm - t);
        }
        s
    }
}

/// A road capture measured: the instrument's answer and the profile behind it
/// (`measure::measure_road` builds it).
#[derive(Debug, Clone)]
pub struct RoadOutcome {
    /// The instrument's result.
    pub result: Result<RoadSolution, PipelineError>,
    /// The raw profile `(s, h)` (metres; drop-outs NaN), when the pipeline found a curve.
    pub profile: Vec<Vec2>,
    /// The calibration used.
    pub calibration: Calibration,
    /// The true MPD, for synthetic captures (metres).
    pub truth_mpd: Option<f64>,
}

impl RoadOutcome {
    /// The outcome of the core's answer on `capture`: `points` are the pipeline's 3-D points,
    /// from which plane 0's raw profile is rebuilt for plots and cross-checks.
    pub fn new(
        capture: &Capture,
        result: Result<Measured<RoadSolution>, PipelineError>,
        points: &[Vec3],
        calibration: Calibration,
        params: &RoadParams,
    ) -> Self {
        let plane_points = match &result {
            Ok(m) => m.profile.points(points, 0),
            Err(_) => points,
        };
        let profile = calibration
            .planes
            .first()
            .and_then(|p| p.axis_crossing())
            .and_then(|z_ref| raw_profile(plane_points, z_ref, params).ok())
            .unwrap_or_default();
        RoadOutcome {
            result: result.map(|m| m.solution),
            profile,
            truth_mpd: true_mpd(capture, &calibration, params),
            calibration,
        }
    }
}

/// The raw profile of plane 0's points ([`road_profile::road_profile`], drop-outs NaN).
pub fn raw_profile(
    points: &[Vec3],
    z_ref: f64,
    params: &RoadParams,
) -> Result<Vec<Vec2>, RoadError> {
    let mut steps = vec![0.0; points.len() + 1];
    let mut out = vec![Vec2::zeros(); points.len() * 4 + 64];
    let s = road_profile::road_profile(points, z_ref, &params.profile, &mut steps, &mut out)?;
    out.truncate(s.samples);
    Ok(out)
}

/// What [`mpd_of_profile`] gives: the MPD, each segment, the drop-out-corrected heights and
/// the filtered resampled profile.
pub type ProfileDepth = (MeanProfileDepth, Vec<SegmentDepth>, Vec<f64>, Vec<f64>);

/// The MPD chain on a profile (allocating the core's buffers): the result, each segment,
/// the drop-out-corrected heights and the filtered resampled profile.
pub fn mpd_of_profile(profile: &[Vec2], params: &RoadParams) -> Result<ProfileDepth, RoadError> {
    let n = profile.len();
    let bins = (params.profile.window_length / params.mpd.spacing).ceil() as usize + 2;
    let mut heights = vec![0.0; n];
    let (mut resampled, mut marks) = (vec![0.0; bins], vec![0.0; bins]);
    let mut segments = vec![SegmentDepth::default(); 64];
    let m = mpd::mean_profile_depth(
        profile,
        params.profile.window_start,
        params.profile.window_length,
        &params.mpd,
        &mut heights,
        &mut resampled,
        &mut marks,
        &mut segments,
    )?;
    segments.truncate(m.segments);
    resampled.truncate(m.resampled);
    Ok((m, segments, heights, resampled))
}

/// Spacing of the dense true profile (metres): well below the 0.15 mm columns.
pub const TRUTH_SPACING: f64 = 0.02e-3;

/// The true profile along plane 0's sheet over the evaluation window, every
/// [`TRUTH_SPACING`]: for each `x`, the point of the laser plane on the first road or plane
/// of the scene (fixed point in depth), as height `z_ref − z` (+ nearer). `None` when the
/// capture has no truth of a road or plane.
pub fn true_profile(
    objects: &[Object],
    calibration: &Calibration,
    params: &RoadParams,
) -> Option<Vec<Vec2>> {
    let plane = calibration.planes.first()?;
    let z_ref = plane.axis_crossing()?;
    let (n, d) = (plane.normal, plane.offset);
    if n.y.abs() < 1e-9 {
        return None;
    }
    let depth_at = |x: f64, z: f64| -> Option<f64> {
        let y = (d - n.x * x - n.z * z) / n.y;
        objects.iter().find_map(|o| match o {
            Object::Road(r) => Some(r.distance_m + road_height(&r.waves, x, y)),
            Object::Plane(p) if p.normal[2].abs() > 1e-9 => {
                // Plane: normal·(X − point) = 0 solved for z.
                let [px, py, pz] = p.point_m;
                let [a, b, c] = p.normal;
                Some(pz - (a * (x - px) + b * (y - py)) / c)
            }
            _ => None,
        })
    };
    let (s0, len) = (params.profile.window_start, params.profile.window_length);
    let count = (len / TRUTH_SPACING).round() as usize;
    let mut out = Vec::with_capacity(count + 1);
    for k in 0..=count {
        let x = s0 + k as f64 * TRUTH_SPACING;
        let mut z = z_ref;
        for _ in 0..60 {
            z = depth_at(x, z)?;
        }
        out.push(Vec2::new(x, z_ref - z));
    }
    Some(out)
}

/// The MPD of the true profile (metres), for synthetic captures of a road.
pub fn true_mpd(capture: &Capture, calibration: &Calibration, params: &RoadParams) -> Option<f64> {
    let objects = &capture.meta.truth.as_ref()?.objects;
    let profile = true_profile(objects, calibration, params)?;
    mpd_of_profile(&profile, params).ok().map(|r| r.0.mpd)
}
