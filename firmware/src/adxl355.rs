//! The ADXL355 3-axis accelerometer (the wall instrument's vertical reference,
//! `docs/building.md` §6, wiring in `docs/hardware.md` "Accelerometer") over I²C: register
//! map, the set-up sequence, the 20-bit sample read. Generic over
//! [`embedded_hal_async::i2c::I2c`], so the sequence is unit-tested on the host against the
//! datasheet values tabled in `docs/hardware.md` ("ADXL355 set-up"), as the MT9V034's is.

use embedded_hal_async::i2c::{Error as _, ErrorKind, I2c};

use crate::ports::{AccelError, Acceleration, Accelerometer};

/// 7-bit I²C address with ASEL (pin MISO/ASEL) tied low.
pub const ADDRESS: u8 = 0x1D;
/// What [`reg::DEVID_AD`] reads (Analog Devices).
pub const DEVID_AD: u8 = 0xAD;
/// What [`reg::DEVID_MST`] reads (MEMS).
pub const DEVID_MST: u8 = 0x1D;
/// What [`reg::PARTID`] reads (ADXL355).
pub const PARTID: u8 = 0xED;
/// The code written to [`reg::RESET`] for a software reset.
pub const RESET_CODE: u8 = 0x52;
/// Range register: ±2 g (bits 1:0 = 01), I²C high-speed mode off, interrupt active low:
/// the finest scale; a hand-held device at rest sees 1 g.
pub const RANGE_2G: u8 = 0x01;
/// Filter register: no high-pass (bits 6:4 = 0; gravity is the signal), ODR 62.5 Hz with
/// the low-pass corner at 15.625 Hz (bits 3:0 = 6): above hand tremor's useful averaging.
pub const FILTER_ODR_62HZ5: u8 = 0x06;
/// Power control: measurement mode (STANDBY bit 0 clear), temperature on, DRDY pin off.
pub const POWER_MEASURE: u8 = 0x04;
/// Sensitivity at ±2 g (LSB per g, datasheet: 256 000, 3.9 µg/LSB).
pub const LSB_PER_G_2G: f32 = 256_000.0;
/// Standard gravity (m/s²), to give the specific force in SI.
pub const STANDARD_GRAVITY: f32 = 9.806_65;
/// Status register: bit 0 DATA_RDY (a new X, Y, Z sample is ready).
pub const STATUS_DATA_RDY: u8 = 0x01;
/// Status polls before a sample is declared late (62.5 Hz: 16 ms per sample; a poll is
/// ≈ 0.1 ms at 400 kHz, so 1000 polls are six sample periods).
pub const MAX_STATUS_POLLS: u32 = 1000;
/// 1σ of one sample on each axis at [`FILTER_ODR_62HZ5`] (m/s²): the datasheet's noise
/// density, 22.5 µg/√Hz, over the low-pass's noise bandwidth ≈ 1.6 × 15.625 Hz
/// (0.1125 mg; the simulator's reference sensor, `docs/building.md` §6).
pub const SAMPLE_SIGMA_M_S2: f32 = 22.5e-6 * 5.0 * STANDARD_GRAVITY;

/// ADXL355 registers used (datasheet register map). Multi-byte reads auto-increment.
pub mod reg {
    /// Analog Devices ID (reads [`super::DEVID_AD`]); DEVID_MST and PARTID follow.
    pub const DEVID_AD: u8 = 0x00;
    /// MEMS ID (reads [`super::DEVID_MST`]).
    pub const DEVID_MST: u8 = 0x01;
    /// Part ID (reads [`super::PARTID`]).
    pub const PARTID: u8 = 0x02;
    /// Status: bit 0 DATA_RDY.
    pub const STATUS: u8 = 0x04;
    /// X data, bits 19:12; then XDATA2 (11:4), XDATA1 (3:0 in bits 7:4), and Y, Z alike.
    pub const XDATA3: u8 = 0x08;
    /// Filter: high-pass corner (bits 6:4), output data rate and low-pass (bits 3:0).
    pub const FILTER: u8 = 0x28;
    /// Range (bits 1:0), interrupt polarity (bit 6), I²C speed (bit 7).
    pub const RANGE: u8 = 0x2C;
    /// Power control: bit 0 STANDBY, bit 1 TEMP_OFF, bit 2 DRDY_OFF.
    pub const POWER_CTL: u8 = 0x2D;
    /// Reset: write [`super::RESET_CODE`].
    pub const RESET: u8 = 0x2F;
}

/// The register writes that set the sensor up, in order, after the identity check.
pub const SETUP: [(u8, u8); 4] = [
    (reg::RESET, RESET_CODE),
    (reg::RANGE, RANGE_2G),
    (reg::FILTER, FILTER_ODR_62HZ5),
    // Last: leaving standby starts the conversions with the range and filter in place.
    (reg::POWER_CTL, POWER_MEASURE),
];

/// One axis from its three data bytes: a 20-bit two's-complement value, left-justified
/// (`d3` bits 19:12, `d2` bits 11:4, `d1` bits 7:4 = bits 3:0).
pub fn axis_counts(d3: u8, d2: u8, d1: u8) -> i32 {
    let raw = ((d3 as u32) << 12) | ((d2 as u32) << 4) | ((d1 as u32) >> 4);
    // Sign-extend bit 19: shift it to bit 31 and back arithmetically.
    ((raw << 12) as i32) >> 12
}

/// The three axes of a 9-byte read from [`reg::XDATA3`].
pub fn sample_counts(b: &[u8; 9]) -> [i32; 3] {
    [
        axis_counts(b[0], b[1], b[2]),
        axis_counts(b[3], b[4], b[5]),
        axis_counts(b[6], b[7], b[8]),
    ]
}

/// The accelerometer's register interface on an I²C bus.
pub struct Adxl355<I> {
    i2c: I,
    ready: bool,
}

impl<I: I2c> Adxl355<I> {
    /// The sensor on `i2c`. Nothing is sent until [`Adxl355::init`] or the first sample.
    pub const fn new(i2c: I) -> Self {
        Adxl355 { i2c, ready: false }
    }

    /// True once [`Adxl355::init`] has succeeded.
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// Checks the three identity registers, resets the sensor and writes [`SETUP`].
    pub async fn init(&mut self) -> Result<(), AccelError> {
        self.ready = false;
        let mut id = [0u8; 3];
        // The first transaction tells an unfitted part from a failing one: a fitted part
        // acknowledges its address and the register pointer, so any missing acknowledge
        // here is no part (the STM32's I²C does not say which byte went unanswered).
        self.i2c
            .write_read(ADDRESS, &[reg::DEVID_AD], &mut id)
            .await
            .map_err(|e| match e.kind() {
                ErrorKind::NoAcknowledge(_) => AccelError::Absent,
                _ => AccelError::Bus,
            })?;
        if id != [DEVID_AD, DEVID_MST, PARTID] {
            return Err(AccelError::WrongPart);
        }
        for (r, v) in SETUP {
            self.write(r, v).await?;
        }
        self.ready = true;
        Ok(())
    }

    /// Waits for DATA_RDY (at most [`MAX_STATUS_POLLS`] polls) and reads one sample in
    /// counts.
    pub async fn read_counts(&mut self) -> Result<[i32; 3], AccelError> {
        if !self.ready {
            self.init().await?;
        }
        let mut polls = 0;
        loop {
            let mut s = [0u8; 1];
            self.i2c
                .write_read(ADDRESS, &[reg::STATUS], &mut s)
                .await
                .map_err(|_| AccelError::Bus)?;
            if s[0] & STATUS_DATA_RDY != 0 {
                break;
            }
            polls += 1;
            if polls >= MAX_STATUS_POLLS {
                return Err(AccelError::Timeout);
            }
        }
        let mut b = [0u8; 9];
        self.i2c
            .write_read(ADDRESS, &[reg::XDATA3], &mut b)
            .await
            .map_err(|_| AccelError::Bus)?;
        Ok(sample_counts(&b))
    }

    async fn write(&mut self, r: u8, v: u8) -> Result<(), AccelError> {
        self.i2c
            .write(ADDRESS, &[r, v])
            .await
            .map_err(|_| AccelError::Bus)
    }
}

impl<I: I2c> Accelerometer for Adxl355<I> {
    async fn sample(&mut self) -> Result<Acceleration, AccelError> {
        let c = self.read_counts().await?;
        let k = STANDARD_GRAVITY / LSB_PER_G_2G;
        Ok(Acceleration {
            m_s2: [c[0] as f32 * k, c[1] as f32 * k, c[2] as f32 * k],
        })
    }

    fn sample_sigma_m_s2(&self) -> f32 {
        SAMPLE_SIGMA_M_S2
    }
}

pub mod model;

#[cfg(test)]
mod tests;
