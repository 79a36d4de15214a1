//! Tangent firmware: the portable application and its two boards.
//!
//! * [`ports`] — the application's ports: one trait per device it uses (camera, laser,
//!   trigger, link, clock, calibration store, mode store, watchdog, accelerometer);
//! * [`app`] — the state machine over them (trigger → exposures → pipeline → report,
//!   protocol commands);
//! * [`measure`] — the seam to the shared pipeline;
//! * [`mode_log`] — the instrument mode remembered across power cycles (an append-only log
//!   in flash words, the [`ports::ModeStore`] of both boards);
//! * [`mt9v034`] — the image sensor's set-up over any `embedded-hal-async` I²C bus;
//! * [`adxl355`] — the accelerometer (the wall instrument's vertical reference) over I²C,
//!   and its register model (the emulated board's part, the driver tests');
//! * [`i2c_target`] — emulated I²C targets on an `embedded-hal-async` bus;
//! * [`exposure`], [`stats`], [`pgm`] — small pure pieces;
//! * [`board`] — the boards: `board::h743` (drivers with feature `h743`) and `board::qemu`
//!   (feature `qemu`), each with its clocks, pins and buffers (one `board_buffers!` per
//!   board).
//!
//! Everything but the boards' drivers builds for the host and is unit-tested there
//! (`cargo test --target x86_64-unknown-linux-gnu --no-default-features --lib`); the host's
//! link tests run [`app::App`] on a test board.
//!
//! See `docs/firmware.md`.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

/// The firmware's version (`DeviceInfo::fw_version`).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

pub mod adxl355;
pub mod app;
pub mod board;
mod buffers;
pub mod exposure;
pub mod i2c_target;
pub mod measure;
pub mod mode_log;
pub mod mt9v034;
pub mod pgm;
pub mod ports;
pub mod stats;

#[cfg(test)]
mod fakes;
