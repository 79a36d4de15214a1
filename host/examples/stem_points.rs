//! Per-point row errors of the stem chain's curves against the captures' truth curves
//! (`docs/error-model.md`, "Small far stems read low"): where along the arc the rows err
//! (by the point's distance in columns from the nearer end of its curve) and how with the
//! true row's phase within its pixel, with the diameters' errors over the same captures.
//!
//! Usage: `stem_points [--half-window N] DIR...` with each `DIR` a capture with a
//! `truth-curve.csv` (e.g. from `tangent simulate random --physics by-seed`); `--half-window`
//! sets the curve smoothing's (`curve::SmoothParams`, 0 = none). Points more than 3 px from
//! the truth curve (a stray object) are left out.
use std::path::Path;

use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::capture::Capture;
use tangent_host::measure::measure_loaded;

/// Distance-from-end bins (columns): 0, 1, … up to `END_BINS - 1` and beyond.
const END_BINS: usize = 8;
/// Phase bins of the true row within its pixel (−0.5 … 0.5).
const PHASE_BINS: usize = 8;

/// Running mean.
#[derive(Default, Clone, Copy)]
struct Mean {
    n: usize,
    sum: f64,
}

impl Mean {
    fn add(&mut self, x: f64) {
        self.n += 1;
        self.sum += x;
    }
    fn value(&self) -> f64 {
        self.sum / self.n.max(1) as f64
    }
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut config = PipelineConfig::default();
    if let Some(i) = args.iter().position(|a| a == "--half-window") {
        let Some(Ok(h)) = args.get(i + 1).map(|s| s.parse::<u8>()) else {
            eprintln!("usage: stem_points [--half-window N] DIR...");
            std::process::exit(2);
        };
        config.smooth.half_window = h;
        args.drain(i..i + 2);
    }
    let params = CylinderParams::default();
    let mut from_end = [Mean::default(); END_BINS];
    let mut by_phase = [Mean::default(); PHASE_BINS];
    let mut diameter_errors = Vec::new();
    for dir in &args {
        let dir = Path::new(dir);
        let capture = match Capture::read(dir) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("{}: {e}", dir.display());
                continue;
            }
        };
        let out = match measure_loaded(
            &capture,
            dir.to_str().unwrap_or("?"),
            None,
            &config,
            &params,
        ) {
            Ok(o) => o,
            Err(e) => {
                eprintln!("{}: {e}", dir.display());
                continue;
            }
        };
        if let (Some(d), Some(t)) = (out.reading.diameter_m, out.reading.truth_diameter_m) {
            diameter_errors.push((d - t) * 1e3);
        }
        let truth: Vec<(u16, f64)> = capture
            .truth_curve
            .iter()
            .flatten()
            .map(|t| (t.column as u16, t.row_px))
            .collect();
        // Each curve's points with their truth, in column order.
        for curve in 0..=out.curve.iter().map(|c| c.curve).max().unwrap_or(0) {
            let mut points: Vec<(u16, f64, f64)> = out
                .curve
                .iter()
                .filter(|c| c.curve == curve && c.amplitude > 0.0)
                .filter_map(|c| {
                    let t = truth
                        .iter()
                        .filter(|t| t.0 == c.column)
                        .map(|t| t.1)
                        .min_by(|a, b| (a - c.row).abs().total_cmp(&(b - c.row).abs()))?;
                    ((c.row - t).abs() <= 3.0).then_some((c.column, c.row, t))
                })
                .collect();
            points.sort_by_key(|p| p.0);
            let n = points.len();
            for (i, &(_, row, t)) in points.iter().enumerate() {
                let end = i.min(n - 1 - i).min(END_BINS - 1);
                from_end[end].add(row - t);
                let phase = t - (t + 0.5).floor();
                let bin = (((phase + 0.5) * PHASE_BINS as f64) as usize).min(PHASE_BINS - 1);
                by_phase[bin].add(row - t);
            }
        }
    }
    let n = diameter_errors.len() as f64;
    diameter_errors.sort_by(f64::total_cmp);
    println!(
        "{} captures read (smoothing half window {}): diameter error mean {:+.2} mm, median {:+.2} mm, MAE {:.2} mm",
        diameter_errors.len(),
        config.smooth.half_window,
        diameter_errors.iter().sum::<f64>() / n,
        diameter_errors.get(diameter_errors.len() / 2).copied().unwrap_or(f64::NAN),
        diameter_errors.iter().map(|e| e.abs()).sum::<f64>() / n,
    );
    println!("\n| columns from the curve's end | points | mean row error px |");
    println!("|---|---|---|");
    for (k, m) in from_end.iter().enumerate() {
        let label = if k + 1 == END_BINS {
            format!("≥ {k}")
        } else {
            k.to_string()
        };
        println!("| {label} | {} | {:+.3} |", m.n, m.value());
    }
    println!("\n| true row's phase in its pixel | points | mean row error px |");
    println!("|---|---|---|");
    for (k, m) in by_phase.iter().enumerate() {
        let centre = -0.5 + (k as f64 + 0.5) / PHASE_BINS as f64;
        println!("| {centre:+.3} | {} | {:+.3} |", m.n, m.value());
    }
}
