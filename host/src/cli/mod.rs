//! One module per `tangent` subcommand. Each exposes an `Args` struct (clap) and
//! `run(args) -> anyhow::Result<ExitCode>`.

pub mod calibrate;
pub mod accuracy;
pub mod evaluate;
pub mod inspect;
pub mod measure;
pub mod simulate;
pub mod study;
