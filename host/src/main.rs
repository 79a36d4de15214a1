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
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result: anyhow::Result<std::process::ExitCode> = match cli.command {
        // Each arm: `Command::Name(args) => cli::name::run(args),`
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
