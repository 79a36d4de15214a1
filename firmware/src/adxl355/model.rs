//! A register-level model of the ADXL355 on I²C (datasheet Rev. D register map): the
//! emulated board's accelerometer and the driver's test part. It answers the identity
//! registers, takes the reset, range, filter and power-control writes, raises DATA_RDY only
//! while measuring, and reads out a fixed specific force plus Gaussian noise per sample as
//! 20-bit left-justified two's complement at the programmed range, so the driver's whole
//! path (set-up, polling, decoding, scaling, averaging) runs against it.
//!
//! Not modelled: the output data rate in time (a sample is ready after
//! [`Adxl355Model::conversion_polls`] status reads instead of 16 ms), the FIFO, the
//! temperature, the high-pass filter and the interrupts.

use embedded_hal_async::i2c::ErrorKind;

use super::{reg, ADDRESS, DEVID_AD, DEVID_MST, PARTID, RESET_CODE, STANDARD_GRAVITY};
use crate::i2c_target::Target;

/// RANGE after reset (datasheet: ±2 g, I²C high speed, interrupts active high).
pub const RANGE_RESET: u8 = 0x81;
/// POWER_CTL after reset: standby.
pub const POWER_RESET: u8 = 0x01;
/// Largest 20-bit count.
const MAX_COUNTS: i32 = (1 << 19) - 1;

/// The part's state.
#[derive(Debug, Clone)]
pub struct Adxl355Model {
    /// What the identity registers read (DEVID_AD, DEVID_MST, PARTID).
    pub id: [u8; 3],
    /// The specific force it senses (sensor axes, m/s²): fixed, as a device held still.
    pub force_m_s2: [f32; 3],
    /// 1σ of each sample's noise on each axis (m/s²).
    pub noise_m_s2: f32,
    /// Status reads with DATA_RDY clear before each new sample (0: always ready).
    pub conversion_polls: u32,
    /// State of the noise generator (xorshift64*; never 0).
    rng: u64,
    pointer: u8,
    range: u8,
    filter: u8,
    power: u8,
    /// Status reads left before DATA_RDY rises.
    polls_left: u32,
    /// The latched sample's nine data bytes (X, Y, Z; read from XDATA3).
    data: [u8; 9],
}

impl Adxl355Model {
    /// An ADXL355 sensing `force_m_s2` with `noise_m_s2` per sample, its noise drawn from
    /// `seed`; in its reset state (standby).
    pub fn new(force_m_s2: [f32; 3], noise_m_s2: f32, seed: u64) -> Self {
        Adxl355Model {
            id: [DEVID_AD, DEVID_MST, PARTID],
            force_m_s2,
            noise_m_s2,
            conversion_polls: 0,
            // Odd and non-zero whatever the seed.
            rng: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
            pointer: 0,
            range: RANGE_RESET,
            filter: 0,
            power: POWER_RESET,
            polls_left: 0,
            data: [0; 9],
        }
    }

    /// True while measuring (POWER_CTL's STANDBY bit clear).
    pub fn is_measuring(&self) -> bool {
        self.power & 0x01 == 0
    }

    /// The programmed sensitivity (LSB per g) of RANGE bits 1:0 (00 is reserved: ±2 g).
    pub fn lsb_per_g(&self) -> f32 {
        match self.range & 0b11 {
            0b10 => 128_000.0,
            0b11 => 64_000.0,
            _ => 256_000.0,
        }
    }

    /// The FILTER register as written.
    pub fn filter(&self) -> u8 {
        self.filter
    }

    fn reset(&mut self) {
        self.range = RANGE_RESET;
        self.filter = 0;
        self.power = POWER_RESET;
        self.polls_left = 0;
    }

    /// One standard normal draw (xorshift64* and Box–Muller).
    fn gaussian(&mut self) -> f32 {
        let mut uniform = || {
            self.rng ^= self.rng >> 12;
            self.rng ^= self.rng << 25;
            self.rng ^= self.rng >> 27;
            let x = self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D);
            // 24 bits in (0, 1]: the logarithm below stays finite.
            ((x >> 40) as f32 + 1.0) / (1u32 << 24) as f32
        };
        let (u1, u2) = (uniform(), uniform());
        libm::sqrtf(-2.0 * libm::logf(u1)) * libm::cosf(2.0 * core::f32::consts::PI * u2)
    }

    /// Latches a new sample into the data registers.
    fn convert(&mut self) {
        let scale = self.lsb_per_g() / STANDARD_GRAVITY;
        for axis in 0..3 {
            let m_s2 = self.force_m_s2[axis] + self.noise_m_s2 * self.gaussian();
            let counts = libm::roundf(m_s2 * scale) as i32;
            let raw = counts.clamp(-MAX_COUNTS - 1, MAX_COUNTS) as u32 & 0xF_FFFF;
            self.data[3 * axis] = (raw >> 12) as u8;
            self.data[3 * axis + 1] = (raw >> 4) as u8;
            self.data[3 * axis + 2] = ((raw & 0xF) << 4) as u8;
        }
        self.polls_left = self.conversion_polls;
    }

    /// The register at `address` as read (reading the data registers consumes nothing:
    /// the status read decides when a new sample is latched).
    fn register(&mut self, address: u8) -> u8 {
        match address {
            reg::DEVID_AD => self.id[0],
            reg::DEVID_MST => self.id[1],
            reg::PARTID => self.id[2],
            reg::STATUS => {
                if !self.is_measuring() {
                    return 0;
                }
                if self.polls_left > 0 {
                    self.polls_left -= 1;
                    return 0;
                }
                self.convert();
                super::STATUS_DATA_RDY
            }
            a if (reg::XDATA3..reg::XDATA3 + 9).contains(&a) => {
                self.data[(a - reg::XDATA3) as usize]
            }
            reg::FILTER => self.filter,
            reg::RANGE => self.range,
            reg::POWER_CTL => self.power,
            _ => 0,
        }
    }
}

impl Target for Adxl355Model {
    fn address(&self) -> u8 {
        ADDRESS
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), ErrorKind> {
        let Some((&pointer, data)) = bytes.split_first() else {
            return Ok(());
        };
        self.pointer = pointer;
        for &v in data {
            match self.pointer {
                reg::RESET if v == RESET_CODE => self.reset(),
                reg::FILTER => self.filter = v,
                reg::RANGE => self.range = v,
                reg::POWER_CTL => {
                    self.power = v;
                    // The first conversion after leaving standby takes its time too.
                    self.polls_left = self.conversion_polls;
                }
                // Read-only and unmodelled registers ignore writes, as the part does.
                _ => {}
            }
            self.pointer = self.pointer.wrapping_add(1);
        }
        Ok(())
    }

    fn read(&mut self, buf: &mut [u8]) -> Result<(), ErrorKind> {
        for b in buf.iter_mut() {
            *b = self.register(self.pointer);
            self.pointer = self.pointer.wrapping_add(1);
        }
        Ok(())
    }
}
