//! The on-device measurement: a frame pair and the calibration in, a reading out.
//!
//! [`Measurer`] is the seam between the application and the shared pipeline
//! (`tangent_core::pipeline`), so the application can be tested with a measurer of known
//! behaviour and the pipeline's working memory stays owned by the board's `main`.

use tangent_core::calibration::Calibration;
use tangent_core::curve::CurvePoint;
use tangent_core::image::segment::ObjectFeatures;
use tangent_core::image::Frame;
use tangent_core::measurement::{Axes, Measurement, StemReading, TiltAngles};
use tangent_core::pipeline::{self, PipelineConfig, PipelineError, Stage, Workspace};
use tangent_core::protocol::codes::Failure;
use tangent_core::real::{Real, Vec2, Vec3};
use tangent_core::solvers::stem::{CylinderParams, CylinderSolution};

/// A captured frame pair, 8-bit, row-major, `width` bytes per row.
#[derive(Debug, Clone, Copy)]
pub struct FramePair<'a> {
    /// Laser-off frame.
    pub off: &'a [u8],
    /// Laser-on frame.
    pub on: &'a [u8],
    /// Width (pixels).
    pub width: usize,
    /// Height (pixels).
    pub height: usize,
    /// Sensor row of the frames' first row (windowed read-out).
    pub row_offset: usize,
    /// Lasers lit in `on` (bit i = plane i).
    pub laser_mask: u8,
}

/// Runs the measurement on a frame pair.
pub trait Measurer {
    /// Measures; a failure is sent as [`Failure::device_error`] (the code map and the
    /// sentence the host prints are in `tangent_core::protocol::codes`).
    fn measure(
        &mut self,
        pair: &FramePair<'_>,
        calibration: &Calibration,
    ) -> Result<Measurement, Failure>;
}

/// Label-table entries of the workspace (`pipeline::WorkspaceSizes::new`).
pub const LABEL_TABLE: usize = 4096;
/// Object-feature entries of the workspace.
pub const OBJECTS: usize = 1024;
/// Histogram bins for 8-bit frames.
pub const HISTOGRAM: usize = 256;

/// Curve/point entries for `width` columns and `planes` planes
/// (`pipeline::WorkspaceSizes::new`: two per column and plane).
pub const fn points_for(width: usize, planes: usize) -> usize {
    width * planes * 2
}

/// The pipeline's point and table buffers (everything but the two per-pixel buffers and the
/// object features), const-constructible so a board can place them in a static of its choice.
pub struct SmallBuffers<const POINTS: usize> {
    /// Histogram.
    pub histogram: [u32; HISTOGRAM],
    /// Segmentation equivalence table.
    pub label_table: [u16; LABEL_TABLE],
    /// Curve points.
    pub curve: [CurvePoint; POINTS],
    /// 3-D points.
    pub points: [Vec3; POINTS],
    /// 1σ of each 3-D point.
    pub sigmas: [Real; POINTS],
    /// Solver scratch (2-D).
    pub scratch_points: [Vec2; POINTS],
    /// Solver scratch (values).
    pub scratch_values: [Real; POINTS],
}

impl<const POINTS: usize> SmallBuffers<POINTS> {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        SmallBuffers {
            histogram: [0; HISTOGRAM],
            label_table: [0; LABEL_TABLE],
            curve: [CurvePoint::ZERO; POINTS],
            points: [Vec3::new(0.0, 0.0, 0.0); POINTS],
            sigmas: [0.0; POINTS],
            scratch_points: [Vec2::new(0.0, 0.0); POINTS],
            scratch_values: [0.0; POINTS],
        }
    }
}

impl<const POINTS: usize> Default for SmallBuffers<POINTS> {
    fn default() -> Self {
        Self::new()
    }
}

/// Object-feature buffer of the workspace (≈ 57 KB: placed separately from
/// [`SmallBuffers`] so boards can spread the workspace over RAM regions).
pub type Objects = [ObjectFeatures; OBJECTS];

/// An all-zero [`Objects`] buffer (all-zero so that a static of it lands in `.bss`, not in
/// `.data` with a 57 KB image in flash; the pipeline initialises every entry it uses).
#[allow(clippy::large_const_arrays)] // only used to initialise statics (zeroed, in .bss)
pub const NO_OBJECTS: Objects = [ZERO_OBJECT; OBJECTS];

const ZERO_OBJECT: ObjectFeatures = ObjectFeatures {
    label: 0,
    pixel_count: 0,
    min_x: 0,
    max_x: 0,
    min_y: 0,
    max_y: 0,
    intensity_sum: 0,
    intensity_x_sum: 0,
    intensity_y_sum: 0,
    x_sum: 0,
    y_sum: 0,
    peak_intensity: 0,
};

/// Assembles a [`Workspace`] from a board's buffers.
pub fn workspace<'w, const POINTS: usize>(
    diff: &'w mut [u8],
    labels: &'w mut [u16],
    objects: &'w mut Objects,
    small: &'w mut SmallBuffers<POINTS>,
) -> Workspace<'w, u8> {
    Workspace {
        diff,
        labels,
        histogram: &mut small.histogram,
        label_table: &mut small.label_table,
        objects,
        curve: &mut small.curve,
        points: &mut small.points,
        sigmas: &mut small.sigmas,
        scratch_points: &mut small.scratch_points,
        scratch_values: &mut small.scratch_values,
    }
}

/// The shared pipeline (`tangent_core::pipeline::measure_stem`) with its working memory.
pub struct PipelineMeasurer<'w> {
    ws: Workspace<'w, u8>,
    /// Image-chain parameters.
    pub config: PipelineConfig,
    /// Cylinder-solver parameters.
    pub params: CylinderParams,
    /// A free-running clock (µs) to time the pipeline's stages with, or `None`.
    pub stage_clock: Option<fn() -> u64>,
    /// Durations of the last measurement's stages (µs of `stage_clock`; zero without a clock
    /// and for the stages a failure kept from running).
    pub last_stages: StageTimes,
}

/// Durations of the stages of the last measurement (µs of the measurer's `stage_clock`), for
/// the instruction-count benchmark: the image stages in the order of
/// [`pipeline::Stage`] (each from the end of the previous one), then the solver.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StageTimes {
    /// Subtraction, threshold, segmentation, selection, curve extraction, triangulation.
    pub image_us: [u64; 6],
    /// Cylinder solver ([`pipeline::solve_stem`]).
    pub solver_us: u64,
}

impl<'w> PipelineMeasurer<'w> {
    /// A measurer with the default parameters (those the host uses).
    pub fn new(ws: Workspace<'w, u8>) -> Self {
        PipelineMeasurer {
            ws,
            config: PipelineConfig::default(),
            params: CylinderParams::default(),
            stage_clock: None,
            last_stages: StageTimes::default(),
        }
    }
}

/// The calibration of a window of rows: the same camera with the principal point moved up
/// by `row_offset` and the height of the window, so that frame row `r` is sensor row
/// `r + row_offset` (the pinhole model is invariant to this shift of the image origin).
pub fn window_calibration(cal: &Calibration, row_offset: usize, height: usize) -> Calibration {
    let mut c = cal.clone();
    c.camera.cy -= row_offset as Real;
    c.camera.height = height as u32;
    c
}

/// The reading of a stem solution, as the wire and the host know it.
pub fn stem_reading(s: &CylinderSolution) -> Measurement {
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
    })
}

impl Measurer for PipelineMeasurer<'_> {
    fn measure(
        &mut self,
        pair: &FramePair<'_>,
        calibration: &Calibration,
    ) -> Result<Measurement, Failure> {
        let frame = |data| {
            Frame::new(data, pair.width, pair.height, pair.width)
                .map_err(|e| Failure::of(&PipelineError::Frame(e)))
        };
        let off = frame(pair.off)?;
        let on = frame(pair.on)?;
        let windowed;
        let cal = if pair.row_offset == 0 && calibration.camera.height as usize == pair.height {
            calibration
        } else {
            windowed = window_calibration(calibration, pair.row_offset, pair.height);
            &windowed
        };
        let clock = self.stage_clock;
        let now = move || clock.map_or(0, |clock| clock());
        let mut stages = StageTimes::default();
        let mut last = now();
        let profile =
            pipeline::extract_profile_probed(&off, &on, cal, &self.config, &mut self.ws, |stage| {
                let t = now();
                let i = match stage {
                    Stage::Subtracted => 0,
                    Stage::Thresholded => 1,
                    Stage::Segmented => 2,
                    Stage::Selected => 3,
                    Stage::Extracted => 4,
                    Stage::Triangulated => 5,
                };
                stages.image_us[i] = t.saturating_sub(last);
                last = t;
            });
        self.last_stages = stages;
        let profile = profile.map_err(|e| Failure::of(&e))?;
        let t = now();
        let solved =
            pipeline::solve_stem(&profile, on.max_value(), cal, &self.params, &mut self.ws);
        self.last_stages.solver_us = now().saturating_sub(t);
        let solved = solved.map_err(|e| Failure::of(&e))?;
        Ok(stem_reading(&solved.solution))
    }
}
