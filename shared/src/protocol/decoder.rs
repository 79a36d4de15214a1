//! A byte stream → frames: the receive side of a link, on either end.

use serde::Deserialize;

use super::{decode, LinkStats, ProtocolError, DELIMITER};

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

/// Stream decoder: accumulates bytes in its buffer up to each 0x00 delimiter, then decodes
/// the frame in place.
///
/// The buffer is any `B: AsMut<[u8]>` (the style of smoltcp's `Packet<T: AsRef<[u8]>>`): the
/// firmware lends a `&'static mut [u8]` from its RAM map, the host owns a `Vec<u8>` or an
/// array, so a long-lived host struct can hold its decoder without a self-referential type.
///
/// Frames longer than the buffer are dropped up to the next delimiter and counted as
/// oversize; undecodable ones are counted as malformed (or version mismatches); empty
/// frames (consecutive delimiters, which a sender may emit to flush a receiver's partial
/// frame) are skipped silently. Nothing the peer sends can make it panic or grow.
pub struct Decoder<B: AsMut<[u8]>> {
    buf: B,
    len: usize,
    discarding: bool,
    stats: LinkStats,
}

impl<B: AsMut<[u8]>> Decoder<B> {
    /// A decoder over `buf` (give it at least [`MAX_FRAME_LEN`](super::MAX_FRAME_LEN) bytes to accept every
    /// frame of this protocol).
    pub const fn new(buf: B) -> Self {
        Decoder {
            buf,
            len: 0,
            discarding: false,
            stats: LinkStats {
                frames_ok: 0,
                malformed: 0,
                oversize: 0,
                version_mismatch: 0,
            },
        }
    }

    /// The buffer back.
    pub fn into_inner(self) -> B {
        self.buf
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
                let Some(frame) = self.buf.as_mut().get_mut(..len) else {
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
            match self.buf.as_mut().get_mut(self.len) {
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
