//! The device ↔ host wire protocol (`docs/protocol.md`).
//!
//! One protocol for the USB CDC-ACM link of the real device and the UART of the emulated
//! one. Every message is one **frame**:
//!
//! ```text
//! raw   = version (1 byte) ‖ postcard(message) ‖ CRC-16/IBM-3740(version ‖ postcard) (2 bytes, LE)
//! frame = COBS(raw) ‖ 0x00
//! ```
//!
//! * [postcard] is the compact, stable serde format both sides already use (varints,
//!   no field names), so host and firmware share these Rust types and nothing else;
//! * COBS (Consistent Overhead Byte Stuffing) removes every 0x00 from the frame, so the
//!   single 0x00 delimiter marks frame boundaries unambiguously: after garbage, a dropped
//!   byte or a receiver that starts mid-frame, the next 0x00 resynchronises the stream;
//! * the CRC-16 (poly 0x1021) catches corrupted bytes: its Hamming distance is 4 for
//!   frames up to 32,751 bits, far above [`MAX_RAW_LEN`], so every 1-, 2- and 3-bit error
//!   and every burst up to 16 bits in a frame is detected;
//! * the version byte comes first and the CRC last in *every* version of the protocol,
//!   so a peer of another version is recognised (CRC valid, version different) and
//!   reported as such instead of as line noise.
//!
//! Host → device frames carry a [`ToDevice`] (a [`Request`] with a tag), device → host
//! frames a [`FromDevice`] (a [`Response`] echoing that tag; tag 0 marks unsolicited
//! messages such as trigger readings). [`Decoder`] turns a byte stream into frames with a
//! caller-owned buffer, rejecting and counting malformed and oversize frames.
//!
//! Values on the wire have a fixed precision whatever [`Real`] is: readings in `f32`
//! (what the device computes in), calibrations in `f64` ([`WireCalibration`]), so an
//! `f32` firmware and an `f64` host read each other's frames.

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::calibration::{Calibration, CalibrationError, MAX_PLANES};
use crate::camera::{Camera, Distortion};
use crate::laser_plane::LaserPlane;
use crate::real::{Real, Vec3};

/// Version of this protocol, the first byte of every raw frame. Bump it on any change to
/// the message types (postcard has no field names: adding a variant in the middle or a
/// field changes the bytes).
pub const PROTOCOL_VERSION: u8 = 1;

/// Most pixel bytes in one [`Response::FrameChunk`].
pub const FRAME_CHUNK_MAX: usize = 512;

/// Largest raw frame (version + postcard message + CRC) either side sends or accepts.
///
/// The largest message is a [`Response::FrameChunk`]: [`FRAME_CHUNK_MAX`] bytes plus a
/// header of at most 1 (tag varint ≤ 3) + 1 (variant) + 5 (capture varint) + 1 (frame)
/// plus 5 (offset) + 5 (total) + 2 (length varint) = 22 bytes; with the version and CRC that
/// is 537 bytes. A [`WireCalibration`] is at most 5 + 8 + 9·8 + 1 + 4·7·8 = 310 bytes.
/// 640 leaves room for growth within this version.
pub const MAX_RAW_LEN: usize = 640;

/// Largest encoded frame on the wire, delimiter included: COBS adds one byte per 254
/// (rounded up), plus the 0x00.
pub const MAX_FRAME_LEN: usize = MAX_RAW_LEN + MAX_RAW_LEN.div_ceil(254) + 1;

/// The CRC of a raw frame: CRC-16/IBM-3740 (a.k.a. CCITT-FALSE: poly 0x1021, init 0xFFFF,
/// no reflection, no final XOR), stored little-endian after the message.
pub const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// Frame delimiter.
pub const DELIMITER: u8 = 0x00;

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
        /// Most bytes wanted (the device sends at most [`FRAME_CHUNK_MAX`]).
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
    /// [`PROTOCOL_VERSION`] of the firmware (also in every frame's first byte).
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
}

/// Hardware the firmware runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Board {
    /// STM32H743 + MT9V034 (the instrument).
    H743,
    /// The emulated board (QEMU mps2-an500, frames from capture files).
    Emulated,
}

/// Counters of a [`Decoder`]: what arrived on the link and what was rejected.
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

/// A measurement as sent on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// Sequence number, from 1, incremented for every reading the device makes (a gap
    /// means a lost reading, a repeat a duplicate).
    pub seq: u32,
    /// Device time of the laser-on exposure (ms since boot).
    pub timestamp_ms: u64,
    /// Calibration the reading was computed with.
    pub calib_id: u32,
    /// The solver that produced the diameter.
    pub method: Method,
    /// Diameter (metres).
    pub diameter_m: f32,
    /// Predicted standard uncertainty of the diameter (metres).
    pub uncertainty_m: f32,
    /// Distance from the camera to the stem axis along the optical axis (metres).
    pub distance_m: f32,
    /// Stem tilt: total angle between the stem axis and the laser-plane normal (radians;
    /// 0 when not measured, i.e. with one plane).
    pub tilt_rad: f32,
    /// Quality flags: the bits of `solvers::cylinder::Flags` (solver and image flags,
    /// e.g. `ARC_TOO_SHORT`, `TILT_IGNORED`, `STRIPE_SATURATED`), sent verbatim.
    pub flags: u16,
    /// Exposure used (µs).
    pub exposure_us: u32,
    /// Running statistics of a held trigger or stream (`None` for a single reading).
    pub stats: Option<RunningStats>,
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
    /// The device has no valid calibration: push one (`tangent calib push`).
    NoCalibration,
    /// The calibration sent is invalid (`detail` = which check failed).
    InvalidCalibration,
    /// The calibration could not be written to storage.
    StorageFailure,
    /// The camera did not deliver a frame in time.
    CameraTimeout,
    /// The camera reported an error (`detail` = driver code).
    CameraFailure,
    /// The laser was on for longer than the hard limit and was forced off.
    LaserTimeout,
    /// The measurement pipeline found no valid result (`detail` = pipeline error code).
    MeasurementFailed,
    /// No frame pair has been captured yet.
    NoFrames,
    /// [`Request::ReadFrameChunk`] asked for a capture that has been replaced.
    StaleCapture,
    /// [`Request::ReadFrameChunk`] asked beyond the end of the frame.
    OutOfRange,
    /// The device is busy (e.g. streaming) and cannot do this now.
    Busy,
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
/// each laser plane's unit normal, offset and source point) so that its bytes do not
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
        let calibration = Calibration {
            id: self.id,
            camera,
            planes,
        };
        calibration.validate()?;
        Ok(calibration)
    }
}

/// The stored calibration record: what the device keeps in non-volatile memory (a flash
/// sector on the H743) and what the emulated board loads at boot (`--calib FILE`).
///
/// ```text
/// magic "TGCL" (4) ‖ n (u32 LE) ‖ postcard(WireCalibration) (n bytes) ‖ CRC-32/ISO-HDLC (4, LE)
/// ```
///
/// The CRC covers magic, length and payload. Erased flash (all 0xFF), a half-written
/// record (power lost while programming) or a record of another layout fails the magic,
/// length or CRC check and reads as "no calibration" rather than a wrong one.
pub mod calibration_record {
    use super::WireCalibration;

    /// Record magic.
    pub const MAGIC: [u8; 4] = *b"TGCL";
    /// Largest record (header + payload + CRC).
    pub const MAX_RECORD: usize = 1024;
    /// CRC of the record: CRC-32/ISO-HDLC (the zlib/PNG CRC).
    pub const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

    /// Writes the record of `cal` into `buf`; returns its length, `None` if `buf` is
    /// too small.
    pub fn encode(cal: &WireCalibration, buf: &mut [u8]) -> Option<usize> {
        let payload_len = {
            let body = buf.get_mut(8..MAX_RECORD.saturating_sub(4).min(buf.len()))?;
            postcard::to_slice(cal, body).ok()?.len()
        };
        buf.get_mut(..4)?.copy_from_slice(&MAGIC);
        buf.get_mut(4..8)?
            .copy_from_slice(&(payload_len as u32).to_le_bytes());
        let end = 8 + payload_len;
        let crc = CRC32.checksum(buf.get(..end)?);
        buf.get_mut(end..end + 4)?
            .copy_from_slice(&crc.to_le_bytes());
        Some(end + 4)
    }

    /// Reads a record from the start of `buf` (trailing bytes ignored); `None` unless
    /// it is complete and intact.
    pub fn decode(buf: &[u8]) -> Option<WireCalibration> {
        if buf.get(..4)? != MAGIC {
            return None;
        }
        let len = u32::from_le_bytes(buf.get(4..8)?.try_into().ok()?) as usize;
        if len > MAX_RECORD - 12 {
            return None;
        }
        let end = 8 + len;
        let stored = u32::from_le_bytes(buf.get(end..end + 4)?.try_into().ok()?);
        if CRC32.checksum(buf.get(..end)?) != stored {
            return None;
        }
        postcard::from_bytes(buf.get(8..end)?).ok()
    }
}

/// Why a frame could not be encoded or decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProtocolError {
    /// The message does not fit in [`MAX_RAW_LEN`] (or the caller's buffer).
    BufferTooSmall,
    /// postcard could not serialise the message.
    Serialize,
    /// The frame is not valid COBS.
    Cobs,
    /// The frame is shorter than version + CRC.
    TooShort,
    /// The CRC does not match: the frame was corrupted.
    Crc {
        /// CRC carried by the frame.
        received: u16,
        /// CRC computed over the frame.
        computed: u16,
    },
    /// A well-formed frame of another protocol version.
    VersionMismatch {
        /// The peer's version.
        received: u8,
    },
    /// The CRC is valid but the message does not decode as the expected type.
    Deserialize,
    /// The frame is longer than the receive buffer.
    Oversize,
}

impl fmt::Display for ProtocolError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ProtocolError::BufferTooSmall => write!(f, "message too large for the frame buffer"),
            ProtocolError::Serialize => write!(f, "message could not be serialised"),
            ProtocolError::Cobs => write!(f, "frame is not valid COBS"),
            ProtocolError::TooShort => write!(f, "frame too short"),
            ProtocolError::Crc { received, computed } => write!(
                f,
                "frame corrupted: CRC {received:#06x} received, {computed:#06x} computed"
            ),
            ProtocolError::VersionMismatch { received } => write!(
                f,
                "peer speaks protocol version {received}, this side speaks version {PROTOCOL_VERSION}"
            ),
            ProtocolError::Deserialize => write!(f, "frame does not decode as the expected message"),
            ProtocolError::Oversize => write!(f, "frame longer than the receive buffer"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ProtocolError {}

/// Encodes `message` as one frame (delimiter included) into `out`, using `scratch` for the
/// raw bytes. Returns the frame length.
///
/// `scratch` needs the raw length (at most [`MAX_RAW_LEN`]); `out` needs
/// [`MAX_FRAME_LEN`] for any message.
pub fn encode<T: Serialize>(
    message: &T,
    scratch: &mut [u8],
    out: &mut [u8],
) -> Result<usize, ProtocolError> {
    let raw = encode_raw(message, PROTOCOL_VERSION, scratch)?;
    cobs_frame(raw, out)
}

/// Writes `version ‖ postcard(message) ‖ CRC` into `scratch`; returns the raw bytes.
/// (Separate from [`encode`] so tests can forge frames of another version.)
pub fn encode_raw<'s, T: Serialize>(
    message: &T,
    version: u8,
    scratch: &'s mut [u8],
) -> Result<&'s [u8], ProtocolError> {
    let limit = scratch.len().min(MAX_RAW_LEN);
    let scratch = scratch
        .get_mut(..limit)
        .ok_or(ProtocolError::BufferTooSmall)?;
    let (head, rest) = scratch
        .split_first_mut()
        .ok_or(ProtocolError::BufferTooSmall)?;
    *head = version;
    let body_len = match postcard::to_slice(message, rest) {
        Ok(body) => body.len(),
        Err(postcard::Error::SerializeBufferFull) => return Err(ProtocolError::BufferTooSmall),
        Err(_) => return Err(ProtocolError::Serialize),
    };
    let crc_at = 1 + body_len;
    let crc = CRC.checksum(scratch.get(..crc_at).ok_or(ProtocolError::BufferTooSmall)?);
    scratch
        .get_mut(crc_at..crc_at + 2)
        .ok_or(ProtocolError::BufferTooSmall)?
        .copy_from_slice(&crc.to_le_bytes());
    scratch
        .get(..crc_at + 2)
        .ok_or(ProtocolError::BufferTooSmall)
}

/// COBS-encodes `raw` into `out` and appends the delimiter; returns the frame length.
pub fn cobs_frame(raw: &[u8], out: &mut [u8]) -> Result<usize, ProtocolError> {
    let n = cobs::try_encode(raw, out).map_err(|_| ProtocolError::BufferTooSmall)?;
    *out.get_mut(n).ok_or(ProtocolError::BufferTooSmall)? = DELIMITER;
    Ok(n + 1)
}

/// Decodes one frame — its COBS bytes, with or without the trailing delimiter — in place,
/// checks CRC and version, and deserialises the message (borrowing from `frame`).
pub fn decode<'a, T: Deserialize<'a>>(frame: &'a mut [u8]) -> Result<T, ProtocolError> {
    let end = frame
        .iter()
        .position(|&b| b == DELIMITER)
        .unwrap_or(frame.len());
    let frame = frame.get_mut(..end).ok_or(ProtocolError::Cobs)?;
    if frame.is_empty() {
        return Err(ProtocolError::TooShort);
    }
    let n = cobs::decode_in_place(frame).map_err(|_| ProtocolError::Cobs)?;
    let raw: &'a [u8] = frame.get(..n).ok_or(ProtocolError::Cobs)?;
    decode_raw(raw)
}

/// Checks CRC and version of raw (COBS-decoded) bytes and deserialises the message.
pub fn decode_raw<'a, T: Deserialize<'a>>(raw: &'a [u8]) -> Result<T, ProtocolError> {
    if raw.len() < 3 {
        return Err(ProtocolError::TooShort);
    }
    let (checked, crc_bytes) = raw.split_at(raw.len() - 2);
    let received = u16::from_le_bytes([crc_bytes[0], crc_bytes[1]]);
    let computed = CRC.checksum(checked);
    if received != computed {
        return Err(ProtocolError::Crc { received, computed });
    }
    let (&version, body) = checked.split_first().ok_or(ProtocolError::TooShort)?;
    if version != PROTOCOL_VERSION {
        return Err(ProtocolError::VersionMismatch { received: version });
    }
    match postcard::from_bytes::<T>(body) {
        Ok(message) => Ok(message),
        Err(_) => Err(ProtocolError::Deserialize),
    }
}

/// Encoder with its own buffers: `FrameEncoder::new().encode(&msg)` gives the bytes to send.
pub struct FrameEncoder {
    scratch: [u8; MAX_RAW_LEN],
    out: [u8; MAX_FRAME_LEN],
}

impl Default for FrameEncoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameEncoder {
    /// An encoder (1.3 KB of buffers).
    pub const fn new() -> Self {
        FrameEncoder {
            scratch: [0; MAX_RAW_LEN],
            out: [0; MAX_FRAME_LEN],
        }
    }

    /// Encodes `message` as one frame, delimiter included.
    pub fn encode<T: Serialize>(&mut self, message: &T) -> Result<&[u8], ProtocolError> {
        let n = encode(message, &mut self.scratch, &mut self.out)?;
        self.out.get(..n).ok_or(ProtocolError::BufferTooSmall)
    }
}

/// What [`Decoder::feed`] found in the bytes it was given.
#[derive(Debug)]
pub enum Feed<'i, T> {
    /// Every input byte was consumed; no frame ended.
    Consumed,
    /// A frame ended and decoded to `message`; `remaining` is the unconsumed input.
    Frame {
        /// The message.
        message: T,
        /// Input after the frame's delimiter.
        remaining: &'i [u8],
    },
    /// A frame ended but was rejected (and counted); `remaining` is the unconsumed input.
    Rejected {
        /// Why.
        error: ProtocolError,
        /// Input after the frame's delimiter.
        remaining: &'i [u8],
    },
}

/// Stream decoder: accumulates bytes in a caller-owned buffer up to each 0x00 delimiter,
/// then decodes the frame in place.
///
/// Frames longer than the buffer are dropped up to the next delimiter and counted as
/// oversize; undecodable ones are counted as malformed (or version mismatches); empty
/// frames (consecutive delimiters, which a sender may emit to flush a receiver's partial
/// frame) are skipped silently. Nothing the peer sends can make it panic or grow.
pub struct Decoder<'b> {
    buf: &'b mut [u8],
    len: usize,
    discarding: bool,
    stats: LinkStats,
}

impl<'b> Decoder<'b> {
    /// A decoder over `buf` (give it at least [`MAX_FRAME_LEN`] bytes to accept every
    /// frame of this protocol).
    pub fn new(buf: &'b mut [u8]) -> Self {
        Decoder {
            buf,
            len: 0,
            discarding: false,
            stats: LinkStats::default(),
        }
    }

    /// Counters since creation.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// Drops any partial frame (e.g. after the link was cut).
    pub fn reset(&mut self) {
        self.len = 0;
        self.discarding = false;
    }

    /// Feeds `input`; stops after the first frame that ends in it. Call again with
    /// `remaining` until [`Feed::Consumed`].
    pub fn feed<'d, 'i, T: Deserialize<'d>>(&'d mut self, input: &'i [u8]) -> Feed<'i, T> {
        let mut rest = input;
        while let Some((&byte, tail)) = rest.split_first() {
            rest = tail;
            if byte == DELIMITER {
                let len = self.len;
                let discarding = self.discarding;
                self.len = 0;
                self.discarding = false;
                if discarding {
                    self.stats.oversize = self.stats.oversize.saturating_add(1);
                    return Feed::Rejected {
                        error: ProtocolError::Oversize,
                        remaining: rest,
                    };
                }
                if len == 0 {
                    continue;
                }
                let Some(frame) = self.buf.get_mut(..len) else {
                    // len never exceeds the buffer; treat the impossible as malformed.
                    self.stats.malformed = self.stats.malformed.saturating_add(1);
                    return Feed::Rejected {
                        error: ProtocolError::Oversize,
                        remaining: rest,
                    };
                };
                let stats = &mut self.stats;
                return match decode::<T>(frame) {
                    Ok(message) => {
                        stats.frames_ok = stats.frames_ok.saturating_add(1);
                        Feed::Frame {
                            message,
                            remaining: rest,
                        }
                    }
                    Err(error) => {
                        if let ProtocolError::VersionMismatch { .. } = error {
                            stats.version_mismatch = stats.version_mismatch.saturating_add(1);
                        } else {
                            stats.malformed = stats.malformed.saturating_add(1);
                        }
                        Feed::Rejected {
                            error,
                            remaining: rest,
                        }
                    }
                };
            }
            if self.discarding {
                continue;
            }
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => {
                    self.discarding = true;
                    self.len = 0;
                }
            }
        }
        Feed::Consumed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(seq: u32) -> Reading {
        Reading {
            seq,
            timestamp_ms: 123_456_789_012,
            calib_id: 7,
            method: Method::CylinderFit,
            diameter_m: 0.3141,
            uncertainty_m: 0.0012,
            distance_m: 1.75,
            tilt_rad: -0.05,
            flags: 0x1803,
            exposure_us: 850,
            stats: Some(RunningStats {
                count: 4,
                mean_m: 0.314,
                spread_m: 0.0004,
            }),
        }
    }

    fn frame_of<T: Serialize>(msg: &T) -> ([u8; MAX_FRAME_LEN], usize) {
        let mut scratch = [0u8; MAX_RAW_LEN];
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = encode(msg, &mut scratch, &mut out).unwrap();
        (out, n)
    }

    #[test]
    fn frame_has_one_delimiter_at_the_end() {
        let msg = FromDevice {
            tag: 0,
            response: Response::Reading(reading(1)),
        };
        let (out, n) = frame_of(&msg);
        assert_eq!(out[n - 1], 0);
        assert!(out[..n - 1].iter().all(|&b| b != 0));
    }

    #[test]
    fn every_request_round_trips() {
        let cal = WireCalibration::from(&Calibration::reference_design());
        let requests = [
            Request::DeviceInfo,
            Request::Measure,
            Request::StartStream,
            Request::StopStream,
            Request::History { after_seq: 41 },
            Request::CaptureFrames,
            Request::ReadFrameChunk {
                capture: 3,
                frame: FrameSel::On,
                offset: 360_448,
                max_len: 512,
            },
            Request::ReadCalibration,
            Request::WriteCalibration(cal),
            Request::SetExposure(Some(1200)),
            Request::SetExposure(None),
            Request::SelfTest,
        ];
        for (i, request) in requests.into_iter().enumerate() {
            let msg = ToDevice {
                tag: 1000 + i as u16,
                request,
            };
            let (mut out, n) = frame_of(&msg);
            let back: ToDevice = decode(&mut out[..n]).unwrap();
            assert_eq!(back, msg);
        }
    }

    #[test]
    fn largest_messages_fit() {
        // A full chunk of 0xFF bytes (no zeros, worst case for COBS) with maximal varints.
        let data = [0xFFu8; FRAME_CHUNK_MAX];
        let msg = FromDevice {
            tag: u16::MAX,
            response: Response::FrameChunk {
                capture: u32::MAX,
                frame: FrameSel::On,
                offset: u32::MAX,
                total: u32::MAX,
                data: &data,
            },
        };
        let (mut out, n) = frame_of(&msg);
        assert!(n <= MAX_FRAME_LEN);
        let back: FromDevice = decode(&mut out[..n]).unwrap();
        assert_eq!(back, msg);

        // A calibration with MAX_PLANES planes and values whose f64 bytes are all non-zero.
        let mut cal = WireCalibration::from(&Calibration::reference_design());
        while cal.planes.len() < MAX_PLANES {
            cal.planes.push(cal.planes[0]).unwrap();
        }
        cal.id = u32::MAX;
        let msg = FromDevice {
            tag: u16::MAX,
            response: Response::Calibration(cal),
        };
        let (mut out, n) = frame_of(&msg);
        let back: FromDevice = decode(&mut out[..n]).unwrap();
        assert_eq!(back, msg);
    }

    #[test]
    fn calibration_survives_the_wire_exactly_in_f64() {
        let cal = Calibration::reference_design();
        let wire = WireCalibration::from(&cal);
        let back = wire.to_calibration().unwrap();
        // f64 → f64 is exact; with the f32 feature Real → f64 → Real is exact as well
        // (every f32 is an f64), so equality holds in both precisions.
        assert_eq!(back, cal);
    }

    #[test]
    fn invalid_calibration_is_rejected() {
        let mut wire = WireCalibration::from(&Calibration::reference_design());
        wire.intrinsics[0] = -1.0;
        assert!(matches!(
            wire.to_calibration(),
            Err(CalibrationError::Camera(_))
        ));
        let mut wire = WireCalibration::from(&Calibration::reference_design());
        wire.planes.clear();
        assert_eq!(wire.to_calibration(), Err(CalibrationError::NoPlanes));
    }

    #[test]
    fn every_single_bit_flip_is_detected() {
        let msg = FromDevice {
            tag: 9,
            response: Response::Reading(reading(77)),
        };
        let mut scratch = [0u8; MAX_RAW_LEN];
        let raw_len = encode_raw(&msg, PROTOCOL_VERSION, &mut scratch)
            .unwrap()
            .len();
        for bit in 0..raw_len * 8 {
            let mut raw = scratch;
            raw[bit / 8] ^= 1 << (bit % 8);
            let r: Result<FromDevice, _> = decode_raw(&raw[..raw_len]);
            assert!(
                matches!(r, Err(ProtocolError::Crc { .. })),
                "bit {bit}: {r:?}"
            );
        }
    }

    #[test]
    fn another_version_is_named_not_called_noise() {
        let mut scratch = [0u8; MAX_RAW_LEN];
        let raw = encode_raw(
            &ToDevice {
                tag: 1,
                request: Request::Measure,
            },
            2,
            &mut scratch,
        )
        .unwrap();
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = cobs_frame(raw, &mut out).unwrap();
        let r: Result<ToDevice, _> = decode(&mut out[..n]);
        assert_eq!(r, Err(ProtocolError::VersionMismatch { received: 2 }));
    }

    /// Decodes every frame of `stream` with a decoder over a `cap`-byte buffer.
    fn decode_stream(stream: &[u8], cap: usize) -> (heapless::Vec<u32, 64>, LinkStats) {
        let mut buf = [0u8; 2048];
        let mut dec = Decoder::new(&mut buf[..cap]);
        let mut seqs = heapless::Vec::new();
        let mut input = stream;
        loop {
            match dec.feed::<FromDevice>(input) {
                Feed::Consumed => break,
                Feed::Frame { message, remaining } => {
                    if let Response::Reading(r) = message.response {
                        seqs.push(r.seq).unwrap();
                    }
                    input = remaining;
                }
                Feed::Rejected { remaining, .. } => input = remaining,
            }
        }
        (seqs, dec.stats())
    }

    fn stream_of(seqs: core::ops::Range<u32>, out: &mut [u8]) -> usize {
        let mut n = 0;
        for seq in seqs {
            let msg = FromDevice {
                tag: 0,
                response: Response::Reading(reading(seq)),
            };
            let (f, len) = frame_of(&msg);
            out[n..n + len].copy_from_slice(&f[..len]);
            n += len;
        }
        n
    }

    #[test]
    fn decoder_splits_a_stream_fed_in_any_pieces() {
        let mut stream = [0u8; 4096];
        let n = stream_of(1..11, &mut stream);
        for piece in [1, 2, 7, 64, n] {
            let mut buf = [0u8; MAX_FRAME_LEN];
            let mut dec = Decoder::new(&mut buf);
            let mut got = heapless::Vec::<u32, 16>::new();
            for chunk in stream[..n].chunks(piece) {
                let mut input = chunk;
                loop {
                    match dec.feed::<FromDevice>(input) {
                        Feed::Consumed => break,
                        Feed::Frame { message, remaining } => {
                            if let Response::Reading(r) = message.response {
                                got.push(r.seq).unwrap();
                            }
                            input = remaining;
                        }
                        Feed::Rejected { error, .. } => panic!("{error}"),
                    }
                }
            }
            assert_eq!(
                &got[..],
                &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10][..],
                "piece {piece}"
            );
            assert_eq!(dec.stats().frames_ok, 10);
        }
    }

    #[test]
    fn decoder_resynchronises_after_garbage_and_corruption() {
        let mut stream = [0u8; 4096];
        let mut n = 0;
        // Garbage before the first frame (a receiver that starts mid-stream).
        for b in [0x13u8, 0x37, 0xFF, 0x01] {
            stream[n] = b;
            n += 1;
        }
        n += stream_of(1..4, &mut stream[n..]);
        // Corrupt one byte inside frame 2 (but not a delimiter).
        let second_start = stream[..n].iter().position(|&b| b == 0).unwrap() + 1;
        stream[second_start + 5] ^= 0x40;
        if stream[second_start + 5] == 0 {
            stream[second_start + 5] = 0x55;
        }
        // A truncated frame (cable yanked mid-frame) followed by complete ones.
        let mut tail = [0u8; 1024];
        let t = stream_of(4..6, &mut tail);
        stream[n..n + 10].copy_from_slice(&tail[..10]);
        n += 10;
        // A sender that (re)starts emits a delimiter first, which ends the partial frame.
        stream[n] = DELIMITER;
        n += 1;
        stream[n..n + t].copy_from_slice(&tail[..t]);
        n += t;
        let (seqs, stats) = decode_stream(&stream[..n], MAX_FRAME_LEN);
        // Frame 1 is swallowed with the garbage prefix; frame 2 is corrupted; the
        // truncated frame is malformed; 3, 4, 5 survive.
        assert_eq!(&seqs[..], &[3, 4, 5][..]);
        assert_eq!(stats.frames_ok, 3);
        assert_eq!(stats.malformed, 3);
    }

    #[test]
    fn decoder_rejects_oversize_frames_and_recovers() {
        let mut stream = [0u8; 4096];
        // 1000 non-zero bytes: longer than the 200-byte buffer used below.
        stream[..1000].fill(0xAB);
        stream[1000] = 0;
        let n = 1001 + stream_of(1..3, &mut stream[1001..]);
        let (seqs, stats) = decode_stream(&stream[..n], 200);
        assert_eq!(&seqs[..], &[1, 2][..]);
        assert_eq!(stats.oversize, 1);
        assert_eq!(stats.malformed, 0);
    }

    #[test]
    fn empty_frames_are_ignored() {
        let mut stream = [0u8; 1024];
        let n = 3 + stream_of(1..2, &mut stream[3..]);
        let (seqs, stats) = decode_stream(&stream[..n], MAX_FRAME_LEN);
        assert_eq!(&seqs[..], &[1][..]);
        assert_eq!(stats.malformed, 0);
    }

    #[test]
    fn calibration_record_round_trip_and_corruption() {
        let cal = WireCalibration::from(&Calibration::reference_design());
        let mut buf = [0xFFu8; calibration_record::MAX_RECORD];
        let n = calibration_record::encode(&cal, &mut buf).unwrap();
        assert_eq!(calibration_record::decode(&buf[..n]), Some(cal.clone()));
        // Erased flash.
        assert_eq!(calibration_record::decode(&[0xFF; 64]), None);
        // Every single-byte corruption and every truncation is rejected.
        for i in 0..n {
            let mut b = buf;
            b[i] ^= 0x20;
            assert_eq!(calibration_record::decode(&b[..n]), None, "byte {i}");
            assert_eq!(calibration_record::decode(&buf[..i]), None, "cut at {i}");
        }
    }

    #[test]
    fn crc_matches_the_published_check_value() {
        // CRC-16/IBM-3740 of "123456789" is 0x29B1 (Greg Cook's CRC catalogue).
        assert_eq!(CRC.checksum(b"123456789"), 0x29B1);
    }

    #[test]
    fn random_bytes_never_panic_the_decoder() {
        // xorshift32: a deterministic byte soup with zeros sprinkled in.
        let mut x = 0x1234_5678u32;
        let mut buf = [0u8; 64];
        let mut dec = Decoder::new(&mut buf);
        let mut frames = 0u32;
        for _ in 0..20_000 {
            let mut chunk = [0u8; 16];
            for b in chunk.iter_mut() {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *b = if x.is_multiple_of(23) { 0 } else { x as u8 };
            }
            let mut input = &chunk[..];
            loop {
                match dec.feed::<ToDevice>(input) {
                    Feed::Consumed => break,
                    Feed::Frame { remaining, .. } => {
                        frames += 1;
                        input = remaining
                    }
                    Feed::Rejected { remaining, .. } => input = remaining,
                }
            }
        }
        let s = dec.stats();
        // A random frame passes the CRC with probability 2^-16 and must then also be a
        // valid message of version 1; over ~14k random frames essentially none should.
        assert!(frames <= 2, "{frames} random frames accepted");
        assert!(s.malformed + s.oversize > 1000);
    }
}
