//! The tables every `tangent evaluate` section shares (stems, spheres): error statistics of
//! a bin of readings against the simulator's truth, a Markdown row per diameter and distance
//! bin, the captures without a reading and the largest errors.

use std::fmt::Write as _;

use crate::measure::Reading;

/// One evaluated capture, whatever the instrument.
pub trait Evaluated {
    /// Simulator seed.
    fn seed(&self) -> u64;
    /// True diameter (m).
    fn truth_m(&self) -> f64;
    /// The distance the tables bin by (m).
    fn distance_m(&self) -> f64;
    /// The reading.
    fn reading(&self) -> &Reading;
    /// Where the object was, for the lists (`"at 1.20 m, tilt 3°"`).
    fn placement(&self) -> String;
}

/// A method's diameter in a reading (the tables' method columns).
pub type MethodDiameter = fn(&Reading) -> Option<f64>;

/// Error statistics of a bin.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ErrorStats {
    /// Captures.
    pub n: usize,
    /// Captures without a reading.
    pub no_reading: usize,
    /// Mean absolute error of the reported diameter (m).
    pub mae: f64,
    /// Mean signed error (m).
    pub bias: f64,
    /// Each method's MAE (m) over the captures where it gave a diameter, and their count.
    pub by_method: Vec<(f64, usize)>,
    /// Share of readings within the relative tolerance of the true diameter.
    pub within_tolerance: f64,
    /// 95th percentile of |error| / diameter over readings.
    pub p95_relative: f64,
    /// Share of readings whose |error| ≤ 2 × their stated 1σ (≈ 95 % for a Gaussian error
    /// and an honest σ).
    pub within_2sigma: f64,
    /// The same with the random part of the 1σ only, where readings state it.
    pub within_2sigma_random: f64,
}

/// Statistics of `samples`: `methods` give the method columns, `tolerance` the relative
/// error counted in [`ErrorStats::within_tolerance`].
pub fn error_stats<S: Evaluated>(
    samples: &[&S],
    methods: &[MethodDiameter],
    tolerance: f64,
) -> ErrorStats {
    let mut s = ErrorStats {
        n: samples.len(),
        by_method: vec![(0.0, 0); methods.len()],
        ..Default::default()
    };
    let mut rel = Vec::new();
    let (mut sum_abs, mut sum) = (0.0, 0.0);
    let (mut within, mut w2, mut w2r) = (0usize, 0usize, 0usize);
    for x in samples {
        let (r, truth) = (x.reading(), x.truth_m());
        for (slot, method) in s.by_method.iter_mut().zip(methods) {
            if let Some(d) = method(r) {
                slot.0 += (d - truth).abs();
                slot.1 += 1;
            }
        }
        match r.diameter_m {
            Some(d) => {
                let e = d - truth;
                sum_abs += e.abs();
                sum += e;
                rel.push(e.abs() / truth);
                within += (e.abs() <= tolerance * truth) as usize;
                w2 += (e.abs() <= 2.0 * r.uncertainty_m.unwrap_or(0.0)) as usize;
                w2r += (e.abs() <= 2.0 * r.random_uncertainty_m.unwrap_or(0.0)) as usize;
            }
            None => s.no_reading += 1,
        }
    }
    let k = rel.len().max(1) as f64;
    s.mae = sum_abs / k;
    s.bias = sum / k;
    s.within_tolerance = within as f64 / k;
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

/// One row per non-empty diameter bin (mm, half-open) and per distance bin (m), each made by
/// `row(label, bin)`; distance labels start with `distance_label`.
pub fn binned_rows<S: Evaluated>(
    samples: &[S],
    diameter_bins_mm: &[(f64, f64)],
    distance_bins_m: &[(f64, f64)],
    distance_label: &str,
    row: impl Fn(&str, &[&S]) -> String,
) -> String {
    let mut out = String::new();
    for &(lo, hi) in diameter_bins_mm {
        let b: Vec<&S> = samples
            .iter()
            .filter(|s| (lo..hi).contains(&(s.truth_m() * 1e3)))
            .collect();
        if !b.is_empty() {
            out += &row(&format!("d {lo:.0}–{:.0} mm", hi.floor()), &b);
        }
    }
    for &(lo, hi) in distance_bins_m {
        let b: Vec<&S> = samples
            .iter()
            .filter(|s| (lo..hi).contains(&s.distance_m()))
            .collect();
        if !b.is_empty() {
            out += &row(&format!("{distance_label} {lo:.1}–{hi:.1} m"), &b);
        }
    }
    out
}

/// The first 12 captures without a reading and the 5 largest errors (`decimals` places of
/// millimetres on the error and its σ).
pub fn failures_and_worst<S: Evaluated>(samples: &[S], decimals: usize) -> String {
    let mut out = String::new();
    let failures: Vec<&S> = samples
        .iter()
        .filter(|s| s.reading().error.is_some())
        .collect();
    if !failures.is_empty() {
        let _ = writeln!(out, "\nNo reading ({}):\n", failures.len());
        for f in failures.iter().take(12) {
            let _ = writeln!(
                out,
                "- seed {}: d {:.0} mm {}: {}",
                f.seed(),
                f.truth_m() * 1e3,
                f.placement(),
                f.reading().error.as_deref().unwrap_or("")
            );
        }
    }
    let mut worst: Vec<&S> = samples
        .iter()
        .filter(|s| s.reading().diameter_m.is_some())
        .collect();
    let error = |s: &S| (s.reading().diameter_m.unwrap_or(0.0) - s.truth_m()).abs();
    worst.sort_by(|a, b| error(b).total_cmp(&error(a)));
    let _ = writeln!(out, "\nLargest errors:\n");
    for w in worst.iter().take(5) {
        let r = w.reading();
        let d = r.diameter_m.unwrap_or(f64::NAN);
        let _ = writeln!(
            out,
            "- seed {}: truth {:.1} mm {} → {:.1} mm ({:+.decimals$} mm, ±{:.decimals$} mm, {}{}{})",
            w.seed(),
            w.truth_m() * 1e3,
            w.placement(),
            d * 1e3,
            (d - w.truth_m()) * 1e3,
            r.uncertainty_m.unwrap_or(f64::NAN) * 1e3,
            r.method.unwrap_or("?"),
            if r.flags.is_empty() { "" } else { "; " },
            r.flags.join(", ")
        );
    }
    out.push('\n');
    out
}
