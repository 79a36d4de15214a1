//! The road instrument ([`Mode::Road`]): plane 0's laser curve as a road profile
//! ([`crate::solvers::road_profile`]), its ISO 13473-1 mean profile depth and the
//! microtexture on its highest macrotexture peak ([`crate::solvers::mpd`]); `docs/road.md`.

use crate::calibration::{Calibration, CalibrationError};
use crate::camera::Camera;
use crate::curve::MAX_CURVES;
use crate::laser_plane::LaserPlane;
use crate::measurement::{Measurement, Micro, Mode, RoadReading};
use crate::pipeline::{GrowParams, PipelineConfig, PipelineError};
#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Real};
use crate::solvers::mpd::{self, MeanProfileDepth, Microtexture, MpdParams, SegmentDepth};
use crate::solvers::result::Flags;
use crate::solvers::road_profile::{self, ProfileParams, ProfileSummary, RoadError};

use super::{Instrument, PlanePoints, Scratch};

/// Focal length of the road head's lens in pixels: 12 mm over the MT9V034's 6 µm pixels
/// (`docs/road.md`, "The road head").
pub const ROAD_HEAD_FOCAL_PX: Real = 2000.0;
/// Distance from the camera to the road the head stands on (metres).
pub const ROAD_HEAD_STANDOFF: Real = 0.3;
/// Baseline between the camera centre and the laser (metres).
pub const ROAD_HEAD_BASELINE: Real = 0.1;

/// The road head's nominal calibration (`docs/hardware.md`, "Road head"): the reference
/// camera's sensor behind a 12 mm lens, one laser plane `ROAD_HEAD_BASELINE` below it tilted
/// to cross the optical axis at the stand-off. A built unit replaces it by its own.
pub fn road_head_calibration(id: u32) -> Result<Calibration, CalibrationError> {
    let camera = Camera {
        fx: ROAD_HEAD_FOCAL_PX,
        fy: ROAD_HEAD_FOCAL_PX,
        ..Camera::reference_design()
    };
    let tilt = (ROAD_HEAD_BASELINE / ROAD_HEAD_STANDOFF).atan();
    let plane = LaserPlane::from_baseline_tilt(ROAD_HEAD_BASELINE, tilt)
        .map_err(|error| CalibrationError::Plane { index: 0, error })?;
    Calibration::new(id, camera, &[plane])
}

/// The road instrument.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Road;

/// Settings of the road instrument.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoadParams {
    /// From points to profile (window, height scale, refusal limits).
    pub profile: ProfileParams,
    /// The MPD chain (ISO 13473-1 defaults).
    pub mpd: MpdParams,
    /// 1σ of one segment's MSD from errors tied to the texture rather than to the column
    /// noise (metres): relief finer than the sheet's thickness across the line, which the
    /// true centre-line profile holds and the stripe averages away, and speckle correlated
    /// over millimetres along it (`docs/road.md`, "Uncertainty"). Default
    /// [`SEGMENT_TEXTURE_SIGMA`].
    pub segment_texture_sigma: Real,
}

/// Default [`RoadParams::segment_texture_sigma`]: fitted on the tuning seeds (3 000 000 on,
/// 84 profiles, 14 of each of six surfaces): their MPD errors' RMS 9.48 µm against the
/// column-noise prediction's 5.75 µm, `√(9.48² − 5.75²)` = 7.5 µm (`docs/accuracy.md`, road
/// section).
pub const SEGMENT_TEXTURE_SIGMA: Real = 7.5e-6;

impl Default for RoadParams {
    fn default() -> Self {
        RoadParams {
            profile: ProfileParams::default(),
            mpd: MpdParams::default(),
            segment_texture_sigma: SEGMENT_TEXTURE_SIGMA,
        }
    }
}

/// Most segments one profile holds (the road head's line spans ≈ 113 mm: one).
pub const MAX_SEGMENTS: usize = 4;

/// Smallest object (pixels) the road head keeps as a piece of its line: two columns of a
/// stripe ≈ 3 rows thick above the threshold (the focused sheet, `docs/road.md`, "The road
/// head"). Under the head's skirt the line is the only lit object, so the caliper's floor
/// against sunlit clutter is not needed; single speckle grains (1–4 pixels) stay out.
pub const ROAD_MIN_PIXELS: u32 = 6;

/// What the road instrument measured on one profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoadSolution {
    /// The profile: samples, drop-outs, spacing, mean height, tilt.
    pub profile: ProfileSummary,
    /// The MPD of the profile's segments.
    pub depth: MeanProfileDepth,
    /// Each segment's depth (the first [`MeanProfileDepth::segments`]).
    pub segments: [SegmentDepth; MAX_SEGMENTS],
    /// RMS height of the filtered, slope-suppressed profile (metres).
    pub rms_height: Real,
    /// Microtexture on the highest peak of the first segment (`None` if too few samples).
    pub micro: Option<Microtexture>,
    /// Stand-off: where plane 0 crosses the optical axis (metres).
    pub standoff: Real,
    /// Predicted 1σ of the MPD (metres): the column noise `σ_c` from second differences,
    /// carried through the resampling (`√(spacing/Δ)`) and the filter (its noise gain `√G`),
    /// each MSD's two peaks independent filtered samples, and the texture-tied error
    /// `σ_t` ([`RoadParams::segment_texture_sigma`]) of each segment:
    /// `σ_MPD = √(σ_c² · spacing/Δ · G / 2 + σ_t²) / √segments` (`docs/road.md`, "Uncertainty").
    pub uncertainty: Real,
    /// Image quality flags.
    pub flags: Flags,
}

impl Instrument for Road {
    const MODE: Mode = Mode::Road;
    type Params = RoadParams;
    type Solution = RoadSolution;

    /// Plane 0's curve is the profile. A refused profile is [`PipelineError::Road`] with the
    /// reason.
    /// The curve is not smoothed: the profile's heights at column resolution are the data,
    /// filtered by the ISO 13473-1 chain alone. The pipeline's quadratic Savitzky–Golay over
    /// 7 columns (1.05 mm on the road) is as wide as a 1 mm furrow: its negative end weights
    /// reach the land and read the floor 5 % too deep, and it attenuates the microtexture
    /// band (`docs/road.md`, "Furrow validation"). And the line breaks at every drop-out
    /// run, so it keeps as many fragments as the workspace holds ([`MAX_CURVES`]): up to 7
    /// drop-out runs are drop-outs, not a lost fragment read as a gap (`docs/road.md`,
    /// "Bad input").
    ///
    /// Drop-outs scattered column by column (a porous or dark surface) break the line into
    /// pieces a few columns wide, taller than wide (the stripe's thickness), more than the
    /// workspace holds. So the shape rule's upper bound is off (under the head's skirt the
    /// line is the only lit object) and the curve is grown along the stripe
    /// ([`crate::pipeline::grow`]) through runs of up to `max_misses` dark columns: the profile
    /// then holds the scattered drop-outs, counted and located, and the standard's 10 %
    /// refuses them by name (`docs/road.md`, "Bad input"). Those pieces are small: the head's
    /// focused sheet images ≈ 1 px thick (σ), ≈ 3 rows above the threshold, so a piece of
    /// three columns is ≈ 9 pixels, below the caliper's 16-pixel floor (set for a trunk's
    /// curve, [`crate::image::select::SelectionParams::default`]); the floor here is [`ROAD_MIN_PIXELS`].
    fn pipeline_config(base: &PipelineConfig) -> PipelineConfig {
        let mut config = *base;
        config.selection.min_pixels = ROAD_MIN_PIXELS;
        config.smooth.half_window = 0;
        config.max_fragments = MAX_CURVES;
        config.selection.max_height_to_width = Real::INFINITY;
        config.grow = Some(GrowParams::default());
        config
    }

    fn solve(
        points: &PlanePoints<'_>,
        params: &RoadParams,
        scratch: Scratch<'_>,
    ) -> Result<RoadSolution, PipelineError> {
        let curve = points.curves().first().copied().unwrap_or(&[]);
        let plane = points.planes().first().ok_or(PipelineError::Calibration)?;
        let standoff = plane.axis_crossing().ok_or(RoadError::NotARoadHead)?;
        let trace = &mut *scratch.points;
        let summary =
            road_profile::road_profile(curve, standoff, &params.profile, scratch.sigmas, trace)?;
        let trace = &trace[..summary.samples];
        let half = scratch.values.len() / 2;
        let (resampled, marks) = scratch.values.split_at_mut(half);
        let mut segments = [SegmentDepth::default(); MAX_SEGMENTS];
        let depth = mpd::mean_profile_depth(
            trace,
            params.profile.window_start,
            params.profile.window_length,
            &params.mpd,
            scratch.sigmas,
            resampled,
            marks,
            &mut segments,
        )?;
        let filtered = &resampled[..depth.resampled];
        let mean = filtered.iter().sum::<Real>() / filtered.len().max(1) as Real;
        let rms_height = sqrt(
            filtered
                .iter()
                .map(|h| (h - mean) * (h - mean))
                .sum::<Real>()
                / filtered.len().max(1) as Real,
        );
        // The chosen macrotexture peak: the higher of the first segment's two.
        let first = segments[0];
        let peak = if first.peaks[0].y >= first.peaks[1].y {
            first.peaks[0].x
        } else {
            first.peaks[1].x
        };
        let heights = &scratch.sigmas[..trace.len()];
        let micro = mpd::microtexture(trace, heights, peak, &params.mpd).ok();
        let uncertainty = mpd_uncertainty(trace, &summary, params, depth.valid_segments);
        Ok(RoadSolution {
            profile: summary,
            depth,
            segments,
            rms_height,
            micro,
            standoff,
            uncertainty,
            flags: points.profile.image_flags(points.full_scale),
        })
    }
}

/// See [`RoadSolution::uncertainty`]. Second differences of white noise have variance
/// `6σ²`; texture at the column scale inflates them, so the estimate errs high.
fn mpd_uncertainty(
    trace: &[crate::real::Vec2],
    summary: &ProfileSummary,
    params: &RoadParams,
    segments: usize,
) -> Real {
    let mpd = &params.mpd;
    let (mut sum, mut n) = (0.0, 0usize);
    for w in trace.windows(3) {
        if w.iter().all(|p| p.y.is_finite()) {
            let d = w[0].y - 2.0 * w[1].y + w[2].y;
            sum += d * d;
            n += 1;
        }
    }
    if n == 0 || segments == 0 {
        return Real::NAN;
    }
    let sigma_column = sqrt(sum / (6.0 * n as Real));
    let gain = mpd::Biquad::butterworth_lowpass(mpd.spacing, mpd.lowpass_cutoff).noise_gain();
    let per_sample = (summary.spacing / mpd.spacing).min(1.0);
    let noise = sigma_column * sigma_column * per_sample * gain / 2.0;
    let texture = params.segment_texture_sigma * params.segment_texture_sigma;
    sqrt((noise + texture) / segments as Real)
}

impl From<&RoadSolution> for Measurement {
    fn from(s: &RoadSolution) -> Self {
        Measurement::Road(RoadReading {
            mpd: s.depth.mpd,
            uncertainty: s.uncertainty,
            etd: s.depth.etd,
            rms_height: s.rms_height,
            mean_height: s.profile.mean_height,
            tilt: s.profile.tilt,
            dropout_fraction: s.profile.dropout_fraction(),
            segments: s.depth.valid_segments.min(255) as u8,
            micro: s.micro.map(|m| Micro {
                rms_height: m.rms_height,
                curvature: m.curvature,
            }),
            flags: s.flags,
        })
    }
}

#[cfg(test)]
mod tests;
