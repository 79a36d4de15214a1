//! The sphere's diameter from one capture (thesis chapter 10, `docs/sphere.md`): the three
//! methods on the curves of two or more laser planes, their uncertainties, the choice of the
//! reported diameter and the flags.
//!
//! * sections ([`super::sphere_sections`]): a robust circle fit per plane, the sphere through
//!   `R² = rᵢ² + hᵢ²` — the naive construction, and the start of the others;
//! * three-tangent ([`super::sphere_three_tangent`]): the section circles from the grazing
//!   rays and the nearest tangent (§10.4);
//! * joint fit ([`super::sphere_fit`]): the sphere fitted to every point at once, weighted by
//!   each point's σ (§10.5) — reported when it converges, because it uses every point once
//!   with its own noise (`docs/accuracy.md`, "Spheres").
//!
//! Refusals ([`SolveError`]): one section only ([`SolveError::OneSection`]: `R` is not
//! observable), round sections that do not share a centre and whose points no one sphere
//! fits ([`SolveError::TwoObjects`]),
//! sections that cannot belong to one sphere ([`SolveError::NotSpherical`]: a flat or
//! elongated object), a radius outside the plausible range. Flags: a short
//! arc, a section near a pole, a sphere test that fails ([`Flags::NOT_SPHERICAL`]), sections
//! off the axis that the joint fit overrules ([`Flags::INCONSISTENT`]), stray points.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec2, Vec3, PI};

use super::circle::RobustParams;
use super::ellipse;
use super::lm::LmParams;
use super::result::{Flags, Method};
use super::sphere_fit::{calibration_sigma_radius, fit_sphere, SphereFit, SphereFitParams};
use super::sphere_sections::{
    circle_section, initial_sphere, sphere_from_sections, Section, Sphere, SphereEstimate,
};
use super::sphere_three_tangent::three_tangent_section;
use super::three_tangent::ThreeTangentParams;
use super::SolveError;
use crate::calibration::{PlanesUncertainty, MAX_PLANES};
use crate::laser_plane::LaserPlane;
use crate::noise::{self, NoiseModel};

/// Settings of the sphere solver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereParams {
    /// Smallest plausible radius (metres).
    pub min_radius: Real,
    /// Largest plausible radius (metres).
    pub max_radius: Real,
    /// Working range of the centre's distance from the camera (metres), min and max.
    pub range: (Real, Real),
    /// Fewest points of a plane's curve for it to count as a section.
    pub min_points: usize,
    /// Arc angle (radians, seen from the section's centre) below which
    /// [`Flags::ARC_TOO_SHORT`] is set.
    pub min_arc_angle: Real,
    /// Smallest section radius relative to the sphere's, `rᵢ/R`, before [`Flags::NEAR_POLE`]
    /// (0.35: within 20° of a pole, where `R` rests on `hᵢ` alone).
    pub pole_ratio: Real,
    /// Sphere test: `χ²` of the sections' fit above which [`Flags::NOT_SPHERICAL`] is set
    /// (per degree of freedom; `docs/sphere.md`, "Is it a sphere?").
    pub not_spherical_chi2: Real,
    /// Sphere test: the ellipse score F of a section above which its ellipse is fitted, and
    /// the relative axis difference above which the section is not round.
    pub not_round: (Real, Real),
    /// Refusal: the sections' centres miss the sphere's axis by more than this fraction of
    /// `R` and no one sphere fits every line's points ([`SolveError::TwoObjects`] when every
    /// section is a round arc, else [`SolveError::NotSpherical`]).
    pub max_misalignment: Real,
    /// Fraction of rejected points above which [`Flags::SEVERAL_OBJECTS`] is set.
    pub max_outlier_fraction: Real,
    /// Three-tangent settings.
    pub three_tangent: ThreeTangentParams,
    /// Robust circle fit settings (its `min_scale` is raised to the points' median σ).
    pub robust: RobustParams,
    /// Joint fit settings.
    pub fit: SphereFitParams,
    /// The sections' fit settings.
    pub lm: LmParams,
    /// Image and calibration noise.
    pub noise: NoiseModel,
    /// Focal length (pixels), for the noise model and the grazing rays' σ.
    pub focal_px: Real,
}

impl Default for SphereParams {
    /// Radii 5 mm – 0.5 m, centres 0.2–3 m away, arcs of 60°, [`NoiseModel::reference`],
    /// f = 1000 px.
    fn default() -> Self {
        SphereParams {
            min_radius: 0.005,
            max_radius: 0.5,
            range: (0.2, 3.0),
            min_points: 8,
            min_arc_angle: 60.0 * PI / 180.0,
            pole_ratio: 0.35,
            not_spherical_chi2: 25.0,
            not_round: (30.0, 0.04),
            max_misalignment: 0.25,
            max_outlier_fraction: 0.3,
            three_tangent: ThreeTangentParams::default(),
            robust: RobustParams::default(),
            fit: SphereFitParams::default(),
            lm: LmParams::default(),
            noise: NoiseModel::reference(),
            focal_px: 1000.0,
        }
    }
}

/// The sphere solver's input: per plane, its curve's 3-D points (camera frame, curve
/// order) with their 1σ, and the plane.
#[derive(Debug, Clone, Copy)]
pub struct SphereInput<'a> {
    /// Each plane's points.
    pub curves: &'a [&'a [Vec3]],
    /// Each point's 1σ (metres), same shape as `curves`.
    pub sigmas: &'a [&'a [Real]],
    /// The laser planes, in the order of `curves`.
    pub planes: &'a [LaserPlane],
    /// The planes' `(e, δ)` covariance when they were refined on a reference
    /// ([`crate::calibration::Calibration::uncertainty`]); `None`: independent, each with
    /// the noise model's budget.
    pub uncertainty: Option<&'a PlanesUncertainty>,
}

/// Memory the solver is lent, each at least as long as all points together.
#[derive(Debug)]
pub struct Scratch<'a> {
    /// In-plane points.
    pub points: &'a mut [Vec2],
    /// Residuals (medians of the robust fits).
    pub values: &'a mut [Real],
}

/// One method's diameter and its 1σ (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Diameter.
    pub diameter: Real,
    /// 1σ of the diameter.
    pub sigma: Real,
    /// Centre of the sphere (camera frame, metres).
    pub centre: Vec3,
}

/// The sphere of one capture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereSolution {
    /// The reported diameter (metres).
    pub diameter: Real,
    /// Its 1σ (metres): the method's random part and the calibration's.
    pub uncertainty: Real,
    /// The random part of `uncertainty` alone (metres): what a simulation with a perfect
    /// calibration can check.
    pub random_uncertainty: Real,
    /// The reported centre (camera frame, metres).
    pub centre: Vec3,
    /// Distance of the centre from the camera (metres).
    pub distance: Real,
    /// The method reported.
    pub method: Method,
    /// Quality flags.
    pub flags: Flags,
    /// Each method's answer, when it had one: sections, three-tangent, joint fit.
    pub sections: Option<Estimate>,
    /// The three-tangent construction's answer.
    pub three_tangent: Option<Estimate>,
    /// The joint fit's answer.
    pub joint_fit: Option<Estimate>,
    /// `χ²/dof` of the circle sections against one sphere (the sphere test).
    pub sections_chi2: Real,
    /// Each plane's section radius (metres; 0 beyond the planes given).
    pub section_radii: [Real; MAX_PLANES],
    /// Number of sections used.
    pub section_count: usize,
}

fn estimate_of(e: &SphereEstimate) -> Estimate {
    Estimate {
        diameter: 2.0 * e.sphere.radius,
        sigma: 2.0 * e.sigma_radius(),
        centre: e.sphere.centre,
    }
}

/// A section whose arc spans less than this share of [`SphereParams::min_arc_angle`] (20°
/// of the default 60°) is straight for the two-objects test: a flat surface's "circle".
const STRAIGHT_ARC_SHARE: Real = 1.0 / 3.0;

/// Median of the positive values of `v` (reorders it); 0 when none.
fn median(v: &mut [Real]) -> Real {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    *m
}

/// Solves the sphere of one capture (module documentation).
pub fn solve(
    input: &SphereInput<'_>,
    params: &SphereParams,
    scratch: Scratch<'_>,
) -> Result<SphereSolution, SolveError> {
    let n = input.curves.len().min(input.planes.len()).min(MAX_PLANES);
    if input.sigmas.len() < n {
        return Err(SolveError::InvalidParameter);
    }
    let usable = (0..n)
        .filter(|&k| input.curves[k].len() >= params.min_points)
        .count();
    if usable < 2 {
        return Err(SolveError::OneSection);
    }
    let total: usize = input.curves[..n].iter().map(|c| c.len()).sum();
    let (Some(flat_all), Some(values_all)) = (
        scratch.points.get_mut(..total),
        scratch.values.get_mut(..total),
    ) else {
        return Err(SolveError::ScratchTooSmall);
    };
    let mut flags = Flags::default();
    // Every section is a round arc (no ellipse, not straight): with disjoint sections, what
    // tells two objects from one object that is not a ball when the sections disagree.
    let mut round_arcs = true;

    // Circle sections (the naive method and the start of the others).
    let mut circles = [None::<Section>; MAX_PLANES];
    let mut section_radii = [0.0; MAX_PLANES];
    let (mut kept, mut given) = (0usize, 0usize);
    let mut offset = 0;
    for k in 0..n {
        let curve = input.curves[k];
        let len = curve.len();
        let flat = &mut flat_all[offset..offset + len];
        let values = &mut values_all[offset..offset + len];
        offset += len;
        if len < params.min_points {
            continue;
        }
        values.copy_from_slice(&input.sigmas[k][..len]);
        let mut robust = params.robust;
        robust.min_scale = robust.min_scale.max(median(values));
        match circle_section(&input.planes[k], curve, &robust, flat, values) {
            Ok((section, fit)) => {
                kept += fit.inliers;
                given += len;
                section_radii[k] = section.radius;
                let cutoff = robust.tuning * fit.rms_residual.max(robust.min_scale);
                if not_round(flat, &fit.circle, cutoff, params) {
                    flags.insert(Flags::NOT_SPHERICAL);
                    round_arcs = false;
                }
                if section.arc < params.min_arc_angle * STRAIGHT_ARC_SHARE {
                    round_arcs = false;
                }
                if section.arc < params.min_arc_angle {
                    flags.insert(Flags::ARC_TOO_SHORT);
                }
                circles[k] = Some(section);
            }
            Err(_) => flags.insert(Flags::FIT_FAILED),
        }
    }
    if given > 0 && (given - kept) as Real > params.max_outlier_fraction * given as Real {
        flags.insert(Flags::SEVERAL_OBJECTS);
    }
    let (list, count) = compact(&circles);
    let sections_fit = if count >= 2 {
        sphere_from_sections(&list[..count], &params.lm).ok()
    } else {
        None
    };
    let mut sections_chi2 = 0.0;
    if let Some(e) = &sections_fit {
        sections_chi2 = e.chi2 / e.dof.max(1) as Real;
        if sections_chi2 > params.not_spherical_chi2 {
            flags.insert(Flags::NOT_SPHERICAL);
        }
    }
    // The joint fit (§10.5) from a starting sphere; the residuals' scratch is `values_all`.
    let mut joint_fit_from = |start: Sphere| {
        fit_sphere(
            &input.curves[..n],
            &input.sigmas[..n],
            &input.planes[..n],
            start,
            &params.fit,
            &mut *values_all,
        )
        .ok()
    };
    // The geometric refusal: the sections' centres must lie on one axis (checked at the
    // fitted sphere, or at the starting one when the fit found none). A short section near a
    // pole can miss the axis through its circle's bias alone while its points lie on the
    // ball: one sphere fitted to every point then keeps each curve's points within their
    // noise, and decides (`docs/sphere.md`, "Sections that miss the axis").
    let mut rescued = None;
    if count >= 2 {
        let sphere = match &sections_fit {
            Some(e) => e.sphere,
            None => initial_sphere(&list[..count])?,
        };
        if misalignment(&list[..count], &sphere) > params.max_misalignment {
            let fit =
                joint_fit_from(sphere).filter(|j| one_sphere_explains(j, &list[..count], params));
            match fit {
                Some(j) => {
                    flags.insert(Flags::INCONSISTENT);
                    rescued = Some(j);
                }
                None if round_arcs || disjoint(&list[..count]) => {
                    return Err(SolveError::TwoObjects)
                }
                None => return Err(SolveError::NotSpherical),
            }
        }
    }

    // Three-tangent sections.
    let mut tangents = [None::<Section>; MAX_PLANES];
    let edge_sigma = 0.5 / params.focal_px;
    let mut offset = 0;
    for ((slot, curve), plane) in tangents
        .iter_mut()
        .zip(input.curves)
        .zip(input.planes)
        .take(n)
    {
        let flat = &mut flat_all[offset..offset + curve.len()];
        offset += curve.len();
        if curve.len() < params.min_points {
            continue;
        }
        if let Ok((section, _)) =
            three_tangent_section(plane, curve, &params.three_tangent, edge_sigma, flat)
        {
            *slot = Some(section);
        }
    }
    let (list_tt, count_tt) = compact(&tangents);
    let tt_fit = if count_tt >= 2 {
        sphere_from_sections(&list_tt[..count_tt], &params.lm).ok()
    } else {
        None
    };
    if tt_fit.is_none() {
        flags.insert(Flags::THREE_TANGENT_FAILED);
    }

    // Joint fit from the best start available (already made when it decided the sections'
    // misalignment).
    let joint = match rescued {
        Some(j) => Some(j),
        None => {
            let start = sections_fit
                .as_ref()
                .or(tt_fit.as_ref())
                .map(|e| e.sphere)
                // Neither circles nor tangents fit the sections: straight or shapeless curves.
                .ok_or(SolveError::NotSpherical)?;
            joint_fit_from(start)
        }
    };
    if joint.is_none() {
        flags.insert(Flags::FIT_FAILED);
    }
    let joint_estimate = joint.map(|j| Estimate {
        diameter: 2.0 * j.sphere.radius,
        sigma: 2.0 * j.sigma_radius(),
        centre: j.sphere.centre,
    });
    let sections = sections_fit.as_ref().map(estimate_of);
    let three_tangent = tt_fit.as_ref().map(estimate_of);

    let (mut chosen, method) = match (joint_estimate, sections, three_tangent) {
        (Some(j), _, _) => (j, Method::JointFit),
        (None, Some(s), _) => (s, Method::SphereSections),
        (None, None, Some(t)) => (t, Method::SphereThreeTangent),
        (None, None, None) => return Err(SolveError::NotConverged),
    };
    // The joint fit and the sections' sphere estimate one diameter from the same points: a
    // disagreement beyond both their σ is an error neither σ models (a speckled steel
    // section, a short section off the axis), and its excess variance is added; beyond 3σ
    // combined it is flagged, as for stems (`docs/sphere.md`, "Methods that disagree").
    if let (Method::JointFit, Some(s)) = (method, sections) {
        let (sigma, disagree) = widened_by_disagreement(&chosen, &s);
        chosen.sigma = sigma;
        if disagree {
            flags.insert(Flags::INCONSISTENT);
        }
    }
    let radius = 0.5 * chosen.diameter;
    if !(radius >= params.min_radius && radius <= params.max_radius) {
        return Err(SolveError::RadiusOutOfRange);
    }
    if section_radii[..n]
        .iter()
        .any(|&r| r > 0.0 && r < params.pole_ratio * radius)
    {
        flags.insert(Flags::NEAR_POLE);
    }
    let distance = norm(&chosen.centre);
    if !(distance >= params.range.0 && distance <= params.range.1) {
        flags.insert(Flags::RANGE_LIMIT);
    }
    // Calibration: the joint fit's response to each calibration error, the planes' errors
    // independent or as a refinement left them (`docs/sphere.md`, "Calibration errors",
    // (S-cal)); without a joint fit, the
    // relative scale error of the plane around the first section's centre, common to the
    // sections (which misses the planes' differential error: such readings are the fallbacks).
    let common_scale = || {
        (0..n)
            .find(|&k| circles[k].is_some())
            .and_then(|k| circles[k].map(|s| (k, s)))
            .map_or(0.0, |(k, s)| {
                noise::calibration_relative_sigma(
                    &input.planes[k],
                    s.centre_3d(),
                    &params.noise,
                    params.focal_px,
                )
            })
            * chosen.diameter
    };
    let calibration = match &joint {
        Some(j) => {
            2.0 * calibration_sigma_radius(
                j,
                &input.curves[..n],
                &input.sigmas[..n],
                &input.planes[..n],
                &params.fit,
                &params.noise,
                params.focal_px,
                input.uncertainty,
            )?
        }
        None => common_scale(),
    };
    let uncertainty = sqrt(chosen.sigma * chosen.sigma + calibration * calibration);
    if !(chosen.diameter.is_finite() && uncertainty.is_finite()) {
        return Err(SolveError::NonFinite);
    }
    Ok(SphereSolution {
        diameter: chosen.diameter,
        uncertainty,
        random_uncertainty: chosen.sigma,
        centre: chosen.centre,
        distance,
        method,
        flags,
        sections,
        three_tangent,
        joint_fit: joint_estimate,
        sections_chi2,
        section_radii,
        section_count: count,
    })
}

/// The sections that exist, in plane order, and their count.
fn compact(sections: &[Option<Section>; MAX_PLANES]) -> ([Section; MAX_PLANES], usize) {
    let mut out = [Section {
        origin: Vec3::zeros(),
        axes: (Vec3::zeros(), Vec3::zeros(), Vec3::zeros()),
        centre: Vec2::zeros(),
        radius: 0.0,
        covariance: crate::real::Mat3::identity(),
        arc: 0.0,
    }; MAX_PLANES];
    let mut count = 0;
    for s in sections.iter().flatten() {
        out[count] = *s;
        count += 1;
    }
    (out, count)
}

/// Two sections whose circles, seen along the planes' normal, do not overlap (their
/// centres farther apart across the normal than the sum of their radii): no one round object
/// has such sections, two side by side do.
fn disjoint(sections: &[Section]) -> bool {
    sections.iter().enumerate().any(|(i, s)| {
        sections[i + 1..].iter().any(|t| {
            let n = s.axes.2;
            let rel = t.centre_3d() - s.centre_3d();
            let across = rel - n * rel.dot(&n);
            norm(&across) > s.radius + t.radius
        })
    })
}

/// One sphere explains every curve: the joint fit kept nearly all of each curve's points
/// (a curve on another object is set aside by its robust weights), each curve's robust
/// residual scale, squared, is within the sphere test's `χ²` per degree of freedom, and no
/// section's circle is larger than the sphere (`rᵢ ≤ R`, one-sided at 95 %: `1.645 σ_r`).
/// Only a section's centre is tested loosely: on a short arc near a pole it is biased
/// (`docs/sphere.md`, "Sections that miss the axis").
fn one_sphere_explains(fit: &SphereFit, sections: &[Section], params: &SphereParams) -> bool {
    let fits_inside = sections.iter().all(|s| {
        s.radius - fit.sphere.radius <= ONE_SIDED_95 * sqrt(s.covariance[(2, 2)].max(0.0))
    });
    fits_inside
        && fit.least_inlier_share >= 1.0 - params.max_outlier_fraction
        && fit.worst_curve_scale * fit.worst_curve_scale <= params.not_spherical_chi2
}

/// The reported estimate's σ widened by its disagreement with another estimate of the same
/// diameter from the same points: the excess of the squared difference over both variances
/// (an error neither σ models) is added; and whether they differ by more than
/// [`DISAGREEMENT_SIGMAS`] combined (`docs/sphere.md`, "Methods that disagree").
fn widened_by_disagreement(reported: &Estimate, other: &Estimate) -> (Real, bool) {
    let spread = reported.diameter - other.diameter;
    let variance = reported.sigma * reported.sigma;
    let combined = variance + other.sigma * other.sigma;
    let excess = (spread * spread - combined).max(0.0);
    (
        sqrt(variance + excess),
        spread * spread > DISAGREEMENT_SIGMAS * DISAGREEMENT_SIGMAS * combined,
    )
}

/// Disagreement of the joint fit and the sections' sphere, in σ combined, beyond which
/// [`Flags::INCONSISTENT`] is set (the stems' rule, [`super::stem`]).
const DISAGREEMENT_SIGMAS: Real = 3.0;

/// The one-sided 95 % point of the normal distribution.
const ONE_SIDED_95: Real = 1.645;

/// Largest distance, relative to `R`, between a section's centre and the sphere centre's
/// projection on its plane.
fn misalignment(sections: &[Section], sphere: &Sphere) -> Real {
    let mut worst: Real = 0.0;
    for s in sections {
        let rel = sphere.centre - s.centre_3d();
        let (a, b, _) = s.axes;
        let miss = sqrt(rel.dot(&a).powi(2) + rel.dot(&b).powi(2));
        worst = worst.max(miss / sphere.radius);
    }
    worst
}

/// The section is detectably elliptic: the score test screens, the fitted ellipse's
/// eccentricity decides (as for stems, `docs/cylinder.md`, "Elliptic stems").
fn not_round(
    flat: &[Vec2],
    circle: &super::circle::Circle,
    cutoff: Real,
    params: &SphereParams,
) -> bool {
    let (min_f, min_ecc) = params.not_round;
    match ellipse::ellipse_score_f(flat, circle, cutoff) {
        Ok(f) if f >= 0.5 * min_f => {}
        _ => return false,
    }
    let lm = LmParams {
        max_iterations: params.lm.max_iterations.max(1000),
        ..params.lm
    };
    match ellipse::fit_ellipse(flat, circle, cutoff, &lm) {
        Ok(e) => e.f_statistic() > min_f && e.eccentricity() > min_ecc,
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests;
