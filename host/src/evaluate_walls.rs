//! Accuracy of the wall instrument against the simulator's truth (`docs/accuracy.md`,
//! "Walls"): random rooms ([`random_room`]: single walls, corners, niches; four materials,
//! matt and glossy, clutter, a tilted camera) measured end to end by the core, each reading
//! (angle between two walls, wall to plumb, distance between parallel walls, segment length)
//! tabulated by distance beside the naive baseline: the same walls' points fitted by
//! unweighted principal components, the segment between its outermost lit points.

use std::fmt::Write as _;

use rayon::prelude::*;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::real::Vec3;
use tangent_core::solvers::plane_pca::{fit_plane, normal_angle, parallel_distance, PlaneFit};
use tangent_core::solvers::stem::CylinderParams;
use tangent_core::solvers::walls::{WallParams, WallSolution};

use crate::calibration_draw::CalibrationUsed;
use crate::evaluate::SeedSet;
use crate::measure::{measure_loaded, Outcome, Solved};
use crate::measure_wall::WallReport;
use crate::simulate::simulate;
use crate::simulate::wall_corpus::{random_room, RoomDraw, RoomKind};

/// Distances of the rooms (metres): the envelope, 0.5–5 m.
pub const RANGE_M: (f64, f64) = (0.5, 5.0);

/// First seed of a set's rooms: tuning from 3 000 000, report from 9 000 000.
pub fn first_seed(set: SeedSet) -> u64 {
    match set {
        SeedSet::Tuning => 3_000_000,
        SeedSet::Report => 9_000_000,
    }
}

/// The baseline's readings of one capture (degrees, millimetres).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Baseline {
    /// Angle between the corner's two walls.
    pub corner_deg: Option<f64>,
    /// The aimed wall's deviation from the plumb.
    pub plumb_deg: Option<f64>,
    /// Distance between the parallel walls.
    pub parallel_mm: Option<f64>,
    /// Segment length, outermost lit point to outermost lit point.
    pub segment_mm: Option<f64>,
}

/// One evaluated room.
#[derive(Debug, Clone)]
pub struct WallSample {
    /// Simulator seed.
    pub seed: u64,
    /// What the seed drew.
    pub draw: RoomDraw,
    /// Tangent's report (with the truth), or why there is none.
    pub report: Result<WallReport, String>,
    /// The baseline's readings on the same points.
    pub baseline: Baseline,
}

/// Simulates and measures `count` random rooms from `first_seed`, in parallel; `crossing`:
/// with the head's third, crossing line (the same rooms otherwise). Each room is measured
/// with `calibration` ([`CalibrationUsed`]: the exact one, or off by a draw from the
/// calibration σ, or that draw refined on a reference ball); the baseline reads Tangent's
/// points.
pub fn run(
    first_seed: u64,
    count: u64,
    crossing: bool,
    calibration: CalibrationUsed<'_>,
) -> anyhow::Result<Vec<WallSample>> {
    let config = PipelineConfig::default();
    let params = CylinderParams::default();
    (first_seed..first_seed + count)
        .into_par_iter()
        .map(|seed| {
            let (spec, draw) = random_room(seed, RoomKind::of_seed(seed), RANGE_M, crossing);
            let (capture, _) = simulate(&spec)?;
            let capture = calibration
                .apply(&capture, &params.noise, seed)?
                .unwrap_or(capture);
            let outcome =
                measure_loaded(&capture, &format!("seed {seed}"), None, &config, &params)?;
            let gravity = capture
                .meta
                .accelerometer
                .as_ref()
                .and_then(|a| a.gravity_camera().ok())
                .map(|(g, _)| Vec3::new(g[0], g[1], g[2]));
            let baseline = baseline(&outcome, gravity);
            let report = match (outcome.reading.wall, outcome.reading.error) {
                (Some(w), _) => Ok(w),
                (None, e) => Err(e.unwrap_or_else(|| "no reading".into())),
            };
            Ok(WallSample {
                seed,
                draw,
                report,
                baseline,
            })
        })
        .collect()
}

/// The naive baseline on Tangent's own segmentation: each wall's points (untrimmed) fitted by
/// unweighted principal components, the same wall pairs, the segment between the outermost
/// points of the aimed wall on the segment's line.
fn baseline(outcome: &Outcome, gravity: Option<Vec3>) -> Baseline {
    let Ok(Solved::Wall(m)) = &outcome.result else {
        return Baseline::default();
    };
    let s: &WallSolution = &m.solution;
    let curve = |k: usize| m.profile.points(&outcome.points, k);
    // A run outside its curve's points would be a broken buffer: no baseline then.
    if s.runs
        .iter()
        .any(|r| r.end as usize > curve(r.curve as usize).len())
    {
        return Baseline::default();
    }
    let planes: Vec<Option<PlaneFit>> = (0..s.walls.len())
        .map(|w| {
            let pts = s
                .runs
                .iter()
                .filter(|r| r.wall == Some(w as u8))
                .flat_map(|r| curve(r.curve as usize)[r.start as usize..r.end as usize].iter())
                .map(|&p| (p, 1.0));
            fit_plane(pts).ok()
        })
        .collect();
    let corner_deg = s.corner.and_then(|c| {
        let (a, b) = (planes[c.walls.0]?, planes[c.walls.1]?);
        Some(180.0 - normal_angle(&a, &b).value.to_degrees())
    });
    let parallel_mm = s.parallel.and_then(|_| {
        let n = s.walls.len();
        let parallel_max = WallParams::default().parallel_max;
        let (a, b) = (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .find(|&(a, b)| {
                normal_angle(&s.walls[a].plane, &s.walls[b].plane).value <= parallel_max
            })?;
        Some(parallel_distance(&planes[a]?, &planes[b]?).value.abs() * 1e3)
    });
    let plumb_deg = gravity
        .zip(planes.get(s.aimed).copied().flatten())
        .map(|(g, p)| {
            let g = g.normalize();
            p.normal.dot(&g).clamp(-1.0, 1.0).asin().to_degrees()
        });
    let segment_mm = s.segment.filter(|g| g.bounded()).and_then(|g| {
        let mine = |r: &&tangent_core::solvers::walls::Run| {
            r.curve as usize == g.curve && r.wall == Some(s.aimed as u8)
        };
        let first = s.runs.iter().filter(mine).min_by_key(|r| r.start)?;
        let last = s.runs.iter().filter(mine).max_by_key(|r| r.end)?;
        let pts = curve(g.curve);
        Some((pts[last.end as usize - 1] - pts[first.start as usize]).norm() * 1e3)
    });
    Baseline {
        corner_deg,
        plumb_deg,
        parallel_mm,
        segment_mm,
    }
}

/// One of the four readings: how to take it from a sample.
struct Quantity {
    name: &'static str,
    /// Short name (CSV).
    key: &'static str,
    unit: &'static str,
    /// The rooms that show it.
    kind: fn(RoomKind) -> bool,
    /// Tangent's value and 1σ, and the truth.
    tangent: fn(&WallReport) -> Option<(f64, f64, f64)>,
    /// The baseline's value.
    baseline: fn(&Baseline) -> Option<f64>,
    /// The target on |error| at 95 % for a true value `t` (the issue's), and up to which
    /// distance it applies (m).
    target: fn(f64) -> f64,
    target_range_m: f64,
    target_text: &'static str,
}

const QUANTITIES: [Quantity; 4] = [
    Quantity {
        name: "Angle between two walls",
        key: "corner_deg",
        unit: "°",
        kind: |k| k == RoomKind::Corner,
        tangent: |r| {
            let c = r.corner.as_ref()?;
            Some((
                c.angle_deg.value,
                c.angle_deg.sigma,
                r.truth.as_ref()?.corner_deg?,
            ))
        },
        baseline: |b| b.corner_deg,
        target: |_| 0.1,
        target_range_m: 3.0,
        target_text: "≤ 0.1° (95 %) up to 3 m",
    },
    Quantity {
        name: "Wall to plumb",
        key: "plumb_deg",
        unit: "°",
        kind: |k| k != RoomKind::Niche,
        tangent: |r| {
            let p = r.plumb_deg?;
            Some((p.value, p.sigma, r.truth.as_ref()?.plumb_deg?))
        },
        baseline: |b| b.plumb_deg,
        target: |_| 0.15,
        target_range_m: 3.0,
        target_text: "≤ 0.15° (95 %) up to 3 m",
    },
    Quantity {
        name: "Distance between parallel walls (one capture: a niche's depth)",
        key: "parallel_mm",
        unit: "mm",
        kind: |k| k == RoomKind::Niche,
        tangent: |r| {
            let p = r.parallel_mm?;
            Some((p.value, p.sigma, r.truth.as_ref()?.parallel_mm?))
        },
        baseline: |b| b.parallel_mm,
        target: |_| 2.0,
        target_range_m: 3.0,
        target_text: "≤ 2 mm (95 %) up to 3 m",
    },
    Quantity {
        name: "Segment length (a niche's width, edge to edge)",
        key: "segment_mm",
        unit: "mm",
        kind: |k| k == RoomKind::Niche,
        tangent: |r| {
            let g = r.segment.as_ref().filter(|g| g.bounded)?;
            Some((
                g.length_mm.value,
                g.length_mm.sigma,
                r.truth.as_ref()?.segment_mm?,
            ))
        },
        baseline: |b| b.segment_mm,
        target: |t| 1.0 + 1e-3 * t,
        target_range_m: 2.0,
        target_text: "≤ 1 mm + 0.1 % (95 %) up to 2 m",
    },
];

const DISTANCE_BINS_M: [(f64, f64); 4] = [(0.5, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 5.0)];

/// Statistics of one quantity over some samples.
#[derive(Debug, Clone, Copy, Default)]
struct Stats {
    rooms: usize,
    read_t: usize,
    read_b: usize,
    mae_t: f64,
    mae_b: f64,
    p95_t: f64,
    p95_b: f64,
    bias_t: f64,
    in_target_t: f64,
    in_target_b: f64,
    in_2sigma: f64,
    median_sigma: f64,
}

fn p95(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() as f64 * 0.95).ceil() as usize).clamp(1, v.len()) - 1]
}

fn stats(q: &Quantity, samples: &[&WallSample]) -> Stats {
    let mut t_err = Vec::new();
    let mut b_err = Vec::new();
    let (mut in_t, mut in_b, mut in_2s, mut bias) = (0usize, 0usize, 0usize, 0.0);
    let mut sigmas = Vec::new();
    let mut rooms = 0;
    for s in samples.iter().filter(|s| (q.kind)(s.draw.kind)) {
        rooms += 1;
        let Some((value, sigma, truth)) = s.report.as_ref().ok().and_then(q.tangent) else {
            continue;
        };
        let e = value - truth;
        t_err.push(e.abs());
        bias += e;
        in_t += (e.abs() <= (q.target)(truth)) as usize;
        in_2s += (e.abs() <= 2.0 * sigma) as usize;
        sigmas.push(sigma);
        if let Some(b) = (q.baseline)(&s.baseline) {
            let e = b - truth;
            b_err.push(e.abs());
            in_b += (e.abs() <= (q.target)(truth)) as usize;
        }
    }
    let mean = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let frac = |k: usize, n: usize| k as f64 / n.max(1) as f64;
    let (nt, nb) = (t_err.len(), b_err.len());
    Stats {
        rooms,
        read_t: nt,
        read_b: nb,
        mae_t: mean(&t_err),
        mae_b: mean(&b_err),
        p95_t: p95(&mut t_err),
        p95_b: p95(&mut b_err),
        bias_t: if nt > 0 { bias / nt as f64 } else { f64::NAN },
        in_target_t: frac(in_t, nt),
        in_target_b: frac(in_b, nb),
        in_2sigma: frac(in_2s, nt),
        median_sigma: {
            sigmas.sort_by(f64::total_cmp);
            sigmas.get(sigmas.len() / 2).copied().unwrap_or(f64::NAN)
        },
    }
}

fn row(label: &str, q: &Quantity, s: &Stats) -> String {
    let d = if q.unit == "°" { 3 } else { 2 };
    let f = |v: f64| {
        if v.is_finite() {
            format!("{v:.d$}")
        } else {
            "—".into()
        }
    };
    format!(
        "| {label} | {} | {} / {} | {} / {} | {} / {} | {} | {} | {:.0} % / {:.0} % | {:.0} % |\n",
        s.rooms,
        s.read_t,
        s.read_b,
        f(s.mae_t),
        f(s.mae_b),
        f(s.p95_t),
        f(s.p95_b),
        f(s.bias_t),
        f(s.median_sigma),
        100.0 * s.in_target_t,
        100.0 * s.in_target_b,
        100.0 * s.in_2sigma,
    )
}

/// The Markdown tables: per quantity, the target range, then per distance bin, matt and
/// glossy, with and without clutter; then the refusals.
pub fn section(title: &str, samples: &[WallSample]) -> String {
    let mut out = format!("### {title}\n\n");
    for q in &QUANTITIES {
        let u = q.unit;
        let _ = write!(
            out,
            "#### {} (target {})\n\n\
             | rooms | n | read T / B | MAE {u} T / B | P95 \\|err\\| {u} T / B | bias {u} T | median σ {u} T | within target T / B | within 2σ T |\n\
             |---|---|---|---|---|---|---|---|---|\n",
            q.name, q.target_text
        );
        let all: Vec<&WallSample> = samples.iter().collect();
        let within: Vec<&WallSample> = samples
            .iter()
            .filter(|s| s.draw.distance_m <= q.target_range_m)
            .collect();
        out += &row(
            &format!("**target range ≤ {} m**", q.target_range_m),
            q,
            &stats(q, &within),
        );
        out += &row("all, 0.5–5 m", q, &stats(q, &all));
        for (lo, hi) in DISTANCE_BINS_M {
            let b: Vec<&WallSample> = samples
                .iter()
                .filter(|s| s.draw.distance_m >= lo && s.draw.distance_m < hi)
                .collect();
            out += &row(&format!("{lo:.1}–{hi:.1} m"), q, &stats(q, &b));
        }
        for (label, pick) in [
            (
                "matt",
                (|s: &WallSample| !s.draw.glossy) as fn(&WallSample) -> bool,
            ),
            ("glossy", |s| s.draw.glossy),
            ("with clutter", |s| s.draw.clutter),
        ] {
            let b: Vec<&WallSample> = samples.iter().filter(|s| pick(s)).collect();
            out += &row(label, q, &stats(q, &b));
        }
        out += "\n";
    }
    let refused: Vec<&WallSample> = samples.iter().filter(|s| s.report.is_err()).collect();
    let _ = writeln!(
        out,
        "No reading: {} of {} rooms.\n",
        refused.len(),
        samples.len()
    );
    for s in refused.iter().take(12) {
        let _ = writeln!(
            out,
            "* seed {} ({}): {}",
            s.seed,
            s.draw.description,
            s.report.as_ref().err().map_or("", |e| e.as_str())
        );
    }
    out + "\n"
}

/// One line per room (comma-separated, a header first): the draw, each reading with its σ
/// and truth, and the baseline's, for analyses beyond the tables.
pub fn csv(samples: &[WallSample]) -> String {
    let mut out = String::from(
        "seed,kind,distance_m,material,glossy,clutter,quantity,value,sigma,truth,baseline,error\n",
    );
    for s in samples {
        let common = format!(
            "{},{},{:.4},{},{},{}",
            s.seed,
            s.draw.kind.name(),
            s.draw.distance_m,
            s.draw.material.name,
            s.draw.glossy as u8,
            s.draw.clutter as u8
        );
        match &s.report {
            Err(e) => {
                let _ = writeln!(out, "{common},,,,,,\"{}\"", e.replace('"', "'"));
            }
            Ok(r) => {
                for q in QUANTITIES.iter().filter(|q| (q.kind)(s.draw.kind)) {
                    let b = (q.baseline)(&s.baseline).map_or(String::new(), |v| format!("{v:.5}"));
                    match (q.tangent)(r) {
                        Some((v, sg, t)) => {
                            let _ = writeln!(out, "{common},{},{v:.5},{sg:.5},{t:.5},{b},", q.key);
                        }
                        None => {
                            let _ = writeln!(out, "{common},{},,,,{b},\"not read\"", q.key);
                        }
                    }
                }
            }
        }
    }
    out
}
