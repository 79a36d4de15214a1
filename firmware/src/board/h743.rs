//! The instrument: STM32H743ZI + MT9V034 on embassy-stm32 (wiring in `docs/hardware.md`).
//!
//! * lasers: push-pull GPIOs, low (off) from the first instructions of `main`;
//! * trigger: EXTI input, debounced by re-reading the level after [`DEBOUNCE_US`];
//! * camera: MT9V034 set up over I²C (register table in `docs/hardware.md`), snapshot mode
//!   started by a pulse on its EXPOSURE pin, frames received by DCMI + DMA into AXI SRAM.
//!   One DMA transfer moves at most 65,535 words (262,140 bytes), and RAM holds two frames
//!   plus the pipeline's per-pixel buffers, so the sensor reads out a window of
//!   [`WINDOW_ROWS`] rows (752 × 160 = 120,320 bytes);
//! * link: USB CDC-ACM (embassy-usb);
//! * calibration: a record in the last flash sector (`protocol::calibration_record`);
//! * watchdog: IWDG1, fed by the application's main loop.

use embassy_stm32::dcmi::{self, Dcmi};
use embassy_stm32::exti::ExtiInput;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::Output;
use embassy_stm32::i2c::{I2c, Master};
use embassy_stm32::mode::Blocking as BlockingMode;
use embassy_stm32::peripherals::DCMI;
use embassy_stm32::peripherals::USB_OTG_FS;
use embassy_stm32::usb::Driver;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Instant, Timer};
use embassy_usb::class::cdc_acm::CdcAcmClass;
use embassy_usb::driver::EndpointError;
use tangent_core::protocol::{self, calibration_record, WireCalibration};

use crate::ports::{self, CameraError, Geometry, LinkError, Strobe};

/// Rows read out per frame. The DMA limit alone allows 348 rows of 752 bytes; RAM decides:
/// two frames, the pipeline's difference frame (1 B/px) and labels (2 B/px) are
/// 5 B/px = 601,600 B for 160 rows, in AXI SRAM (frames, difference) and SRAM1–3 (labels).
/// See `docs/hardware.md` for the working range this window covers.
pub const WINDOW_ROWS: u16 = 160;
/// First sensor row of the window: centred on the 480-row sensor.
pub const WINDOW_ROW_OFFSET: u16 = (480 - WINDOW_ROWS) / 2;
/// Sensor width.
pub const WIDTH: u16 = 752;
/// Bytes of one frame.
pub const FRAME_BYTES: usize = WIDTH as usize * WINDOW_ROWS as usize;
/// Trigger debounce time (µs): mechanical bounce of a tactile switch lasts < 5 ms.
pub const DEBOUNCE_US: u64 = 10_000;
/// MT9V034 7-bit I²C address with S_CTRL_ADR0/1 tied low (0x90/0x91 on the bus).
pub const MT9V034_ADDR: u8 = 0x48;
/// MT9V034 chip version (register 0x00).
pub const MT9V034_CHIP_ID: u16 = 0x1324;
/// Pixel clock of the sensor module (its own 26.66 MHz oscillator).
pub const PIXCLK_HZ: u64 = 26_660_000;
/// Horizontal blanking written to the sensor (pixel clocks; default 94, minimum 61).
pub const HBLANK: u16 = 94;

/// embassy-time clock.
pub struct EmbassyClock;

impl ports::Clock for EmbassyClock {
    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }
    async fn delay_us(&self, us: u32) {
        Timer::after(Duration::from_micros(us as u64)).await
    }
}

/// Two lasers on GPIOs (high = on).
pub struct GpioLasers {
    pins: [Output<'static>; 2],
}

impl GpioLasers {
    /// Takes the two laser outputs (created low).
    pub fn new(mut pins: [Output<'static>; 2]) -> Self {
        for p in pins.iter_mut() {
            p.set_low();
        }
        GpioLasers { pins }
    }
}

impl ports::Laser for GpioLasers {
    fn count(&self) -> u8 {
        self.pins.len() as u8
    }
    fn set(&mut self, mask: u8) {
        for (i, p) in self.pins.iter_mut().enumerate() {
            if mask & (1 << i) != 0 {
                p.set_high();
            } else {
                p.set_low();
            }
        }
    }
}

/// Trigger button (active high, pull-down), debounced.
pub struct Button {
    input: ExtiInput<'static, embassy_stm32::mode::Async>,
}

impl Button {
    /// Wraps an EXTI input.
    pub fn new(input: ExtiInput<'static, embassy_stm32::mode::Async>) -> Self {
        Button { input }
    }
}

impl ports::Trigger for Button {
    fn is_pressed(&mut self) -> bool {
        self.input.is_high()
    }
    async fn wait_pressed(&mut self) {
        loop {
            self.input.wait_for_rising_edge().await;
            // A press is a level that is still high after the bounce has died out.
            Timer::after(Duration::from_micros(DEBOUNCE_US)).await;
            if self.input.is_high() {
                return;
            }
        }
    }
}

/// USB CDC-ACM link.
pub struct UsbLink {
    class: CdcAcmClass<'static, Driver<'static, USB_OTG_FS>>,
}

impl UsbLink {
    /// Wraps a CDC-ACM class.
    pub fn new(class: CdcAcmClass<'static, Driver<'static, USB_OTG_FS>>) -> Self {
        UsbLink { class }
    }
}

fn link_err(_: EndpointError) -> LinkError {
    LinkError::Disconnected
}

impl ports::Link for UsbLink {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, LinkError> {
        self.class.wait_connection().await;
        let max = self.class.max_packet_size() as usize;
        let buf = buf.get_mut(..max).ok_or(LinkError::Disconnected)?;
        self.class.read_packet(buf).await.map_err(link_err)
    }

    async fn write_all(&mut self, data: &[u8]) -> Result<(), LinkError> {
        if !self.class.dtr() {
            // Nobody has the port open: drop the message rather than block.
            return Err(LinkError::Disconnected);
        }
        let max = self.class.max_packet_size() as usize;
        for packet in data.chunks(max) {
            self.class.write_packet(packet).await.map_err(link_err)?;
        }
        if data.len().is_multiple_of(max) {
            // A full last packet needs a zero-length packet to end the transfer.
            self.class.write_packet(&[]).await.map_err(link_err)?;
        }
        Ok(())
    }
}

/// Independent watchdog.
pub struct Iwdg {
    wdg: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG1>,
}

impl Iwdg {
    /// Starts the watchdog (it cannot be stopped afterwards).
    pub fn start(mut wdg: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG1>) -> Self {
        wdg.unleash();
        Iwdg { wdg }
    }
}

impl ports::Watchdog for Iwdg {
    fn feed(&mut self) {
        self.wdg.pet();
    }
}

/// Offset of the calibration sector from the start of flash (bank 2, sector 7).
pub const CALIB_OFFSET: u32 = 0x1E_0000;
/// Size of the calibration sector.
pub const CALIB_SECTOR: u32 = 128 * 1024;
/// Flash programming granularity of the H7 (a 256-bit flash word).
const FLASH_WORD: usize = 32;

/// Calibration record in the last flash sector.
pub struct FlashStore {
    flash: Flash<'static, Blocking>,
}

impl FlashStore {
    /// Wraps the flash driver.
    pub fn new(flash: Flash<'static, Blocking>) -> Self {
        FlashStore { flash }
    }
}

impl ports::CalibrationStore for FlashStore {
    fn load(&mut self) -> Option<WireCalibration> {
        let mut buf = [0u8; calibration_record::MAX_RECORD];
        self.flash.blocking_read(CALIB_OFFSET, &mut buf).ok()?;
        calibration_record::decode(&buf)
    }

    fn save(&mut self, calibration: &WireCalibration) -> Result<(), u32> {
        let mut buf = [0xFFu8; calibration_record::MAX_RECORD];
        let n = calibration_record::encode(calibration, &mut buf).ok_or(1u32)?;
        let padded = n.div_ceil(FLASH_WORD) * FLASH_WORD;
        let data = buf.get(..padded).ok_or(2u32)?;
        self.flash
            .blocking_erase(CALIB_OFFSET, CALIB_OFFSET + CALIB_SECTOR)
            .map_err(|_| 3u32)?;
        self.flash
            .blocking_write(CALIB_OFFSET, data)
            .map_err(|_| 4u32)?;
        // Read back: a record that does not verify is not stored.
        match self.load() {
            Some(ref c) if c == calibration => Ok(()),
            _ => Err(5),
        }
    }
}

/// MT9V034 registers used (datasheet register map; context A).
pub mod reg {
    /// Chip version (reads 0x1324).
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
    /// ADC companding: 2 = linear 10-bit.
    pub const ADC_COMPANDING: u8 = 0x1C;
    /// Analog gain (16 = 1×, up to 64 = 4×).
    pub const ANALOG_GAIN: u8 = 0x35;
    /// AEC/AGC enable: bit 0 AEC, bit 1 AGC (context A).
    pub const AEC_AGC_ENABLE: u8 = 0xAF;
}

/// The MT9V034 on I²C + DCMI.
pub struct Mt9v034 {
    i2c: I2c<'static, BlockingMode, Master>,
    dcmi: Dcmi<'static, DCMI>,
    exposure_pin: Output<'static>,
    shutter_rows: u16,
    ready: bool,
}

impl Mt9v034 {
    /// Takes the sensor's buses and sets it up ([`Mt9v034::init`]); a sensor that does not
    /// answer now is set up again before the next capture.
    pub fn new(
        i2c: I2c<'static, BlockingMode, Master>,
        dcmi: Dcmi<'static, DCMI>,
        exposure_pin: Output<'static>,
    ) -> Self {
        let mut cam = Mt9v034 {
            i2c,
            dcmi,
            exposure_pin,
            shutter_rows: 0,
            ready: false,
        };
        if let Err(e) = cam.init() {
            defmt::warn!("MT9V034 set-up failed: {}", e.code());
        }
        cam
    }

    /// Checks the chip id and writes the set-up of `docs/hardware.md`.
    pub fn init(&mut self) -> Result<(), CameraError> {
        self.ready = false;
        if self.read(reg::CHIP_VERSION)? != MT9V034_CHIP_ID {
            return Err(CameraError::Bus);
        }
        self.write(reg::RESET, 1)?;
        self.write(reg::RESET, 0)?;
        let setup: [(u8, u16); 12] = [
            (reg::COL_START, 1),
            (reg::ROW_START, 4 + WINDOW_ROW_OFFSET),
            (reg::WINDOW_HEIGHT, WINDOW_ROWS),
            (reg::WINDOW_WIDTH, WIDTH),
            (reg::HBLANK, HBLANK),
            (reg::VBLANK, 45),
            (reg::READ_MODE, 0x0300), // no binning, no flip (bits 9:8 reserved = 11)
            (reg::AEC_AGC_ENABLE, 0), // exposure and gain are ours: AEC/AGC off
            (reg::ANALOG_GAIN, 16),   // 1x: lowest noise; exposure does the work
            (reg::ADC_COMPANDING, 2), // linear 10-bit; DCMI takes D9..D2
            (reg::LED_OUT_CONTROL, 0), // LED_OUT high during integration (gates the lasers)
            // Snapshot mode (11 in bits 4:3), parallel output on, sequential, bit 9 clear.
            (reg::CHIP_CONTROL, (3 << 3) | (1 << 7) | (1 << 8)),
        ];
        for (r, v) in setup {
            self.write(r, v)?;
        }
        self.shutter_rows = 0;
        self.ready = true;
        Ok(())
    }

    fn write(&mut self, r: u8, v: u16) -> Result<(), CameraError> {
        let [hi, lo] = v.to_be_bytes();
        self.i2c
            .blocking_write(MT9V034_ADDR, &[r, hi, lo])
            .map_err(|_| CameraError::Bus)
    }

    fn read(&mut self, r: u8) -> Result<u16, CameraError> {
        let mut b = [0u8; 2];
        self.i2c
            .blocking_write_read(MT9V034_ADDR, &[r], &mut b)
            .map_err(|_| CameraError::Bus)?;
        Ok(u16::from_be_bytes(b))
    }

    /// Integration time in rows: one row lasts (width + hblank) pixel clocks.
    fn rows_for(exposure_us: u32) -> u16 {
        let row_ns = (WIDTH as u64 + HBLANK as u64) * 1_000_000_000 / PIXCLK_HZ;
        let rows = (exposure_us as u64 * 1000).div_ceil(row_ns.max(1));
        rows.clamp(1, 32_767) as u16
    }
}

impl ports::Camera for Mt9v034 {
    fn geometry(&self) -> Geometry {
        Geometry {
            width: WIDTH,
            height: WINDOW_ROWS,
            row_offset: WINDOW_ROW_OFFSET,
        }
    }

    async fn capture<L: ports::Laser, C: ports::Clock>(
        &mut self,
        exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        buf: &mut [u8],
    ) -> Result<(), CameraError> {
        if !self.ready {
            self.init()?;
        }
        let rows = Self::rows_for(exposure_us);
        if rows != self.shutter_rows {
            self.write(reg::TOTAL_SHUTTER_WIDTH, rows)?;
            self.shutter_rows = rows;
        }
        let words: &mut [u32] = bytemuck::try_cast_slice_mut(
            buf.get_mut(..FRAME_BYTES).ok_or(CameraError::BufferSize)?,
        )
        .map_err(|_| CameraError::BufferSize)?;
        let pin = &mut self.exposure_pin;
        let expose = async {
            // Snapshot: the rising edge of EXPOSURE starts integration, which lasts the
            // programmed shutter width; the lasers follow (and LED_OUT gates them).
            strobe.on();
            pin.set_high();
            Timer::after(Duration::from_micros(exposure_us as u64)).await;
            pin.set_low();
            strobe.off();
        };
        let (result, ()) = embassy_futures::join::join(self.dcmi.capture(words), expose).await;
        result.map_err(|e| match e {
            dcmi::Error::Overrun => CameraError::Transfer,
            _ => CameraError::Transfer,
        })
    }
}

/// The instrument board.
pub struct H743;

impl ports::Board for H743 {
    type Camera = Mt9v034;
    type Laser = GpioLasers;
    type Trigger = Button;
    type Link = UsbLink;
    type Clock = EmbassyClock;
    type Store = FlashStore;
    type Watchdog = Iwdg;
    const KIND: protocol::Board = protocol::Board::H743;
    fn log(args: core::fmt::Arguments<'_>) {
        defmt::info!("{}", defmt::Display2Format(&args));
    }
}
