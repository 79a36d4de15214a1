//! Tests of `camera`.
// The casts to f64 are no-ops in f64 builds but needed with `--features f32`.
#![allow(clippy::unnecessary_cast)]

use super::*;

/// Machine epsilon of the precision under test, as `f64`.
const EPS: f64 = Real::EPSILON as f64;

/// Strong distortion of the brief: barrel `k1 = −0.3` with the usual opposite-sign `k2`,
/// a small `k3` and 1e-3-level decentering.
fn strong() -> Distortion {
    Distortion {
        k1: -0.3,
        k2: 0.1,
        k3: -0.01,
        p1: 1e-3,
        p2: -1e-3,
    }
}

/// The reference sensor with the strong lens (corner at r_d ≈ 0.45).
fn reference_strong() -> Camera {
    Camera {
        distortion: strong(),
        ..Camera::reference_design()
    }
}

/// A wide-angle variant (f = 400 px, corner at r_d ≈ 1.06, ~30 % distortion there).
fn wide_strong() -> Camera {
    Camera {
        fx: 400.0,
        fy: 402.0,
        cx: 380.2,
        cy: 236.9,
        distortion: strong(),
        ..Camera::reference_design()
    }
}

/// OpenCV's distortion written out independently, term by term, in f64: the ground
/// truth the `Real` implementation is checked against.
fn distort_f64(k: &Distortion, x: f64, y: f64) -> (f64, f64) {
    let (k1, k2, k3, p1, p2) = (
        k.k1 as f64,
        k.k2 as f64,
        k.k3 as f64,
        k.p1 as f64,
        k.p2 as f64,
    );
    let r2 = x * x + y * y;
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
    (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )
}

#[test]
fn distortion_matches_hand_computed_opencv_case() {
    // Worked by hand (exact decimals) for (x, y) = (0.3, −0.2):
    // r² = 0.13; radial = 1 − 0.3·0.13 + 0.1·0.0169 − 0.02·0.002197 = 0.96264606
    // x_d = 0.3·radial + 2·0.001·0.3·(−0.2) − 0.0005·(0.13 + 0.18) = 0.288518818
    // y_d = −0.2·radial + 0.001·(0.13 + 0.08) + 2·(−0.0005)·0.3·(−0.2) = −0.192259212
    let k = Distortion {
        k1: -0.3,
        k2: 0.1,
        k3: -0.02,
        p1: 0.001,
        p2: -0.0005,
    };
    let d = k.apply(Vec2::new(0.3, -0.2));
    // ~10 roundings of O(0.3) values: 10·ε·0.3 bounds the evaluation error.
    let tol = 10.0 * EPS * 0.3;
    assert!((d.x as f64 - 0.288518818).abs() <= tol, "{}", d.x);
    assert!((d.y as f64 + 0.192259212).abs() <= tol, "{}", d.y);
}

#[test]
fn jacobian_matches_central_differences() {
    let k = strong();
    let h = 1e-3 as Real;
    for &(x, y) in &[(0.3, -0.2), (-0.7, 0.5), (0.05, 0.9), (0.0, 0.0)] {
        let p = Vec2::new(x, y);
        let (_, j) = k.apply_with_jacobian(p);
        for (col, dp) in [Vec2::new(h, 0.0), Vec2::new(0.0, h)].iter().enumerate() {
            let fd = (k.apply(p + dp) - k.apply(p - dp)) / (2.0 * h);
            // Central-difference truncation error h²/6·|f'''| (|f'''| ≲ 6 here: 6·|k1|
            // plus higher terms at r ≤ 1.1) plus rounding ε·|f|/h.
            let tol = (h * h) as f64 + 4.0 * EPS / h as f64;
            assert!((fd.x - j[0][col]).abs() as f64 <= tol, "{x},{y} col {col}");
            assert!((fd.y - j[1][col]).abs() as f64 <= tol, "{x},{y} col {col}");
        }
    }
}

#[test]
fn pinhole_projection_is_the_passage_equation() {
    let cam = Camera::reference_design();
    let px = cam.project(Vec3::new(0.25, -0.1, 2.0)).unwrap();
    // u = f·x/z + cx = 1000·0.125 + 375.5, v = 1000·(−0.05) + 239.5.
    assert!((px.x as f64 - 500.5).abs() <= 4.0 * EPS * 500.5);
    assert!((px.y as f64 - 189.5).abs() <= 4.0 * EPS * 239.5);
    let ray = cam.pixel_to_ray(px).unwrap();
    assert!((ray.x as f64 - 0.125).abs() <= 4.0 * EPS * 500.0 / 1000.0);
    assert!((ray.y as f64 + 0.05).abs() <= 4.0 * EPS * 240.0 / 1000.0);
    assert_eq!(ray.z, 1.0);
}

#[test]
fn project_then_pixel_to_ray_round_trips() {
    for cam in [reference_strong(), wide_strong()] {
        cam.validate().unwrap();
        for &(x, y, z) in &[
            (0.3, -0.2, 2.0),
            (-0.1, 0.05, 0.7),
            (0.0, 0.0, 1.0),
            (0.12, 0.11, 1.3),
        ] {
            let px = cam.project(Vec3::new(x, y, z)).unwrap();
            let ray = cam.pixel_to_ray(px).unwrap();
            let (ex, ey) = (x as f64 / z as f64, y as f64 / z as f64);
            // Error model: the pixel carries ~2 ε·|u| of rounding (|u| < 1000), i.e.
            // 2ε·1000/f in normalised units, amplified by |J⁻¹| ≤ 1.5, plus the
            // inverse's own floor (8 ε (1 + |d|)); ×2 margin.
            let tol = 2.0 * (2.0 * EPS * 1000.0 / cam.fx as f64 * 1.5 + 8.0 * EPS * 2.0);
            assert!((ray.x as f64 - ex).abs() <= tol, "{} vs {ex}", ray.x);
            assert!((ray.y as f64 - ey).abs() <= tol, "{} vs {ey}", ray.y);
        }
    }
}

#[test]
fn undistort_converges_over_whole_image() {
    for cam in [reference_strong(), wide_strong()] {
        let f = cam.fx.max(cam.fy) as f64;
        let mut worst: f64 = 0.0;
        let mut count = 0;
        let (w, h) = (cam.width as i32, cam.height as i32);
        // Every 4th pixel plus the extreme edges −0.5 and w − 0.5.
        let us = (0..w)
            .step_by(4)
            .map(|i| i as Real)
            .chain([-0.5, w as Real - 0.5]);
        for u in us {
            let vs = (0..h)
                .step_by(4)
                .map(|j| j as Real)
                .chain([-0.5, h as Real - 0.5]);
            for v in vs {
                let d = Vec2::new((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy);
                let p = cam.undistort(d).unwrap();
                // Newton itself (not the fallback) must be what converged.
                assert_eq!(cam.undistort_newton(d), Some(p));
                // Residual measured in f64 with the independent formula.
                let (xd, yd) = distort_f64(&cam.distortion, p.x as f64, p.y as f64);
                let ru = (xd - d.x as f64) * cam.fx as f64;
                let rv = (yd - d.y as f64) * cam.fy as f64;
                let res = (ru * ru + rv * rv).sqrt();
                // Error model: the solution is exact up to the rounding of evaluating
                // the distortion in `Real` (≈ 4 ε|d|) and of storing p (ε|p|/2),
                // amplified by |J⁻¹| ≤ 1.5 here: ≤ 8 ε (1 + |d|) in normalised units.
                // In f64 that is ~1e-11 px, far inside the brief's 1e-4 px; in f32
                // ~1.4e-3 px at f = 1000.
                let tol = (8.0 * EPS * (1.0 + d.norm() as f64) * f).min(1e-4);
                let tol = if EPS < 1e-10 {
                    tol
                } else {
                    8.0 * EPS * (1.0 + d.norm() as f64) * f
                };
                assert!(res <= tol, "pixel ({u}, {v}): residual {res} px > {tol}");
                worst = worst.max(res);
                count += 1;
            }
        }
        assert!(count > 20_000);
        extern crate std;
        std::println!("f = {f}: worst undistort residual {worst:e} px over {count} pixels");
    }
}

#[test]
fn undistort_recovers_known_ideal_points() {
    let cam = wide_strong();
    for i in -10..=10 {
        for j in -6..=6 {
            let (x, y) = (i as f64 * 0.09, j as f64 * 0.09);
            let (xd, yd) = distort_f64(&cam.distortion, x, y);
            let p = cam.undistort(Vec2::new(xd as Real, yd as Real)).unwrap();
            // Rounding the input to `Real` (ε|d|/2) plus the inverse's floor
            // (8 ε (1 + |d|)), through |J⁻¹| ≤ 1.5.
            let tol = 1.5 * (0.5 * EPS * 1.3 + 8.0 * EPS * 2.3);
            assert!(
                (p.x as f64 - x).abs() <= tol && (p.y as f64 - y).abs() <= tol,
                "{x},{y}: {p:?}"
            );
        }
    }
}

#[test]
fn fixed_point_fallback_converges_for_moderate_lens() {
    // The fallback is a contraction for the reference sensor's strong lens (Lipschitz
    // constant ≈ 3|k1| r² ≈ 0.2 at the corner), so it reaches the same floor as Newton.
    let cam = reference_strong();
    for &(u, v) in &[(-0.5, -0.5), (751.5, 479.5), (100.0, 400.0), (375.5, 239.5)] {
        let d = Vec2::new((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy);
        let p = cam.undistort_fixed_point(d).unwrap();
        let (xd, yd) = distort_f64(&cam.distortion, p.x as f64, p.y as f64);
        let res = ((xd - d.x as f64).hypot(yd - d.y as f64)) * cam.fx as f64;
        let tol = 8.0 * EPS * (1.0 + d.norm() as f64) * cam.fx as f64;
        assert!(res <= tol, "({u}, {v}): {res} px");
    }
}

#[test]
fn validity_region_is_where_radial_distortion_is_monotone() {
    // k1 = −0.3 alone: d(r·radial)/dr = 1 − 0.9 r², zero at r² = 1/0.9.
    let k = Distortion {
        k1: -0.3,
        ..Distortion::default()
    };
    assert!(k.radially_monotone_up_to(1.0 / 0.9 - 1e-3));
    assert!(!k.radially_monotone_up_to(1.0 / 0.9 + 1e-3));
    // k1 = −0.3, k2 = 0.02: g(s) = 1 − 0.9 s + 0.1 s², roots s = (0.9 ∓ √0.41)/0.2 =
    // 1.29844…, 7.70156…; g > 0 again beyond the second root, but the lens folded in
    // between, so r² = 9 must still be rejected.
    let k = Distortion {
        k1: -0.3,
        k2: 0.02,
        ..Distortion::default()
    };
    let s1 = (0.9 - (0.41 as Real).sqrt()) / 0.2;
    assert!(k.radially_monotone_up_to(s1 - 1e-3));
    assert!(!k.radially_monotone_up_to(s1 + 1e-3));
    assert!(!k.radially_monotone_up_to(9.0));
    // Pinhole: always monotone; negative / NaN radii rejected.
    assert!(Distortion::default().radially_monotone_up_to(1e6));
    assert!(!Distortion::default().radially_monotone_up_to(Real::NAN));
}

#[test]
fn fold_over_is_rejected() {
    // A point at ideal radius 1.5 would land at r_d = 1.5 − 0.3·1.5³ = 0.4875, inside a
    // 300 px-focal image, though the lens never sends it there.
    let cam = Camera {
        fx: 300.0,
        fy: 300.0,
        distortion: Distortion {
            k1: -0.3,
            ..Distortion::default()
        },
        ..Camera::reference_design()
    };
    assert_eq!(
        cam.project(Vec3::new(1.5, 0.0, 1.0)),
        Err(CameraError::OutsideValidRegion)
    );
    // The largest distorted radius is r·radial at r = 1/√0.9: 0.7027; the image corner
    // at r_d ≈ 1.48 has no pre-image, so the camera is invalid.
    assert!(cam.undistort(Vec2::new(1.2, 0.8)).is_err());
    assert_eq!(cam.validate(), Err(CameraError::InvalidDistortion));
}

#[test]
fn error_cases() {
    let cam = reference_strong();
    assert_eq!(
        cam.project(Vec3::new(0.1, 0.1, 0.0)),
        Err(CameraError::BehindCamera)
    );
    assert_eq!(
        cam.project(Vec3::new(0.1, 0.1, -1.0)),
        Err(CameraError::BehindCamera)
    );
    assert_eq!(
        cam.project(Vec3::new(Real::NAN, 0.1, 1.0)),
        Err(CameraError::NonFinite)
    );
    assert_eq!(
        cam.pixel_to_ray(Vec2::new(Real::INFINITY, 3.0)),
        Err(CameraError::NonFinite)
    );
    let zero_f = Camera { fx: 0.0, ..cam };
    assert_eq!(zero_f.validate(), Err(CameraError::InvalidIntrinsics));
    assert_eq!(
        zero_f.pixel_to_ray(Vec2::new(10.0, 10.0)),
        Err(CameraError::InvalidIntrinsics)
    );
    assert_eq!(
        Camera { fy: -1000.0, ..cam }.validate(),
        Err(CameraError::InvalidIntrinsics)
    );
    assert_eq!(
        Camera { width: 0, ..cam }.validate(),
        Err(CameraError::InvalidIntrinsics)
    );
    assert_eq!(
        Camera {
            cx: Real::NAN,
            ..cam
        }
        .validate(),
        Err(CameraError::InvalidIntrinsics)
    );
    let nan_k = Camera {
        distortion: Distortion {
            k2: Real::NAN,
            ..strong()
        },
        ..cam
    };
    assert_eq!(nan_k.validate(), Err(CameraError::InvalidDistortion));
}

#[test]
fn contains_uses_pixel_edges() {
    let cam = Camera::reference_design();
    assert!(cam.contains(Vec2::new(-0.5, -0.5)));
    assert!(cam.contains(Vec2::new(751.5, 479.5)));
    assert!(!cam.contains(Vec2::new(751.6, 0.0)));
    assert!(!cam.contains(Vec2::new(0.0, -0.6)));
}
