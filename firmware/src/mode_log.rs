//! The instrument mode remembered across resets and power cycles: an append-only log of
//! 32-byte records in a flash sector of its own (`docs/hardware.md`, "The instrument mode").
//!
//! Flash is erased a sector at a time and programmed once per 256-bit flash word between
//! erases, so the mode is not rewritten in place: each change programs the **next free word**
//! with a [`record`]; at boot the **last valid record** in address order is the mode; the
//! sector is erased only when every word is used (4 096 changes per erase on the H743's
//! 128 KiB sector, so ≈ 10 000 erase cycles last 40 million changes). A word that a power cut
//! tore while it was programmed fails its magic or CRC and is skipped: the mode is then the
//! one before, which is right, because its `SetMode` was never acknowledged.
//!
//! The log works on any [`FlashWords`] (the H743's sector, the emulated board's file, the unit
//! tests' RAM with injected faults), so every board runs this one implementation of
//! [`ModeStore`].

use tangent_core::measurement::Mode;
use tangent_core::protocol::calibration_record::CRC32;
use tangent_core::protocol::ModeStoreState;

use crate::ports::ModeStore;

/// Bytes of one flash word (the STM32H7's programming unit, 256 bits).
pub const WORD: usize = 32;
/// Erased flash reads as this byte.
pub const ERASED: u8 = 0xFF;

/// A sector of flash words: read any word, program an erased one once, erase all. Errors
/// are board codes (sent as the `detail` of `StorageFailure`).
pub trait FlashWords {
    /// Words in the sector.
    fn words(&self) -> usize;
    /// Reads word `index`. A word whose contents the hardware cannot return (an ECC error
    /// after a torn write) is an error, not a fault.
    fn read(&mut self, index: usize, word: &mut [u8; WORD]) -> Result<(), u32>;
    /// Programs word `index`, which must be erased.
    fn program(&mut self, index: usize, word: &[u8; WORD]) -> Result<(), u32>;
    /// Erases every word of the sector.
    fn erase(&mut self) -> Result<(), u32>;
}

/// The 32-byte record of one mode change.
///
/// ```text
/// "TGMD" (4) ‖ format 1 (1) ‖ mode number (1) ‖ 0xFF × 22 ‖ CRC-32/ISO-HDLC of bytes 0..28 (4, LE)
/// ```
///
/// The mode number is its index in [`Mode::ALL`] (as on the wire). The padding stays erased
/// so a later format can use it.
pub mod record {
    use super::{number_of, Mode, CRC32, ERASED, WORD};

    /// The record's first four bytes.
    pub const MAGIC: [u8; 4] = *b"TGMD";
    /// The record layout's version.
    pub const FORMAT: u8 = 1;
    /// Offset of the CRC (the last four bytes).
    const CRC_AT: usize = WORD - 4;

    /// What one flash word holds.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Word {
        /// Never programmed since the last erase.
        Erased,
        /// A valid record of mode number `n` (not necessarily a mode this build knows).
        Record(u8),
        /// Programmed but not a valid record: torn by a power cut, or foreign data.
        Damaged,
    }

    /// The record of `mode`.
    pub fn encode(mode: Mode) -> [u8; WORD] {
        let mut w = [ERASED; WORD];
        w[..4].copy_from_slice(&MAGIC);
        w[4] = FORMAT;
        w[5] = number_of(mode);
        let crc = CRC32.checksum(&w[..CRC_AT]);
        w[CRC_AT..].copy_from_slice(&crc.to_le_bytes());
        w
    }

    /// What `w` holds.
    pub fn decode(w: &[u8; WORD]) -> Word {
        if w.iter().all(|&b| b == ERASED) {
            return Word::Erased;
        }
        let crc = u32::from_le_bytes([w[CRC_AT], w[CRC_AT + 1], w[CRC_AT + 2], w[CRC_AT + 3]]);
        if w[..4] != MAGIC || w[4] != FORMAT || CRC32.checksum(&w[..CRC_AT]) != crc {
            return Word::Damaged;
        }
        Word::Record(w[5])
    }
}

/// Why a save failed: board codes of the flash driver, and the log's own.
pub mod codes {
    /// The word just programmed did not read back as the record written.
    pub const VERIFY: u32 = 0x100;
    /// The sector has no words.
    pub const NO_SECTOR: u32 = 0x101;
}

/// The mode's number: its index in [`Mode::ALL`], as on the wire.
pub fn number_of(mode: Mode) -> u8 {
    Mode::ALL.iter().position(|m| *m == mode).unwrap_or(0) as u8
}

/// The mode log over a sector of flash words.
pub struct ModeLog<F: FlashWords> {
    flash: F,
    /// The next word to program ([`FlashWords::words`] when the sector is full).
    next_free: usize,
}

impl<F: FlashWords> ModeLog<F> {
    /// The log over `flash`; nothing is read until [`ModeStore::load`].
    pub fn new(flash: F) -> Self {
        ModeLog {
            next_free: 0,
            flash,
        }
    }

    /// The sector (for tests and diagnostics).
    pub fn flash(&self) -> &F {
        &self.flash
    }

    /// The next word a save will program.
    pub fn next_free(&self) -> usize {
        self.next_free
    }
}

impl<F: FlashWords> ModeStore for ModeLog<F> {
    fn load(&mut self) -> ModeStoreState {
        let mut last: Option<u8> = None;
        let mut unreadable = None;
        let mut used = 0;
        let mut word = [0u8; WORD];
        for i in 0..self.flash.words() {
            let kind = match self.flash.read(i, &mut word) {
                Ok(()) => record::decode(&word),
                Err(code) => {
                    // Unreadable words are used words (never program over them).
                    unreadable = Some(code);
                    record::Word::Damaged
                }
            };
            match kind {
                record::Word::Erased => continue,
                record::Word::Record(n) => last = Some(n),
                record::Word::Damaged => {}
            }
            used = i + 1;
        }
        self.next_free = used;
        match (last, unreadable) {
            (Some(n), _) => match Mode::ALL.get(n as usize).copied() {
                // A torn word after the last record is a change that was never
                // acknowledged: the record before it is the mode.
                Some(mode) if tangent_core::instrument::supports(mode) => {
                    ModeStoreState::Loaded(mode)
                }
                _ => ModeStoreState::Unusable(n),
            },
            (None, Some(code)) => ModeStoreState::Unreadable(code),
            (None, None) if used > 0 => ModeStoreState::Corrupt,
            (None, None) => ModeStoreState::Empty,
        }
    }

    fn save(&mut self, mode: Mode) -> Result<(), u32> {
        let words = self.flash.words();
        if words == 0 {
            return Err(codes::NO_SECTOR);
        }
        if self.next_free >= words {
            // Full: start again at the sector's first word. A power cut between the erase
            // and the program leaves an empty log (the default mode, reported).
            self.flash.erase()?;
            self.next_free = 0;
        }
        let at = self.next_free;
        let w = record::encode(mode);
        // The word is used whatever happens next: never program it twice.
        self.next_free = at + 1;
        self.flash.program(at, &w)?;
        let mut back = [0u8; WORD];
        self.flash.read(at, &mut back)?;
        if record::decode(&back) != record::Word::Record(number_of(mode)) {
            return Err(codes::VERIFY);
        }
        Ok(())
    }
}

/// A board without a mode store (the emulated board without `--mode-store`): the mode lives
/// in RAM and a reset returns to the default, which [`ModeStoreState::Volatile`] says.
pub struct VolatileModes;

impl ModeStore for VolatileModes {
    fn load(&mut self) -> ModeStoreState {
        ModeStoreState::Volatile
    }
    fn save(&mut self, _mode: Mode) -> Result<(), u32> {
        Ok(())
    }
}

#[cfg(test)]
mod tests;
