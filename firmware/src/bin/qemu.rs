//! Tangent firmware on the emulated board (QEMU mps2-an500). See `qemu/run.sh` and
//! `docs/firmware.md`; the board (command line, frame files, UART, buffers) is
//! `tangent_firmware::board::qemu`.
//!
//! Runs the same application as the H743 on a busy-polling executor
//! (`embassy_futures::block_on`: every future is polled in a loop, which costs nothing
//! under emulation and needs no interrupt-driven time driver). With `--bench` it measures
//! every frame pair once, prints the pipeline's instruction counts — the work on the
//! laser-on rows as they arrive, and the work after the last pixel, per stage (run QEMU with
//! `-icount shift=0`) — and exits instead of serving the link.
#![no_std]
#![no_main]

use core::panic::PanicInfo;

use cortex_m_rt::{entry, exception};
use tangent_firmware::app::App;
use tangent_firmware::board::qemu::{self, Qemu};
use tangent_firmware::measure::PipelineMeasurer;

#[exception]
fn SysTick() {
    qemu::on_systick();
}

#[entry]
fn main() -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        qemu::exit(false)
    };
    let board = qemu::start(cp.SYST);
    let mut measurer = PipelineMeasurer::new(board.workspace);
    if board.bench {
        measurer.stage_clock = Some(|| qemu::ticks() * 1_000_000 / qemu::SYSCLK_HZ);
    }
    let scenes = board.devices.camera.scene_count();
    let mut app = App::new(board.devices, measurer, board.buffers);
    if board.bench {
        bench(&mut app, scenes)
    } else {
        embassy_futures::block_on(app.run())
    }
}

/// Measures each of the `scenes` frame pairs once, prints the instruction counts, exits.
fn bench(app: &mut App<'_, Qemu<'static>, PipelineMeasurer<'_>>, scenes: usize) -> ! {
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
    // One pair per reading: the counts are those of one frame pair (a stem reading of K
    // pairs costs K of them and the combination, `docs/performance.md`).
    let mut ok = app.set_exposures(1).is_ok();
    embassy_futures::block_on(async {
        for i in 0..scenes {
            match app.measure_once().await {
                Ok(r) => {
                    let m = r.measurement;
                    qemu::log(format_args!(
                        "bench scene={} readout_us={} readout_block_max_us={} pipeline_us={} stages_us={:?} solver_us={} diameter_m={} uncertainty_m={} method={:?} flags={:#x}",
                        i,
                        app.measurer().last_stages.readout_us,
                        app.measurer().last_stages.readout_block_max_us,
                        app.last_pipeline_us,
                        app.measurer().last_stages.image_us,
                        app.measurer().last_stages.solver_us,
                        m.value(),
                        m.uncertainty(),
                        m.method(),
                        m.flags().0
                    ))
                }
                Err(e) => {
                    ok = false;
                    qemu::log(format_args!(
                        "bench scene={} readout_us={} readout_block_max_us={} pipeline_us={} error={:?} detail={}",
                        i,
                        app.measurer().last_stages.readout_us,
                        app.measurer().last_stages.readout_block_max_us,
                        app.last_pipeline_us,
                        e.code,
                        e.detail
                    ))
                }
            }
        }
        qemu::exit(ok)
    })
}

#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    // The lasers of this board are a RAM bitmask; nothing to switch off. Report and stop.
    qemu::log(format_args!("panic: {}", info));
    qemu::exit(false)
}
