//! `tangent measure`: replay captures through the measurement core and print the readings.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use indicatif::{ParallelProgressIterator, ProgressBar, ProgressStyle};
use rayon::prelude::*;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::calibration_file;
use tangent_host::measure::{expand_captures, measure_capture, Reading};
use tangent_host::plot;

/// Arguments of `tangent measure`.
#[derive(clap::Args, Debug)]
#[command(
    long_about = "Replays recorded captures (a directory with capture.toml and its PGM frames, \
or a directory of such directories) through the same measurement core the device runs, and prints \
per capture the stem diameter in mm with its 1-sigma uncertainty, the method used, the tilt and \
quality flags — or why no trustworthy reading exists.\n\nExit status: 0 when every capture gave a \
reading, 1 when some gave none (the reason is printed), 2 when a capture could not be read."
)]
pub struct Args {
    /// Capture directories (or directories of captures).
    #[arg(required = true)]
    captures: Vec<PathBuf>,
    /// Use this calibration file instead of each capture's own.
    #[arg(long, value_name = "FILE")]
    calib: Option<PathBuf>,
    /// Print one JSON object per capture (keys: capture, diameter_m, uncertainty_m, method,
    /// flags, tilt, error, …) instead of text.
    #[arg(long)]
    json: bool,
    /// Write a PNG per capture into DIR: the difference frame with the extracted curve and the
    /// section with the fitted circle.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
}

/// Runs `tangent measure`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let dirs = expand_captures(&args.captures)?;
    let calibration = match &args.calib {
        Some(path) => Some(
            calibration_file::read(path).with_context(|| format!("reading {}", path.display()))?,
        ),
        None => None,
    };
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let config = PipelineConfig::default();
    let params = CylinderParams::default();
    let bar = if dirs.len() > 1 && std::io::stderr().is_terminal() {
        ProgressBar::new(dirs.len() as u64).with_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} captures {eta}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        )
    } else {
        ProgressBar::hidden()
    };
    let results: Vec<Result<Reading, String>> = dirs
        .par_iter()
        .progress_with(bar)
        .map(|dir| {
            let outcome = measure_capture(dir, calibration.as_ref(), &config, &params)
                .map_err(|e| format!("{}: {e}", dir.display()))?;
            if let Some(plot_dir) = &args.plot {
                let name = dir
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "capture".into());
                let path = plot_dir.join(format!("{name}.png"));
                plot::measurement_png(
                    &path,
                    &outcome,
                    &format!("{name}: {}", outcome.reading.summary()),
                )
                .map_err(|e| format!("{}: {e:#}", path.display()))?;
            }
            Ok(outcome.reading)
        })
        .collect();

    let mut out = std::io::stdout().lock();
    let (mut no_reading, mut unreadable) = (0, 0);
    for r in &results {
        match r {
            Ok(reading) => {
                no_reading += reading.error.is_some() as usize;
                if args.json {
                    writeln!(out, "{}", serde_json::to_string(reading)?)?;
                } else {
                    writeln!(out, "{}: {}", reading.capture, reading.summary())?;
                }
            }
            Err(e) => {
                unreadable += 1;
                if args.json {
                    writeln!(out, "{}", serde_json::json!({ "error": e }))?;
                } else {
                    eprintln!("error: {e}");
                }
            }
        }
    }
    Ok(if unreadable > 0 {
        ExitCode::from(2)
    } else if no_reading > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
