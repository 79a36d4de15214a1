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
//! messages such as trigger readings). [`Decoder`] turns a byte stream into frames in a
//! buffer its user lends or owns, rejecting and counting malformed and oversize frames.
//!
//! The module is the device contract, in four rooms:
//!
//! * `messages`: the message types ([`Request`], [`Response`], [`Reading`] carrying the
//!   shared [`Measurement`](crate::measurement::Measurement), …) and the calibration on the
//!   wire;
//! * `framing`: one message ↔ one frame ([`encode`], [`decode`], [`FrameEncoder`]) and the
//!   stored calibration record ([`calibration_record`]);
//! * `decoder`: a byte stream → frames ([`Decoder`]);
//! * [`codes`]: what the numbers and bits mean to people and to both ends — the failure codes
//!   with the sentence a forester reads, the names of flags and methods, the USB ids and the
//!   limits both sides rely on.
//!
//! Values on the wire have a fixed precision whatever [`Real`](crate::real::Real) is: readings in `f32`
//! (what the device computes in), calibrations in `f64` ([`WireCalibration`]), so an
//! `f32` firmware and an `f64` host read each other's frames.

pub mod codes;
mod decoder;
mod framing;
mod messages;

pub use decoder::{Decoder, Feed};
pub use framing::{
    calibration_record, cobs_frame, decode, decode_raw, encode, encode_raw, FrameEncoder,
    ProtocolError,
};
pub use messages::{
    self_test, AccelReading, Board, DeviceError, DeviceInfo, ErrorCode, FrameSel, FrameSetInfo,
    FromDevice, LinkStats, Method, ModeStoreState, Reading, Request, Response, RunningStats,
    SelfTestReport, ToDevice, WireAccelerometer, WireCalibration, WirePlane, WirePlanesUncertainty,
    UNSOLICITED,
};

/// Version of this protocol, the first byte of every raw frame. Bump it on any change to
/// the message types (postcard has no field names: adding a variant in the middle or a
/// field changes the bytes). The history of versions is in `docs/protocol.md`.
pub const PROTOCOL_VERSION: u8 = 7;

/// Most pixel bytes in one [`Response::FrameChunk`].
pub const FRAME_CHUNK_MAX: usize = 512;

/// Largest raw frame (version + postcard message + CRC) either side sends or accepts.
///
/// The largest message is a [`Response::FrameChunk`]: [`FRAME_CHUNK_MAX`] bytes plus a
/// header of at most 1 (tag varint ≤ 3) + 1 (variant) + 5 (capture varint) + 1 (frame)
/// plus 5 (offset) + 5 (total) + 2 (length varint) = 22 bytes; with the version and CRC that
/// is 537 bytes. A [`WireCalibration`] is at most 5 + 8 + 9·8 + 1 + 4·7·8 + 1 + 8·8 = 375
/// bytes, and with the planes' uncertainty (1 + 1 + 8·4 + 1 + 28·4 = 147) 522 bytes.
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

#[cfg(test)]
mod tests;
