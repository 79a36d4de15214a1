//! The simulator's physics models (`docs/simulator.md`, "Physics models"): each model is
//! recorded in the capture's truth, changes the frames but never the geometry (the true curve),
//! and its pieces reduce to the reference where they should.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;
use tangent_core::real::Vec3;
use tangent_host::capture::Capture;
use tangent_host::simulate::corpus::random_stem;
use tangent_host::simulate::laser::SheetProfile;
use tangent_host::simulate::physics::{self, model_for_seed};
use tangent_host::simulate::reflectance::Reflectance;
use tangent_host::simulate::{sensor, simulate, SimSpec};
use tangent_host::truth::PhysicsModel;

/// A mid-range stem (the seed's own geometry), rendered with `model`.
fn render(seed: u64, model: PhysicsModel) -> (SimSpec, Capture) {
    let mut spec = random_stem(seed, 0.0);
    physics::apply(model, seed, &mut spec);
    let (capture, _) = simulate(&spec).expect("simulates");
    (spec, capture)
}

#[test]
fn every_model_changes_the_frames_but_not_the_geometry() {
    let seed = 1_000_003;
    let (ref_spec, reference) = render(seed, PhysicsModel::Reference);
    // The reference model is the simulator's default chain: applying it changes nothing.
    assert_eq!(ref_spec.params, random_stem(seed, 0.0).params);
    let ref_truth = reference.truth_curve.clone().expect("truth curve");
    assert!(ref_truth.len() > 50, "the stem is lit");
    for model in PhysicsModel::ALL.into_iter().skip(1) {
        let (spec, capture) = render(seed, model);
        assert_eq!(spec.params.physics, model);
        assert_eq!(spec.objects, ref_spec.objects, "{model:?} moved the scene");
        let truth = capture.meta.truth.as_ref().expect("truth");
        assert_eq!(truth.physics_model, Some(model), "{model:?} not recorded");
        assert_eq!(
            capture.truth_curve.as_ref(),
            Some(&ref_truth),
            "{model:?} changed the true curve"
        );
        assert_ne!(
            capture.frames, reference.frames,
            "{model:?} rendered the reference frames"
        );
    }
}

#[test]
fn the_model_survives_a_write_and_read() {
    let seed = 1_000_005; // coarse_speckle
    let (spec, capture) = render(seed, model_for_seed(seed));
    assert_eq!(spec.params.physics, PhysicsModel::CoarseSpeckle);
    let dir = std::env::temp_dir().join(format!("tangent-physics-{}", std::process::id()));
    capture.write(&dir).expect("writes");
    let back = Capture::read(&dir).expect("reads");
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(
        back.meta.truth.as_ref().and_then(|t| t.physics_model),
        Some(PhysicsModel::CoarseSpeckle)
    );
    let again = SimSpec::from_capture(&back).expect("spec");
    assert_eq!(
        again.params, spec.params,
        "the [simulation] table holds the draw"
    );
}

#[test]
fn models_cycle_with_the_seed_and_names_round_trip() {
    for (i, m) in PhysicsModel::ALL.into_iter().enumerate() {
        assert_eq!(model_for_seed(7_000_000 + i as u64), PhysicsModel::ALL[i]);
        assert_eq!(PhysicsModel::from_name(m.name()), Some(m));
    }
}

#[test]
fn sheet_profiles_carry_unit_power() {
    for profile in [
        SheetProfile::Gaussian,
        SheetProfile::FlatTop { order: 4.0 },
        SheetProfile::FlatTop { order: 10.0 },
    ] {
        let w = 1.3e-3;
        let n = 20_000;
        let ds = 10.0 * w / n as f64;
        let integral: f64 = (0..n)
            .map(|i| profile.density(-5.0 * w + (i as f64 + 0.5) * ds, w) * ds)
            .sum();
        assert!((integral - 1.0).abs() < 1e-6, "{profile:?}: {integral}");
    }
    // Order 2 is the Gaussian.
    let (g, s) = (
        SheetProfile::Gaussian.density(0.4e-3, 1e-3),
        SheetProfile::FlatTop { order: 2.0 }.density(0.4e-3, 1e-3),
    );
    assert!((g - s).abs() < 1e-9 * g);
}

#[test]
fn brdfs_reduce_to_lambert() {
    let n = Vec3::new(0.0, 0.0, -1.0);
    let l = Vec3::new(0.3, -0.2, -1.0).normalize();
    let v = Vec3::new(-0.1, 0.1, -1.0).normalize();
    let rho = 0.3;
    let flat = [
        Reflectance::OrenNayar { sigma_rad: 0.0 },
        Reflectance::Glossy {
            specular_fraction: 0.0,
            exponent: 30.0,
        },
    ];
    for r in flat {
        assert!((r.pi_brdf(rho, n, l, v) - rho).abs() < 1e-12, "{r:?}");
    }
    // Rough bark is brighter than Lambert towards retro-reflection (the laser sits by the
    // camera) and a specular lobe peaks where the half vector meets the normal.
    let on = Reflectance::OrenNayar { sigma_rad: 0.5 };
    let grazing = Vec3::new(0.8, 0.0, -0.6).normalize();
    assert!(on.pi_brdf(rho, n, grazing, grazing) > rho);
    let glossy = Reflectance::Glossy {
        specular_fraction: 0.1,
        exponent: 40.0,
    };
    assert!(glossy.pi_brdf(rho, n, n, n) > 2.0 * rho);
    assert_eq!(
        glossy.pi_brdf(rho, n, -l, v),
        0.0,
        "light behind the surface"
    );
}

#[test]
fn correlated_speckle_keeps_its_contrast_and_is_correlated() {
    let (w, h) = (200, 200);
    let mut rng = Pcg64::seed_from_u64(5);
    let white: Vec<f64> = (0..w * h)
        .map(|_| StandardNormal.sample(&mut rng))
        .collect();
    let cells = 6.0; // contrast 1/√6 ≈ 0.41
    let m = sensor::correlated_speckle(&white, w, h, 1.5, cells);
    let mean = m.iter().sum::<f64>() / m.len() as f64;
    let var = m.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / m.len() as f64;
    assert!((mean - 1.0).abs() < 0.03, "mean {mean}");
    let contrast = var.sqrt() / mean;
    assert!(
        (contrast - 1.0 / cells.sqrt()).abs() < 0.05,
        "contrast {contrast}"
    );
    // Neighbours correlate (grain 1.5 px: ρ ≈ exp(−1/(4·1.5²)) ≈ 0.9).
    let cov: f64 = (0..h)
        .flat_map(|y| (0..w - 1).map(move |x| (y, x)))
        .map(|(y, x)| (m[y * w + x] - mean) * (m[y * w + x + 1] - mean))
        .sum::<f64>()
        / (h * (w - 1)) as f64;
    assert!(cov / var > 0.7, "neighbour correlation {}", cov / var);
}

#[test]
fn disc_blur_keeps_the_mean_and_spreads_a_point() {
    let (w, h) = (21, 21);
    let mut img = vec![0.0; w * h];
    img[10 * w + 10] = 1.0;
    sensor::disc_blur(&mut img, w, h, 2.0);
    let total: f64 = img.iter().sum();
    assert!((total - 1.0).abs() < 1e-12);
    // Area of a radius-2 disc ≈ 12.6 px: the centre keeps ≈ 1/12.6.
    assert!((img[10 * w + 10] - 1.0 / (std::f64::consts::PI * 4.0)).abs() < 0.01);
    assert_eq!(img[10 * w + 14], 0.0, "nothing beyond the radius");
}
