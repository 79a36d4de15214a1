//! `tangent log export`: the field log as inventory software imports it.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use tangent_host::fieldlog::{self, ExportFormat, FieldLog, Record};

/// Arguments of `tangent log`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Export the log: per plot a header block (plot id, start, note, tree count), then one
    /// row per tree (tree_id, species, dbh_mm, uncertainty_mm, tilt_deg, flags, time,
    /// device_id, calib_id, seq, plot_id). TSV suits Field-Map's calliper import and Haglöf
    /// software (set "lines to skip" to 5); JSON nests trees in plots.
    Export(ExportArgs),
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum Format {
    Csv,
    Tsv,
    Json,
}

/// Arguments of `tangent log export`.
#[derive(clap::Args, Debug)]
struct ExportArgs {
    /// Output format.
    #[arg(long, value_enum)]
    format: Format,
    /// The field log.
    #[arg(long, default_value = "tangent-field.log")]
    log: PathBuf,
    /// Only this plot.
    #[arg(long)]
    plot_id: Option<String>,
    /// Write here instead of standard output.
    #[arg(long, short)]
    out: Option<PathBuf>,
}

/// Runs `tangent log …`.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.command {
        Command::Export(a) => export(a),
    }
}

fn export(a: ExportArgs) -> Result<ExitCode> {
    // The error names the file.
    let mut records = FieldLog::read(&a.log).context("cannot read the field log")?;
    if let Some(id) = &a.plot_id {
        records.retain(|r| match r {
            Record::Plot(p) => &p.plot_id == id,
            Record::Tree(t) => &t.plot_id == id,
        });
        if records.is_empty() {
            anyhow::bail!("no plot {id} in {}", a.log.display());
        }
    }
    let format = match a.format {
        Format::Csv => ExportFormat::Csv,
        Format::Tsv => ExportFormat::Tsv,
        Format::Json => ExportFormat::Json,
    };
    let text = fieldlog::export(&records, format);
    match &a.out {
        Some(path) => std::fs::write(path, text)
            .with_context(|| format!("cannot write {}", path.display()))?,
        None => print!("{text}"),
    }
    Ok(ExitCode::SUCCESS)
}
