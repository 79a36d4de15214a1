//! The stem diameter of one capture (thesis chapter 9; `docs/cylinder.md`, "Choosing the
//! method"): [`solve`] runs the methods — three-tangent and robust circle fit in one plane,
//! cylinder fit and generalised three-tangent over two or more — gives each its 1σ from the
//! points' stored σ and the noise model, chooses the reported diameter, sets
//! the quality [`Flags`], and returns a specific [`SolveError`] when nothing is trustworthy.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec2, Vec3, PI};

use super::circle::{self, RobustParams, WEIGHTED_SCRATCH_PER_POINT};
use super::cylinder_fit::{
    calibration_sigma_radius, fit_cylinder_weighted, fit_weights, initial_cylinder,
    project_along_axis, to_plane, CYLINDER_SCRATCH_PER_POINT,
};
use super::ellipse::{self, EllipseFit};
use super::lm::LmParams;
use super::result::{Flags, Method, Tilt};
use super::three_tangent::{
    generalised_three_tangent, three_tangent, ThreeTangent, ThreeTangentParams,
};
use super::SolveError;
use crate::calibration::{PlanesUncertainty, MAX_PLANES};
use crate::laser_plane::LaserPlane;
use crate::noise::{self, NoiseModel};

mod budget;
mod exposures;
mod level;
mod sigma;
mod solution;
use budget::bin_curves;
pub use budget::POINT_BUDGET;
pub use exposures::{combine_exposures, MAX_EXPOSURES};
use level::LevelMap;
use sigma::{
    arc_angle, elliptic_diameter, noise_vector, one_point_sigma, projected_section, robust_circle,
    three_tangent_variance, Start,
};
pub use sigma::{edge_bias_sigma, BENDING_FRACTION};
pub use solution::CylinderSolution;

/// Input of [`solve`]: the laser curves of one capture.
#[derive(Debug, Clone, Copy)]
pub struct CylinderInput<'a> {
    /// Per plane, the triangulated points (metres, camera frame), in image-column order.
    pub curves: &'a [&'a [Vec3]],
    /// Per plane, each point's 1σ (metres, along its noise direction
    /// [`noise::DisplacementField`]), same indexing as `curves` (the pipeline writes them
    /// beside the points: [`crate::pipeline::point_sigmas`]).
    pub sigmas: &'a [&'a [Real]],
    /// The laser planes, same order as `curves`.
    pub planes: &'a [LaserPlane],
    /// The planes' calibration covariance when they were refined against each other
    /// ([`crate::calibration::Calibration::uncertainty`]); `None`: independent, each with
    /// the noise model's σ. Used by the two-plane fit's calibration σ.
    pub uncertainty: Option<&'a PlanesUncertainty>,
}

/// Settings of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CylinderParams {
    /// Smallest plausible radius (metres).
    pub min_radius: Real,
    /// Largest plausible radius (metres).
    pub max_radius: Real,
    /// Working range: nearest distance from the source (metres), min and max.
    pub range: (Real, Real),
    /// Arc angle (radians, seen from the centre) below which the fit is flagged
    /// [`Flags::ARC_TOO_SHORT`] and not preferred.
    pub min_arc_angle: Real,
    /// Largest tilt (radians) before [`Flags::LARGE_TILT`].
    pub max_tilt: Real,
    /// Fraction of rejected points above which [`Flags::SEVERAL_OBJECTS`] is set.
    pub max_outlier_fraction: Real,
    /// Three-tangent settings.
    pub three_tangent: ThreeTangentParams,
    /// Robust circle fit settings (its `min_scale` is raised to the predicted point noise).
    pub robust: RobustParams,
    /// Cylinder fit settings.
    pub lm: LmParams,
    /// Image and calibration noise (for the uncertainties).
    pub noise: NoiseModel,
    /// Focal length along the image rows' normal (`fy`, pixels), for the noise model.
    pub focal_px: Real,
    /// Non-roundness test: smallest F statistic of circle against ellipse
    /// ([`EllipseFit::f_statistic`]) for [`Flags::ELLIPTIC`].
    pub elliptic_min_f: Real,
    /// Non-roundness test: smallest relative axis difference `(a − b)/(a + b)` for
    /// [`Flags::ELLIPTIC`] (smaller ones are within what a round stem's bark and the stripe
    /// extraction's coherent bending produce; `docs/cylinder.md`, "Elliptic stems").
    pub elliptic_min_eccentricity: Real,
    /// Most points of one curve the solver uses; longer curves are binned
    /// (`docs/error-model.md`, "Point budget"; default [`POINT_BUDGET`]). `0` or `usize::MAX`
    /// fits every point; 1 and 2 count as 3 (the curve's ends and one bin between).
    pub point_budget: usize,
}

/// Default [`CylinderParams::elliptic_min_f`]: far above the 1e-6 tail of `F(2, n − 5)`
/// (≈ 14 for n ≥ 100) because the residuals are not independent (coherent bending, bark): the
/// statistic only screens, the eccentricity decides (`docs/cylinder.md`, "Elliptic stems").
pub const ELLIPTIC_MIN_F: Real = 30.0;

/// Fraction of [`CylinderParams::elliptic_min_f`] below which the score-test F
/// ([`ellipse::ellipse_score_f`]) settles the non-roundness test without fitting the ellipse.
const ELLIPTIC_SCREEN: Real = 0.5;

/// Iteration budget of the ellipse fit in the non-roundness test.
const ELLIPSE_MAX_ITERATIONS: u32 = 1000;

/// Default [`CylinderParams::elliptic_min_eccentricity`]: 4 % (axis ratio 1.08).
pub const ELLIPTIC_MIN_ECCENTRICITY: Real = 0.04;

impl Default for CylinderParams {
    /// The reference caliper: radii 1–60 cm, range 0.3–3.5 m, min arc 40°, max tilt 35°,
    /// f = 1000 px, [`NoiseModel::reference`].
    fn default() -> Self {
        CylinderParams {
            min_radius: 0.01,
            max_radius: 0.6,
            range: (0.3, 3.5),
            min_arc_angle: 40.0 * PI / 180.0,
            max_tilt: 35.0 * PI / 180.0,
            max_outlier_fraction: 0.3,
            three_tangent: ThreeTangentParams::default(),
            robust: RobustParams::default(),
            lm: LmParams::default(),
            noise: NoiseModel::reference(),
            focal_px: 1000.0,
            elliptic_min_f: ELLIPTIC_MIN_F,
            elliptic_min_eccentricity: ELLIPTIC_MIN_ECCENTRICITY,
            point_budget: POINT_BUDGET,
        }
    }
}

/// Caller-owned working memory of [`solve`]. Each curve longer than the point budget is
/// binned into `bins` first (the budget lowered to what `points` and `values` hold); then
/// `points` must be at least as long as the longest curve the solver works on, and `values`
/// must hold the whole-arc fits' [`circle::WEIGHTED_SCRATCH_PER_POINT`] values per point of
/// it.
pub struct Scratch<'a> {
    /// In-plane / projected points.
    pub points: &'a mut [Vec2],
    /// Residual magnitudes (robust scale).
    pub values: &'a mut [Real],
    /// The bins of the curves longer than the point budget (up to the budget per curve); a
    /// curve there is no room left for is used whole.
    pub bins: &'a mut [Vec3],
    /// The bins' 1σ, beside `bins`.
    pub bin_sigmas: &'a mut [Real],
}

/// One-plane result (internal): both methods with their σ.
struct PlaneResult {
    tt: Option<(ThreeTangent, Real)>,
    fit: Option<(circle::CircleFit, Real, Real)>, // fit, σ_r, arc angle
    /// The radius the pull correction removed from the fit.
    pull: Real,
    /// The whole-arc fit's information radius σ (`sigma::RobustCircle::information`).
    information: Option<Real>,
    ellipse: Option<EllipseFit>,
    flags: Flags,
    n: usize,
}

/// The one-plane reading of `curve` in the level section: three-tangent, the whole-arc robust
/// circle fit and the non-roundness test. A two-plane solve runs it only as its fallback (its
/// arc length comes from plane 0's projected section, `solve_tilted`): on the device it was
/// a fifth of a tilted stem's solver (`docs/performance.md`).
fn solve_plane(
    curve: &[Vec3],
    sigmas: &[Real],
    plane: &LaserPlane,
    params: &CylinderParams,
    scratch: &mut Scratch<'_>,
) -> Result<PlaneResult, SolveError> {
    let n = to_plane(curve, plane, scratch.points)?.len();
    // The level section of a vertical stem (docs/cylinder.md, "One plane: the level section").
    let level = LevelMap::of(plane);
    for p in scratch.points[..n].iter_mut() {
        *p = level.to_level(*p);
    }
    let pts = &scratch.points[..n];
    let mut flags = Flags::default();
    let cal = |r: Real, centre: Vec2| {
        noise::calibration_relative_sigma(
            plane,
            plane.from_plane_coords(level.to_plane(centre)),
            &params.noise,
            params.focal_px,
        ) * r
    };
    // Model noise of a point the data does not contain, in the level section.
    let noise_at = |q: Vec2| level.to_level(noise_vector(plane, level.to_plane(q), params));
    // Three-tangent with σ from the edges (model) and from D (max of model and data).
    let tt = match three_tangent(pts, &params.three_tangent) {
        Ok(t) => {
            let near = t.bisector * t.nearest_distance;
            let s_point = noise_at(near).dot(&t.bisector).abs();
            let random = sqrt(three_tangent_variance(&t, s_point, params));
            let s = sqrt(random * random + cal(t.radius, t.centre).powi(2));
            Some((t, s))
        }
        Err(_) => {
            flags.insert(Flags::THREE_TANGENT_FAILED);
            None
        }
    };
    // Robust fit, scale floor = predicted point noise at the arc's nearest point; each data
    // point's noise vector is its stored σ along the field's direction.
    let values = &mut scratch.values[..];
    let mut ellipse = None;
    let field = noise::DisplacementField::of(plane);
    let noise_of =
        |i: usize| level.to_level(field.direction_in_plane(level.to_plane(pts[i])) * sigmas[i]);
    let near_sigma = |q: Vec2| norm(&noise_at(q));
    let mut information = None;
    let mut pull = 0.0;
    let fit = robust_circle(
        pts,
        Start::Fit,
        near_sigma,
        noise_of,
        params,
        circle::Pull::Evaluate,
        values,
    )
    .map(|rc| {
        let mut f = rc.fit;
        information = Some(rc.information);
        // The whole-arc fit's σ: the points' own σ, inflated by χ² and the residuals'
        // correlation along the stripe (docs/error-model.md, "Correlation along the stripe").
        let random = rc.data_sigma.hypot(rc.bending);
        let s = sqrt(random * random + cal(f.circle.radius, f.circle.centre).powi(2));
        let arc = arc_angle(pts, f.circle.centre);
        let rejected = 1.0 - f.inliers as Real / pts.len() as Real;
        if rejected > params.max_outlier_fraction {
            flags.insert(Flags::SEVERAL_OBJECTS);
        }
        if f.rms_residual > 3.0 * rc.near_sigma.max(params.robust.min_scale) || rejected > 0.2 {
            flags.insert(Flags::POOR_FIT);
        }
        if arc < params.min_arc_angle {
            flags.insert(Flags::ARC_TOO_SHORT);
        }
        ellipse = non_round(pts, &f, rc.cutoff, params);
        // The normal-residual pull of noise along the line of sight, removed to second order
        // (docs/error-model.md §5e, "The pull to second order"); the tests above judged the
        // fitted circle itself.
        f.circle.radius -= rc.pull;
        pull = rc.pull;
        (f, s, arc)
    });
    if fit.is_none() {
        flags.insert(Flags::FIT_FAILED);
    }
    // Edge bias of the three-tangent method (docs/cylinder.md, "Stripe fade-out"): the
    // stripe fades as cos ι → 0 towards the silhouette and the last extracted column lies
    // inside it, so `α` is biased low by an amount the image noise model does not contain.
    // The fit does not need the ends; its grazing half-aperture `asin(R/|C|)` estimates the
    // true one, and the difference (with the fit's own σ on it) is added to the
    // three-tangent's σ as a bias term.
    let tt = match (tt, fit.as_ref()) {
        (Some((t, s)), Some((f, sf, _))) => Some((t, s.hypot(edge_bias_sigma(&t, &f.circle, *sf)))),
        (tt, _) => tt,
    };
    Ok(PlaneResult {
        tt,
        fit,
        pull,
        information,
        ellipse,
        flags,
        n,
    })
}

/// The point budget: [`CylinderParams::point_budget`], lowered to what the scratch's
/// `points` and `values` (their lengths) hold for the whole-arc fits (a workspace sized for a
/// narrow frame bins its longer curves rather than refusing them): each curve's circle fit,
/// and with two or more `curves` the cylinder fit over all of them.
fn point_budget(params: &CylinderParams, points: usize, values: usize, curves: usize) -> usize {
    let cylinder = if curves >= 2 {
        values / (CYLINDER_SCRATCH_PER_POINT * curves)
    } else {
        usize::MAX
    };
    params
        .point_budget
        .min(points)
        .min(values / WEIGHTED_SCRATCH_PER_POINT)
        .min(cylinder)
}

/// The ellipse fitted to the circle fit's inliers when the section is detectably not round
/// (`docs/cylinder.md`, "Elliptic stems"): F statistic above `elliptic_min_f` and relative
/// axis difference above `elliptic_min_eccentricity`. `None` for a round section or when the
/// ellipse fit fails (then the circle stands).
fn non_round(
    pts: &[Vec2],
    fit: &circle::CircleFit,
    cutoff: Real,
    params: &CylinderParams,
) -> Option<EllipseFit> {
    // The ellipse's valley is long and flat (size against shape along the line of sight):
    // LM needs a few hundred steps from the circle (measured: ≤ 220 on the corpus).
    let lm = LmParams {
        max_iterations: params.robust.lm.max_iterations.max(ELLIPSE_MAX_ITERATIONS),
        ..params.robust.lm
    };
    // Screening (`docs/cylinder.md`, "Screening"): the score-test F costs one pass over the
    // points; the fitted F never exceeded it by more than 14 % on the corpus and 367
    // evaluation curves, so below half the threshold the fit cannot flag the stem.
    if ellipse::ellipse_score_f(pts, &fit.circle, cutoff).ok()?
        < ELLIPTIC_SCREEN * params.elliptic_min_f
    {
        return None;
    }
    let e = ellipse::fit_ellipse(pts, &fit.circle, cutoff, &lm).ok()?;
    (e.f_statistic() > params.elliptic_min_f && e.eccentricity() > params.elliptic_min_eccentricity)
        .then_some(e)
}

/// Largest relative 1σ of a reading that is still reported (`docs/cylinder.md` §6, rule 3;
/// first for short arcs, since session 10 for every reading, [`bounded`]): above it the 3σ
/// interval reaches a zero radius, so the reading does not bound the stem's size and the
/// capture is refused.
const MAX_REL_SIGMA: Real = 1.0 / 3.0;

/// The solution, if its 1σ bounds the stem's size: rule 3's bound (`docs/cylinder.md` §6)
/// holds for every reading, not only a short arc's — above a third of the diameter the 3σ
/// interval reaches zero and the number says nothing of the stem ([`SolveError::Unbounded`]).
fn bounded(sol: CylinderSolution) -> Result<CylinderSolution, SolveError> {
    if sol.uncertainty.is_finite() && sol.uncertainty <= MAX_REL_SIGMA * sol.diameter {
        Ok(sol)
    } else {
        Err(SolveError::Unbounded)
    }
}

/// Choice between a three-tangent radius and a fit radius (`docs/cylinder.md`, "Choosing
/// the method"): `(use_fit, inconsistent)`, or `None` when there is no trustworthy answer.
fn choose(tt: Option<(Real, Real)>, fit: Option<(Real, Real, bool)>) -> Option<(bool, bool)> {
    // The three-tangent alone has no check on the fade-out of its edges (docs/cylinder.md
    // §5b: biased low by up to tens of percent, and a fragment of the curve looks like a
    // small stem): without a fit to judge it there is no trustworthy answer.
    let (rf, sf, short) = fit?;
    let inconsistent = tt.is_some_and(|(rt, st)| (rt - rf).abs() > 3.0 * sqrt(st * st + sf * sf));
    if short {
        // Rule 3: on a short arc the visible ends are not the tangent points (§5b), so the
        // three-tangent is never better than the fit: the fit with its honest σ, or nothing.
        return (sf.is_finite() && sf <= MAX_REL_SIGMA * rf.abs()).then_some((true, inconsistent));
    }
    Some(match tt {
        Some((_, st)) if !inconsistent => (sf < st, false),
        _ => (true, inconsistent),
    })
}

/// Solves the stem diameter of one capture (`docs/cylinder.md`, "Choosing the method").
///
/// * One plane: three-tangent and robust circle fit; [`Flags::TILT_IGNORED`].
/// * Two or more planes: cylinder fit (axis and radius) and the generalised three-tangent
///   method on each curve projected along the axis; [`CylinderSolution::tilt`] is set. If the
///   cylinder fit fails or its σ breaks rule 3's bound, falls back to the one-plane solution
///   of plane 0 ([`Flags::TILT_FIT_FAILED`]).
///
/// The reported diameter is the method with the smaller 1σ, except: the fit when the two
/// disagree beyond 3σ ([`Flags::INCONSISTENT`], occluded edge), and the fit with
/// [`Flags::ARC_TOO_SHORT`] when the arc is short. Errors: [`SolveError::PlaneCount`] (no
/// curve, or curves ≠ planes), [`SolveError::ScratchTooSmall`], [`SolveError::ArcTooShort`]
/// (short arc and the fit's σ above a third of its radius), [`SolveError::Unbounded`] (any
/// other reading whose σ is above a third of its diameter), [`SolveError::RadiusOutOfRange`],
/// and the
/// [`SolveError::NotConverged`] when both methods fail.
pub fn solve(
    input: &CylinderInput<'_>,
    params: &CylinderParams,
    scratch: Scratch<'_>,
) -> Result<CylinderSolution, SolveError> {
    if input.curves.is_empty()
        || input.curves.len() != input.planes.len()
        || input.sigmas.len() != input.curves.len()
        || input.curves.len() > MAX_PLANES
    {
        return Err(SolveError::PlaneCount);
    }
    if input
        .curves
        .iter()
        .zip(input.sigmas)
        .any(|(c, s)| c.len() != s.len())
    {
        return Err(SolveError::InvalidParameter);
    }
    if !(params.min_radius > 0.0
        && params.max_radius > params.min_radius
        && params.focal_px > 0.0
        && params.focal_px.is_finite())
    {
        return Err(SolveError::InvalidParameter);
    }
    // Every method works on at most the point budget per curve (docs/error-model.md, "Point
    // budget"); the measured points are what the reading reports it used.
    let Scratch {
        points,
        values,
        bins,
        bin_sigmas,
    } = scratch;
    let budget = point_budget(params, points.len(), values.len(), input.curves.len());
    let (curves, sigmas) = bin_curves(input.curves, input.sigmas, budget, bins, bin_sigmas);
    let planes = input.curves.len();
    let measured = |k: usize| input.curves.get(k).map_or(0, |c| c.len());
    let input = &CylinderInput {
        curves: &curves[..planes],
        sigmas: &sigmas[..planes],
        planes: input.planes,
        uncertainty: input.uncertainty,
    };
    let mut scratch = Scratch {
        points,
        values,
        bins: &mut [],
        bin_sigmas: &mut [],
    };
    let longest = input.curves.iter().map(|c| c.len()).max().unwrap_or(0);
    let total: usize = input.curves.iter().map(|c| c.len()).sum();
    if scratch.points.len() < longest
        || scratch.values.len() < (WEIGHTED_SCRATCH_PER_POINT * longest).max(longest)
        || (planes >= 2 && scratch.values.len() < CYLINDER_SCRATCH_PER_POINT * total)
    {
        return Err(SolveError::ScratchTooSmall);
    }
    let plane0 = &input.planes[0];
    let two_planes = input.curves.len() >= 2;
    let plane0_reading = |scratch: &mut Scratch<'_>| {
        solve_plane(input.curves[0], input.sigmas[0], plane0, params, scratch)
    };
    let sol = if two_planes {
        // A cylinder fit whose σ does not bound the size (an axis the curves leave
        // undetermined) is a failed tilt fit: plane 0's own reading stands in for it.
        match solve_tilted(input, params, &mut scratch).and_then(bounded) {
            Ok(s) => s,
            Err(_) => {
                let one = plane0_reading(&mut scratch)?;
                let mut s = finish_plane(&one, plane0, params)?;
                s.flags.insert(Flags::TILT_FIT_FAILED);
                s.flags.insert(Flags::TILT_IGNORED);
                s
            }
        }
    } else {
        let one = plane0_reading(&mut scratch)?;
        let mut s = finish_plane(&one, plane0, params)?;
        s.flags.insert(Flags::TILT_IGNORED);
        s
    };
    let r = 0.5 * sol.diameter;
    if !(r >= params.min_radius && r <= params.max_radius) {
        return Err(SolveError::RadiusOutOfRange);
    }
    let mut sol = bounded(sol)?;
    sol.n_points = if sol.tilt.is_some() {
        (0..planes).map(measured).sum()
    } else {
        measured(0)
    };
    if !(sol.distance >= params.range.0 && sol.distance <= params.range.1) {
        sol.flags.insert(Flags::RANGE_LIMIT);
    }
    Ok(sol)
}

fn finish_plane(
    one: &PlaneResult,
    plane: &LaserPlane,
    params: &CylinderParams,
) -> Result<CylinderSolution, SolveError> {
    // The one-plane results are in the level section (`solve_plane`).
    let level = LevelMap::of(plane);
    if let (Some(e), Some((f, _, _))) = (one.ellipse, one.fit) {
        let cal_rel = noise::calibration_relative_sigma(
            plane,
            plane.from_plane_coords(level.to_plane(e.centre)),
            &params.noise,
            params.focal_px,
        );
        let (d, s) = elliptic_diameter(&e, cal_rel)?;
        let mut flags = one.flags;
        flags.insert(Flags::ELLIPTIC);
        let c = f.circle.centre;
        return Ok(CylinderSolution {
            diameter: d,
            method: Method::CircleFit,
            uncertainty: s,
            calibration_uncertainty: cal_rel * d,
            tilt: None,
            flags,
            fit_rms: f.rms_residual,
            n_points: one.n,
            exposures: 1,
            three_tangent_diameter: one.tt.map(|(t, _)| 2.0 * t.radius),
            three_tangent_uncertainty: one.tt.map(|(_, s)| 2.0 * s),
            fit_diameter: Some(2.0 * f.circle.radius),
            fit_uncertainty: one.fit.map(|(_, s, _)| 2.0 * s),
            information_uncertainty: one.information.map(|s| 2.0 * s),
            // The ellipse's axes, not the corrected circle, give the diameter.
            pull_correction: 0.0,
            distance: norm(&c) - f.circle.radius,
            centre: plane.from_plane_coords(level.to_plane(e.centre)),
            axes: Some((2.0 * e.semi_axes.0, 2.0 * e.semi_axes.1)),
        });
    }
    let short = one.flags.contains(Flags::ARC_TOO_SHORT);
    let tt = one.tt.map(|(t, s)| (t.radius, s));
    let fit = one.fit.map(|(f, s, _)| (f.circle.radius, s, short));
    let (use_fit, inconsistent) = match choose(tt, fit) {
        Some(c) => c,
        None => {
            return Err(if one.fit.is_some() {
                SolveError::ArcTooShort
            } else {
                SolveError::NotConverged
            })
        }
    };
    let mut flags = one.flags;
    if inconsistent {
        flags.insert(Flags::INCONSISTENT);
    }
    let (radius, sigma, method, centre, distance) = if use_fit {
        let (f, s, _) = one.fit.ok_or(SolveError::NotConverged)?;
        let c = f.circle.centre;
        (
            f.circle.radius,
            s,
            Method::CircleFit,
            c,
            norm(&c) - f.circle.radius,
        )
    } else {
        let (t, s) = one.tt.ok_or(SolveError::NotConverged)?;
        (
            t.radius,
            s,
            Method::ThreeTangent,
            t.centre,
            t.nearest_distance,
        )
    };
    let cal_rel = noise::calibration_relative_sigma(
        plane,
        plane.from_plane_coords(level.to_plane(centre)),
        &params.noise,
        params.focal_px,
    );
    Ok(CylinderSolution {
        diameter: 2.0 * radius,
        method,
        uncertainty: 2.0 * sigma,
        calibration_uncertainty: cal_rel * 2.0 * radius,
        tilt: None,
        flags,
        fit_rms: one.fit.map(|(f, _, _)| f.rms_residual).unwrap_or(0.0),
        n_points: one.n,
        exposures: 1,
        three_tangent_diameter: one.tt.map(|(t, _)| 2.0 * t.radius),
        three_tangent_uncertainty: one.tt.map(|(_, s)| 2.0 * s),
        fit_diameter: one.fit.map(|(f, _, _)| 2.0 * f.circle.radius),
        fit_uncertainty: one.fit.map(|(_, s, _)| 2.0 * s),
        information_uncertainty: one.information.map(|s| 2.0 * s),
        pull_correction: if use_fit { 2.0 * one.pull } else { 0.0 },
        distance,
        centre: plane.from_plane_coords(level.to_plane(centre)),
        axes: None,
    })
}

fn solve_tilted(
    input: &CylinderInput<'_>,
    params: &CylinderParams,
    scratch: &mut Scratch<'_>,
) -> Result<CylinderSolution, SolveError> {
    let init = initial_cylinder(input.curves, input.planes, scratch.points)?;
    // Whole-arc weighted fit (docs/cylinder.md, "Whole-arc fit"): each point's own σ along
    // its plane's noise direction.
    let mut fields = [noise::DisplacementField::of(&input.planes[0]); MAX_PLANES];
    for (f, plane) in fields.iter_mut().zip(input.planes) {
        *f = noise::DisplacementField::of(plane);
    }
    let point_noise = |k: usize, i: usize| match (input.curves[k].get(i), input.sigmas[k].get(i)) {
        (Some(x), Some(s)) => fields
            .get(k)
            .map_or(Vec3::zeros(), |f| f.direction(*x) * *s),
        _ => Vec3::zeros(),
    };
    let fit = fit_cylinder_weighted(
        input.curves,
        point_noise,
        init,
        &params.robust,
        scratch.values,
    )?
    .fit;
    // The calibration's part of the radius σ: each plane's own errors, through the fit with
    // its own weights (docs/cylinder.md, (Cy-cal)).
    let total = input.curves.iter().map(|c| c.len()).sum();
    let cal_sigma = calibration_sigma_radius(
        &fit,
        input.curves,
        fit_weights(scratch.values, total).ok_or(SolveError::ScratchTooSmall)?,
        input.planes,
        &params.noise,
        params.focal_px,
        input.uncertainty,
    )?;
    let cyl = fit.cylinder;
    let plane0 = &input.planes[0];
    // Generalised three-tangent on every curve; mean radius, σ of the mean of the
    // per-curve model σ's (independent curves).
    let mut rsum = 0.0;
    let mut s2sum = 0.0;
    let mut k = 0;
    // Σ of the per-curve data-driven radius variances of the projected circle fits.
    let mut fit_s2sum = 0.0;
    let mut kf = 0;
    // Σ of the per-curve information radius variances (the bound's counterpart of the above).
    let mut info_s2sum = 0.0;
    // Σ of the per-curve edge-fade bias σ's: a bias, common to the curves, so it is
    // averaged, not reduced as independent noise.
    let mut edge_sum = 0.0;
    // Plane 0's visible arc, seen from the axis.
    let mut arc0 = None;
    // Non-roundness in the plane perpendicular to the fitted axis (where a round stem's
    // section is a circle whatever the tilt), judged on plane 0's projected section.
    let mut ellipse = None;
    for (index, ((curve, sigmas), plane)) in input
        .curves
        .iter()
        .zip(input.sigmas)
        .zip(input.planes)
        .enumerate()
    {
        // The data-driven terms of the one-plane path on the projected curve
        // (docs/cylinder.md, "Data-driven σ of the two-plane result").
        let section = projected_section(curve, sigmas, plane, &cyl, index == 0, params, scratch);
        let extra = section.map(|p| {
            if index == 0 {
                arc0 = Some(p.arc);
                ellipse = p.ellipse;
            }
            info_s2sum += p.information * p.information;
            (p.circle, p.sigma)
        });
        if let Some((_, sf)) = extra {
            fit_s2sum += sf * sf;
            kf += 1;
        }
        if let Ok(t) = generalised_three_tangent(
            curve,
            plane.source,
            cyl.axis,
            &params.three_tangent,
            scratch.points,
        ) {
            let s_point = one_point_sigma(plane, params, t.nearest_distance);
            // Fade-out of the projected edges, judged against the projected fit.
            let edge = extra.map_or(0.0, |(c, sf)| edge_bias_sigma(&t, &c, sf));
            rsum += t.radius;
            s2sum += three_tangent_variance(&t, s_point, params);
            edge_sum += edge;
            k += 1;
        }
    }
    // Where the axis meets plane 0.
    let denom = plane0.normal.dot(&cyl.axis);
    let centre = if denom.abs() > 1e-6 {
        cyl.point + cyl.axis * ((plane0.offset - plane0.normal.dot(&cyl.point)) / denom)
    } else {
        return Err(SolveError::Degenerate);
    };
    // The calibration's σ relative to the radius, for the methods that share the fit's axis.
    let cal_rel = cal_sigma / cyl.radius;
    // The cylinder fit's own σ assumes independent, equal point noise; the dim ends of a far
    // curve and coherent bending break that as in one plane. σ of the mean of the per-curve
    // data-driven terms (independent curves) is the floor, as `max` in `solve_plane`.
    let data_sigma = if kf > 0 {
        sqrt(fit_s2sum / (kf * kf) as Real)
    } else {
        0.0
    };
    let fit_sigma = sqrt(fit.sigma_radius.max(data_sigma).powi(2) + cal_sigma * cal_sigma);
    let tt = if k > 0 {
        let r = rsum / k as Real;
        let edge = edge_sum / k as Real;
        let s = sqrt(s2sum / (k * k) as Real + edge * edge + (cal_rel * r).powi(2));
        Some((r, s))
    } else {
        None
    };
    let mut flags = Flags::default();
    if tt.is_none() {
        flags.insert(Flags::THREE_TANGENT_FAILED);
    }
    // Without a projected fit, the arc is seen from the fitted axis itself.
    let arc0 = arc0.or_else(|| {
        let projected =
            project_along_axis(input.curves[0], plane0.source, cyl.axis, scratch.points).ok()?;
        let w = cyl.point - plane0.source;
        let axis_at = Vec2::new(w.dot(&projected.e1), w.dot(&projected.e2));
        Some(arc_angle(projected.points, axis_at))
    });
    let short = arc0.is_some_and(|arc| arc < params.min_arc_angle);
    if short {
        flags.insert(Flags::ARC_TOO_SHORT);
    }
    let (use_fit, inconsistent) =
        choose(tt, Some((cyl.radius, fit_sigma, short))).ok_or(SolveError::ArcTooShort)?;
    if inconsistent {
        flags.insert(Flags::INCONSISTENT);
    }
    let tilt = Tilt::of(cyl.axis, plane0, fit.sigma_axis);
    if tilt.total > params.max_tilt {
        flags.insert(Flags::LARGE_TILT);
    }
    let point_sigma = one_point_sigma(plane0, params, norm(&(centre - plane0.source)) - cyl.radius);
    if fit.rms_residual > 3.0 * point_sigma.max(params.robust.min_scale) {
        flags.insert(Flags::POOR_FIT);
    }
    let (radius, sigma, method) = match (use_fit, tt) {
        (false, Some((r, s))) => (r, s, Method::GeneralisedThreeTangent),
        _ => (cyl.radius, fit_sigma, Method::CylinderFit),
    };
    let c0 = plane0.to_plane_coords(centre);
    // An elliptic section reports the mean of its axes (`docs/cylinder.md`, "Elliptic stems").
    let (diameter, method, uncertainty, axes) = match ellipse {
        Some(e) => {
            let (d, s) = elliptic_diameter(&e, cal_rel)?;
            flags.insert(Flags::ELLIPTIC);
            let axes = (2.0 * e.semi_axes.0, 2.0 * e.semi_axes.1);
            (d, Method::CylinderFit, s, Some(axes))
        }
        None => (2.0 * radius, method, 2.0 * sigma, None),
    };
    Ok(CylinderSolution {
        diameter,
        method,
        uncertainty,
        calibration_uncertainty: cal_rel * diameter,
        tilt: Some(tilt),
        flags,
        fit_rms: fit.rms_residual,
        n_points: fit.points,
        exposures: 1,
        three_tangent_diameter: tt.map(|(r, _)| 2.0 * r),
        three_tangent_uncertainty: tt.map(|(_, s)| 2.0 * s),
        fit_diameter: Some(2.0 * cyl.radius),
        fit_uncertainty: Some(2.0 * fit_sigma),
        information_uncertainty: (kf > 0).then(|| 2.0 * sqrt(info_s2sum) / kf as Real),
        pull_correction: 0.0,
        distance: norm(&c0) - cyl.radius,
        centre,
        axes,
    })
}

#[cfg(test)]
mod tests;
