#![allow(clippy::unnecessary_cast)]

use super::*;
use crate::real::PI;

/// Exactness of noise-free fits: 1e-6 in f64, what f32 rounding leaves of metres otherwise.
const TOL: Real = if core::mem::size_of::<Real>() == 4 {
    2e-4
} else {
    1e-6
};

/// A small deterministic Gaussian source (LCG + Box–Muller), enough for Monte-Carlo checks.
pub(crate) struct Gauss(u64);

impl Gauss {
    pub(crate) fn new(seed: u64) -> Self {
        Gauss(seed.wrapping_mul(6364136223846793005).wrapping_add(1))
    }
    fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    pub(crate) fn next(&mut self) -> Real {
        let (a, b) = (self.uniform(), self.uniform());
        ((-2.0 * a.ln()).sqrt() * (2.0 * core::f64::consts::PI * b).cos()) as Real
    }
}

/// Two horizontal lines 50 mm apart on the plane through `(0, 0, z)` with normal `normal`,
/// `n` points each over ±`half` metres, noise `sigma` along the normal.
fn two_lines(normal: Vec3, z: Real, half: Real, n: usize, sigma: Real, seed: u64) -> [Vec3; 400] {
    assert!(2 * n <= 400);
    let normal = normal.normalize();
    let p0 = Vec3::new(0.0, 0.0, z);
    // In-plane axes: horizontal and "down".
    let u = Vec3::y().cross(&normal).normalize();
    let v = normal.cross(&u);
    let mut g = Gauss::new(seed);
    let mut out = [Vec3::zeros(); 400];
    for (i, o) in out.iter_mut().take(2 * n).enumerate() {
        let t = -half + 2.0 * half * (i % n) as Real / (n - 1) as Real;
        let s = if i < n { 0.0 } else { 0.05 };
        *o = p0 + u * t + v * s + normal * (sigma * g.next());
    }
    out
}

#[test]
fn an_exact_plane_is_recovered() {
    let normal = Vec3::new(0.3, -0.1, 1.0).normalize();
    let pts = two_lines(normal, 2.0, 0.6, 100, 0.0, 1);
    let fit = fit_plane(pts[..200].iter().map(|&p| (p, 1e-3))).unwrap();
    assert!((fit.normal - normal).norm() < TOL, "{:?}", fit.normal);
    assert!((fit.offset - 2.0 * normal.z).abs() < TOL);
    assert!(fit.quality > 0.999 && fit.rms < TOL && fit.points == 200);
}

#[test]
fn collinear_points_are_degenerate_and_bad_values_refused() {
    let line: [Vec3; 20] = core::array::from_fn(|i| Vec3::new(i as Real * 0.01, 0.0, 2.0));
    assert_eq!(
        fit_plane(line.iter().map(|&p| (p, 1e-3))),
        Err(SolveError::Degenerate)
    );
    assert_eq!(
        fit_plane(line[..2].iter().map(|&p| (p, 1e-3))),
        Err(SolveError::TooFewPoints)
    );
    assert_eq!(
        fit_plane(line.iter().map(|&p| (p, 0.0))),
        Err(SolveError::NonFinite)
    );
    let mut bad = line;
    bad[3].x = Real::NAN;
    assert_eq!(
        fit_plane(bad.iter().map(|&p| (p, 1e-3))),
        Err(SolveError::NonFinite)
    );
}

/// The predicted σ of the pitch (tilt about the lines, the weak direction) and yaw covers
/// the Monte-Carlo scatter: 2σ coverage between 90 and 98 %.
#[test]
fn predicted_sigmas_cover_the_scatter() {
    let normal = Vec3::new(0.2, 0.0, 1.0).normalize();
    let truth = orientation(
        &fit_plane(
            two_lines(normal, 2.0, 0.6, 150, 0.0, 0)[..300]
                .iter()
                .map(|&p| (p, 1e-3)),
        )
        .unwrap(),
    )
    .unwrap();
    let (mut inside_pitch, mut inside_yaw, mut inside_z, runs) = (0, 0, 0, 400);
    for seed in 0..runs {
        let pts = two_lines(normal, 2.0, 0.6, 150, 1e-3, 100 + seed);
        let fit = fit_plane(pts[..300].iter().map(|&p| (p, 1e-3))).unwrap();
        let o = orientation(&fit).unwrap();
        inside_pitch += ((o.pitch.value - truth.pitch.value).abs() <= 2.0 * o.pitch.sigma) as u32;
        inside_yaw += ((o.yaw.value - truth.yaw.value).abs() <= 2.0 * o.yaw.sigma) as u32;
        inside_z += ((o.axis_distance.value - truth.axis_distance.value).abs()
            <= 2.0 * o.axis_distance.sigma) as u32;
    }
    for (name, k) in [
        ("pitch", inside_pitch),
        ("yaw", inside_yaw),
        ("z", inside_z),
    ] {
        let c = k as f64 / runs as f64;
        assert!((0.90..=0.98).contains(&c), "{name}: 2σ coverage {c}");
    }
}

#[test]
fn angle_distance_and_plumb_of_known_planes() {
    let a = fit_plane(
        two_lines(Vec3::new(1.0, 0.0, 1.0), 2.0, 0.5, 100, 0.0, 0)[..200]
            .iter()
            .map(|&p| (p, 1e-3)),
    )
    .unwrap();
    let b = fit_plane(
        two_lines(Vec3::new(-1.0, 0.0, 1.0), 2.0, 0.5, 100, 0.0, 0)[..200]
            .iter()
            .map(|&p| (p, 1e-3)),
    )
    .unwrap();
    let angle = normal_angle(&a, &b);
    assert!((angle.value - PI / 2.0).abs() < TOL && angle.sigma > 0.0);
    let far = fit_plane(
        two_lines(Vec3::new(1.0, 0.0, 1.0), 2.5, 0.5, 100, 0.0, 0)[..200]
            .iter()
            .map(|&p| (p, 1e-3)),
    )
    .unwrap();
    let d = parallel_distance(&a, &far);
    let expected = 0.5 * (0.5 as Real).sqrt();
    assert!((d.value - expected).abs() < TOL, "{}", d.value);
    // A vertical wall is plumb; a gravity 1° off the camera's y axis towards z reads 1°.
    let tilt = (1.0 as Real).to_radians();
    let p = plumb_deviation(&a, Vec3::new(0.0, tilt.cos(), tilt.sin()), 0.0).unwrap();
    assert!(
        (p.value - tilt * (0.5 as Real).sqrt()).abs() < TOL,
        "{}",
        p.value
    );
    let (point, dir) = plane_intersection(a.normal, a.offset, b.normal, b.offset).unwrap();
    assert!(dir.x.abs() < TOL && dir.z.abs() < TOL);
    assert!((point - Vec3::new(0.0, 0.0, 2.0)).norm() < TOL);
    assert!(plane_intersection(a.normal, a.offset, far.normal, far.offset).is_none());
}

#[test]
fn a_line_bias_predicts_the_tilt_it_causes() {
    // A frontal wall at 1.5 m lit by two lines 50 mm apart; the lower line's points all move
    // by the same ∂X/∂v·b (a stripe-row bias b shared along the line). The rotation the refit
    // shows must be what add_line_bias predicts for that line alone.
    let normal = Vec3::z();
    let pts = two_lines(normal, 1.5, 0.5, 100, 0.0, 1);
    let sigma = 1e-3;
    let dxdv = Vec3::new(0.0, 1.5e-3, -22.5e-3); // ≈ z/f, −z²/(f e) at 1.5 m, e = 0.1 m
    let bias = 0.01;
    let shifted = |i: usize, p: Vec3| if i >= 100 { p + dxdv * bias } else { p };
    let clean = fit_plane(pts[..200].iter().map(|&p| (p, sigma))).unwrap();
    let biased = fit_plane(
        pts[..200]
            .iter()
            .enumerate()
            .map(|(i, &p)| (shifted(i, p), sigma)),
    )
    .unwrap();
    let tilt = (biased.normal - clean.normal).dot(&Vec3::y()).abs();
    // Line 0 is counted in the weights but not biased (line index beyond MAX_LINES).
    let mut fit = clean;
    fit.normal_cov = Mat3::zeros();
    fit.centroid_sigma = 0.0;
    let lines = pts[..200]
        .iter()
        .enumerate()
        .map(|(i, &p)| (if i >= 100 { 1 } else { MAX_LINES }, p, sigma, dxdv));
    add_line_bias(&mut fit, lines, bias);
    let predicted = sqrt(fit.normal_variance_along(Vec3::y()));
    assert!(tilt > 1e-4, "the bias tilts the plane: {tilt}");
    assert!(
        (predicted - tilt).abs() <= 0.02 * tilt + TOL / 10.0,
        "predicted {predicted} rad, refit moved {tilt} rad"
    );
    // The plane's move along its normal at the centroid.
    let shift = biased.signed_distance(clean.centroid).abs();
    assert!((fit.centroid_sigma - shift).abs() <= 0.02 * shift + TOL);
    // No bias, no change.
    let mut same = clean;
    add_line_bias(&mut same, core::iter::empty(), 0.01);
    assert_eq!(same, clean);
}
