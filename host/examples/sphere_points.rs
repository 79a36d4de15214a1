//! Per-point truth errors of the sphere chain's curves on cached random balls
//! (`docs/sphere.md`, "Grown sections and the points' own σ"; table in `docs/accuracy.md`,
//! "Grown sections"): each curve point's row against the capture's truth curve, binned by
//! the point's amplitude relative to its ball's median, with the σ the chain states for it
//! (`NoiseModel::stripe_centre_px`) and the estimator term alone (no speckle floor).
//!
//! Usage: `sphere_points CACHE FIRST COUNT [--grow]` with `CACHE` a `tangent evaluate
//! --sphere-cache` directory; `--grow` grows the curves along their stripes (`docs/pipeline.md`
//! §9), as the measured-but-not-adopted variant of `docs/accuracy.md` did. Points more than 3 px from the truth curve (the floor's stripe, a stray
//! object) are left out.
use std::path::Path;

use tangent_core::noise::NoiseModel;
use tangent_core::pipeline::{GrowParams, PipelineConfig};
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::capture::Capture;
use tangent_host::measure::{measure_loaded, Solved};

/// Relative-amplitude bins.
const BINS: [(f64, f64); 6] = [
    (0.0, 0.2),
    (0.2, 0.35),
    (0.35, 0.5),
    (0.5, 0.8),
    (0.8, 1.2),
    (1.2, f64::INFINITY),
];

/// One point: steel?, relative amplitude, row error (px), stated σ (px), estimator σ (px).
type PointError = (bool, f64, f64, f64, f64);

fn ball_points(dir: &Path, config: &PipelineConfig, params: &CylinderParams) -> Vec<PointError> {
    let Ok(capture) = Capture::read(dir) else {
        return Vec::new();
    };
    let steel = std::fs::read_to_string(dir.join("capture.toml"))
        .is_ok_and(|s| s.contains("steel") || s.contains("shiny"));
    let Ok(out) = measure_loaded(&capture, "ball", None, config, params) else {
        return Vec::new();
    };
    let Ok(Solved::Sphere(m)) = &out.result else {
        return Vec::new();
    };
    let truth: Vec<(u16, f64)> = capture
        .truth_curve
        .iter()
        .flatten()
        .map(|t| (t.column as u16, t.row_px))
        .collect();
    let lit: Vec<_> = out.curve.iter().filter(|c| c.amplitude > 0.0).collect();
    let mut amplitudes: Vec<f64> = lit.iter().map(|c| c.amplitude).collect();
    amplitudes.sort_by(f64::total_cmp);
    let Some(&median) = amplitudes.get(amplitudes.len() / 2) else {
        return Vec::new();
    };
    let estimator_only = NoiseModel {
        speckle_contrast: 0.0,
        ..params.noise
    };
    lit.iter()
        .filter_map(|c| {
            let truth_row = truth
                .iter()
                .filter(|t| t.0 == c.column)
                .map(|t| t.1)
                .min_by(|a, b| (a - c.row).abs().total_cmp(&(b - c.row).abs()))?;
            let e = c.row - truth_row;
            (e.abs() <= 3.0).then(|| {
                (
                    steel,
                    c.amplitude / median,
                    e,
                    params
                        .noise
                        .stripe_centre_px(c.amplitude, c.width, m.profile.noise),
                    estimator_only.stripe_centre_px(c.amplitude, c.width, m.profile.noise),
                )
            })
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(cache), Some(Ok(first)), Some(Ok(count))) = (
        args.get(1),
        args.get(2).map(|s| s.parse::<u64>()),
        args.get(3).map(|s| s.parse::<u64>()),
    ) else {
        eprintln!("usage: sphere_points CACHE FIRST COUNT [--grow]");
        std::process::exit(2);
    };
    let params = CylinderParams::default();
    let config = PipelineConfig {
        grow: args.iter().any(|a| a == "--grow").then(GrowParams::default),
        ..PipelineConfig::default()
    };
    let points: Vec<PointError> = (first..first + count)
        .flat_map(|seed| ball_points(&Path::new(cache).join(seed.to_string()), &config, &params))
        .collect();
    println!(
        "| finish | amplitude / median | n | mean e px | rms e px | stated σ px | rms e/σ_est |"
    );
    println!("|---|---|---|---|---|---|---|");
    for steel in [false, true] {
        for (lo, hi) in BINS {
            let bin: Vec<_> = points
                .iter()
                .filter(|p| p.0 == steel && p.1 >= lo && p.1 < hi)
                .collect();
            let n = bin.len() as f64;
            if bin.is_empty() {
                continue;
            }
            let mean = bin.iter().map(|p| p.2).sum::<f64>() / n;
            let rms = (bin.iter().map(|p| p.2 * p.2).sum::<f64>() / n).sqrt();
            let stated = bin.iter().map(|p| p.3).sum::<f64>() / n;
            let z = (bin.iter().map(|p| (p.2 / p.4).powi(2)).sum::<f64>() / n).sqrt();
            println!(
                "| {} | {lo}–{hi} | {} | {mean:+.3} | {rms:.3} | {stated:.3} | {z:.2} |",
                if steel { "steel" } else { "matt" },
                bin.len()
            );
        }
    }
}
