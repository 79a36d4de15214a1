//! One module per `tangent` subcommand. Each exposes an `Args` struct (clap) and
//! `run(args) -> anyhow::Result<ExitCode>`.

pub mod calib;
pub mod calibrate;
pub mod devices;
pub mod flash;
pub mod listen;
pub mod log;
pub mod record;
pub mod accuracy;
pub mod evaluate;
pub mod inspect;
pub mod measure;
pub mod simulate;
pub mod study;
