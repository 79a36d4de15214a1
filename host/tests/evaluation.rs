//! `tangent evaluate` in a small form: a few captures per physics model, measured by Tangent
//! and by the naive baseline, tabulated per model and distance bin. Asserts that the tables
//! are computed and that the baseline column exists and is sane — not accuracy thresholds
//! of the solver (those are the full evaluation's business, `docs/accuracy.md`).

use tangent_host::calibration_draw::CalibrationUsed;
use tangent_host::evaluate::{
    baseline_metrics, compare, comparison_section, metrics, run, tangent_metrics, wins, Exposures,
    Sample, SeedSet, DISTANCE_BINS_M,
};
use tangent_host::truth::PhysicsModel;

#[test]
fn seed_sets_are_disjoint() {
    let ranges: Vec<(u64, u64)> = [SeedSet::Tuning, SeedSet::Report]
        .into_iter()
        .flat_map(|s| [s.first_seed(false), s.first_seed(true)])
        .map(|a| (a, a + SeedSet::MAX_CAPTURES))
        .collect();
    for (i, a) in ranges.iter().enumerate() {
        for b in &ranges[i + 1..] {
            assert!(a.1 <= b.0 || b.1 <= a.0, "{a:?} overlaps {b:?}");
        }
    }
}

#[test]
fn metrics_of_known_errors() {
    // Errors 1, 2, 3, 10 mm on a 500 mm stem (σ 2 mm), one capture without a reading.
    let truth = 0.5;
    let rows = [1e-3, 2e-3, 3e-3, 10e-3]
        .into_iter()
        .map(|e| (truth, Some(truth + e), Some(2e-3)))
        .chain(std::iter::once((truth, None, None)));
    let m = metrics(rows);
    assert_eq!((m.n, m.no_reading), (5, 1));
    assert!((m.mae - 4e-3).abs() < 1e-12);
    assert!((m.median - 2.5e-3).abs() < 1e-12);
    assert!((m.max - 10e-3).abs() < 1e-12);
    assert!((m.within_1pct - 0.75).abs() < 1e-12, "5 mm is 1 %");
    assert_eq!(m.within_2sigma, Some(0.75));
    let none = metrics([(truth, Some(truth), None)].into_iter());
    assert_eq!(
        none.within_2sigma, None,
        "a pipeline without σ has no 2σ column"
    );
}

#[test]
fn small_evaluation_per_model_with_the_baseline_column() {
    // Two captures per model: 16 consecutive seeds of the tuning set.
    let samples: Vec<Sample> = run(
        SeedSet::Tuning.first_seed(false),
        16,
        0.0,
        CalibrationUsed::Exact,
        Exposures::default(),
    )
    .expect("runs");
    assert_eq!(samples.len(), 16);
    for model in PhysicsModel::ALL {
        assert_eq!(
            samples.iter().filter(|s| s.physics == model).count(),
            2,
            "{model:?}"
        );
    }
    let all: Vec<&Sample> = samples.iter().collect();
    let (t, b) = (tangent_metrics(&all), baseline_metrics(&all));
    assert_eq!((t.n, b.n), (16, 16));
    // The baseline is a working pipeline: it reads most captures, and its median error is
    // a small fraction of the diameter (a broken segmentation or triangulation reads metres).
    assert!(
        b.no_reading <= 8,
        "baseline read only {} of 16",
        16 - b.no_reading
    );
    let mut rel: Vec<f64> = samples
        .iter()
        .filter_map(|s| {
            s.baseline
                .as_ref()
                .ok()
                .map(|d| (d - s.truth_m).abs() / s.truth_m)
        })
        .collect();
    rel.sort_by(f64::total_cmp);
    let median = rel[rel.len() / 2];
    assert!(median < 0.15, "baseline median relative error {median}");
    assert_eq!(b.within_2sigma, None);
    assert!(t.within_2sigma.is_some());
    if let Some(c) = compare(&all) {
        assert!(c.paired > 0 && c.tangent_mae.is_finite() && c.baseline_mae.is_finite());
    }
    let (won, cells) = wins(&samples);
    assert!(won <= cells && cells <= PhysicsModel::ALL.len() * DISTANCE_BINS_M.len());
    let table = comparison_section("Transversal", &samples);
    for model in PhysicsModel::ALL {
        assert!(
            table.contains(&format!("| {} |", model.name())),
            "{model:?} row"
        );
    }
    assert!(table.contains("MAE mm T / B"), "baseline column");
    assert!(table.contains(&format!("Tangent wins **{won} of {cells}**")));
}
