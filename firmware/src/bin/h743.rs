//! Tangent firmware on the STM32H743 + MT9V034 (see `docs/firmware.md`, `docs/hardware.md`).
//! `cargo run --release` in `firmware/` flashes it through probe-rs and shows the defmt log.
#![no_std]
#![no_main]

use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::dcmi::{self, Dcmi};
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::flash::Flash;
use embassy_stm32::gpio::{Level, Output, Pull, Speed};
use embassy_stm32::i2c::{self, I2c};
use embassy_stm32::time::Hertz;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, dma, interrupt, peripherals, usb, Config};
use embassy_usb::class::cdc_acm::{CdcAcmClass, State};
use embassy_usb::Builder;
use panic_probe as _;
use static_cell::StaticCell;
use tangent_core::protocol::codes;
use tangent_firmware::app::{App, Buffers};
use tangent_firmware::board::h743::{
    Button, EmbassyClock, FlashStore, GpioLasers, Iwdg, Mt9v034, UsbLink, FRAME_BYTES, H743,
};
use tangent_firmware::hal::Devices;
use tangent_firmware::measure::{self, PipelineMeasurer, SmallBuffers};

bind_interrupts!(struct Irqs {
    OTG_FS => usb::InterruptHandler<peripherals::USB_OTG_FS>;
    DCMI => dcmi::InterruptHandler<peripherals::DCMI>;
    DMA1_STREAM0 => dma::InterruptHandler<peripherals::DMA1_CH0>;
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
});

/// Watchdog timeout: the main loop feeds it at least every 100 ms when idle and between
/// measurements (one measurement takes < 100 ms).
const WATCHDOG_US: u32 = 2_000_000;

/// The two frame buffers, in AXI SRAM (DMA1 cannot reach DTCM). Words, for the DCMI DMA.
#[link_section = ".axisram"]
static mut FRAMES: [[u32; FRAME_BYTES / 4]; 2] = [[0; FRAME_BYTES / 4]; 2];
/// Pipeline difference frame (AXI SRAM).
#[link_section = ".axisram"]
static mut DIFF: [u8; FRAME_BYTES] = [0; FRAME_BYTES];
/// Pipeline labels (SRAM1–3: 240,640 of its 294,912 bytes).
#[link_section = ".sram123"]
static mut LABELS: [u16; FRAME_BYTES] = [0; FRAME_BYTES];
/// Curve/point entries for 752 columns and two planes.
const POINTS: usize = measure::points_for(752, 2);
/// The pipeline's point and table buffers (AXI SRAM, after the frames).
#[link_section = ".axisram"]
static mut SMALL: SmallBuffers<POINTS> = SmallBuffers::new();
/// The pipeline's object features (DTCM: CPU-only, which the pipeline is).
static mut OBJECTS: measure::Objects = measure::NO_OBJECTS;

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let mut config = Config::default();
    {
        use embassy_stm32::rcc::*;
        // 64 MHz HSI → PLL1: 400 MHz core (voltage scale 1), 200 MHz AHB (DCMI kernel
        // clock ≥ 2.5 × 26.66 MHz PIXCLK), HSI48 trimmed from USB SOF for the OTG FS.
        config.rcc.hsi = Some(HSIPrescaler::DIV1);
        config.rcc.csi = true;
        config.rcc.hsi48 = Some(Hsi48Config {
            sync_from_usb: true,
        });
        config.rcc.pll1 = Some(Pll {
            source: PllSource::HSI,
            prediv: PllPreDiv::DIV4,
            mul: PllMul::MUL50,
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
        config.rcc.voltage_scale = VoltageScale::Scale1;
        config.rcc.mux.usbsel = mux::Usbsel::HSI48;
    }
    let p = embassy_stm32::init(config);

    // Lasers first: driven low before anything else can fail.
    let lasers = GpioLasers::new([
        Output::new(p.PE2, Level::Low, Speed::Low),
        Output::new(p.PE3, Level::Low, Speed::Low),
    ]);
    defmt::info!("Tangent firmware {} (H743)", env!("CARGO_PKG_VERSION"));

    let mut wdg = IndependentWatchdog::new(p.IWDG1, WATCHDOG_US);
    wdg.pet();

    // Camera: I2C1 (PB8 SCL, PB9 SDA) for set-up, DCMI 8-bit on D9..D2 of the sensor.
    let mut i2c_config = i2c::Config::default();
    i2c_config.frequency = Hertz(400_000);
    let i2c = I2c::new_blocking(p.I2C1, p.PB8, p.PB9, i2c_config);
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
    let exposure_pin = Output::new(p.PD12, Level::Low, Speed::High);
    let camera = Mt9v034::new(i2c, dcmi, exposure_pin);

    let trigger = Button::new(ExtiInput::new(p.PC13, p.EXTI13, Pull::Down, Irqs));
    let store = FlashStore::new(Flash::new_blocking(p.FLASH));

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
    let mut dev_config = embassy_usb::Config::new(codes::USB_VID, codes::USB_PID);
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
    let mut usb_dev = builder.build();

    // The .axisram/.sram123 sections are NOLOAD (not initialised by the reset handler):
    // zero them in place (all-zero bytes are a valid value of every buffer type) before
    // taking references, without building the ~190 KB values on the DTCM stack.
    // SAFETY: `main` runs once; these statics are borrowed only here, for the program's life.
    let (frames, diff, labels, small) = unsafe {
        core::ptr::write_bytes(core::ptr::addr_of_mut!(FRAMES), 0, 1);
        core::ptr::write_bytes(core::ptr::addr_of_mut!(DIFF), 0, 1);
        core::ptr::write_bytes(core::ptr::addr_of_mut!(LABELS), 0, 1);
        core::ptr::write_bytes(core::ptr::addr_of_mut!(SMALL), 0, 1);
        (
            &mut *core::ptr::addr_of_mut!(FRAMES),
            &mut *core::ptr::addr_of_mut!(DIFF),
            &mut *core::ptr::addr_of_mut!(LABELS),
            &mut *core::ptr::addr_of_mut!(SMALL),
        )
    };
    let [off, on] = frames;
    static RX: StaticCell<[u8; tangent_core::protocol::MAX_FRAME_LEN]> = StaticCell::new();
    let buffers = Buffers {
        off: bytemuck::cast_slice_mut(off.as_mut_slice()),
        on: bytemuck::cast_slice_mut(on.as_mut_slice()),
        rx: RX.init([0; tangent_core::protocol::MAX_FRAME_LEN]),
    };
    let dev = Devices::<H743> {
        camera,
        laser: lasers,
        trigger,
        link: UsbLink::new(class),
        clock: EmbassyClock,
        store,
        watchdog: Iwdg::start(wdg),
    };
    // SAFETY: as above; OBJECTS is in .bss (zeroed by the reset handler).
    let objects = unsafe { &mut *core::ptr::addr_of_mut!(OBJECTS) };
    let measurer = PipelineMeasurer::new(measure::workspace(diff, labels, objects, small));
    let mut app = App::new(dev, measurer, buffers);
    embassy_futures::join::join(usb_dev.run(), app.run()).await;
}
