//! The instrument: STM32H743ZI + MT9V034 on embassy-stm32 (wiring in `docs/hardware.md`).
//!
//! * lasers: push-pull GPIOs, low (off) from the first instructions after the clock set-up;
//! * trigger: EXTI input, debounced by re-reading the level after [`DEBOUNCE_US`];
//! * camera: MT9V034 set up over I²C ([`crate::mt9v034`], register table in
//!   `docs/hardware.md`), snapshot mode started by a pulse on its EXPOSURE pin, frames
//!   received by DCMI + circular DMA in double-buffered line blocks (16 rows) in AXI SRAM:
//!   the laser-off frame is stored whole, the laser-on frame goes through the pipeline block
//!   by block as it is read out, so the whole 752 × 480 frame fits ([`WINDOW_ROWS`]);
//! * link: USB CDC-ACM (embassy-usb);
//! * calibration: a record in the last flash sector (`protocol::calibration_record`);
//! * mode: the mode log ([`crate::mode_log`]) in the sector before it;
//! * watchdog: IWDG1, fed by the application's main loop.
//!
//! What the board is — frame window, clocks, USB identity, buffer sizes — is here and builds
//! everywhere (the sensor set-up tests on the host use the window). The drivers (`devices`)
//! and the bring-up (`start`: clock tree, pin map, USB descriptors, buffers) need the
//! feature `h743`; `src/bin/h743.rs` only starts the board and runs the application.

use crate::mt9v034::{self, Window};
use tangent_core::pipeline::WorkspaceSizes;

#[cfg(feature = "h743")]
mod devices;
#[cfg(feature = "h743")]
mod start;
#[cfg(feature = "h743")]
pub use devices::*;
#[cfg(feature = "h743")]
pub use start::*;

/// Rows read out per frame: the whole sensor. Frames arrive in double-buffered DMA line
/// blocks, so the one-transfer limit (65,535 words) does not apply, and the pipeline keeps
/// one per-pixel buffer (the laser-off frame, turned into the difference in place):
/// `docs/hardware.md`, "Memory map".
pub const WINDOW_ROWS: u16 = mt9v034::HEIGHT;
/// First sensor row of the window.
pub const WINDOW_ROW_OFFSET: u16 = 0;
/// The sensor rows read out.
pub const WINDOW: Window = Window {
    first_row: WINDOW_ROW_OFFSET,
    rows: WINDOW_ROWS,
};
/// Frame width: the whole sensor width.
pub const WIDTH: u16 = mt9v034::WIDTH;
/// Bytes of one frame: the laser-off frame the pipeline stores and turns into the difference
/// frame in place (`docs/hardware.md`, "Memory map").
pub const FRAME_BYTES: usize = WIDTH as usize * WINDOW_ROWS as usize;
/// Curve/point entries of the pipeline's workspace: every column, two planes.
pub const POINTS: usize = WorkspaceSizes::new(WIDTH as usize, WINDOW_ROWS as usize, 8, 2).points;
/// Pixel clock of the sensor module (its own 26.66 MHz oscillator).
pub const PIXCLK_HZ: u64 = 26_660_000;
/// Trigger debounce time (µs): mechanical bounce of a tactile switch lasts < 5 ms.
pub const DEBOUNCE_US: u64 = 10_000;
/// Watchdog timeout (µs): the main loop feeds it at least every 100 ms when idle and between
/// measurements (one measurement takes < 100 ms).
pub const WATCHDOG_US: u32 = 2_000_000;
/// USB vendor and product ids: the device contract's (`tangent devices` looks for them).
pub use tangent_core::protocol::codes::{USB_PID, USB_VID};
/// Offset of the calibration sector from the start of flash (bank 2, sector 7; `memory.x`).
pub const CALIB_OFFSET: u32 = 0x1E_0000;
/// Size of the calibration sector.
pub const CALIB_SECTOR: u32 = 128 * 1024;
/// Offset of the mode log's sector from the start of flash (bank 2, sector 6; `memory.x`).
pub const MODES_OFFSET: u32 = 0x1C_0000;
/// Size of the mode log's sector: 4 096 flash words, one per mode change between erases.
pub const MODES_SECTOR: u32 = 128 * 1024;
