//! `tangent measure`: replay captures through the measurement core and print the readings.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use indicatif::{ParallelProgressIterator, ProgressBar, ProgressStyle};
use rayon::prelude::*;
use tangent_core::calibration::Calibration;
use tangent_core::instrument::road::{RoadParams, RoadSolution};
use tangent_core::pipeline::PipelineConfig;
use tangent_core::pipeline::PipelineError;
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::measure::{measure_capture, measure_road_dir, MeasureError, Reading};
use tangent_host::road::section::Section;
use tangent_host::road::{plot::road_png, RoadReport};
use tangent_host::{calibration_file, capture, plot};

/// The long help of `tangent measure` (`main.rs` gives it to clap on the subcommand, where
/// the short doc comment would otherwise replace it).
pub const LONG_ABOUT: &str =
    "Replays recorded captures (a directory with capture.toml and its PGM frames, \
or a directory of such directories) through the same measurement core the device runs, and prints \
per capture the stem diameter in mm with its 1-sigma uncertainty, the method used, the tilt and \
quality flags — or why no trustworthy reading exists. A path that cannot be read is reported \
(with --json as {\"error\": …}) and the other captures are still measured.\n\nExit status: 0 when \
every capture gave a reading, 1 when some gave none (the reason is printed), 2 when a capture, \
a path given, or the --calib file could not be read (or a --plot image not written).";

/// Arguments of `tangent measure`.
#[derive(clap::Args, Debug)]
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
    /// section with the fitted circle (road captures: the profile with its drop-outs, the
    /// filtered profile and each segment's peaks).
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// Accumulate the road captures into one section with this location label and print its
    /// MPD, running count and exclusions (`docs/road.md`, "Ambulatory use").
    #[arg(long, value_name = "LABEL")]
    section: Option<String>,
    /// With --section: store the section's MPD in this field log under its label.
    #[arg(long, value_name = "FILE", requires = "section")]
    log: Option<PathBuf>,
}

/// Runs `tangent measure`: every capture that can be read is measured; the others are
/// reported (exit status in the command's help).
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    // Each argument's captures, or why it names none: a bad argument is reported in its
    // place and does not stop the others.
    let targets: Vec<Result<PathBuf, String>> = args
        .captures
        .iter()
        .flat_map(|arg| match capture::find_captures(arg) {
            Ok(dirs) => dirs.into_iter().map(Ok).collect(),
            Err(e) => vec![Err(format!("{}: {e}", arg.display()))],
        })
        .collect();
    let mut out = std::io::stdout().lock();
    let setup = || -> anyhow::Result<Option<Calibration>> {
        if let Some(dir) = &args.plot {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        // The error names the file.
        Ok(args
            .calib
            .as_deref()
            .map(calibration_file::read)
            .transpose()?)
    };
    let calibration = match setup() {
        Ok(c) => c,
        Err(e) => {
            // Nothing can be measured: one message for the whole run.
            report_unreadable(&mut out, args.json, &super::error_text(&e))?;
            return Ok(ExitCode::from(UNREADABLE));
        }
    };
    let config = PipelineConfig::default();
    let params = CylinderParams::default();
    let bar = if targets.len() > 1 && std::io::stderr().is_terminal() {
        ProgressBar::new(targets.len() as u64).with_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} captures {eta}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        )
    } else {
        ProgressBar::hidden()
    };
    // A road head's height-scale correction travels in its calibration file's `[road]`.
    let mut road_params = RoadParams::default();
    if let Some(path) = &args.calib {
        match calibration_file::read_road(path) {
            Ok(Some(r)) => road_params.profile.height_scale = r.height_scale,
            Ok(None) => {}
            Err(e) => {
                report_unreadable(&mut out, args.json, &e.to_string())?;
                return Ok(ExitCode::from(UNREADABLE));
            }
        }
    }
    let results: Vec<Result<(Reading, Option<RoadResult>), String>> = targets
        .par_iter()
        .progress_with(bar)
        .map(|target| {
            let dir = target.as_ref().map_err(Clone::clone)?;
            // A capture's errors name its files relative to it; put the directory in front.
            let outcome = match measure_capture(dir, calibration.as_ref(), &config, &params) {
                Err(MeasureError::UnsupportedMode(capture::Mode::Road)) => {
                    return measure_road_capture(
                        dir,
                        calibration.as_ref(),
                        &config,
                        &road_params,
                        args.plot.as_deref(),
                    )
                    .map(|(r, s)| (r, Some(s)));
                }
                other => other.map_err(|e| format!("{}: {e}", dir.display()))?,
            };
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
            Ok((outcome.reading, None))
        })
        .collect();
    let mut section = args.section.as_deref().map(Section::new);

    let (mut no_reading, mut unreadable) = (0, 0);
    for r in &results {
        match r {
            Ok((reading, road)) => {
                if let (Some(section), Some(result)) = (section.as_mut(), road) {
                    section.add(result);
                    if !args.json {
                        writeln!(out, "  running: {}", section.summary())?;
                    }
                }
                no_reading += reading.error.is_some() as usize;
                if args.json {
                    writeln!(out, "{}", serde_json::to_string(reading)?)?;
                } else {
                    writeln!(out, "{}: {}", reading.capture, reading.summary())?;
                }
            }
            Err(e) => {
                unreadable += 1;
                report_unreadable(&mut out, args.json, e)?;
            }
        }
    }
    let board_walls = results
        .iter()
        .filter_map(|r| r.as_ref().ok()?.0.wall.as_ref())
        .filter(|w| w.planes_calibration == "board")
        .count();
    if board_walls > 0 && !args.json {
        out.flush()?;
        eprintln!("{}", board_calibration_hint(board_walls));
    }
    if let Some(section) = &section {
        if let Some(path) = &args.log {
            let stored = tangent_host::fieldlog::FieldLog::open(path)
                .and_then(|mut log| {
                    section.log_to(&mut log, calibration.as_ref().map_or(0, |c| c.id))
                })
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            if stored && !args.json {
                eprintln!("stored section {} in {}", section.label, path.display());
            }
        }
        if args.json {
            writeln!(
                out,
                "{}",
                serde_json::json!({ "section": section, "mpd_m": section.mpd() })
            )?;
        } else {
            writeln!(out, "{}", section.summary())?;
        }
    }
    Ok(if unreadable > 0 {
        ExitCode::from(UNREADABLE)
    } else if no_reading > 0 {
        ExitCode::from(NO_READING)
    } else {
        ExitCode::SUCCESS
    })
}

/// What to do about wall readings measured with board-calibrated planes: their σ are honest
/// but carry the board's budget, several degrees on a wall's tilt (`docs/building.md` §4), which
/// refining the planes against each other on a flat wall removes (`docs/calibration.md` §13).
fn board_calibration_hint(walls: usize) -> String {
    format!(
        "note: {walls} wall reading(s) used laser planes calibrated on the board only, so their σ \
         carry the board's calibration budget (a wall's tilt to several degrees). Refine the planes \
         against each other once: `tangent calibrate wall --calib FILE CAPTURES...` on three or \
         more captures of one flat wall at 1–3 m, then measure with `--calib FILE` \
         (docs/calibration.md, section 13)."
    )
}

/// Exit status when some capture gave no reading (and every one was read).
const NO_READING: u8 = 1;
/// Exit status when a path, a capture or the `--calib` file could not be read (or a `--plot`
/// image not written).
const UNREADABLE: u8 = 2;

/// Reports what could not be read: a JSON object `{"error": …}` on standard output with
/// `--json` (one line per capture, like the readings), else `error: …` on standard error.
fn report_unreadable(out: &mut impl Write, json: bool, message: &str) -> std::io::Result<()> {
    if json {
        writeln!(out, "{}", serde_json::json!({ "error": message }))
    } else {
        eprintln!("error: {message}");
        Ok(())
    }
}

/// A road capture's solution, for the section.
type RoadResult = Result<RoadSolution, PipelineError>;

/// Measures a road capture: its reading (and plot), and its solution for the section.
fn measure_road_capture(
    dir: &std::path::Path,
    calibration: Option<&Calibration>,
    config: &PipelineConfig,
    params: &RoadParams,
    plot_dir: Option<&std::path::Path>,
) -> Result<(Reading, RoadResult), String> {
    let name = dir.display().to_string();
    let outcome =
        measure_road_dir(dir, calibration, config, params).map_err(|e| format!("{name}: {e}"))?;
    let reading = Reading::road(
        &name,
        outcome
            .result
            .as_ref()
            .map(|s| RoadReport::new(s, outcome.truth_mpd))
            .map_err(|e| tangent_core::protocol::codes::Failure::of(e).to_string()),
    );
    if let Some(plot_dir) = plot_dir {
        let file = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "capture".into());
        let path = plot_dir.join(format!("{file}.png"));
        road_png(
            &path,
            &outcome,
            params,
            &format!("{file}: {}", reading.summary()),
        )
        .map_err(|e| format!("{}: {e:#}", path.display()))?;
    }
    Ok((reading, outcome.result))
}
