//! Several exposure pairs in one capture (the trigger held): `tangent measure` reads each
//! pair and combines the readings (`tangent_core::solvers::stem::combine_exposures`,
//! `docs/error-model.md` §6, (E7)).

use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::capture::Capture;
use tangent_host::measure::{measure_loaded, Reading};
use tangent_host::simulate::corpus::random_stem;
use tangent_host::simulate::physics::{self, model_for_seed};
use tangent_host::simulate::simulate;

fn measure(capture: &Capture) -> Reading {
    measure_loaded(
        capture,
        "burst",
        None,
        &PipelineConfig::default(),
        &CylinderParams::default(),
    )
    .expect("measures")
    .reading
}

/// Tuning seed 1 000 000 (a 383 mm stem at 2.37 m, the reference physics) with four pairs:
/// each pair is measured as a capture of its own, the combined reading is their mean (equal
/// weights, none stray), it names the four exposures and its error is within its 2σ. With
/// the same speckle in every pair the pairs agree more closely than with renewed speckle, and
/// the combined σ does not fall below one pair's (their shared error does not average).
#[test]
fn several_exposures_combine_into_one_reading() {
    let seed = 1_000_000;
    let mut spreads = Vec::new();
    for frozen in [false, true] {
        let mut spec = random_stem(seed, 0.0);
        physics::apply(model_for_seed(seed), seed, &mut spec);
        spec.params.exposure_pairs = 4;
        spec.params.frozen_speckle = frozen;
        let (capture, _) = simulate(&spec).expect("simulates");
        assert_eq!(capture.pairs(), 4);
        let pairs: Vec<Reading> = (0..4)
            .map(|k| measure(&capture.exposure_pair(k).expect("pair")))
            .collect();
        let diameters: Vec<f64> = pairs.iter().map(|r| r.diameter_m.expect("reads")).collect();
        let mean = diameters.iter().sum::<f64>() / 4.0;
        let spread = diameters
            .iter()
            .map(|d| (d - mean).abs())
            .fold(0.0, f64::max);
        spreads.push(spread);

        let combined = measure(&capture);
        assert_eq!(
            (combined.exposures, combined.exposure_pairs),
            (Some(4), Some(4))
        );
        assert!(
            combined.summary().contains("4 exposures"),
            "{}",
            combined.summary()
        );
        let (d, s, truth) = (
            combined.diameter_m.unwrap(),
            combined.uncertainty_m.unwrap(),
            combined.truth_diameter_m.unwrap(),
        );
        assert!(
            (d - mean).abs() < 1e-9,
            "{d} against the pairs' mean {mean}"
        );
        assert!((d - truth).abs() <= 2.0 * s, "{d} ± {s} against {truth}");
        // Pair 0 is rendered as a single-pair capture is: the same bytes, the same reading.
        spec.params.exposure_pairs = 1;
        let (single, _) = simulate(&spec).expect("simulates");
        assert_eq!(measure(&single).diameter_m, pairs[0].diameter_m);
        if frozen {
            let one = pairs[0].uncertainty_m.unwrap();
            assert!(
                s >= 0.9 * one,
                "frozen speckle: σ {s} against one pair's {one}"
            );
        }
    }
    assert!(
        spreads[1] < spreads[0],
        "frozen speckle should spread the pairs less: {spreads:?}"
    );
}
