//! The MT9V034 image sensor's set-up over I²C: register map, the set-up sequence, the shutter
//! width of an exposure. Generic over [`embedded_hal_async::i2c::I2c`], so the sequence is
//! unit-tested on the host against the datasheet values tabled in `docs/hardware.md`
//! ("MT9V034 set-up"); the H743 board adds the frame transfer (DCMI) and the EXPOSURE pin.

use embedded_hal_async::i2c::I2c;

use crate::ports::CameraError;

/// 7-bit I²C address with S_CTRL_ADR0/1 tied low (0x90/0x91 on the bus).
pub const ADDRESS: u8 = 0x48;
/// What register [`reg::CHIP_VERSION`] reads on an MT9V034.
pub const CHIP_VERSION: u16 = 0x1324;
/// Sensor width (columns).
pub const WIDTH: u16 = 752;
/// Sensor height (rows).
pub const HEIGHT: u16 = 480;
/// Row-start value of the first active row (the rows above are dark rows).
pub const FIRST_ACTIVE_ROW: u16 = 4;
/// Column-start value of the first active column.
pub const FIRST_ACTIVE_COLUMN: u16 = 1;
/// Horizontal blanking written to the sensor (pixel clocks; default 94, minimum 61).
pub const HBLANK: u16 = 94;
/// Vertical blanking written to the sensor (rows; the default).
pub const VBLANK: u16 = 45;
/// Read mode: no binning, no flips (bits 9:8 are reserved and read 11).
pub const READ_MODE: u16 = 0x0300;
/// Analog gain 1× (16 = 1×, up to 64 = 4×): the lowest noise; the exposure does the work.
pub const ANALOG_GAIN_1X: u16 = 16;
/// ADC companding: linear 10-bit (the subpixel estimators assume a linear response).
pub const ADC_LINEAR: u16 = 2;
/// LED_OUT control: enabled (bit 0 clear), not inverted (bit 1 clear), so LED_OUT is high
/// during integration and gates the lasers in hardware.
pub const LED_OUT_DURING_INTEGRATION: u16 = 0;
/// Chip control: snapshot mode (bits 4:3 = 11), parallel output on (bit 7), sequential
/// (bit 8); reserved bit 9 cleared.
pub const CHIP_CONTROL_SNAPSHOT: u16 = (0b11 << 3) | (1 << 7) | (1 << 8);
/// Longest shutter width the set-up writes (rows).
pub const MAX_SHUTTER_ROWS: u16 = 32_767;

/// MT9V034 registers used (datasheet register map; context A).
pub mod reg {
    /// Chip version (reads [`super::CHIP_VERSION`]).
    pub const CHIP_VERSION: u8 = 0x00;
    /// Column start (min 1).
    pub const COL_START: u8 = 0x01;
    /// Row start (min 4).
    pub const ROW_START: u8 = 0x02;
    /// Window height (rows).
    pub const WINDOW_HEIGHT: u8 = 0x03;
    /// Window width (columns).
    pub const WINDOW_WIDTH: u8 = 0x04;
    /// Horizontal blanking (pixel clocks).
    pub const HBLANK: u8 = 0x05;
    /// Vertical blanking (rows).
    pub const VBLANK: u8 = 0x06;
    /// Chip control: operating mode bits 4:3 (01 master, 11 snapshot), bit 7 parallel
    /// output enable, bit 8 sequential, bit 9 reserved (clear on MT9V034).
    pub const CHIP_CONTROL: u8 = 0x07;
    /// Coarse shutter width total (integration time in rows).
    pub const TOTAL_SHUTTER_WIDTH: u8 = 0x0B;
    /// Reset: bit 0 soft reset.
    pub const RESET: u8 = 0x0C;
    /// Read mode (binning, flips).
    pub const READ_MODE: u8 = 0x0D;
    /// LED_OUT control: bit 0 disables LED_OUT, bit 1 inverts it.
    pub const LED_OUT_CONTROL: u8 = 0x1B;
    /// ADC companding: 2 = linear 10-bit, 3 = companded.
    pub const ADC_COMPANDING: u8 = 0x1C;
    /// Analog gain (16 = 1×, up to 64 = 4×).
    pub const ANALOG_GAIN: u8 = 0x35;
    /// AEC/AGC enable: bit 0 AEC, bit 1 AGC (context A).
    pub const AEC_AGC_ENABLE: u8 = 0xAF;
}

/// The sensor rows read out: full-width rows `first_row .. first_row + rows` of the
/// [`HEIGHT`] active rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// First active row read out (0 = the top row).
    pub first_row: u16,
    /// Rows read out.
    pub rows: u16,
}

/// The register writes that set the sensor up for `window`, in order (after the soft reset).
pub const fn setup(window: Window) -> [(u8, u16); 12] {
    [
        (reg::COL_START, FIRST_ACTIVE_COLUMN),
        (reg::ROW_START, FIRST_ACTIVE_ROW + window.first_row),
        (reg::WINDOW_HEIGHT, window.rows),
        (reg::WINDOW_WIDTH, WIDTH),
        (reg::HBLANK, HBLANK),
        (reg::VBLANK, VBLANK),
        (reg::READ_MODE, READ_MODE),
        // Exposure and gain are the firmware's (auto-exposure on the stripe, not the scene).
        (reg::AEC_AGC_ENABLE, 0),
        (reg::ANALOG_GAIN, ANALOG_GAIN_1X),
        // DCMI takes D9..D2 of the linear 10-bit value.
        (reg::ADC_COMPANDING, ADC_LINEAR),
        (reg::LED_OUT_CONTROL, LED_OUT_DURING_INTEGRATION),
        // Last: the mode change starts snapshot operation with everything above in place.
        (reg::CHIP_CONTROL, CHIP_CONTROL_SNAPSHOT),
    ]
}

/// The sensor's register interface on an I²C bus.
pub struct Mt9v034<I> {
    i2c: I,
    window: Window,
    pixclk_hz: u64,
    /// Shutter width last written (`None`: not since the set-up).
    shutter_rows: Option<u16>,
    ready: bool,
}

impl<I: I2c> Mt9v034<I> {
    /// The sensor on `i2c`, to read `window`, clocked at `pixclk_hz`. Nothing is sent until
    /// [`Mt9v034::init`] or [`Mt9v034::prepare`].
    pub const fn new(i2c: I, window: Window, pixclk_hz: u64) -> Self {
        Mt9v034 {
            i2c,
            window,
            pixclk_hz,
            shutter_rows: None,
            ready: false,
        }
    }

    /// The window read out.
    pub fn window(&self) -> Window {
        self.window
    }

    /// True once [`Mt9v034::init`] has succeeded.
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// Checks the chip version, soft-resets the sensor and writes [`setup`].
    pub async fn init(&mut self) -> Result<(), CameraError> {
        self.ready = false;
        self.shutter_rows = None;
        if self.read(reg::CHIP_VERSION).await? != CHIP_VERSION {
            return Err(CameraError::Bus);
        }
        self.write(reg::RESET, 1).await?;
        self.write(reg::RESET, 0).await?;
        for (r, v) in setup(self.window) {
            self.write(r, v).await?;
        }
        self.ready = true;
        Ok(())
    }

    /// Readies the sensor for an exposure of `exposure_us`: sets it up if it is not (a sensor
    /// that failed before is tried again), and writes the shutter width when it changed.
    pub async fn prepare(&mut self, exposure_us: u32) -> Result<(), CameraError> {
        if !self.ready {
            self.init().await?;
        }
        let rows = self.shutter_rows_for(exposure_us);
        if self.shutter_rows != Some(rows) {
            self.write(reg::TOTAL_SHUTTER_WIDTH, rows).await?;
            self.shutter_rows = Some(rows);
        }
        Ok(())
    }

    /// Integration time in rows, rounded up: one row lasts [`WIDTH`] + [`HBLANK`] pixel
    /// clocks.
    pub fn shutter_rows_for(&self, exposure_us: u32) -> u16 {
        let row_ns = (WIDTH as u64 + HBLANK as u64) * 1_000_000_000 / self.pixclk_hz.max(1);
        let rows = (exposure_us as u64 * 1000).div_ceil(row_ns.max(1));
        rows.clamp(1, MAX_SHUTTER_ROWS as u64) as u16
    }

    /// Writes a 16-bit register (address byte, then the value big-endian).
    async fn write(&mut self, r: u8, v: u16) -> Result<(), CameraError> {
        let [hi, lo] = v.to_be_bytes();
        self.i2c
            .write(ADDRESS, &[r, hi, lo])
            .await
            .map_err(|_| CameraError::Bus)
    }

    /// Reads a 16-bit register.
    async fn read(&mut self, r: u8) -> Result<u16, CameraError> {
        let mut b = [0u8; 2];
        self.i2c
            .write_read(ADDRESS, &[r], &mut b)
            .await
            .map_err(|_| CameraError::Bus)?;
        Ok(u16::from_be_bytes(b))
    }
}

#[cfg(test)]
mod tests;
