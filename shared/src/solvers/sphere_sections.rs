//! A sphere from its planar sections (`docs/sphere.md`, "Sphere from sections"): each laser
//! plane cuts the sphere in a circle (centre `cᵢ`, radius `rᵢ` in the plane); the sphere's
//! centre `C` projects onto every plane at `cᵢ` and lies `hᵢ = (C − cᵢ)·nᵢ` off it, and
//! `R² = rᵢ² + hᵢ²`. Two sections (four unknowns `C, R`, six equations) determine the sphere
//! and test it; one leaves `R` unobservable.
//!
//! The sections themselves come from a circle fit ([`circle_section`], reusing
//! [`super::circle`]) or the three-tangent construction ([`super::sphere_three_tangent`]);
//! [`sphere_from_sections`] combines any of them by a covariance-weighted least-squares fit
//! of `(C, R)` through the shared LM ([`super::lm`]).

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Mat3, Real, Vec2, Vec3};

use nalgebra::{SMatrix, SVector};

use super::circle::{fit_hyper, fit_robust, CircleFit, RobustParams};
use super::correlation::correlation_length;
use super::lm::{minimise, spd_inverse, Evaluated, LeastSquares, LmParams, NormalEquations};
use super::SolveError;
use crate::laser_plane::LaserPlane;

/// Smallest point noise a section's covariance assumes (metres).
const MIN_NOISE: Real = 1e-6;

/// A sphere: centre (camera frame) and radius, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Centre.
    pub centre: Vec3,
    /// Radius (positive).
    pub radius: Real,
}

impl Sphere {
    /// The least-squares parameters `(Cx, Cy, Cz, R)`.
    pub fn params(&self) -> SVector<Real, 4> {
        SVector::<Real, 4>::new(self.centre.x, self.centre.y, self.centre.z, self.radius)
    }

    /// The sphere of least-squares parameters `(Cx, Cy, Cz, R)`.
    pub fn of_params(p: &SVector<Real, 4>) -> Sphere {
        Sphere {
            centre: Vec3::new(p[0], p[1], p[2]),
            radius: p[3],
        }
    }
}

/// A weighted least-squares cost in a sphere's `(C, R)`: the one shape of both sphere fits
/// (the sections' and the joint one), minimised by [`minimise_sphere`].
pub(crate) trait SphereCost {
    /// `JᵀWJ`, `JᵀWr` and `Σ rᵀWr` at `sphere`; an error outside the cost's domain.
    fn normal_equations(&self, sphere: &Sphere) -> Result<NormalEquations<4>, SolveError>;
}

/// A [`SphereCost`] as the shared LM's problem: a flat parameter space, additive steps.
struct SphereProblem<'c, C>(&'c C);

impl<C: SphereCost> LeastSquares<4> for SphereProblem<'_, C> {
    type Params = SVector<Real, 4>;
    type Extra = ();

    fn evaluate(&self, p: &Self::Params) -> Result<(NormalEquations<4>, ()), SolveError> {
        Ok((self.0.normal_equations(&Sphere::of_params(p))?, ()))
    }

    fn step(&self, p: &Self::Params, delta: &SVector<Real, 4>) -> Self::Params {
        p + delta
    }

    fn step_scale(&self, p: &Self::Params) -> Real {
        1.0 + p.norm()
    }
}

/// Minimises `cost` from `start` with the shared LM: the sphere and the normal equations
/// there.
pub(crate) fn minimise_sphere<C: SphereCost>(
    cost: &C,
    start: Sphere,
    lm: &LmParams,
) -> Result<(Sphere, NormalEquations<4>), SolveError> {
    let problem = SphereProblem(cost);
    let (min, _) = minimise(&problem, Evaluated::at(&problem, start.params())?, lm)?;
    Ok((Sphere::of_params(&min.params), min.normal))
}

/// One planar section of the sphere: a circle in a laser plane, with the covariance of its
/// in-plane centre and radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Section {
    /// A point of the plane (the laser source): origin of the in-plane coordinates.
    pub origin: Vec3,
    /// In-plane unit axes `(a, b)` ([`LaserPlane::plane_axes`]) and the unit normal `n`.
    pub axes: (Vec3, Vec3, Vec3),
    /// The circle's centre in the plane's coordinates `(x, y)` along `(a, b)` (metres).
    pub centre: Vec2,
    /// The circle's radius (metres).
    pub radius: Real,
    /// Covariance of `(x, y, r)` (m²).
    pub covariance: Mat3,
    /// Angle the measured arc spans seen from the circle's centre (radians).
    pub arc: Real,
}

impl Section {
    /// The circle's centre in the camera frame.
    pub fn centre_3d(&self) -> Vec3 {
        self.origin + self.axes.0 * self.centre.x + self.axes.1 * self.centre.y
    }
}

/// The sphere of a set of sections with what the fit says about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereEstimate {
    /// The sphere.
    pub sphere: Sphere,
    /// Covariance of `(Cx, Cy, Cz, R)` (m²), from the sections' covariances.
    pub covariance: SMatrix<Real, 4, 4>,
    /// The weighted sum of squared residuals at the solution: `χ²` with
    /// [`SphereEstimate::dof`] degrees of freedom when the object is a sphere.
    pub chi2: Real,
    /// Degrees of freedom of [`SphereEstimate::chi2`]: `3k − 4` for `k` sections.
    pub dof: usize,
}

impl SphereEstimate {
    /// 1σ of the radius (metres).
    pub fn sigma_radius(&self) -> Real {
        sqrt(self.covariance[(3, 3)].max(0.0))
    }
}

/// The circle section of one plane's curve: a robust geometric circle fit
/// ([`fit_robust`] from [`fit_hyper`]) of the in-plane points, its covariance from the
/// residuals' own scale, inflated by their correlation length along the curve
/// (`docs/sphere.md`, "Section covariance").
///
/// `points` are the plane's 3-D points in curve order; `flat` (≥ their count) receives their
/// in-plane coordinates and `scratch` (same length) the robust fit's residuals. Returns the
/// section and the fit (for its inlier count and residuals).
pub fn circle_section(
    plane: &LaserPlane,
    points: &[Vec3],
    robust: &RobustParams,
    flat: &mut [Vec2],
    scratch: &mut [Real],
) -> Result<(Section, CircleFit), SolveError> {
    let flat = flat
        .get_mut(..points.len())
        .ok_or(SolveError::ScratchTooSmall)?;
    for (q, p) in flat.iter_mut().zip(points) {
        *q = plane.to_plane_coords(*p);
    }
    let start = fit_hyper(flat)?;
    let fit = fit_robust(flat, start, robust, scratch)?;
    let c = fit.circle;
    let cutoff = robust.tuning * fit.rms_residual.max(robust.min_scale);
    let inflation = correlation_length(inlier_residuals(flat, &c, cutoff, scratch));
    // The residuals' own scale (the point noise model overstates the noise normal to the
    // surface, `docs/sphere.md`), floored at 1 µm so that exact data keep an invertible
    // covariance.
    let floor = if fit.rms_residual > 0.0 {
        (MIN_NOISE / fit.rms_residual).powi(2).max(1.0)
    } else {
        return Err(SolveError::Degenerate);
    };
    let arc = arc_angle(flat, c.centre, |q| {
        (norm(&(q - c.centre)) - c.radius).abs() <= cutoff
    });
    let (a, b) = plane.plane_axes();
    Ok((
        Section {
            origin: plane.source,
            axes: (a, b, plane.normal),
            centre: c.centre,
            radius: c.radius,
            covariance: fit.covariance * (inflation * floor),
            arc,
        },
        fit,
    ))
}

/// The residuals `|q − c| − r` of the points within `cutoff` of the circle, in curve order,
/// written to the front of `buf` (as long as `points`).
fn inlier_residuals<'b>(
    points: &[Vec2],
    circle: &super::circle::Circle,
    cutoff: Real,
    buf: &'b mut [Real],
) -> &'b [Real] {
    let mut n = 0;
    for (q, slot) in points
        .iter()
        .map(|q| norm(&(q - circle.centre)) - circle.radius)
        .filter(|d| d.abs() <= cutoff)
        .zip(buf.iter_mut())
    {
        *slot = q;
        n += 1;
    }
    &buf[..n]
}

/// Angle spanned by the points `keep` accepts, seen from `centre`: the range of their polar
/// angle unwrapped along the curve (at most 2π).
pub fn arc_angle(points: &[Vec2], centre: Vec2, keep: impl Fn(Vec2) -> bool) -> Real {
    // Points come in curve order: accumulate the unwrapped polar angle and take its range.
    let (mut lo, mut hi, mut acc) = (0.0 as Real, 0.0 as Real, 0.0 as Real);
    let mut previous: Option<Real> = None;
    for q in points.iter().copied().filter(|q| keep(*q)) {
        let d = q - centre;
        let angle = d.y.atan2(d.x);
        if let Some(prev) = previous {
            let mut step = angle - prev;
            while step > crate::real::PI {
                step -= 2.0 * crate::real::PI;
            }
            while step < -crate::real::PI {
                step += 2.0 * crate::real::PI;
            }
            acc += step;
            lo = lo.min(acc);
            hi = hi.max(acc);
        }
        previous = Some(angle);
    }
    (hi - lo).min(2.0 * crate::real::PI)
}

/// A first sphere from two or more sections (`docs/sphere.md`, "Starting point"): along the
/// mean normal `n̄`, the centre's position `s` solves `r₁² + (s − d₁)² = r₂² + (s − d₂)²`
/// for the two sections farthest apart (`dᵢ = cᵢ·n̄`); across it, the mean of the section
/// centres. [`SolveError::PlaneCount`] for fewer than two sections,
/// [`SolveError::Degenerate`] when they lie in one plane.
pub fn initial_sphere(sections: &[Section]) -> Result<Sphere, SolveError> {
    if sections.len() < 2 {
        return Err(SolveError::PlaneCount);
    }
    let mut n_mean = Vec3::zeros();
    for s in sections {
        let n = s.axes.2;
        n_mean += if n.dot(&sections[0].axes.2) < 0.0 {
            -n
        } else {
            n
        };
    }
    let len = norm(&n_mean);
    if !(len > 0.0) {
        return Err(SolveError::Degenerate);
    }
    let n = n_mean / len;
    let along = |s: &Section| s.centre_3d().dot(&n);
    let (mut lo, mut hi) = (0usize, 0usize);
    for (i, s) in sections.iter().enumerate() {
        if along(s) < along(&sections[lo]) {
            lo = i;
        }
        if along(s) > along(&sections[hi]) {
            hi = i;
        }
    }
    let (s1, s2) = (&sections[lo], &sections[hi]);
    let (d1, d2) = (along(s1), along(s2));
    let span = d2 - d1;
    let size = s1.radius.max(s2.radius);
    if !(span > 1e-6 * size.max(1e-3)) {
        return Err(SolveError::Degenerate);
    }
    let s = (s2.radius * s2.radius - s1.radius * s1.radius + d2 * d2 - d1 * d1) / (2.0 * span);
    let mut across = Vec3::zeros();
    for sec in sections {
        let c = sec.centre_3d();
        across += c - n * c.dot(&n);
    }
    let centre = across / sections.len() as Real + n * s;
    // The largest `√(rᵢ² + hᵢ²)`: inside the domain `R > |hᵢ|` of every section's residual.
    let mut radius: Real = 0.0;
    for sec in sections {
        let h = (centre - sec.centre_3d()).dot(&sec.axes.2);
        radius = radius.max(sqrt(sec.radius * sec.radius + h * h));
    }
    if !(radius.is_finite() && centre.iter().all(|v| v.is_finite()) && radius > 0.0) {
        return Err(SolveError::NonFinite);
    }
    Ok(Sphere { centre, radius })
}

/// The least-squares problem of [`sphere_from_sections`]: per section the residual
/// `eᵢ = (xᵢ(C) − xᵢ, yᵢ(C) − yᵢ, √(R² − hᵢ²) − rᵢ)` weighted by the inverse of the
/// section's covariance.
struct FromSections<'a> {
    sections: &'a [Section],
    weights: [Mat3; crate::calibration::MAX_PLANES],
}

impl SphereCost for FromSections<'_> {
    fn normal_equations(&self, sphere: &Sphere) -> Result<NormalEquations<4>, SolveError> {
        let (centre, radius) = (sphere.centre, sphere.radius);
        let mut jtj = SMatrix::<Real, 4, 4>::zeros();
        let mut jtr = SVector::<Real, 4>::zeros();
        let mut cost = 0.0;
        for (s, w) in self.sections.iter().zip(self.weights.iter()) {
            let (a, b, n) = s.axes;
            let rel = centre - s.origin;
            let h = rel.dot(&n);
            let q2 = radius * radius - h * h;
            if !(q2 > 0.0 && radius > 0.0) {
                return Err(SolveError::Degenerate);
            }
            let q = sqrt(q2);
            let e = Vec3::new(
                rel.dot(&a) - s.centre.x,
                rel.dot(&b) - s.centre.y,
                q - s.radius,
            );
            let mut j = SMatrix::<Real, 3, 4>::zeros();
            for k in 0..3 {
                j[(0, k)] = a[k];
                j[(1, k)] = b[k];
                j[(2, k)] = -h * n[k] / q;
            }
            j[(2, 3)] = radius / q;
            let jt_w = j.transpose() * w;
            jtj += jt_w * j;
            jtr += jt_w * e;
            cost += e.dot(&(w * e));
        }
        if !cost.is_finite() {
            return Err(SolveError::NonFinite);
        }
        Ok(NormalEquations { jtj, jtr, cost })
    }
}

/// The sphere of two or more sections: the covariance-weighted least-squares `(C, R)` of
/// [`FromSections`], started at [`initial_sphere`] (`docs/sphere.md`, "Sphere from
/// sections"). Its covariance is `(JᵀWJ)⁻¹` and its `χ²` tests whether the sections lie on
/// one sphere.
///
/// Errors: fewer than two sections or more than `MAX_PLANES` ([`SolveError::PlaneCount`]),
/// coplanar sections or a singular section covariance ([`SolveError::Degenerate`]), no
/// convergence.
pub fn sphere_from_sections(
    sections: &[Section],
    lm: &LmParams,
) -> Result<SphereEstimate, SolveError> {
    if sections.len() < 2 || sections.len() > crate::calibration::MAX_PLANES {
        return Err(SolveError::PlaneCount);
    }
    lm.validate()?;
    let mut weights = [Mat3::zeros(); crate::calibration::MAX_PLANES];
    for (w, s) in weights.iter_mut().zip(sections) {
        *w = s.covariance.try_inverse().ok_or(SolveError::Degenerate)?;
        if !w.iter().all(|v| v.is_finite()) {
            return Err(SolveError::NonFinite);
        }
    }
    let first = initial_sphere(sections)?;
    let (sphere, normal) = minimise_sphere(&FromSections { sections, weights }, first, lm)?;
    let covariance = spd_inverse(&normal.jtj).ok_or(SolveError::Degenerate)?;
    Ok(SphereEstimate {
        sphere,
        covariance,
        chi2: normal.cost,
        dof: 3 * sections.len() - 4,
    })
}
