//! The set-up sequence against the datasheet values of `docs/hardware.md` ("ADXL355 set-up"),
//! and the 20-bit sample decoding, through an I²C bus that records every transaction.

use std::vec::Vec;

use embassy_futures::block_on;

use super::model::Adxl355Model;
use super::*;
use crate::fakes::{self, Transfer};
use crate::i2c_target::TargetBus;

/// One I²C transaction as the sensor sees it.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Access {
    /// Register write: (register, value).
    Write(u8, u8),
    /// Read of `n` bytes from a register.
    Read(u8, usize),
}

type RecordingBus = fakes::RecordingBus<Adxl355Model>;

/// The register model of the part, sensing `force` without noise, on a recording bus.
fn bus(force: [f32; 3]) -> RecordingBus {
    fakes::RecordingBus::new(Adxl355Model::new(force, 0.0, 1))
}

/// The register accesses of a transaction log.
fn accesses(transfers: &[Transfer]) -> Vec<Access> {
    transfers
        .iter()
        .map(|t| match (t.write.as_slice(), t.read) {
            (&[r, v], 0) => Access::Write(r, v),
            (&[r], n) if n > 0 => Access::Read(r, n),
            other => panic!("not a register access: {other:?}"),
        })
        .collect()
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
    let mut s = Adxl355::new(bus([0.0; 3]));
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
    assert_eq!(accesses(&s.i2c.transfers), want);
    // The part took it: measuring at ±2 g, 62.5 Hz.
    let part = s.i2c.target();
    assert!(part.is_measuring());
    assert_eq!(
        (part.lsb_per_g(), part.filter()),
        (LSB_PER_G_2G, FILTER_ODR_62HZ5)
    );
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
fn a_wrong_part_a_failing_bus_and_no_part_are_told_apart() {
    let mut b = bus([0.0; 3]);
    b.target().id = [0xAD, 0x1D, 0xE5]; // an ADXL345-like part ID
    let mut s = Adxl355::new(b);
    assert_eq!(block_on(s.init()), Err(AccelError::WrongPart));
    assert!(!s.is_ready());
    let mut b = bus([0.0; 3]);
    b.fail_after = 2;
    let mut s = Adxl355::new(b);
    assert_eq!(block_on(s.init()), Err(AccelError::Bus));
    assert!(!s.is_ready());
    // Nothing answers the address: an unfitted part, reported as such (not a failure).
    let mut s = Adxl355::new(TargetBus::<Adxl355Model>::new(None));
    assert_eq!(block_on(s.init()), Err(AccelError::Absent));
    assert_eq!(block_on(s.mean(16)).map(|_| ()), Err(AccelError::Absent));
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
    // −1 g on x, 0 on y, +1 g on z: whole counts at ±2 g.
    let mut b = bus([-STANDARD_GRAVITY, 0.0, STANDARD_GRAVITY]);
    b.target().conversion_polls = 2;
    let mut s = Adxl355::new(b);
    let a = block_on(s.sample()).unwrap();
    let close = |a: f32, b: f32| (a - b).abs() < 1e-4;
    assert!(close(a.m_s2[0], -STANDARD_GRAVITY), "{a:?}");
    assert!(close(a.m_s2[1], 0.0), "{a:?}");
    assert!(close(a.m_s2[2], STANDARD_GRAVITY), "{a:?}");
    // Set-up (1 read + 4 writes), then three status polls and the data read.
    let tail: Vec<Access> = accesses(&s.i2c.transfers)[5..].to_vec();
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
fn a_sensor_left_in_standby_times_out() {
    // A part whose POWER_CTL write is lost stays in standby: DATA_RDY never rises.
    let mut s = Adxl355::new(bus([0.0, 0.0, STANDARD_GRAVITY]));
    s.ready = true;
    assert_eq!(block_on(s.read_counts()), Err(AccelError::Timeout));
}

/// The mean of n noisy samples scatters as σ/√n about the sensed force: the averaging the
/// application does with every wall reading, through the whole driver, on the model the
/// emulated board uses.
#[test]
fn the_mean_of_noisy_samples_scatters_as_sigma_over_root_n() {
    let force = [0.3, -STANDARD_GRAVITY, 0.1];
    let (n, trials) = (16u16, 400);
    let mut s = Adxl355::new(TargetBus::new(Some(Adxl355Model::new(
        force,
        SAMPLE_SIGMA_M_S2,
        7,
    ))));
    let mut sum2 = [0.0f64; 3];
    for _ in 0..trials {
        let m = block_on(s.mean(n)).unwrap();
        for axis in 0..3 {
            sum2[axis] += ((m.m_s2[axis] - force[axis]) as f64).powi(2);
        }
    }
    let want = SAMPLE_SIGMA_M_S2 as f64 / (n as f64).sqrt();
    for (axis, s2) in sum2.iter().enumerate() {
        let rms = (s2 / trials as f64).sqrt();
        // 400 trials: the rms is within ±10 % of σ/√n at ≈ 3σ (its relative σ is 1/√800);
        // the 1-count quantisation (3.8e-5 m/s²) adds ≈ 1 % here.
        assert!(
            (rms / want - 1.0).abs() < 0.1,
            "axis {axis}: rms {rms:e}, σ/√n {want:e}"
        );
    }
    assert_eq!(s.sample_sigma_m_s2(), SAMPLE_SIGMA_M_S2);
}
