//! The three-tangent construction for a sphere (`docs/sphere.md`, "Three-tangent sections";
//! thesis §10.4): in each laser plane, the two rays from the source that graze the section and
//! the tangent at its point nearest the source fix the section circle
//! ([`super::three_tangent::three_tangent`], the stem's construction); the sections then give
//! the sphere through [`super::sphere_sections::sphere_from_sections`].
//!
//! The section's covariance follows from the three measured quantities — the half-aperture
//! `α`, the bisector's direction `β` (each from the two grazing angles, `σ_edge/√2`) and the
//! nearest distance `D` (its parabola fit) — through `r = D·sin α/(1 − sin α)` and
//! `c = (D + r)·(cos β, sin β)`.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{Mat3, Real, Vec2, Vec3, PI};

use super::sphere_sections::Section;
use super::three_tangent::{three_tangent, ThreeTangent, ThreeTangentParams};
use super::SolveError;
use crate::laser_plane::LaserPlane;

/// The three-tangent section of one plane's curve (3-D points in curve order; `flat`, at
/// least as long, receives their in-plane coordinates). `edge_sigma` is the 1σ of each
/// grazing ray's angle (radians; half a column over the focal length for column-wise
/// extraction).
///
/// Errors: those of [`three_tangent`]; [`SolveError::Degenerate`] for a section covariance
/// that is not finite.
pub fn three_tangent_section(
    plane: &LaserPlane,
    points: &[Vec3],
    params: &ThreeTangentParams,
    edge_sigma: Real,
    flat: &mut [Vec2],
) -> Result<(Section, ThreeTangent), SolveError> {
    let flat = flat
        .get_mut(..points.len())
        .ok_or(SolveError::ScratchTooSmall)?;
    for (q, p) in flat.iter_mut().zip(points) {
        *q = plane.to_plane_coords(*p);
    }
    let tt = three_tangent(flat, params)?;
    let covariance = section_covariance(&tt, edge_sigma);
    if !covariance.iter().all(|v| v.is_finite()) {
        return Err(SolveError::Degenerate);
    }
    let (a, b) = plane.plane_axes();
    Ok((
        Section {
            origin: plane.source,
            axes: (a, b, plane.normal),
            centre: tt.centre,
            radius: tt.radius,
            covariance,
            // The lit arc between the two tangent points, seen from the centre.
            arc: PI - 2.0 * tt.alpha,
        },
        tt,
    ))
}

/// Covariance of `(x, y, r)` of a three-tangent section (module documentation):
/// `J·diag(σ_α², σ_β², σ_D²)·Jᵀ` with `σ_α = σ_β = σ_edge/√2` and `σ_D² = factor·rms²` of
/// the nearest-point fit.
pub fn section_covariance(tt: &ThreeTangent, edge_sigma: Real) -> Mat3 {
    let (dr_dalpha, dr_dd) = tt.partials();
    let u = tt.bisector;
    let across = Vec2::new(-u.y, u.x);
    let reach = tt.nearest_distance + tt.radius;
    // Columns: ∂/∂α, ∂/∂β, ∂/∂D of (x, y, r).
    let j = Mat3::new(
        dr_dalpha * u.x,
        reach * across.x,
        (1.0 + dr_dd) * u.x,
        dr_dalpha * u.y,
        reach * across.y,
        (1.0 + dr_dd) * u.y,
        dr_dalpha,
        0.0,
        dr_dd,
    );
    let var_angle = 0.5 * edge_sigma * edge_sigma;
    let var_d = (tt.nearest_variance_factor * tt.window_rms * tt.window_rms).max(0.0);
    let d = Mat3::from_diagonal(&Vec3::new(var_angle, var_angle, var_d));
    let cov = j * d * j.transpose();
    // A floor on each diagonal keeps the matrix invertible when one variance vanishes
    // (exact data): 1e-12 m² is (1 µm)².
    cov + Mat3::identity() * 1e-12
}
