//! The refinement against analytic truth: sections of a sphere cut by the true planes,
//! triangulated with planes off by a draw of the board calibration's σ.

use super::*;
use crate::calibration_draw::drawn;
use crate::capture::Capture;
use crate::simulate::sphere_corpus::mid_plane_y;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;
use tangent_core::solvers::sphere_sections::Sphere;

/// The board calibration's σ of `e` and `δ` only (the camera exact).
fn planes_only() -> NoiseModel {
    NoiseModel {
        focal_px: 0.0,
        ..NoiseModel::reference()
    }
}

/// Views of a ball of radius `r` at the distances `zs` (centre between the lines, `x`
/// alternating across the view): each true section's visible arc, one point per image
/// column, its row off by `noise_px` (the stripe centre's error) and its ray
/// triangulated on the drawn plane.
fn views(
    truth: &Calibration,
    off: &Calibration,
    r: f64,
    zs: &[f64],
    noise_px: f64,
    seed: u64,
) -> Vec<ReferenceView> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let n = Normal::new(0.0, noise_px).unwrap();
    let camera = &truth.camera;
    zs.iter()
        .enumerate()
        .map(|(i, &z)| {
            let x = if i.is_multiple_of(2) {
                0.1 * z
            } else {
                -0.08 * z
            };
            let c = Vec3::new(x, mid_plane_y(z), z);
            let planes = truth
                .planes
                .iter()
                .zip(off.planes.iter())
                .map(|(t, o)| {
                    let h = t.normal.dot(&c) - t.offset;
                    let rc = (r * r - h * h).sqrt();
                    let centre = c - t.normal * h;
                    let a = t.normal.cross(&Vec3::z()).normalize();
                    let b = t.normal.cross(&a);
                    // The visible arc, densely; then one point per image column.
                    let mut by_column = std::collections::BTreeMap::new();
                    for j in 0..20_000 {
                        let phi = j as f64 / 20_000.0 * std::f64::consts::TAU;
                        let p = centre + (a * phi.cos() + b * phi.sin()) * rc;
                        if (p - c).dot(&p) < -0.1 * r * p.norm() {
                            let px = camera.project(p).unwrap();
                            by_column.entry(px.x.round() as i64).or_insert(p);
                        }
                    }
                    by_column
                        .values()
                        .map(|p| {
                            let px = camera.project(*p).unwrap();
                            let seen = Vec2::new(px.x, px.y + n.sample(&mut rng));
                            let ray = camera.pixel_to_normalised(seen).unwrap();
                            retriangulate(&Vec3::new(ray.x, ray.y, 1.0), o)
                        })
                        .collect()
                })
                .collect();
            ReferenceView {
                name: format!("z = {z}"),
                planes,
                start: Surface::Sphere(Sphere {
                    centre: c + Vec3::new(0.003, -0.002, 0.004),
                    radius: r * 1.03,
                }),
            }
        })
        .collect()
}

fn tilt_difference(c: &Calibration) -> f64 {
    c.planes[1].baseline_tilt().1 - c.planes[0].baseline_tilt().1
}

fn baseline_difference(c: &Calibration) -> f64 {
    c.planes[1].baseline_tilt().0 - c.planes[0].baseline_tilt().0
}

/// A 145 mm ball at four distances (0.1 px stripe noise) recovers the planes' relative
/// tilt within the σ it states, which is well inside the board calibration's; the relative
/// baseline, which an unknown diameter cannot see, stays within its (prior-held) σ.
#[test]
fn a_ball_at_four_distances_restores_the_planes_relative_tilt() {
    let truth = Calibration::reference_design();
    let prior = planes_only();
    let board = std::f64::consts::SQRT_2 * prior.tilt;
    let (mut before2, mut after2, mut worst) = (0.0, 0.0, 0.0_f64);
    let n = 12;
    for seed in 0..n {
        let off = drawn(&truth, &prior, seed).unwrap();
        let v = views(&truth, &off, 0.0725, &[0.6, 0.9, 1.2, 1.5], 0.1, seed);
        let fit = refine_planes(&off, &v, &prior, None).unwrap();
        let before = tilt_difference(&off) - tilt_difference(&truth);
        let after = tilt_difference(&fit.calibration) - tilt_difference(&truth);
        let b_after = baseline_difference(&fit.calibration) - baseline_difference(&truth);
        assert!(
            fit.relative_tilt_sigma < 0.5 * board,
            "seed {seed}: σ {:e}",
            fit.relative_tilt_sigma
        );
        assert!(
            after.abs() < 3.5 * fit.relative_tilt_sigma,
            "seed {seed}: relative tilt {before:e} → {after:e}, σ {:e}",
            fit.relative_tilt_sigma
        );
        assert!(
            b_after.abs() < 3.5 * fit.relative_baseline_sigma,
            "seed {seed}: relative baseline {b_after:e}, σ {:e}",
            fit.relative_baseline_sigma
        );
        // The calibration carries the posterior: the relative tilt's σ follows from it.
        let u = fit
            .calibration
            .uncertainty
            .expect("a refined calibration carries it");
        let (t0, t1) = (u.sigmas()[1], u.sigmas()[3]);
        let from_covariance = (t0 * t0 + t1 * t1 - 2.0 * u.correlation(1, 3) * t0 * t1).sqrt();
        assert!(
            (from_covariance - fit.relative_tilt_sigma).abs() < 1e-6 * fit.relative_tilt_sigma,
            "{from_covariance:e} vs {:e}",
            fit.relative_tilt_sigma
        );
        // Each plane alone stays near the board's σ (the common part is unseen).
        assert!(t0 > 0.3 * prior.tilt && t0 <= prior.tilt, "{t0:e}");
        before2 += before * before;
        after2 += after * after;
        worst = worst.max((after / fit.relative_tilt_sigma).abs());
    }
    let rms = |s: f64| (s / n as f64).sqrt();
    // The draws' relative tilt error scatters by ≈ √2·0.2 mrad; the refined one by its σ.
    assert!(
        rms(after2) < 0.5 * rms(before2),
        "{} vs {}",
        rms(after2),
        rms(before2)
    );
    // One error beyond 0.5σ in twelve: the σ is not inflated past what the errors are.
    assert!(worst > 0.5, "largest error {worst}σ");
}

/// A certified diameter makes the common scale observable: each plane's baseline σ shrinks
/// below the unknown-diameter fit's, and each baseline comes back within it.
#[test]
fn a_certified_diameter_fixes_the_common_scale() {
    let truth = Calibration::reference_design();
    let prior = planes_only();
    let off = drawn(&truth, &prior, 3).unwrap();
    let v = views(&truth, &off, 0.0725, &[0.6, 0.9, 1.2, 1.5], 0.1, 3);
    let known = KnownDiameter {
        diameter: 0.145,
        sigma: 2e-6,
    };
    let free = refine_planes(&off, &v, &prior, None).unwrap();
    let fit = refine_planes(&off, &v, &prior, Some(known)).unwrap();
    for k in 0..2 {
        let e_true = truth.planes[k].baseline_tilt().0;
        let e_fit = fit.calibration.planes[k].baseline_tilt().0;
        let c = fit.corrections[k];
        assert!(
            c.baseline_sigma < 0.8 * free.corrections[k].baseline_sigma,
            "{c:?} vs {:?}",
            free.corrections[k]
        );
        assert!(
            (e_fit - e_true).abs() < 3.5 * c.baseline_sigma,
            "plane {k}: {e_fit} vs {e_true}, {c:?}"
        );
    }
}

/// On rendered captures (the simulator's matt 145 mm ball at 0.6–1.6 m, its own stripe
/// extraction and noise) the relative tilt comes back within its σ for every draw, and the
/// views' diameters agree better after than before.
#[test]
fn rendered_views_of_a_reference_ball_restore_the_relative_tilt() {
    use crate::simulate::rig::two_plane_calibration;
    use crate::simulate::simulate;
    use crate::simulate::sphere_corpus::reference_ball_spec;
    let truth = two_plane_calibration();
    let prior = planes_only();
    let captures: Vec<Capture> = (0..6)
        .map(|i| simulate(&reference_ball_spec(i, 7)).unwrap().0)
        .collect();
    let spread = |d: &[f64]| {
        let m = d.iter().sum::<f64>() / d.len() as f64;
        (d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
    };
    for seed in 0..6 {
        let off = drawn(&truth, &prior, seed).unwrap();
        let v: Vec<ReferenceView> = captures
            .iter()
            .enumerate()
            .map(|(i, c)| ReferenceView::of_ball(c, &off, &format!("view {i}")).unwrap())
            .collect();
        let fit = refine_planes(&off, &v, &prior, None).unwrap();
        let after = tilt_difference(&fit.calibration) - tilt_difference(&truth);
        assert!(
            after.abs() < 3.5 * fit.relative_tilt_sigma,
            "seed {seed}: {after:e} ± {:e}",
            fit.relative_tilt_sigma
        );
        let d0: Vec<f64> = fit.views.iter().map(|v| v.size.0).collect();
        let d1: Vec<f64> = fit.views.iter().map(|v| v.size.1).collect();
        eprintln!("seed {seed}: relative tilt {:+.3} → {:+.3} ± {:.3} mrad; diameters' spread {:.2} → {:.2} mm",
            (tilt_difference(&off) - tilt_difference(&truth)) * 1e3, after * 1e3, fit.relative_tilt_sigma * 1e3, spread(&d0) * 1e3, spread(&d1) * 1e3);
    }
}

/// Views at one distance leave the relative tilt and baseline confounded: refused, with what
/// to do.
#[test]
fn views_at_one_distance_are_refused() {
    let truth = Calibration::reference_design();
    let prior = planes_only();
    let off = drawn(&truth, &prior, 5).unwrap();
    let v = views(&truth, &off, 0.0725, &[1.0, 1.0, 1.0], 0.1, 5);
    match refine_planes(&off, &v, &prior, None) {
        Err(CalibrateError::Undetermined(why)) => assert!(why.contains("other distances"), "{why}"),
        other => panic!("{:?}", other.map(|f| f.relative_tilt_sigma)),
    }
}

/// Fewer than three views, or a single-plane calibration, are refused.
#[test]
fn too_few_views_or_planes_are_refused() {
    let truth = Calibration::reference_design();
    let prior = planes_only();
    let v = views(&truth, &truth, 0.0725, &[0.6, 1.2], 0.1, 1);
    assert!(matches!(
        refine_planes(&truth, &v, &prior, None),
        Err(CalibrateError::TooFewViews {
            found: 2,
            needed: 3
        })
    ));
    let one = Calibration::new(0, truth.camera, &truth.planes[..1]).unwrap();
    assert!(matches!(
        refine_planes(&one, &v, &prior, None),
        Err(CalibrateError::Undetermined(_))
    ));
}

/// On rendered views of a flat wall lit by the three-line head (six at 1–3 m), every
/// plane's tilt relative to plane 0 comes back within 3.5 of its stated σ, far inside the
/// board's; the crossing line pins plane 0's to a few µrad.
#[test]
fn rendered_views_of_a_flat_wall_restore_the_three_planes_relative_tilts() {
    use crate::simulate::rig::three_plane_calibration;
    use crate::simulate::simulate;
    use crate::simulate::wall_corpus::reference_wall_spec;
    let truth = three_plane_calibration();
    let prior = planes_only();
    let captures: Vec<Capture> = (0..6)
        .map(|i| simulate(&reference_wall_spec(i, 7, true)).unwrap().0)
        .collect();
    let relative =
        |c: &Calibration, k: usize| c.planes[k].baseline_tilt().1 - c.planes[0].baseline_tilt().1;
    for seed in 0..3 {
        let off = drawn(&truth, &prior, seed).unwrap();
        let v: Vec<ReferenceView> = captures
            .iter()
            .enumerate()
            .map(|(i, c)| ReferenceView::of_wall(c, &off, &format!("view {i}")).unwrap())
            .collect();
        let fit = refine_planes(&off, &v, &prior, None).unwrap();
        let after: Vec<f64> = (1..3)
            .map(|k| relative(&fit.calibration, k) - relative(&truth, k))
            .collect();
        eprintln!(
            "seed {seed}: relative tilts {:+.4}, {:+.4} → {:+.4}, {:+.4} mrad (σ of plane 1's {:.4})",
            (relative(&off, 1) - relative(&truth, 1)) * 1e3,
            (relative(&off, 2) - relative(&truth, 2)) * 1e3,
            after[0] * 1e3,
            after[1] * 1e3,
            fit.relative_tilt_sigma * 1e3
        );
        assert!(
            after[0].abs() < 3.5 * fit.relative_tilt_sigma,
            "seed {seed}: {after:?}"
        );
        assert!(
            fit.relative_tilt_sigma < 0.25 * prior.tilt,
            "{}",
            fit.relative_tilt_sigma
        );
        assert!(after[1].abs() < 0.05 * prior.tilt, "seed {seed}: {after:?}");
    }
}
