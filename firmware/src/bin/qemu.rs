//! Tangent firmware on the emulated board (QEMU mps2-an500). See `qemu/run.sh` and
//! `docs/firmware.md`.
//!
//! Runs the same application as the H743 on a busy-polling executor
//! (`embassy_futures::block_on`: every future is polled in a loop, which costs nothing
//! under emulation and needs no interrupt-driven time driver). With `--bench` it measures
//! every frame pair once, prints the pipeline's instruction count (run QEMU with
//! `-icount shift=0`) and exits instead of serving the link.
#![no_std]
#![no_main]

use core::panic::PanicInfo;

use cortex_m_rt::{entry, exception};
use tangent_core::measurement::Measurement;
use tangent_firmware::app::{App, Buffers};
use tangent_firmware::board::qemu::{self, FileCamera, Qemu, QemuClock, QemuLaser, RamStore, Uart};
use tangent_firmware::hal::Devices;
use tangent_firmware::measure::{self, PipelineMeasurer, SmallBuffers};

/// Largest frame the emulated board accepts (752 × 480 8-bit).
const MAX_FRAME: usize = 752 * 480;

static mut OFF: [u8; MAX_FRAME] = [0; MAX_FRAME];
static mut ON: [u8; MAX_FRAME] = [0; MAX_FRAME];
static mut RX: [u8; tangent_core::protocol::MAX_FRAME_LEN] =
    [0; tangent_core::protocol::MAX_FRAME_LEN];
static mut CMDLINE: [u8; 4096] = [0; 4096];
/// Pipeline working memory for a full frame and two planes.
const POINTS: usize = measure::points_for(752, 2);
static mut DIFF: [u8; MAX_FRAME] = [0; MAX_FRAME];
static mut LABELS: [u16; MAX_FRAME] = [0; MAX_FRAME];
static mut SMALL: SmallBuffers<POINTS> = SmallBuffers::new();
static mut OBJECTS: measure::Objects = measure::NO_OBJECTS;

#[exception]
fn SysTick() {
    qemu::on_systick();
}

#[entry]
fn main() -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        qemu::exit(false)
    };
    qemu::start_systick(cp.SYST);

    // SAFETY: `main` runs once; these statics are borrowed only here, for the program's
    // whole life.
    let (off, on, rx, cmdline, diff, labels, small, objects) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(OFF),
            &mut *core::ptr::addr_of_mut!(ON),
            &mut *core::ptr::addr_of_mut!(RX),
            &mut *core::ptr::addr_of_mut!(CMDLINE),
            &mut *core::ptr::addr_of_mut!(DIFF),
            &mut *core::ptr::addr_of_mut!(LABELS),
            &mut *core::ptr::addr_of_mut!(SMALL),
            &mut *core::ptr::addr_of_mut!(OBJECTS),
        )
    };
    let Some(cmdline) = qemu::command_line(cmdline) else {
        qemu::log(format_args!("no semihosting command line"));
        qemu::exit(false)
    };

    let mut calib_path = None;
    let mut bench = false;
    let mut row_offset = 0u16;
    let mut files: heapless::Vec<&str, { 2 * qemu::MAX_SCENES }> = heapless::Vec::new();
    let mut args = cmdline.split_ascii_whitespace();
    // The first word is the program (the -kernel file name).
    let _ = args.next();
    while let Some(a) = args.next() {
        match a {
            "--calib" => calib_path = args.next(),
            "--bench" => bench = true,
            "--window" => match args.next().and_then(|r| r.parse().ok()) {
                Some(r) => row_offset = r,
                None => {
                    qemu::log(format_args!(
                        "--window needs the sensor row of the files' first row"
                    ));
                    qemu::exit(false)
                }
            },
            f => {
                if files.push(f).is_err() {
                    qemu::log(format_args!(
                        "too many frame files (max {})",
                        2 * qemu::MAX_SCENES
                    ));
                    qemu::exit(false)
                }
            }
        }
    }
    let mut scenes = heapless::Vec::new();
    for pair in files.chunks_exact(2) {
        let _ = scenes.push((pair[0], pair[1]));
    }
    if scenes.is_empty() || !files.len().is_multiple_of(2) {
        qemu::log(format_args!(
            "usage: tangent-qemu [--calib FILE] [--bench] [--window ROW] OFF.pgm ON.pgm [OFF.pgm ON.pgm ...]"
        ));
        qemu::exit(false)
    }
    let camera = match FileCamera::new(scenes) {
        Ok(c) => c.with_row_offset(row_offset),
        Err(e) => {
            qemu::log(format_args!("cannot read the first frame: {:?}", e));
            qemu::exit(false)
        }
    };
    let n_scenes = camera.scene_count();
    // The workspace covers the camera's frame size (at most MAX_FRAME pixels).
    let pixels = tangent_firmware::hal::Camera::geometry(&camera)
        .frame_len()
        .min(MAX_FRAME);
    let calibration = match calib_path {
        Some(p) => match qemu::load_calibration(p) {
            Some(c) => Some(c),
            None => {
                qemu::log(format_args!("{}: not a valid calibration record", p));
                qemu::exit(false)
            }
        },
        None => None,
    };

    // SAFETY: UART0 is used by nothing else.
    let link = unsafe { Uart::new(Uart::UART0) };
    let dev = Devices::<Qemu> {
        camera,
        laser: QemuLaser::new(),
        trigger: qemu::NoTrigger,
        link,
        clock: QemuClock,
        store: RamStore::new(calibration),
        watchdog: qemu::NoWatchdog,
    };
    let mut measurer = PipelineMeasurer::new(measure::workspace(
        &mut diff[..pixels],
        &mut labels[..pixels],
        objects,
        small,
    ));
    if bench {
        measurer.stage_clock = Some(|| qemu::ticks() * 1_000_000 / qemu::SYSCLK_HZ);
    }
    let mut app = App::new(dev, measurer, Buffers { off, on, rx });

    if bench {
        // The instruction counter's scale: `asm::delay(n)` runs n + 1 iterations of a
        // two-instruction loop (cortex-m 0.7.10), 40,000,002 instructions here. Under
        // `-icount shift=0` that is 40.000002 ms of virtual time = 1,000,000 SysTick ticks
        // at 25 MHz; the line lets the benchmark check both assumptions.
        let t0 = qemu::ticks();
        cortex_m::asm::delay(20_000_000);
        let t1 = qemu::ticks();
        qemu::log(format_args!(
            "bench calibration instructions=40000002 ticks={} ns_per_tick={}",
            t1 - t0,
            1_000_000_000 / qemu::SYSCLK_HZ
        ));
        embassy_futures::block_on(async {
            let mut ok = true;
            for i in 0..n_scenes {
                match app.measure_once().await {
                    Ok(r) => match r.measurement {
                        Measurement::Stem(stem) => qemu::log(format_args!(
                        "bench scene={} pipeline_us={} stages_us={:?} solver_us={} diameter_m={} uncertainty_m={} method={:?} flags={:#x}",
                        i,
                        app.last_pipeline_us,
                        app.measurer().last_stages.image_us,
                        app.measurer().last_stages.solver_us,
                        stem.diameter,
                        stem.uncertainty,
                        stem.method,
                        stem.flags.0
                    )),
                    },
                    Err(e) => {
                        ok = false;
                        qemu::log(format_args!(
                            "bench scene={} pipeline_us={} error={:?} detail={}",
                            i, app.last_pipeline_us, e.code, e.detail
                        ))
                    }
                }
            }
            qemu::exit(ok)
        })
    } else {
        embassy_futures::block_on(app.run())
    }
}

#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    // The lasers of this board are a RAM bitmask; nothing to switch off. Report and stop.
    qemu::log(format_args!("panic: {}", info));
    qemu::exit(false)
}
