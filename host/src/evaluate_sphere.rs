//! Accuracy of the sphere instrument against the simulator's truth (`docs/accuracy.md`,
//! "Spheres"): random balls ([`crate::simulate::sphere_corpus::random_sphere`]) measured end to end by the core, tabulated by
//! diameter and distance with the three methods side by side and a naive baseline
//! ([`kasa_baseline`]: the stems' naive segmentation, Kåsa's circle per plane and
//! `R² = r² + h²`).

use std::fmt::Write as _;
use std::path::Path;

use rayon::prelude::*;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;

use tangent_core::solvers::circle::fit_kasa;
use tangent_core::solvers::sphere_sections::{initial_sphere, Section};

use crate::baseline::stripe_points;
use crate::calibration_draw;
use crate::capture::Capture;
use crate::evaluate::table::{
    binned_rows, error_stats, failures_and_worst, ErrorStats, Evaluated, MethodDiameter,
};
use crate::measure::{measure_loaded, sphere_params, Reading};
use crate::simulate::simulate;
use crate::simulate::sphere_corpus::{Finish, RandomBall};
use crate::truth::Object;

/// One evaluated ball.
#[derive(Debug, Clone)]
pub struct SphereSample {
    /// Simulator seed.
    pub seed: u64,
    /// What the seed drew.
    pub ball: RandomBall,
    /// True diameter (m).
    pub truth_m: f64,
    /// True distance of the centre from the camera (m).
    pub distance_m: f64,
    /// The reading.
    pub reading: Reading,
    /// The naive baseline's diameter (m), or why it gave none ([`kasa_baseline`]).
    pub baseline: Result<f64, String>,
}

/// The naive baseline on a sphere capture: the stems' naive stripe points
/// ([`crate::baseline::stripe_points`]: global threshold, per-column centre of mass), Kåsa's
/// algebraic circle per plane, and the sphere through the two outermost sections by
/// `R² = rᵢ² + hᵢ²` ([`initial_sphere`], exact for parallel planes): no robust fit, no
/// weights, no joint fit. Returns the diameter (m).
pub fn kasa_baseline(capture: &Capture) -> Result<f64, String> {
    let cal = &capture.calibration;
    let per_plane = stripe_points(capture, None).map_err(|e| e.to_string())?;
    let mut sections = Vec::new();
    for (plane, points) in cal.planes.iter().zip(&per_plane) {
        if points.len() < 3 {
            continue;
        }
        let circle = fit_kasa(points).map_err(|e| e.to_string())?;
        let (a, b) = plane.plane_axes();
        sections.push(Section {
            origin: plane.source,
            axes: (a, b, plane.normal),
            centre: circle.centre,
            radius: circle.radius,
            covariance: tangent_core::real::Mat3::identity(),
            arc: 0.0,
        });
    }
    if sections.len() < 2 {
        return Err(format!(
            "{} planes with 3 stripe points (2 needed)",
            sections.len()
        ));
    }
    let sphere = initial_sphere(&sections).map_err(|e| e.to_string())?;
    Ok(2.0 * sphere.radius as f64)
}

/// Simulates and measures `count` random balls from `first_seed`, in parallel. With `cache`,
/// each ball's capture is read from `cache/<seed>` when there and written there otherwise
/// (re-measuring a set after a solver change without simulating it again). Each ball
/// is measured with `calibration` ([`crate::calibration_draw::CalibrationUsed`]): the exact
/// one it was rendered with, one off by a draw from the calibration σ the sphere solver
/// states (so that *within 2σ* checks the whole stated σ), or that draw refined on a
/// reference ball.
pub fn run(
    first_seed: u64,
    count: u64,
    cache: Option<&Path>,
    calibration: calibration_draw::CalibrationUsed<'_>,
) -> anyhow::Result<Vec<SphereSample>> {
    let config = PipelineConfig::default();
    let params = CylinderParams::default();
    (first_seed..first_seed + count)
        .into_par_iter()
        .map(|seed| {
            let ball = RandomBall::draw(seed);
            let spec = ball.spec();
            let dir = cache.map(|c| c.join(seed.to_string()));
            let capture = match &dir {
                Some(d) if d.join("capture.toml").exists() => Capture::read(d)?,
                _ => {
                    let (capture, _) = simulate(&spec)?;
                    if let Some(d) = &dir {
                        capture.write(d)?;
                    }
                    capture
                }
            };
            let capture = calibration
                .apply(&capture, &sphere_params(&params).noise, seed)?
                .unwrap_or(capture);
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
                ball,
                truth_m,
                distance_m,
                reading: outcome.reading,
                baseline: kasa_baseline(&capture),
            })
        })
        .collect()
}

impl Evaluated for SphereSample {
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
        format!(
            "{}, centre at {:.2} m",
            if self.ball.finish == Finish::Shiny {
                "steel"
            } else {
                "matt"
            },
            self.distance_m
        )
    }
}

/// The method columns: joint fit, sections, three-tangent.
const SPHERE_METHODS: [MethodDiameter; 3] = [
    |r| r.fit_diameter_m,
    |r| r.sections_diameter_m,
    |r| r.three_tangent_diameter_m,
];

/// Statistics of `samples` (within 0.5 %, the target).
pub fn stats(samples: &[&SphereSample]) -> ErrorStats {
    error_stats(samples, &SPHERE_METHODS, 0.005)
}

const DIAMETER_BINS_MM: [(f64, f64); 4] =
    [(20.0, 50.0), (50.0, 100.0), (100.0, 200.0), (200.0, 400.01)];
const DISTANCE_BINS_M: [(f64, f64); 4] = [(0.3, 0.6), (0.6, 1.0), (1.0, 1.5), (1.5, 2.1)];

/// The naive baseline on `samples`: its MAE (m) and its share within 0.5 % over the balls it
/// read, and their count.
pub fn baseline_stats(samples: &[&SphereSample]) -> (f64, f64, usize) {
    let errors: Vec<(f64, f64)> = samples
        .iter()
        .filter_map(|s| s.baseline.as_ref().ok().map(|d| (d - s.truth_m, s.truth_m)))
        .collect();
    let n = errors.len();
    if n == 0 {
        return (0.0, 0.0, 0);
    }
    let mae = errors.iter().map(|(e, _)| e.abs()).sum::<f64>() / n as f64;
    let within = errors.iter().filter(|(e, d)| e.abs() <= 0.005 * d).count() as f64 / n as f64;
    (mae, within, n)
}

fn row(label: &str, samples: &[&SphereSample]) -> String {
    let s = stats(samples);
    let (b_mae, b_within, b_n) = baseline_stats(samples);
    let mm = |v: f64| format!("{:.2}", v * 1e3);
    let m = |k: usize| format!("{} ({})", mm(s.by_method[k].0), s.by_method[k].1);
    format!(
        "| {label} | {} | {} | {} | {} | {} | {} | {} | {} ({b_n}, {:.0} %) | {:.0} % | {:.2} % | {:.0} % | {:.0} % |\n",
        s.n,
        s.no_reading,
        mm(s.mae),
        mm(s.bias),
        m(0),
        m(1),
        m(2),
        mm(b_mae),
        b_within * 100.0,
        s.within_tolerance * 100.0,
        s.p95_relative * 100.0,
        s.within_2sigma * 100.0,
        s.within_2sigma_random * 100.0
    )
}

const HEADER: &str = "| bin | n | no reading | MAE mm | bias mm | joint fit MAE mm (n) | sections MAE mm (n) | three-tangent MAE mm (n) | naive Kåsa MAE mm (n, within 0.5 %) | within 0.5 % | P95 \\|err\\|/d | within 2σ | within 2σ random |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";

/// Whether a ball is in the target subset (d ≥ 50 mm, centre ≤ 1.5 m).
pub fn in_target(s: &SphereSample) -> bool {
    s.truth_m >= 0.05 && s.distance_m <= 1.5
}

/// A Markdown section: the target subset, its matt and steel balls, everything, then per
/// diameter and per distance bin; the refusals and the largest errors.
pub fn section(title: &str, samples: &[SphereSample]) -> String {
    let mut out = format!("### {title}\n\n{HEADER}");
    let target: Vec<&SphereSample> = samples.iter().filter(|s| in_target(s)).collect();
    out += &row("**target: d ≥ 50 mm, ≤ 1.5 m**", &target);
    for (finish, label) in [
        (Finish::Matt, "target, matt"),
        (Finish::Shiny, "target, steel"),
    ] {
        let b: Vec<&SphereSample> = target
            .iter()
            .copied()
            .filter(|s| s.ball.finish == finish)
            .collect();
        out += &row(label, &b);
    }
    let all: Vec<&SphereSample> = samples.iter().collect();
    out += &row("all", &all);
    out += &binned_rows(samples, &DIAMETER_BINS_MM, &DISTANCE_BINS_M, "centre", row);
    out + &failures_and_worst(samples, 2)
}

/// One line per ball (comma-separated, a header first): the draw, the reading, each method's
/// diameter, for analyses beyond the tables (`tangent evaluate --sphere-csv`).
pub fn csv(samples: &[SphereSample]) -> String {
    let mut out = String::from(
        "seed,truth_mm,distance_m,across_m,shift,steel,floor,method,diameter_mm,error_mm,\
         sigma_mm,sigma_random_mm,fit_mm,sections_mm,three_tangent_mm,kasa_mm,points,flags,error\n",
    );
    let mm = |v: Option<f64>| v.map_or(String::new(), |v| format!("{:.4}", v * 1e3));
    for s in samples {
        let r = &s.reading;
        let _ = writeln!(
            out,
            "{},{:.3},{:.4},{:.4},{:.3},{},{},{},{},{},{},{},{},{},{},{},{},{},\"{}\"",
            s.seed,
            s.truth_m * 1e3,
            s.distance_m,
            s.ball.x,
            s.ball.shift,
            (s.ball.finish == Finish::Shiny) as u8,
            s.ball.on_floor as u8,
            r.method.unwrap_or(""),
            mm(r.diameter_m),
            mm(r.diameter_m.map(|d| d - s.truth_m)),
            mm(r.uncertainty_m),
            mm(r.random_uncertainty_m),
            mm(r.fit_diameter_m),
            mm(r.sections_diameter_m),
            mm(r.three_tangent_diameter_m),
            mm(s.baseline.as_ref().ok().copied()),
            r.points.map_or(String::new(), |p| p.to_string()),
            r.flags.join(" "),
            r.error.as_deref().unwrap_or("").replace('"', "'")
        );
    }
    out
}
