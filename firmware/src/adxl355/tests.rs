//! The set-up sequence against the datasheet values of `docs/hardware.md` ("ADXL355 set-up"),
//! and the 20-bit sample decoding, through an I²C bus that records every transaction.

use std::vec::Vec;

use embassy_futures::block_on;
use embedded_hal_async::i2c::{ErrorKind, ErrorType, I2c, Operation};

use super::*;

/// One I²C transaction as the sensor sees it.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Access {
    /// Register write: (register, value).
    Write(u8, u8),
    /// Read of `n` bytes from a register.
    Read(u8, usize),
}

/// An ADXL355 on a bus that records what is sent: answers the identity read with `id`, the
/// status with DATA_RDY after `not_ready` polls, the data with `data`; fails every
/// transaction after the first `fail_after`.
struct RecordingBus {
    accesses: Vec<Access>,
    id: [u8; 3],
    not_ready: usize,
    data: [u8; 9],
    fail_after: usize,
}

impl RecordingBus {
    fn new() -> Self {
        RecordingBus {
            accesses: Vec::new(),
            id: [DEVID_AD, DEVID_MST, PARTID],
            not_ready: 0,
            data: [0; 9],
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
        assert_eq!(address, 0x1D, "the accelerometer's address (ASEL low)");
        if self.accesses.len() >= self.fail_after {
            return Err(ErrorKind::Bus);
        }
        match ops {
            [Operation::Write(&[r, v])] => self.accesses.push(Access::Write(r, v)),
            [Operation::Write(&[r]), Operation::Read(buf)] => {
                self.accesses.push(Access::Read(r, buf.len()));
                match (r, buf.len()) {
                    (reg::DEVID_AD, 3) => buf.copy_from_slice(&self.id),
                    (reg::STATUS, 1) => {
                        buf[0] = if self.not_ready == 0 {
                            STATUS_DATA_RDY
                        } else {
                            self.not_ready -= 1;
                            0
                        }
                    }
                    (reg::XDATA3, 9) => buf.copy_from_slice(&self.data),
                    other => panic!("unexpected read {other:?}"),
                }
            }
            other => panic!("not a register access: {other:?}"),
        }
        Ok(())
    }
}

/// The rows of the "ADXL355 set-up" table of `docs/hardware.md`, in order: register, name
/// and value (the first word of the value column, 0x-hex).
fn documented_setup() -> Vec<(u8, &'static str, u8)> {
    let doc = include_str!("../../../docs/hardware.md");
    let section = doc
        .split("\n## ")
        .find(|s| s.starts_with("ADXL355 set-up"))
        .expect("docs/hardware.md has an \"ADXL355 set-up\" section");
    let hex = |s: &str| u8::from_str_radix(s.trim_start_matches("0x"), 16);
    section
        .lines()
        .filter(|l| l.starts_with("| 0x"))
        .map(|l| {
            let cols: Vec<&str> = l.split('|').map(str::trim).collect();
            let value = cols[3].split_whitespace().next().unwrap_or("");
            let r = hex(cols[1]).unwrap_or_else(|_| panic!("register of {l}"));
            let v = hex(value).unwrap_or_else(|_| panic!("value of {l}"));
            (r, cols[2], v)
        })
        .collect()
}

#[test]
fn set_up_is_the_documented_sequence() {
    let doc = documented_setup();
    assert_eq!(doc.len(), 5, "{doc:?}");
    let mut s = Adxl355::new(RecordingBus::new());
    block_on(s.init()).unwrap();
    assert!(s.is_ready());
    let want: Vec<Access> = doc
        .iter()
        .map(|&(r, name, v)| {
            if name.contains("(read)") {
                assert_eq!(v, DEVID_AD, "{name}");
                Access::Read(r, 3)
            } else {
                Access::Write(r, v)
            }
        })
        .collect();
    assert_eq!(s.i2c.accesses, want);
}

#[test]
fn datasheet_register_addresses() {
    // ADXL355 datasheet register map (Rev. D, Table 15).
    let map = [
        (reg::DEVID_AD, 0x00),
        (reg::DEVID_MST, 0x01),
        (reg::PARTID, 0x02),
        (reg::STATUS, 0x04),
        (reg::XDATA3, 0x08),
        (reg::FILTER, 0x28),
        (reg::RANGE, 0x2C),
        (reg::POWER_CTL, 0x2D),
        (reg::RESET, 0x2F),
    ];
    for (code, datasheet) in map {
        assert_eq!(code, datasheet);
    }
    assert_eq!(
        (DEVID_AD, DEVID_MST, PARTID, RESET_CODE),
        (0xAD, 0x1D, 0xED, 0x52)
    );
}

#[test]
fn a_wrong_part_or_a_silent_bus_is_refused() {
    let mut bus = RecordingBus::new();
    bus.id = [0xAD, 0x1D, 0xE5]; // an ADXL345-like part ID
    let mut s = Adxl355::new(bus);
    assert_eq!(block_on(s.init()), Err(AccelError::WrongPart));
    assert!(!s.is_ready());
    let mut bus = RecordingBus::new();
    bus.fail_after = 2;
    let mut s = Adxl355::new(bus);
    assert_eq!(block_on(s.init()), Err(AccelError::Bus));
    assert!(!s.is_ready());
}

#[test]
fn twenty_bit_samples_decode_with_their_sign() {
    // Datasheet: 20-bit two's complement, left-justified in three bytes.
    assert_eq!(axis_counts(0x00, 0x00, 0x10), 1);
    assert_eq!(axis_counts(0x7F, 0xFF, 0xF0), 0x7FFFF);
    assert_eq!(axis_counts(0xFF, 0xFF, 0xF0), -1);
    assert_eq!(axis_counts(0x80, 0x00, 0x00), -0x80000);
    // The low nibble of the third byte is reserved: ignored.
    assert_eq!(axis_counts(0x00, 0x00, 0x1F), 1);
}

#[test]
fn a_sample_waits_for_data_ready_and_reads_one_g() {
    let g = LSB_PER_G_2G as i32; // +1 g on z, −1 g on x, 0 on y
    let enc = |c: i32| {
        let raw = (c as u32) & 0xFFFFF;
        [
            (raw >> 12) as u8,
            (raw >> 4) as u8,
            ((raw & 0xF) << 4) as u8,
        ]
    };
    let mut bus = RecordingBus::new();
    bus.not_ready = 2;
    let (x, y, z) = (enc(-g), enc(0), enc(g));
    bus.data = [x[0], x[1], x[2], y[0], y[1], y[2], z[0], z[1], z[2]];
    let mut s = Adxl355::new(bus);
    let a = block_on(s.sample()).unwrap();
    let close = |a: f32, b: f32| (a - b).abs() < 1e-4;
    assert!(close(a.m_s2[0], -STANDARD_GRAVITY), "{a:?}");
    assert!(close(a.m_s2[1], 0.0), "{a:?}");
    assert!(close(a.m_s2[2], STANDARD_GRAVITY), "{a:?}");
    // Set-up (1 read + 4 writes), then three status polls and the data read.
    let tail: Vec<Access> = s.i2c.accesses[5..].to_vec();
    assert_eq!(
        tail,
        [
            Access::Read(reg::STATUS, 1),
            Access::Read(reg::STATUS, 1),
            Access::Read(reg::STATUS, 1),
            Access::Read(reg::XDATA3, 9),
        ]
    );
}

#[test]
fn a_sensor_that_never_becomes_ready_times_out() {
    let mut bus = RecordingBus::new();
    bus.not_ready = usize::MAX;
    let mut s = Adxl355::new(bus);
    assert_eq!(block_on(s.read_counts()), Err(AccelError::Timeout));
}
