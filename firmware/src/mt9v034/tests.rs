//! The set-up sequence against the datasheet values of `docs/hardware.md`, through an I²C bus
//! that records every transaction.

use std::vec::Vec;

use embassy_futures::block_on;
use embedded_hal_async::i2c::ErrorKind;

use super::*;
use crate::board::h743;
use crate::fakes::{self, Transfer};
use crate::i2c_target::Target;

/// One I²C transaction as the sensor sees it.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Access {
    /// Register write: (register, value).
    Write(u8, u16),
    /// Register read.
    Read(u8),
}

/// An MT9V034's registers as its I²C interface presents them: writes of a 16-bit value,
/// and the chip version (`chip_version`) as the only register read.
struct Registers {
    chip_version: u16,
    pointer: u8,
}

impl Target for Registers {
    fn address(&self) -> u8 {
        0x48
    }
    fn write(&mut self, bytes: &[u8]) -> Result<(), ErrorKind> {
        self.pointer = bytes[0];
        Ok(())
    }
    fn read(&mut self, buf: &mut [u8]) -> Result<(), ErrorKind> {
        assert_eq!(
            self.pointer,
            reg::CHIP_VERSION,
            "only the chip version is read"
        );
        buf.copy_from_slice(&self.chip_version.to_be_bytes());
        Ok(())
    }
}

type RecordingBus = fakes::RecordingBus<Registers>;

/// A sensor answering `chip_version` on a recording bus.
fn bus(chip_version: u16) -> RecordingBus {
    fakes::RecordingBus::new(Registers {
        chip_version,
        pointer: 0,
    })
}

/// The register accesses of a transaction log.
fn accesses(transfers: &[Transfer]) -> Vec<Access> {
    transfers
        .iter()
        .map(|t| match (t.write.as_slice(), t.read) {
            (&[r, hi, lo], 0) => Access::Write(r, u16::from_be_bytes([hi, lo])),
            (&[r], 2) => Access::Read(r),
            other => panic!("not a register access: {other:?}"),
        })
        .collect()
}

/// The H743 board's sensor on a recording bus.
fn sensor(bus: RecordingBus) -> Mt9v034<RecordingBus> {
    Mt9v034::new(bus, h743::WINDOW, h743::PIXCLK_HZ)
}

/// The rows of the "MT9V034 set-up" table of `docs/hardware.md`, in order: register, name and
/// value (the first word of the value column, decimal or 0x-hex).
fn documented_setup() -> Vec<(u8, &'static str, u16)> {
    let doc = include_str!("../../../docs/hardware.md");
    let section = doc
        .split("\n## ")
        .find(|s| s.starts_with("MT9V034 set-up"))
        .expect("docs/hardware.md has an \"MT9V034 set-up\" section");
    let number = |s: &str| match s.strip_prefix("0x") {
        Some(hex) => u16::from_str_radix(hex, 16),
        None => s.parse(),
    };
    section
        .lines()
        .filter(|l| l.starts_with("| 0x"))
        .map(|l| {
            let cols: Vec<&str> = l.split('|').map(str::trim).collect();
            let value = cols[3].split_whitespace().next().unwrap_or("");
            let r = number(cols[1]).unwrap_or_else(|_| panic!("register of {l}"));
            let v = number(value).unwrap_or_else(|_| panic!("value of {l}"));
            (r as u8, cols[2], v)
        })
        .collect()
}

#[test]
fn set_up_is_the_documented_sequence() {
    let doc = documented_setup();
    assert_eq!(doc.len(), 15, "{doc:?}");
    let mut s = sensor(bus(CHIP_VERSION));
    block_on(s.init()).unwrap();
    assert!(s.is_ready());
    let want: Vec<Access> = doc
        .iter()
        .map(|&(r, name, v)| {
            if name.contains("(read)") {
                assert_eq!(v, CHIP_VERSION, "{name}");
                Access::Read(r)
            } else {
                Access::Write(r, v)
            }
        })
        .collect();
    assert_eq!(accesses(&s.i2c.transfers), want);
}

#[test]
fn datasheet_register_addresses() {
    // MT9V034 datasheet register map.
    let map = [
        (reg::CHIP_VERSION, 0x00),
        (reg::COL_START, 0x01),
        (reg::ROW_START, 0x02),
        (reg::WINDOW_HEIGHT, 0x03),
        (reg::WINDOW_WIDTH, 0x04),
        (reg::HBLANK, 0x05),
        (reg::VBLANK, 0x06),
        (reg::CHIP_CONTROL, 0x07),
        (reg::TOTAL_SHUTTER_WIDTH, 0x0B),
        (reg::RESET, 0x0C),
        (reg::READ_MODE, 0x0D),
        (reg::LED_OUT_CONTROL, 0x1B),
        (reg::ADC_COMPANDING, 0x1C),
        (reg::ANALOG_GAIN, 0x35),
        (reg::AEC_AGC_ENABLE, 0xAF),
    ];
    for (code, datasheet) in map {
        assert_eq!(code, datasheet);
    }
    assert_eq!(CHIP_VERSION, 0x1324);
}

#[test]
fn lasers_are_gated_by_led_out_in_snapshot_mode() {
    let written = setup(h743::WINDOW);
    let value = |r| written.iter().find(|&&(w, _)| w == r).map(|&(_, v)| v);
    // LED_OUT enabled (bit 0 clear) and not inverted (bit 1 clear): high while integrating.
    assert_eq!(value(reg::LED_OUT_CONTROL).map(|v| v & 0b11), Some(0));
    // Snapshot mode (bits 4:3 = 11): integration starts on the EXPOSURE pin only.
    assert_eq!(
        value(reg::CHIP_CONTROL).map(|v| (v >> 3) & 0b11),
        Some(0b11)
    );
    // The mode change comes last, with the window and LED_OUT already in place.
    assert_eq!(written.last().map(|&(r, _)| r), Some(reg::CHIP_CONTROL));
}

#[test]
fn the_window_is_the_boards_and_inside_the_sensor() {
    let w = h743::WINDOW;
    let written = setup(w);
    assert!(written.contains(&(reg::ROW_START, 4 + w.first_row)));
    assert!(written.contains(&(reg::WINDOW_HEIGHT, w.rows)));
    assert!(w.first_row + w.rows <= HEIGHT);
    assert_eq!(w.rows, h743::WINDOW_ROWS);
}

#[test]
fn shutter_width_is_written_when_the_exposure_changes() {
    let mut s = sensor(bus(CHIP_VERSION));
    // t_row = (752 + 94) / 26.66 MHz = 31.73 µs (docs/hardware.md).
    block_on(s.prepare(1000)).unwrap();
    let set_up = s.i2c.transfers.len();
    assert_eq!(set_up, 15 + 1, "the first exposure sets the sensor up");
    assert_eq!(
        accesses(&s.i2c.transfers).last().cloned(),
        Some(Access::Write(0x0B, 32))
    );
    block_on(s.prepare(1000)).unwrap();
    assert_eq!(
        s.i2c.transfers.len(),
        set_up,
        "same exposure, nothing written"
    );
    block_on(s.prepare(2000)).unwrap();
    assert_eq!(
        accesses(&s.i2c.transfers).last().cloned(),
        Some(Access::Write(0x0B, 64))
    );
    assert_eq!(s.shutter_rows_for(0), 1);
    assert_eq!(s.shutter_rows_for(u32::MAX), MAX_SHUTTER_ROWS);
}

#[test]
fn a_wrong_chip_is_refused_before_any_write() {
    let mut s = sensor(bus(0x1313)); // MT9V032
    assert_eq!(block_on(s.init()), Err(CameraError::Bus));
    assert!(!s.is_ready());
    assert_eq!(accesses(&s.i2c.transfers), [Access::Read(0x00)]);
}

#[test]
fn a_bus_failure_is_reported_and_the_set_up_retried() {
    let mut b = bus(CHIP_VERSION);
    b.fail_after = 5;
    let mut s = sensor(b);
    assert_eq!(block_on(s.prepare(1000)), Err(CameraError::Bus));
    assert!(!s.is_ready());
    s.i2c.fail_after = usize::MAX;
    s.i2c.transfers.clear();
    block_on(s.prepare(1000)).unwrap();
    assert_eq!(
        accesses(&s.i2c.transfers).first().cloned(),
        Some(Access::Read(0x00)),
        "set up again"
    );
    assert_eq!(s.i2c.transfers.len(), 16);
}
