//! Laser-plane calibration from captures of the laser on the calibration board
//! (`docs/calibration.md`, section 8; thesis §6.3).
//!
//! Per capture: the board's pose from its corners (the camera is already calibrated), the
//! stripe's pixels from the laser-on − laser-off difference, each stripe pixel's ray
//! intersected with the board plane (only points on the board itself are kept). Over all
//! captures the points lie on the laser plane, which is fitted by robust least squares
//! (iteratively reweighted orthogonal regression with Tukey's biweight). The repeatability
//! study (thesis §6.3.4) is a leave-one-pose-out jackknife of baseline, tilt and roll.

use image::GrayImage;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use tangent_core::camera::Camera;
use tangent_core::laser_plane::LaserPlane;
use tangent_core::peaks::{self, DEFAULT_ESTIMATOR};
use tangent_core::real::{Vec2, Vec3};

use super::{corners, zhang, Board, CalibrateError, Pose, View};
use crate::capture::Capture;
use crate::pgm::Pgm;

/// Fewest stripe points a plane fit accepts: three define a plane, but a calibration from
/// a handful of pixels would be dominated by their noise; 50 is a fraction of one stripe.
pub const MIN_STRIPE_POINTS: usize = 50;

/// Tukey biweight tuning constant (in units of the robust scale): 95 % efficiency at the
/// Gaussian, zero weight beyond 4.685 σ.
pub const TUKEY_C: f64 = 4.685;

/// Margin (in squares) around the inner-corner grid within which a stripe point counts as
/// on the board: the printed board extends one full square beyond its inner corners, so
/// half a square stays safely on the print even with a slightly trimmed border.
pub const BOARD_MARGIN_SQUARES: f64 = 0.5;

/// The board pose for a calibrated camera: homography of the undistorted (ideal normalised)
/// corners, pose from it with `K = I`, then Gauss–Newton on the pixel reprojection error
/// (`docs/calibration.md`, "Board pose with a known camera"). `None` if fewer than 4
/// corners undistort or the geometry is degenerate.
pub fn board_pose(camera: &Camera, view: &View, board: &Board) -> Option<Pose> {
    let mut bp = Vec::new();
    let mut ip = Vec::new();
    for c in &view.corners {
        if let Ok(n) = camera.pixel_to_normalised(c.pixel) {
            let p = board.point(c.i, c.j);
            bp.push(Vec2::new(p.x, p.y));
            ip.push(n);
        }
    }
    let h = zhang::homography(&bp, &ip)?;
    let pose = zhang::pose_from_homography(&Matrix3::identity(), &h)?;
    // Gauss–Newton on the 6 pose parameters with a numerical Jacobian; 10 iterations are
    // plenty from the homography start (quadratic convergence near the optimum).
    let residuals = |p: &[f64; 6]| -> Vec<f64> {
        let pose = Pose {
            rotation: nalgebra::Rotation3::from_scaled_axis(Vector3::new(p[0], p[1], p[2])),
            translation: Vector3::new(p[3], p[4], p[5]),
        };
        let mut r = Vec::with_capacity(2 * view.corners.len());
        for c in &view.corners {
            let x = pose.apply(&board.point(c.i, c.j));
            let px = camera.normalised_to_pixel(Vec2::new(x.x / x.z, x.y / x.z));
            r.push(px.x - c.pixel.x);
            r.push(px.y - c.pixel.y);
        }
        r
    };
    let rv = pose.rotation.scaled_axis();
    let mut p = [
        rv.x,
        rv.y,
        rv.z,
        pose.translation.x,
        pose.translation.y,
        pose.translation.z,
    ];
    let mut cost: f64 = residuals(&p).iter().map(|x| x * x).sum();
    for _ in 0..10 {
        let r = residuals(&p);
        let mut jtj = nalgebra::Matrix6::<f64>::zeros();
        let mut jtr = nalgebra::Vector6::<f64>::zeros();
        let mut cols = Vec::with_capacity(6);
        for k in 0..6 {
            let h = 1e-6 * (p[k].abs() + 1e-2);
            let (mut a, mut b) = (p, p);
            a[k] += h;
            b[k] -= h;
            let (ra, rb) = (residuals(&a), residuals(&b));
            cols.push(
                ra.iter()
                    .zip(&rb)
                    .map(|(x, y)| (x - y) / (2.0 * h))
                    .collect::<Vec<f64>>(),
            );
        }
        for a in 0..6 {
            for b in 0..6 {
                jtj[(a, b)] = cols[a].iter().zip(&cols[b]).map(|(x, y)| x * y).sum();
            }
            jtr[a] = cols[a].iter().zip(&r).map(|(x, y)| x * y).sum();
        }
        let Some(delta) = jtj.cholesky().map(|c| c.solve(&(-jtr))) else {
            break;
        };
        let mut cand = p;
        for k in 0..6 {
            cand[k] += delta[k];
        }
        let c: f64 = residuals(&cand).iter().map(|x| x * x).sum();
        if !(c.is_finite() && c <= cost) {
            break;
        }
        p = cand;
        let done = cost - c <= 1e-14 * cost.max(1e-300);
        cost = c;
        if done {
            break;
        }
    }
    Some(Pose {
        rotation: nalgebra::Rotation3::from_scaled_axis(Vector3::new(p[0], p[1], p[2])),
        translation: Vector3::new(p[3], p[4], p[5]),
    })
}

/// Stripe pixels of a laser-on − laser-off difference image (row-major, `width × height`):
/// in every column, the row of the largest difference if it exceeds the threshold, located
/// to subpixel accuracy by the core's default peak estimator (the one the instrument uses).
///
/// The threshold is `max(8σ, 0.1·max)`, `σ` the robust (MAD) noise of the difference image:
/// 8σ makes a false column at most ~1e-15 likely under Gaussian noise, and a tenth of the
/// brightest stripe sample rejects faint secondary reflections.
pub fn stripe_pixels(diff: &[f64], width: usize, height: usize) -> Vec<Vec2> {
    if width == 0 || height == 0 || diff.len() != width * height {
        return Vec::new();
    }
    let mut abs_dev: Vec<f64> = diff.iter().map(|v| v.abs()).collect();
    let mid = abs_dev.len() / 2;
    let (_, med, _) = abs_dev.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    let sigma = 1.4826 * *med;
    let max = diff.iter().copied().fold(f64::MIN, f64::max);
    let threshold = (8.0 * sigma).max(0.1 * max);
    let mut out = Vec::new();
    let mut column = vec![0.0; height];
    for x in 0..width {
        for (y, c) in column.iter_mut().enumerate() {
            *c = diff[y * width + x];
        }
        let (peak, &value) = match column.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) {
            Some(p) => p,
            None => continue,
        };
        if !(value > threshold && value > 0.0) {
            continue;
        }
        if let Ok(p) = peaks::locate(&column, peak, DEFAULT_ESTIMATOR) {
            if p.position.is_finite() && (p.position - peak as f64).abs() <= 2.0 {
                out.push(Vec2::new(x as f64, p.position));
            }
        }
    }
    out
}

/// [`stripe_pixels`] of a stripe of either direction: per column (a line across the image)
/// and per row (the walls' crossing line, which runs down the image: `docs/building.md`,
/// "The crossing line"), whichever finds more pixels — a stripe crosses many columns and few
/// rows, or the reverse. Pixels as `(u, v)` either way.
pub fn stripe_pixels_either_way(diff: &[f64], width: usize, height: usize) -> Vec<Vec2> {
    let across = stripe_pixels(diff, width, height);
    if width == 0 || height == 0 || diff.len() != width * height {
        return across;
    }
    let mut transposed = vec![0.0; diff.len()];
    if tangent_core::pipeline::crossing::transpose_frame(diff, width, height, &mut transposed)
        .is_err()
    {
        return across;
    }
    let down: Vec<Vec2> = stripe_pixels(&transposed, height, width)
        .into_iter()
        .map(|p| Vec2::new(p.y, p.x))
        .collect();
    if down.len() > across.len() {
        down
    } else {
        across
    }
}

/// Back-projects stripe pixels onto the board plane of `pose` and keeps the points that
/// lie on the board (inner-corner grid plus [`BOARD_MARGIN_SQUARES`]). Camera frame, metres.
pub fn stripe_points_on_board(
    camera: &Camera,
    pose: &Pose,
    board: &Board,
    pixels: &[Vec2],
) -> Vec<Vec3> {
    let (n, d) = pose.plane();
    let m = BOARD_MARGIN_SQUARES * board.square;
    let (xmax, ymax) = (
        (board.cols - 1) as f64 * board.square + m,
        (board.rows - 1) as f64 * board.square + m,
    );
    let inv = pose.rotation.inverse();
    pixels
        .iter()
        .filter_map(|&px| {
            let ray = camera.pixel_to_ray(px).ok()?;
            let denom = n.dot(&ray);
            if denom.abs() < 1e-9 {
                return None;
            }
            let t = d / denom;
            if !(t.is_finite() && t > 0.0) {
                return None;
            }
            let x = ray * t;
            let b = inv * (x - pose.translation);
            // Both board orientations of a partial labelling are covered by testing
            // against the grid's bounding box.
            (b.x >= -m && b.x <= xmax && b.y >= -m && b.y <= ymax).then_some(x)
        })
        .collect()
}

/// A fitted plane `n·X = d` with its fit statistics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFit {
    /// Unit normal (sign chosen so that `d > 0`).
    pub normal: Vec3,
    /// Offset (metres).
    pub offset: f64,
    /// RMS orthogonal distance of the inliers (metres).
    pub rms: f64,
    /// Points with non-zero final weight.
    pub inliers: usize,
    /// Points given.
    pub points: usize,
}

/// Robust plane fit: orthogonal regression (smallest eigenvector of the weighted scatter
/// matrix) re-weighted with Tukey's biweight of the orthogonal distances, scale from their
/// MAD, until the normal stops moving (`docs/calibration.md`, "Plane fit").
///
/// Each re-weighting step solves the weighted least-squares problem exactly; the thesis's
/// gradient descent on the same objective converges to the same point, only more slowly.
pub fn fit_plane(points: &[Vec3]) -> Result<PlaneFit, CalibrateError> {
    if points.len() < MIN_STRIPE_POINTS {
        return Err(CalibrateError::TooFewStripePoints {
            found: points.len(),
            needed: MIN_STRIPE_POINTS,
        });
    }
    let mut weights = vec![1.0; points.len()];
    let mut normal = Vec3::zeros();
    let mut offset = 0.0;
    for _ in 0..50 {
        let (n, d) = weighted_plane(points, &weights)
            .ok_or_else(|| CalibrateError::Degenerate("stripe points are collinear".into()))?;
        let moved = (n - normal).norm().min((n + normal).norm());
        normal = n;
        offset = d;
        let dist: Vec<f64> = points.iter().map(|p| normal.dot(p) - offset).collect();
        let mut abs: Vec<f64> = dist.iter().map(|x| x.abs()).collect();
        let mid = abs.len() / 2;
        let (_, med, _) = abs.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        // Floor the scale at 1 nm so exact (synthetic) data keep all points.
        let scale = (1.4826 * *med).max(1e-9);
        let c = TUKEY_C * scale;
        for (w, r) in weights.iter_mut().zip(&dist) {
            let u = r / c;
            *w = if u.abs() < 1.0 {
                (1.0 - u * u).powi(2)
            } else {
                0.0
            };
        }
        if moved < 1e-12 {
            break;
        }
    }
    if offset < 0.0 {
        normal = -normal;
        offset = -offset;
    }
    let (mut ss, mut inliers) = (0.0, 0);
    for (p, w) in points.iter().zip(&weights) {
        if *w > 0.0 {
            let r = normal.dot(p) - offset;
            ss += r * r;
            inliers += 1;
        }
    }
    Ok(PlaneFit {
        normal,
        offset,
        rms: (ss / inliers.max(1) as f64).sqrt(),
        inliers,
        points: points.len(),
    })
}

/// Weighted orthogonal regression: the plane through the weighted centroid whose normal is
/// the eigenvector of the smallest eigenvalue of the weighted scatter matrix.
fn weighted_plane(points: &[Vec3], weights: &[f64]) -> Option<(Vec3, f64)> {
    let wsum: f64 = weights.iter().sum();
    // NaN weights compare false and are rejected too.
    if wsum.is_nan() || wsum <= 0.0 {
        return None;
    }
    let c = points
        .iter()
        .zip(weights)
        .fold(Vec3::zeros(), |a, (p, w)| a + p * *w)
        / wsum;
    let mut s = Matrix3::<f64>::zeros();
    for (p, w) in points.iter().zip(weights) {
        let q = p - c;
        s += q * q.transpose() * *w;
    }
    let eig = SymmetricEigen::new(s);
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let (imid, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != imin)
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    // Collinear points: the two smallest eigenvalues are both ~0 and the normal is undefined.
    if eig.eigenvalues[imid] <= 1e-12 * eig.eigenvalues.iter().fold(0.0, |a: f64, b| a.max(*b)) {
        return None;
    }
    let n: Vector3<f64> = eig.eigenvectors.column(imin).into_owned();
    let n = n.normalize();
    Some((n, n.dot(&c)))
}

/// The laser plane of a fit, with the emission point either given (projected onto the
/// plane) or, by default, the thesis's source `S = R_z(ρ)·(0, e, 0)`: the point where the
/// plane meets the camera's (rolled) `y` axis (`docs/calibration.md`, "Source point").
pub fn laser_plane(fit: &PlaneFit, source: Option<Vec3>) -> Result<LaserPlane, CalibrateError> {
    let bad =
        |e| CalibrateError::Degenerate(format!("fitted plane is not a valid laser plane: {e}"));
    let foot = fit.normal * fit.offset;
    let tmp = LaserPlane::new(fit.normal, fit.offset, foot).map_err(bad)?;
    match source {
        Some(s) => {
            let s = s - fit.normal * (fit.normal.dot(&s) - fit.offset);
            LaserPlane::new(fit.normal, fit.offset, s).map_err(bad)
        }
        None => {
            let (e, delta) = tmp.baseline_tilt();
            LaserPlane::from_baseline_tilt_roll(e, delta, tmp.roll()).map_err(bad)
        }
    }
}

/// Baseline `e` (metres), tilt `δ` and roll `ρ` (radians) of a plane `(n, d)`.
pub fn baseline_tilt_roll(normal: Vec3, offset: f64) -> Option<(f64, f64, f64)> {
    let p = LaserPlane::new(normal, offset, normal * offset).ok()?;
    let (e, t) = p.baseline_tilt();
    Some((e, t, p.roll()))
}

/// The repeatability study of thesis §6.3.4 on one data set: the plane refitted with each
/// pose left out in turn.
#[derive(Debug, Clone, PartialEq)]
pub struct Repeatability {
    /// `(e, δ, ρ)` of each leave-one-out fit (metres, radians, radians).
    pub fits: Vec<(f64, f64, f64)>,
    /// Jackknife standard error of `(e, δ, ρ)`: `sqrt((n−1)/n · Σ(θ_k − θ̄)²)`.
    pub std_error: (f64, f64, f64),
    /// Spread (max − min) of `(e, δ, ρ)` over the leave-one-out fits.
    pub spread: (f64, f64, f64),
}

/// Leave-one-pose-out repeatability; `None` with fewer than 3 poses or if a sub-fit fails.
pub fn repeatability(per_pose: &[Vec<Vec3>]) -> Option<Repeatability> {
    let n = per_pose.len();
    if n < 3 {
        return None;
    }
    let mut fits = Vec::with_capacity(n);
    for k in 0..n {
        let pts: Vec<Vec3> = per_pose
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != k)
            .flat_map(|(_, v)| v.iter().copied())
            .collect();
        let f = fit_plane(&pts).ok()?;
        fits.push(baseline_tilt_roll(f.normal, f.offset)?);
    }
    let nf = n as f64;
    let stat = |g: &dyn Fn(&(f64, f64, f64)) -> f64| {
        let mean = fits.iter().map(g).sum::<f64>() / nf;
        let ss: f64 = fits.iter().map(|f| (g(f) - mean).powi(2)).sum();
        let lo = fits.iter().map(g).fold(f64::MAX, f64::min);
        let hi = fits.iter().map(g).fold(f64::MIN, f64::max);
        (((nf - 1.0) / nf * ss).sqrt(), hi - lo)
    };
    let (se, sp) = stat(&|f| f.0);
    let (st, tp) = stat(&|f| f.1);
    let (sr, rp) = stat(&|f| f.2);
    Some(Repeatability {
        fits,
        std_error: (se, st, sr),
        spread: (sp, tp, rp),
    })
}

/// Result of a laser-plane calibration.
#[derive(Debug, Clone)]
pub struct LaserCalibration {
    /// The fitted plane.
    pub fit: PlaneFit,
    /// The laser plane (with its source point).
    pub plane: LaserPlane,
    /// Stripe points on the board per pose (camera frame, metres).
    pub per_pose: Vec<Vec<Vec3>>,
    /// Leave-one-pose-out repeatability, when there are at least 3 poses.
    pub repeatability: Option<Repeatability>,
}

/// Calibrates one laser plane from `(board view, stripe pixels)` per pose.
pub fn calibrate_plane(
    camera: &Camera,
    board: &Board,
    poses: &[(View, Vec<Vec2>)],
    source: Option<Vec3>,
) -> Result<LaserCalibration, CalibrateError> {
    let mut per_pose = Vec::with_capacity(poses.len());
    for (view, pixels) in poses {
        let pose = board_pose(camera, view, board).ok_or_else(|| {
            CalibrateError::Degenerate(format!("no board pose for {}", view.name))
        })?;
        per_pose.push(stripe_points_on_board(camera, &pose, board, pixels));
    }
    if per_pose.iter().filter(|p| !p.is_empty()).count() < 2 {
        // One pose gives one line of the plane: its rotation about that line is free.
        return Err(CalibrateError::TooFewViews {
            found: per_pose.iter().filter(|p| !p.is_empty()).count(),
            needed: 2,
        });
    }
    let all: Vec<Vec3> = per_pose.iter().flatten().copied().collect();
    let fit = fit_plane(&all)?;
    super::sanity::plane_determined(&per_pose, fit.normal)?;
    let plane = laser_plane(&fit, source)?;
    let repeatability = repeatability(&per_pose);
    if let Some(rep) = &repeatability {
        super::sanity::plane_repeatable(rep.std_error)?;
    }
    Ok(LaserCalibration {
        fit,
        plane,
        per_pose,
        repeatability,
    })
}

/// A PGM frame as an 8-bit grey image for the corner detector (scaled by `255 / maxval`)
/// and as raw `f64` samples for the stripe (no rescaling: the stripe threshold is relative).
pub fn pgm_gray(p: &Pgm) -> (GrayImage, Vec<f64>) {
    let raw = p.to_u16();
    let scale = 255.0 / p.maxval.max(1) as f64;
    let bytes = raw
        .iter()
        .map(|&v| (v as f64 * scale).round().min(255.0) as u8)
        .collect();
    let img = GrayImage::from_raw(p.width as u32, p.height as u32, bytes).unwrap_or_default();
    (img, raw.iter().map(|&v| v as f64).collect())
}

/// One board capture prepared for the laser calibration: the board's corners (laser-off
/// frame) and, per laser-on frame lighting a single laser, that laser's stripe pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardCapture {
    /// The laser-off frame (8-bit), for the report.
    pub image: GrayImage,
    /// Corners of the board in the laser-off frame.
    pub view: View,
    /// `(laser index, stripe pixels)` per single-laser laser-on frame.
    pub stripes: Vec<(usize, Vec<Vec2>)>,
}

/// Extracts the board corners and the stripes of a capture (`docs/calibration.md`, §8).
/// Frames lighting several lasers at once are ignored (their stripes cannot be told
/// apart by the calibration); an error names what is missing.
pub fn board_capture(
    camera: &Camera,
    board: &Board,
    capture: &Capture,
    name: &str,
) -> Result<BoardCapture, String> {
    let (off_img, off) = pgm_gray(capture.off_frame());
    if (off_img.width(), off_img.height()) != (camera.width, camera.height) {
        return Err(format!(
            "frame {}x{} differs from the camera's {}x{}",
            off_img.width(),
            off_img.height(),
            camera.width,
            camera.height
        ));
    }
    let view = corners::detect(&off_img, board, name).map_err(|e| format!("board: {e}"))?;
    let mut stripes = Vec::new();
    for (lasers, frame) in capture.on_frames() {
        let [k] = lasers[..] else { continue };
        let (_, on) = pgm_gray(frame);
        if on.len() != off.len() {
            return Err("laser-on and laser-off frames differ in size".into());
        }
        let diff: Vec<f64> = on.iter().zip(&off).map(|(a, b)| a - b).collect();
        stripes.push((
            k,
            stripe_pixels_either_way(&diff, frame.width, frame.height),
        ));
    }
    if stripes.is_empty() {
        return Err("no laser-on frame lights a single laser".into());
    }
    Ok(BoardCapture {
        image: off_img,
        view,
        stripes,
    })
}

/// Calibrates every laser seen in `captures`: plane `k` from the frames lighting laser `k`
/// alone, with the default source point (see [`laser_plane`]). Lasers must be numbered
/// `0..n` without gaps (plane `i` of the calibration is laser output `i`).
pub fn calibrate_lasers(
    camera: &Camera,
    board: &Board,
    captures: &[BoardCapture],
) -> Result<Vec<LaserCalibration>, CalibrateError> {
    let n = captures
        .iter()
        .flat_map(|c| c.stripes.iter().map(|s| s.0 + 1))
        .max()
        .unwrap_or(0);
    if n == 0 {
        return Err(CalibrateError::TooFewViews {
            found: 0,
            needed: 2,
        });
    }
    (0..n)
        .map(|k| {
            let poses: Vec<(View, Vec<Vec2>)> = captures
                .iter()
                .flat_map(|c| {
                    c.stripes
                        .iter()
                        .filter(|s| s.0 == k)
                        .map(|s| (c.view.clone(), s.1.clone()))
                })
                .collect();
            calibrate_plane(camera, board, &poses, None)
        })
        .collect()
}
