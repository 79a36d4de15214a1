//! The on-device measurement: a frame pair and the calibration in, a reading out.
//!
//! [`Measurer`] is the seam between the application and the shared pipeline
//! (`tangent_core::pipeline`), so the application can be tested with a measurer of known
//! behaviour and the pipeline's working memory stays owned by the board's `main`.

use tangent_core::calibration::Calibration;
use tangent_core::protocol::Method;

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

/// What a measurement found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// The solver used.
    pub method: Method,
    /// Diameter (metres).
    pub diameter_m: f32,
    /// Predicted standard uncertainty (metres).
    pub uncertainty_m: f32,
    /// Distance to the stem axis (metres).
    pub distance_m: f32,
    /// Tilt (radians).
    pub tilt_rad: f32,
    /// [`tangent_core::protocol::flags`].
    pub flags: u16,
}

/// Runs the measurement on a frame pair.
pub trait Measurer {
    /// Measures; the error is a code sent as the detail of
    /// [`tangent_core::protocol::ErrorCode::MeasurementFailed`].
    fn measure(&mut self, pair: &FramePair<'_>, calibration: &Calibration) -> Result<Outcome, u32>;
}

/// Detail code of a measurement the firmware could not attempt because the shared
/// pipeline is not linked in yet.
pub const PIPELINE_UNAVAILABLE: u32 = 0xFFFF;

/// The shared pipeline (`tangent_core::pipeline`) with its working memory.
pub struct PipelineMeasurer {
    _private: (),
}

impl PipelineMeasurer {
    /// A measurer.
    pub fn new() -> Self {
        PipelineMeasurer { _private: () }
    }
}

impl Default for PipelineMeasurer {
    fn default() -> Self {
        Self::new()
    }
}

impl Measurer for PipelineMeasurer {
    fn measure(&mut self, _pair: &FramePair<'_>, _calibration: &Calibration) -> Result<Outcome, u32> {
        Err(PIPELINE_UNAVAILABLE)
    }
}
