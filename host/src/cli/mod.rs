//! One module per `tangent` subcommand. Each exposes an `Args` struct (clap) and
//! `run(args) -> anyhow::Result<ExitCode>`.

pub mod accuracy;
pub mod calib;
pub mod calibrate;
pub mod devices;
pub mod evaluate;
pub mod flash;
pub mod inspect;
pub mod listen;
pub mod log;
pub mod measure;
pub mod record;
pub mod simulate;
pub mod study;
