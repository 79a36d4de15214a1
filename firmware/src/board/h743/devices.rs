//! The H743 board's drivers: its implementations of the application's ports.

use core::cell::RefCell;

use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_embedded_hal::shared_bus::asynch::i2c::I2cDevice;
use embassy_stm32::dcmi::Dcmi;
use embassy_stm32::dma::ReadableRingBuffer;
use embassy_stm32::exti::ExtiInput;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::Output;
use embassy_stm32::i2c::{I2c, Master};
use embassy_stm32::mode::Blocking as BlockingMode;
use embassy_stm32::pac;
use embassy_stm32::peripherals::DCMI;
use embassy_stm32::peripherals::USB_OTG_FS;
use embassy_stm32::usb::Driver;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_sync::mutex::Mutex;
use embassy_time::{Duration, Instant, Timer};
use embassy_usb::class::cdc_acm::CdcAcmClass;
use embassy_usb::driver::EndpointError;
use tangent_core::protocol::{self, calibration_record, WireCalibration};

use super::{
    CALIB_OFFSET, CALIB_SECTOR, DEBOUNCE_US, FRAME_BYTES, MODES_OFFSET, MODES_SECTOR, PIXCLK_HZ,
    WIDTH, WINDOW,
};
use crate::adxl355::Adxl355;
use crate::mode_log::{FlashWords, ModeLog, WORD};
use crate::mt9v034::Mt9v034;
use crate::ports::{self, CameraError, Geometry, LinkError, Strobe};

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

/// The three lasers on GPIOs (high = on): the parallel pair and the walls' crossing line,
/// each also gated by the sensor's LED_OUT (`docs/hardware.md`).
pub struct GpioLasers {
    pins: [Output<'static>; 3],
}

impl GpioLasers {
    /// Takes the three laser outputs (created low).
    pub fn new(mut pins: [Output<'static>; 3]) -> Self {
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

/// Flash programming granularity of the H7 (a 256-bit flash word).
const FLASH_WORD: usize = WORD;

/// The flash, shared by the calibration store and the mode log (one driver, two sectors).
/// Both run on the application's one task, never at the same time.
pub type SharedFlash = &'static RefCell<Flash<'static, Blocking>>;

/// Board code of a flash driver that is busy with the other store (cannot happen on the one
/// task; reported rather than a panic).
const FLASH_BUSY: u32 = 6;

/// Calibration record in the last flash sector.
pub struct FlashStore {
    flash: SharedFlash,
}

impl FlashStore {
    /// The calibration sector of `flash`.
    pub fn new(flash: SharedFlash) -> Self {
        FlashStore { flash }
    }
}

impl ports::CalibrationStore for FlashStore {
    fn load(&mut self) -> Option<WireCalibration> {
        let mut buf = [0u8; calibration_record::MAX_RECORD];
        let mut flash = self.flash.try_borrow_mut().ok()?;
        flash.blocking_read(CALIB_OFFSET, &mut buf).ok()?;
        calibration_record::decode(&buf)
    }

    fn save(&mut self, calibration: &WireCalibration) -> Result<(), u32> {
        let mut buf = [0xFFu8; calibration_record::MAX_RECORD];
        let n = calibration_record::encode(calibration, &mut buf).ok_or(1u32)?;
        let padded = n.div_ceil(FLASH_WORD) * FLASH_WORD;
        let data = buf.get(..padded).ok_or(2u32)?;
        {
            let mut flash = self.flash.try_borrow_mut().map_err(|_| FLASH_BUSY)?;
            flash
                .blocking_erase(CALIB_OFFSET, CALIB_OFFSET + CALIB_SECTOR)
                .map_err(|_| 3u32)?;
            flash.blocking_write(CALIB_OFFSET, data).map_err(|_| 4u32)?;
        }
        // Read back: a record that does not verify is not stored.
        match self.load() {
            Some(ref c) if c == calibration => Ok(()),
            _ => Err(5),
        }
    }
}

/// The mode log's sector (bank 2, sector 6; `memory.x`) as flash words. Board codes:
/// 3 erase failed, 4 program failed, 6 flash busy, 7 the word has an uncorrectable ECC error
/// (torn by a power cut), 8 a word outside the sector.
pub struct ModeSector {
    flash: SharedFlash,
}

/// The H743 board's mode store.
pub type FlashModes = ModeLog<ModeSector>;

impl ModeSector {
    /// The mode sector of `flash`.
    pub fn new(flash: SharedFlash) -> Self {
        ModeSector { flash }
    }

    fn offset(index: usize) -> Result<u32, u32> {
        let at = (index * WORD) as u32;
        if at + WORD as u32 > MODES_SECTOR {
            return Err(8);
        }
        Ok(MODES_OFFSET + at)
    }
}

/// Reads one flash word at `address` with data bus faults ignored, and says whether the flash
/// found an uncorrectable (double) ECC error in it. A word torn by a power cut while it was
/// programmed can hold one; an ordinary read of it would be a bus fault at every boot. With
/// FAULTMASK set the core runs at priority −1, where CCR.BFHFNMIGN makes a load's bus fault
/// return without faulting (ARMv7-M ARM B3.2.8); FLASH_SR2.DBECCERR then tells.
fn read_word_ecc_checked(address: u32, word: &mut [u8; WORD]) -> bool {
    use cortex_m::peripheral::SCB;
    const BFHFNMIGN: u32 = 1 << 8;
    let bank = pac::FLASH.bank(1);
    bank.ccr().write(|w| w.set_clr_dbeccerr(true));
    // SAFETY: the SCB's CCR is changed and restored with faults masked (nothing else runs);
    // the address is inside the mode sector of the flash, always mapped for reading.
    unsafe {
        core::arch::asm!("cpsid f");
        let scb = &*SCB::PTR;
        let ccr = scb.ccr.read();
        scb.ccr.write(ccr | BFHFNMIGN);
        cortex_m::asm::dsb();
        cortex_m::asm::isb();
        for (i, chunk) in word.chunks_exact_mut(4).enumerate() {
            let v = core::ptr::read_volatile((address as usize + 4 * i) as *const u32);
            chunk.copy_from_slice(&v.to_le_bytes());
        }
        cortex_m::asm::dsb();
        scb.ccr.write(ccr);
        cortex_m::asm::isb();
        core::arch::asm!("cpsie f");
    }
    let failed = bank.sr().read().dbeccerr();
    bank.ccr().write(|w| {
        w.set_clr_dbeccerr(true);
        w.set_clr_sneccerr(true);
    });
    !failed
}

impl FlashWords for ModeSector {
    fn words(&self) -> usize {
        MODES_SECTOR as usize / WORD
    }

    fn read(&mut self, index: usize, word: &mut [u8; WORD]) -> Result<(), u32> {
        let address = 0x0800_0000 + Self::offset(index)?;
        if read_word_ecc_checked(address, word) {
            Ok(())
        } else {
            Err(7)
        }
    }

    fn program(&mut self, index: usize, word: &[u8; WORD]) -> Result<(), u32> {
        let at = Self::offset(index)?;
        let mut flash = self.flash.try_borrow_mut().map_err(|_| FLASH_BUSY)?;
        flash.blocking_write(at, word).map_err(|_| 4u32)
    }

    fn erase(&mut self) -> Result<(), u32> {
        let mut flash = self.flash.try_borrow_mut().map_err(|_| FLASH_BUSY)?;
        flash
            .blocking_erase(MODES_OFFSET, MODES_OFFSET + MODES_SECTOR)
            .map_err(|_| 3u32)
    }
}

/// I2C1 in blocking mode behind embassy's blocking-to-async adapter (a register write is
/// 3 bytes, ≈ 80 µs at 400 kHz; the DMA-driven `I2c::new` would need two more DMA streams
/// and the I2C1 interrupts for no gain).
pub type I2c1 = BlockingAsync<I2c<'static, BlockingMode, Master>>;

/// I2C1 shared by the image sensor and the accelerometer (`docs/hardware.md`, "Wiring"):
/// an async mutex around the bus, one transaction at a time. Both are used from the
/// application's one task, never during a frame's read-out.
pub type SharedI2c1 = Mutex<NoopRawMutex, I2c1>;

/// One device's handle on [`SharedI2c1`].
pub type SensorBus = I2cDevice<'static, NoopRawMutex, I2c1>;

/// The camera: the MT9V034 (set up over I²C) with its EXPOSURE pin, frames by DCMI + DMA.
pub struct Mt9v034Dcmi {
    sensor: Mt9v034<SensorBus>,
    /// The DCMI's pins and configuration (snapshot mode, polarities); its one-transfer
    /// capture is not used: frames arrive in line blocks through `ring`.
    _dcmi: Dcmi<'static, DCMI>,
    /// Circular DMA from the DCMI into two line blocks (half-transfer and transfer-complete
    /// interrupts): a frame of any height, one block handed over while the other fills.
    ring: ReadableRingBuffer<'static, u32>,
    /// The block handed to the pipeline (read out of the ring).
    block: &'static mut [u32; BLOCK_WORDS],
    exposure_pin: Output<'static>,
}

/// Words of one line block: [`ports::BLOCK_ROWS`] rows of the frame's width.
pub const BLOCK_WORDS: usize = ports::BLOCK_ROWS * WIDTH as usize / 4;

impl Mt9v034Dcmi {
    /// Takes the sensor's buses and sets it up (a sensor that does not answer now is set up
    /// again before the next capture); `ring` is the circular DMA from the DCMI's data
    /// register into two blocks of [`BLOCK_WORDS`] words, `block` where each is read to.
    pub async fn new(
        i2c: SensorBus,
        dcmi: Dcmi<'static, DCMI>,
        ring: ReadableRingBuffer<'static, u32>,
        block: &'static mut [u32; BLOCK_WORDS],
        exposure_pin: Output<'static>,
    ) -> Self {
        let mut sensor = Mt9v034::new(i2c, WINDOW, PIXCLK_HZ);
        if let Err(e) = sensor.init().await {
            defmt::warn!("MT9V034 set-up failed: {}", e.code());
        }
        Mt9v034Dcmi {
            sensor,
            _dcmi: dcmi,
            ring,
            block,
            exposure_pin,
        }
    }

    /// One snapshot: the exposure pulse, and the frame's line blocks handed to `each` as the
    /// DMA fills them. A block overwritten before it was read (the pipeline too slow for the
    /// pixel clock) is a transfer error.
    async fn stream<L: ports::Laser, C: ports::Clock>(
        &mut self,
        exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        mut each: impl FnMut(&[u8]),
    ) -> Result<(), CameraError> {
        self.sensor.prepare(exposure_us).await?;
        let blocks = FRAME_BYTES / (4 * BLOCK_WORDS);
        // A frame is a whole number of ring turns (2 blocks each), so the DMA starts every
        // frame at the ring's start.
        self.ring.clear();
        self.ring.start();
        pac::DCMI.icr().write(|r| {
            r.set_ovr_isc(true);
            r.set_err_isc(true);
            r.set_frame_isc(true);
        });
        // Snapshot mode (set up by `Dcmi::new_8bit`): CAPTURE clears itself after a frame.
        pac::DCMI.cr().modify(|r| {
            r.set_enable(true);
            r.set_capture(true);
        });
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
        let (ring, block) = (&mut self.ring, &mut *self.block);
        let read = async {
            for _ in 0..blocks {
                ring.read_exact(&mut block[..])
                    .await
                    .map_err(|_| CameraError::Transfer)?;
                each(bytemuck::cast_slice(&block[..]));
            }
            Ok(())
        };
        let (result, ()) = embassy_futures::join::join(read, expose).await;
        pac::DCMI.cr().modify(|r| {
            r.set_capture(false);
            r.set_enable(false);
        });
        self.ring.stop().await;
        result
    }
}

impl ports::Camera for Mt9v034Dcmi {
    fn geometry(&self) -> Geometry {
        Geometry {
            width: WIDTH,
            height: WINDOW.rows,
            row_offset: WINDOW.first_row,
        }
    }

    async fn capture<L: ports::Laser, C: ports::Clock>(
        &mut self,
        exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        buf: &mut [u8],
    ) -> Result<(), CameraError> {
        let frame = buf.get_mut(..FRAME_BYTES).ok_or(CameraError::BufferSize)?;
        let mut at = 0;
        self.stream(exposure_us, strobe, |rows| {
            if let Some(dst) = frame.get_mut(at..at + rows.len()) {
                dst.copy_from_slice(rows);
            }
            at += rows.len();
        })
        .await
    }

    async fn capture_rows<L: ports::Laser, C: ports::Clock, S: ports::RowSink + ?Sized>(
        &mut self,
        exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        _buf: &mut [u8],
        sink: &mut S,
    ) -> Result<(), CameraError> {
        self.stream(exposure_us, strobe, |rows| sink.rows(rows))
            .await
    }
}

/// The instrument board.
pub struct H743;

impl ports::Board for H743 {
    type Camera = Mt9v034Dcmi;
    type Laser = GpioLasers;
    type Trigger = Button;
    type Link = UsbLink;
    type Clock = EmbassyClock;
    type Store = FlashStore;
    type ModeStore = FlashModes;
    type Watchdog = Iwdg;
    type Accelerometer = Adxl355<SensorBus>;
    const KIND: protocol::Board = protocol::Board::H743;
    fn log(args: core::fmt::Arguments<'_>) {
        defmt::info!("{}", defmt::Display2Format(&args));
    }
}
