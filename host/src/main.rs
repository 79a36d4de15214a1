//! `tangent`: the command-line companion of the Tangent instrument.

mod cli;

use clap::{Parser, Subcommand};

/// Tangent — non-contact dimensional measurement by laser-plane triangulation.
#[derive(Parser, Debug)]
#[command(name = "tangent", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// One variant per subcommand; each lives in `src/cli/<name>.rs`.
#[derive(Subcommand, Debug)]
enum Command {
    // Each variant: `Name(cli::name::Args)`; keep one per line, alphabetical.
    /// Compute a calibration: camera from chessboard images, laser planes from board captures,
    /// the planes refined against each other on a ball or a flat wall (`calibrate camera`,
    /// `laser`, `ball`, `wall`; also `road`, `accelerometer`).
    Calibrate(cli::calibrate::Args),
    /// The calibration stored on the device: copy a file to it or read it back
    /// (`device-calibration push|pull`).
    DeviceCalibration(cli::device_calibration::Args),
    /// List the serial ports that look like a Tangent.
    Devices(cli::devices::Args),
    /// Serve the field app (the caliper in a browser) on localhost, with a WebSocket
    /// bridge to a serial port or the emulated caliper.
    App(cli::app::Args),
    /// Build the firmware and flash it through probe-rs.
    Flash(cli::flash::Args),
    /// Receive readings from the device, print them and append them to the field log.
    Listen(cli::listen::Args),
    /// The field log (`log export --format csv|tsv|json`).
    Log(cli::log::Args),
    /// Record raw frame pairs from the device as capture directories.
    Record(cli::record::Args),
    /// Plot the error model's predicted diameter error against distance (PNG).
    #[command(long_about = cli::accuracy::LONG_ABOUT)]
    Accuracy(cli::accuracy::Args),
    /// Accuracy against the simulator's truth on fresh random stems (writes docs/accuracy.md).
    #[command(long_about = cli::evaluate::LONG_ABOUT)]
    Evaluate(cli::evaluate::Args),
    /// A PNG of a capture: frames, difference, true and extracted laser curves.
    Inspect(cli::inspect::Args),
    /// Replay captures and print the stem diameter, uncertainty, method, tilt and flags.
    #[command(long_about = cli::measure::LONG_ABOUT)]
    Measure(cli::measure::Args),
    /// Render synthetic captures (one stem, random stems, or the test corpus).
    Simulate(cli::simulate::Args),
    /// Studies that generate the tables in docs/ (e.g. `study subpixel`).
    Study(cli::study::Args),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result: anyhow::Result<std::process::ExitCode> = match cli.command {
        // Each arm: `Command::Name(args) => cli::name::run(args),`
        Command::Calibrate(args) => cli::calibrate::run(args),
        Command::DeviceCalibration(args) => cli::device_calibration::run(args),
        Command::Devices(args) => cli::devices::run(args),
        Command::App(args) => cli::app::run(args),
        Command::Flash(args) => cli::flash::run(args),
        Command::Listen(args) => cli::listen::run(args),
        Command::Log(args) => cli::log::run(args),
        Command::Record(args) => cli::record::run(args),
        Command::Accuracy(args) => cli::accuracy::run(args),
        Command::Evaluate(args) => cli::evaluate::run(args),
        Command::Inspect(args) => cli::inspect::run(args),
        Command::Measure(args) => cli::measure::run(args),
        Command::Simulate(args) => cli::simulate::run(args),
        Command::Study(args) => cli::study::run(args),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {}", cli::error_text(&err));
            std::process::ExitCode::FAILURE
        }
    }
}
