//! The instrument: STM32H743ZI + MT9V034 on embassy-stm32 (wiring in `docs/hardware.md`).
//!
//! * lasers: push-pull GPIOs, low (off) from the first instructions after the clock set-up;
//! * trigger: EXTI input, debounced by re-reading the level after [`DEBOUNCE_US`];
//! * camera: MT9V034 set up over I²C ([`crate::mt9v034`], register table in
//!   `docs/hardware.md`), snapshot mode started by a pulse on its EXPOSURE pin, frames
//!   received by DCMI + DMA into AXI SRAM. One DMA transfer moves at most 65,535 words
//!   (262,140 bytes), and RAM holds two frames plus the pipeline's per-pixel buffers, so the
//!   sensor reads out a window of [`WINDOW_ROWS`] rows (752 × 160 = 120,320 bytes);
//! * link: USB CDC-ACM (embassy-usb);
//! * calibration: a record in the last flash sector (`protocol::calibration_record`);
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

/// Rows read out per frame. The pipeline's memory is laid out for the whole 480-row frame
/// (`docs/hardware.md`, "Memory map": the laser-off frame stored whole and turned into the
/// difference in place, the laser-on frame streamed); the window remains because this
/// board's camera driver still reads a frame in one DMA transfer (at most 65,535 words), into
/// a stored laser-on window, rather than in double-buffered line blocks. See
/// `docs/hardware.md` for the working range this window covers.
pub const WINDOW_ROWS: u16 = 160;
/// First sensor row of the window: centred on the 480-row sensor.
pub const WINDOW_ROW_OFFSET: u16 = (mt9v034::HEIGHT - WINDOW_ROWS) / 2;
/// The sensor rows read out.
pub const WINDOW: Window = Window {
    first_row: WINDOW_ROW_OFFSET,
    rows: WINDOW_ROWS,
};
/// Frame width: the whole sensor width.
pub const WIDTH: u16 = mt9v034::WIDTH;
/// Bytes of one frame of the read-out window.
pub const FRAME_BYTES: usize = WIDTH as usize * WINDOW_ROWS as usize;
/// Bytes of a whole sensor frame (752 × 480): the laser-off frame the pipeline stores and
/// turns into the difference frame in place (`docs/hardware.md`, "Memory map").
pub const SENSOR_FRAME_BYTES: usize = WIDTH as usize * mt9v034::HEIGHT as usize;
/// Curve/point entries of the pipeline's workspace: every column, two planes.
pub const POINTS: usize = WorkspaceSizes::new(WIDTH as usize, mt9v034::HEIGHT as usize, 8, 2).points;
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
