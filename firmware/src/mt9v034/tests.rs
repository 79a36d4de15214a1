//! The set-up sequence against the datasheet values of `docs/hardware.md`, through an I²C bus
//! that records every transaction.

use std::vec::Vec;

use embassy_futures::block_on;
use embedded_hal_async::i2c::{ErrorKind, ErrorType, I2c, Operation};

use super::*;
use crate::board::h743;

/// One I²C transaction as the sensor sees it.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Access {
    /// Register write: (register, value).
    Write(u8, u16),
    /// Register read.
    Read(u8),
}

/// An MT9V034 on a bus that records what is sent; answers the chip-version read with
/// `chip_version` and fails every transaction after the first `fail_after`.
struct RecordingBus {
    accesses: Vec<Access>,
    chip_version: u16,
    fail_after: usize,
}

impl RecordingBus {
    fn new() -> Self {
        RecordingBus {
            accesses: Vec::new(),
            chip_version: CHIP_VERSION,
            fail_after: usize::MAX,
        }
    }
}

impl ErrorType for RecordingBus {
    type Error = ErrorKind;
}

impl I2c for RecordingBus {
    async fn transaction(
        &mut self,
        address: u8,
        ops: &mut [Operation<'_>],
    ) -> Result<(), ErrorKind> {
        assert_eq!(address, 0x48, "the sensor's address");
        if self.accesses.len() >= self.fail_after {
            return Err(ErrorKind::Bus);
        }
        match ops {
            [Operation::Write(&[r, hi, lo])] => self
                .accesses
                .push(Access::Write(r, u16::from_be_bytes([hi, lo]))),
            [Operation::Write(&[r]), Operation::Read(buf)] if buf.len() == 2 => {
                assert_eq!(r, reg::CHIP_VERSION, "only the chip version is read");
                buf.copy_from_slice(&self.chip_version.to_be_bytes());
                self.accesses.push(Access::Read(r));
            }
            other => panic!("not a register access: {other:?}"),
        }
        Ok(())
    }
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
    let mut s = sensor(RecordingBus::new());
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
    assert_eq!(s.i2c.accesses, want);
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
    let mut s = sensor(RecordingBus::new());
    // t_row = (752 + 94) / 26.66 MHz = 31.73 µs (docs/hardware.md).
    block_on(s.prepare(1000)).unwrap();
    let set_up = s.i2c.accesses.len();
    assert_eq!(set_up, 15 + 1, "the first exposure sets the sensor up");
    assert_eq!(s.i2c.accesses.last(), Some(&Access::Write(0x0B, 32)));
    block_on(s.prepare(1000)).unwrap();
    assert_eq!(
        s.i2c.accesses.len(),
        set_up,
        "same exposure, nothing written"
    );
    block_on(s.prepare(2000)).unwrap();
    assert_eq!(s.i2c.accesses.last(), Some(&Access::Write(0x0B, 64)));
    assert_eq!(s.shutter_rows_for(0), 1);
    assert_eq!(s.shutter_rows_for(u32::MAX), MAX_SHUTTER_ROWS);
}

#[test]
fn a_wrong_chip_is_refused_before_any_write() {
    let mut s = sensor(RecordingBus {
        chip_version: 0x1313, // MT9V032
        ..RecordingBus::new()
    });
    assert_eq!(block_on(s.init()), Err(CameraError::Bus));
    assert!(!s.is_ready());
    assert_eq!(s.i2c.accesses, [Access::Read(0x00)]);
}

#[test]
fn a_bus_failure_is_reported_and_the_set_up_retried() {
    let mut s = sensor(RecordingBus {
        fail_after: 5,
        ..RecordingBus::new()
    });
    assert_eq!(block_on(s.prepare(1000)), Err(CameraError::Bus));
    assert!(!s.is_ready());
    s.i2c.fail_after = usize::MAX;
    s.i2c.accesses.clear();
    block_on(s.prepare(1000)).unwrap();
    assert_eq!(
        s.i2c.accesses.first(),
        Some(&Access::Read(0x00)),
        "set up again"
    );
    assert_eq!(s.i2c.accesses.len(), 16);
}
