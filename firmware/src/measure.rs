//! The on-device measurement: a frame pair and the calibration in, a reading out.
//!
//! [`Measurer`] is the seam between the application and the shared pipeline
//! (`tangent_core::pipeline`), so the application can be tested with a measurer of known
//! behaviour and the pipeline's working memory stays owned by the board's `main`.

use tangent_core::calibration::Calibration;
use tangent_core::image::Frame;
use tangent_core::instrument::{self, InstrumentParams};
use tangent_core::measurement::{Measurement, Mode};
use tangent_core::pipeline::{self, PipelineConfig, PipelineError, Stage, Workspace};
use tangent_core::protocol::codes::Failure;
use tangent_core::real::Real;

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
    /// Measures with the instrument of `mode`; a failure is sent as
    /// [`Failure::device_error`] (the code map and the sentence the host prints are in
    /// `tangent_core::protocol::codes`).
    fn measure(
        &mut self,
        mode: Mode,
        pair: &FramePair<'_>,
        calibration: &Calibration,
    ) -> Result<Measurement, Failure>;
}

/// The shared pipeline (`tangent_core::instrument`, the instrument of the device's mode) with
/// its working memory.
pub struct PipelineMeasurer<'w> {
    ws: Workspace<'w, u8>,
    /// Image-chain parameters.
    pub config: PipelineConfig,
    /// Every instrument's solver parameters.
    pub params: InstrumentParams,
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
    /// The mode's solver ([`instrument::solve`]).
    pub solver_us: u64,
}

impl<'w> PipelineMeasurer<'w> {
    /// A measurer with the default parameters (those the host uses).
    pub fn new(ws: Workspace<'w, u8>) -> Self {
        PipelineMeasurer {
            ws,
            config: PipelineConfig::default(),
            params: InstrumentParams::default(),
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

impl Measurer for PipelineMeasurer<'_> {
    fn measure(
        &mut self,
        mode: Mode,
        pair: &FramePair<'_>,
        calibration: &Calibration,
    ) -> Result<Measurement, Failure> {
        if !instrument::supports(mode) {
            return Err(Failure::UnsupportedMode(mode));
        }
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
        let solved = instrument::solve(
            mode,
            &profile,
            on.max_value(),
            cal,
            &self.params,
            &mut self.ws,
        );
        self.last_stages.solver_us = now().saturating_sub(t);
        solved.map_err(|e| Failure::of(&e))
    }
}
