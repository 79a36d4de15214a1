//! `tangent listen`: receive readings as the forester pulls the trigger, print them and
//! append them to the field log (durably, before they are shown).
//!
//! Tree ids count up by one per trigger press (the readings of a held trigger share one
//! id); species and the next tree id can be typed while listening when the session is
//! interactive (a terminal on stdin). Without a terminal nothing is ever prompted, so the
//! command runs unattended (scripts, tests, a data logger).

use std::io::{BufRead, IsTerminal};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::mpsc;
use std::time::Duration;

use anyhow::{Context, Result};
use plotters::prelude::*;
use tangent_core::measurement::{Measurement, Mode};
use tangent_core::protocol::Reading;
use tangent_host::fieldlog::{self, FieldLog, PlotHeader, Record, TreeRecord};
use tangent_host::link::{self, Link, LinkConfig, LinkEvent};

use super::devices::resolve_port;

/// Arguments of `tangent listen`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial port of the Tangent (default: the one `tangent devices` finds).
    #[arg(long)]
    port: Option<String>,
    /// Field log to append to (created if missing).
    #[arg(long, default_value = "tangent-field.log")]
    log: PathBuf,
    /// Plot id: starts this plot in the log if it is not the current one (default: carry on
    /// with the log's current plot, or plot "1" in a new log).
    #[arg(long)]
    plot_id: Option<String>,
    /// Note stored in the plot header when a plot is started.
    #[arg(long, default_value = "")]
    note: String,
    /// Tree id of the next reading (default: one more than the plot's last tree).
    #[arg(long)]
    tree_id: Option<u32>,
    /// Species code for the readings (your inventory's code list, e.g. PIAB or 50).
    #[arg(long, default_value = "")]
    species: String,
    /// Free-text label stored with every reading of this session ("kitchen NE corner",
    /// "door 2"); shown by `tangent log show` and exported as the `label` column.
    #[arg(long, default_value = "")]
    label: String,
    /// Also keep a PNG of this session's diameters (± 2σ) by tree id, updated per reading.
    #[arg(long, value_name = "PNG")]
    plot: Option<PathBuf>,
    /// Set the device to this instrument first (cylinder, sphere, wall, road); it keeps it
    /// until told otherwise or restarted (the link sets it again after a restart).
    #[arg(long, value_parser = parse_mode)]
    mode: Option<Mode>,
    /// Frame pairs one stem reading combines (1–16, `docs/error-model.md` §6): more pairs
    /// average the speckle the hand renews, each pair two more frames (about 35 ms at the
    /// sensor's 60 frames/s); the device keeps the
    /// count until it restarts (the link sets it again after a restart).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=16))]
    exposures: Option<u8>,
    /// Ask the device to measure continuously (as if the trigger were held).
    #[arg(long)]
    stream: bool,
    /// Ask the device for this many single measurements (as trigger presses), then stop.
    #[arg(long, value_name = "N")]
    measure: Option<u32>,
    /// Stop after this many readings (default: run until interrupted).
    #[arg(long, value_name = "N")]
    count: Option<u64>,
    /// Give up when the device has been gone this long (seconds; default: wait forever).
    #[arg(long, value_name = "S")]
    reconnect_timeout: Option<f64>,
}

/// A [`Mode`] by its name, for `--mode`.
pub(crate) fn parse_mode(name: &str) -> Result<Mode, String> {
    Mode::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = Mode::ALL.iter().map(|m| m.name()).collect();
        format!("unknown mode `{name}` (one of: {})", names.join(", "))
    })
}

/// What the forester typed: a tree id, a species code, or both.
#[derive(Debug, PartialEq)]
enum Typed {
    TreeId(u32),
    Species(String),
}

/// `17` → tree 17; `PIAB` → species; `17 PIAB` or `17 50` → both (the second word is
/// always the species, so numeric species codes work); `- 50` → species 50 only.
fn parse_typed(line: &str) -> Vec<Typed> {
    let words: Vec<&str> = line.split_whitespace().collect();
    match words.as_slice() {
        [] => vec![],
        [one] => match one.parse::<u32>() {
            Ok(n) => vec![Typed::TreeId(n)],
            Err(_) => vec![Typed::Species(one.to_string())],
        },
        [first, second, ..] => {
            let mut out = Vec::new();
            if let Ok(n) = first.parse::<u32>() {
                out.push(Typed::TreeId(n));
            }
            out.push(Typed::Species(second.to_string()));
            out
        }
    }
}

/// Runs the listener.
pub fn run(args: Args) -> Result<ExitCode> {
    // The port first: a listen that cannot reach the device leaves the log untouched (no
    // file created, no plot header appended, no torn tail set aside).
    let path = resolve_port(args.port.clone())?;
    let mut cfg = LinkConfig {
        reconnect_timeout: args.reconnect_timeout.map(Duration::from_secs_f64),
        ..LinkConfig::default()
    };
    if args.stream {
        // A streaming device reads requests between measurements (the emulated board
        // about one byte per measurement): give replies more time.
        cfg.reply_timeout = Duration::from_secs(5);
    }
    let mut link = Link::open(&path, cfg)?;
    if let Some(mode) = args.mode {
        link.set_mode(mode)?;
    }
    if let Some(count) = args.exposures {
        link.set_exposures(count)?;
    }
    // The error names the file.
    let mut log = FieldLog::open(&args.log).context("cannot open the field log")?;
    if log.torn_bytes() > 0 {
        eprintln!(
            "recovered the field log: an incomplete last record ({} bytes, from a crash) was \
             set aside in {}.torn; every saved reading is intact",
            log.torn_bytes(),
            args.log.display()
        );
    }
    if log.skipped() > 0 {
        eprintln!(
            "warning: {} damaged line(s) in the middle of the log were skipped",
            log.skipped()
        );
    }
    let plot_id = match (&args.plot_id, log.current_plot()) {
        (Some(id), Some(cur)) if *id == cur.plot_id => id.clone(),
        (None, Some(cur)) => cur.plot_id.clone(),
        (wanted, _) => {
            let id = wanted.clone().unwrap_or_else(|| "1".to_string());
            log.append(Record::Plot(PlotHeader {
                plot_id: id.clone(),
                started: fieldlog::now_rfc3339(),
                note: args.note.clone(),
            }))?;
            eprintln!("started plot {id}");
            id
        }
    };

    link.on_event(|e| match e {
        LinkEvent::Lost(why) => eprintln!("link lost ({why}); waiting for the device…"),
        LinkEvent::Reconnected { .. } => eprintln!("device back; catching up"),
        LinkEvent::Rebooted => eprintln!("the device restarted"),
        LinkEvent::MeasurementFailed(error) => eprintln!("{error}"),
        LinkEvent::Unrecoverable { from, to } => eprintln!(
            "warning: readings {from}–{to} were made while disconnected and are no longer on the device"
        ),
    });
    let id = link.identity().clone();
    let device_id = link::device_id(&path, &id);
    // Readings this device made while we were not listening (same boot: its clock and
    // sequence numbers are past the log's) come from its history.
    if let Some(t) = log.last_tree_from(&device_id) {
        if t.device_time_ms <= id.uptime_ms && t.seq <= id.last_seq {
            link.resume_after(t.seq);
        }
    }
    eprintln!(
        "listening to {} on {path} (firmware {}, calibration {}, mode {}{}), plot {plot_id}, log {}",
        device_id,
        id.fw_version,
        id.calib_id
            .map(|c| c.to_string())
            .unwrap_or_else(|| "NONE — push one with `tangent device-calibration push`".into()),
        id.mode.name(),
        if id.mode == Mode::Cylinder {
            format!(", {} exposures per reading", id.exposures)
        } else {
            String::new()
        },
        args.log.display()
    );
    if args.mode.is_none() && id.mode_store.is_default() {
        // The device did not find the mode it was last set to: say why it measures this one.
        eprintln!(
            "the device measures {}: {} (choose one with --mode)",
            id.mode.name(),
            id.mode_store
        );
    }

    let mut next_tree = args.tree_id.unwrap_or_else(|| {
        log.last_tree_in(&plot_id)
            .map(|t| t.tree_id + 1)
            .unwrap_or(1)
    });
    let mut species = args.species.clone();
    let typed = if std::io::stdin().is_terminal() {
        eprintln!("type a tree id and/or species code (`17`, `PIAB`, `17 PIAB`, `- 50`) + Enter to set the next tree");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Some(rx)
    } else {
        None
    };

    if args.stream {
        link.start_stream()?;
    }
    let mut to_measure = args.measure.unwrap_or(0);
    let mut session: Vec<TreeRecord> = Vec::new();
    let mut last_tree: Option<u32> = None;
    let mut received = 0u64;
    loop {
        if args.count.is_some_and(|n| received >= n) {
            break;
        }
        if let Some(rx) = &typed {
            while let Ok(line) = rx.try_recv() {
                for t in parse_typed(&line) {
                    match t {
                        Typed::TreeId(n) => next_tree = n,
                        Typed::Species(s) => species = s,
                    }
                }
                eprintln!(
                    "next: tree {next_tree}, species {}",
                    if species.is_empty() { "-" } else { &species }
                );
            }
        }
        if to_measure > 0 {
            to_measure -= 1;
            if let Err(e) = link.measure() {
                eprintln!("{e}");
            }
        }
        let Some(reading) = link.next_reading(Duration::from_millis(250))? else {
            if args.measure.is_some() && to_measure == 0 && !args.stream {
                // Every requested measurement is in (the link has already checked the
                // device's history for any lost on the wire).
                break;
            }
            continue;
        };
        received += 1;
        // A held trigger (or stream) reports running statistics: its readings after the
        // first are the same tree.
        let continues = reading.stats.is_some_and(|s| s.count > 1) && last_tree.is_some();
        let tree_id = match (continues, last_tree) {
            (true, Some(t)) => t,
            _ => {
                let t = next_tree;
                next_tree += 1;
                t
            }
        };
        last_tree = Some(tree_id);
        let record = TreeRecord::from_reading(
            &reading,
            fieldlog::Filing {
                plot_id: &plot_id,
                tree_id,
                species: &species,
                label: &args.label,
                device_id: &device_id,
                time: &fieldlog::now_rfc3339(),
            },
        );
        // Write-ahead: on disk before it is shown.
        log.append(Record::Tree(record.clone()))?;
        println!("{}", describe(&record, &reading));
        session.push(record);
        if let Some(png) = &args.plot {
            if let Err(e) = session_png(png, &plot_id, &session) {
                eprintln!("warning: cannot write {}: {e:#}", png.display());
            }
        }
    }
    if args.stream {
        link.stop_stream()?;
    }
    let c = link.counters();
    eprintln!(
        "{received} reading(s) saved; link: {} frames, {} rejected, {} duplicates dropped, {} reconnects, {} lost",
        c.frames_ok,
        c.malformed + c.oversize + c.version_mismatch,
        c.duplicates,
        c.reconnects,
        c.lost
    );
    Ok(ExitCode::SUCCESS)
}

fn describe(t: &TreeRecord, r: &Reading) -> String {
    let species = if t.species.is_empty() {
        "-"
    } else {
        &t.species
    };
    let mut s = if t.kind == "stem" {
        format!(
            "tree {:>4} {:<6} {:7.1} mm ± {:.1}  tilt {:4.1}°",
            t.tree_id, species, t.diameter_mm, t.uncertainty_mm, t.tilt_deg
        )
    } else {
        format!(
            "{} {:>4} {:<6} d = {:7.1} mm ± {:.1}",
            t.kind, t.tree_id, species, t.diameter_mm, t.uncertainty_mm
        )
    };
    if let Measurement::Stem(stem) = &r.measurement {
        if stem.exposures > 1 {
            s += &format!("  ({} exposures)", stem.exposures);
        }
    }
    if let Some(st) = r.stats.filter(|s| s.count > 1) {
        s += &format!(
            "  (held: {} readings, mean {:.1} mm, spread {:.1} mm)",
            st.count,
            st.mean_m as f64 * 1e3,
            st.spread_m as f64 * 1e3
        );
    }
    // A wall reading without its plumb says why (no accelerometer, or it failed).
    if let Some(a) = r.accelerometer.filter(|a| a.mean().is_none()) {
        s += &format!("  ({a})");
    }
    if !t.label.is_empty() {
        s += &format!("  \"{}\"", t.label);
    }
    let flags = fieldlog::flag_names(t.flags);
    if !flags.is_empty() {
        s += &format!("  [{flags}]");
    }
    s += &format!("  #{}", t.seq);
    s
}

/// Diameter ± 2σ by tree id for this session.
fn session_png(path: &std::path::Path, plot_id: &str, trees: &[TreeRecord]) -> Result<()> {
    tangent_host::plot::init_fonts();
    let err = |e: &dyn std::fmt::Debug| anyhow::anyhow!("{e:?}");
    let root = BitMapBackend::new(path, (900, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let x_max = trees.iter().map(|t| t.tree_id).max().unwrap_or(1) + 1;
    let x_min = trees
        .iter()
        .map(|t| t.tree_id)
        .min()
        .unwrap_or(1)
        .saturating_sub(1);
    let y_max = trees
        .iter()
        .map(|t| t.diameter_mm + 2.0 * t.uncertainty_mm)
        .fold(10.0, f64::max)
        * 1.1;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("plot {plot_id}: diameters (± 2σ)"),
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(x_min as f64..x_max as f64, 0.0..y_max)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("tree id")
        .y_desc("diameter (mm)")
        .draw()
        .map_err(|e| err(&e))?;
    // Error bars as vertical segments (plotters' ErrorBar needs a feature this crate
    // does not enable), the reading as a dot.
    chart
        .draw_series(trees.iter().map(|t| {
            let x = t.tree_id as f64;
            PathElement::new(
                vec![
                    (x, t.diameter_mm - 2.0 * t.uncertainty_mm),
                    (x, t.diameter_mm + 2.0 * t.uncertainty_mm),
                ],
                BLUE.stroke_width(2),
            )
        }))
        .map_err(|e| err(&e))?;
    chart
        .draw_series(
            trees
                .iter()
                .map(|t| Circle::new((t.tree_id as f64, t.diameter_mm), 4, BLUE.filled())),
        )
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn typed_lines() {
        assert_eq!(
            parse_typed(" 17  PIAB "),
            vec![Typed::TreeId(17), Typed::Species("PIAB".into())]
        );
        assert_eq!(parse_typed("50"), vec![Typed::TreeId(50)]);
        assert_eq!(
            parse_typed("12 50"),
            vec![Typed::TreeId(12), Typed::Species("50".into())]
        );
        assert_eq!(parse_typed("- 50"), vec![Typed::Species("50".into())]);
        assert!(parse_typed("").is_empty());
    }
}
