//! Accuracy evaluation against the simulator's truth: random stems across the product's
//! envelope, each rendered with a physics model drawn from its seed
//! ([`crate::simulate::physics`]), measured end to end by the same core the device runs and by
//! the naive baseline ([`crate::baseline`]), tabulated per physics model and distance bin
//! (Tangent beside the baseline), then per diameter bin with the three-tangent method and the
//! fit side by side. Two disjoint frozen seed sets ([`SeedSet`]): tune on one, report the
//! other. `tangent evaluate` writes `docs/accuracy.md` from it.

use std::fmt::Write as _;

use rayon::prelude::*;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;

use crate::baseline;
use crate::measure::{measure_loaded, Reading};
use crate::simulate::physics::{self, model_for_seed};
use crate::simulate::{corpus::random_stem, simulate};
use crate::truth::{Object, PhysicsModel};

pub mod table;

use table::{binned_rows, error_stats, failures_and_worst, ErrorStats, Evaluated, MethodDiameter};

/// The frozen seed sets of the evaluation (`docs/accuracy.md`, "Seed sets"). A set's
/// transversal captures use seeds `transversal_first + i`, its tilted ones
/// `tilted_first + i`, `i < MAX_CAPTURES`; the four ranges are disjoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SeedSet {
    /// Seeds anyone may look at while tuning the solver (the seeds of the evaluations before
    /// the physics models: transversal from 1 000 000).
    Tuning,
    /// Held-out seeds: the numbers the docs quote; never tune on them.
    Report,
}

impl SeedSet {
    /// Largest number of captures of one kind in a set (keeps the ranges disjoint).
    pub const MAX_CAPTURES: u64 = 500_000;

    /// First seed of the set's transversal (`tilted == false`) or tilted captures.
    pub fn first_seed(self, tilted: bool) -> u64 {
        match (self, tilted) {
            (SeedSet::Tuning, false) => 1_000_000,
            (SeedSet::Tuning, true) => 1_500_000,
            (SeedSet::Report, false) => 7_000_000,
            (SeedSet::Report, true) => 7_500_000,
        }
    }

    /// First seed of the set's random balls (`docs/accuracy.md`, "Spheres"): tuning from
    /// 2 000 000 (the balls the sphere solver's σ was calibrated on), report from 8 000 000.
    pub fn first_sphere_seed(self) -> u64 {
        match self {
            SeedSet::Tuning => 2_000_000,
            SeedSet::Report => 8_000_000,
        }
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            SeedSet::Tuning => "tuning",
            SeedSet::Report => "report",
        }
    }
}

/// The exposure pairs each evaluated stem capture holds (`docs/simulator.md`, "Several
/// exposures"): Tangent combines them; the baseline measures the first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exposures {
    /// Pairs per capture (1: one trigger, one pair).
    pub pairs: usize,
    /// The same speckle in every pair (the hand did not renew it).
    pub frozen_speckle: bool,
}

impl Default for Exposures {
    fn default() -> Self {
        Exposures {
            pairs: 1,
            frozen_speckle: false,
        }
    }
}

/// One evaluated capture.
#[derive(Debug, Clone)]
pub struct Sample {
    /// Simulator seed.
    pub seed: u64,
    /// Physics model the capture was rendered with.
    pub physics: PhysicsModel,
    /// The naive baseline's diameter (m), or why it gave none.
    pub baseline: Result<f64, String>,
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
/// a lean > 0 uses the two-plane device), each with the physics model of its seed
/// ([`model_for_seed`]), by Tangent and by the baseline, in parallel. Tangent measures
/// with `calibration` ([`crate::calibration_draw::CalibrationUsed`]: exact, off by a draw from
/// the calibration σ its solver states, or that draw refined on a reference ball); the
/// baseline keeps the exact one.
pub fn run(
    first_seed: u64,
    count: u64,
    tilt_max_deg: f64,
    calibration: crate::calibration_draw::CalibrationUsed<'_>,
    exposures: Exposures,
) -> anyhow::Result<Vec<Sample>> {
    let config = PipelineConfig::default();
    let params = CylinderParams::default();
    (first_seed..first_seed + count)
        .into_par_iter()
        .map(|seed| {
            let mut spec = random_stem(seed, tilt_max_deg);
            let model = model_for_seed(seed);
            physics::apply(model, seed, &mut spec);
            spec.params.exposure_pairs = exposures.pairs;
            spec.params.frozen_speckle = exposures.frozen_speckle;
            let (capture, _) = simulate(&spec)?;
            // The baseline below keeps the exact calibration.
            let drawn = calibration.apply(&capture, &params.noise, seed)?;
            let measured = drawn.as_ref().unwrap_or(&capture);
            let outcome =
                measure_loaded(measured, &format!("seed {seed}"), None, &config, &params)?;
            let baseline = baseline::measure(&capture, None)
                .map(|b| b.diameter_m)
                .map_err(|e| e.to_string());
            let (distance_m, tilt_deg) = stem_geometry(&spec.objects);
            Ok(Sample {
                seed,
                physics: model,
                baseline,
                truth_m: outcome.reading.truth_diameter_m.unwrap_or(f64::NAN),
                distance_m,
                tilt_deg,
                reading: outcome.reading,
            })
        })
        .collect()
}

/// One sample as a JSON object (`tangent evaluate --samples`): the seed, its physics model,
/// the truth, Tangent's reading and the baseline's diameter or error.
pub fn sample_json(s: &Sample) -> serde_json::Value {
    serde_json::json!({
        "seed": s.seed,
        "physics": s.physics.name(),
        "truth_m": s.truth_m,
        "distance_m": s.distance_m,
        "tilt_deg": s.tilt_deg,
        "baseline_m": s.baseline.as_ref().ok(),
        "baseline_error": s.baseline.as_ref().err(),
        "reading": &s.reading,
    })
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

/// Statistics of `samples` (method columns: three-tangent, fit; within 1 %).
pub fn stats(samples: &[&Sample]) -> ErrorStats {
    error_stats(samples, &STEM_METHODS, 0.01)
}

const STEM_METHODS: [MethodDiameter; 2] = [|r| r.three_tangent_diameter_m, |r| r.fit_diameter_m];

impl Evaluated for Sample {
    fn seed(&self) -> u64 {
        self.seed
    }
    fn truth_m(&self) -> f64 {
        self.truth_m
    }
    fn distance_m(&self) -> f64 {
        self.distance_m
    }
    fn reading(&self) -> &Reading {
        &self.reading
    }
    fn placement(&self) -> String {
        format!("at {:.2} m, tilt {:.0}°", self.distance_m, self.tilt_deg)
    }
}

/// Distance bins of the tables (metres, half-open; the last one closes at 3 m).
pub const DISTANCE_BINS_M: [(f64, f64); 3] = [(0.5, 1.0), (1.0, 2.0), (2.0, 3.01)];

const DIAMETER_BINS_MM: [(f64, f64); 4] = [
    (50.0, 100.0),
    (100.0, 200.0),
    (200.0, 400.0),
    (400.0, 1000.01),
];
fn row(label: &str, s: &ErrorStats) -> String {
    let mm = |v: f64| format!("{:.2}", v * 1e3);
    format!(
        "| {label} | {} | {} | {} | {} | {} ({}) | {} ({}) | {:.0} % | {:.2} % | {:.0} % |\n",
        s.n,
        s.no_reading,
        mm(s.mae),
        mm(s.bias),
        mm(s.by_method[0].0),
        s.by_method[0].1,
        mm(s.by_method[1].0),
        s.by_method[1].1,
        s.within_tolerance * 100.0,
        s.p95_relative * 100.0,
        s.within_2sigma * 100.0
    )
}

const HEADER: &str = "| bin | n | no reading | MAE mm | bias mm | three-tangent MAE mm (n) | fit MAE mm (n) | within 1 % | P95 \\|err\\|/d | within 2σ |\n|---|---|---|---|---|---|---|---|---|---|\n";

/// A Markdown section for one run: overall, then per diameter bin and per distance bin.
pub fn section(title: &str, samples: &[Sample]) -> String {
    let mut out = format!("### {title}\n\n{HEADER}");
    let all: Vec<&Sample> = samples.iter().collect();
    out += &row("**all**", &stats(&all));
    out += &binned_rows(
        samples,
        &DIAMETER_BINS_MM,
        &DISTANCE_BINS_M,
        "z",
        |label, b| row(label, &stats(b)),
    );
    out += &bound_table(samples);
    out + &failures_and_worst(samples, 1)
}

/// What readings whose errors were normal with a given σ would score: the expected MAE
/// `√(2/π)·σ` and the chance of |error| ≤ 1 % of `d`, `erf(0.01·d/(√2·σ))`, averaged over
/// `(d, σ)`.
fn expected_scores(pairs: &[(f64, f64)]) -> (f64, f64) {
    let n = pairs.len().max(1) as f64;
    let mae = pairs
        .iter()
        .map(|&(_, s)| s * (2.0 / std::f64::consts::PI).sqrt())
        .sum::<f64>()
        / n;
    let within = pairs
        .iter()
        .map(|&(d, s)| libm::erf(0.01 * d / (std::f64::consts::SQRT_2 * s)))
        .sum::<f64>()
        / n;
    (mae, within)
}

/// The bound beside the measured scores, per distance bin (`docs/error-model.md` §6, "The
/// single-exposure bound"): readings with errors as large as the points' own scatter allows
/// (`information_uncertainty_m`), and as large as the stated σ.
fn bound_table(samples: &[Sample]) -> String {
    let mut out = String::from(
        "\nThe bound (`docs/error-model.md` §6): the scores of readings whose errors were as large \
         as the points' own scatter allows (*bound*: `information_uncertainty_m`, the fit's \
         white-noise σ with the stripe's correlation length) and as large as the stated σ \
         (*stated σ*: with the coherent bending and the calibration).\n\n\
         | bin | n read | MAE mm | bound MAE mm | stated-σ MAE mm | within 1 % | bound within 1 % | stated-σ within 1 % |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    let mut bins = vec![("**all**".to_string(), (0.0, f64::INFINITY))];
    bins.extend(
        DISTANCE_BINS_M
            .iter()
            .map(|&b| (format!("z {}", distance_label(b)), b)),
    );
    for (label, bin) in bins {
        let read: Vec<(&Sample, f64, f64, f64)> = samples
            .iter()
            .filter(|s| in_distance_bin(s, bin))
            .filter_map(|s| {
                let r = &s.reading;
                Some((
                    s,
                    r.diameter_m?,
                    r.uncertainty_m?,
                    r.information_uncertainty_m?,
                ))
            })
            .collect();
        if read.is_empty() {
            continue;
        }
        let n = read.len() as f64;
        let mae = read
            .iter()
            .map(|(s, d, _, _)| (d - s.truth_m).abs())
            .sum::<f64>()
            / n;
        let within = read
            .iter()
            .filter(|(s, d, _, _)| (d - s.truth_m).abs() <= 0.01 * s.truth_m)
            .count() as f64
            / n;
        let bound: Vec<(f64, f64)> = read.iter().map(|&(s, _, _, i)| (s.truth_m, i)).collect();
        let stated: Vec<(f64, f64)> = read.iter().map(|&(s, _, st, _)| (s.truth_m, st)).collect();
        let (bound_mae, bound_within) = expected_scores(&bound);
        let (stated_mae, stated_within) = expected_scores(&stated);
        out += &format!(
            "| {label} | {} | {:.2} | {:.2} | {:.2} | {:.0} % | {:.0} % | {:.0} % |\n",
            read.len(),
            mae * 1e3,
            bound_mae * 1e3,
            stated_mae * 1e3,
            within * 100.0,
            bound_within * 100.0,
            stated_within * 100.0
        );
    }
    out + "\n"
}

/// The metrics of one pipeline (Tangent or the baseline) over a set of captures.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Metrics {
    /// Captures.
    pub n: usize,
    /// Captures without a reading.
    pub no_reading: usize,
    /// Mean absolute error of the readings (m).
    pub mae: f64,
    /// Median absolute error (m).
    pub median: f64,
    /// Largest absolute error (m).
    pub max: f64,
    /// Share of readings within 1 % of the true diameter.
    pub within_1pct: f64,
    /// Share of readings with |error| ≤ 2 × the stated σ (`None`: the pipeline states none).
    pub within_2sigma: Option<f64>,
}

/// Metrics of `(truth, reading, σ)` triples (the σ of a pipeline that states none is
/// `None` on every reading).
pub fn metrics(rows: impl Iterator<Item = (f64, Option<f64>, Option<f64>)>) -> Metrics {
    let mut m = Metrics::default();
    let mut errors = Vec::new();
    let (mut within, mut within2, mut with_sigma) = (0usize, 0usize, 0usize);
    for (truth, reading, sigma) in rows {
        m.n += 1;
        let Some(d) = reading else {
            m.no_reading += 1;
            continue;
        };
        let e = (d - truth).abs();
        errors.push(e);
        within += (e <= 0.01 * truth) as usize;
        if let Some(s) = sigma {
            with_sigma += 1;
            within2 += (e <= 2.0 * s) as usize;
        }
    }
    if errors.is_empty() {
        m.mae = f64::NAN;
        m.median = f64::NAN;
        m.max = f64::NAN;
        m.within_1pct = f64::NAN;
        return m;
    }
    let k = errors.len() as f64;
    m.mae = errors.iter().sum::<f64>() / k;
    m.max = errors.iter().copied().fold(0.0, f64::max);
    errors.sort_by(f64::total_cmp);
    let mid = errors.len() / 2;
    m.median = if errors.len() % 2 == 1 {
        errors[mid]
    } else {
        0.5 * (errors[mid - 1] + errors[mid])
    };
    m.within_1pct = within as f64 / k;
    m.within_2sigma = (with_sigma > 0).then(|| within2 as f64 / with_sigma as f64);
    m
}

/// Tangent's metrics on `samples`.
pub fn tangent_metrics(samples: &[&Sample]) -> Metrics {
    metrics(
        samples
            .iter()
            .map(|s| (s.truth_m, s.reading.diameter_m, s.reading.uncertainty_m)),
    )
}

/// The baseline's metrics on `samples`.
pub fn baseline_metrics(samples: &[&Sample]) -> Metrics {
    metrics(
        samples
            .iter()
            .map(|s| (s.truth_m, s.baseline.as_ref().ok().copied(), None)),
    )
}

/// Tangent against the baseline on one bin: the MAE of each over the captures both read
/// (paired, so neither gains by refusing hard captures), and the verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Comparison {
    /// Captures both pipelines read.
    pub paired: usize,
    /// Tangent's MAE over them (m).
    pub tangent_mae: f64,
    /// The baseline's MAE over them (m).
    pub baseline_mae: f64,
    /// Tangent wins: lower paired MAE and no more captures without a reading.
    pub tangent_wins: bool,
}

/// Compares Tangent with the baseline on `samples` (`None` when the bin is empty or no
/// capture was read by both).
pub fn compare(samples: &[&Sample]) -> Option<Comparison> {
    let (mut t, mut b, mut n) = (0.0, 0.0, 0usize);
    let (mut t_none, mut b_none) = (0usize, 0usize);
    for s in samples {
        t_none += s.reading.diameter_m.is_none() as usize;
        b_none += s.baseline.is_err() as usize;
        if let (Some(dt), Ok(db)) = (s.reading.diameter_m, &s.baseline) {
            t += (dt - s.truth_m).abs();
            b += (db - s.truth_m).abs();
            n += 1;
        }
    }
    (n > 0).then(|| {
        let (tangent_mae, baseline_mae) = (t / n as f64, b / n as f64);
        Comparison {
            paired: n,
            tangent_mae,
            baseline_mae,
            tangent_wins: tangent_mae < baseline_mae && t_none <= b_none,
        }
    })
}

fn distance_label((lo, hi): (f64, f64)) -> String {
    format!("{lo:.1}–{:.0} m", hi.floor())
}

fn in_distance_bin(s: &Sample, (lo, hi): (f64, f64)) -> bool {
    (lo..hi).contains(&s.distance_m)
}

const COMPARISON_HEADER: &str = "| set | n | no reading T / B | MAE mm T / B | median mm T / B | max mm T / B | within 1 % T / B | within 2σ T | paired MAE mm T / B (n) | Tangent wins |\n|---|---|---|---|---|---|---|---|---|---|\n";

fn comparison_row(label: &str, samples: &[&Sample]) -> String {
    let (t, b) = (tangent_metrics(samples), baseline_metrics(samples));
    let mm = |v: f64| {
        if v.is_finite() {
            format!("{:.2}", v * 1e3)
        } else {
            "—".into()
        }
    };
    let pct = |v: f64| {
        if v.is_finite() {
            format!("{:.0} %", v * 100.0)
        } else {
            "—".into()
        }
    };
    let (paired, wins) = match compare(samples) {
        Some(c) => (
            format!(
                "{} / {} ({})",
                mm(c.tangent_mae),
                mm(c.baseline_mae),
                c.paired
            ),
            if c.tangent_wins { "yes" } else { "**no**" }.to_string(),
        ),
        None => ("—".into(), "—".into()),
    };
    format!(
        "| {label} | {} | {} / {} | {} / {} | {} / {} | {} / {} | {} / {} | {} | {paired} | {wins} |\n",
        t.n,
        t.no_reading,
        b.no_reading,
        mm(t.mae),
        mm(b.mae),
        mm(t.median),
        mm(b.median),
        mm(t.max),
        mm(b.max),
        pct(t.within_1pct),
        pct(b.within_1pct),
        t.within_2sigma.map_or("—".into(), pct),
    )
}

/// How many (physics model × distance bin) cells Tangent wins against the baseline, of the
/// non-empty ones.
pub fn wins(samples: &[Sample]) -> (usize, usize) {
    let (mut won, mut cells) = (0, 0);
    for model in PhysicsModel::ALL {
        for bin in DISTANCE_BINS_M {
            let cell: Vec<&Sample> = samples
                .iter()
                .filter(|s| s.physics == model && in_distance_bin(s, bin))
                .collect();
            if let Some(c) = compare(&cell) {
                cells += 1;
                won += c.tangent_wins as usize;
            }
        }
    }
    (won, cells)
}

/// A Markdown section comparing Tangent with the naive baseline: overall and per distance
/// bin, per physics model, and the MAE of every (model × distance bin) cell.
pub fn comparison_section(title: &str, samples: &[Sample]) -> String {
    let all: Vec<&Sample> = samples.iter().collect();
    let mut out =
        format!("### {title}: Tangent (T) against the naive baseline (B)\n\n{COMPARISON_HEADER}");
    out += &comparison_row("**all**", &all);
    for bin in DISTANCE_BINS_M {
        let b: Vec<&Sample> = all
            .iter()
            .copied()
            .filter(|s| in_distance_bin(s, bin))
            .collect();
        out += &comparison_row(&distance_label(bin), &b);
    }
    let _ = write!(
        out,
        "\nPer physics model (all distances):\n\n{COMPARISON_HEADER}"
    );
    for model in PhysicsModel::ALL {
        let m: Vec<&Sample> = all.iter().copied().filter(|s| s.physics == model).collect();
        if !m.is_empty() {
            out += &comparison_row(model.name(), &m);
        }
    }
    let _ = write!(
        out,
        "\nPer physics model and distance bin — n, MAE mm T / B (paired), Tangent's within 1 %:\n\n| model |"
    );
    for bin in DISTANCE_BINS_M {
        let _ = write!(out, " {} |", distance_label(bin));
    }
    out += "\n|---|";
    for _ in DISTANCE_BINS_M {
        out += "---|";
    }
    out.push('\n');
    for model in PhysicsModel::ALL {
        let _ = write!(out, "| {} |", model.name());
        for bin in DISTANCE_BINS_M {
            let cell: Vec<&Sample> = all
                .iter()
                .copied()
                .filter(|s| s.physics == model && in_distance_bin(s, bin))
                .collect();
            let t = tangent_metrics(&cell);
            match compare(&cell) {
                Some(c) => {
                    let mark = if c.tangent_wins { "" } else { " ✗" };
                    let _ = write!(
                        out,
                        " {}: {:.1} / {:.1}{mark}, {:.0} % |",
                        cell.len(),
                        c.tangent_mae * 1e3,
                        c.baseline_mae * 1e3,
                        t.within_1pct * 100.0
                    );
                }
                None if cell.is_empty() => out += " — |",
                None => {
                    let _ = write!(out, " {}: no paired reading |", cell.len());
                }
            }
        }
        out.push('\n');
    }
    let (won, cells) = wins(samples);
    let _ = writeln!(
        out,
        "\nTangent wins **{won} of {cells}** (model × distance) cells (✗: lost).\n"
    );
    out
}
