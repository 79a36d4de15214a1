// The casts to f64 are no-ops in f64 builds but needed with `--features f32`.
#![allow(clippy::unnecessary_cast)]

extern crate std;
use super::*;
use crate::camera::Camera;
use crate::noise::sample_columns;
use crate::solvers::circle::tests::Rng;
use crate::solvers::circle::Circle;
use crate::solvers::cylinder_fit::tests::{planes, section, tilted_cylinder};
use crate::solvers::three_tangent::tests::lit_arc;

const EPS: Real = Real::EPSILON;

fn noisy_columns(
    plane: &LaserPlane,
    c: &Circle,
    sigma_px: Real,
    rng: &mut Rng,
    out: &mut std::vec::Vec<Vec3>,
) {
    let cam = Camera::reference_design();
    let mut buf = [Vec2::zeros(); 800];
    let (n, _) = sample_columns(plane, &cam, c.centre, c.radius, &mut buf).unwrap();
    out.clear();
    for q in &buf[..n] {
        let x = plane.from_plane_coords(*q);
        let g = noise::displacement_per_pixel(plane, cam.fy, x).unwrap();
        out.push(x + g * (sigma_px * rng.gauss() as Real));
    }
}

/// Each point's 1σ, as the pipeline writes it ([`crate::pipeline::point_sigmas`]).
fn sigmas_of(curve: &[Vec3], plane: &LaserPlane, params: &CylinderParams) -> std::vec::Vec<Real> {
    let px = params.noise.image_px();
    curve
        .iter()
        .map(|x| noise::displacement_sigma(plane, params.focal_px, *x, px).unwrap_or(0.0))
        .collect()
}

#[test]
fn solve_transversal_stem() {
    let (p0, _) = planes();
    let params = CylinderParams::default();
    let mut rng = Rng::new(1);
    let mut curve = std::vec::Vec::new();
    let mut pts = std::vec![Vec2::zeros(); 800];
    let mut vals = std::vec![0.0; 3200];
    for (d, diam) in [(1.5, 0.3), (0.8, 0.12), (2.5, 0.5)] {
        let (d, diam): (Real, Real) = (d, diam);
        let c = Circle::new(Vec2::new(0.02, d + diam / 2.0), diam / 2.0);
        noisy_columns(&p0, &c, params.noise.image_px(), &mut rng, &mut curve);
        let sol = solve(
            &CylinderInput {
                curves: &[&curve],
                sigmas: &[&sigmas_of(&curve, &p0, &params)],
                planes: &[p0],
                uncertainty: None,
            },
            &params,
            Scratch {
                points: &mut pts,
                values: &mut vals,
                bins: &mut std::vec![Vec3::zeros(); MAX_PLANES * POINT_BUDGET],
                bin_sigmas: &mut std::vec![0.0; MAX_PLANES * POINT_BUDGET],
            },
        )
        .unwrap();
        // The uncertainty includes calibration (systematic, absent here) so it bounds
        // the random error from above; 4σ.
        assert!(
            (sol.diameter - diam).abs() < 4.0 * sol.uncertainty,
            "{sol:?}"
        );
        assert!(sol.flags.contains(Flags::TILT_IGNORED));
        // Round: never flagged elliptic (docs/cylinder.md, "Elliptic stems").
        assert!(
            !sol.flags.contains(Flags::ELLIPTIC) && sol.axes.is_none(),
            "{sol:?}"
        );
        assert!(sol.tilt.is_none());
        assert!(sol.three_tangent_diameter.is_some() && sol.fit_diameter.is_some());
        assert_eq!(sol.n_points, curve.len());
        assert!((sol.distance - d).abs() < 0.01);
        // Rule 3's bound, for any arc (`docs/cylinder.md` §6): a σ above a third of the
        // diameter does not bound the stem.
        assert_eq!(bounded(sol).map(|b| b.diameter), Ok(sol.diameter));
        for sigma in [0.34 * sol.diameter, Real::INFINITY, Real::NAN] {
            let loose = CylinderSolution {
                uncertainty: sigma,
                ..sol
            };
            assert_eq!(bounded(loose), Err(SolveError::Unbounded), "{sigma}");
        }
    }
}

/// Adds 0.3 mm of isotropic Gaussian noise to every point of two sections.
fn jitter(c0: &mut [Vec3], c1: &mut [Vec3], seed: u64) {
    let mut rng = Rng::new(seed);
    for x in c0.iter_mut().chain(c1.iter_mut()) {
        *x += Vec3::new(
            rng.gauss() as Real,
            rng.gauss() as Real,
            rng.gauss() as Real,
        ) * 3e-4;
    }
}

/// Gaussian noise of 0.3 mm on each point of `curve` along its noise direction in `plane`, as
/// a stripe's row error moves a triangulated point: it stays on its plane. (Isotropic 3-D
/// noise leaves the plane and, across the stripe at the limbs, exceeds the points' lateral σ:
/// the robust fit then rejects limb points that the binned curve's averages keep, a weighting
/// no measured curve has.)
fn jitter_along_rays(curve: &mut [Vec3], plane: &LaserPlane, seed: u64) {
    let mut rng = Rng::new(seed);
    let field = noise::DisplacementField::of(plane);
    for x in curve.iter_mut() {
        *x += field.direction(*x) * (rng.gauss() as Real * 3e-4);
    }
}

#[test]
fn solve_tilted_stem_two_planes() {
    let (p0, p1) = planes();
    let deg = PI / 180.0;
    let params = CylinderParams::default();
    let truth = tilted_cylinder(-10.0 * deg, 25.0 * deg, 0.2, Vec2::new(0.0, 1.6), &p0);
    let (mut c0, mut c1) = (std::vec::Vec::new(), std::vec::Vec::new());
    section(&truth, &p0, 1500, &mut c0);
    section(&truth, &p1, 1500, &mut c1);
    jitter(&mut c0, &mut c1, 9);
    let mut pts = std::vec![Vec2::zeros(); 1500];
    let mut vals = std::vec![0.0; 6000];
    let sol = solve(
        &CylinderInput {
            curves: &[&c0, &c1],
            sigmas: &[&sigmas_of(&c0, &p0, &params), &sigmas_of(&c1, &p1, &params)],
            planes: &[p0, p1],
            uncertainty: None,
        },
        &params,
        Scratch {
            points: &mut pts,
            values: &mut vals,
            bins: &mut std::vec![Vec3::zeros(); MAX_PLANES * POINT_BUDGET],
            bin_sigmas: &mut std::vec![0.0; MAX_PLANES * POINT_BUDGET],
        },
    )
    .unwrap();
    let tilt = sol.tilt.unwrap();
    assert!(
        (sol.diameter - 0.4).abs() < 4.0 * sol.uncertainty,
        "{sol:?}"
    );
    assert!((tilt.phi - 25.0 * deg).abs() < 2.0 * deg, "{tilt:?}");
    assert!((tilt.theta + 10.0 * deg).abs() < 2.0 * deg, "{tilt:?}");
    assert!(!sol.flags.contains(Flags::TILT_IGNORED));
    // The one-plane answer would have been inflated by ≈ 1/cos 25° = +10 %.
    let one = solve(
        &CylinderInput {
            curves: &[&c0],
            sigmas: &[&sigmas_of(&c0, &p0, &params)],
            planes: &[p0],
            uncertainty: None,
        },
        &params,
        Scratch {
            points: &mut pts,
            values: &mut vals,
            bins: &mut std::vec![Vec3::zeros(); MAX_PLANES * POINT_BUDGET],
            bin_sigmas: &mut std::vec![0.0; MAX_PLANES * POINT_BUDGET],
        },
    )
    .unwrap();
    assert!(one.diameter > 0.4 * 1.05, "{one:?}");
}

#[test]
fn solve_errors() {
    let (p0, p1) = planes();
    let params = CylinderParams::default();
    let mut pts = [Vec2::zeros(); 4];
    let mut vals = [0.0; 4];
    let curve = [Vec3::new(0.0, 0.0, 1.0); 10];
    let r = solve(
        &CylinderInput {
            curves: &[&curve],
            sigmas: &[&sigmas_of(&curve, &p0, &params)],
            planes: &[p0, p1],
            uncertainty: None,
        },
        &params,
        Scratch {
            points: &mut pts,
            values: &mut vals,
            bins: &mut std::vec![Vec3::zeros(); MAX_PLANES * POINT_BUDGET],
            bin_sigmas: &mut std::vec![0.0; MAX_PLANES * POINT_BUDGET],
        },
    );
    assert_eq!(r.err(), Some(SolveError::PlaneCount));
    let r = solve(
        &CylinderInput {
            curves: &[&curve],
            sigmas: &[&sigmas_of(&curve, &p0, &params)],
            planes: &[p0],
            uncertainty: None,
        },
        &params,
        Scratch {
            points: &mut pts,
            values: &mut vals,
            bins: &mut std::vec![Vec3::zeros(); MAX_PLANES * POINT_BUDGET],
            bin_sigmas: &mut std::vec![0.0; MAX_PLANES * POINT_BUDGET],
        },
    );
    assert_eq!(r.err(), Some(SolveError::ScratchTooSmall));
    // A 1.4 m stem: outside the plausible range (max radius 0.6 m).
    let mut rng = Rng::new(3);
    let mut big = std::vec::Vec::new();
    noisy_columns(
        &p0,
        &Circle::new(Vec2::new(0.0, 3.5), 0.7),
        0.0,
        &mut rng,
        &mut big,
    );
    let mut pts = std::vec![Vec2::zeros(); 800];
    let mut vals = std::vec![0.0; 3200];
    let r = solve(
        &CylinderInput {
            curves: &[&big],
            sigmas: &[&sigmas_of(&big, &p0, &params)],
            planes: &[p0],
            uncertainty: None,
        },
        &params,
        Scratch {
            points: &mut pts,
            values: &mut vals,
            bins: &mut std::vec![Vec3::zeros(); MAX_PLANES * POINT_BUDGET],
            bin_sigmas: &mut std::vec![0.0; MAX_PLANES * POINT_BUDGET],
        },
    );
    assert_eq!(r.err(), Some(SolveError::RadiusOutOfRange));
}

/// The fade-out bias term: a three-tangent solution whose edges stop short of the true
/// grazing rays by `g` radians (each side) gets `∂r/∂α·g` from an exact fitted circle
/// (σ_fit = 0), and the fit's σ adds in quadrature through `∂α_f/∂R = 1/(L cos α_f)`.
#[test]
fn edge_bias_sigma_measures_the_fade_gap() {
    let (c, r) = (Vec2::new(0.05, 2.0), 0.15);
    let mut pts = std::vec![Vec2::zeros(); 400];
    lit_arc(c, r, 400, &mut pts);
    let l = c.norm();
    let alpha_true = (r / l).asin();
    // Drop the outer points until the aperture has lost about 1 % of α on each side.
    let keep: std::vec::Vec<Vec2> = pts
        .iter()
        .copied()
        .filter(|q| {
            let psi = (q.x * c.y - q.y * c.x).atan2(q.dot(&c));
            psi.abs() <= 0.99 * alpha_true
        })
        .collect();
    let t = three_tangent(&keep, &ThreeTangentParams::default()).unwrap();
    let gap = alpha_true - t.alpha;
    assert!(gap > 0.0);
    let (dr_da, _) = t.partials();
    let exact = circle::Circle::new(c, r);
    let b = edge_bias_sigma(&t, &exact, 0.0);
    assert!(
        (b - dr_da * gap).abs() <= 1e-6 * b + 64.0 * EPS,
        "{b} vs {}",
        dr_da * gap
    );
    // The three-tangent radius really is short by about that much.
    assert!(
        ((r - t.radius) - b).abs() < 0.05 * b,
        "short by {} vs {b}",
        r - t.radius
    );
    let sf = 1e-3;
    let with_fit = edge_bias_sigma(&t, &exact, sf);
    let s_af = sf / (l * alpha_true.cos());
    assert!((with_fit - dr_da * gap.hypot(s_af)).abs() <= 1e-6 * with_fit);
    // Source inside the circle: no grazing geometry, no term.
    assert_eq!(
        edge_bias_sigma(&t, &circle::Circle::new(Vec2::new(0.0, 0.1), 0.2), 0.0),
        0.0
    );
}

/// [`solve`] on `curves` with scratch for curves of up to 1,600 points (on two planes, the
/// cylinder fit's tables for up to 1,777 points per curve).
fn read_with(
    curves: &[&[Vec3]],
    sigmas: &[&[Real]],
    planes: &[LaserPlane],
    params: &CylinderParams,
) -> CylinderSolution {
    let mut pts = std::vec![Vec2::zeros(); 1600];
    let mut vals = std::vec![0.0; 32_000];
    solve(
        &CylinderInput {
            curves,
            sigmas,
            planes,
            uncertainty: None,
        },
        params,
        Scratch {
            points: &mut pts,
            values: &mut vals,
            bins: &mut std::vec![Vec3::zeros(); MAX_PLANES * POINT_BUDGET],
            bin_sigmas: &mut std::vec![0.0; MAX_PLANES * POINT_BUDGET],
        },
    )
    .unwrap()
}

/// The point budget bins a long arc without moving the reading (`docs/error-model.md`, "Point
/// budget"): a 1 m stem at 1 m (≈ 700 columns) read with every point and with the default
/// budget differ by far less than the reading's σ, and the σ stays the same within 10 %.
#[test]
fn budget_keeps_the_reading() {
    let (p0, _) = planes();
    let all = CylinderParams {
        point_budget: usize::MAX,
        ..CylinderParams::default()
    };
    let budget = CylinderParams::default();
    let mut rng = Rng::new(3);
    let mut curve = std::vec::Vec::new();
    let mut worst: Real = 0.0;
    for (d, diam) in [(1.0, 1.0), (0.6, 0.6), (1.2, 0.8)] {
        let (d, diam): (Real, Real) = (d, diam);
        let c = Circle::new(Vec2::new(0.0, d + diam / 2.0), diam / 2.0);
        noisy_columns(&p0, &c, all.noise.image_px(), &mut rng, &mut curve);
        assert!(curve.len() > 2 * POINT_BUDGET, "{}", curve.len());
        let sigmas = sigmas_of(&curve, &p0, &all);
        let read = |params: &CylinderParams| read_with(&[&curve], &[&sigmas], &[p0], params);
        let (a, b) = (read(&all), read(&budget));
        let random = a.fit_uncertainty.unwrap();
        worst = worst.max((a.diameter - b.diameter).abs() / random);
        assert!(
            (a.diameter - b.diameter).abs() < 0.2 * random,
            "all {a:?}\nbudget {b:?}"
        );
        let ratio = b.uncertainty / a.uncertainty;
        assert!(ratio > 0.9 && ratio < 1.1, "all {a:?}\nbudget {b:?}");
        assert_eq!(b.n_points, curve.len());
    }
    std::println!("largest change of the reading: {worst:.3} σ");
}

/// On two planes the point budget bins both curves before every method (cylinder fit,
/// projected sections, generalised three-tangent): a 70 cm stem tilted 27° at 1.2 m read with
/// every point (≈ 1000 per curve, noise along each point's ray: [`jitter_along_rays`]) and
/// with the budget differs by far less than the reading's σ, and the σ (with the calibration
/// term, which follows the fit's weights along the arc) stays the same within 10 %.
#[test]
fn budget_on_two_planes_keeps_the_reading() {
    let (p0, p1) = planes();
    let deg = PI / 180.0;
    let all = CylinderParams {
        point_budget: usize::MAX,
        ..CylinderParams::default()
    };
    let budget = CylinderParams::default();
    let truth = tilted_cylinder(-10.0 * deg, 25.0 * deg, 0.35, Vec2::new(0.0, 1.2), &p0);
    let (mut c0, mut c1) = (std::vec::Vec::new(), std::vec::Vec::new());
    section(&truth, &p0, 1500, &mut c0);
    section(&truth, &p1, 1500, &mut c1);
    assert!(
        c0.len().min(c1.len()) > 2 * POINT_BUDGET,
        "{} {}",
        c0.len(),
        c1.len()
    );
    jitter_along_rays(&mut c0, &p0, 5);
    jitter_along_rays(&mut c1, &p1, 6);
    let (s0, s1) = (sigmas_of(&c0, &p0, &all), sigmas_of(&c1, &p1, &all));
    let read = |params: &CylinderParams| read_with(&[&c0, &c1], &[&s0, &s1], &[p0, p1], params);
    let (a, b) = (read(&all), read(&budget));
    assert!(
        a.tilt.is_some() && !a.flags.contains(Flags::TILT_IGNORED),
        "{a:?}"
    );
    let random = a.fit_uncertainty.unwrap();
    assert!(
        (a.diameter - b.diameter).abs() < 0.2 * random,
        "all {a:?}\nbudget {b:?}"
    );
    let ratio = b.uncertainty / a.uncertainty;
    assert!(ratio > 0.9 && ratio < 1.1, "all {a:?}\nbudget {b:?}");
    assert_eq!(b.n_points, c0.len() + c1.len());
    std::println!(
        "two planes: change {:.3} σ, σ ratio {ratio:.3}",
        (a.diameter - b.diameter).abs() / random
    );
}

/// Rule 3 (`docs/cylinder.md` §6): a short arc reports the fit with its σ, never the
/// three-tangent, and is refused once the fit's σ exceeds a third of its radius.
#[test]
fn choose_rules() {
    // Rule 1: both agree → the smaller σ.
    assert_eq!(
        choose(Some((0.10, 0.001)), Some((0.101, 0.002, false))),
        Some((false, false))
    );
    assert_eq!(
        choose(Some((0.10, 0.002)), Some((0.101, 0.001, false))),
        Some((true, false))
    );
    // Rule 2: disagreement beyond 3σ → the fit, inconsistent.
    assert_eq!(
        choose(Some((0.05, 0.001)), Some((0.10, 0.001, false))),
        Some((true, true))
    );
    // Rule 3: short arc → the fit even when the three-tangent's σ is smaller.
    assert_eq!(
        choose(Some((0.10, 0.001)), Some((0.101, 0.01, true))),
        Some((true, false))
    );
    assert_eq!(
        choose(Some((0.05, 0.001)), Some((0.30, 0.08, true))),
        Some((true, true))
    );
    assert_eq!(choose(None, Some((0.30, 0.09, true))), Some((true, false)));
    // …refused when the fit's 3σ interval reaches a zero radius.
    assert_eq!(choose(Some((0.10, 0.001)), Some((0.30, 0.11, true))), None);
    assert_eq!(choose(None, Some((0.30, 0.11, true))), None);
    assert_eq!(choose(None, Some((0.30, Real::NAN, true))), None);
    // Rule 4: no fit → no answer; no three-tangent → the fit.
    assert_eq!(choose(Some((0.10, 0.001)), None), None);
    assert_eq!(
        choose(None, Some((0.10, 0.001, false))),
        Some((true, false))
    );
    assert_eq!(choose(None, None), None);
}

/// The information σ (`docs/error-model.md` §6, (E6)) is the fit's actual spread on points
/// with independent noise of their stated σ: over 200 noise draws of a 30 cm stem at 1.5 m and
/// a 12 cm one at 0.8 m, the standard deviation of the fit diameter is the mean information σ
/// within three times the sampling error of a spread over 200 draws (±5 % at 1σ), and the
/// stated σ, which adds the bending and calibration terms, is never below it.
#[test]
fn the_information_sigma_is_the_fits_spread_on_white_noise() {
    let (p0, _) = planes();
    let params = CylinderParams::default();
    let mut rng = Rng::new(11);
    let mut curve = std::vec::Vec::new();
    for (d, diam) in [(1.5, 0.3), (0.8, 0.12)] {
        let (d, diam): (Real, Real) = (d, diam);
        let c = Circle::new(Vec2::new(0.02, d + diam / 2.0), diam / 2.0);
        let (mut sum, mut sum2, mut info, mut k) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        for _ in 0..200 {
            noisy_columns(&p0, &c, params.noise.image_px(), &mut rng, &mut curve);
            let sigmas = sigmas_of(&curve, &p0, &params);
            let sol = read_with(&[&curve], &[&sigmas], &[p0], &params);
            let (Some(fit), Some(i)) = (sol.fit_diameter, sol.information_uncertainty) else {
                panic!("no fit: {sol:?}");
            };
            assert!(sol.fit_uncertainty.unwrap() >= i, "{sol:?}");
            sum += fit as f64;
            sum2 += (fit as f64) * (fit as f64);
            info += i as f64;
            k += 1;
        }
        let n = k as f64;
        let spread = ((sum2 - sum * sum / n) / (n - 1.0)).sqrt();
        let ratio = spread / (info / n);
        std::println!("d {diam} at {d} m: spread / information σ = {ratio:.3}");
        assert!((0.85..1.15).contains(&ratio), "ratio {ratio}");
    }
}
