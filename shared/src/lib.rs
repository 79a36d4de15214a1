//! # tangent-core
//!
//! The measurement core of Tangent, a handheld laser-plane triangulation instrument. It is
//! `no_std` and allocation-free: every buffer is owned by the caller (as in smoltcp), and every
//! fallible step returns a typed error instead of panicking on bad data.
//!
//! Modules follow the measurement chain, one chapter of the method each (see `docs/`):
//!
//! | chain step | module | derivation |
//! |---|---|---|
//! | scalar type | [`real`] | – |
//! | camera model | [`camera`] | `docs/camera-model.md` |
//! | laser planes, triangulation | [`laser_plane`] | `docs/laser-plane.md` |
//! | calibration set | [`calibration`] | `docs/formats.md` |
//! | accelerometer bias and alignment to the camera | [`accelerometer`] | `docs/hardware.md` |
//! | frames, subtraction, thresholds, segmentation | [`image`] | `docs/image-processing.md` |
//! | subpixel peak estimators | [`peaks`] | `docs/subpixel.md` |
//! | laser-curve extraction and smoothing | [`curve`] | `docs/subpixel.md` §8 |
//! | noise of one point (stripe, speckle, calibration) | [`noise`] | `docs/error-model.md` |
//! | solvers per object kind | [`solvers`] | `docs/cylinder.md`, … |
//! | predicted uncertainty of a reading | [`error_model`] | `docs/error-model.md` |
//! | one reading of any instrument | [`measurement`] | `docs/architecture.md` |
//! | device ↔ host wire protocol | [`protocol`] | `docs/protocol.md` |
//! | the image chain, frame pair → 3-D points per plane | [`pipeline`] | `docs/pipeline.md` |
//! | instruments: points → one [`Measurement`] per capture mode | [`instrument`] | `docs/pipeline.md` |
//!
//! The handful of types a library user needs are re-exported here: a [`Frame`] pair and a
//! [`Calibration`] in, working memory from [`Buffers`] (static) or `OwnedBuffers` (heap,
//! feature `alloc`), [`measure`] with the capture's [`Mode`], one [`Measurement`] or a
//! [`PipelineError`] out. `examples/measure_pair.rs` shows it end to end.
#![no_std]
#![deny(missing_docs)]
// No unsafe code, except three single instructions of the Cortex-M7 (feature `cortex-m7`, ARM
// only: `image::lanes`, `real::sqrt`), which allow it locally: inline assembly is the stable
// way to reach them.
#![deny(unsafe_code)]
// `x as Real` is a no-op in the default f64 build but a real conversion with `f32`: the casts
// stay so that one source serves both precisions.
#![allow(clippy::unnecessary_cast)]

#[cfg(feature = "std")]
extern crate std;

pub mod accelerometer;
pub mod calibration;
pub mod camera;
pub mod curve;
pub mod error_model;
pub mod image;
pub mod instrument;
pub mod laser_plane;
pub mod measurement;
pub mod noise;
pub mod peaks;
pub mod pipeline;
pub mod protocol;
pub mod real;
pub mod solvers;

pub use calibration::Calibration;
pub use image::Frame;
pub use instrument::{measure, InstrumentParams};
pub use measurement::{Measurement, Mode};
#[cfg(any(test, feature = "alloc"))]
pub use pipeline::OwnedBuffers;
pub use pipeline::{Buffers, PipelineConfig, PipelineError, Workspace};
