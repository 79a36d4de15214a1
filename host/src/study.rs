//! Subpixel estimator study (thesis Table 5.1): bias and noise of every
//! [`tangent_core::peaks::Estimator`] on rendered laser-stripe profiles whose centre is known
//! exactly.
//!
//! A stripe is a Gaussian of standard deviation `σ` (pixels) integrated over each pixel's
//! width, so pixel `i` of a stripe centred on `μ` receives
//! `∫_{i-½}^{i+½} exp(-(u-μ)²/2σ²) du = σ√(π/2)·[erf((i+½-μ)/σ√2) − erf((i-½-μ)/σ√2)]`
//! (pixel centres at integers, the architecture's convention); the truth is then `μ` exactly,
//! with no sampling model to argue about. Each [`Condition`] degrades that profile the way the
//! sensor chain does (speckle, DC offset, additive noise, saturation, quantisation,
//! threshold, in that order). Everything random comes from a PCG64 seeded per
//! (condition, σ, offset) from [`SEED`], so the tables are reproducible bit for bit and
//! independent of evaluation order. The model and the results are discussed in
//! `docs/subpixel.md`; `tangent study subpixel` writes `docs/subpixel-study.md`.

use std::fmt::Write as _;

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;
use rayon::prelude::*;
use tangent_core::peaks::{self, Estimator, PeakError, DEFAULT_ESTIMATOR};
use tangent_core::real::Real;

/// Seed of every random draw of the study.
pub const SEED: u64 = 0x7A46_E417_5EED_0001;

/// Stripe standard deviations studied, in pixels.
pub const SIGMAS: [Real; 7] = [0.5, 0.7, 1.0, 1.5, 2.0, 3.0, 4.0];

/// Range of stripe σ over which the default estimator must meet its requirement
/// (the instrument's optics give σ ≈ 1–2 px; 0.7–3 px brackets focus and distance).
pub const REQUIREMENT_SIGMAS: (Real, Real) = (0.7, 3.0);

/// Required worst-case |bias| of the default estimator, pixels.
pub const REQUIRED_MAX_BIAS: Real = 0.02;

/// Required noise RMS of the default estimator relative to the best of the set.
pub const REQUIRED_NOISE_RATIO: Real = 1.5;

/// The estimators compared, in table order.
pub const ESTIMATORS: [Estimator; 7] = [
    Estimator::Gaussian3,
    Estimator::CentreOfMass { half_window: 2 },
    Estimator::CentreOfMass { half_window: 5 },
    Estimator::Parabolic,
    Estimator::BlaisRioux4,
    Estimator::BlaisRioux8,
    Estimator::GaussianFit,
];

/// Samples in a rendered profile; the stripe centre sits near the middle, so even σ = 4 px
/// (±5σ = ±20 px) and the widest estimator window fit.
const PROFILE_LEN: usize = 49;
/// Index of the pixel nearest the stripe centre.
const CENTRE: usize = PROFILE_LEN / 2;

/// Multiplicative, spatially correlated speckle (see [`speckle_factors`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Speckle {
    /// Standard deviation of the multiplicative factor (speckle contrast after the pixel
    /// and aperture averaging).
    pub contrast: Real,
    /// Correlation length: σ of the Gaussian kernel that correlates the factor, pixels.
    pub correlation: Real,
}

/// One imaging condition of the study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Condition {
    /// Short name (table column).
    pub name: &'static str,
    /// One-line description for the report.
    pub description: &'static str,
    /// Value of the brightest pixel of a stripe centred on a pixel, as a fraction of the
    /// sensor's full scale (> 1 saturates).
    pub amplitude: Real,
    /// Full scale in digital numbers when the profile is quantised (255, 1023), else `None`.
    pub full_scale_dn: Option<u32>,
    /// Constant added to every sample (fraction of full scale), e.g. ambient light left by an
    /// imperfect subtraction.
    pub dc: Real,
    /// Additive Gaussian noise σ as a fraction of [`Condition::amplitude`].
    pub noise: Real,
    /// Multiplicative speckle, if any.
    pub speckle: Option<Speckle>,
    /// Samples below this fraction of full scale are set to zero (the segmentation's
    /// threshold, which the curve extraction inherits).
    pub threshold: Real,
}

impl Condition {
    const IDEAL: Condition = Condition {
        name: "ideal",
        description: "exact pixel-integrated Gaussian, peak at 0.8 full scale",
        amplitude: 0.8,
        full_scale_dn: None,
        dc: 0.0,
        noise: 0.0,
        speckle: None,
        threshold: 0.0,
    };

    /// Whether the condition draws random numbers (then the study averages trials).
    pub fn is_random(&self) -> bool {
        self.noise > 0.0 || self.speckle.is_some()
    }
}

/// The conditions of the study, in table order.
pub fn conditions() -> Vec<Condition> {
    let i = Condition::IDEAL;
    vec![
        i,
        Condition {
            name: "8-bit",
            description: "quantised to 8 bits, peak 204 DN of 255",
            full_scale_dn: Some(255),
            ..i
        },
        Condition {
            name: "10-bit",
            description: "quantised to 10 bits, peak 818 DN of 1023",
            full_scale_dn: Some(1023),
            ..i
        },
        Condition {
            name: "saturated",
            description: "8 bits, peak driven to 1.5× full scale and clipped at 255",
            amplitude: 1.5,
            full_scale_dn: Some(255),
            ..i
        },
        Condition {
            name: "DC 10 %",
            description: "constant offset of 10 % of full scale added",
            dc: 0.1,
            ..i
        },
        Condition {
            name: "threshold",
            description: "8 bits, samples below 15 % of full scale set to 0",
            full_scale_dn: Some(255),
            threshold: 0.15,
            ..i
        },
        Condition {
            name: "noise 1 %",
            description: "additive Gaussian noise, σ = 1 % of the peak",
            noise: 0.01,
            ..i
        },
        Condition {
            name: "sat. + noise",
            description: "peak at 1.5× full scale, clipped, plus noise σ = 1 % of the peak",
            amplitude: 1.5,
            noise: 0.01,
            ..i
        },
        Condition {
            name: "speckle",
            description: "multiplicative speckle, contrast 5 %, correlation 1 px",
            speckle: Some(Speckle {
                contrast: 0.05,
                correlation: 1.0,
            }),
            ..i
        },
    ]
}

/// Study size: sub-pixel offsets spanning one pixel, and noise trials per offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StudyConfig {
    /// Offsets `-½ + (k+½)/offsets`, `k = 0..offsets`: a full pixel, symmetric about 0.
    pub offsets: usize,
    /// Trials per offset for random conditions (deterministic ones use 1).
    pub trials: usize,
}

impl Default for StudyConfig {
    fn default() -> Self {
        StudyConfig {
            offsets: 20,
            trials: 400,
        }
    }
}

/// Bias and noise of one estimator under one condition at one stripe width.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    /// Mean over offsets of the mean error (signed), pixels.
    pub mean_bias: Real,
    /// Largest |mean error| over the offsets, pixels.
    pub max_bias: Real,
    /// RMS over offsets of the standard deviation over trials, pixels (0 when deterministic).
    pub noise_rms: Real,
    /// Fraction of the profiles on which the estimator returned an error.
    pub failures: Real,
    /// The most frequent error, if any.
    pub error: Option<PeakError>,
}

/// Result of the whole study: `cells[condition][sigma][estimator]`.
#[derive(Debug, Clone)]
pub struct Study {
    /// The configuration used.
    pub config: StudyConfig,
    /// Conditions, as [`conditions`].
    pub conditions: Vec<Condition>,
    /// Cells indexed by condition, σ ([`SIGMAS`]), estimator ([`ESTIMATORS`]).
    pub cells: Vec<Vec<Vec<Cell>>>,
}

/// Standard normal CDF difference over a pixel: the integral of `exp(-(u-μ)²/2σ²)` over
/// `[i-½, i+½]`.
// `f64::from` is a no-op while the host's `Real` is f64, and keeps this right if it is not.
#[allow(clippy::useless_conversion)]
fn pixel_integral(i: Real, mu: Real, sigma: Real) -> Real {
    let s = sigma * std::f64::consts::SQRT_2 as Real;
    let k = sigma * (std::f64::consts::PI as Real / 2.0).sqrt();
    let e = |x: Real| libm::erf(f64::from(x)) as Real;
    k * (e((i + 0.5 - mu) / s) - e((i - 0.5 - mu) / s))
}

/// Speckle factors `m_i = max(0, 1 + C·g_i)`, `g` unit-variance Gaussian noise correlated by
/// a Gaussian kernel of σ = `correlation` px (taps normalised so that `Σh² = 1`).
///
/// Model: the stripe's intensity along a column is the ideal Gaussian times a random
/// interference pattern. Fully developed speckle has contrast 1, but the pixel area, the lens
/// aperture and the laser's spectral width average several grains per pixel, which leaves
/// a contrast `C` of a few percent and a grain about a pixel wide; the factor is drawn per
/// pixel, correlated over `correlation` pixels, and is the same whether the stripe is
/// bright or faint (multiplicative), so more light does not average it away.
fn speckle_factors(rng: &mut Pcg64, s: Speckle, out: &mut [Real]) {
    let reach = (3.0 * s.correlation).ceil() as usize;
    let taps: Vec<Real> = (0..=2 * reach)
        .map(|k| {
            let d = k as Real - reach as Real;
            (-d * d / (2.0 * s.correlation * s.correlation)).exp()
        })
        .collect();
    let norm = taps.iter().map(|h| h * h).sum::<Real>().sqrt();
    let white: Vec<Real> = (0..out.len() + 2 * reach)
        .map(|_| StandardNormal.sample(rng))
        .collect();
    for (i, m) in out.iter_mut().enumerate() {
        let g: Real = taps
            .iter()
            .zip(&white[i..])
            .map(|(h, w)| h * w)
            .sum::<Real>()
            / norm;
        *m = (1.0 + s.contrast * g).max(0.0);
    }
}

/// Renders one profile of `cond` with the stripe centred on `mu` into `out`
/// (values in DN when quantised, fractions of full scale otherwise); returns the saturation
/// level in the same unit.
pub fn render(cond: &Condition, sigma: Real, mu: Real, rng: &mut Pcg64, out: &mut [Real]) -> Real {
    let scale = cond.amplitude / pixel_integral(0.0, 0.0, sigma);
    let mut speckle = vec![1.0; out.len()];
    if let Some(s) = cond.speckle {
        speckle_factors(rng, s, &mut speckle);
    }
    let fs = cond.full_scale_dn.map_or(1.0, |n| n as Real);
    for (i, v) in out.iter_mut().enumerate() {
        let mut x = scale * pixel_integral(i as Real, mu, sigma) * speckle[i] + cond.dc;
        if cond.noise > 0.0 {
            let n: Real = StandardNormal.sample(rng);
            x += cond.noise * cond.amplitude * n;
        }
        // Sensor: clip to [0, full scale], then quantise, then the threshold.
        x = x.clamp(0.0, 1.0) * fs;
        if cond.full_scale_dn.is_some() {
            x = x.round();
        }
        if x < cond.threshold * fs {
            x = 0.0;
        }
        *v = x;
    }
    fs
}

/// Index of the largest sample (the first of equal ones); the study then moves to the middle
/// of a saturated plateau with [`peaks::plateau_centre`], as the curve extraction does.
fn argmax(p: &[Real]) -> usize {
    let mut best = 0;
    for (i, &x) in p.iter().enumerate() {
        if x > p[best] {
            best = i;
        }
    }
    best
}

/// Seed of one (condition, σ, offset) stream, so that results do not depend on the order
/// (or the parallelism) of evaluation.
fn stream_seed(c: usize, s: usize, k: usize) -> u64 {
    SEED ^ ((c as u64) << 40) ^ ((s as u64) << 20) ^ (k as u64)
}

/// Runs every estimator on `cond` at stripe width `sigma`.
fn run_cell(cond: &Condition, ci: usize, si: usize, sigma: Real, cfg: &StudyConfig) -> Vec<Cell> {
    let trials = if cond.is_random() { cfg.trials } else { 1 };
    let ne = ESTIMATORS.len();
    // Per estimator: Σ over offsets of mean error, max |mean error|, Σ variance, failures.
    let mut sum_bias = vec![0.0; ne];
    let mut max_bias: Vec<Real> = vec![0.0; ne];
    let mut sum_var = vec![0.0; ne];
    let mut counted_offsets = vec![0usize; ne];
    let mut fails = vec![0usize; ne];
    let mut first_error: Vec<Option<PeakError>> = vec![None; ne];
    let mut profile = [0.0; PROFILE_LEN];
    // errors[e][t]: error of estimator e in trial t at the current offset.
    let mut errors: Vec<Vec<Real>> = vec![Vec::with_capacity(trials); ne];
    for k in 0..cfg.offsets {
        let offset = -0.5 + (k as Real + 0.5) / cfg.offsets as Real;
        let mu = CENTRE as Real + offset;
        let mut rng = Pcg64::seed_from_u64(stream_seed(ci, si, k));
        errors.iter_mut().for_each(Vec::clear);
        for _ in 0..trials {
            let sat = render(cond, sigma, mu, &mut rng, &mut profile);
            let peak = peaks::plateau_centre(&profile, argmax(&profile));
            for (e, est) in ESTIMATORS.iter().enumerate() {
                match peaks::locate_with_saturation(&profile, peak, *est, sat) {
                    Ok(p) => errors[e].push(p.position - mu),
                    Err(err) => {
                        fails[e] += 1;
                        first_error[e].get_or_insert(err);
                    }
                }
            }
        }
        for e in 0..ne {
            let n = errors[e].len();
            if n == 0 {
                continue;
            }
            let mean = errors[e].iter().sum::<Real>() / n as Real;
            let var = if n > 1 {
                errors[e]
                    .iter()
                    .map(|x| (x - mean) * (x - mean))
                    .sum::<Real>()
                    / (n - 1) as Real
            } else {
                0.0
            };
            sum_bias[e] += mean;
            max_bias[e] = max_bias[e].max(mean.abs());
            sum_var[e] += var;
            counted_offsets[e] += 1;
        }
    }
    (0..ne)
        .map(|e| {
            let n = counted_offsets[e].max(1) as Real;
            Cell {
                mean_bias: sum_bias[e] / n,
                max_bias: if counted_offsets[e] == 0 {
                    Real::NAN
                } else {
                    max_bias[e]
                },
                noise_rms: (sum_var[e] / n).sqrt(),
                failures: fails[e] as Real / (cfg.offsets * trials) as Real,
                error: first_error[e],
            }
        })
        .collect()
}

/// Runs the whole study (parallel over conditions × σ; deterministic).
pub fn run(config: StudyConfig) -> Study {
    let conds = conditions();
    let jobs: Vec<(usize, usize)> = (0..conds.len())
        .flat_map(|c| (0..SIGMAS.len()).map(move |s| (c, s)))
        .collect();
    let results: Vec<Vec<Cell>> = jobs
        .par_iter()
        .map(|&(c, s)| run_cell(&conds[c], c, s, SIGMAS[s], &config))
        .collect();
    let mut cells = vec![Vec::with_capacity(SIGMAS.len()); conds.len()];
    for ((c, _), r) in jobs.into_iter().zip(results) {
        cells[c].push(r);
    }
    Study {
        config,
        conditions: conds,
        cells,
    }
}

/// Outcome of the default estimator's requirement on one (condition, σ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RequirementRow {
    /// Condition name.
    pub condition: &'static str,
    /// Stripe σ, px.
    pub sigma: Real,
    /// Worst-case |bias| of the default, px.
    pub max_bias: Real,
    /// Noise RMS of the default, px.
    pub noise_rms: Real,
    /// Smallest noise RMS of the set (estimators that never failed), px.
    pub best_noise_rms: Real,
    /// Whether this row meets the requirement.
    pub ok: bool,
}

/// Checks the default estimator's requirement on the conditions with 1 % noise (with and
/// without saturation) over [`REQUIREMENT_SIGMAS`]: worst-case |bias| ≤ [`REQUIRED_MAX_BIAS`]
/// and noise RMS ≤ [`REQUIRED_NOISE_RATIO`] × the best of the set.
pub fn requirement(study: &Study) -> Vec<RequirementRow> {
    let d = ESTIMATORS
        .iter()
        .position(|e| *e == DEFAULT_ESTIMATOR)
        .expect("default in set");
    let mut rows = Vec::new();
    for (ci, cond) in study.conditions.iter().enumerate() {
        if cond.noise != 0.01 {
            continue;
        }
        for (si, &sigma) in SIGMAS.iter().enumerate() {
            if sigma < REQUIREMENT_SIGMAS.0 || sigma > REQUIREMENT_SIGMAS.1 {
                continue;
            }
            let cells = &study.cells[ci][si];
            let best = cells
                .iter()
                .filter(|c| c.failures == 0.0)
                .map(|c| c.noise_rms)
                .fold(Real::INFINITY, Real::min);
            let c = cells[d];
            let ok = c.failures == 0.0
                && c.max_bias <= REQUIRED_MAX_BIAS
                && c.noise_rms <= REQUIRED_NOISE_RATIO * best;
            rows.push(RequirementRow {
                condition: cond.name,
                sigma,
                max_bias: c.max_bias,
                noise_rms: c.noise_rms,
                best_noise_rms: best,
                ok,
            });
        }
    }
    rows
}

fn estimator_label(e: &Estimator) -> String {
    match e {
        Estimator::CentreOfMass { half_window } => format!("centre of mass ±{half_window}"),
        other => other.name().to_string(),
    }
}

fn fmt_cell(c: &Cell) -> String {
    if c.failures >= 1.0 {
        return "fails".into();
    }
    let mut s = format!(
        "{:+.3} / {:.3} / {:.3}",
        c.mean_bias, c.max_bias, c.noise_rms
    );
    if c.failures > 0.0 {
        let _ = write!(s, " ({:.1} % fail)", 100.0 * c.failures);
    }
    s
}

/// Formats the study as the Markdown report `docs/subpixel-study.md`.
pub fn to_markdown(study: &Study) -> String {
    let mut m = String::new();
    let in_req = |s: Real| s >= REQUIREMENT_SIGMAS.0 && s <= REQUIREMENT_SIGMAS.1;
    let _ = writeln!(m, "# Subpixel estimator study (generated)\n");
    let _ = writeln!(
        m,
        "Generated by `tangent study subpixel --out docs/subpixel-study.md`; do not edit by \
         hand. Method and discussion: `docs/subpixel.md`.\n"
    );
    let _ = writeln!(
        m,
        "Stripes are Gaussians of standard deviation σ integrated over each pixel (exact erf \
         rendering), centred at {} sub-pixel offsets spanning one pixel; random conditions \
         average {} trials per offset (PCG64, seed `{:#x}`). For each estimator: **mean bias** \
         (signed mean error over offsets), **worst |bias|** (largest |mean error| over \
         offsets) and **noise RMS** (RMS over offsets of the standard deviation over trials), \
         all in pixels. The peak index given to every estimator is the profile's arg-max, moved \
         to the middle of a saturated plateau, as in the curve extraction; saturated samples are those at full scale.\n",
        study.config.offsets, study.config.trials, SEED
    );
    let _ = writeln!(m, "## Conditions\n");
    let _ = writeln!(m, "| condition | model |\n|---|---|");
    for c in &study.conditions {
        let _ = writeln!(m, "| {} | {} |", c.name, c.description);
    }
    // Summary (Table 5.1 style): worst-case over σ in the requirement range.
    let _ = writeln!(
        m,
        "\n## Summary: worst case over σ = {}–{} px\n\nEach cell: worst |bias| / noise RMS \
         (px), the largest over σ ∈ {{{}}}, over the profiles where the estimator succeeded; \
         `(≤ x % fail)` gives its largest failure rate, `fails` that it failed on every \
         profile at some σ.\n",
        REQUIREMENT_SIGMAS.0,
        REQUIREMENT_SIGMAS.1,
        SIGMAS
            .iter()
            .filter(|s| in_req(**s))
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = write!(m, "| estimator |");
    for c in &study.conditions {
        let _ = write!(m, " {} |", c.name);
    }
    let _ = write!(m, "\n|---|");
    for _ in &study.conditions {
        let _ = write!(m, "---|");
    }
    let _ = writeln!(m);
    for (e, est) in ESTIMATORS.iter().enumerate() {
        let mark = if *est == DEFAULT_ESTIMATOR {
            " (default)"
        } else {
            ""
        };
        let _ = write!(m, "| {}{} |", estimator_label(est), mark);
        for ci in 0..study.conditions.len() {
            let mut worst: Real = 0.0;
            let mut noise: Real = 0.0;
            let mut fail: Real = 0.0;
            let mut all_failed = false;
            for (si, s) in SIGMAS.iter().enumerate() {
                if !in_req(*s) {
                    continue;
                }
                let c = &study.cells[ci][si][e];
                fail = fail.max(c.failures);
                all_failed |= c.failures >= 1.0;
                if c.failures < 1.0 {
                    worst = worst.max(c.max_bias);
                    noise = noise.max(c.noise_rms);
                }
            }
            if all_failed {
                let _ = write!(m, " fails |");
            } else if fail > 0.0 {
                let _ = write!(
                    m,
                    " {worst:.3} / {noise:.3} (≤ {:.1} % fail) |",
                    100.0 * fail
                );
            } else {
                let _ = write!(m, " {worst:.3} / {noise:.3} |");
            }
        }
        let _ = writeln!(m);
    }
    // Requirement of the default estimator.
    let rows = requirement(study);
    let all_ok = rows.iter().all(|r| r.ok);
    let _ = writeln!(
        m,
        "\n## Default estimator requirement\n\n`{}`: worst |bias| ≤ {} px and noise RMS ≤ {}× \
         the best of the set, at 1 % noise, σ = {}–{} px, with and without saturation: \
         **{}**.\n",
        estimator_label(&DEFAULT_ESTIMATOR),
        REQUIRED_MAX_BIAS,
        REQUIRED_NOISE_RATIO,
        REQUIREMENT_SIGMAS.0,
        REQUIREMENT_SIGMAS.1,
        if all_ok { "met" } else { "NOT met" }
    );
    let _ = writeln!(
        m,
        "| condition | σ (px) | worst \\|bias\\| | noise RMS | best RMS of set | ratio | ok |\n\
         |---|---|---|---|---|---|---|"
    );
    for r in &rows {
        let _ = writeln!(
            m,
            "| {} | {} | {:.4} | {:.4} | {:.4} | {:.2} | {} |",
            r.condition,
            r.sigma,
            r.max_bias,
            r.noise_rms,
            r.best_noise_rms,
            r.noise_rms / r.best_noise_rms,
            if r.ok { "yes" } else { "**no**" }
        );
    }
    // Detail per condition.
    let _ = writeln!(
        m,
        "\n## Detail per condition\n\nEach cell: mean bias / worst |bias| / noise RMS (px).\n"
    );
    for (ci, cond) in study.conditions.iter().enumerate() {
        let _ = writeln!(m, "### {} — {}\n", cond.name, cond.description);
        let _ = write!(m, "| estimator |");
        for s in SIGMAS {
            let _ = write!(m, " σ = {s} |");
        }
        let _ = write!(m, "\n|---|");
        for _ in SIGMAS {
            let _ = write!(m, "---|");
        }
        let _ = writeln!(m);
        for (e, est) in ESTIMATORS.iter().enumerate() {
            let _ = write!(m, "| {} |", estimator_label(est));
            for si in 0..SIGMAS.len() {
                let _ = write!(m, " {} |", fmt_cell(&study.cells[ci][si][e]));
            }
            let _ = writeln!(m);
        }
        let errs: Vec<String> = ESTIMATORS
            .iter()
            .enumerate()
            .filter_map(|(e, est)| {
                (0..SIGMAS.len())
                    .find_map(|si| study.cells[ci][si][e].error)
                    .map(|err| format!("{}: {}", estimator_label(est), err))
            })
            .collect();
        if !errs.is_empty() {
            let _ = writeln!(m, "\nFirst error seen: {}.", errs.join("; "));
        }
        let _ = writeln!(m);
    }
    m
}
