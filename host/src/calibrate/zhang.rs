//! Zhang's closed-form calibration: homographies, intrinsics, extrinsics, and a linear first
//! guess of the radial distortion (`docs/calibration.md`, sections 2–5).
//!
//! Why hand-written rather than `vision-calibration` (which has a Zhang solver): the result
//! must be expressed in the core's exact camera model and feed our own Levenberg–Marquardt
//! with its Jacobian (for the parameter standard deviations), and the closed form is some
//! fifty lines of linear algebra over `nalgebra`, which we already use.

use nalgebra::{DMatrix, Matrix3, Rotation3, Vector3};
use tangent_core::real::{Vec2, Vec3};

use super::{Board, CalibrateError, Pose, View};

/// The homography `H` (3×3, up to scale) that maps board points `(X, Y, 1)` (metres) to
/// pixels `(u, v, 1)`, by the normalised direct linear transform
/// (`docs/calibration.md`, "Homography"). `None` with fewer than 4 points or a degenerate
/// configuration (collinear points).
pub fn homography(board_pts: &[Vec2], image_pts: &[Vec2]) -> Option<Matrix3<f64>> {
    let n = board_pts.len();
    if n < 4 || image_pts.len() != n {
        return None;
    }
    let tb = normalising_transform(board_pts)?;
    let ti = normalising_transform(image_pts)?;
    let mut a = DMatrix::<f64>::zeros(2 * n, 9);
    for (k, (b, p)) in board_pts.iter().zip(image_pts).enumerate() {
        let xb = tb * Vector3::new(b.x, b.y, 1.0);
        let xi = ti * Vector3::new(p.x, p.y, 1.0);
        let (x, y) = (xb.x, xb.y);
        let (u, v) = (xi.x, xi.y);
        let r0 = [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u];
        let r1 = [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v];
        for c in 0..9 {
            a[(2 * k, c)] = r0[c];
            a[(2 * k + 1, c)] = r1[c];
        }
    }
    let h = null_vector(a)?;
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let h = ti.try_inverse()? * hn * tb;
    let scale = h[(2, 2)];
    if !(scale.is_finite() && scale.abs() > 0.0) {
        return Some(h / h.norm());
    }
    Some(h / scale)
}

/// Hartley's normalisation: translate the centroid to the origin and scale so that the
/// mean distance to it is √2. `None` if all points coincide.
fn normalising_transform(pts: &[Vec2]) -> Option<Matrix3<f64>> {
    let n = pts.len() as f64;
    let c = pts.iter().fold(Vec2::zeros(), |a, p| a + p) / n;
    let mean_dist = pts.iter().map(|p| (p - c).norm()).sum::<f64>() / n;
    if !(mean_dist.is_finite() && mean_dist > 0.0) {
        return None;
    }
    let s = std::f64::consts::SQRT_2 / mean_dist;
    Some(Matrix3::new(
        s,
        0.0,
        -s * c.x,
        0.0,
        s,
        -s * c.y,
        0.0,
        0.0,
        1.0,
    ))
}

/// Unit vector minimising `|A·x|`: the right singular vector of the smallest singular value.
fn null_vector(a: DMatrix<f64>) -> Option<Vec<f64>> {
    let cols = a.ncols();
    // For a wide or square-deficient A, pad with zero rows so that the SVD returns a full V.
    let a = if a.nrows() < cols {
        let mut p = DMatrix::zeros(cols, cols);
        p.view_mut((0, 0), (a.nrows(), cols)).copy_from(&a);
        p
    } else {
        a
    };
    let svd = a.svd(false, true);
    let v_t = svd.v_t?;
    let (imin, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))?;
    let row = v_t.row(imin);
    let v: Vec<f64> = row.iter().copied().collect();
    if v.iter().all(|x| x.is_finite()) {
        Some(v)
    } else {
        None
    }
}

/// The row `v_ij` of Zhang's constraint `h_iᵀ·B·h_j = v_ijᵀ·b`, with
/// `b = (B11, B12, B22, B13, B23, B33)` (`docs/calibration.md`, "Constraints on B").
fn v_ij(h: &Matrix3<f64>, i: usize, j: usize) -> [f64; 6] {
    let hi = h.column(i);
    let hj = h.column(j);
    [
        hi[0] * hj[0],
        hi[0] * hj[1] + hi[1] * hj[0],
        hi[1] * hj[1],
        hi[2] * hj[0] + hi[0] * hj[2],
        hi[2] * hj[1] + hi[1] * hj[2],
        hi[2] * hj[2],
    ]
}

/// Intrinsics `(fx, fy, cx, cy)` from per-view homographies by Zhang's closed form with
/// zero skew, computed in coordinates pre-normalised by the image size for conditioning.
///
/// Falls back to the principal point at the image centre (the same constraints solved for
/// the two focal lengths only, as OpenCV initialises) when the full solution is not a valid
/// camera — with two views, nearly parallel views, or strong distortion biasing the
/// homographies (`docs/calibration.md`, "Closed-form K").
pub fn intrinsics(
    homographies: &[Matrix3<f64>],
    width: u32,
    height: u32,
) -> Result<(f64, f64, f64, f64), CalibrateError> {
    if homographies.is_empty() {
        return Err(CalibrateError::TooFewViews {
            found: 0,
            needed: 2,
        });
    }
    // N maps pixels to roughly unit-size coordinates centred on the image.
    let s = 0.5 * (width as f64 + height as f64);
    let (c0x, c0y) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    let nmat = Matrix3::new(
        1.0 / s,
        0.0,
        -c0x / s,
        0.0,
        1.0 / s,
        -c0y / s,
        0.0,
        0.0,
        1.0,
    );
    let hs: Vec<Matrix3<f64>> = homographies
        .iter()
        .map(|h| {
            let g = nmat * h;
            g / g.norm()
        })
        .collect();
    let back = |fx: f64, fy: f64, cx: f64, cy: f64| (fx * s, fy * s, cx * s + c0x, cy * s + c0y);

    if let Some((fx, fy, cx, cy)) = full_closed_form(&hs) {
        // Accept only a camera whose principal point is inside the central half of the image
        // and whose aspect ratio is plausible; anything else signals a biased solution.
        let (fxp, fyp, cxp, cyp) = back(fx, fy, cx, cy);
        let inside =
            (cxp - c0x).abs() < 0.25 * width as f64 && (cyp - c0y).abs() < 0.25 * height as f64;
        let aspect = fxp / fyp;
        if inside && (0.5..2.0).contains(&aspect) {
            return Ok((fxp, fyp, cxp, cyp));
        }
    }
    let (fx, fy) = centred_closed_form(&hs).ok_or_else(|| {
        CalibrateError::Degenerate(
            "no focal length fits the homographies (views parallel to the image?)".into(),
        )
    })?;
    Ok(back(fx, fy, 0.0, 0.0))
}

/// Zhang's full solution for `b` (with the zero-skew row `B12 = 0`), then `K` from `B`.
fn full_closed_form(hs: &[Matrix3<f64>]) -> Option<(f64, f64, f64, f64)> {
    if hs.len() < 2 {
        return None;
    }
    let mut v = DMatrix::<f64>::zeros(2 * hs.len() + 1, 6);
    for (k, h) in hs.iter().enumerate() {
        let v12 = v_ij(h, 0, 1);
        let v11 = v_ij(h, 0, 0);
        let v22 = v_ij(h, 1, 1);
        for c in 0..6 {
            v[(2 * k, c)] = v12[c];
            v[(2 * k + 1, c)] = v11[c] - v22[c];
        }
    }
    // Zero skew: B12 = 0 (weighted like one homography's constraints).
    v[(2 * hs.len(), 1)] = 1.0;
    let b = null_vector(v)?;
    let (mut b11, mut b12, mut b22, mut b13, mut b23, mut b33) =
        (b[0], b[1], b[2], b[3], b[4], b[5]);
    if b11 < 0.0 {
        b11 = -b11;
        b12 = -b12;
        b22 = -b22;
        b13 = -b13;
        b23 = -b23;
        b33 = -b33;
    }
    let den = b11 * b22 - b12 * b12;
    if !(den > 0.0 && b11 > 0.0) {
        return None;
    }
    let v0 = (b12 * b13 - b11 * b23) / den;
    let lambda = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11;
    let alpha2 = lambda / b11;
    let beta2 = lambda * b11 / den;
    if !(alpha2 > 0.0 && beta2 > 0.0) {
        return None;
    }
    let (alpha, beta) = (alpha2.sqrt(), beta2.sqrt());
    let gamma = -b12 * alpha2 * beta / lambda;
    let u0 = gamma * v0 / beta - b13 * alpha2 / lambda;
    let all = [alpha, beta, u0, v0];
    if all.iter().all(|x| x.is_finite()) {
        Some((alpha, beta, u0, v0))
    } else {
        None
    }
}

/// The constraints with the principal point at the origin of the pre-normalised
/// coordinates: `B = diag(1/fx², 1/fy², 1)`, linear least squares in `(1/fx², 1/fy²)`.
fn centred_closed_form(hs: &[Matrix3<f64>]) -> Option<(f64, f64)> {
    let mut a = DMatrix::<f64>::zeros(2 * hs.len(), 2);
    let mut rhs = nalgebra::DVector::<f64>::zeros(2 * hs.len());
    for (k, h) in hs.iter().enumerate() {
        let (h1, h2) = (h.column(0), h.column(1));
        a[(2 * k, 0)] = h1[0] * h2[0];
        a[(2 * k, 1)] = h1[1] * h2[1];
        rhs[2 * k] = -h1[2] * h2[2];
        a[(2 * k + 1, 0)] = h1[0] * h1[0] - h2[0] * h2[0];
        a[(2 * k + 1, 1)] = h1[1] * h1[1] - h2[1] * h2[1];
        rhs[2 * k + 1] = -(h1[2] * h1[2] - h2[2] * h2[2]);
    }
    let sol = a.clone().svd(true, true).solve(&rhs, 1e-14).ok()?;
    let (ix, iy) = (sol[0], sol[1]);
    if ix > 0.0 && iy > 0.0 {
        let (fx, fy) = (1.0 / ix.sqrt(), 1.0 / iy.sqrt());
        if fx.is_finite() && fy.is_finite() {
            return Some((fx, fy));
        }
    }
    // One positive, one not: the views constrain only a common focal length well; use the
    // isotropic solution `fx = fy` (one unknown).
    let (mut num, mut den) = (0.0, 0.0);
    for r in 0..a.nrows() {
        let c = a[(r, 0)] + a[(r, 1)];
        num += c * rhs[r];
        den += c * c;
    }
    let i = num / den;
    if i > 0.0 && i.is_finite() {
        let f = 1.0 / i.sqrt();
        return Some((f, f));
    }
    None
}

/// The board pose from a homography and the intrinsics: `r1 = λK⁻¹h1`, `r2 = λK⁻¹h2`,
/// `r3 = r1 × r2`, `t = λK⁻¹h3`, with the sign making the board lie in front of the camera
/// and `R` projected onto the nearest rotation (`docs/calibration.md`, "Extrinsics").
pub fn pose_from_homography(k: &Matrix3<f64>, h: &Matrix3<f64>) -> Option<Pose> {
    let kinv = k.try_inverse()?;
    let a1 = kinv * h.column(0);
    let a2 = kinv * h.column(1);
    let a3 = kinv * h.column(2);
    let norm = 0.5 * (a1.norm() + a2.norm());
    if !(norm.is_finite() && norm > 0.0) {
        return None;
    }
    let mut lambda = 1.0 / norm;
    if (a3 * lambda).z < 0.0 {
        lambda = -lambda;
    }
    let r1 = a1 * lambda;
    let r2 = a2 * lambda;
    let r3 = r1.cross(&r2);
    let m = Matrix3::from_columns(&[r1, r2, r3]);
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut r = u * vt;
    if r.determinant() < 0.0 {
        let mut u2 = u;
        u2.column_mut(2).neg_mut();
        r = u2 * vt;
    }
    let t = a3 * lambda;
    if !t.iter().all(|x| x.is_finite()) {
        return None;
    }
    Some(Pose {
        rotation: Rotation3::from_matrix_unchecked(r),
        translation: t,
    })
}

/// Zhang's linear estimate of `(k1, k2)`: with the ideal normalised point `(x, y)`,
/// `r² = x² + y²` and the observed pixel `(ŭ, v̆)`, the model gives
/// `ŭ − u = (u − cx)(k1·r² + k2·r⁴)` and likewise in `v`; least squares over all corners
/// (`docs/calibration.md`, "Distortion, first guess").
pub fn radial_distortion_guess(
    k: &Matrix3<f64>,
    poses: &[Pose],
    views: &[&View],
    board: &Board,
) -> (f64, f64) {
    let (fx, fy, cx, cy) = (k[(0, 0)], k[(1, 1)], k[(0, 2)], k[(1, 2)]);
    let (mut ata, mut atb) = (
        nalgebra::Matrix2::<f64>::zeros(),
        nalgebra::Vector2::<f64>::zeros(),
    );
    for (pose, view) in poses.iter().zip(views) {
        for c in &view.corners {
            let x = pose.apply(&board.point(c.i, c.j));
            if x.z <= 0.0 {
                continue;
            }
            let (xn, yn) = (x.x / x.z, x.y / x.z);
            let r2 = xn * xn + yn * yn;
            let (u, v) = (fx * xn + cx, fy * yn + cy);
            for (d, obs) in [(u - cx, c.pixel.x - u), (v - cy, c.pixel.y - v)] {
                let row = nalgebra::Vector2::new(d * r2, d * r2 * r2);
                ata += row * row.transpose();
                atb += row * obs;
            }
        }
    }
    match ata.try_inverse() {
        Some(inv) => {
            let k = inv * atb;
            if k.iter().all(|x| x.is_finite()) {
                (k[0], k[1])
            } else {
                (0.0, 0.0)
            }
        }
        None => (0.0, 0.0),
    }
}

/// Board points (metres, `z` dropped) and pixels of a view, in corner order.
pub fn correspondences(view: &View, board: &Board) -> (Vec<Vec2>, Vec<Vec2>) {
    view.corners
        .iter()
        .map(|c| {
            let p: Vec3 = board.point(c.i, c.j);
            (Vec2::new(p.x, p.y), c.pixel)
        })
        .unzip()
}

/// `K` as a matrix.
pub fn k_matrix(fx: f64, fy: f64, cx: f64, cy: f64) -> Matrix3<f64> {
    Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0)
}

/// Rotation vector (axis × angle) of a pose, the parametrisation used by the refinement.
pub fn rotation_vector(r: &Rotation3<f64>) -> Vector3<f64> {
    r.scaled_axis()
}
