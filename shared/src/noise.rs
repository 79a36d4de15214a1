//! Noise of one triangulated point (thesis chapter 7; derivations in `docs/error-model.md`).
//!
//! A laser-curve point comes from one image column `u` (exact: an integer) and a subpixel row
//! `v` (noisy). Its error is therefore one vector per point, `∂X/∂v·δv`
//! ([`displacement_per_pixel`]), which lies in the laser plane along the line from the
//! point to where the camera's vertical axis meets the plane ([`DisplacementField`]) — radial
//! from the source for the reference geometry. `δv` has two independent parts
//! ([`NoiseModel`]): the subpixel estimator's noise and laser speckle. Calibration errors (`e`,
//! `f`, `δ`) move every point coherently ([`calibration_displacements`],
//! [`calibration_relative_sigma`]).
//!
//! These primitives sit below the solvers: the pipeline writes each point's 1σ
//! ([`displacement_sigma`]) beside the point, the solvers read it and take its direction from
//! [`DisplacementField`]; [`crate::error_model`] (above the solvers) predicts a reading's
//! uncertainty from them.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::fmt;

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec2, Vec3, PI};

use crate::calibration::{PlanesUncertainty, MAX_PLANES, PLANE_PARAMS};
use crate::camera::Camera;
use crate::laser_plane::LaserPlane;

/// Why a point's noise could not be computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseError {
    /// The point is not in front of the camera, or the plane/ray geometry is degenerate.
    InvalidGeometry,
    /// The output buffer is shorter than the number of samples.
    ScratchTooSmall,
}

impl fmt::Display for NoiseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NoiseError::InvalidGeometry => f.write_str("invalid geometry for the noise model"),
            NoiseError::ScratchTooSmall => f.write_str("scratch buffer too small"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for NoiseError {}

/// The noise sources of a reading (`docs/error-model.md`, "Noise sources"). All 1σ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseModel {
    /// Subpixel estimator noise of the stripe centre along `v` (pixels), from sensor noise
    /// and quantisation.
    pub subpixel_px: Real,
    /// Speckle contrast `C` (1 = fully developed speckle on rough bark; a speckle filter or
    /// averaging lowers the effective value).
    pub speckle_contrast: Real,
    /// Laser wavelength (metres).
    pub wavelength: Real,
    /// Lens f-number `N` (the observation aperture `sin u' ≈ 1/(2N)`).
    pub f_number: Real,
    /// Pixel pitch (metres).
    pub pixel_pitch: Real,
    /// Uncertainty of the grazing-ray column at each end of the curve (pixels).
    pub edge_px: Real,
    /// Calibration uncertainty of the baseline `e` (metres).
    pub baseline: Real,
    /// Calibration uncertainty of the focal length (pixels).
    pub focal_px: Real,
    /// Calibration uncertainty of the plane tilt `δ` (radians).
    pub tilt: Real,
}

impl NoiseModel {
    /// This model with plane `k`'s calibration σ as `uncertainty` states them (a refinement's
    /// posterior, `docs/calibration.md` §14), or unchanged (the board's budget) without one.
    pub fn for_plane(&self, k: usize, uncertainty: Option<&PlanesUncertainty>) -> NoiseModel {
        match uncertainty {
            Some(u) => {
                let (baseline, tilt) = u.plane_sigma(k);
                NoiseModel {
                    baseline,
                    tilt,
                    ..*self
                }
            }
            None => *self,
        }
    }

    /// The reference device (`docs/error-model.md`, "Reference values"): 0.05 px subpixel
    /// noise, fully developed speckle at 650 nm through f/2 with 6 µm pixels, 0.5 px edge
    /// uncertainty, calibration to 0.2 mm in `e`, 1 px in `f`, 0.2 mrad in `δ`.
    pub fn reference() -> Self {
        NoiseModel {
            subpixel_px: 0.05,
            speckle_contrast: 1.0,
            wavelength: 650e-9,
            f_number: 2.0,
            pixel_pitch: 6e-6,
            edge_px: 0.5,
            baseline: 2e-4,
            focal_px: 1.0,
            tilt: 2e-4,
        }
    }

    /// Speckle-induced σ of the stripe centre (pixels): `C·λ/(2π·sin u')` with
    /// `sin u' = 1/(2N)`, i.e. `C·λ·N/(π·pitch)` (Dorsch, Häusler & Herrmann 1994;
    /// `docs/error-model.md`, "Speckle").
    pub fn speckle_px(&self) -> Real {
        if !(self.pixel_pitch > 0.0) {
            return 0.0;
        }
        self.speckle_contrast * self.wavelength * self.f_number / (PI * self.pixel_pitch)
    }

    /// Total random σ of the stripe centre (pixels): subpixel and speckle in quadrature.
    pub fn image_px(&self) -> Real {
        let s = self.speckle_px();
        sqrt(self.subpixel_px * self.subpixel_px + s * s)
    }

    /// σ of one stripe centre (pixels along `v`) from what the image says of it
    /// (`docs/error-model.md`, "A point's own σ"): the Cramér–Rao bound of a Gaussian cross
    /// profile of peak `amplitude` and σ `width_px` (pixels, [`crate::peaks::Peak::sigma`])
    /// under white noise `noise_dn` per sample (the difference image's, same units as
    /// `amplitude`; 1/12 of quantisation added),
    /// `σ_est = (σ_n/A)·√(2s/√π)`, in quadrature with speckle ([`NoiseModel::speckle_px`]).
    /// The weighted Gaussian log-fit reaches the bound (`docs/subpixel.md` §6). Where the
    /// amplitude is unknown or not positive, or `width_px` is not positive, the model's
    /// [`NoiseModel::image_px`] stands.
    pub fn stripe_centre_px(&self, amplitude: Real, width_px: Real, noise_dn: Real) -> Real {
        self.stripe_centre(noise_dn).px(amplitude, width_px)
    }

    /// [`NoiseModel::stripe_centre_px`] under noise `noise_dn` for many points: what does not
    /// depend on the point computed once (the pipeline's per-point cost on the device,
    /// `docs/performance.md`, issue 17).
    pub fn stripe_centre(&self, noise_dn: Real) -> StripeCentreSigma {
        let speckle = self.speckle_px();
        StripeCentreSigma {
            fallback: self.image_px(),
            noise_known: noise_dn >= 0.0,
            noise: sqrt(noise_dn * noise_dn + 1.0 / 12.0),
            speckle_squared: speckle * speckle,
            sqrt_pi: sqrt(PI),
        }
    }

    /// σ of one grazing-ray angle (radians): `edge_px / f` (a column is `1/f` rad near the
    /// optical axis).
    pub fn edge_angle_sigma(&self, focal_px: Real) -> Real {
        if focal_px > 0.0 {
            self.edge_px / focal_px
        } else {
            Real::INFINITY
        }
    }
}

/// [`NoiseModel::stripe_centre_px`] with the model and the image noise fixed
/// ([`NoiseModel::stripe_centre`]): the same σ, the same operations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StripeCentreSigma {
    /// [`NoiseModel::image_px`], where the point's amplitude or width says nothing.
    fallback: Real,
    /// The image noise is not negative (nor NaN).
    noise_known: bool,
    /// `√(σ_n² + 1/12)`.
    noise: Real,
    /// [`NoiseModel::speckle_px`]².
    speckle_squared: Real,
    /// `√π`.
    sqrt_pi: Real,
}

impl StripeCentreSigma {
    /// σ (pixels) of the stripe centre of peak `amplitude` and σ `width_px`
    /// ([`NoiseModel::stripe_centre_px`]).
    #[inline]
    pub fn px(&self, amplitude: Real, width_px: Real) -> Real {
        if !(amplitude > 0.0 && width_px > 0.0 && self.noise_known && amplitude.is_finite()) {
            return self.fallback;
        }
        let estimator = self.noise / amplitude * sqrt(2.0 * width_px / self.sqrt_pi);
        sqrt(estimator * estimator + self.speckle_squared)
    }

    /// [`NoiseModel::image_px`].
    pub fn image_px(&self) -> Real {
        self.fallback
    }
}

/// `∂X/∂v`: how the triangulated point `x` (on `plane`, camera frame) moves per pixel of
/// stripe position along the image column (`docs/error-model.md`, "One point"); for a
/// row-wise plane ([`LaserPlane::is_row_wise`], the crossing line) `∂X/∂u`, the same with
/// `x ↔ y`:
///
/// ```text
/// X = d·r/(n·r),  r = (x_n, y_n, 1),  ∂r/∂v = (0, 1/f_y, 0)
/// ∂X/∂v = z·∂r/∂v − (z/d)·(n_y/f_y)·X
/// ```
pub fn displacement_per_pixel(
    plane: &LaserPlane,
    focal_px: Real,
    x: Vec3,
) -> Result<Vec3, NoiseError> {
    PerPixel::of(plane, focal_px).at(x)
}

/// [`displacement_per_pixel`] over one plane and focal length: the stripe's axis and
/// `∂r/∂v` found once, the same operations per point (the pipeline's per-point cost on the
/// device, `docs/performance.md`, issue 17).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerPixel {
    /// `∂r/∂v` (or `∂r/∂u` for a row-wise plane).
    dr: Vec3,
    /// The normal's component along the stripe's axis.
    normal_a: Real,
    /// The plane's offset `d`.
    offset: Real,
    /// Focal length (pixels).
    focal_px: Real,
}

impl PerPixel {
    /// The derivative's constants for `plane` at focal length `focal_px` (pixels).
    #[inline]
    pub fn of(plane: &LaserPlane, focal_px: Real) -> Self {
        // A row-wise plane's stripe moves along the rows (∂/∂u, `n_x`): the same formula
        // with x and y swapped (`pipeline::crossing`).
        let (axis, normal_a) = stripe_axis(plane);
        PerPixel {
            dr: axis / focal_px,
            normal_a,
            offset: plane.offset,
            focal_px,
        }
    }

    /// [`displacement_per_pixel`] at the point `x` (camera frame).
    #[inline]
    pub fn at(&self, x: Vec3) -> Result<Vec3, NoiseError> {
        if !(x.z > 0.0 && x.z.is_finite() && self.focal_px > 0.0 && self.offset > 0.0) {
            return Err(NoiseError::InvalidGeometry);
        }
        Ok(self.dr * x.z - x * (x.z / self.offset * self.normal_a / self.focal_px))
    }

    /// [`displacement_sigma`] at the point `x` for `sigma_px` pixels of stripe-centre noise.
    #[inline]
    pub fn sigma(&self, x: Vec3, sigma_px: Real) -> Result<Real, NoiseError> {
        Ok(norm(&self.at(x)?) * sigma_px)
    }
}

/// The image axis along which depth moves `plane`'s stripe, as a camera-frame unit vector,
/// and the normal's component along it: `(ŷ, n_y)` for a line across the image, `(x̂, n_x)`
/// for a row-wise (crossing) line ([`LaserPlane::is_row_wise`]).
fn stripe_axis(plane: &LaserPlane) -> (Vec3, Real) {
    if plane.is_row_wise() {
        (Vec3::new(1.0, 0.0, 0.0), plane.normal.x)
    } else {
        (Vec3::new(0.0, 1.0, 0.0), plane.normal.y)
    }
}

/// 1σ of the triangulated point `x` (metres, along [`displacement_per_pixel`]) for
/// `sigma_px` pixels of stripe-centre noise: `|∂X/∂v|·σ_v`. The pipeline writes it beside
/// each point; the solvers read it (`docs/error-model.md`, "One point").
pub fn displacement_sigma(
    plane: &LaserPlane,
    focal_px: Real,
    x: Vec3,
    sigma_px: Real,
) -> Result<Real, NoiseError> {
    PerPixel::of(plane, focal_px).sigma(x, sigma_px)
}

/// The direction of [`displacement_per_pixel`] over one laser plane. Every image column's
/// plane of sight contains the camera's vertical axis, so a point moves along the line from
/// it to where that axis meets the laser plane: `∂X/∂v ∝ d·ŷ − n_y·X` with a positive factor
/// (`docs/error-model.md`, "One point"). Lets a solver turn a stored 1σ
/// ([`displacement_sigma`]) into the noise vector without the camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisplacementField {
    /// `d·ŷ`: the plane offset along the camera's vertical axis.
    offset_y: Vec3,
    /// `n_y`.
    normal_y: Real,
    /// `d·ŷ − n_y·s` in the plane's in-plane axes (`s` the source, the in-plane origin).
    pivot: Vec2,
}

impl DisplacementField {
    /// The field of `plane`.
    pub fn of(plane: &LaserPlane) -> Self {
        let (axis, normal_y) = stripe_axis(plane);
        let offset_y = axis * plane.offset;
        let w = offset_y - plane.source * normal_y;
        let (a, b) = plane.plane_axes();
        DisplacementField {
            offset_y,
            normal_y,
            pivot: Vec2::new(w.dot(&a), w.dot(&b)),
        }
    }

    /// Unit direction of the noise of the point `x` (camera frame), zero where undefined.
    pub fn direction(&self, x: Vec3) -> Vec3 {
        let w = self.offset_y - x * self.normal_y;
        let n = norm(&w);
        if n > 0.0 {
            w / n
        } else {
            Vec3::zeros()
        }
    }

    /// Unit direction of the noise of the in-plane point `q`
    /// ([`LaserPlane::to_plane_coords`]), in the plane's in-plane axes; zero where undefined.
    pub fn direction_in_plane(&self, q: Vec2) -> Vec2 {
        let w = self.pivot - q * self.normal_y;
        let n = norm(&w);
        if n > 0.0 {
            w / n
        } else {
            Vec2::zeros()
        }
    }
}

/// 1σ errors of the coordinates of one point (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointSigma {
    /// σ of `x`.
    pub x: Real,
    /// σ of `y`.
    pub y: Real,
    /// σ of `z`.
    pub z: Real,
}

/// σ of `x, y, z` of a point from `sigma_px` of stripe-centre noise (thesis §7.2–7.3).
pub fn point_sigma(
    plane: &LaserPlane,
    focal_px: Real,
    x: Vec3,
    sigma_px: Real,
) -> Result<PointSigma, NoiseError> {
    let g = displacement_per_pixel(plane, focal_px, x)? * sigma_px;
    Ok(PointSigma {
        x: g.x.abs(),
        y: g.y.abs(),
        z: g.z.abs(),
    })
}

/// Displacements of the triangulated point `x` when the calibration is off by 1σ in `e`,
/// `f` and `δ` (in that order; thesis §7.4): the pixel is kept, the point re-triangulated
/// with the perturbed plane (`e + σ_e` or `δ + σ_δ`, same roll) or focal length
/// (`f(1 + σ_f/f)` on both axes, principal point fixed). Exact, not linearised.
pub fn calibration_displacements(
    plane: &LaserPlane,
    focal_px: Real,
    x: Vec3,
    noise: &NoiseModel,
) -> Result<[Vec3; 3], NoiseError> {
    let (pe, pf, pd) = perturbed(plane, focal_px, noise)?;
    Ok([
        retriangulate(x, &pe, 1.0)? - x,
        retriangulate(x, plane, pf)? - x,
        retriangulate(x, &pd, 1.0)? - x,
    ])
}

/// The perturbed planes (`e + σ_e`, `δ + σ_δ`) and focal scale `1/(1 + σ_f/f)`.
pub(crate) fn perturbed(
    plane: &LaserPlane,
    focal_px: Real,
    noise: &NoiseModel,
) -> Result<(LaserPlane, Real, LaserPlane), NoiseError> {
    let (e, delta) = plane.baseline_tilt();
    let roll = plane.roll();
    if !(e.is_finite() && focal_px > 0.0) {
        return Err(NoiseError::InvalidGeometry);
    }
    let pe = LaserPlane::from_baseline_tilt_roll(e + noise.baseline, delta, roll)
        .map_err(|_| NoiseError::InvalidGeometry)?;
    let pd = LaserPlane::from_baseline_tilt_roll(e, delta + noise.tilt, roll)
        .map_err(|_| NoiseError::InvalidGeometry)?;
    Ok((pe, 1.0 / (1.0 + noise.focal_px / focal_px), pd))
}

/// The point seen at the same pixel as `x`, with normalised coordinates scaled by
/// `ray_scale` (a focal-length error), triangulated on `plane`.
pub(crate) fn retriangulate(
    x: Vec3,
    plane: &LaserPlane,
    ray_scale: Real,
) -> Result<Vec3, NoiseError> {
    if !(x.z > 0.0) {
        return Err(NoiseError::InvalidGeometry);
    }
    let r = Vec3::new(x.x / x.z * ray_scale, x.y / x.z * ray_scale, 1.0);
    plane
        .intersect_ray(r)
        .map_err(|_| NoiseError::InvalidGeometry)
}

/// Relative 1σ of a radius measured around `centre` (camera frame, on `plane`) from the
/// calibration uncertainties: the calibration errors map the plane onto itself by a smooth
/// transformation whose local scale along the two in-plane axes changes by `Δs_a`, `Δs_b`;
/// a circle's radius changes by their mean (`docs/error-model.md`, "Calibration errors").
/// Local scales by central differences over ±5 cm. Returns 0 on degenerate geometry.
pub fn calibration_relative_sigma(
    plane: &LaserPlane,
    centre: Vec3,
    noise: &NoiseModel,
    focal_px: Real,
) -> Real {
    let Ok((pe, pf, pd)) = perturbed(plane, focal_px, noise) else {
        return 0.0;
    };
    let (a, b) = plane.plane_axes();
    let h: Real = 0.05;
    let mut total = 0.0;
    for k in 0..3 {
        let map = |x: Vec3| -> Option<Vec2> {
            let (pl, s) = match k {
                0 => (&pe, 1.0),
                1 => (plane, pf),
                _ => (&pd, 1.0),
            };
            retriangulate(x, pl, s).ok().map(|y| pl.to_plane_coords(y))
        };
        let pts = [
            centre + a * h,
            centre - a * h,
            centre + b * h,
            centre - b * h,
        ];
        let mut m = [Vec2::zeros(); 4];
        for (o, p) in m.iter_mut().zip(pts) {
            match map(p) {
                Some(v) => *o = v,
                None => return 0.0,
            }
        }
        let sa = norm(&(m[0] - m[1])) / (2.0 * h) - 1.0;
        let sb = norm(&(m[2] - m[3])) / (2.0 * h) - 1.0;
        let rel = 0.5 * (sa + sb);
        total += rel * rel;
    }
    sqrt(total)
}

/// The 1σ of a fitted quantity under the calibration's errors, from its linear responses to
/// each error at its 1σ: to the focal length (`focal`, common to every plane) and to plane
/// `k`'s offset and tilt (`response(k, 0)`, `response(k, 1)`, planes `0..planes`), the
/// planes' parameters combined under `uncertainty` ([`PlanesUncertainty::spread_under`]).
/// The two-plane fits' calibration σ ((Cy-cal), (S-cal)). `None` when not finite.
pub fn calibration_spread(
    uncertainty: Option<&PlanesUncertainty>,
    focal: Real,
    planes: usize,
    response: impl Fn(usize, usize) -> Real,
) -> Option<Real> {
    let planes = planes.min(MAX_PLANES);
    let mut shifts = [0.0; PLANE_PARAMS];
    for k in 0..planes {
        shifts[2 * k] = response(k, 0);
        shifts[2 * k + 1] = response(k, 1);
    }
    let spread = PlanesUncertainty::spread_under(uncertainty, &shifts[..2 * planes]);
    let sigma = sqrt(focal * focal + spread * spread);
    sigma.is_finite().then_some(sigma)
}

/// Samples the lit and visible arc of the circle of `centre` and `radius` (in-plane
/// coordinates of `plane`, a transversal stem: axis along the plane normal) at one point per
/// image column, as a column-wise stripe extraction does: the points whose noise this module
/// describes (exact column, noisy row). Writes into `out`; returns
/// `(count, cut)` where `cut` says the arc reaches the image border (an end is not a
/// grazing ray). Uses the pinhole part of `camera` (`fx`, `cx`, width).
pub fn sample_columns(
    plane: &LaserPlane,
    camera: &Camera,
    centre: Vec2,
    radius: Real,
    out: &mut [Vec2],
) -> Result<(usize, bool), NoiseError> {
    let (a, b) = plane.plane_axes();
    let s = plane.source;
    let cam = plane.camera_centre_in_plane();
    let mut n = 0;
    let mut cut = false;
    let w = camera.width;
    for col in 0..w {
        let xn = (col as Real - camera.cx) / camera.fx;
        let m = Vec3::new(1.0, 0.0, -xn);
        let g = Vec2::new(m.dot(&a), m.dot(&b));
        let gn2 = g.norm_squared();
        if !(gn2 > 0.0) {
            continue;
        }
        let h = -m.dot(&s);
        let q0 = g * (h / gn2);
        let dir = Vec2::new(-g.y, g.x) / sqrt(gn2);
        let rel = q0 - centre;
        let bb = dir.dot(&rel);
        let cc = rel.norm_squared() - radius * radius;
        let disc = bb * bb - cc;
        if !(disc >= 0.0) {
            continue;
        }
        let sq = sqrt(disc);
        for t in [-bb - sq, -bb + sq] {
            let q = q0 + dir * t;
            let nrm = q - centre;
            let lit = nrm.dot(&q) < 0.0;
            let visible = nrm.dot(&(cam - q)) > 0.0 && plane.from_plane_coords(q).z > 0.0;
            if lit && visible {
                let slot = out.get_mut(n).ok_or(NoiseError::ScratchTooSmall)?;
                *slot = q;
                n += 1;
                if col == 0 || col + 1 == w {
                    cut = true;
                }
                break;
            }
        }
    }
    Ok((n, cut))
}

#[cfg(test)]
#[allow(clippy::unnecessary_cast)]
mod tests {
    use super::*;
    use crate::calibration::Calibration;
    use crate::camera::Camera;

    fn reference() -> (LaserPlane, Camera) {
        let cal = Calibration::reference_design();
        (cal.planes[0], cal.camera)
    }

    #[test]
    fn displacement_matches_finite_difference() {
        let (plane, cam) = reference();
        for (u, v) in [(375.5, 250.0), (100.0, 245.0), (700.0, 260.0)] {
            let (u, v): (Real, Real) = (u, v);
            let tri = |v: Real| {
                plane
                    .intersect_ray(cam.pixel_to_ray(Vec2::new(u, v)).unwrap())
                    .unwrap()
            };
            let x = tri(v);
            let g = displacement_per_pixel(&plane, cam.fy, x).unwrap();
            // Central difference with h = 0.01 px: truncation h²·X''' ~ 1e-4·|g|·(h·f_y…)
            // is ≤ 1e-6 relative; rounding ε·|X|/h. Tolerance 1e-5·|g| + 10ε|X|/h.
            let h: Real = 0.01;
            let fd = (tri(v + h) - tri(v - h)) / (2.0 * h);
            let tol = 1e-5 * g.norm() + 10.0 * Real::EPSILON * x.norm() / h;
            assert!((fd - g).norm() < tol, "{fd} {g}");
            // Thesis §7.2: σ_z = z²·σ_v/(e·f) on the optical axis (x = 0, zero roll).
            if u == 375.5 {
                let (e, _) = plane.baseline_tilt();
                let want = x.z * x.z / (e * cam.fy);
                assert!((g.z.abs() - want).abs() < 1e-4 * want);
            }
        }
    }

    /// The field's direction is that of `∂X/∂v`, in 3-D and in plane coordinates, for a
    /// plane with roll (source off the camera's vertical axis) as well as the reference one.
    #[test]
    fn displacement_field_follows_the_derivative() {
        let (reference_plane, cam) = reference();
        let rolled = LaserPlane::from_baseline_tilt_roll(0.1, 0.07, 0.2).unwrap();
        for plane in [reference_plane, rolled] {
            let field = DisplacementField::of(&plane);
            let (a, b) = plane.plane_axes();
            for (u, v) in [(375.5, 250.0), (100.0, 245.0), (700.0, 260.0)] {
                let (u, v): (Real, Real) = (u, v);
                let Ok(x) = plane.intersect_ray(cam.pixel_to_ray(Vec2::new(u, v)).unwrap()) else {
                    continue;
                };
                let g = displacement_per_pixel(&plane, cam.fy, x).unwrap();
                let want = g / g.norm();
                // Both are unit vectors from O(1) inputs: rounding only.
                assert!((field.direction(x) - want).norm() < 1e3 * Real::EPSILON);
                let in_plane = field.direction_in_plane(plane.to_plane_coords(x));
                let want2 = Vec2::new(want.dot(&a), want.dot(&b));
                assert!(
                    (in_plane - want2).norm() < 1e3 * Real::EPSILON,
                    "{in_plane} {want2}"
                );
                let s = displacement_sigma(&plane, cam.fy, x, 0.1).unwrap();
                assert!((s - 0.1 * g.norm()).abs() <= 4.0 * Real::EPSILON * s);
            }
        }
    }

    #[test]
    fn baseline_error_scales_points() {
        // e enters X = e·r/(y_n + tan δ) linearly: ΔX = X·σ_e/e exactly.
        let (plane, cam) = reference();
        let noise = NoiseModel::reference();
        let (e, _) = plane.baseline_tilt();
        let x = plane
            .intersect_ray(cam.pixel_to_ray(Vec2::new(500.0, 250.0)).unwrap())
            .unwrap();
        let d = calibration_displacements(&plane, cam.fx, x, &noise).unwrap();
        let want = x * (noise.baseline / e);
        assert!((d[0] - want).norm() < 1e-6 * want.norm() + 100.0 * Real::EPSILON * x.norm());
        let rel = calibration_relative_sigma(&plane, x, &noise, cam.fx);
        assert!(rel >= noise.baseline / e * 0.999, "{rel}");
    }
}
