//! The accelerometer's calibration: its bias, a common scale and the rotation of its axes
//! into the camera frame, from static poses in which the camera's gravity is known (from
//! the chessboard lying on a level surface), by the weighted orthogonal Procrustes solution
//! with scale (Umeyama) refined by generalised least squares on the shared LM, and the σ of
//! each (`docs/hardware.md`,
//! "Accelerometer calibration", eqs. (A1)–(A5)).
//!
//! The model of a pose `i` at rest (sensor axes):
//!
//! ```text
//! aᵢ = k · Rᵀ · uᵢ + b + noise,      uᵢ = −g · ĝᵢ                                   (A1)
//! ```
//!
//! `aᵢ` the mean specific force the sensor reads, `ĝᵢ` gravity in the camera frame (unit,
//! down), `R` the rotation from the sensor's axes into the camera frame (the capture's
//! `camera_from_sensor`), `b` the bias, `k` the scale (the sensor's sensitivity error and
//! the local gravity's departure from standard gravity together).

// `!(x > 0.0)` is deliberate: it also rejects NaN (as in `solvers`).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Mat3, Real, Vec3};
use crate::solvers::lm::{minimise, Evaluated, LeastSquares, LmParams, NormalEquations};
use crate::solvers::SolveError;
use nalgebra::{Matrix3, Rotation3, SMatrix, SVector};

/// Standard gravity (m/s²).
pub const STANDARD_GRAVITY: Real = 9.806_65;

/// One static pose: what the accelerometer read and where gravity was in the camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Mean specific force over the pose (sensor axes, m/s²).
    pub mean_m_s2: Vec3,
    /// Gravity in the camera frame (pointing down, any length; from the chessboard's pose).
    pub gravity_camera: Vec3,
    /// 1σ of the mean reading per axis (m/s²): the sensor's noise over the samples averaged.
    pub sigma_m_s2: Real,
    /// 1σ of `gravity_camera`'s direction about each axis across it (radians): the
    /// chessboard pose's and the level surface's error.
    pub direction_sigma_rad: Real,
}

impl Pose {
    /// Covariance of the pose's residual (A1) (m²/s⁴): the reading's noise on every axis,
    /// and the gravity direction's error across gravity only (along it, it is second order).
    fn covariance(&self, force: &Vec3) -> Mat3 {
        let across = STANDARD_GRAVITY * self.direction_sigma_rad;
        let f = force / STANDARD_GRAVITY;
        Mat3::identity() * (self.sigma_m_s2 * self.sigma_m_s2)
            + (Mat3::identity() - f * f.transpose()) * (across * across)
    }

    /// The fit's weight of the pose: the inverse of its mean variance per axis (the
    /// direction error spread over two of three axes).
    fn weight(&self) -> Real {
        let across = STANDARD_GRAVITY * self.direction_sigma_rad;
        1.0 / (self.sigma_m_s2 * self.sigma_m_s2 + across * across * 2.0 / 3.0)
    }
}

/// The calibration found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelCalibration {
    /// Bias (sensor axes, m/s²).
    pub bias_m_s2: Vec3,
    /// 1σ of the bias per axis (m/s²).
    pub bias_sigma_m_s2: Vec3,
    /// Rotation from the sensor's axes into the camera frame (rotation vector, radians).
    pub camera_from_sensor_rad: Vec3,
    /// 1σ of that rotation about each camera axis (radians).
    pub alignment_sigma_rad: Vec3,
    /// The common scale `k` (1 for a perfect sensor under standard gravity).
    pub scale: Real,
    /// 1σ of the scale.
    pub scale_sigma: Real,
    /// Root-mean-square residual over the poses' axes (m/s²).
    pub rms_m_s2: Real,
    /// χ² per degree of freedom against the poses' σ (≈ 1 when they explain the scatter;
    /// the σ above are inflated by it when it exceeds its 99 % point, the poses' σ then
    /// being too small).
    pub chi2: Real,
    /// Poses used.
    pub poses: usize,
}

/// Parameters of the fit: bias (3), rotation (3), scale (1).
const PARAMS: usize = 7;

/// Solves (A1) for `b`, `R` and `k` from `poses` (at least 3, whose gravity directions are
/// not all on one line: (A3) needs two independent directions; the six faces of a cube or
/// any spread of tilts work).
///
/// `TooFewPoints` below 3 poses; `NonFinite` for a non-finite reading or gravity, a reading
/// σ that is not positive or a direction σ that is negative; `Degenerate` for gravity directions on one line (the rotation about it
/// is unobservable) or a singular normal matrix.
pub fn calibrate(poses: &[Pose]) -> Result<AccelCalibration, SolveError> {
    if poses.len() < 3 {
        return Err(SolveError::TooFewPoints);
    }
    // Specific force in the camera frame (up, standard gravity) and the weights.
    let force = |p: &Pose| -> Result<Vec3, SolveError> {
        let len = p.gravity_camera.norm();
        if !(len > 0.0 && len.is_finite()) {
            return Err(SolveError::NonFinite);
        }
        Ok(-p.gravity_camera / len * STANDARD_GRAVITY)
    };
    let (mut w_sum, mut u_mean, mut a_mean) = (0.0 as Real, Vec3::zeros(), Vec3::zeros());
    for p in poses {
        let sigmas_valid = p.sigma_m_s2 > 0.0
            && p.sigma_m_s2.is_finite()
            && p.direction_sigma_rad >= 0.0
            && p.direction_sigma_rad.is_finite();
        if !sigmas_valid || !p.mean_m_s2.iter().all(|v| v.is_finite()) {
            return Err(SolveError::NonFinite);
        }
        let w = p.weight();
        w_sum += w;
        u_mean += force(p)? * w;
        a_mean += p.mean_m_s2 * w;
    }
    u_mean /= w_sum;
    a_mean /= w_sum;
    // (A2): the weighted cross-covariance of the centred readings and forces, and the
    // forces' spread.
    let mut cross = Mat3::zeros();
    let mut spread = 0.0 as Real;
    for p in poses {
        let w = p.weight();
        let x = force(p)? - u_mean;
        let y = p.mean_m_s2 - a_mean;
        cross += y * x.transpose() * w;
        spread += w * x.norm_squared();
    }
    let svd = cross.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(SolveError::Degenerate);
    };
    let mut order = [0usize, 1, 2];
    order.sort_unstable_by(|&i, &j| {
        svd.singular_values[j]
            .partial_cmp(&svd.singular_values[i])
            .unwrap_or(core::cmp::Ordering::Equal)
    });
    let (s0, s1) = (svd.singular_values[order[0]], svd.singular_values[order[1]]);
    // Two independent directions of gravity at least; else a rotation about the one
    // direction fits as well as any other.
    if !(s0 > 0.0) || !(s1 > 1e-6 * s0) || !(spread > 0.0) {
        return Err(SolveError::Degenerate);
    }
    // (A3): the rotation M = Rᵀ (camera → sensor) nearest to the cross-covariance, a
    // reflection excluded.
    let d = (u * v_t).determinant().signum();
    let mut flip = Mat3::identity();
    // The smallest singular value's direction takes the sign.
    flip[(order[2], order[2])] = d;
    let m = u * flip * v_t;
    // (A4): scale and bias: the start of (A5).
    let trace: Real = (0..3).map(|i| svd.singular_values[i] * flip[(i, i)]).sum();
    let k = trace / spread;
    let bias = a_mean - m * u_mean * k;
    if !(k > 0.0) || !bias.iter().all(|v| v.is_finite()) {
        return Err(SolveError::Degenerate);
    }

    // (A5): the generalised least squares from there, each pose weighted by the inverse of
    // its residual's covariance (the shared LM), and the covariance (JᵀΣ⁻¹J)⁻¹ at the
    // minimum.
    let problem = Problem { poses };
    let start = Evaluated::at(&problem, Params { bias, m, k })?;
    let (min, _) = minimise(&problem, start, &LmParams::default())?;
    let Params { bias, m, k } = min.params;
    let mut rss = 0.0 as Real;
    for p in poses {
        let r = p.mean_m_s2 - m * force(p)? * k - bias;
        rss += r.norm_squared();
    }
    let dof = 3 * poses.len() - PARAMS;
    let chi2_dof = if dof > 0 {
        min.normal.cost / dof as Real
    } else {
        1.0
    };
    // The poses' σ stand unless the residuals reject them (χ²/dof above its 99 % point,
    // ≈ 1 + 2.33 √(2/dof)): then the scatter, not the declared noise, sets the σ.
    let rejects = dof > 0 && chi2_dof > 1.0 + 2.33 * sqrt(2.0 / dof as Real);
    let inflation = if rejects { chi2_dof } else { 1.0 };
    let cov = min.normal.jtj.try_inverse().ok_or(SolveError::Degenerate)? * inflation;
    let sd = |i: usize| sqrt(cov[(i, i)].max(0.0));
    // δ is a rotation of the camera frame before M: about the camera's axes, as the
    // alignment's σ is stated.
    let r_cs = Rotation3::from_matrix_unchecked(m.transpose());
    Ok(AccelCalibration {
        bias_m_s2: bias,
        bias_sigma_m_s2: Vec3::new(sd(0), sd(1), sd(2)),
        camera_from_sensor_rad: r_cs.scaled_axis(),
        alignment_sigma_rad: Vec3::new(sd(3), sd(4), sd(5)),
        scale: k,
        scale_sigma: sd(6),
        rms_m_s2: sqrt(rss / (3 * poses.len()) as Real),
        chi2: chi2_dof,
        poses: poses.len(),
    })
}

/// Gravity in the camera frame (unit, down) from a reading and a calibration, (B9) of
/// `docs/building.md` with the scale: `ĝ = −R (a − b) / |a − b|` (the scale cancels in the
/// direction). `None` for a reading equal to the bias.
pub fn gravity_camera(reading_m_s2: Vec3, calibration: &AccelCalibration) -> Option<Vec3> {
    let up = reading_m_s2 - calibration.bias_m_s2;
    let len = up.norm();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let r: Matrix3<Real> = *Rotation3::new(calibration.camera_from_sensor_rad).matrix();
    Some(-(r * up) / len)
}

/// What the device knows of its accelerometer to turn a mean reading into gravity in the
/// camera frame: the calibration's bias and rotation, each with one 1σ for every axis (the
/// record a capture and the device's calibration carry; `docs/building.md` §6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alignment {
    /// The calibrated bias subtracted from the mean (sensor axes, m/s²).
    pub bias_m_s2: Vec3,
    /// 1σ of that bias on each axis (m/s²).
    pub bias_sigma_m_s2: Real,
    /// The calibrated rotation from the sensor's axes into the camera frame (rotation
    /// vector, radians).
    pub camera_from_sensor_rad: Vec3,
    /// 1σ of that rotation about each axis (radians).
    pub alignment_sigma_rad: Real,
}

/// The accelerometer's mean over one capture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanReading {
    /// Mean specific force (sensor axes, m/s²; at rest it points up).
    pub mean_m_s2: Vec3,
    /// Samples averaged.
    pub samples: u32,
    /// 1σ of one sample on each axis (m/s²; the sensor's noise at its filter setting).
    pub sample_sigma_m_s2: Real,
}

/// Gravity in the camera frame from one capture's mean reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vertical {
    /// Gravity's direction (unit, pointing down, camera frame).
    pub down: Vec3,
    /// 1σ of that direction about any axis across it (radians).
    pub sigma_rad: Real,
}

/// Why a reading gives no vertical reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VerticalError {
    /// A value is not finite (its field's name).
    NonFinite(&'static str),
    /// A σ is negative or not finite (its field's name and value).
    BadSigma(&'static str, Real),
    /// No samples were averaged.
    NoSamples,
    /// The mean less the bias is not ≈ 1 g (its magnitude, m/s²): the device was moving
    /// (or the part is broken).
    NotAtRest(Real),
}

impl core::fmt::Display for VerticalError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            VerticalError::NonFinite(name) => write!(f, "accelerometer.{name} is not finite"),
            VerticalError::BadSigma(name, x) => {
                write!(f, "accelerometer.{name} = {x}: must be ≥ 0")
            }
            VerticalError::NoSamples => write!(f, "accelerometer.samples = 0: at least one"),
            VerticalError::NotAtRest(g) => write!(
                f,
                "accelerometer.mean_m_s2 less bias is {g:.2} m/s², not ≈ 9.81: the device was not at rest"
            ),
        }
    }
}

/// Gravity in the camera frame and the 1σ of its direction from a mean reading, (B9) of
/// `docs/building.md`: `ĝ = −R (a − b)/|a − b|`, `σ² = (σ_b² + σ_a²/N)/|a − b|² + σ_R²`.
/// The one computation of it: the device's plumb and the host's (from a capture's record or
/// a device's reading) both come from here. `|a − b|` outside 0.5–1.5 g is
/// [`VerticalError::NotAtRest`].
pub fn vertical(reading: &MeanReading, alignment: &Alignment) -> Result<Vertical, VerticalError> {
    let finite = |v: &Vec3| v.iter().all(|x| x.is_finite());
    if !finite(&reading.mean_m_s2) {
        return Err(VerticalError::NonFinite("mean_m_s2"));
    }
    if !finite(&alignment.bias_m_s2) {
        return Err(VerticalError::NonFinite("bias_m_s2"));
    }
    if !finite(&alignment.camera_from_sensor_rad) {
        return Err(VerticalError::NonFinite("camera_from_sensor_rad"));
    }
    for (name, x) in [
        ("sample_sigma_m_s2", reading.sample_sigma_m_s2),
        ("bias_sigma_m_s2", alignment.bias_sigma_m_s2),
        ("alignment_sigma_rad", alignment.alignment_sigma_rad),
    ] {
        if !(x >= 0.0 && x.is_finite()) {
            return Err(VerticalError::BadSigma(name, x));
        }
    }
    if reading.samples == 0 {
        return Err(VerticalError::NoSamples);
    }
    let up = reading.mean_m_s2 - alignment.bias_m_s2;
    let g = up.norm();
    if !(g > 0.5 * STANDARD_GRAVITY && g < 1.5 * STANDARD_GRAVITY) {
        return Err(VerticalError::NotAtRest(g));
    }
    let r = Rotation3::new(alignment.camera_from_sensor_rad);
    let down = -(r * up) / g;
    let noise2 = alignment.bias_sigma_m_s2 * alignment.bias_sigma_m_s2
        + reading.sample_sigma_m_s2 * reading.sample_sigma_m_s2 / reading.samples as Real;
    let sigma_rad =
        sqrt(noise2 / (g * g) + alignment.alignment_sigma_rad * alignment.alignment_sigma_rad);
    Ok(Vertical { down, sigma_rad })
}

/// The parameters of (A1): bias, `M = Rᵀ` (camera → sensor) and scale.
#[derive(Debug, Clone, Copy)]
struct Params {
    bias: Vec3,
    m: Mat3,
    k: Real,
}

/// (A1) as a least-squares problem for the shared LM.
struct Problem<'a> {
    poses: &'a [Pose],
}

impl LeastSquares<PARAMS> for Problem<'_> {
    type Params = Params;
    type Extra = ();

    /// Residual `r = a − k M u − b`, parameters `(b, δ, k)` with `M ← M (I + [δ]×)`:
    /// `∂r/∂b = −I`, `∂r/∂δ = k M [u]×`, `∂r/∂k = −M u`; whitened by each pose's Σ.
    fn evaluate(&self, p: &Params) -> Result<(NormalEquations<PARAMS>, ()), SolveError> {
        let mut jtj = SMatrix::<Real, PARAMS, PARAMS>::zeros();
        let mut jtr = SVector::<Real, PARAMS>::zeros();
        let mut cost = 0.0 as Real;
        for pose in self.poses {
            let len = pose.gravity_camera.norm();
            if !(len > 0.0) {
                return Err(SolveError::NonFinite);
            }
            let u = -pose.gravity_camera / len * STANDARD_GRAVITY;
            let r = pose.mean_m_s2 - p.m * u * p.k - p.bias;
            let w = pose
                .covariance(&u)
                .try_inverse()
                .ok_or(SolveError::Degenerate)?;
            let mut j = SMatrix::<Real, 3, PARAMS>::zeros();
            j.fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&(-Mat3::identity()));
            j.fixed_view_mut::<3, 3>(0, 3)
                .copy_from(&(p.m * u.cross_matrix() * p.k));
            j.fixed_view_mut::<3, 1>(0, 6).copy_from(&(-(p.m * u)));
            let jt_w = j.transpose() * w;
            jtj += jt_w * j;
            jtr += jt_w * r;
            cost += (r.transpose() * w * r)[(0, 0)];
        }
        if !cost.is_finite() {
            return Err(SolveError::NonFinite);
        }
        Ok((NormalEquations { jtj, jtr, cost }, ()))
    }

    fn step(&self, p: &Params, delta: &SVector<Real, PARAMS>) -> Params {
        let turn = Rotation3::new(Vec3::new(delta[3], delta[4], delta[5]));
        Params {
            bias: p.bias + Vec3::new(delta[0], delta[1], delta[2]),
            m: p.m * turn.matrix(),
            k: p.k + delta[6],
        }
    }

    fn step_scale(&self, p: &Params) -> Real {
        1.0 + p.bias.norm() + p.k
    }
}

/// The residual vector of a pose under a calibration (m/s², sensor axes), for reports.
pub fn residual(pose: &Pose, calibration: &AccelCalibration) -> Option<SVector<Real, 3>> {
    let len = pose.gravity_camera.norm();
    if !(len > 0.0) {
        return None;
    }
    let u = -pose.gravity_camera / len * STANDARD_GRAVITY;
    let m: Matrix3<Real> = Rotation3::new(calibration.camera_from_sensor_rad)
        .matrix()
        .transpose();
    Some(pose.mean_m_s2 - m * u * calibration.scale - calibration.bias_m_s2)
}

#[cfg(test)]
mod tests;
