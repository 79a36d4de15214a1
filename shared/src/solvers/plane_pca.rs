//! Weighted principal-component plane fit with its quality index and covariance, and the
//! plane-to-plane quantities the wall instrument reports: angle, distance between parallel
//! planes, a plane's direction seen from the instrument and from the plumb
//! (`docs/building.md`, "Plane by principal components" and "From planes to readings").

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Mat3, Real, Vec3};

use super::correlation::correlation_inflation;
use super::SolveError;

/// A plane fitted to weighted points: `normal·X = offset`, with what qualifies it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFit {
    /// Unit normal, pointing away from the camera centre (`offset > 0`).
    pub normal: Vec3,
    /// Distance from the camera centre to the plane (metres).
    pub offset: Real,
    /// Weighted centroid of the points (metres, camera frame).
    pub centroid: Vec3,
    /// The in-plane principal directions: `axes[0]` of largest spread, `axes[1]` across it.
    pub axes: [Vec3; 2],
    /// Weighted variances of the points along `axes[0]`, `axes[1]` and the normal (m²):
    /// the scatter matrix's eigenvalues, largest first.
    pub spread: [Real; 3],
    /// Quality index `1 − λ₃/λ₂` in `[0, 1]` (`docs/building.md`, "Quality index"): 1 for
    /// points spread over a flat area, 0 for a line or a blob.
    pub quality: Real,
    /// Weighted root-mean-square distance of the points from the plane (metres).
    pub rms: Real,
    /// Residual χ² per degree of freedom against the points' σ (≈ 1 when the noise model
    /// explains the scatter).
    pub chi2: Real,
    /// Covariance of the unit normal (rank 2, in the plane's tangent space), inflated by
    /// `max(1, chi2)`.
    pub normal_cov: Mat3,
    /// 1σ of the plane's offset at the centroid (metres), inflated like `normal_cov`.
    pub centroid_sigma: Real,
    /// Number of points.
    pub points: usize,
}

/// Fits a plane to `(point, σ)` samples, each weighted by `1/σ²` (σ: the point's 1σ along
/// the plane's normal). Two passes over `samples` (centroid, then scatter about it, so that
/// `f32` keeps the millimetre spreads of points metres away).
///
/// `TooFewPoints` below 3 samples; `NonFinite` for a NaN point or a σ that is not positive
/// and finite; `Degenerate` when the points lie on a line (no second in-plane direction).
pub fn fit_plane<I>(samples: I) -> Result<PlaneFit, SolveError>
where
    I: Iterator<Item = (Vec3, Real)> + Clone,
{
    let (mut w_sum, mut c, mut n) = (0.0 as Real, Vec3::zeros(), 0usize);
    for (p, s) in samples.clone() {
        if !(s > 0.0 && s.is_finite() && p.iter().all(|v| v.is_finite())) {
            return Err(SolveError::NonFinite);
        }
        let w = 1.0 / (s * s);
        w_sum += w;
        c += p * w;
        n += 1;
    }
    if n < 3 {
        return Err(SolveError::TooFewPoints);
    }
    c /= w_sum;
    let mut scatter = Mat3::zeros();
    for (p, s) in samples.clone() {
        let d = p - c;
        scatter += d * d.transpose() / (s * s);
    }
    scatter /= w_sum;
    let eigen = nalgebra::SymmetricEigen::new(scatter);
    let mut order = [0usize, 1, 2];
    order.sort_unstable_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let spread = order.map(|k| eigen.eigenvalues[k].max(0.0));
    let axis = |k: usize| -> Vec3 { eigen.eigenvectors.column(order[k]).into_owned() };
    let (e0, e1, mut normal) = (axis(0), axis(1), axis(2));
    if !(spread[1] > 0.0) || spread[1] <= spread[0] * LINE_RATIO {
        return Err(SolveError::Degenerate);
    }
    let len = norm(&normal);
    if !(len > 0.0) {
        return Err(SolveError::Degenerate);
    }
    normal /= len;
    let mut offset = normal.dot(&c);
    if offset < 0.0 {
        normal = -normal;
        offset = -offset;
    }
    let mut chi2_sum = 0.0;
    for (p, s) in samples.clone() {
        let r = normal.dot(&(p - c)) / s;
        chi2_sum += r * r;
    }
    let dof = (n - 3).max(1) as Real;
    let chi2 = chi2_sum / dof;
    // Neighbouring points along a laser line share speckle and smoothing: their residuals are
    // correlated, and n correlated points carry less than n points' information
    // (docs/error-model.md §5b; the same AR(1) factor as the sphere's sections). Samples come
    // in curve order; outliers beyond 4 residual scales do not set the correlation.
    let cutoff = 4.0 * sqrt(chi2.max(1.0));
    let correlation = correlation_inflation(
        samples.clone().map(|(p, s)| normal.dot(&(p - c)) / s),
        cutoff,
    );
    let inflation = chi2.max(1.0) * correlation;
    // docs/building.md, eq. (B3): var(δn·e_k) = s² / (W λ_k) for the in-plane axes e_k.
    let normal_cov =
        (e0 * e0.transpose() / spread[0] + e1 * e1.transpose() / spread[1]) * (inflation / w_sum);
    Ok(PlaneFit {
        normal,
        offset,
        centroid: c,
        axes: [e0, e1],
        spread,
        quality: 1.0 - spread[2] / spread[1],
        rms: sqrt(spread[2]),
        chi2,
        normal_cov,
        centroid_sigma: sqrt(inflation / w_sum),
        points: n,
    })
}

/// Most laser lines [`add_line_bias`] tells apart (the calibration's plane limit).
pub const MAX_LINES: usize = crate::calibration::MAX_PLANES;

/// Adds to `fit`'s covariance the error a common stripe-row bias of 1σ `bias_px` on each
/// laser line puts on the plane (`docs/building.md`, eq. (B3b)): the peak estimator's
/// phase-dependent bias is the same for every point of a line that sits at one subpixel row
/// phase (a frontal wall), so it does not average out along the line, and two parallel lines
/// 5 cm apart turn a 0.01 px difference into tenths of a degree of pitch.
///
/// `samples`: `(line, point, σ, ∂X/∂v)` with the σ of the fit (its weights) and
/// [`crate::noise::displacement_per_pixel`]; lines at or beyond [`MAX_LINES`] are ignored.
/// The weighted least-squares response of the plane (two in-plane rotations `α_k` about the
/// centroid and the offset) to residual shifts `δr_i = n·∂X_i/∂v · b` is
/// `α_k = Σ w_i ((X_i − c)·e_k) δr_i / (W λ_k)`, `δρ = Σ w_i δr_i / W`; independent biases per
/// line add their squares.
pub fn add_line_bias<I>(fit: &mut PlaneFit, samples: I, bias_px: Real)
where
    I: Iterator<Item = (usize, Vec3, Real, Vec3)>,
{
    if !(bias_px > 0.0) {
        return;
    }
    let mut per_line = [[0.0 as Real; 3]; MAX_LINES];
    let mut w_sum = 0.0 as Real;
    for (line, p, s, dxdv) in samples {
        if !(s > 0.0 && s.is_finite()) {
            continue;
        }
        let w = 1.0 / (s * s);
        w_sum += w;
        let Some(g) = per_line.get_mut(line) else {
            continue;
        };
        let shift = w * fit.normal.dot(&dxdv);
        let arm = p - fit.centroid;
        g[0] += shift * arm.dot(&fit.axes[0]);
        g[1] += shift * arm.dot(&fit.axes[1]);
        g[2] += shift;
    }
    if !(w_sum > 0.0 && fit.spread[0] > 0.0 && fit.spread[1] > 0.0) {
        return;
    }
    let b2 = bias_px * bias_px;
    let mut centroid_var = fit.centroid_sigma * fit.centroid_sigma;
    for g in per_line {
        let dn = fit.axes[0] * (g[0] / (w_sum * fit.spread[0]))
            + fit.axes[1] * (g[1] / (w_sum * fit.spread[1]));
        fit.normal_cov += dn * dn.transpose() * b2;
        let drho = g[2] / w_sum;
        centroid_var += drho * drho * b2;
    }
    fit.centroid_sigma = sqrt(centroid_var);
}

/// Below this ratio of the second to the first spread the points are a line, not an area.
const LINE_RATIO: Real = 1e-8;

impl PlaneFit {
    /// Signed distance of `p` from the plane (positive beyond it, seen from the camera).
    pub fn signed_distance(&self, p: Vec3) -> Real {
        self.normal.dot(&p) - self.offset
    }

    /// 1σ of the plane's position along its normal at the point `p` of the plane: the
    /// offset's σ at the centroid and the normal's σ over the lever arm `p − centroid`.
    pub fn sigma_at(&self, p: Vec3) -> Real {
        let arm = p - self.centroid;
        sqrt(self.centroid_sigma * self.centroid_sigma + arm.dot(&(self.normal_cov * arm)))
    }

    /// Variance of the normal's component along the unit vector `u`.
    pub fn normal_variance_along(&self, u: Vec3) -> Real {
        u.dot(&(self.normal_cov * u)).max(0.0)
    }
}

/// A value and its 1σ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The value (metres or radians).
    pub value: Real,
    /// Its 1σ (same unit).
    pub sigma: Real,
}

/// The angle between the normals of two planes, `acos(n_a·n_b)` in `[0, π]`, and its 1σ
/// from both normals' covariances (`docs/building.md`, eq. (B5)).
pub fn normal_angle(a: &PlaneFit, b: &PlaneFit) -> Estimate {
    let cos = a.normal.dot(&b.normal).clamp(-1.0, 1.0);
    let value = cos.acos();
    let sin = sqrt((1.0 - cos * cos).max(0.0));
    // δθ = −(δn_a·n_b + n_a·δn_b)/sin θ; near θ = 0 the angle's σ is the normals' own spread.
    let var = if sin > 1e-6 {
        (a.normal_variance_along(b.normal) + b.normal_variance_along(a.normal)) / (sin * sin)
    } else {
        0.5 * (a.normal_cov.trace() + b.normal_cov.trace())
    };
    Estimate {
        value,
        sigma: sqrt(var),
    }
}

/// Distance between two (nearly) parallel planes, measured along their mean normal between
/// their centroids, with its 1σ (`docs/building.md`, eq. (B6)). Both normals point away
/// from the camera, so the distance is the farther plane's offset less the nearer one's
/// where they face the same way.
pub fn parallel_distance(a: &PlaneFit, b: &PlaneFit) -> Estimate {
    let gap = b.centroid - a.centroid;
    let value = 0.5 * (gap.dot(&a.normal) + gap.dot(&b.normal));
    let half = gap * 0.5;
    let var = a.centroid_sigma * a.centroid_sigma
        + b.centroid_sigma * b.centroid_sigma
        + half.dot(&((a.normal_cov + b.normal_cov) * half));
    Estimate {
        value: value.abs(),
        sigma: sqrt(var),
    }
}

/// A plane's direction seen from the instrument (`docs/building.md`, "Orientation").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orientation {
    /// Turn of the wall about the camera's vertical axis `y`: 0 when it faces the camera,
    /// positive when its right-hand part (seen from the camera) is nearer.
    pub yaw: Estimate,
    /// Tilt about the camera's horizontal axis `x`: 0 when it faces the camera, positive when
    /// its lower part (image bottom) is nearer.
    pub pitch: Estimate,
    /// Distance from the camera centre along the optical axis to the plane (metres).
    pub axis_distance: Estimate,
}

/// [`Orientation`] of `plane`; `None` when the optical axis runs parallel to the plane.
pub fn orientation(plane: &PlaneFit) -> Option<Orientation> {
    let n = plane.normal;
    if !(n.z > 1e-6) {
        return None;
    }
    // yaw = atan2(n_x, n_z) about y; pitch = atan2(n_y, √(n_x² + n_z²)) about x.
    let h = sqrt(n.x * n.x + n.z * n.z);
    let yaw_dir = Vec3::new(n.z, 0.0, -n.x) / h;
    // d yaw = yaw_dir·δn / h; d pitch = δn_y / h (pitch = asin n_y).
    let yaw_sigma = sqrt(plane.normal_variance_along(yaw_dir)) / h;
    let pitch_sigma = sqrt(plane.normal_variance_along(Vec3::y())) / h;
    let z = plane.offset / n.z;
    let on_axis = Vec3::new(0.0, 0.0, z);
    Some(Orientation {
        yaw: Estimate {
            value: n.x.atan2(n.z),
            sigma: yaw_sigma,
        },
        pitch: Estimate {
            value: n.y.atan2(h),
            sigma: pitch_sigma,
        },
        axis_distance: Estimate {
            value: z,
            sigma: plane.sigma_at(on_axis) / n.z,
        },
    })
}

/// The wall's deviation from the plumb: the angle between the plane and the vertical
/// `asin(n·ĝ)` (signed: positive when the wall's top leans away from the camera), from the
/// gravity direction `gravity` (camera frame, pointing down, any length) and its 1σ
/// direction error `gravity_sigma` (radians; `docs/building.md`, "Plumb").
pub fn plumb_deviation(plane: &PlaneFit, gravity: Vec3, gravity_sigma: Real) -> Option<Estimate> {
    let len = norm(&gravity);
    if !(len > 0.0) || !gravity_sigma.is_finite() {
        return None;
    }
    let g = gravity / len;
    let s = plane.normal.dot(&g).clamp(-1.0, 1.0);
    let c = sqrt((1.0 - s * s).max(0.0));
    if !(c > 1e-6) {
        return None;
    }
    // The component of g across the normal carries the normal's error into the angle.
    let across = (g - plane.normal * s) / c;
    let var = plane.normal_variance_along(across) + gravity_sigma * gravity_sigma;
    Some(Estimate {
        value: s.asin(),
        sigma: sqrt(var),
    })
}

/// The line where two planes meet (`normal_a·X = offset_a`, `normal_b·X = offset_b`): a point
/// on it nearest the origin and its unit direction, `None` when they are parallel.
pub fn plane_intersection(
    normal_a: Vec3,
    offset_a: Real,
    normal_b: Vec3,
    offset_b: Real,
) -> Option<(Vec3, Vec3)> {
    let d = normal_a.cross(&normal_b);
    let d2 = d.norm_squared();
    if !(d2 > 1e-12) {
        return None;
    }
    let p = (normal_b.cross(&d) * offset_a + d.cross(&normal_a) * offset_b) / d2;
    Some((p, d / sqrt(d2)))
}

#[cfg(test)]
#[path = "plane_pca_tests.rs"]
pub(crate) mod tests;
