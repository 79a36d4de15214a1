//! `tangent evaluate`: accuracy of the whole chain against the simulator's truth, across the
//! physics models and beside the naive baseline, written as `docs/accuracy.md`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use tangent_host::calibration_draw::{CalibrationUsed, ReferenceKind, ReferenceSessions};
use tangent_host::evaluate::{comparison_section, run as run_samples, section, Exposures, SeedSet};

/// The long help of `tangent evaluate` (`main.rs` gives it to clap on the subcommand, where
/// the short doc comment would otherwise replace it).
pub const LONG_ABOUT: &str =
    "Simulates random stems across the product's envelope (diameters 50–1000 mm \
log-uniform, distances 0.5–3 m, forest light), each rendered with a physics model drawn from its \
seed (reflectance, sheet profile, PSF/defocus, speckle, texture scale, sensor noise; \
docs/simulator.md), measures each end to end with the device's core and with the naive baseline \
(subtraction, Otsu, per-column centre of mass, Kåsa circle), and tabulates the errors per physics \
model and distance bin, Tangent beside the baseline, then per diameter bin. Two frozen, disjoint \
seed sets: `--set tuning` (look at it while tuning) and `--set report` (the numbers the docs \
quote). Full run: `cargo tangent evaluate --set report --n 200 --out docs/accuracy.md`.";

/// Arguments of `tangent evaluate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Seed set: `tuning` or `report` (held out; docs quote it).
    #[arg(long, value_enum, default_value_t = SeedSet::Report)]
    set: SeedSet,
    /// Transversal stems to simulate (one laser plane).
    #[arg(long = "n", alias = "count", default_value_t = 200)]
    count: u64,
    /// Tilted stems (two-plane device) to simulate.
    #[arg(long, default_value_t = 120)]
    tilted_count: u64,
    /// Largest lean of the tilted run (degrees).
    #[arg(long, default_value_t = 30.0)]
    tilt_max_deg: f64,
    /// Write the Markdown report here instead of printing it.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also write every evaluated stem capture here, one JSON object per line (seed, physics
    /// model, truth, Tangent's reading, the baseline's): for diagnosing single captures.
    #[arg(long)]
    samples: Option<PathBuf>,
    /// Random balls to simulate for the sphere section (`docs/accuracy.md`, "Spheres"; seeds
    /// from `--sphere-seed`).
    #[arg(long, default_value_t = 0)]
    spheres: u64,
    /// First seed of the balls (default: the `--set`'s, `SeedSet::first_sphere_seed`).
    #[arg(long)]
    sphere_seed: Option<u64>,
    /// Also write one line per ball here (CSV: the draw, the reading, each method's diameter).
    #[arg(long)]
    sphere_csv: Option<PathBuf>,
    /// Report the spheres only (no stems).
    #[arg(long)]
    spheres_only: bool,
    /// Keep the simulated balls' captures here (`<dir>/<seed>/`) and read them back on the
    /// next run: re-measuring a set after a solver change without simulating it again.
    #[arg(long)]
    sphere_cache: Option<PathBuf>,
    /// Measure each stem or ball with its calibration off by a draw from the calibration σ
    /// the solver states (`host/src/calibration_draw.rs`), so that *within 2σ* checks the
    /// whole stated σ, calibration term included (default: the exact calibration, which
    /// exercises only the random part).
    #[arg(long)]
    calibration_errors: bool,
    /// With --calibration-errors: on a two-plane head, refine each drawn calibration on a
    /// rendered session of the reference ball (`tangent calibrate ball`,
    /// `docs/calibration.md` section 12) before measuring; this many sessions, shared round
    /// robin by the captures' seeds.
    #[arg(
        long,
        requires = "calibration_errors",
        conflicts_with = "wall_sessions"
    )]
    ball_sessions: Option<u64>,
    /// With --calibration-errors: refine each drawn calibration on a rendered session of a
    /// flat wall (`tangent calibrate wall`, `docs/calibration.md` section 13) of the head
    /// measured (`--walls-crossing`: the three-line head) before measuring; this many
    /// sessions, shared round robin by the captures' seeds.
    #[arg(long, requires = "calibration_errors")]
    wall_sessions: Option<u64>,
    /// Evaluate the road instrument instead (`docs/road.md`): MPD per surface type, furrow
    /// depths, piezo height-scale calibration, vertical resolution, captif-slp cross-check,
    /// bad input; `--count` fresh seeds per surface.
    #[arg(long)]
    road: bool,
    /// Evaluate the wall instrument instead (`docs/accuracy.md`, "Walls"): this many random
    /// rooms (single walls, corners, niches; 0.5–5 m) from the `--set`'s first wall seed,
    /// beside the naive baseline (unweighted principal components).
    #[arg(long, default_value_t = 0)]
    walls: u64,
    /// First seed of the rooms (default: the `--set`'s, `evaluate_walls::first_seed`).
    #[arg(long)]
    walls_seed: Option<u64>,
    /// With `--walls`: the head with the third, crossing line (`docs/building.md`, "The
    /// crossing line"), on the same rooms.
    #[arg(long)]
    walls_crossing: bool,
    /// Also write one line per room and reading here (CSV).
    #[arg(long)]
    walls_csv: Option<PathBuf>,
    /// First seed of the road surfaces (`--road`).
    #[arg(long, default_value_t = 1_000_000)]
    road_seed: u64,
    /// Exposure pairs per stem capture (frame pairs while the trigger is held,
    /// `docs/error-model.md` §6, (E7)): Tangent combines them, the baseline reads the first.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=16))]
    exposure_pairs: u64,
    /// With --exposure-pairs: the same speckle in every pair (the hand did not renew it;
    /// the worst case for averaging).
    #[arg(long)]
    frozen_speckle: bool,
}

/// Runs `tangent evaluate`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    if args.spheres_only {
        let doc = sphere_section(&args)?;
        return write(&args, &doc);
    }
    if args.walls > 0 {
        let doc = walls_section(&args)?;
        return write(&args, &doc);
    }
    if args.road {
        let scratch = std::env::temp_dir().join(format!("tangent-road-{}", std::process::id()));
        std::fs::create_dir_all(&scratch)
            .with_context(|| format!("creating {}", scratch.display()))?;
        let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let doc = format!(
            "## Road instrument\n\nGenerated by `tangent evaluate --road --n {} --road-seed {}` \
             (deterministic; `docs/road.md`).\n\n{}",
            args.count,
            args.road_seed,
            tangent_host::evaluate_road::report(args.road_seed, args.count, &repo, &scratch)?
        );
        std::fs::remove_dir_all(&scratch).ok();
        match &args.out {
            Some(path) => {
                std::fs::write(path, &doc).with_context(|| format!("writing {}", path.display()))?
            }
            None => print!("{doc}"),
        }
        return Ok(ExitCode::SUCCESS);
    }
    if args.count > SeedSet::MAX_CAPTURES || args.tilted_count > SeedSet::MAX_CAPTURES {
        anyhow::bail!(
            "--n and --tilted-count are at most {} (the seed sets' ranges would overlap)",
            SeedSet::MAX_CAPTURES
        );
    }
    let start = Instant::now();
    let (t_seed, tilt_seed) = (args.set.first_seed(false), args.set.first_seed(true));
    let sessions = ball_sessions(&args)?;
    let used = calibration_used(&args, sessions.as_ref());
    let exposures = Exposures {
        pairs: args.exposure_pairs as usize,
        frozen_speckle: args.frozen_speckle,
    };
    let transversal = run_samples(t_seed, args.count, 0.0, used, exposures)?;
    let tilted = run_samples(
        tilt_seed,
        args.tilted_count,
        args.tilt_max_deg,
        used,
        exposures,
    )?;
    let elapsed = start.elapsed().as_secs_f64();
    if let Some(path) = &args.samples {
        let lines: Vec<String> = transversal
            .iter()
            .chain(&tilted)
            .map(|s| tangent_host::evaluate::sample_json(s).to_string())
            .collect();
        std::fs::write(path, lines.join("\n") + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let mut doc = String::from(
        "# Accuracy of the stem diameter\n\n\
         Generated by `cargo tangent evaluate --set report --n 200 --out docs/accuracy.md` \
         (deterministic). Each row: simulated captures (random stems, each rendered with the \
         physics model of its seed, `docs/simulator.md` \"Physics models\"), measured end to end \
         by `tangent_core::instrument::measure_with::<Stem>` (T) and by the naive baseline (B: \
         subtraction, Otsu threshold, per-column centre of mass, Kåsa circle; \
         `host/src/baseline.rs`) with the same calibration, compared with the simulator's true \
         diameter. *within 2σ* checks Tangent's stated uncertainty (≈ 95 % if it is honest; the \
         baseline states none). *Paired MAE* is over the captures both read; Tangent wins a bin \
         when its paired MAE is lower and it has no more captures without a reading.\n\n\
         Seed sets (frozen, disjoint): **tuning** — transversal seeds 1 000 000 + i, tilted \
         1 500 000 + i; **report** — transversal 7 000 000 + i, tilted 7 500 000 + i \
         (i < 500 000). Tune on the tuning set only; the report set is what the docs quote. \
         Physics model of seed s: the (s mod 8)-th of reference, oren_nayar_bark, \
         specular_sheen, flat_top_sheet, defocus, coarse_speckle, noisy_sensor, mixed.\n\n\
         Targets (issue 12): transversal MAE ≤ 3 mm overall and ≤ 1.5 mm up to 2 m; tilted ≤ \
         3 mm; ≥ 75 % of readings within 1 %; |error| ≤ 2σ for 90–98 %; better than the naive \
         baseline in every bin.\n\n",
    );
    doc += &format!(
        "Command parameters: set **{}**, {} transversal stems from seed {}, {} tilted stems \
         (≤ {}°) from seed {}{}.\n\n## Evaluation across physics models\n\n",
        args.set.name(),
        args.count,
        t_seed,
        args.tilted_count,
        args.tilt_max_deg,
        tilt_seed,
        match (exposures.pairs, exposures.frozen_speckle) {
            (1, _) => String::new(),
            (k, false) => format!("; {k} exposure pairs per capture, speckle renewed in each"),
            (k, true) => format!("; {k} exposure pairs per capture, the same speckle in each"),
        }
    );
    doc += &comparison_section("Transversal stems (one laser plane)", &transversal);
    doc += &comparison_section(
        &format!(
            "Tilted stems up to {}° (two laser planes)",
            args.tilt_max_deg
        ),
        &tilted,
    );
    doc += "## Detail per diameter and distance (all physics models)\n\n";
    doc += &section("Transversal stems (one laser plane)", &transversal);
    doc += &section(
        &format!(
            "Tilted stems up to {}° (two laser planes)",
            args.tilt_max_deg
        ),
        &tilted,
    );
    if args.spheres > 0 {
        doc += &sphere_section(&args)?;
    }
    eprintln!(
        "evaluated {} captures (set {}) in {elapsed:.1} s ({:.2} s per capture)",
        transversal.len() + tilted.len(),
        args.set.name(),
        elapsed / (transversal.len() + tilted.len()).max(1) as f64
    );
    write(&args, &doc)
}

/// The reference sessions of `--ball-sessions` or `--wall-sessions`, rendered.
fn ball_sessions(args: &Args) -> anyhow::Result<Option<ReferenceSessions>> {
    let wall = ReferenceKind::Wall {
        crossing: args.walls_crossing,
    };
    match (args.ball_sessions, args.wall_sessions) {
        (Some(n), _) => ReferenceSessions::render(ReferenceKind::Ball, n).map(Some),
        (None, Some(n)) => ReferenceSessions::render(wall, n).map(Some),
        (None, None) => Ok(None),
    }
}

/// The calibration the captures are measured with (`--calibration-errors`,
/// `--ball-sessions`).
fn calibration_used<'a>(
    args: &Args,
    sessions: Option<&'a ReferenceSessions>,
) -> CalibrationUsed<'a> {
    match (args.calibration_errors, sessions) {
        (false, _) => CalibrationUsed::Exact,
        (true, None) => CalibrationUsed::Drawn,
        (true, Some(s)) => CalibrationUsed::Refined(s),
    }
}

/// The sphere section: `--spheres` random balls from `--sphere-seed`.
fn sphere_section(args: &Args) -> anyhow::Result<String> {
    let first = args
        .sphere_seed
        .unwrap_or_else(|| args.set.first_sphere_seed());
    let sessions = ball_sessions(args)?;
    let samples = tangent_host::evaluate_sphere::run(
        first,
        args.spheres,
        args.sphere_cache.as_deref(),
        calibration_used(args, sessions.as_ref()),
    )?;
    if let Some(path) = &args.sphere_csv {
        std::fs::write(path, tangent_host::evaluate_sphere::csv(&samples))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(tangent_host::evaluate_sphere::section(
        &format!(
            "{} random balls (seeds {}–{}, set {}): 20–400 mm, centre 0.3–2 m, matt and steel, \
             in the air and on a floor, two laser planes",
            args.spheres,
            first,
            first + args.spheres.saturating_sub(1),
            args.set.name()
        ),
        &samples,
    ))
}

/// The walls section: `--walls` random rooms from `--walls-seed`.
fn walls_section(args: &Args) -> anyhow::Result<String> {
    use tangent_host::evaluate_walls as ev;
    let first = args.walls_seed.unwrap_or_else(|| ev::first_seed(args.set));
    let start = Instant::now();
    let sessions = ball_sessions(args)?;
    let samples = ev::run(
        first,
        args.walls,
        args.walls_crossing,
        calibration_used(args, sessions.as_ref()),
    )?;
    eprintln!(
        "evaluated {} rooms in {:.1} s",
        samples.len(),
        start.elapsed().as_secs_f64()
    );
    if let Some(path) = &args.walls_csv {
        std::fs::write(path, ev::csv(&samples))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(ev::section(
        &format!(
            "{} random rooms (seeds {}–{}, set {}): walls, corners and niches 0.5–5 m away, \
             {}; `tangent evaluate --walls {} --set {}{}`",
            args.walls,
            first,
            first + args.walls.saturating_sub(1),
            args.set.name(),
            if args.walls_crossing {
                "three laser lines (two parallel, one crossing)"
            } else {
                "two parallel laser lines"
            },
            args.walls,
            args.set.name(),
            if args.walls_crossing {
                " --walls-crossing"
            } else {
                ""
            }
        ),
        &samples,
    ))
}

fn write(args: &Args, doc: &str) -> anyhow::Result<ExitCode> {
    match &args.out {
        Some(path) => {
            std::fs::write(path, doc).with_context(|| format!("writing {}", path.display()))?
        }
        None => print!("{doc}"),
    }
    Ok(ExitCode::SUCCESS)
}
