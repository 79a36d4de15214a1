//! The camera model (thesis chapter 2): pinhole intrinsics plus Brown–Conrady distortion.
//!
//! Three coordinate systems meet here (derivations in `docs/camera-model.md`):
//!
//! * the **camera frame** (metres): origin at the optical centre, `x` right, `y` down,
//!   `z` forward along the optical axis;
//! * **normalised image coordinates** (dimensionless): `(x/z, y/z)`, the point where the ray
//!   crosses the plane `z = 1`. *Ideal* normalised coordinates are those of the pinhole model;
//!   *distorted* ones are where the real lens sends the ray;
//! * **pixel coordinates** `(u, v)`: `u = fx·x_d + cx`, `v = fy·y_d + cy`, with the centre of
//!   pixel `(i, j)` at `(i, j)` (OpenCV's convention; see `docs/architecture.md`).
//!
//! The distortion follows OpenCV's `(k1, k2, p1, p2, k3)` convention exactly, so coefficients
//! from `cv::calibrateCamera` (or any Zhang-method tool using the same model) can be used as
//! they are. Skew is taken as zero (true for every modern sensor, and OpenCV's default).
//!
//! Why hand-written: the `opencv` crate needs the C++ library and `std`, which the firmware
//! cannot have; the model is a few lines, and its inverse needs the validity-region and
//! residual checks below, which we want under our own control and tests.

use core::fmt;

use serde::{Deserialize, Serialize};

// `Float` supplies sqrt/atan2/… in `no_std`; with `std` the inherent methods win.
#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Mat3, Real, Vec2, Vec3};

/// Most Newton iterations [`Camera::undistort`] makes. Newton converges quadratically from the
/// distorted point for any realistic lens (`docs/camera-model.md`, "Convergence"): 3–5
/// iterations reach machine precision, so 20 leaves room for strong lenses near the
/// validity limit without letting a hopeless case run for long.
pub const MAX_NEWTON_ITERATIONS: usize = 20;

/// Most fixed-point iterations of the fallback inverse (linear convergence, see the docs).
pub const MAX_FIXED_POINT_ITERATIONS: usize = 200;

/// Largest reprojection residual (pixels) that [`Camera::undistort`] accepts in `f64`.
///
/// The residual actually reached is at the rounding floor (~1e-12 px in `f64`); this value
/// only separates "converged" from "diverged". In `f32` the rounding floor itself is about
/// 1e-4 px (see [`Camera::undistort_tolerance_px`]), so the accepted residual grows with
/// the precision.
pub const UNDISTORT_TOLERANCE_PX: Real = 1e-4;

/// Brown–Conrady lens distortion, in OpenCV's convention.
///
/// For ideal normalised coordinates `(x, y)` and `r² = x² + y²`:
///
/// ```text
/// radial = 1 + k1·r² + k2·r⁴ + k3·r⁶
/// x_d = x·radial + 2·p1·x·y + p2·(r² + 2x²)
/// y_d = y·radial + p1·(r² + 2y²) + 2·p2·x·y
/// ```
///
/// (`docs/camera-model.md`, "Brown–Conrady distortion"). `Default` is no distortion.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Distortion {
    /// Radial coefficient of `r²`.
    pub k1: Real,
    /// Radial coefficient of `r⁴`.
    pub k2: Real,
    /// Radial coefficient of `r⁶`.
    pub k3: Real,
    /// First tangential (decentering) coefficient.
    pub p1: Real,
    /// Second tangential (decentering) coefficient.
    pub p2: Real,
}

impl Distortion {
    /// True when every coefficient is zero (pure pinhole camera).
    #[inline]
    pub fn is_zero(&self) -> bool {
        self.k1 == 0.0 && self.k2 == 0.0 && self.k3 == 0.0 && self.p1 == 0.0 && self.p2 == 0.0
    }

    /// True when every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        self.k1.is_finite()
            && self.k2.is_finite()
            && self.k3.is_finite()
            && self.p1.is_finite()
            && self.p2.is_finite()
    }

    /// Applies the distortion to ideal normalised coordinates and returns the distorted ones
    /// together with the Jacobian `∂(x_d, y_d)/∂(x, y)` (row-major `[[a, b], [c, d]]`).
    ///
    /// The Jacobian is the derivative of the formulas in the type documentation
    /// (`docs/camera-model.md`, equation (J)); Newton's inverse needs it.
    pub fn apply_with_jacobian(&self, ideal: Vec2) -> (Vec2, [[Real; 2]; 2]) {
        let (x, y) = (ideal.x, ideal.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d(radial)/d(r²)
        let dradial = self.k1 + r2 * (2.0 * self.k2 + r2 * 3.0 * self.k3);
        let xd = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y;
        // ∂radial/∂x = 2x·dradial, ∂radial/∂y = 2y·dradial.
        let dxdx = radial + 2.0 * x * x * dradial + 2.0 * self.p1 * y + 6.0 * self.p2 * x;
        let dxdy = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let dydx = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let dydy = radial + 2.0 * y * y * dradial + 6.0 * self.p1 * y + 2.0 * self.p2 * x;
        (Vec2::new(xd, yd), [[dxdx, dxdy], [dydx, dydy]])
    }

    /// Applies the distortion to ideal normalised coordinates.
    pub fn apply(&self, ideal: Vec2) -> Vec2 {
        self.apply_with_jacobian(ideal).0
    }

    /// True when the radial part of the distortion is strictly increasing on `[0, r]` with
    /// `r² = r2`, i.e. `d(r·radial(r))/dr = 1 + 3k1·r² + 5k2·r⁴ + 7k3·r⁶ > 0` there.
    ///
    /// Beyond the first zero of that derivative the lens model folds back on itself: two
    /// different rays land on the same pixel, and the model (a polynomial fitted inside the
    /// image) no longer describes the lens. `docs/camera-model.md`, "Validity region".
    pub fn radially_monotone_up_to(&self, r2: Real) -> bool {
        if !(r2.is_finite() && r2 >= 0.0) {
            return false;
        }
        // g(s) = 1 + 3k1 s + 5k2 s² + 7k3 s³ with s = r²; g(0) = 1 > 0. Its minimum on
        // [0, r2] is at r2 or at an interior root of g'(s) = 3k1 + 10k2 s + 21k3 s².
        let g = |s: Real| 1.0 + s * (3.0 * self.k1 + s * (5.0 * self.k2 + s * 7.0 * self.k3));
        if g(r2) <= 0.0 {
            return false;
        }
        let (a, b, c) = (21.0 * self.k3, 10.0 * self.k2, 3.0 * self.k1);
        let mut roots = [Real::NAN; 2];
        if a == 0.0 {
            if b != 0.0 {
                roots[0] = -c / b;
            }
        } else {
            let disc = b * b - 4.0 * a * c;
            if disc >= 0.0 {
                // Numerically stable quadratic roots (no cancellation).
                let q = -0.5 * (b + b.signum() * sqrt(disc));
                roots[0] = q / a;
                if q != 0.0 {
                    roots[1] = c / q;
                }
            }
        }
        roots
            .iter()
            .all(|&s| !(s.is_finite() && s > 0.0 && s < r2) || g(s) > 0.0)
    }
}

/// Why a camera operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraError {
    /// Zero image size, or a focal length / principal point that is not finite and positive
    /// (focal) or finite (principal point).
    InvalidIntrinsics,
    /// A distortion coefficient is not finite, or the distortion model folds over inside
    /// the image (some pixel of the image is outside the model's validity region).
    InvalidDistortion,
    /// The point is on or behind the camera's `z = 0` plane (`z ≤ 0`).
    BehindCamera,
    /// An input coordinate is NaN or infinite.
    NonFinite,
    /// The iterative inverse of the distortion did not reach the residual tolerance.
    UndistortDiverged,
    /// The point is beyond the radius where the radial distortion stops being monotone
    /// (the lens model folds over), so it has no unique image / pre-image.
    OutsideValidRegion,
}

impl fmt::Display for CameraError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CameraError::InvalidIntrinsics => write!(
                f,
                "invalid camera intrinsics (size must be non-zero, focal lengths finite and positive, principal point finite)"
            ),
            CameraError::InvalidDistortion => write!(
                f,
                "invalid distortion (non-finite coefficient, or the model folds over inside the image)"
            ),
            CameraError::BehindCamera => write!(f, "point is on or behind the camera (z <= 0)"),
            CameraError::NonFinite => write!(f, "non-finite coordinate"),
            CameraError::UndistortDiverged => {
                write!(f, "distortion inverse did not converge")
            }
            CameraError::OutsideValidRegion => write!(
                f,
                "point is outside the region where the distortion model is one-to-one"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CameraError {}

/// A calibrated camera: pinhole intrinsics (pixels) and Brown–Conrady distortion.
///
/// Pixel ↔ normalised coordinates ("passage equations", `docs/camera-model.md`):
///
/// ```text
/// u = fx·x_d + cx        x_d = (u − cx) / fx
/// v = fy·y_d + cy        y_d = (v − cy) / fy
/// ```
///
/// where `(x_d, y_d)` = [`Distortion::apply`] of the ideal `(x/z, y/z)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along `u`, in pixels (focal length / pixel pitch).
    pub fx: Real,
    /// Focal length along `v`, in pixels.
    pub fy: Real,
    /// Principal point, `u` coordinate (pixels).
    pub cx: Real,
    /// Principal point, `v` coordinate (pixels).
    pub cy: Real,
    /// Lens distortion.
    pub distortion: Distortion,
}

impl Camera {
    /// The nominal reference design: MT9V034 (752 × 480, 6 µm pixels) behind a 6 mm lens,
    /// so `f = 6 mm / 6 µm = 1000 px`, principal point at the geometric image centre
    /// `((752 − 1)/2, (480 − 1)/2) = (375.5, 239.5)`, no distortion.
    ///
    /// This is the *design*, not a calibrated unit: a real unit's principal point is off
    /// by tens of pixels and its lens has `k1` of a few percent.
    pub fn reference_design() -> Self {
        Camera {
            width: 752,
            height: 480,
            fx: 1000.0,
            fy: 1000.0,
            cx: 375.5,
            cy: 239.5,
            distortion: Distortion::default(),
        }
    }

    /// Checks that the intrinsics are usable and that every pixel of the image has a unique
    /// ray (the distortion does not fold over inside the image).
    ///
    /// The fold-over check undistorts the four image corners (the extreme edges of the
    /// pixel area): the distorted radius is largest at a corner, and within the monotone
    /// region the ideal radius grows with it, so if the corners are valid so is the image.
    pub fn validate(&self) -> Result<(), CameraError> {
        let finite_positive = |v: Real| v.is_finite() && v > 0.0;
        if self.width == 0
            || self.height == 0
            || !finite_positive(self.fx)
            || !finite_positive(self.fy)
            || !self.cx.is_finite()
            || !self.cy.is_finite()
        {
            return Err(CameraError::InvalidIntrinsics);
        }
        if !self.distortion.is_finite() {
            return Err(CameraError::InvalidDistortion);
        }
        if self.distortion.is_zero() {
            return Ok(());
        }
        let (u0, v0) = (-0.5, -0.5);
        let (u1, v1) = (self.width as Real - 0.5, self.height as Real - 0.5);
        for (u, v) in [(u0, v0), (u1, v0), (u0, v1), (u1, v1)] {
            if self.pixel_to_normalised(Vec2::new(u, v)).is_err() {
                return Err(CameraError::InvalidDistortion);
            }
        }
        Ok(())
    }

    /// True when `pixel` lies on the sensor, i.e. in `[-0.5, width − 0.5] × [-0.5, height − 0.5]`.
    pub fn contains(&self, pixel: Vec2) -> bool {
        pixel.x >= -0.5
            && pixel.y >= -0.5
            && pixel.x <= self.width as Real - 0.5
            && pixel.y <= self.height as Real - 0.5
    }

    /// The intrinsic matrix `K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]` (pixels ← ideal
    /// normalised homogeneous coordinates, distortion excluded).
    pub fn intrinsic_matrix(&self) -> Mat3 {
        Mat3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// Ideal normalised coordinates → distorted normalised coordinates ([`Distortion::apply`]).
    pub fn distort(&self, ideal: Vec2) -> Vec2 {
        self.distortion.apply(ideal)
    }

    /// The residual (pixels) [`Camera::undistort`] accepts for a distorted point.
    ///
    /// `max(UNDISTORT_TOLERANCE_PX, 32·ε·(1 + |d|)·max(fx, fy))`: the second term is the
    /// rounding floor of evaluating the distortion (a handful of roundings of quantities of
    /// size `|d|`, i.e. a few ε·|d|, scaled to pixels, with a ×8 margin). In `f64` it is
    /// ~1e-11 px and the 1e-4 px bound applies; in `f32` at the reference design it is
    /// ~5e-3 px. `docs/camera-model.md`, "Accuracy in f32".
    pub fn undistort_tolerance_px(&self, distorted: Vec2) -> Real {
        let f = self.fx.max(self.fy);
        let floor = 32.0 * Real::EPSILON * (1.0 + norm(&distorted)) * f;
        floor.max(UNDISTORT_TOLERANCE_PX)
    }

    /// Distorted normalised coordinates → ideal normalised coordinates: the inverse of
    /// [`Camera::distort`].
    ///
    /// Newton's method on the 2 × 2 Jacobian, started at the distorted point, with step
    /// halving if a step does not reduce the residual; if Newton fails (singular Jacobian,
    /// no convergence), OpenCV's fixed-point iteration `x ← (d − tangential(x)) / radial(x)`
    /// is tried. The result is accepted only if its reprojection residual is below
    /// [`Camera::undistort_tolerance_px`] and it lies inside the validity region
    /// ([`Distortion::radially_monotone_up_to`]). `docs/camera-model.md`, "Inverse".
    ///
    /// Inlined up to the iteration, so that a camera without distortion costs a triangulated
    /// point only the two checks (`docs/performance.md`, issue 17).
    #[inline]
    pub fn undistort(&self, distorted: Vec2) -> Result<Vec2, CameraError> {
        if !(distorted.x.is_finite() && distorted.y.is_finite()) {
            return Err(CameraError::NonFinite);
        }
        if self.distortion.is_zero() {
            return Ok(distorted);
        }
        self.undistort_iterative(distorted)
    }

    /// [`Camera::undistort`] of a finite point with a distortion: the iteration and its
    /// acceptance.
    fn undistort_iterative(&self, distorted: Vec2) -> Result<Vec2, CameraError> {
        let dist = &self.distortion;
        let tol_px = self.undistort_tolerance_px(distorted);
        let residual_px = |p: Vec2| {
            let r = dist.apply(p) - distorted;
            let (ru, rv) = (r.x * self.fx, r.y * self.fy);
            sqrt(ru * ru + rv * rv)
        };
        let accept = |p: Vec2| -> Result<Vec2, CameraError> {
            if !(p.x.is_finite() && p.y.is_finite()) {
                return Err(CameraError::UndistortDiverged);
            }
            if !dist.radially_monotone_up_to(p.norm_squared()) {
                return Err(CameraError::OutsideValidRegion);
            }
            // NaN residual compares false and is rejected.
            if residual_px(p) <= tol_px {
                Ok(p)
            } else {
                Err(CameraError::UndistortDiverged)
            }
        };

        let newton = self.undistort_newton(distorted);
        let newton_result = match newton {
            Some(p) => accept(p),
            None => Err(CameraError::UndistortDiverged),
        };
        match newton_result {
            Ok(p) => Ok(p),
            Err(e) => match self.undistort_fixed_point(distorted) {
                Some(p) => accept(p).map_err(|_| e),
                None => Err(e),
            },
        }
    }

    /// Damped Newton iterations for `distort(p) = d`; `None` if the Jacobian is singular
    /// or the values become non-finite.
    fn undistort_newton(&self, d: Vec2) -> Option<Vec2> {
        let dist = &self.distortion;
        // Stop once a step is below √ε·(1 + |p|): Newton's error after such a step is
        // O(step²) = O(ε), the rounding floor (docs/camera-model.md, "Convergence").
        // One more "polishing" step is then taken to settle on the floor.
        let sqrt_eps = sqrt(Real::EPSILON);
        let mut p = d;
        let (f0, mut jac) = dist.apply_with_jacobian(p);
        let mut r = f0 - d;
        let mut r_norm = norm(&r);
        let mut polishing = false;
        for _ in 0..MAX_NEWTON_ITERATIONS {
            let [[a, b], [c, e]] = jac;
            let det = a * e - b * c;
            if !(det.is_finite() && det > 0.0) {
                // A non-positive determinant means the model folds here: not invertible.
                return None;
            }
            // Solve J·s = r (Cramer's rule, exact enough for a well-conditioned 2 × 2).
            let step = Vec2::new((e * r.x - b * r.y) / det, (a * r.y - c * r.x) / det);
            let mut scale: Real = 1.0;
            let mut accepted = false;
            for _ in 0..8 {
                let cand = p - step * scale;
                let (fc, jc) = dist.apply_with_jacobian(cand);
                let rc = fc - d;
                let rc_norm = norm(&rc);
                // Accept a step that does not increase the residual; at the rounding floor
                // the residual only fluctuates, so "not larger" (not "smaller") is used.
                if rc_norm.is_finite() && rc_norm <= r_norm {
                    p = cand;
                    jac = jc;
                    r = rc;
                    r_norm = rc_norm;
                    accepted = true;
                    break;
                }
                scale *= 0.5;
            }
            if !accepted {
                // No step reduces the residual: we are at the rounding floor (or stuck).
                return Some(p);
            }
            if polishing {
                return Some(p);
            }
            let step_norm = norm(&step) * scale;
            if step_norm <= sqrt_eps * (1.0 + norm(&p)) {
                polishing = true;
            }
        }
        Some(p)
    }

    /// OpenCV's fixed-point inverse, `p ← (d − tangential(p)) / radial(p)`; converges
    /// linearly when the distortion is a contraction (moderate lenses). `None` on a
    /// non-finite value or zero radial factor.
    fn undistort_fixed_point(&self, d: Vec2) -> Option<Vec2> {
        let k = &self.distortion;
        let mut p = d;
        for _ in 0..MAX_FIXED_POINT_ITERATIONS {
            let (x, y) = (p.x, p.y);
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (k.k1 + r2 * (k.k2 + r2 * k.k3));
            if !(radial.is_finite() && radial > 0.0) {
                return None;
            }
            let tx = 2.0 * k.p1 * x * y + k.p2 * (r2 + 2.0 * x * x);
            let ty = k.p1 * (r2 + 2.0 * y * y) + 2.0 * k.p2 * x * y;
            let next = Vec2::new((d.x - tx) / radial, (d.y - ty) / radial);
            let step = norm(&(next - p));
            p = next;
            if !step.is_finite() {
                return None;
            }
            if step <= 4.0 * Real::EPSILON * (1.0 + norm(&p)) {
                break;
            }
        }
        Some(p)
    }

    /// Distorted pixel → ideal normalised coordinates `(x/z, y/z)` of its ray.
    #[inline]
    pub fn pixel_to_normalised(&self, pixel: Vec2) -> Result<Vec2, CameraError> {
        if !(pixel.x.is_finite() && pixel.y.is_finite()) {
            return Err(CameraError::NonFinite);
        }
        if !(self.fx.is_finite() && self.fx > 0.0 && self.fy.is_finite() && self.fy > 0.0) {
            return Err(CameraError::InvalidIntrinsics);
        }
        let distorted = Vec2::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy);
        if !(distorted.x.is_finite() && distorted.y.is_finite()) {
            return Err(CameraError::InvalidIntrinsics);
        }
        self.undistort(distorted)
    }

    /// Distorted pixel → direction `(x, y, 1)` of its ray in the camera frame (not unit:
    /// its `z` is 1, so a point at depth `z` on the ray is `z·ray`).
    #[inline]
    pub fn pixel_to_ray(&self, pixel: Vec2) -> Result<Vec3, CameraError> {
        let n = self.pixel_to_normalised(pixel)?;
        Ok(Vec3::new(n.x, n.y, 1.0))
    }

    /// Ideal normalised coordinates → distorted pixel (distortion, then intrinsics).
    ///
    /// Does not check the validity region; [`Camera::project`] does.
    pub fn normalised_to_pixel(&self, ideal: Vec2) -> Vec2 {
        let d = self.distort(ideal);
        Vec2::new(self.fx * d.x + self.cx, self.fy * d.y + self.cy)
    }

    /// Camera-frame point (metres) → distorted pixel.
    ///
    /// Errors: [`CameraError::NonFinite`], [`CameraError::BehindCamera`] if `z ≤ 0`, and
    /// [`CameraError::OutsideValidRegion`] if the ray is beyond the radius where the
    /// distortion model folds over (there a far-off point would wrongly land in the image).
    /// The pixel may lie outside the sensor; use [`Camera::contains`].
    pub fn project(&self, point: Vec3) -> Result<Vec2, CameraError> {
        if !(point.x.is_finite() && point.y.is_finite() && point.z.is_finite()) {
            return Err(CameraError::NonFinite);
        }
        if point.z <= 0.0 {
            return Err(CameraError::BehindCamera);
        }
        let ideal = Vec2::new(point.x / point.z, point.y / point.z);
        if !(ideal.x.is_finite() && ideal.y.is_finite()) {
            return Err(CameraError::NonFinite);
        }
        if !self
            .distortion
            .radially_monotone_up_to(ideal.norm_squared())
        {
            return Err(CameraError::OutsideValidRegion);
        }
        Ok(self.normalised_to_pixel(ideal))
    }
}

#[cfg(test)]
mod tests;
