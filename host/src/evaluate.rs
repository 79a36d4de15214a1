//! Accuracy evaluation against the simulator's truth: fresh random stems across the
//! product's envelope (seeds never used for tuning), measured end to end by the same core the
//! device runs, tabulated per diameter and distance bin with the three-tangent method and
//! the fit side by side. `tangent evaluate` writes `docs/accuracy.md` from it.

use std::fmt::Write as _;

use rayon::prelude::*;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;

use crate::measure::{measure_loaded, Reading};
use crate::simulate::{corpus::random_stem, simulate};
use crate::truth::Object;

/// One evaluated capture.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Simulator seed.
    pub seed: u64,
    /// True diameter (m).
    pub truth_m: f64,
    /// True distance to the stem's front surface on the optical axis (m).
    pub distance_m: f64,
    /// True lean (degrees).
    pub tilt_deg: f64,
    /// The reading.
    pub reading: Reading,
}

/// Simulates and measures `count` random stems from `first_seed` (lean up to `tilt_max_deg`;
/// a lean > 0 uses the two-plane device), in parallel.
pub fn run(first_seed: u64, count: u64, tilt_max_deg: f64) -> anyhow::Result<Vec<Sample>> {
    let config = PipelineConfig::default();
    let params = CylinderParams::default();
    (first_seed..first_seed + count)
        .into_par_iter()
        .map(|seed| {
            let spec = random_stem(seed, tilt_max_deg);
            let (capture, _) = simulate(&spec)?;
            let outcome =
                measure_loaded(&capture, &format!("seed {seed}"), None, &config, &params)?;
            let (distance_m, tilt_deg) = stem_geometry(&spec.objects);
            Ok(Sample {
                seed,
                truth_m: outcome.reading.truth_diameter_m.unwrap_or(f64::NAN),
                distance_m,
                tilt_deg,
                reading: outcome.reading,
            })
        })
        .collect()
}

/// Distance (from the camera to the stem's surface: axis distance minus radius) and lean from
/// vertical (degrees) of the scene's first cylinder.
fn stem_geometry(objects: &[Object]) -> (f64, f64) {
    for o in objects {
        if let Object::Cylinder(c) = o {
            let p = nalgebra::Vector3::from(c.axis_point_m);
            let u = nalgebra::Vector3::from(c.axis_direction).normalize();
            let axis_distance = (p - u * p.dot(&u)).norm();
            let r = c
                .radius_m
                .or(c.semi_axes_m.map(|[a, b]| (a + b) / 2.0))
                .unwrap_or(0.0);
            return (
                axis_distance - r,
                u.y.abs().clamp(0.0, 1.0).acos().to_degrees(),
            );
        }
    }
    (f64::NAN, f64::NAN)
}

/// Error statistics of a set of samples.
#[derive(Debug, Clone, Copy, Default)]
pub struct Stats {
    /// Samples.
    pub n: usize,
    /// Samples without a reading.
    pub no_reading: usize,
    /// Mean absolute error of the reported diameter (m).
    pub mae: f64,
    /// Mean signed error (m).
    pub bias: f64,
    /// Mean absolute error of the three-tangent diameter (m), over samples where it exists.
    pub mae_three_tangent: f64,
    /// Samples with a three-tangent diameter.
    pub n_three_tangent: usize,
    /// Mean absolute error of the fit diameter (m), over samples where it exists.
    pub mae_fit: f64,
    /// Samples with a fit diameter.
    pub n_fit: usize,
    /// Share of readings within 1 % of the true diameter.
    pub within_1pct: f64,
    /// 95th percentile of |error| / diameter over readings.
    pub p95_relative: f64,
    /// Share of readings whose |error| ≤ 2 × their stated 1σ (calibrated uncertainty check:
    /// ≈ 95 % for a Gaussian error).
    pub within_2sigma: f64,
}

/// Statistics of `samples`.
pub fn stats(samples: &[&Sample]) -> Stats {
    let mut s = Stats {
        n: samples.len(),
        ..Default::default()
    };
    let mut rel = Vec::new();
    let (mut sum_abs, mut sum, mut within, mut within2) = (0.0, 0.0, 0usize, 0usize);
    let (mut tt, mut fit) = (0.0, 0.0);
    for x in samples {
        let r = &x.reading;
        if let Some(d) = r.three_tangent_diameter_m {
            tt += (d - x.truth_m).abs();
            s.n_three_tangent += 1;
        }
        if let Some(d) = r.fit_diameter_m {
            fit += (d - x.truth_m).abs();
            s.n_fit += 1;
        }
        match r.diameter_m {
            Some(d) => {
                let e = d - x.truth_m;
                sum_abs += e.abs();
                sum += e;
                rel.push(e.abs() / x.truth_m);
                within += (e.abs() <= 0.01 * x.truth_m) as usize;
                within2 += (e.abs() <= 2.0 * r.uncertainty_m.unwrap_or(0.0)) as usize;
            }
            None => s.no_reading += 1,
        }
    }
    let k = rel.len().max(1) as f64;
    s.mae = sum_abs / k;
    s.bias = sum / k;
    s.within_1pct = within as f64 / k;
    s.within_2sigma = within2 as f64 / k;
    s.mae_three_tangent = tt / s.n_three_tangent.max(1) as f64;
    s.mae_fit = fit / s.n_fit.max(1) as f64;
    rel.sort_by(f64::total_cmp);
    s.p95_relative = rel
        .get(((rel.len() as f64 * 0.95).ceil() as usize).saturating_sub(1))
        .copied()
        .unwrap_or(f64::NAN);
    s
}

const DIAMETER_BINS_MM: [(f64, f64); 4] = [
    (50.0, 100.0),
    (100.0, 200.0),
    (200.0, 400.0),
    (400.0, 1000.01),
];
const DISTANCE_BINS_M: [(f64, f64); 3] = [(0.5, 1.0), (1.0, 2.0), (2.0, 3.01)];

fn row(label: &str, s: &Stats) -> String {
    let mm = |v: f64| format!("{:.2}", v * 1e3);
    format!(
        "| {label} | {} | {} | {} | {} | {} ({}) | {} ({}) | {:.0} % | {:.2} % | {:.0} % |\n",
        s.n,
        s.no_reading,
        mm(s.mae),
        mm(s.bias),
        mm(s.mae_three_tangent),
        s.n_three_tangent,
        mm(s.mae_fit),
        s.n_fit,
        s.within_1pct * 100.0,
        s.p95_relative * 100.0,
        s.within_2sigma * 100.0
    )
}

const HEADER: &str = "| bin | n | no reading | MAE mm | bias mm | three-tangent MAE mm (n) | fit MAE mm (n) | within 1 % | P95 \\|err\\|/d | within 2σ |\n|---|---|---|---|---|---|---|---|---|---|\n";

/// A Markdown section for one run: overall, then per diameter bin and per distance bin.
pub fn section(title: &str, samples: &[Sample]) -> String {
    let mut out = format!("## {title}\n\n{HEADER}");
    let all: Vec<&Sample> = samples.iter().collect();
    out += &row("**all**", &stats(&all));
    for (lo, hi) in DIAMETER_BINS_MM {
        let b: Vec<&Sample> = samples
            .iter()
            .filter(|s| (lo..hi).contains(&(s.truth_m * 1e3)))
            .collect();
        if !b.is_empty() {
            out += &row(&format!("d {lo:.0}–{:.0} mm", hi.floor()), &stats(&b));
        }
    }
    for (lo, hi) in DISTANCE_BINS_M {
        let b: Vec<&Sample> = samples
            .iter()
            .filter(|s| (lo..hi).contains(&s.distance_m))
            .collect();
        if !b.is_empty() {
            out += &row(&format!("z {lo:.1}–{:.1} m", hi.floor()), &stats(&b));
        }
    }
    let failures: Vec<&Sample> = samples
        .iter()
        .filter(|s| s.reading.error.is_some())
        .collect();
    if !failures.is_empty() {
        let _ = writeln!(out, "\nNo reading ({}):\n", failures.len());
        for f in failures.iter().take(12) {
            let _ = writeln!(
                out,
                "- seed {}: d {:.0} mm at {:.2} m, tilt {:.0}°: {}",
                f.seed,
                f.truth_m * 1e3,
                f.distance_m,
                f.tilt_deg,
                f.reading.error.as_deref().unwrap_or("")
            );
        }
    }
    let mut worst: Vec<&Sample> = samples
        .iter()
        .filter(|s| s.reading.diameter_m.is_some())
        .collect();
    worst.sort_by(|a, b| {
        let e = |s: &Sample| (s.reading.diameter_m.unwrap_or(0.0) - s.truth_m).abs();
        e(b).total_cmp(&e(a))
    });
    let _ = writeln!(out, "\nLargest errors:\n");
    for w in worst.iter().take(5) {
        let d = w.reading.diameter_m.unwrap_or(f64::NAN);
        let _ = writeln!(
            out,
            "- seed {}: truth {:.1} mm at {:.2} m, tilt {:.0}° → {:.1} mm ({:+.1} mm, ±{:.1} mm, {}{}{})",
            w.seed,
            w.truth_m * 1e3,
            w.distance_m,
            w.tilt_deg,
            d * 1e3,
            (d - w.truth_m) * 1e3,
            w.reading.uncertainty_m.unwrap_or(f64::NAN) * 1e3,
            w.reading.method.unwrap_or("?"),
            if w.reading.flags.is_empty() { "" } else { "; " },
            w.reading.flags.join(", ")
        );
    }
    out.push('\n');
    out
}
