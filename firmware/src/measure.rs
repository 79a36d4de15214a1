//! The on-device measurement: a frame pair and the calibration in, a reading out.
//!
//! [`Measurer`] is the seam between the application and the shared pipeline
//! (`tangent_core::pipeline`), so the application can be tested with a measurer of known
//! behaviour and the pipeline's working memory stays owned by the board's `main`. A measurer
//! that streams ([`StreamMeasurer`], the pipeline's) takes the laser-off frame into its own
//! memory and the laser-on frame row block by row block as the camera reads it out
//! (`tangent_core::pipeline::ProfileStream`), so only the work after the last pixel is left
//! when the frame is in.

use heapless::Vec;
use tangent_core::calibration::Calibration;
use tangent_core::image::Frame;
use tangent_core::instrument::stem::Stem;
use tangent_core::instrument::{self, InstrumentParams};
use tangent_core::measurement::{Measurement, Mode};
use tangent_core::pipeline::{
    self, PipelineConfig, PipelineError, ProfileStream, Stage, Workspace,
};
use tangent_core::protocol::codes::Failure;
use tangent_core::real::{Real, Vec3};
use tangent_core::solvers::stem::{combine_exposures, CylinderSolution, MAX_EXPOSURES};

use crate::ports::{Geometry, RowSink};

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

    /// The streaming form of this measurer, if it has one: the application then captures
    /// the laser-off frame into it and streams the laser-on frame through it instead of
    /// storing the pair.
    fn streaming(&mut self) -> Option<&mut dyn StreamMeasurer> {
        None
    }

    /// Gravity in the camera frame (unit, down) and the 1σ of its direction (radians) for
    /// the next measurements, or `None` when the device has no vertical: the wall's plumb
    /// (`tangent_core::accelerometer::vertical`). A measurer without a use for it ignores it.
    fn set_vertical(&mut self, _gravity: Option<(Vec3, Real)>) {}

    /// Starts a reading of several exposures (frame pairs while the trigger is held): the
    /// pairs measured from here until [`Measurer::combined`] are one reading's.
    fn begin_exposures(&mut self) {}

    /// The reading combined from the exposures measured since [`Measurer::begin_exposures`]
    /// (`docs/error-model.md` §6, (E7)), or `None` when this measurer does not combine
    /// them (the application then reports the first exposure that read).
    fn combined(&mut self, _mode: Mode) -> Option<Result<Measurement, Failure>> {
        None
    }
}

/// A measurer fed as the frames are read out: [`StreamMeasurer::begin`] gives the buffer the
/// laser-off frame is captured into, the laser-on frame's rows arrive through [`RowSink`],
/// and [`StreamMeasurer::finish`] does the work after the last pixel.
pub trait StreamMeasurer: RowSink {
    /// Starts a pair of frames of `geometry` measured with `calibration` (of the full
    /// sensor); returns where the laser-off frame goes (`geometry.frame_len()` bytes).
    fn begin(
        &mut self,
        geometry: Geometry,
        calibration: &Calibration,
    ) -> Result<&mut [u8], Failure>;
    /// The measurement with the instrument of `mode`, once the laser-on frame's last row is
    /// in.
    fn finish(&mut self, mode: Mode) -> Result<Measurement, Failure>;
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
    /// The pair being streamed: its state, its calibration (of the frames' window) and the
    /// first error the rows met.
    stream: Option<(ProfileStream, Calibration, Option<PipelineError>)>,
    /// The stem solutions of the reading's exposures so far ([`Measurer::begin_exposures`]).
    exposures: Vec<CylinderSolution, MAX_EXPOSURES>,
}

/// Durations of the stages of the last measurement (µs of the measurer's `stage_clock`), for
/// the instruction-count benchmark: the work during the read-out, then the image stages in
/// the order of [`pipeline::Stage`] (each from the end of the previous one), then the solver.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StageTimes {
    /// Work on the laser-on rows as they arrive (subtraction, histogram, candidate runs):
    /// the sum over the row blocks, 0 for a stored pair.
    pub readout_us: u64,
    /// The longest of those blocks (µs): the read-out's worst case against the pixel clock.
    pub readout_block_max_us: u64,
    /// After the last pixel: statistics and darkness tests, threshold, segmentation,
    /// selection, curve extraction, growing, smoothing and triangulation, the faint search
    /// (for a stored pair the first includes the whole subtraction; a stage the chain did not
    /// reach is 0).
    pub image_us: [u64; 8],
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
            stream: None,
            exposures: Vec::new(),
        }
    }

    fn now(&self) -> u64 {
        self.stage_clock.map_or(0, |clock| clock())
    }

    /// The image stages' times from `start` and the solver's, then the reading: the part of a
    /// measurement after the profile's stages have been probed.
    fn solve(
        &mut self,
        mode: Mode,
        profile: Result<pipeline::Profile, PipelineError>,
        cal: &Calibration,
    ) -> Result<Measurement, Failure> {
        let profile = profile.map_err(|e| Failure::of(&instrument::image_failure(mode, e)))?;
        let t = self.now();
        // 8-bit frames: full scale 255.
        let solved = if mode == Mode::Cylinder {
            // The stem's solution is kept whole: the reading's exposures combine from it.
            let solution = instrument::solve_with::<Stem, u8>(
                &profile,
                255,
                cal,
                &self.params.cylinder,
                &mut self.ws,
            );
            if let Ok(s) = &solution {
                // Never full: the application measures at most `MAX_EXPOSURES` pairs per
                // reading, and one beyond would only be left out of the combination.
                let _ = self.exposures.push(*s);
            }
            solution.map(|s| Measurement::from(&s))
        } else {
            instrument::solve(mode, &profile, 255, cal, &self.params, &mut self.ws)
        };
        self.last_stages.solver_us = self.now().saturating_sub(t);
        solved.map_err(|e| Failure::of(&e))
    }
}

/// Index of a stage in [`StageTimes::image_us`].
fn stage_index(stage: Stage) -> usize {
    match stage {
        Stage::Subtracted => 0,
        Stage::Thresholded => 1,
        Stage::Segmented => 2,
        Stage::Selected => 3,
        Stage::Extracted => 4,
        Stage::Grown => 5,
        Stage::Triangulated => 6,
        Stage::FaintSearched => 7,
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
        let config = instrument::pipeline_config(mode, &self.config);
        let profile =
            pipeline::extract_profile_probed(&off, &on, cal, &config, &mut self.ws, |stage| {
                let t = now();
                stages.image_us[stage_index(stage)] = t.saturating_sub(last);
                last = t;
            });
        self.last_stages = stages;
        self.solve(mode, profile, cal)
    }

    fn streaming(&mut self) -> Option<&mut dyn StreamMeasurer> {
        Some(self)
    }

    fn set_vertical(&mut self, gravity: Option<(Vec3, Real)>) {
        self.params.wall.walls.gravity = gravity;
    }

    fn begin_exposures(&mut self) {
        self.exposures.clear();
    }

    fn combined(&mut self, mode: Mode) -> Option<Result<Measurement, Failure>> {
        if mode != Mode::Cylinder || self.exposures.is_empty() {
            return None;
        }
        Some(
            combine_exposures(&self.exposures)
                .map(|s| Measurement::from(&s))
                .map_err(|e| Failure::of(&PipelineError::Solve(e))),
        )
    }
}

impl RowSink for PipelineMeasurer<'_> {
    fn rows(&mut self, rows: &[u8]) {
        let t = self.now();
        if let Some((stream, _, error @ None)) = &mut self.stream {
            if let Err(e) = stream.push_rows(&mut self.ws, rows) {
                *error = Some(e);
            }
        }
        let spent = self.now().saturating_sub(t);
        self.last_stages.readout_us += spent;
        self.last_stages.readout_block_max_us = self.last_stages.readout_block_max_us.max(spent);
    }
}

impl StreamMeasurer for PipelineMeasurer<'_> {
    fn begin(
        &mut self,
        geometry: Geometry,
        calibration: &Calibration,
    ) -> Result<&mut [u8], Failure> {
        let (height, row_offset) = (geometry.height as usize, geometry.row_offset as usize);
        let cal = if row_offset == 0 && calibration.camera.height as usize == height {
            calibration.clone()
        } else {
            window_calibration(calibration, row_offset, height)
        };
        self.last_stages = StageTimes::default();
        let stream = ProfileStream::begin(&mut self.ws, &cal, &self.config, 8)
            .map_err(|e| Failure::of(&e))?;
        self.stream = Some((stream, cal, None));
        let len = geometry.frame_len();
        let n = self.ws.diff.len();
        self.ws
            .diff
            .get_mut(..len)
            .ok_or(Failure::of(&PipelineError::WorkspaceTooSmall {
                buffer: "diff",
                needed: len,
                actual: n,
            }))
    }

    fn finish(&mut self, mode: Mode) -> Result<Measurement, Failure> {
        if !instrument::supports(mode) {
            return Err(Failure::UnsupportedMode(mode));
        }
        let Some((stream, cal, error)) = self.stream.take() else {
            return Err(Failure::of(&PipelineError::Frame(
                tangent_core::image::FrameError::Empty,
            )));
        };
        if let Some(e) = error {
            return Err(Failure::of(&e));
        }
        let clock = self.stage_clock;
        let now = move || clock.map_or(0, |clock| clock());
        let mut stages = self.last_stages;
        let mut last = now();
        // `begin` ran on the base settings (the mode is known only now): the instruments'
        // own settings differ from them only in what is done here (fragments kept, smoothing).
        let config = instrument::pipeline_config(mode, &self.config);
        let profile = stream.finish_probed(&mut self.ws, &cal, &config, |stage| {
            let t = now();
            stages.image_us[stage_index(stage)] = t.saturating_sub(last);
            last = t;
        });
        self.last_stages = stages;
        self.solve(mode, profile, &cal)
    }
}
