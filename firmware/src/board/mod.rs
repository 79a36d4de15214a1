//! The boards, one module each: what the board is (frame size, clocks, pin map, USB identity,
//! where its buffers live) and its implementations of the application's ports. The binaries
//! (`src/bin/`) only start a board and run the application on it.
//!
//! `h743`'s constants build everywhere (the sensor set-up tests on the host use its window);
//! its drivers need the feature `h743`. `qemu` needs the feature `qemu`.

pub mod h743;
#[cfg(feature = "qemu")]
pub mod qemu;
