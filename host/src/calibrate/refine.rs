//! Levenberg–Marquardt refinement of the whole camera model and every board pose, started
//! from Zhang's closed form (`docs/calibration.md`, sections 6–7).
//!
//! Parameters: `(fx, fy, cx, cy, k1, k2, p1, p2, k3)` (OpenCV's order), then per view a
//! rotation vector and a translation. Residuals: projected − observed pixel, through the
//! core's [`Camera::normalised_to_pixel`], so the calibrated model is exactly the one the
//! instrument evaluates. The Jacobian is by central differences, block by block (the 9
//! intrinsic columns touch every view, the 6 pose columns of a view touch only that view),
//! and the normal matrix `JᵀJ` is assembled from those blocks.
//!
//! Why hand-written rather than a crate (`levenberg-marquardt`, `argmin`): the problem has
//! the block structure above, which a generic dense solver would ignore, and we need `JᵀJ`
//! at the optimum for the parameter covariance anyway.

use nalgebra::{DMatrix, DVector, Rotation3, Vector3};
use tangent_core::camera::{Camera, Distortion};
use tangent_core::real::Vec2;

use super::zhang;
use super::{Board, CalibrateError, Pose, View};

/// Number of intrinsic parameters (`fx, fy, cx, cy, k1, k2, p1, p2, k3`).
pub const N_INTRINSICS: usize = 9;

/// Names of the intrinsic parameters, in parameter order.
pub const INTRINSIC_NAMES: [&str; N_INTRINSICS] =
    ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"];

/// A view whose RMS reprojection error exceeds this multiple of the median view RMS is
/// reported as an outlier: with equally good corners the per-view RMS values scatter by
/// roughly `1/√(2n)` of their value (n ≈ 50 corners, ±10 %), so three times the median is
/// far outside chance and points at a bad detection, motion blur or a moving board.
pub const OUTLIER_VIEW_FACTOR: f64 = 3.0;

/// Most Levenberg–Marquardt iterations.
pub const MAX_ITERATIONS: usize = 200;

/// The result of a camera calibration.
#[derive(Debug, Clone)]
pub struct CameraCalibration {
    /// The calibrated camera.
    pub camera: Camera,
    /// The closed-form (Zhang) starting point, for the report.
    pub initial: Camera,
    /// Names of the views used (as in the input order).
    pub view_names: Vec<String>,
    /// Board pose of each view.
    pub poses: Vec<Pose>,
    /// Per view, per corner: (observed pixel, projected − observed residual).
    pub residuals: Vec<Vec<(Vec2, Vec2)>>,
    /// RMS reprojection error per view (pixels), `sqrt(Σ|r|² / n)` over its corners.
    pub per_view_rms: Vec<f64>,
    /// Overall RMS reprojection error (pixels), `sqrt(Σ|r|² / N)` over all corners
    /// (OpenCV's definition).
    pub rms: f64,
    /// Standard deviation of the intrinsics, same order as [`INTRINSIC_NAMES`], from
    /// `σ²·(JᵀJ)⁻¹` with `σ²` the residual variance per coordinate.
    pub std_dev: [f64; N_INTRINSICS],
    /// `σ`: the residual standard deviation per coordinate (pixels), `sqrt(Σr² / (m − p))`.
    pub sigma: f64,
    /// Indices of the views reported as outliers (see [`OUTLIER_VIEW_FACTOR`]).
    pub outlier_views: Vec<usize>,
    /// Iterations the refinement took.
    pub iterations: usize,
}

impl CameraCalibration {
    /// Total number of corners used.
    pub fn corner_count(&self) -> usize {
        self.residuals.iter().map(|v| v.len()).sum()
    }
}

fn camera_from(p: &[f64], width: u32, height: u32) -> Camera {
    Camera {
        width,
        height,
        fx: p[0],
        fy: p[1],
        cx: p[2],
        cy: p[3],
        distortion: Distortion {
            k1: p[4],
            k2: p[5],
            p1: p[6],
            p2: p[7],
            k3: p[8],
        },
    }
}

fn intrinsic_params(c: &Camera) -> [f64; N_INTRINSICS] {
    let d = c.distortion;
    [c.fx, c.fy, c.cx, c.cy, d.k1, d.k2, d.p1, d.p2, d.k3]
}

fn pose_from(p: &[f64]) -> Pose {
    Pose {
        rotation: Rotation3::from_scaled_axis(Vector3::new(p[0], p[1], p[2])),
        translation: Vector3::new(p[3], p[4], p[5]),
    }
}

/// Residuals of one view (projected − observed, `u` then `v` per corner) into `out`.
fn view_residuals(cam: &Camera, pose: &[f64], view: &View, board: &Board, out: &mut [f64]) {
    let pose = pose_from(pose);
    for (k, c) in view.corners.iter().enumerate() {
        let x = pose.apply(&board.point(c.i, c.j));
        let ideal = Vec2::new(x.x / x.z, x.y / x.z);
        let px = cam.normalised_to_pixel(ideal);
        out[2 * k] = px.x - c.pixel.x;
        out[2 * k + 1] = px.y - c.pixel.y;
    }
}

/// Central-difference step for a parameter of value `v`: relative 1e-6 with an absolute
/// floor. The truncation error of a central difference is O(h²·f‴) ≈ 1e-12 relative and the
/// rounding error O(ε/h) ≈ 1e-10 relative: both far below what the covariance needs.
fn step(v: f64, floor: f64) -> f64 {
    1e-6 * (v.abs() + floor)
}

struct Problem<'a> {
    views: &'a [&'a View],
    board: &'a Board,
    width: u32,
    height: u32,
    /// Offsets of each view's residuals.
    offsets: Vec<usize>,
    m: usize,
}

impl Problem<'_> {
    fn n(&self) -> usize {
        N_INTRINSICS + 6 * self.views.len()
    }

    fn residuals(&self, p: &[f64]) -> DVector<f64> {
        let cam = camera_from(p, self.width, self.height);
        let mut r = DVector::zeros(self.m);
        for (v, view) in self.views.iter().enumerate() {
            let o = self.offsets[v];
            let pose = &p[N_INTRINSICS + 6 * v..N_INTRINSICS + 6 * v + 6];
            view_residuals(
                &cam,
                pose,
                view,
                self.board,
                &mut r.as_mut_slice()[o..o + 2 * view.corners.len()],
            );
        }
        r
    }

    /// `(JᵀJ, Jᵀr)` at `p`, assembled from the per-view blocks.
    fn normal_equations(&self, p: &[f64], r: &DVector<f64>) -> (DMatrix<f64>, DVector<f64>) {
        let n = self.n();
        let mut jtj = DMatrix::zeros(n, n);
        let mut jtr = DVector::zeros(n);
        // Intrinsic columns: full residual vectors.
        let mut j_int = DMatrix::<f64>::zeros(self.m, N_INTRINSICS);
        for c in 0..N_INTRINSICS {
            let floor = if c < 4 { 1.0 } else { 1e-2 };
            let h = step(p[c], floor);
            let mut pp = p.to_vec();
            pp[c] = p[c] + h;
            let rp = self.residuals(&pp);
            pp[c] = p[c] - h;
            let rm = self.residuals(&pp);
            j_int.set_column(c, &((rp - rm) / (2.0 * h)));
        }
        let cam = camera_from(p, self.width, self.height);
        for (v, view) in self.views.iter().enumerate() {
            let o = self.offsets[v];
            let len = 2 * view.corners.len();
            let base = N_INTRINSICS + 6 * v;
            let mut j_pose = DMatrix::<f64>::zeros(len, 6);
            let mut pose = [0.0; 6];
            pose.copy_from_slice(&p[base..base + 6]);
            let (mut rp, mut rm) = (vec![0.0; len], vec![0.0; len]);
            for c in 0..6 {
                let floor = if c < 3 { 1.0 } else { 1e-2 };
                let h = step(pose[c], floor);
                let mut q = pose;
                q[c] = pose[c] + h;
                view_residuals(&cam, &q, view, self.board, &mut rp);
                q[c] = pose[c] - h;
                view_residuals(&cam, &q, view, self.board, &mut rm);
                for k in 0..len {
                    j_pose[(k, c)] = (rp[k] - rm[k]) / (2.0 * h);
                }
            }
            let ji = j_int.rows(o, len);
            let rv = r.rows(o, len);
            // Blocks of JᵀJ: intrinsic × pose and pose × pose; the intrinsic × intrinsic
            // block is accumulated over views.
            let cross = ji.transpose() * &j_pose;
            jtj.view_mut((0, base), (N_INTRINSICS, 6)).copy_from(&cross);
            jtj.view_mut((base, 0), (6, N_INTRINSICS))
                .copy_from(&cross.transpose());
            jtj.view_mut((base, base), (6, 6))
                .copy_from(&(j_pose.transpose() * &j_pose));
            jtr.rows_mut(base, 6).copy_from(&(j_pose.transpose() * rv));
        }
        jtj.view_mut((0, 0), (N_INTRINSICS, N_INTRINSICS))
            .copy_from(&(j_int.transpose() * &j_int));
        jtr.rows_mut(0, N_INTRINSICS)
            .copy_from(&(j_int.transpose() * r));
        (jtj, jtr)
    }
}

/// Zhang's closed form for the intrinsics and poses, plus the linear `(k1, k2)` guess.
pub fn initial_estimate(
    views: &[&View],
    board: &Board,
    width: u32,
    height: u32,
) -> Result<(Camera, Vec<Pose>), CalibrateError> {
    let mut hs = Vec::with_capacity(views.len());
    for v in views {
        let (b, i) = zhang::correspondences(v, board);
        let h = zhang::homography(&b, &i).ok_or_else(|| {
            CalibrateError::Degenerate(format!("no homography for view {}", v.name))
        })?;
        hs.push(h);
    }
    let (fx, fy, cx, cy) = zhang::intrinsics(&hs, width, height)?;
    let k = zhang::k_matrix(fx, fy, cx, cy);
    let poses = hs
        .iter()
        .zip(views)
        .map(|(h, v)| {
            zhang::pose_from_homography(&k, h)
                .ok_or_else(|| CalibrateError::Degenerate(format!("no pose for view {}", v.name)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (k1, k2) = zhang::radial_distortion_guess(&k, &poses, views, board);
    let camera = Camera {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
        distortion: Distortion {
            k1,
            k2,
            ..Distortion::default()
        },
    };
    Ok((camera, poses))
}

/// Calibrates the camera from the labelled corners of several views: Zhang's closed form,
/// then Levenberg–Marquardt over all parameters. Views with fewer than 6 corners are not
/// accepted (a homography has 8 degrees of freedom; 6 corners leave a margin of 4).
pub fn calibrate_camera(
    views: &[View],
    board: &Board,
) -> Result<CameraCalibration, CalibrateError> {
    let used: Vec<&View> = views.iter().filter(|v| v.corners.len() >= 6).collect();
    // 9 intrinsics + 6 per view against 2 equations per view from the closed form:
    // three views are the minimum for a free principal point (Zhang, §3.1).
    if used.len() < 3 {
        return Err(CalibrateError::TooFewViews {
            found: used.len(),
            needed: 3,
        });
    }
    super::sanity::distinct_views(&used)?;
    let (width, height) = (used[0].width, used[0].height);
    let (initial, poses) = initial_estimate(&used, board, width, height)?;

    let mut offsets = Vec::with_capacity(used.len());
    let mut m = 0;
    for v in &used {
        offsets.push(m);
        m += 2 * v.corners.len();
    }
    let problem = Problem {
        views: &used,
        board,
        width,
        height,
        offsets,
        m,
    };
    let n = problem.n();
    let mut p = Vec::with_capacity(n);
    p.extend_from_slice(&intrinsic_params(&initial));
    for pose in &poses {
        p.extend(zhang::rotation_vector(&pose.rotation).iter());
        p.extend(pose.translation.iter());
    }

    let (p, iterations) = levenberg_marquardt(&problem, p)?;
    let r = problem.residuals(&p);
    let (jtj, _) = problem.normal_equations(&p, &r);
    let camera = camera_from(&p, width, height);
    let poses: Vec<Pose> = (0..used.len())
        .map(|v| pose_from(&p[N_INTRINSICS + 6 * v..N_INTRINSICS + 6 * v + 6]))
        .collect();
    super::sanity::orientations_spread(&poses)?;

    let dof = m.saturating_sub(n).max(1);
    let sigma = (r.norm_squared() / dof as f64).sqrt();
    let mut std_dev = [f64::NAN; N_INTRINSICS];
    if let Some(chol) = jtj.clone().cholesky() {
        let cov = chol.inverse();
        for (k, s) in std_dev.iter_mut().enumerate() {
            *s = sigma * cov[(k, k)].max(0.0).sqrt();
        }
    }

    // What the views cannot determine is refused by name before the camera's validity
    // (an undetermined camera is often also an invalid one).
    super::sanity::parameters_determined(&camera, &INTRINSIC_NAMES, &std_dev)?;
    if camera.validate().is_err() {
        return Err(CalibrateError::Refinement(format!(
            "the refined camera is not valid: {camera:?}"
        )));
    }

    let mut residuals = Vec::with_capacity(used.len());
    let mut per_view_rms = Vec::with_capacity(used.len());
    let mut total = 0.0;
    for (v, view) in used.iter().enumerate() {
        let o = problem.offsets[v];
        let res: Vec<(Vec2, Vec2)> = view
            .corners
            .iter()
            .enumerate()
            .map(|(k, c)| (c.pixel, Vec2::new(r[o + 2 * k], r[o + 2 * k + 1])))
            .collect();
        let ss: f64 = res.iter().map(|(_, e)| e.norm_squared()).sum();
        total += ss;
        per_view_rms.push((ss / res.len() as f64).sqrt());
        residuals.push(res);
    }
    let n_corners: usize = used.iter().map(|v| v.corners.len()).sum();
    let rms = (total / n_corners as f64).sqrt();
    let mut sorted = per_view_rms.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let median = sorted[sorted.len() / 2];
    let outlier_views = per_view_rms
        .iter()
        .enumerate()
        .filter(|(_, &e)| e > OUTLIER_VIEW_FACTOR * median)
        .map(|(i, _)| i)
        .collect();

    let calibration = CameraCalibration {
        camera,
        initial,
        view_names: used.iter().map(|v| v.name.clone()).collect(),
        poses,
        residuals,
        per_view_rms,
        rms,
        std_dev,
        sigma,
        outlier_views,
        iterations,
    };
    Ok(calibration)
}

/// Levenberg–Marquardt with Marquardt's diagonal scaling (`docs/calibration.md`, "LM").
fn levenberg_marquardt(
    problem: &Problem<'_>,
    mut p: Vec<f64>,
) -> Result<(Vec<f64>, usize), CalibrateError> {
    let n = p.len();
    let mut r = problem.residuals(&p);
    let mut cost = r.norm_squared();
    if !cost.is_finite() {
        return Err(CalibrateError::Refinement(
            "initial estimate projects to non-finite pixels".into(),
        ));
    }
    let mut mu = 1e-3;
    let mut iterations = 0;
    let (mut jtj, mut jtr) = problem.normal_equations(&p, &r);
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        let mut accepted = false;
        // Try increasing damping until the cost decreases (at most ~15 tries, μ × 10^15).
        for _ in 0..16 {
            let mut a = jtj.clone();
            for k in 0..n {
                a[(k, k)] += mu * jtj[(k, k)].max(1e-12);
            }
            let Some(chol) = a.cholesky() else {
                mu *= 10.0;
                continue;
            };
            let delta = chol.solve(&(-&jtr));
            let cand: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
            let rc = problem.residuals(&cand);
            let cc = rc.norm_squared();
            if cc.is_finite() && cc < cost {
                let rel = (cost - cc) / cost;
                let small_step = delta
                    .iter()
                    .zip(&p)
                    .all(|(d, x)| d.abs() <= 1e-10 * (x.abs() + 1e-3));
                p = cand;
                r = rc;
                cost = cc;
                mu = (mu / 10.0).max(1e-12);
                accepted = true;
                if rel < 1e-12 || small_step {
                    return Ok((p, iterations));
                }
                break;
            }
            mu *= 10.0;
        }
        if !accepted {
            // No damping decreases the cost: we are at the minimum to rounding.
            return Ok((p, iterations));
        }
        (jtj, jtr) = problem.normal_equations(&p, &r);
    }
    Ok((p, iterations))
}
