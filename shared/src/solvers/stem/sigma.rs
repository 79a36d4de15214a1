//! The σ of each method of [`super::solve`] (`docs/error-model.md`, "Data-driven fit
//! uncertainty"; `docs/cylinder.md`, "Stripe fade-out"): the robust circle fit with its
//! residual sandwich and coherent-bending terms, the three-tangent variance and edge bias,
//! the elliptic reading, and the model σ of points the data does not contain.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec2, Vec3, PI};

use super::{CylinderParams, Scratch};
use crate::laser_plane::LaserPlane;
use crate::noise;
use crate::solvers::circle;
use crate::solvers::cylinder_fit::{project_along_axis, Cylinder};
use crate::solvers::ellipse::{self, EllipseFit};
use crate::solvers::three_tangent::ThreeTangent;
use crate::solvers::SolveError;

/// Angle subtended at `centre` by the points (the arc's extent, radians).
pub(super) fn arc_angle(points: &[Vec2], centre: Vec2) -> Real {
    let mut sum = Vec2::zeros();
    for q in points {
        let d = q - centre;
        let n = norm(&d);
        if n > 0.0 {
            sum += d / n;
        }
    }
    let len = norm(&sum);
    if !(len > 0.0) {
        return 2.0 * PI;
    }
    let f = sum / len;
    let s = Vec2::new(f.y, -f.x);
    let (mut lo, mut hi) = (Real::INFINITY, Real::NEG_INFINITY);
    for q in points {
        let d = q - centre;
        let a = d.dot(&s).atan2(d.dot(&f));
        lo = lo.min(a);
        hi = hi.max(a);
    }
    hi - lo
}

/// Model point noise (1σ, in-plane vector, metres) of the in-plane point `q` of `plane`: for
/// points the data does not contain (an arc's nearest tangent point); data points carry
/// their σ.
pub(super) fn noise_vector(plane: &LaserPlane, q: Vec2, params: &CylinderParams) -> Vec2 {
    let x = plane.from_plane_coords(q);
    let g =
        noise::displacement_per_pixel(plane, params.focal_px, x).unwrap_or_else(|_| Vec3::zeros());
    let (a, b) = plane.plane_axes();
    Vec2::new(g.dot(&a), g.dot(&b)) * params.noise.image_px()
}

/// Diameter and 1σ of an elliptic section (`docs/cylinder.md`, "Elliptic stems"): the mean
/// of the fitted axes `a + b`; σ² = fit σ² + (a − b)² (the unseen back may differ from the
/// front's continuation by as much as the front's own non-roundness) + calibration.
/// [`SolveError::NotRound`] when the fit does not resolve the axes (its σ on `a + b`
/// exceeds their difference `2(a − b)`: nothing distinguishes the ellipse's size from its
/// shape).
pub(super) fn elliptic_diameter(e: &EllipseFit, cal_rel: Real) -> Result<(Real, Real), SolveError> {
    let (a, b) = e.semi_axes;
    let d = a + b;
    if !(e.sigma_mean_diameter < 2.0 * (a - b)) {
        return Err(SolveError::NotRound);
    }
    let s = sqrt(e.sigma_mean_diameter.powi(2) + (a - b).powi(2) + (cal_rel * d).powi(2));
    Ok((d, s))
}

/// Share of the fit's residual RMS (in pixels of stripe position) that bends the curve
/// coherently — ends against middle (`docs/error-model.md`, "Coherent bending"). Measured
/// on simulated captures against their true curves (development seeds 5000–5039, not the
/// evaluation's): the mean row error of the outer fifths minus that of the middle reaches
/// about half the per-point RMS on dim, far stripes.
pub const BENDING_FRACTION: Real = 0.5;

/// 1σ of the fit radius from a coherent bending of the curve: every point displaced along its
/// noise vector `gᵢ` (1σ, `noise(i)` for point `i`) by `s·P₂(τ)/ḡ`, `τ ∈ [−1, 1]` its position
/// along the curve, `P₂ = (3τ² − 1)/2` (ends against middle), `ḡ` the mean `|gᵢ|`, `s` =
/// [`BENDING_FRACTION`] × the fit's residual RMS (a bend of that many RMS in units of the mean
/// point noise). Propagated through the linearised geometric fit
/// (`Δθ = A⁻¹ Σ Jᵢ (nᵢ·gᵢ) δᵢ`, `docs/error-model.md`).
pub(super) fn bending_sigma(
    fit: &circle::CircleFit,
    pts: &[Vec2],
    noise: impl Fn(usize) -> Vec2,
) -> Real {
    let n = pts.len();
    if n < 4 {
        return 0.0;
    }
    let c = fit.circle;
    let mut a = crate::real::Mat3::zeros();
    let mut b = Vec3::zeros();
    let mut sigma_sum = 0.0;
    for (i, q) in pts.iter().enumerate() {
        let d = q - c.centre;
        let len = norm(&d);
        if !(len > 0.0) {
            continue;
        }
        let nn = d / len;
        let j = Vec3::new(-nn.x, -nn.y, -1.0);
        let g = noise(i);
        sigma_sum += norm(&g);
        let tau = 2.0 * i as Real / (n - 1) as Real - 1.0;
        let p2 = 0.5 * (3.0 * tau * tau - 1.0);
        a += j * j.transpose();
        b += j * (nn.dot(&g) * p2);
    }
    let mean_sigma = sigma_sum / n as Real;
    if !(mean_sigma > 0.0) {
        return 0.0;
    }
    let s = BENDING_FRACTION * fit.rms_residual / mean_sigma;
    match a.try_inverse() {
        Some(inv) => {
            let out = ((inv * b)[2] * s).abs();
            if out.is_finite() {
                out
            } else {
                0.0
            }
        }
        None => 0.0,
    }
}

/// Radius error (1σ) of the three-tangent solution `t` due to the fade-out of its edges, judged
/// against a fitted `circle` whose radius has 1σ `sigma_fit` (`docs/cylinder.md`, "Stripe
/// fade-out"): the fit's grazing half-aperture `α_f = asin(R/|C|)` minus the three-tangent's
/// `α`, through `∂r/∂α`, in quadrature with the fit's own uncertainty on `α_f` mapped the
/// same way (`∂α_f/∂R = 1/(|C| cos α_f)`). Zero when the circle does not enclose a grazing
/// geometry (source inside it).
pub fn edge_bias_sigma(t: &ThreeTangent, circle: &circle::Circle, sigma_fit: Real) -> Real {
    let l = norm(&circle.centre);
    if !(l > circle.radius && circle.radius > 0.0) {
        return 0.0;
    }
    let alpha_f = (circle.radius / l).asin();
    let (dr_da, _) = t.partials();
    let gap = alpha_f - t.alpha;
    let s_alpha_f = sigma_fit / (l * alpha_f.cos());
    let out = dr_da * gap.hypot(s_alpha_f);
    if out.is_finite() {
        out
    } else {
        Real::INFINITY
    }
}

/// One curve of a two-plane reading projected along the fitted axis ([`projected_section`]).
pub(super) struct ProjectedSection {
    /// The section's data-driven radius σ: the one-plane terms about the cylinder's section,
    /// `data_sigma` in quadrature with the coherent bending.
    pub(super) sigma: Real,
    /// The section's information radius σ ([`RobustCircle::information`]).
    pub(super) information: Real,
    /// The cylinder's section in the projection's frame (origin at the plane's source).
    pub(super) circle: circle::Circle,
    /// The visible arc seen from the axis (radians, [`arc_angle`]).
    pub(super) arc: Real,
    /// The section's non-roundness ([`super::non_round`] against its own whole-arc fit), if
    /// it was asked for and found.
    pub(super) ellipse: Option<EllipseFit>,
}

/// Data-driven radius σ of one curve projected along the cylinder's axis onto the plane
/// perpendicular to it (origin at `plane.source`, [`project_along_axis`]; the projected lit arc
/// is an arc of the true section): the one-plane path's [`robust_circle`] terms, evaluated
/// about the cylinder's own section (`docs/cylinder.md`, "Data-driven σ of the two-plane
/// result": the fit already placed that circle with both curves, and a fit of the section
/// alone would cost as much as the cylinder's rounds to move it by less than its σ). A data
/// point's noise vector is its stored σ along its direction, projected. With `roundness`, the
/// section is also judged for non-roundness: screened against the cylinder's section, and
/// where the screen does not clear it, against its own whole-arc fit, as the one-plane path
/// judges its section. `None` when the projection or the assessment fails.
pub(super) fn projected_section(
    curve: &[Vec3],
    sigmas: &[Real],
    plane: &LaserPlane,
    cylinder: &Cylinder,
    roundness: bool,
    params: &CylinderParams,
    scratch: &mut Scratch<'_>,
) -> Option<ProjectedSection> {
    let source = plane.source;
    let projected = project_along_axis(curve, source, cylinder.axis, scratch.points).ok()?;
    let (u, e1, e2, n) = (
        projected.axis,
        projected.e1,
        projected.e2,
        projected.points.len(),
    );
    let w = cylinder.point - source;
    let section = circle::Circle {
        centre: Vec2::new(w.dot(&e1), w.dot(&e2)),
        radius: cylinder.radius,
    };
    // Back from the projection to the laser plane: `x = s + q₁e₁ + q₂e₂ + t·u` with
    // `n·(x − s) = 0` (the source lies in the plane).
    let nu = plane.normal.dot(&u);
    if !(nu.abs() > 1e-6) {
        return None;
    }
    let to_plane = |q: Vec2| {
        let w = e1 * q.x + e2 * q.y;
        source + w - u * (plane.normal.dot(&w) / nu)
    };
    let near_sigma = |q: Vec2| {
        let g = noise::displacement_per_pixel(plane, params.focal_px, to_plane(q))
            .unwrap_or_else(|_| Vec3::zeros());
        norm(&(Vec2::new(g.dot(&e1), g.dot(&e2)) * params.noise.image_px()))
    };
    let field = noise::DisplacementField::of(plane);
    let noise_of = |i: usize| {
        let g = field.direction(curve[i]) * sigmas[i];
        Vec2::new(g.dot(&e1), g.dot(&e2))
    };
    let pts = &scratch.points[..n];
    let rc = robust_circle(
        pts,
        Start::At(section),
        near_sigma,
        noise_of,
        params,
        circle::Pull::Skip,
        scratch.values,
    )?;
    let sigma = rc.data_sigma.hypot(rc.bending);
    if !sigma.is_finite() {
        return None;
    }
    let cleared = |c: &circle::Circle, cutoff: Real| {
        ellipse::ellipse_score_f(pts, c, cutoff)
            .is_ok_and(|f| f < super::ELLIPTIC_SCREEN * params.elliptic_min_f)
    };
    let ellipse = if roundness && !cleared(&section, rc.cutoff) {
        robust_circle(
            pts,
            Start::Fit,
            near_sigma,
            noise_of,
            params,
            circle::Pull::Skip,
            scratch.values,
        )
        .and_then(|own| super::non_round(pts, &own.fit, own.cutoff, params))
    } else {
        None
    };
    Some(ProjectedSection {
        sigma,
        information: rc.information,
        circle: section,
        arc: arc_angle(pts, section.centre),
        ellipse,
    })
}

/// The whole-arc circle fit with its data-driven σ terms (`docs/error-model.md`, "Data-driven fit
/// uncertainty"), as the one-plane and the projected two-plane results both use.
pub(super) struct RobustCircle {
    /// The robust fit (Hyper start, Tukey weights).
    pub(super) fit: circle::CircleFit,
    /// Model σ of the initial circle's point nearest the source: the robust scale's floor.
    pub(super) near_sigma: Real,
    /// Residual beyond which a point is the fit's outlier.
    pub(super) cutoff: Real,
    /// Radius σ of the whole-arc fit ([`circle::WeightedFit::sigma_radius`]): the points'
    /// own σ, inflated by the reduced χ² and the residuals' correlation length.
    pub(super) data_sigma: Real,
    /// Radius σ from a coherent bending of the curve ([`bending_sigma`]).
    pub(super) bending: Real,
    /// Radius σ the points' own scatter and its correlation along the stripe allow (the
    /// sandwich σ × `√L`: no floor at the model σ, no bending; `docs/error-model.md` §6,
    /// "The single-exposure bound").
    pub(super) information: Real,
    /// Expected bias of the fit's radius from the noise along the line of sight
    /// ([`circle::WeightedFit::radius_pull`]; 0 with [`circle::Pull::Skip`]).
    pub(super) pull: Real,
}

/// Where [`robust_circle`] takes its circle.
pub(super) enum Start {
    /// The whole-arc fit from [`start_circle`].
    Fit,
    /// This circle, assessed without a fit of its own ([`circle::weighted_at`]).
    At(circle::Circle),
}

/// [`RobustCircle`] of `pts`: with [`Start::Fit`] the robust whole-arc fit from the Hyper start
/// ([`start_circle`]), with [`Start::At`] its terms about a given circle without a fit; the
/// scale floor `near_sigma` of the start's point nearest the source (origin), the residual
/// sandwich and the bending term with the points' noise vectors `noise(i)`; the radius's pull
/// only when `pull` asks for it (and a fit ran). `None` when a fit fails or the start circle is
/// centred on the source.
pub(super) fn robust_circle(
    pts: &[Vec2],
    start: Start,
    near_sigma: impl Fn(Vec2) -> Real,
    noise: impl Fn(usize) -> Vec2,
    params: &CylinderParams,
    pull: circle::Pull,
    values: &mut [Real],
) -> Option<RobustCircle> {
    let init = match start {
        Start::Fit => start_circle(pts)?,
        Start::At(c) => c,
    };
    let cn = norm(&init.centre);
    if !(cn > 0.0) {
        return None;
    }
    let near = init.centre - init.centre / cn * init.radius;
    let s_point = near_sigma(near);
    let mut rp = params.robust;
    rp.min_scale = rp.min_scale.max(s_point);
    // Whole-arc fit (docs/cylinder.md, "Whole-arc fit"): every point with its own σ along
    // its noise direction, none trimmed but real outliers.
    let wf = match start {
        Start::Fit => circle::fit_weighted(pts, &noise, init, &rp, pull, values),
        Start::At(c) => circle::weighted_at(pts, &noise, c, &rp, values),
    }
    .ok()?;
    let fit = wf.fit;
    let cutoff = rp.tuning * fit.rms_residual.max(rp.min_scale);
    let bending = bending_sigma(&fit, pts, noise);
    let data_sigma = wf.sigma_radius;
    Some(RobustCircle {
        fit,
        near_sigma: s_point,
        cutoff,
        data_sigma,
        bending,
        information: wf.sandwich_sigma_radius * sqrt(wf.correlation_length.max(1.0)),
        pull: wf.radius_pull,
    })
}

/// Start of the robust fit: the Hyper circle when its centre lies beyond the arc's middle
/// point as seen from the source (origin): every point a stem shows the source satisfies
/// `|p| < |C|`, the middle one by the radius. Otherwise (a short, noisy arc whose outlying end
/// points tip the algebraic fit to the concave side, report seed 7 000 124) the circle
/// through the middle point with half the chord for radius, centred beyond it on its line of
/// sight (`docs/cylinder.md`, "Whole-arc fit"): from the concave side the fit runs away to a
/// line; from any start beyond the arc it converges to the same circle. `None` when the
/// Hyper fit fails.
fn start_circle(pts: &[Vec2]) -> Option<circle::Circle> {
    let hyper = circle::fit_hyper(pts).ok()?;
    let mid = *pts.get(pts.len() / 2)?;
    let d_mid = norm(&mid);
    if norm(&hyper.centre) > d_mid {
        return Some(hyper);
    }
    let (first, last) = (pts.first()?, pts.last()?);
    let radius = 0.5 * norm(&(last - first));
    if !(radius > 0.0 && d_mid > 0.0) {
        return None;
    }
    Some(circle::Circle {
        centre: mid + mid / d_mid * radius,
        radius,
    })
}

/// Random variance of a three-tangent radius (`docs/cylinder.md`, "Sensitivity"): `α` from
/// the two grazing-ray columns (`edge_px` each, so `σ_α = σ_edge/√2`) and `D` from the window
/// parabola with the point noise the larger of `point_sigma` (the model's, along the
/// bisector) and the window's own RMS.
pub(super) fn three_tangent_variance(
    t: &ThreeTangent,
    point_sigma: Real,
    params: &CylinderParams,
) -> Real {
    let (dr_da, dr_dd) = t.partials();
    let s_alpha = params.noise.edge_angle_sigma(params.focal_px) / sqrt(2.0);
    let s_d = sqrt(t.nearest_variance_factor) * point_sigma.max(t.window_rms);
    (dr_da * s_alpha).powi(2) + (dr_dd * s_d).powi(2)
}

/// Model σ of one point (metres, along the viewing direction) at in-plane distance
/// `distance` straight ahead of the source.
pub(super) fn one_point_sigma(plane: &LaserPlane, params: &CylinderParams, distance: Real) -> Real {
    norm(&noise_vector(
        plane,
        Vec2::new(0.0, distance.max(0.0)),
        params,
    ))
}
