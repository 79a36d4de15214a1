//! # tangent-host
//!
//! The `std` companion of the Tangent instrument: capture files, the capture simulator,
//! replay and measurement of recorded captures, calibration, the device link and the field
//! log. The `tangent` binary is a thin CLI over these modules (one file per subcommand in
//! `src/cli/`).
#![deny(missing_docs)]

pub mod baseline;
pub mod bridge;
pub mod calibrate;
pub mod calibration_bounds;
pub mod calibration_draw;
pub mod calibration_file;
pub mod capture;
pub mod emulator;
pub mod evaluate;
pub mod evaluate_road;
pub mod evaluate_sphere;
pub mod evaluate_walls;
pub mod fieldlog;
pub mod link;
pub mod measure;
pub mod measure_wall;
pub mod pgm;
pub mod plot;
pub mod road;
pub mod simulate;
pub mod study;
pub mod truth;
