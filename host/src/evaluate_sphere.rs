//! Accuracy of the sphere instrument against the simulator's truth (`docs/accuracy.md`,
//! "Spheres"): random balls ([`random_sphere`]) measured end to end by the core, tabulated by
//! diameter and distance with the three methods side by side.

use std::fmt::Write as _;

use rayon::prelude::*;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;

use crate::measure::{measure_loaded, Reading};
use crate::simulate::{simulate, sphere_corpus::random_sphere};
use crate::truth::Object;

/// One evaluated ball.
#[derive(Debug, Clone)]
pub struct SphereSample {
    /// Simulator seed.
    pub seed: u64,
    /// True diameter (m).
    pub truth_m: f64,
    /// True distance of the centre from the camera (m).
    pub distance_m: f64,
    /// The reading.
    pub reading: Reading,
}

/// Simulates and measures `count` random balls from `first_seed`, in parallel.
pub fn run(first_seed: u64, count: u64) -> anyhow::Result<Vec<SphereSample>> {
    let config = PipelineConfig::default();
    let params = CylinderParams::default();
    (first_seed..first_seed + count)
        .into_par_iter()
        .map(|seed| {
            let spec = random_sphere(seed);
            let (capture, _) = simulate(&spec)?;
            let outcome =
                measure_loaded(&capture, &format!("seed {seed}"), None, &config, &params)?;
            let (truth_m, distance_m) = spec
                .objects
                .iter()
                .find_map(|o| match o {
                    Object::Sphere(s) => Some((2.0 * s.radius_m, {
                        let c = s.centre_m;
                        (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
                    })),
                    _ => None,
                })
                .unwrap_or((f64::NAN, f64::NAN));
            Ok(SphereSample {
                seed,
                truth_m,
                distance_m,
                reading: outcome.reading,
            })
        })
        .collect()
}

/// Error statistics of a set of balls.
#[derive(Debug, Clone, Copy, Default)]
pub struct SphereStats {
    /// Balls.
    pub n: usize,
    /// Balls without a reading.
    pub no_reading: usize,
    /// Mean absolute error of the reported diameter (m).
    pub mae: f64,
    /// Mean signed error (m).
    pub bias: f64,
    /// MAE of the joint fit, the sections and the three-tangent construction (m), each over
    /// the balls where it gave a diameter, with those counts.
    pub by_method: [(f64, usize); 3],
    /// Share of readings within 0.5 % of the true diameter.
    pub within_half_pct: f64,
    /// 95th percentile of |error| / diameter.
    pub p95_relative: f64,
    /// Share of readings with |error| ≤ 2 × the stated 1σ.
    pub within_2sigma: f64,
    /// The same with the random part of the 1σ only (the simulation's calibration is exact).
    pub within_2sigma_random: f64,
}

/// Statistics of `samples`.
pub fn stats(samples: &[&SphereSample]) -> SphereStats {
    let mut s = SphereStats {
        n: samples.len(),
        ..Default::default()
    };
    let mut rel = Vec::new();
    let (mut sum_abs, mut sum) = (0.0, 0.0);
    let (mut half, mut w2, mut w2r) = (0usize, 0usize, 0usize);
    for x in samples {
        let r = &x.reading;
        for (k, d) in [
            r.fit_diameter_m,
            r.sections_diameter_m,
            r.three_tangent_diameter_m,
        ]
        .into_iter()
        .enumerate()
        {
            if let Some(d) = d {
                s.by_method[k].0 += (d - x.truth_m).abs();
                s.by_method[k].1 += 1;
            }
        }
        match r.diameter_m {
            Some(d) => {
                let e = d - x.truth_m;
                sum_abs += e.abs();
                sum += e;
                rel.push(e.abs() / x.truth_m);
                half += (e.abs() <= 0.005 * x.truth_m) as usize;
                w2 += (e.abs() <= 2.0 * r.uncertainty_m.unwrap_or(0.0)) as usize;
                w2r += (e.abs() <= 2.0 * r.random_uncertainty_m.unwrap_or(0.0)) as usize;
            }
            None => s.no_reading += 1,
        }
    }
    let k = rel.len().max(1) as f64;
    s.mae = sum_abs / k;
    s.bias = sum / k;
    s.within_half_pct = half as f64 / k;
    s.within_2sigma = w2 as f64 / k;
    s.within_2sigma_random = w2r as f64 / k;
    for m in &mut s.by_method {
        m.0 /= m.1.max(1) as f64;
    }
    rel.sort_by(f64::total_cmp);
    s.p95_relative = rel
        .get(((rel.len() as f64 * 0.95).ceil() as usize).saturating_sub(1))
        .copied()
        .unwrap_or(f64::NAN);
    s
}

const DIAMETER_BINS_MM: [(f64, f64); 4] =
    [(20.0, 50.0), (50.0, 100.0), (100.0, 200.0), (200.0, 400.01)];
const DISTANCE_BINS_M: [(f64, f64); 4] = [(0.3, 0.6), (0.6, 1.0), (1.0, 1.5), (1.5, 2.1)];

fn row(label: &str, s: &SphereStats) -> String {
    let mm = |v: f64| format!("{:.2}", v * 1e3);
    let m = |k: usize| format!("{} ({})", mm(s.by_method[k].0), s.by_method[k].1);
    format!(
        "| {label} | {} | {} | {} | {} | {} | {} | {} | {:.0} % | {:.2} % | {:.0} % | {:.0} % |\n",
        s.n,
        s.no_reading,
        mm(s.mae),
        mm(s.bias),
        m(0),
        m(1),
        m(2),
        s.within_half_pct * 100.0,
        s.p95_relative * 100.0,
        s.within_2sigma * 100.0,
        s.within_2sigma_random * 100.0
    )
}

const HEADER: &str = "| bin | n | no reading | MAE mm | bias mm | joint fit MAE mm (n) | sections MAE mm (n) | three-tangent MAE mm (n) | within 0.5 % | P95 \\|err\\|/d | within 2σ | within 2σ random |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n";

/// A Markdown section: the target subset (d ≥ 50 mm, centre ≤ 1.5 m), everything, then per
/// diameter and per distance bin; the refusals and the largest errors.
pub fn section(title: &str, samples: &[SphereSample]) -> String {
    let mut out = format!("### {title}\n\n{HEADER}");
    let target: Vec<&SphereSample> = samples
        .iter()
        .filter(|s| s.truth_m >= 0.05 && s.distance_m <= 1.5)
        .collect();
    out += &row("**target: d ≥ 50 mm, ≤ 1.5 m**", &stats(&target));
    let all: Vec<&SphereSample> = samples.iter().collect();
    out += &row("all", &stats(&all));
    for (lo, hi) in DIAMETER_BINS_MM {
        let b: Vec<&SphereSample> = samples
            .iter()
            .filter(|s| (lo..hi).contains(&(s.truth_m * 1e3)))
            .collect();
        if !b.is_empty() {
            out += &row(&format!("d {lo:.0}–{:.0} mm", hi.floor()), &stats(&b));
        }
    }
    for (lo, hi) in DISTANCE_BINS_M {
        let b: Vec<&SphereSample> = samples
            .iter()
            .filter(|s| (lo..hi).contains(&s.distance_m))
            .collect();
        if !b.is_empty() {
            out += &row(&format!("centre {lo:.1}–{hi:.1} m"), &stats(&b));
        }
    }
    let failures: Vec<&SphereSample> = samples
        .iter()
        .filter(|s| s.reading.error.is_some())
        .collect();
    if !failures.is_empty() {
        let _ = writeln!(out, "\nNo reading ({}), the first 12:\n", failures.len());
        for f in failures.iter().take(12) {
            let _ = writeln!(
                out,
                "- seed {}: d {:.0} mm, centre {:.2} m: {}",
                f.seed,
                f.truth_m * 1e3,
                f.distance_m,
                f.reading.error.as_deref().unwrap_or("")
            );
        }
    }
    let mut worst: Vec<&SphereSample> = samples
        .iter()
        .filter(|s| s.reading.diameter_m.is_some())
        .collect();
    worst.sort_by(|a, b| {
        let e = |s: &SphereSample| (s.reading.diameter_m.unwrap_or(0.0) - s.truth_m).abs();
        e(b).total_cmp(&e(a))
    });
    let _ = writeln!(out, "\nLargest errors:\n");
    for w in worst.iter().take(5) {
        let d = w.reading.diameter_m.unwrap_or(f64::NAN);
        let _ = writeln!(
            out,
            "- seed {}: truth {:.1} mm, centre {:.2} m → {:.1} mm ({:+.2} mm, ±{:.2} mm, {}{}{})",
            w.seed,
            w.truth_m * 1e3,
            w.distance_m,
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
