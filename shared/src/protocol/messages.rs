//! The messages of the protocol: what the host asks, what the device answers, and the
//! calibration on the wire (in `f64` whatever either side computes in).

use serde::{Deserialize, Serialize};

use crate::accelerometer::{Alignment, MeanReading};
use crate::calibration::{
    Calibration, CalibrationError, PlanesUncertainty, MAX_PLANES, PLANE_PARAMS,
};
use crate::camera::{Camera, Distortion};
use crate::laser_plane::LaserPlane;
use crate::measurement::{Measurement, Mode};
use crate::real::{Real, Vec3};

/// A host → device frame: a request and the tag its response will echo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ToDevice {
    /// Chosen by the host (non-zero), echoed in every response to this request.
    pub tag: u16,
    /// What the host asks for.
    pub request: Request,
}

/// A device → host frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FromDevice<'a> {
    /// The tag of the request this answers, or [`UNSOLICITED`].
    pub tag: u16,
    /// The message.
    #[serde(borrow)]
    pub response: Response<'a>,
}

/// Tag of device messages that answer no request (trigger readings, the boot banner).
pub const UNSOLICITED: u16 = 0;

/// What the host asks the device.
// The calibration variant is large, but messages live briefly on the stack and `no_std` has
// no `Box`: the size difference is accepted.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Request {
    /// Device identity and health → [`Response::Info`].
    DeviceInfo,
    /// One measurement, as one trigger press → [`Response::Reading`] or [`Response::Error`].
    Measure,
    /// Measure continuously, as if the trigger were held: readings (with running
    /// statistics) are sent with this request's tag until [`Request::StopStream`].
    /// Answered first by [`Response::Ack`].
    StartStream,
    /// Ends a stream → [`Response::Ack`] (also when no stream was running).
    StopStream,
    /// Re-sends the readings kept in the device's history whose sequence number is
    /// greater than `after_seq` (as [`Response::Reading`]s), then [`Response::HistoryEnd`].
    /// This is how a host that lost the link recovers readings without duplicates.
    History {
        /// Last sequence number the host already has (0 = all).
        after_seq: u32,
    },
    /// Captures a raw frame pair (laser off, laser on) into the device's frame buffers
    /// → [`Response::FramesReady`]. Read it with [`Request::ReadFrameChunk`].
    CaptureFrames,
    /// Reads part of the last captured pair → [`Response::FrameChunk`]. The host pulls
    /// chunks at its own pace and asks again for any chunk it lost.
    ReadFrameChunk {
        /// The capture the host is reading (from [`FrameSetInfo::capture`]); a
        /// [`ErrorCode::StaleCapture`] error says a newer capture has replaced it.
        capture: u32,
        /// Which frame of the pair.
        frame: FrameSel,
        /// Byte offset into the frame (row-major, `width` bytes per row).
        offset: u32,
        /// Most bytes wanted (the device sends at most [`FRAME_CHUNK_MAX`](super::FRAME_CHUNK_MAX)).
        max_len: u16,
    },
    /// The stored calibration → [`Response::Calibration`] (or an error when none).
    ReadCalibration,
    /// Validates, stores (non-volatile where the board has storage) and activates a
    /// calibration → [`Response::Ack`].
    WriteCalibration(WireCalibration),
    /// Fixes the exposure (µs), or returns to auto-exposure with `None` → [`Response::Ack`].
    SetExposure(Option<u32>),
    /// Runs the self-test → [`Response::SelfTest`].
    SelfTest,
    /// Selects the instrument every later reading measures with (trigger, [`Request::Measure`],
    /// stream) → [`Response::Ack`]; the device remembers it ([`DeviceInfo::mode`] reports it).
    /// A mode this firmware has no solver for is refused with [`ErrorCode::MeasurementFailed`]
    /// and the detail of [`Failure::UnsupportedMode`](super::codes::Failure::UnsupportedMode),
    /// and the mode stays as it was.
    SetMode(Mode),
    /// Sets how many frame pairs one stem reading combines (a trigger press, a
    /// [`Request::Measure`], each reading of a stream): 1 to
    /// [`MAX_EXPOSURES`](crate::solvers::stem::MAX_EXPOSURES), combined by
    /// [`combine_exposures`](crate::solvers::stem::combine_exposures) (protocol version 7) →
    /// [`Response::Ack`]; any other count is refused with [`ErrorCode::InvalidSetting`] and
    /// the count stays as it was. Kept until the next reset ([`DeviceInfo::exposures`]); the
    /// other instruments measure one pair per reading.
    SetExposures(u8),
}

/// One frame of a captured pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FrameSel {
    /// Exposed with every laser off (ambient light).
    Off,
    /// Exposed with the lasers on.
    On,
}

/// What the device sends.
#[allow(clippy::large_enum_variant)] // as for `Request`
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Response<'a> {
    /// Device identity and health.
    Info(DeviceInfo<'a>),
    /// A measurement (trigger press, [`Request::Measure`], a stream or the history).
    Reading(Reading),
    /// The request failed, or a trigger press could not be measured.
    Error(DeviceError),
    /// The request was carried out.
    Ack,
    /// End of a [`Request::History`] replay.
    HistoryEnd {
        /// Highest sequence number the device has issued (0 = none yet).
        last_seq: u32,
    },
    /// A frame pair was captured.
    FramesReady(FrameSetInfo),
    /// Part of a captured frame.
    FrameChunk {
        /// Capture this chunk belongs to.
        capture: u32,
        /// Which frame of the pair.
        frame: FrameSel,
        /// Byte offset of `data` in the frame.
        offset: u32,
        /// The frame's total size in bytes.
        total: u32,
        /// The pixels (8-bit, row-major).
        #[serde(borrow)]
        data: &'a [u8],
    },
    /// The stored calibration.
    Calibration(WireCalibration),
    /// Result of [`Request::SelfTest`].
    SelfTest(SelfTestReport),
}

/// Device identity, sent for [`Request::DeviceInfo`] and unsolicited at boot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceInfo<'a> {
    /// [`PROTOCOL_VERSION`](super::PROTOCOL_VERSION) of the firmware (also in every frame's first byte).
    pub protocol_version: u8,
    /// Firmware version (semver of the firmware crate).
    pub fw_version: &'a str,
    /// Which board this is.
    pub board: Board,
    /// Id of the active calibration, `None` when the device has none.
    pub calib_id: Option<u32>,
    /// Size of the frames the camera delivers (pixels).
    pub frame_width: u16,
    /// Size of the frames the camera delivers (pixels).
    pub frame_height: u16,
    /// Milliseconds since boot.
    pub uptime_ms: u64,
    /// Highest reading sequence number issued (0 = none).
    pub last_seq: u32,
    /// Link health since boot.
    pub link: LinkStats,
    /// The instrument the device measures with ([`Request::SetMode`]).
    pub mode: Mode,
    /// Where [`DeviceInfo::mode`] came from: the device's non-volatile mode store, or the
    /// default because the store was empty, damaged or unreadable (protocol version 4).
    pub mode_store: ModeStoreState,
    /// Frame pairs one stem reading combines ([`Request::SetExposures`]; protocol
    /// version 7).
    pub exposures: u8,
}

/// What the device's mode store held at boot, or did since: why [`DeviceInfo::mode`] is
/// what it is (`docs/hardware.md`, "The instrument mode").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModeStoreState {
    /// The mode was read from the store at boot, or stored by the last [`Request::SetMode`].
    Loaded(Mode),
    /// Nothing stored yet (a new device, or a store erased when it filled up and the power
    /// failed before the new record): the default mode.
    Empty,
    /// The store holds no valid record (every record damaged): the default mode.
    Corrupt,
    /// The store could not be read (the board's error code): the default mode.
    Unreadable(u32),
    /// The last record names mode number `n`, which this firmware cannot measure (written by
    /// another firmware version): the default mode.
    Unusable(u8),
    /// This board keeps the mode in RAM only (the emulated board without `--mode-store`):
    /// a reset returns to the default mode.
    Volatile,
}

impl ModeStoreState {
    /// True when the mode was not read from the store, so a reset forgot the one last set.
    pub fn is_default(self) -> bool {
        !matches!(self, ModeStoreState::Loaded(_))
    }
}

impl core::fmt::Display for ModeStoreState {
    /// How the host reports it: "stored", or why the device measures with the default mode.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ModeStoreState::Loaded(m) => write!(f, "{} (stored)", m.name()),
            ModeStoreState::Empty => write!(f, "no mode stored yet: the default"),
            ModeStoreState::Corrupt => write!(
                f,
                "the stored mode is damaged (no valid record): the default, until a mode is set"
            ),
            ModeStoreState::Unreadable(code) => write!(
                f,
                "the mode store cannot be read (board code {code}): the default, until a mode is set"
            ),
            ModeStoreState::Unusable(n) => write!(
                f,
                "the stored mode number {n} is not one this firmware measures: the default, until a mode is set"
            ),
            ModeStoreState::Volatile => {
                write!(f, "this board does not keep the mode across a reset")
            }
        }
    }
}

/// Hardware the firmware runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Board {
    /// STM32H743 + MT9V034 (the instrument).
    H743,
    /// The emulated board (QEMU mps2-an500, frames from capture files).
    Emulated,
}

/// Counters of a [`Decoder`](super::Decoder): what arrived on the link and what was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct LinkStats {
    /// Frames decoded and accepted.
    pub frames_ok: u32,
    /// Frames rejected: COBS error, bad CRC, too short, undecodable message.
    pub malformed: u32,
    /// Frames longer than the receive buffer (discarded up to the next delimiter).
    pub oversize: u32,
    /// Well-formed frames of another protocol version.
    pub version_mismatch: u32,
}

/// A reading as sent on the wire: what was measured ([`Measurement`], its scalars as `f32`)
/// and when, with what calibration and exposure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// Sequence number, from 1, incremented for every reading the device makes (a gap
    /// means a lost reading, a repeat a duplicate).
    pub seq: u32,
    /// Device time of the laser-on exposure (ms since boot).
    pub timestamp_ms: u64,
    /// Calibration the reading was computed with.
    pub calib_id: u32,
    /// Exposure used (µs).
    pub exposure_us: u32,
    /// What the instrument measured: the same type the pipeline returns and the host prints
    /// and logs (flag and method names in [`codes`](super::codes)).
    pub measurement: Measurement,
    /// Running statistics of a held trigger or stream (`None` for a single reading).
    pub stats: Option<RunningStats>,
    /// The accelerometer's part of the capture, for an instrument that uses the vertical
    /// (the wall's plumb; protocol version 5): its mean, or why there is none. `None` in the
    /// other modes (the device does not read it).
    pub accelerometer: Option<AccelReading>,
}

/// The accelerometer's part of a reading (`docs/building.md` §6, `docs/protocol.md`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum AccelReading {
    /// The mean specific force over the capture.
    Mean {
        /// x, y, z along the sensor's axes (m/s²; at rest it points up).
        m_s2: [f32; 3],
        /// Samples averaged.
        samples: u16,
        /// 1σ of one sample on each axis at the sensor's filter setting (m/s²).
        sample_sigma_m_s2: f32,
    },
    /// No accelerometer answers (none fitted, or disconnected): the reading has no vertical.
    Absent,
    /// The accelerometer failed (`detail`: the board's code, `docs/protocol.md`).
    Failed(u32),
}

impl AccelReading {
    /// The mean as the core's reading (what [`crate::accelerometer::vertical`] takes), or
    /// `None` when there is no mean.
    pub fn mean(&self) -> Option<MeanReading> {
        match *self {
            AccelReading::Mean {
                m_s2,
                samples,
                sample_sigma_m_s2,
            } => Some(MeanReading {
                mean_m_s2: Vec3::new(m_s2[0] as Real, m_s2[1] as Real, m_s2[2] as Real),
                samples: samples as u32,
                sample_sigma_m_s2: sample_sigma_m_s2 as Real,
            }),
            AccelReading::Absent | AccelReading::Failed(_) => None,
        }
    }
}

impl core::fmt::Display for AccelReading {
    /// What the host prints of it.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            AccelReading::Mean { m_s2, samples, .. } => write!(
                f,
                "accelerometer ({:.4}, {:.4}, {:.4}) m/s², mean of {samples}",
                m_s2[0], m_s2[1], m_s2[2]
            ),
            AccelReading::Absent => write!(f, "no accelerometer answers: no vertical reference"),
            AccelReading::Failed(code) => write!(
                f,
                "the accelerometer failed ({}): no vertical reference",
                super::codes::accel_failure(*code)
            ),
        }
    }
}

/// Running statistics of the readings of one held trigger or stream.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RunningStats {
    /// Readings so far (this one included).
    pub count: u32,
    /// Mean diameter (metres).
    pub mean_m: f32,
    /// Sample standard deviation of the diameters (metres; 0 for one reading).
    pub spread_m: f32,
}

/// Which solver produced a reading: the solvers' own type, serialised as it is.
pub use crate::solvers::result::Method;

/// An error reported by the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeviceError {
    /// What went wrong.
    pub code: ErrorCode,
    /// Code-specific detail (e.g. the peer's protocol version, a driver error number).
    pub detail: u32,
}

/// Device error codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ErrorCode {
    /// A request frame of another protocol version (`detail` = its version).
    UnsupportedVersion,
    /// The device has no valid calibration: push one (`tangent device-calibration push`).
    NoCalibration,
    /// The calibration sent is invalid (`detail` = which check failed).
    InvalidCalibration,
    /// The calibration or the mode could not be written to storage (`detail` = board code).
    StorageFailure,
    /// The camera did not deliver a frame in time.
    CameraTimeout,
    /// The camera reported an error (`detail` = driver code).
    CameraFailure,
    /// The laser was on for longer than the hard limit and was forced off.
    LaserTimeout,
    /// The measurement pipeline found no valid result (`detail` = the failure, packed as
    /// [`Failure::detail`](super::codes::Failure::detail)).
    MeasurementFailed,
    /// No frame pair has been captured yet.
    NoFrames,
    /// [`Request::ReadFrameChunk`] asked for a capture that has been replaced.
    StaleCapture,
    /// [`Request::ReadFrameChunk`] asked beyond the end of the frame.
    OutOfRange,
    /// The device is busy (e.g. streaming) and cannot do this now.
    Busy,
    /// A setting's value is outside what the device accepts (`detail` = the value sent;
    /// protocol version 7).
    InvalidSetting,
}

/// Description of a captured frame pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameSetInfo {
    /// Capture number (increments with every captured pair, measurement or dump).
    pub capture: u32,
    /// Frame width (pixels).
    pub width: u16,
    /// Frame height (pixels).
    pub height: u16,
    /// First sensor row of the frame (non-zero when the device reads a window of rows).
    pub row_offset: u16,
    /// Bits per pixel of the data (8).
    pub bit_depth: u8,
    /// Exposure of both frames (µs).
    pub exposure_us: u32,
    /// Device time of the laser-on exposure (ms since boot).
    pub timestamp_ms: u64,
    /// Bitmask of the lasers lit in the on frame (bit i = plane i).
    pub laser_mask: u8,
    /// Calibration active when captured, if any.
    pub calib_id: Option<u32>,
}

/// Result of the device self-test: each bit of `failed` a failed check.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SelfTestReport {
    /// Bitmask of failed [`self_test`] checks (0 = all passed).
    pub failed: u32,
    /// Checks that were run (bitmask).
    pub ran: u32,
}

/// Self-test check bits ([`SelfTestReport`]).
pub mod self_test {
    /// The camera answered and delivered a frame.
    pub const CAMERA: u32 = 1 << 0;
    /// The stored calibration is present and valid.
    pub const CALIBRATION: u32 = 1 << 1;
    /// The laser frame is brighter than the dark frame (lasers and filter work).
    pub const LASER_CONTRAST: u32 = 1 << 2;
    /// The dark frame is not saturated (exposure/ambient light sane).
    pub const DARK_LEVEL: u32 = 1 << 3;
}

/// A calibration on the wire, in `f64` whatever the sender's [`Real`] is.
///
/// Mirrors [`Calibration`] field by field (camera intrinsics, Brown–Conrady coefficients,
/// each laser plane's unit normal, offset and source point), with the accelerometer's
/// calibration beside it (the device's whole calibration record), so that its bytes do not
/// depend on the precision either side computes in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireCalibration {
    /// [`Calibration::id`].
    pub id: u32,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// `[fx, fy, cx, cy]` (pixels).
    pub intrinsics: [f64; 4],
    /// `[k1, k2, k3, p1, p2]`.
    pub distortion: [f64; 5],
    /// The laser planes.
    pub planes: heapless::Vec<WirePlane, MAX_PLANES>,
    /// The accelerometer's calibration, when the device has one (protocol version 5): what
    /// turns its readings into gravity in the camera frame for the plumb.
    pub accelerometer: Option<WireAccelerometer>,
    /// The planes' `(e, δ)` covariance after a refinement on a reference (protocol version
    /// 6; [`Calibration::uncertainty`]), `None` for independent board-calibrated planes.
    pub uncertainty: Option<WirePlanesUncertainty>,
}

/// Entries above the diagonal of a [`PLANE_PARAMS`]-square correlation.
const UPPER_ENTRIES: usize = PLANE_PARAMS * (PLANE_PARAMS - 1) / 2;

/// The planes' covariance on the wire ([`PlanesUncertainty`]), in `f32`: an uncertainty
/// needs no more digits, and the whole record stays inside one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WirePlanesUncertainty {
    /// 1σ of `e₀, δ₀, e₁, δ₁, …` (metres, radians).
    pub sigma: heapless::Vec<f32, PLANE_PARAMS>,
    /// The correlation above its diagonal, row by row (`(0,1), (0,2), …, (1,2), …`).
    pub correlation: heapless::Vec<f32, UPPER_ENTRIES>,
}

impl From<&PlanesUncertainty> for WirePlanesUncertainty {
    fn from(u: &PlanesUncertainty) -> Self {
        let n = u.sigmas().len();
        let mut out = WirePlanesUncertainty {
            sigma: heapless::Vec::new(),
            correlation: heapless::Vec::new(),
        };
        // Both capacities are the largest `n` can need: these pushes cannot fail.
        for &s in u.sigmas() {
            let _ = out.sigma.push(s as f32);
        }
        for i in 0..n {
            for j in i + 1..n {
                let _ = out.correlation.push(u.correlation(i, j) as f32);
            }
        }
        out
    }
}

impl WirePlanesUncertainty {
    /// The core's covariance, validated ([`PlanesUncertainty::new`]).
    pub fn to_uncertainty(&self) -> Result<PlanesUncertainty, CalibrationError> {
        let n = self.sigma.len();
        let invalid = CalibrationError::Uncertainty;
        if self.correlation.len() != n * n.saturating_sub(1) / 2 {
            return Err(invalid(
                crate::calibration::UncertaintyError::CorrelationShape {
                    expected: n * n.saturating_sub(1) / 2,
                    got: self.correlation.len(),
                },
            ));
        }
        let mut sigma = [0.0 as Real; PLANE_PARAMS];
        let mut correlation = [0.0 as Real; PLANE_PARAMS * PLANE_PARAMS];
        let mut upper = self.correlation.iter();
        for i in 0..n {
            sigma[i] = self.sigma[i] as Real;
            correlation[i * n + i] = 1.0;
            for j in i + 1..n {
                let r = upper.next().copied().unwrap_or(Real::NAN as f32) as Real;
                correlation[i * n + j] = r;
                correlation[j * n + i] = r;
            }
        }
        PlanesUncertainty::new(&sigma[..n], &correlation[..n * n]).map_err(invalid)
    }
}

/// The accelerometer's calibration on the wire (`f64`): the core's
/// [`Alignment`] (bias and sensor-to-camera rotation, each with one 1σ for all axes).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WireAccelerometer {
    /// Bias (sensor axes, m/s²).
    pub bias_m_s2: [f64; 3],
    /// 1σ of the bias on each axis (m/s²).
    pub bias_sigma_m_s2: f64,
    /// Rotation from the sensor's axes into the camera frame (rotation vector, radians).
    pub camera_from_sensor_rad: [f64; 3],
    /// 1σ of that rotation about each axis (radians).
    pub alignment_sigma_rad: f64,
}

impl From<&Alignment> for WireAccelerometer {
    fn from(a: &Alignment) -> Self {
        let v = |x: &Vec3| [x.x as f64, x.y as f64, x.z as f64];
        WireAccelerometer {
            bias_m_s2: v(&a.bias_m_s2),
            bias_sigma_m_s2: a.bias_sigma_m_s2 as f64,
            camera_from_sensor_rad: v(&a.camera_from_sensor_rad),
            alignment_sigma_rad: a.alignment_sigma_rad as f64,
        }
    }
}

impl WireAccelerometer {
    /// The alignment in the local precision; `None` unless every value is finite and the
    /// σ are ≥ 0.
    pub fn to_alignment(&self) -> Option<Alignment> {
        let finite = |a: &[f64]| a.iter().all(|x| x.is_finite());
        let sigma_ok = |x: f64| x >= 0.0 && x.is_finite();
        if !finite(&self.bias_m_s2)
            || !finite(&self.camera_from_sensor_rad)
            || !sigma_ok(self.bias_sigma_m_s2)
            || !sigma_ok(self.alignment_sigma_rad)
        {
            return None;
        }
        let v = |a: [f64; 3]| Vec3::new(a[0] as Real, a[1] as Real, a[2] as Real);
        Some(Alignment {
            bias_m_s2: v(self.bias_m_s2),
            bias_sigma_m_s2: self.bias_sigma_m_s2 as Real,
            camera_from_sensor_rad: v(self.camera_from_sensor_rad),
            alignment_sigma_rad: self.alignment_sigma_rad as Real,
        })
    }
}

/// A laser plane on the wire: `normal · X = offset`, emission point `source`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WirePlane {
    /// Unit normal (camera frame).
    pub normal: [f64; 3],
    /// Distance from the camera centre to the plane (metres).
    pub offset: f64,
    /// Laser emission point (metres, camera frame).
    pub source: [f64; 3],
}

impl From<&Calibration> for WireCalibration {
    fn from(c: &Calibration) -> Self {
        let cam = &c.camera;
        let d = &cam.distortion;
        let mut planes = heapless::Vec::new();
        for p in c.planes.iter() {
            // Both vectors hold at most MAX_PLANES, so this push cannot fail.
            let _ = planes.push(WirePlane {
                normal: [p.normal.x as f64, p.normal.y as f64, p.normal.z as f64],
                offset: p.offset as f64,
                source: [p.source.x as f64, p.source.y as f64, p.source.z as f64],
            });
        }
        WireCalibration {
            id: c.id,
            width: cam.width,
            height: cam.height,
            intrinsics: [cam.fx as f64, cam.fy as f64, cam.cx as f64, cam.cy as f64],
            distortion: [
                d.k1 as f64,
                d.k2 as f64,
                d.k3 as f64,
                d.p1 as f64,
                d.p2 as f64,
            ],
            planes,
            accelerometer: None,
            uncertainty: c.uncertainty.as_ref().map(WirePlanesUncertainty::from),
        }
    }
}

impl WireCalibration {
    /// The calibration in the local precision, validated ([`Calibration::validate`]).
    pub fn to_calibration(&self) -> Result<Calibration, CalibrationError> {
        let [fx, fy, cx, cy] = self.intrinsics;
        let [k1, k2, k3, p1, p2] = self.distortion;
        let camera = Camera {
            width: self.width,
            height: self.height,
            fx: fx as Real,
            fy: fy as Real,
            cx: cx as Real,
            cy: cy as Real,
            distortion: Distortion {
                k1: k1 as Real,
                k2: k2 as Real,
                k3: k3 as Real,
                p1: p1 as Real,
                p2: p2 as Real,
            },
        };
        let v = |a: [f64; 3]| Vec3::new(a[0] as Real, a[1] as Real, a[2] as Real);
        let mut planes = heapless::Vec::new();
        for p in self.planes.iter() {
            // Same capacity on both sides: cannot fail.
            let _ = planes.push(LaserPlane {
                normal: v(p.normal),
                offset: p.offset as Real,
                source: v(p.source),
            });
        }
        let uncertainty = match &self.uncertainty {
            Some(u) => Some(u.to_uncertainty()?),
            None => None,
        };
        let calibration = Calibration {
            id: self.id,
            camera,
            planes,
            uncertainty,
        };
        calibration.validate()?;
        Ok(calibration)
    }
}
