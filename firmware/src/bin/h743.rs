//! Tangent firmware on the STM32H743 + MT9V034 (see `docs/firmware.md`, `docs/hardware.md`).
//! `cargo run --release` in `firmware/` flashes it through probe-rs and shows the defmt log.
//! The board (clocks, pins, USB, buffers) is `tangent_firmware::board::h743`.
#![no_std]
#![no_main]

use defmt_rtt as _;
use embassy_executor::Spawner;
use panic_probe as _;
use tangent_firmware::app::App;
use tangent_firmware::board::h743;
use tangent_firmware::measure::PipelineMeasurer;

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let mut board = h743::start().await;
    let measurer = PipelineMeasurer::new(board.workspace);
    let mut app = App::new(board.devices, measurer, board.buffers);
    embassy_futures::join::join(board.usb.run(), app.run()).await;
}
