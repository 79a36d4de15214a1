//! What the device says, owned: the host keeps replies beyond the receive buffer that
//! [`Response`] borrows from.

use tangent_core::measurement::Mode;
use tangent_core::protocol::{
    Board, DeviceError, FrameSel, FrameSetInfo, LinkStats, ModeStoreState, Reading, Response,
    SelfTestReport, WireCalibration,
};

/// Device identity and health ([`tangent_core::protocol::DeviceInfo`], owned).
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceIdentity {
    /// Protocol version of the firmware.
    pub protocol_version: u8,
    /// Firmware version.
    pub fw_version: String,
    /// Board.
    pub board: Board,
    /// Active calibration id.
    pub calib_id: Option<u32>,
    /// Frame width (pixels).
    pub frame_width: u16,
    /// Frame height (pixels).
    pub frame_height: u16,
    /// Device uptime (ms).
    pub uptime_ms: u64,
    /// Highest sequence number issued.
    pub last_seq: u32,
    /// The device's receive counters.
    pub link: LinkStats,
    /// The instrument the device measures with.
    pub mode: Mode,
    /// Whether `mode` was read from the device's mode store, or why it is the default.
    pub mode_store: ModeStoreState,
    /// Frame pairs one stem reading combines.
    pub exposures: u8,
}

/// A device message, owned ([`Response`] borrows from the receive buffer).
// Replies live briefly on the stack; boxing the calibration would only add an allocation.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// [`Response::Info`].
    Info(DeviceIdentity),
    /// [`Response::Reading`].
    Reading(Reading),
    /// [`Response::Error`].
    Error(DeviceError),
    /// [`Response::Ack`].
    Ack,
    /// [`Response::HistoryEnd`].
    HistoryEnd {
        /// Highest sequence number issued.
        last_seq: u32,
    },
    /// [`Response::FramesReady`].
    FramesReady(FrameSetInfo),
    /// [`Response::FrameChunk`].
    FrameChunk {
        /// Capture number.
        capture: u32,
        /// Which frame.
        frame: FrameSel,
        /// Offset of `data`.
        offset: u32,
        /// Frame size.
        total: u32,
        /// Pixels.
        data: Vec<u8>,
    },
    /// [`Response::Calibration`].
    Calibration(WireCalibration),
    /// [`Response::SelfTest`].
    SelfTest(SelfTestReport),
}

impl From<Response<'_>> for Reply {
    fn from(r: Response<'_>) -> Self {
        match r {
            Response::Info(i) => Reply::Info(DeviceIdentity {
                protocol_version: i.protocol_version,
                fw_version: i.fw_version.to_string(),
                board: i.board,
                calib_id: i.calib_id,
                frame_width: i.frame_width,
                frame_height: i.frame_height,
                uptime_ms: i.uptime_ms,
                last_seq: i.last_seq,
                link: i.link,
                mode: i.mode,
                mode_store: i.mode_store,
                exposures: i.exposures,
            }),
            Response::Reading(r) => Reply::Reading(r),
            Response::Error(e) => Reply::Error(e),
            Response::Ack => Reply::Ack,
            Response::HistoryEnd { last_seq } => Reply::HistoryEnd { last_seq },
            Response::FramesReady(f) => Reply::FramesReady(f),
            Response::FrameChunk {
                capture,
                frame,
                offset,
                total,
                data,
            } => Reply::FrameChunk {
                capture,
                frame,
                offset,
                total,
                data: data.to_vec(),
            },
            Response::Calibration(c) => Reply::Calibration(c),
            Response::SelfTest(s) => Reply::SelfTest(s),
        }
    }
}
