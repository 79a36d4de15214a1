//! Bringing the H743 board up: the clock tree, the pin map (`docs/hardware.md`, "Wiring"),
//! the USB descriptors, and the buffers' places in RAM.

use core::cell::RefCell;
use core::ptr::addr_of_mut;
use embassy_stm32::dcmi::{self, Dcmi};
use embassy_stm32::dma::ReadableRingBuffer;
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::{Level, Output, Pull, Speed};
use embassy_stm32::i2c::{self, I2c};
use embassy_stm32::peripherals::USB_OTG_FS;
use embassy_stm32::time::Hertz;
use embassy_stm32::usb::Driver;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, dma, interrupt, peripherals, usb};
use embassy_usb::class::cdc_acm::{CdcAcmClass, State};
use embassy_usb::{Builder, UsbDevice};
use static_cell::StaticCell;
use tangent_core::pipeline::Workspace;

use super::devices::BLOCK_WORDS;
use super::devices::{
    Button, EmbassyClock, FlashModes, FlashStore, GpioLasers, Iwdg, ModeSector, Mt9v034Dcmi,
    SharedI2c1, UsbLink, H743,
};
use super::{FRAME_BYTES, POINTS, USB_PID, USB_VID, WATCHDOG_US};
use crate::adxl355::Adxl355;
use crate::app::Buffers;
use crate::buffers::FrameBuffer;
use crate::ports::AccelError;
use crate::ports::Devices;
use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_embedded_hal::shared_bus::asynch::i2c::I2cDevice;
use embassy_sync::mutex::Mutex;

bind_interrupts!(struct Irqs {
    OTG_FS => usb::InterruptHandler<peripherals::USB_OTG_FS>;
    DCMI => dcmi::InterruptHandler<peripherals::DCMI>;
    DMA1_STREAM0 => dma::InterruptHandler<peripherals::DMA1_CH0>;
    DMA1_STREAM1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
});

// The laser-off frame (752 × 480, turned into the difference in place) in AXI SRAM (DMA1
// cannot reach DTCM), with the DMA's line blocks (below); the run tables and the per-point
// buffers in SRAM1–3; the object features in DTCM (.bss: CPU-only, which the pipeline is).
// No stored frame pair for raw captures. See `memory.x` and `docs/hardware.md`, "Memory map".
crate::buffers::board_buffers! {
    off_bytes = 0, on_bytes = 0, diff_bytes = FRAME_BYTES, points = POINTS;
    #[link_section = ".axisram"] off;
    #[link_section = ".axisram"] on;
    #[link_section = ".axisram"] diff;
    #[link_section = ".sram123"] runs;
    #[link_section = ".sram123"] small;
    objects;
    #[link_section = ".sram4"] readout;
    #[link_section = ".axisram"] faint;
}

/// The clock tree: 64 MHz HSI → PLL1 (÷4 × 60 ÷ 2): 480 MHz core at voltage scale 0 (the
/// STM32H743's rated maximum, revision V silicon; embassy raises VOS1 → VOS0 through the
/// SYSCFG over-drive), 240 MHz AHB (DCMI kernel clock ≥ 2.5 × 26.66 MHz PIXCLK), APB 120 MHz,
/// HSI48 trimmed from USB SOF for the OTG FS.
pub fn clock_tree() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.hsi = Some(HSIPrescaler::DIV1);
    config.rcc.csi = true;
    config.rcc.hsi48 = Some(Hsi48Config {
        sync_from_usb: true,
    });
    config.rcc.pll1 = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL60,
        fracn: None,
        divp: Some(PllDiv::DIV2),
        divq: None,
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV2;
    config.rcc.apb1_pre = APBPrescaler::DIV2;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config.rcc.apb3_pre = APBPrescaler::DIV2;
    config.rcc.apb4_pre = APBPrescaler::DIV2;
    config.rcc.voltage_scale = VoltageScale::Scale0;
    config.rcc.mux.usbsel = mux::Usbsel::HSI48;
    config
}

/// The started board: what the application runs on, and the USB stack to run beside it.
pub struct Started {
    /// The devices.
    pub devices: Devices<H743>,
    /// The USB device (run it concurrently with the application).
    pub usb: UsbDevice<'static, Driver<'static, USB_OTG_FS>>,
    /// The application's buffers.
    pub buffers: Buffers<'static>,
    /// The pipeline's working memory.
    pub workspace: Workspace<'static, u8>,
}

/// Brings the board up (once: the peripherals can be taken only once): clocks, the lasers
/// off before anything that can fail, the watchdog, the camera, trigger, flash, USB and the
/// buffers.
pub async fn start() -> Started {
    let p = embassy_stm32::init(clock_tree());

    // Lasers first: driven low before anything else can fail.
    let lasers = GpioLasers::new([
        Output::new(p.PE2, Level::Low, Speed::Low),
        Output::new(p.PE3, Level::Low, Speed::Low),
        // The walls' crossing line (docs/hardware.md).
        Output::new(p.PE7, Level::Low, Speed::Low),
    ]);
    defmt::info!("Tangent firmware {} (H743)", crate::VERSION);

    let mut wdg = IndependentWatchdog::new(p.IWDG1, WATCHDOG_US);
    wdg.pet();

    // I2C1 (PB8 SCL, PB9 SDA): the camera's set-up and the accelerometer, shared.
    let mut i2c_config = i2c::Config::default();
    i2c_config.frequency = Hertz(400_000);
    static I2C1: StaticCell<SharedI2c1> = StaticCell::new();
    let i2c1: &'static SharedI2c1 = I2C1.init(Mutex::new(BlockingAsync::new(I2c::new_blocking(
        p.I2C1, p.PB8, p.PB9, i2c_config,
    ))));
    // Camera: DCMI 8-bit on D9..D2 of the sensor.
    let mut dcmi_config = dcmi::Config::default();
    dcmi_config.pixclk_polarity = dcmi::PixelClockPolarity::RisingEdge;
    dcmi_config.vsync_level = dcmi::VSyncDataInvalidLevel::Low;
    dcmi_config.hsync_level = dcmi::HSyncDataInvalidLevel::Low;
    let dcmi = Dcmi::new_8bit(
        p.DCMI,
        p.DMA1_CH0,
        Irqs,
        p.PC6,
        p.PC7,
        p.PE0,
        p.PE1,
        p.PE4,
        p.PD3,
        p.PE5,
        p.PE6,
        p.PB7,
        p.PA4,
        p.PA6,
        dcmi_config,
    );
    // The line blocks: a circular DMA on DMA1 stream 1 with the DCMI's request, into two
    // blocks in AXI SRAM (DMA-reachable), and the block the pipeline reads.
    #[link_section = ".axisram"]
    static mut RING: FrameBuffer<{ 8 * BLOCK_WORDS }> = FrameBuffer([0; 8 * BLOCK_WORDS]);
    #[link_section = ".axisram"]
    static mut BLOCK: [u32; BLOCK_WORDS] = [0; BLOCK_WORDS];
    let request = dcmi::FrameDma::<peripherals::DCMI>::request(&*p.DMA1_CH1);
    // SAFETY: `start` runs once (the peripherals can be taken only once), so these are the
    // only references to the statics; NOLOAD sections are zeroed in place first. The ring
    // reads the DCMI's data register, a valid peripheral address for the DMA.
    let (ring, block) = unsafe {
        core::ptr::write_bytes(addr_of_mut!(RING), 0, 1);
        core::ptr::write_bytes(addr_of_mut!(BLOCK), 0, 1);
        let ring_bytes: &'static mut [u8; 8 * BLOCK_WORDS] = &mut (*addr_of_mut!(RING)).0;
        let words: &'static mut [u32] = bytemuck::cast_slice_mut(&mut ring_bytes[..]);
        let ring = ReadableRingBuffer::new(
            dma::Channel::new(p.DMA1_CH1, Irqs),
            request,
            embassy_stm32::pac::DCMI.dr().as_ptr() as *mut u32,
            words,
            dma::TransferOptions::default(),
        );
        (ring, &mut *addr_of_mut!(BLOCK))
    };
    let exposure_pin = Output::new(p.PD12, Level::Low, Speed::High);
    let camera = Mt9v034Dcmi::new(I2cDevice::new(i2c1), dcmi, ring, block, exposure_pin).await;
    // The accelerometer (the wall's vertical): the device measures without it when none
    // answers (every wall reading then says so).
    let mut accelerometer = Adxl355::new(I2cDevice::new(i2c1));
    match accelerometer.init().await {
        Ok(()) => defmt::info!("ADXL355 accelerometer set up"),
        Err(AccelError::Absent) => {
            defmt::info!("no accelerometer answers on I2C1: wall readings without the plumb")
        }
        Err(e) => defmt::warn!("ADXL355 set-up failed: code {}", e.code()),
    }

    let trigger = Button::new(ExtiInput::new(p.PC13, p.EXTI13, Pull::Down, Irqs));
    // One flash driver for the calibration's sector and the mode log's.
    static FLASH: StaticCell<RefCell<Flash<'static, Blocking>>> = StaticCell::new();
    let flash: &'static RefCell<_> = FLASH.init(RefCell::new(Flash::new_blocking(p.FLASH)));
    let store = FlashStore::new(flash);
    let modes = FlashModes::new(ModeSector::new(flash));

    // USB CDC-ACM.
    static EP_OUT: StaticCell<[u8; 256]> = StaticCell::new();
    static CONFIG_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL: StaticCell<[u8; 64]> = StaticCell::new();
    static CDC_STATE: StaticCell<State> = StaticCell::new();
    let mut usb_config = usb::Config::default();
    // Bus-powered from the host: no VBUS sensing needed.
    usb_config.vbus_detection = false;
    let driver = usb::Driver::new_fs(
        p.USB_OTG_FS,
        Irqs,
        p.PA12,
        p.PA11,
        EP_OUT.init([0; 256]),
        usb_config,
    );
    let mut dev_config = embassy_usb::Config::new(USB_VID, USB_PID);
    dev_config.manufacturer = Some("Tangent");
    dev_config.product = Some("Tangent caliper");
    dev_config.serial_number = Some("H743-0001");
    let mut builder = Builder::new(
        driver,
        dev_config,
        CONFIG_DESC.init([0; 256]),
        BOS_DESC.init([0; 256]),
        &mut [],
        CONTROL.init([0; 64]),
    );
    let class = CdcAcmClass::new(&mut builder, CDC_STATE.init(State::new()), 64);
    let usb = builder.build();

    let Some((buffers, workspace)) = take_buffers(FRAME_BYTES) else {
        defmt::panic!("the H743 board is started once");
    };
    let devices = Devices {
        camera,
        laser: lasers,
        trigger,
        link: UsbLink::new(class),
        clock: EmbassyClock,
        store,
        modes,
        watchdog: Iwdg::start(wdg),
        accelerometer,
    };
    Started {
        devices,
        usb,
        buffers,
        workspace,
    }
}
