//! What a calibration refuses (`docs/calibration.md`, "When calibration refuses"): views
//! that cannot determine it (repeated views, too little tilt between them, a laser plane
//! seen at a single depth) and parameters whose standard deviation exceeds a sane bound.
//! Loaded values outside physical ranges are refused by [`crate::calibration_bounds`].

use nalgebra::Vector3;
use tangent_core::camera::Camera;
use tangent_core::real::Vec3;

use super::{CalibrateError, Pose, View};
use crate::calibration_bounds::corner_radius;

/// Two views whose common corners differ by less than this RMS (pixels) are the same view:
/// corner noise is ~0.1–0.3 px, so a board that has not moved agrees to well under 1 px,
/// and a board that has moved enough to add information differs by many pixels.
pub const SAME_VIEW_PX: f64 = 1.0;

/// Distinct views needed (Zhang's closed form: three for a free principal point).
pub const MIN_DISTINCT_VIEWS: usize = 3;

/// Least angle (degrees) between the board orientations of two views. Each view gives
/// Zhang's two constraints through its rotation only; views at the same orientation give
/// the same constraints, and the focal length follows from the difference between them.
/// Zhang (2000, §5.1) shows the error growing steeply below ~10° between planes; 5° is half
/// of that, a margin below which no calibration should be trusted.
pub const MIN_ORIENTATION_SPREAD_DEG: f64 = 5.0;

/// Largest relative standard deviation of fx and fy: a diameter scales with `1/f`, so 1 %
/// of `f` is 1 % of every reading — ten times the reference device's calibration budget
/// (`NoiseModel::reference`: σ_f = 1 px), beyond which the focal length is not determined.
pub const MAX_FOCAL_SIGMA_RELATIVE: f64 = 0.01;

/// Largest standard deviation of cx and cy as a fraction of the image's larger side: 2 %
/// (≈ 15 px on 752 px) tilts every ray by ~1° — not a calibration.
pub const MAX_PRINCIPAL_SIGMA_FRACTION: f64 = 0.02;

/// Largest displacement, as a fraction of the radius at the farthest image corner, that
/// one distortion coefficient's standard deviation may cause there (`σ(k_i)·r^(2i)` for the
/// radial, `3·σ(p)·r²` for the tangential terms): 5 % (≈ 20 px at a 400 px radius). The
/// marginal σ of k2, k3 are large because they are correlated with each other (the
/// OpenCV sample: ≈ 1.5 %); an unconstrained one is orders of magnitude beyond.
pub const MAX_DISTORTION_SIGMA_EFFECT: f64 = 0.05;

/// Least spread (metres) of the stripe lines of different poses across the laser plane.
/// One pose shows one line of the plane; its rotation about that line is fixed only by a
/// second line away from it. The board pose from ~50 corners at 0.2 px puts the board —
/// and so the stripe line on it — to `0.2 px·Z/(f·√50)` ≈ 15–30 µm at 0.5 m; over a lever
/// `L` that is a tilt error of `σ·√2/L`, under 2 mrad (ten times the budget σ_δ = 0.2 mrad)
/// for `L ≥ 20 mm`.
pub const MIN_PLANE_SPREAD_M: f64 = 0.02;

/// Largest jackknife standard errors of a laser plane's baseline (metres) and its tilt and
/// roll (radians): ten times the reference calibration budget (σ_e = 0.2 mm, σ_δ = 0.2
/// mrad, `NoiseModel::reference`).
pub const MAX_PLANE_STD_ERROR: (f64, f64, f64) = (2e-3, 2e-3, 2e-3);

/// Refuses repeated views: a view whose corners agree with an earlier one's to within
/// [`SAME_VIEW_PX`] adds nothing, and fewer than [`MIN_DISTINCT_VIEWS`] distinct views
/// cannot determine the camera.
pub fn distinct_views(views: &[&View]) -> Result<(), CalibrateError> {
    let mut distinct: Vec<&View> = Vec::new();
    let mut repeats = Vec::new();
    for v in views {
        match distinct.iter().find_map(|d| {
            let rms = common_corner_rms(d, v)?;
            (rms < SAME_VIEW_PX).then_some((d, rms))
        }) {
            Some((d, rms)) => repeats.push(format!(
                "{} repeats {} (corners within {rms:.2} px)",
                v.name, d.name
            )),
            None => distinct.push(v),
        }
    }
    if distinct.len() < MIN_DISTINCT_VIEWS {
        return Err(CalibrateError::Undetermined(format!(
            "{} distinct view(s), at least {MIN_DISTINCT_VIEWS} needed: {}; photograph the \
             board at different tilts",
            distinct.len(),
            repeats.join("; ")
        )));
    }
    Ok(())
}

/// RMS distance (pixels) between the corners two views share, `None` with fewer than 6.
fn common_corner_rms(a: &View, b: &View) -> Option<f64> {
    let (mut ss, mut n) = (0.0, 0usize);
    for ca in &a.corners {
        if let Some(cb) = b.corners.iter().find(|c| (c.i, c.j) == (ca.i, ca.j)) {
            ss += (ca.pixel - cb.pixel).norm_squared();
            n += 1;
        }
    }
    (n >= 6).then(|| (ss / n as f64).sqrt())
}

/// Refuses board poses whose orientations all lie within [`MIN_ORIENTATION_SPREAD_DEG`] of
/// each other: Zhang's constraints come from the rotations alone, so such views do not
/// determine the focal length, whatever their distances.
pub fn orientations_spread(poses: &[Pose]) -> Result<(), CalibrateError> {
    let normals: Vec<Vector3<f64>> = poses.iter().map(|p| p.rotation * Vec3::z()).collect();
    let mut spread: f64 = 0.0;
    for (i, a) in normals.iter().enumerate() {
        for b in &normals[i + 1..] {
            // A relabelled board (rotated by 180°) flips its normal: compare as lines.
            let angle = a.angle(b).to_degrees();
            spread = spread.max(angle.min(180.0 - angle));
        }
    }
    if spread.is_nan() || spread < MIN_ORIENTATION_SPREAD_DEG {
        return Err(CalibrateError::Undetermined(format!(
            "the board orientations differ by at most {spread:.1}°, at least \
             {MIN_ORIENTATION_SPREAD_DEG}° needed; tilt the board differently between views"
        )));
    }
    Ok(())
}

/// Refuses a camera calibration with a parameter whose σ is beyond its bound (the
/// `MAX_*_SIGMA_*` constants), naming the parameter and its σ.
/// `names` and `std_dev` are the refined intrinsics' names and standard deviations, in the
/// refinement's order.
pub fn parameters_determined(
    c: &Camera,
    names: &[&'static str],
    std_dev: &[f64],
) -> Result<(), CalibrateError> {
    let r = corner_radius(c);
    for (&name, &sigma) in names.iter().zip(std_dev) {
        let (bound, unit) = match name {
            "fx" => (MAX_FOCAL_SIGMA_RELATIVE * c.fx, "px"),
            "fy" => (MAX_FOCAL_SIGMA_RELATIVE * c.fy, "px"),
            "cx" | "cy" => (
                MAX_PRINCIPAL_SIGMA_FRACTION * c.width.max(c.height) as f64,
                "px",
            ),
            "k1" => (MAX_DISTORTION_SIGMA_EFFECT / r.powi(2), ""),
            "k2" => (MAX_DISTORTION_SIGMA_EFFECT / r.powi(4), ""),
            "k3" => (MAX_DISTORTION_SIGMA_EFFECT / r.powi(6), ""),
            _ => (MAX_DISTORTION_SIGMA_EFFECT / (3.0 * r * r), ""),
        };
        // A NaN σ (singular normal matrix) is undetermined too.
        if sigma.is_nan() || sigma > bound {
            return Err(CalibrateError::TooUncertain {
                name,
                sigma,
                bound,
                unit,
            });
        }
    }
    Ok(())
}

/// Refuses a laser plane whose leave-one-pose-out standard errors exceed
/// [`MAX_PLANE_STD_ERROR`] (`std_error`: baseline, tilt, roll, as in
/// [`super::laser::Repeatability::std_error`]).
pub fn plane_repeatable(std_error: (f64, f64, f64)) -> Result<(), CalibrateError> {
    let (se, st, sr) = std_error;
    let (be, bt, br) = MAX_PLANE_STD_ERROR;
    for (name, sigma, bound, scale, unit) in [
        ("the laser baseline", se, be, 1e3, "mm"),
        ("the laser tilt", st, bt, 1e3, "mrad"),
        ("the laser roll", sr, br, 1e3, "mrad"),
    ] {
        if sigma.is_nan() || sigma > bound {
            return Err(CalibrateError::TooUncertain {
                name,
                sigma: sigma * scale,
                bound: bound * scale,
                unit,
            });
        }
    }
    Ok(())
}

/// Refuses a laser plane the poses do not determine: its stripe lines must be spread across
/// the plane by at least [`MIN_PLANE_SPREAD_M`] (two or more distinct depths). `normal` is
/// the fitted plane's unit normal.
pub fn plane_determined(per_pose: &[Vec<Vec3>], normal: Vec3) -> Result<(), CalibrateError> {
    let all: Vec<&Vec3> = per_pose.iter().flatten().collect();
    let n = all.len().max(1) as f64;
    let mean = all.iter().fold(Vec3::zeros(), |a, p| a + *p) / n;
    // The stripe direction is the main axis of the points within the plane; the spread is
    // measured along the in-plane direction across it.
    let mut scatter = nalgebra::Matrix3::zeros();
    for p in &all {
        let d = *p - mean;
        let d = d - normal * normal.dot(&d);
        scatter += d * d.transpose();
    }
    let eig = scatter.symmetric_eigen();
    let (imax, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .unwrap_or((0, &0.0));
    let along: Vec3 = eig.eigenvectors.column(imax).into_owned();
    let across = normal.cross(&along);
    let centres: Vec<f64> = per_pose
        .iter()
        .filter(|p| !p.is_empty())
        .map(|p| p.iter().map(|x| across.dot(&(x - mean))).sum::<f64>() / p.len() as f64)
        .collect();
    let lo = centres.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = centres.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let spread = hi - lo;
    if spread.is_nan() || spread < MIN_PLANE_SPREAD_M {
        return Err(CalibrateError::Undetermined(format!(
            "the laser stripes of the {} pose(s) lie within {:.1} mm of each other across the \
             plane, at least {:.0} mm needed: place the board at two or more distinct depths",
            centres.len(),
            spread.max(0.0) * 1e3,
            MIN_PLANE_SPREAD_M * 1e3
        )));
    }
    Ok(())
}
