//! One message ↔ one frame: `version ‖ postcard ‖ CRC-16`, COBS-stuffed and ended by 0x00
//! (the module documentation of [`protocol`](super) gives the reasons), and the CRC'd record a
//! calibration is stored as.

use core::fmt;

use serde::{Deserialize, Serialize};

use super::{WireCalibration, CRC, DELIMITER, MAX_FRAME_LEN, MAX_RAW_LEN, PROTOCOL_VERSION};

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
    use super::{from_bytes_exact, WireCalibration};

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
        from_bytes_exact(buf.get(8..end)?).ok()
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
    /// The CRC is valid and a message decodes, but bytes follow it inside the frame: the
    /// peer sent something else than it meant (or a forgery), so the message is refused.
    TrailingBytes {
        /// Bytes left after the message.
        count: usize,
    },
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
            ProtocolError::TrailingBytes { count } => {
                write!(f, "frame has {count} byte(s) after its message")
            }
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
    from_bytes_exact(body)
}

/// Deserialises a message that fills `bytes` exactly: postcard's `from_bytes` ignores what
/// follows a message, so `take_from_bytes` and an empty rest are required instead.
fn from_bytes_exact<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, ProtocolError> {
    match postcard::take_from_bytes::<T>(bytes) {
        Ok((message, [])) => Ok(message),
        Ok((_, rest)) => Err(ProtocolError::TrailingBytes { count: rest.len() }),
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
