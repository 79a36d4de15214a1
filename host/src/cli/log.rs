//! `tangent log export`: the field log as inventory software imports it; `tangent log
//! check`: what a log holds, damage included, without changing it; `tangent log show`: its
//! readings, one a line, with their kind and label.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use tangent_host::fieldlog::{self, ExportFormat, FieldLog, Scan};

/// The exit status of `log export` and `log check` (also in their `--help`).
const EXIT_STATUS: &str = "Exit status: 0 the log is intact; 1 it could not be read; 2 bad \
arguments; 3 some bytes are not readable records — each is named by line and byte range (export \
also appends them to <log>.damaged) and every readable record is exported; 4 every record was \
read, but the log needed care: a reading found twice (exported once), a plot header lost (its \
trees are kept), CR LF line ends, a byte-order mark, a damaged first line or a lost newline.";

/// The log could not all be read as records.
const EXIT_DAMAGED: u8 = 3;
/// Every record was read, with findings.
const EXIT_TOLERATED: u8 = 4;

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
    /// device_id, calib_id, seq, plot_id, kind, label). TSV suits Field-Map's calliper import and Haglöf
    /// software (set "lines to skip" to 5); JSON nests trees in plots.
    #[command(after_help = EXIT_STATUS)]
    Export(ExportArgs),
    /// Say what is in a log without changing it: plots, trees, damaged lines (line numbers
    /// and byte ranges), readings found twice, a torn tail.
    #[command(after_help = EXIT_STATUS)]
    Check(CheckArgs),
    /// List the readings, one a line: plot, number, kind (stem, sphere, wall, …), value
    /// (mm) ± σ, species, flags, time and the user's label.
    #[command(after_help = EXIT_STATUS)]
    Show(ShowArgs),
}

/// Arguments of `tangent log show`.
#[derive(clap::Args, Debug)]
struct ShowArgs {
    /// The field log.
    #[arg(long, default_value = "tangent-field.log")]
    log: PathBuf,
    /// Only this plot.
    #[arg(long)]
    plot_id: Option<String>,
    /// Only readings of this kind (`stem`, `sphere`, `wall`, `road`, `road_section`).
    #[arg(long)]
    kind: Option<String>,
}

/// Arguments of `tangent log check`.
#[derive(clap::Args, Debug)]
struct CheckArgs {
    /// The field log.
    #[arg(long, default_value = "tangent-field.log")]
    log: PathBuf,
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
        Command::Check(a) => check(a),
        Command::Show(a) => show(a),
    }
}

fn show(a: ShowArgs) -> Result<ExitCode> {
    let scan = FieldLog::scan_file(&a.log)
        .with_context(|| format!("cannot read the field log {}", a.log.display()))?;
    for finding in scan.findings() {
        eprintln!("warning: {}: {finding}", a.log.display());
    }
    let records = match &a.plot_id {
        Some(id) => {
            let selected = fieldlog::select_plot(&scan.records(), id);
            if selected.is_empty() {
                anyhow::bail!("{}: no plot {id}", a.log.display());
            }
            selected
        }
        None => scan.records(),
    };
    for p in fieldlog::plots(&records) {
        for t in p.trees {
            if a.kind.as_deref().is_some_and(|k| k != t.kind) {
                continue;
            }
            println!("{}", fieldlog::reading_line(t));
        }
    }
    Ok(exit_code(&scan))
}

/// The exit status for what a scan found.
fn exit_code(scan: &Scan) -> ExitCode {
    if !scan.damaged.is_empty() {
        ExitCode::from(EXIT_DAMAGED)
    } else if !scan.is_clean() {
        ExitCode::from(EXIT_TOLERATED)
    } else {
        ExitCode::SUCCESS
    }
}

fn check(a: CheckArgs) -> Result<ExitCode> {
    let scan = FieldLog::scan_file(&a.log)
        .with_context(|| format!("cannot read the field log {}", a.log.display()))?;
    let records = scan.records();
    let plots = fieldlog::plots(&records);
    let trees: usize = plots.iter().map(|p| p.trees.len()).sum();
    println!(
        "{}: {} plot(s), {trees} tree(s)",
        a.log.display(),
        plots.len()
    );
    for p in &plots {
        let started = if p.header_lost {
            "header lost".to_string()
        } else {
            format!("started {}", p.started)
        };
        println!("  plot {}: {} tree(s), {started}", p.plot_id, p.trees.len());
    }
    let torn: usize = scan.torn_tail().iter().map(|d| d.end - d.start).sum();
    let mut lines: Vec<usize> = scan.damaged_inside().iter().map(|d| d.line).collect();
    lines.dedup();
    println!(
        "damaged lines: {}; readings found twice: {}; torn tail: {torn} byte(s)",
        lines.len(),
        scan.duplicates.len()
    );
    for finding in scan.findings() {
        println!("  {finding}");
    }
    if scan.is_clean() {
        println!("the log is intact");
    }
    Ok(exit_code(&scan))
}

fn export(a: ExportArgs) -> Result<ExitCode> {
    let bytes = std::fs::read(&a.log)
        .with_context(|| format!("cannot read the field log {}", a.log.display()))?;
    let scan = FieldLog::scan_bytes(&a.log, &bytes)?;
    report_damage(&a.log, &bytes, &scan);
    let format = match a.format {
        Format::Csv => ExportFormat::Csv,
        Format::Tsv => ExportFormat::Tsv,
        Format::Json => ExportFormat::Json,
    };
    let text = fieldlog::export_records(&scan.records(), a.plot_id.as_deref(), format)
        .with_context(|| format!("{}", a.log.display()))?;
    match &a.out {
        Some(path) => std::fs::write(path, text)
            .with_context(|| format!("cannot write {}", path.display()))?,
        None => print!("{text}"),
    }
    Ok(exit_code(&scan))
}

/// Names every finding on standard error and saves the unreadable bytes next to the log.
fn report_damage(log: &std::path::Path, bytes: &[u8], scan: &Scan) {
    for finding in scan.findings() {
        eprintln!("warning: {}: {finding}", log.display());
    }
    if scan.damaged.is_empty() {
        return;
    }
    let side = fieldlog::side_path(log, "damaged");
    match fieldlog::save_damaged(log, bytes, &scan.damaged) {
        Ok(n) => eprintln!(
            "warning: {} unreadable span(s) in {}; their raw bytes are in {} ({n} newly saved); \
             every readable record is exported",
            scan.damaged.len(),
            log.display(),
            side.display()
        ),
        Err(e) => eprintln!("warning: could not save the unreadable bytes: {e}"),
    }
}
