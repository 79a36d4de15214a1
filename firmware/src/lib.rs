//! Tangent firmware: the portable application and its two boards.
//!
//! * [`ports`] — the application's ports: one trait per device it uses (camera, laser,
//!   trigger, link, clock, calibration store, watchdog);
//! * [`app`] — the state machine over them (trigger → exposures → pipeline → report,
//!   protocol commands);
//! * [`measure`] — the seam to the shared pipeline; [`exposure`], [`stats`], [`pgm`] — small pure pieces, unit-tested on the host
//!   (`cargo test --target x86_64-unknown-linux-gnu --no-default-features --lib`);
//! * `board::h743` (feature `h743`) and `board::qemu` (feature `qemu`): the boards.
//!
//! See `docs/firmware.md`.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

/// The firmware's version (`DeviceInfo::fw_version`).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

pub mod app;
pub mod exposure;
pub mod measure;
pub mod pgm;
pub mod ports;
pub mod stats;

/// The boards (only on the Cortex-M target).
#[cfg(target_os = "none")]
pub mod board;
