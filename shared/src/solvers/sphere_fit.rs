//! The joint fit of a sphere to every 3-D point of every laser plane (`docs/sphere.md`,
//! "Joint fit"; thesis §10.5's "gradient-descent" method, here by the shared
//! Levenberg–Marquardt): minimises `Σ wⱼ·(|Xⱼ − C| − R)²/σ⊥ⱼ²` over `(C, R)`, with Tukey
//! weights `wⱼ` re-computed from the previous round's residuals so that a stray object does
//! not pull the sphere. `σ⊥ⱼ` is the point's σ projected on the sphere's normal (a point
//! moves along its stripe's displacement direction, and only the normal part of that moves
//! the residual); the covariance uses the errors' σ, which add a direction-free part
//! (`docs/sphere.md`, "Joint fit").

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec3};

use nalgebra::{SMatrix, SVector};

use super::circle::tukey;
use super::correlation::correlation_length;
use super::lm::{spd_inverse, LmParams, NormalEquations};
use super::sphere_sections::{minimise_sphere, Sphere, SphereCost};
use super::SolveError;
use crate::calibration::{PlanesUncertainty, MAX_PLANES};
use crate::laser_plane::LaserPlane;
use crate::noise::{self, NoiseModel};

/// [`SphereFitParams::direction_free_share`]'s default, from the tuning balls
/// with grown sections and estimator-only point σ (`docs/sphere.md`, "Joint fit" and
/// "Grown sections and the points' own σ").
pub const KAPPA: Real = 0.2;

/// Settings of [`fit_sphere`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereFitParams {
    /// The inner Levenberg–Marquardt settings.
    pub lm: LmParams,
    /// Tukey constant in units of the robust scale of the σ-normalised residuals.
    pub tuning: Real,
    /// Reweighting rounds after the first (plain weighted) fit.
    pub rounds: u32,
    /// Smallest share of a point's σ its *weight* keeps normal to the sphere (`|d̂·n̂|`
    /// floor of the weights' `σ·max(|d̂·n̂|, floor)`).
    pub min_normal_share: Real,
    /// `κ`: the direction-free share of a point's *error*, `σ⊥ = σ·√((d̂·n̂)² + κ²)`, which
    /// the covariance uses. Only part of a stripe centre's error is a shift along the image
    /// column (which moves the point along `d̂`): the smoothing along the curve and the
    /// cross profile's change on a curved surface move it in any direction, and where `d̂`
    /// runs along the surface (the limbs) that part is what is left. Calibrated on the
    /// tuning balls (`docs/sphere.md`, "Joint fit"; `docs/error-model.md`, "5d. Sphere").
    pub direction_free_share: Real,
}

impl Default for SphereFitParams {
    fn default() -> Self {
        SphereFitParams {
            lm: LmParams::default(),
            tuning: 4.685,
            rounds: 3,
            min_normal_share: 0.3,
            direction_free_share: KAPPA,
        }
    }
}

/// Result of [`fit_sphere`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereFit {
    /// The sphere.
    pub sphere: Sphere,
    /// Covariance of `(Cx, Cy, Cz, R)` (m²): the sandwich `A⁻¹BA⁻¹` of the weights and the
    /// errors' σ, scaled by the residuals' own variance against the errors' σ (the σ model
    /// sets the points' relative errors, the data their scale) and by the residuals'
    /// correlation length along the curves (`docs/sphere.md`, "Uncertainty of the joint
    /// fit").
    pub covariance: SMatrix<Real, 4, 4>,
    /// `Σw·(d/σ)² / (Σw − 4)`: 1 when the residuals are as large as the points' σ predict.
    pub reduced_chi2: Real,
    /// Points with non-zero weight.
    pub inliers: usize,
    /// The smallest share of one curve's points kept (non-zero weight): low when a curve
    /// lies on another object, which the robust fit sets aside.
    pub least_inlier_share: Real,
    /// The largest, over the curves, of the robust scale `1.4826·median|e/σ_e|` of a curve's
    /// kept residuals: about 1 when every curve lies on the sphere within its points' noise.
    pub worst_curve_scale: Real,
    /// Points given.
    pub points: usize,
    /// The last round's Tukey cut (σ units; `None`: no reweighting round), so that
    /// [`calibration_sigma_radius`] weighs the points as the fit did.
    pub cut: Option<Real>,
}

impl SphereFit {
    /// 1σ of the radius (metres).
    pub fn sigma_radius(&self) -> Real {
        sqrt(self.covariance[(3, 3)].max(0.0))
    }
}

/// The problem: residuals `(|Xⱼ − C| − R)/σⱼ` with weights frozen at the previous round.
struct Joint<'a> {
    curves: &'a [&'a [Vec3]],
    sigmas: &'a [&'a [Real]],
    planes: &'a [LaserPlane],
    /// The sphere whose normals project the σ (the previous round's), fixed within a round.
    normals_of: Sphere,
    /// Floor of the weights' projection ([`SphereFitParams::min_normal_share`]).
    min_share: Real,
    /// The errors' direction-free share ([`SphereFitParams::direction_free_share`]).
    kappa: Real,
    /// Previous round's Tukey cut (in σ units); `None` in the first round.
    cut: Option<Real>,
}

/// Unit direction in which a point `x` of laser plane `plane` moves when its stripe's row
/// moves: the line the plane shares with the camera's column plane through `x` (the plane of
/// the rays of one image column, normal `(z, 0, −x)` for a pinhole).
fn displacement_direction(plane: &LaserPlane, x: Vec3) -> Option<Vec3> {
    let column_normal = Vec3::new(x.z, 0.0, -x.x);
    let d = plane.normal.cross(&column_normal);
    let len = norm(&d);
    (len > 0.0).then(|| d / len)
}

/// One point as the fit sees it.
#[derive(Debug, Clone, Copy)]
struct Term {
    /// The point.
    x: Vec3,
    /// The σ its weight uses: `σ·max(|d̂·n̂|, floor)`.
    weight_sigma: Real,
    /// The σ of its error normal to the ball: `σ·√((d̂·n̂)² + κ²)`.
    error_sigma: Real,
    /// Its Tukey weight.
    w: Real,
}

impl Joint<'_> {
    /// Each point with its σ normal to the sphere and its weight.
    fn each(&self, mut f: impl FnMut(Term)) {
        let reference = self.normals_of;
        for ((curve, sigmas), plane) in self.curves.iter().zip(self.sigmas).zip(self.planes) {
            for (p, s) in curve.iter().zip(sigmas.iter()) {
                let to_point = p - reference.centre;
                let distance = norm(&to_point);
                let share = match displacement_direction(plane, *p) {
                    Some(d) if distance > 0.0 => (d.dot(&to_point) / distance).abs(),
                    _ => 1.0,
                };
                let sigma = s * share.max(self.min_share);
                let w = match self.cut {
                    None => 1.0,
                    Some(cut) => tukey((distance - reference.radius) / (sigma * cut)),
                };
                f(Term {
                    x: *p,
                    weight_sigma: sigma,
                    error_sigma: s * sqrt(share * share + self.kappa * self.kappa),
                    w,
                });
            }
        }
    }
}

impl SphereCost for Joint<'_> {
    fn normal_equations(&self, sphere: &Sphere) -> Result<NormalEquations<4>, SolveError> {
        let (centre, radius) = (sphere.centre, sphere.radius);
        let mut jtj = SMatrix::<Real, 4, 4>::zeros();
        let mut jtr = SVector::<Real, 4>::zeros();
        let mut cost = 0.0;
        let mut bad = false;
        self.each(
            |Term {
                 x,
                 weight_sigma: sigma,
                 w,
                 ..
             }| {
                if !(w > 0.0) {
                    return;
                }
                let d = x - centre;
                let len = norm(&d);
                if !(len > 0.0 && sigma > 0.0) {
                    bad = true;
                    return;
                }
                let inv = 1.0 / sigma;
                let e = (len - radius) * inv;
                let u = d / len;
                let j = SVector::<Real, 4>::new(-u.x * inv, -u.y * inv, -u.z * inv, -inv);
                jtj += j * j.transpose() * w;
                jtr += j * (w * e);
                cost += w * e * e;
            },
        );
        if bad || !cost.is_finite() || !(radius > 0.0) {
            return Err(SolveError::Degenerate);
        }
        Ok(NormalEquations { jtj, jtr, cost })
    }
}

/// Fits a sphere to the points of every curve (`curves[k]` of plane `planes[k]`, with 1σ
/// `sigmas[k]` along the stripe's displacement, same lengths) from `start` (the sections'
/// sphere): a fit weighted by each point's σ projected on the sphere's normal, then `rounds` Tukey
/// reweightings at the robust scale of the normalised residuals (at least 1, so that points
/// as noisy as predicted are all kept). `scratch` (at least the total point count) holds the
/// residuals for the median.
///
/// Errors: fewer than 5 points, a point with a non-positive σ, non-finite data, a singular
/// normal matrix, no convergence.
pub fn fit_sphere(
    curves: &[&[Vec3]],
    sigmas: &[&[Real]],
    planes: &[LaserPlane],
    start: Sphere,
    params: &SphereFitParams,
    scratch: &mut [Real],
) -> Result<SphereFit, SolveError> {
    params.lm.validate()?;
    if !(params.tuning > 0.0
        && params.min_normal_share > 0.0
        && params.min_normal_share <= 1.0
        && params.direction_free_share >= 0.0
        && params.direction_free_share.is_finite())
        || curves.len() != sigmas.len()
        || curves.len() > planes.len()
    {
        return Err(SolveError::InvalidParameter);
    }
    let total: usize = curves.iter().map(|c| c.len()).sum();
    if curves.iter().zip(sigmas).any(|(c, s)| c.len() != s.len()) {
        return Err(SolveError::InvalidParameter);
    }
    if total < 5 {
        return Err(SolveError::TooFewPoints);
    }
    let buf = scratch
        .get_mut(..total)
        .ok_or(SolveError::ScratchTooSmall)?;
    let mut problem = Joint {
        curves,
        sigmas,
        planes,
        normals_of: start,
        min_share: params.min_normal_share,
        kappa: params.direction_free_share,
        cut: None,
    };
    let (mut sphere, mut normal) = minimise_sphere(&problem, start, &params.lm)?;
    for _ in 0..params.rounds {
        problem.normals_of = sphere;
        problem.cut = None;
        let mut k = 0;
        problem.each(|t| {
            buf[k] = ((norm(&(t.x - sphere.centre)) - sphere.radius) / t.weight_sigma).abs();
            k += 1;
        });
        let mid = buf.len() / 2;
        let (_, median, _) = buf.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        let scale = (1.4826 * *median).max(1.0);
        problem.cut = Some(params.tuning * scale);
        (sphere, normal) = minimise_sphere(&problem, sphere, &params.lm)?;
    }
    // The covariance (`docs/sphere.md`, "Uncertainty of the joint fit"): the weights are
    // `1/σ_w²` (projected), the errors' variances `σ_e²` (projected and direction-free), so
    // the estimator's covariance is the sandwich `A⁻¹ B A⁻¹` with `A = Σ w jjᵀ/σ_w²` (the
    // normal matrix) and `B = Σ w² jjᵀ σ_e²/σ_w⁴`, its scale the residuals' own against
    // `σ_e` (`Σ w e²/σ_e² / (Σw − 4)`).
    let (mut weight_sum, mut inliers, mut error_chi2) = (0.0, 0usize, 0.0);
    let mut meat = SMatrix::<Real, 4, 4>::zeros();
    problem.each(|t| {
        weight_sum += t.w;
        if t.w > 0.0 {
            inliers += 1;
            let d = t.x - sphere.centre;
            let len = norm(&d);
            let e = len - sphere.radius;
            error_chi2 += t.w * e * e / (t.error_sigma * t.error_sigma);
            if len > 0.0 {
                let u = d / len;
                let j = SVector::<Real, 4>::new(-u.x, -u.y, -u.z, -1.0);
                let v = t.error_sigma / (t.weight_sigma * t.weight_sigma);
                meat += j * j.transpose() * (t.w * t.w * v * v);
            }
        }
    });
    if !(weight_sum > 4.0) {
        return Err(SolveError::TooFewPoints);
    }
    let reduced_chi2 = normal.cost / (weight_sum - 4.0);
    let error_scale = error_chi2 / (weight_sum - 4.0);
    // Residual correlation along each curve (speckle, smoothing, defocus) over the inliers:
    // curve k's n_k points count as n_k/L_k independent ones, and the fit's variance is
    // that of Σ n_k/L_k points (`docs/sphere.md`, "Uncertainty of the joint fit").
    let (mut used, mut independent) = (0.0, 0.0);
    let (mut least_inlier_share, mut worst_curve_scale): (Real, Real) = (1.0, 0.0);
    for k in 0..curves.len() {
        let one = Joint {
            curves: &curves[k..k + 1],
            sigmas: &sigmas[k..k + 1],
            planes: &planes[k..k + 1],
            ..problem
        };
        let mut n = 0;
        one.each(|t| {
            if t.w > 0.0 {
                if let Some(slot) = buf.get_mut(n) {
                    *slot = (norm(&(t.x - sphere.centre)) - sphere.radius) / t.error_sigma;
                    n += 1;
                }
            }
        });
        if n > 0 {
            used += n as Real;
            independent += n as Real / correlation_length(&buf[..n]);
            for v in buf[..n].iter_mut() {
                *v = v.abs();
            }
            let (_, median, _) = buf[..n].select_nth_unstable_by(n / 2, |a, b| a.total_cmp(b));
            worst_curve_scale = worst_curve_scale.max(1.4826 * *median);
        }
        if !curves[k].is_empty() {
            least_inlier_share = least_inlier_share.min(n as Real / curves[k].len() as Real);
        }
    }
    let inflation = if independent > 0.0 {
        used / independent
    } else {
        1.0
    };
    let bread = spd_inverse(&normal.jtj).ok_or(SolveError::Degenerate)?;
    let covariance = bread * meat * bread * (error_scale * inflation);
    Ok(SphereFit {
        sphere,
        covariance,
        reduced_chi2,
        inliers,
        least_inlier_share,
        worst_curve_scale,
        points: total,
        cut: problem.cut,
    })
}

/// 1σ of the fitted radius from the calibration's errors (`docs/sphere.md`, "Calibration
/// errors", (S-cal)): each error moves every point it touches by a known displacement
/// `δXⱼ` (`noise::calibration_displacements`: the pixel kept, the point re-triangulated),
/// the residuals by `n̂ⱼ·δXⱼ`, and the fit — linearised at its solution, with its own
/// weights — by `δθ = A⁻¹ Σ cⱼ (n̂ⱼ, 1)(n̂ⱼ·δXⱼ)`, `A = Σ cⱼ (n̂ⱼ, 1)(n̂ⱼ, 1)ᵀ`,
/// `cⱼ = wⱼ/σ_wⱼ²`. The focal length is the camera's, one error for every point; each
/// plane's baseline `e` and tilt `δ` are calibrated from its own board poses, so they are
/// independent errors, one pair per plane. A difference between the planes' errors shifts
/// one section against the other along the line of sight, which for the front arcs a camera
/// sees is nearly a change of radius: that is the term a common scale misses.
///
/// When the planes were refined against each other on a reference, their errors are
/// correlated (`uncertainty`, [`PlanesUncertainty`]): each plane's `e` and `δ` are then moved
/// by their own posterior 1σ and the radius's shifts combined through the correlation
/// (`docs/calibration.md` §14), so the difference the reference pinned down no longer counts
/// at the board's budget.
///
/// `curves`, `sigmas`, `planes` as given to [`fit_sphere`]; `noise` the calibration σ,
/// `focal_px` the camera's. Errors: a plane or point that cannot be re-triangulated, or a
/// singular normal matrix ([`SolveError::Degenerate`]).
#[allow(clippy::too_many_arguments)]
pub fn calibration_sigma_radius(
    fit: &SphereFit,
    curves: &[&[Vec3]],
    sigmas: &[&[Real]],
    planes: &[LaserPlane],
    params: &SphereFitParams,
    noise: &NoiseModel,
    focal_px: Real,
    uncertainty: Option<&PlanesUncertainty>,
) -> Result<Real, SolveError> {
    let n = curves
        .len()
        .min(sigmas.len())
        .min(planes.len())
        .min(MAX_PLANES);
    let centre = fit.sphere.centre;
    let mut a = SMatrix::<Real, 4, 4>::zeros();
    // Right-hand sides: the focal length's, then each plane's `e` and `δ`.
    let mut focal = SVector::<Real, 4>::zeros();
    let mut per_plane = [[SVector::<Real, 4>::zeros(); 2]; MAX_PLANES];
    let mut failed = false;
    for k in 0..n {
        // Each plane moved by its own 1σ: the board's budget, or the refinement's posterior.
        let plane_noise = noise.for_plane(k, uncertainty);
        let (by_e, ray_scale, by_tilt) = noise::perturbed(&planes[k], focal_px, &plane_noise)
            .map_err(|_| SolveError::Degenerate)?;
        let one = Joint {
            curves: &curves[k..k + 1],
            sigmas: &sigmas[k..k + 1],
            planes: &planes[k..k + 1],
            normals_of: fit.sphere,
            min_share: params.min_normal_share,
            kappa: params.direction_free_share,
            cut: fit.cut,
        };
        one.each(|t| {
            let d = t.x - centre;
            let len = norm(&d);
            if !(t.w > 0.0 && len > 0.0 && t.weight_sigma > 0.0) {
                return;
            }
            let u = d / len;
            let j = SVector::<Real, 4>::new(u.x, u.y, u.z, 1.0);
            let c = t.w / (t.weight_sigma * t.weight_sigma);
            a += j * j.transpose() * c;
            let moved = |plane: &LaserPlane, scale: Real| {
                noise::retriangulate(t.x, plane, scale).map(|y| u.dot(&(y - t.x)))
            };
            match (
                moved(&planes[k], ray_scale),
                moved(&by_e, 1.0),
                moved(&by_tilt, 1.0),
            ) {
                (Ok(f), Ok(e), Ok(tilt)) => {
                    focal += j * (c * f);
                    per_plane[k][0] += j * (c * e);
                    per_plane[k][1] += j * (c * tilt);
                }
                _ => failed = true,
            }
        });
    }
    if failed {
        return Err(SolveError::Degenerate);
    }
    let inverse = spd_inverse(&a).ok_or(SolveError::Degenerate)?;
    let radius_of = |b: &SVector<Real, 4>| (inverse * b)[3];
    noise::calibration_spread(uncertainty, radius_of(&focal), n, |k, p| {
        radius_of(&per_plane[k][p])
    })
    .ok_or(SolveError::NonFinite)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::calibration::Calibration;
    use std::vec::Vec;

    /// Points of both reference planes' sections of a ball of radius `r` at `z`, facing the
    /// camera, each moved along the ball's normal by a deterministic ±`noise` pattern.
    fn sections(z: Real, r: Real, noise: Real) -> (Calibration, [Vec<Vec3>; 2], Sphere) {
        let cal = Calibration::reference_design();
        let y = |p: &LaserPlane| (p.offset - p.normal.z * z) / p.normal.y;
        let centre = Vec3::new(0.0, 0.5 * (y(&cal.planes[0]) + y(&cal.planes[1])), z);
        let mut out = [Vec::new(), Vec::new()];
        for (k, plane) in cal.planes.iter().enumerate() {
            let (a, b) = plane.plane_axes();
            let h = (centre - plane.source).dot(&plane.normal);
            let rho = sqrt(r * r - h * h);
            let foot = centre - plane.normal * h;
            for i in 0..400 {
                let t = i as Real / 400.0 * 2.0 * crate::real::PI;
                let x = foot + (a * t.cos() + b * t.sin()) * rho;
                if (x - centre).dot(&(-x)) <= 0.0 || (x - centre).dot(&(plane.source - x)) <= 0.0 {
                    continue;
                }
                let n = (x - centre) / r;
                let wiggle = [1.0, -0.6, 0.3, -1.2, 0.8, -0.4, 0.1][i % 7];
                out[k].push(x + n * (noise * wiggle));
            }
        }
        (cal, out, Sphere { centre, radius: r })
    }

    fn fit(scale: Real, params: &SphereFitParams) -> SphereFit {
        let (cal, curves, truth) = sections(1.0, 0.1, 2e-4);
        let sig: Vec<Vec<Real>> = curves
            .iter()
            .map(|c| std::vec![1e-3 * scale; c.len()])
            .collect();
        let refs: [&[Vec3]; 2] = [&curves[0], &curves[1]];
        let sigs: [&[Real]; 2] = [&sig[0], &sig[1]];
        let mut scratch = std::vec![0.0; curves[0].len() + curves[1].len()];
        let start = Sphere {
            centre: truth.centre + Vec3::new(0.002, -0.001, 0.003),
            radius: truth.radius * 1.02,
        };
        fit_sphere(&refs, &sigs, &cal.planes, start, params, &mut scratch).expect("fits")
    }

    /// The calibration σ of the radius against re-fits: each calibration error applied to
    /// the points it moves (re-triangulated, exact), the sphere fitted again, the radius
    /// changes added in quadrature. A 300 mm ball at 1.5 m, where one plane's tilt error
    /// shifts its section along the line of sight by millimetres.
    #[test]
    fn the_calibration_sigma_is_the_refits_spread() {
        let (cal, curves, truth) = sections(1.5, 0.15, 0.0);
        let sig: Vec<Vec<Real>> = curves.iter().map(|c| std::vec![5e-4; c.len()]).collect();
        let sigs: [&[Real]; 2] = [&sig[0], &sig[1]];
        let params = SphereFitParams::default();
        let noise = NoiseModel::reference();
        let focal = 1000.0;
        let mut scratch = std::vec![0.0; curves[0].len() + curves[1].len()];
        let refit = |curves: &[Vec<Vec3>; 2], scratch: &mut [Real]| {
            let refs: [&[Vec3]; 2] = [&curves[0], &curves[1]];
            fit_sphere(&refs, &sigs, &cal.planes, truth, &params, scratch).expect("fits")
        };
        let base = refit(&curves, &mut scratch);
        let refs: [&[Vec3]; 2] = [&curves[0], &curves[1]];
        let stated = calibration_sigma_radius(
            &base,
            &refs,
            &sigs,
            &cal.planes,
            &params,
            &noise,
            focal,
            None,
        )
        .expect("evaluates");
        let moved = |k: Option<usize>, which: usize| -> Real {
            let mut c = curves.clone();
            for (j, curve) in c.iter_mut().enumerate() {
                if k.is_some_and(|k| k != j) {
                    continue;
                }
                let (pe, pf, pd) = noise::perturbed(&cal.planes[j], focal, &noise).unwrap();
                for x in curve.iter_mut() {
                    *x = match which {
                        0 => noise::retriangulate(*x, &pe, 1.0),
                        1 => noise::retriangulate(*x, &cal.planes[j], pf),
                        _ => noise::retriangulate(*x, &pd, 1.0),
                    }
                    .unwrap();
                }
            }
            let mut scratch = std::vec![0.0; c[0].len() + c[1].len()];
            refit(&c, &mut scratch).sphere.radius - base.sphere.radius
        };
        let mut variance = moved(None, 1).powi(2);
        for k in 0..2 {
            variance += moved(Some(k), 0).powi(2) + moved(Some(k), 2).powi(2);
        }
        let refits = sqrt(variance);
        // A third of a millimetre on the radius: several times the common scale's share.
        assert!(refits > 1e-4, "{refits}");
        assert!(
            ((stated - refits) / refits).abs() < 0.1,
            "stated {stated} against re-fits {refits}"
        );
    }

    /// Under a refinement's covariance the planes' errors are correlated. With both tilts
    /// off by the same 1σ (correlation 1) the stated planes' term is the re-fit's change
    /// under that common move (a common scale and shift, not the two sections' difference),
    /// not what the same σ uncorrelated give; with the board's σ and no correlation it is
    /// the independent term.
    #[test]
    fn the_planes_covariance_is_the_correlated_refits_spread() {
        let (cal, curves, truth) = sections(1.5, 0.15, 0.0);
        let sig: Vec<Vec<Real>> = curves.iter().map(|c| std::vec![5e-4; c.len()]).collect();
        let sigs: [&[Real]; 2] = [&sig[0], &sig[1]];
        let refs: [&[Vec3]; 2] = [&curves[0], &curves[1]];
        let params = SphereFitParams::default();
        let noise = NoiseModel::reference();
        let focal = 1000.0;
        let mut scratch = std::vec![0.0; curves[0].len() + curves[1].len()];
        let base =
            fit_sphere(&refs, &sigs, &cal.planes, truth, &params, &mut scratch).expect("fits");
        let stated = |u: Option<&PlanesUncertainty>| {
            calibration_sigma_radius(&base, &refs, &sigs, &cal.planes, &params, &noise, focal, u)
                .expect("evaluates")
        };
        let identity = |e: Real, t: Real| {
            PlanesUncertainty::new(
                &[e, t, e, t],
                &[
                    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
                ],
            )
            .unwrap()
        };
        let board = identity(noise.baseline, noise.tilt);
        let independent = stated(None);
        assert!(((stated(Some(&board)) - independent) / independent).abs() < 1e-6);
        // The focal length's share alone: every plane known exactly.
        let focal_only = stated(Some(&identity(0.0, 0.0)));
        let common_tilt = PlanesUncertainty::new(
            &[0.0, noise.tilt, 0.0, noise.tilt],
            &[
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0,
            ],
        )
        .unwrap();
        let planes_term = sqrt(stated(Some(&common_tilt)).powi(2) - focal_only.powi(2));
        // The re-fit with both planes' tilts moved by σ at once.
        let mut moved = curves.clone();
        for (k, curve) in moved.iter_mut().enumerate() {
            let (_, _, by_tilt) = noise::perturbed(&cal.planes[k], focal, &noise).unwrap();
            for x in curve.iter_mut() {
                *x = noise::retriangulate(*x, &by_tilt, 1.0).unwrap();
            }
        }
        let moved_refs: [&[Vec3]; 2] = [&moved[0], &moved[1]];
        let refit = fit_sphere(
            &moved_refs,
            &sigs,
            &cal.planes,
            truth,
            &params,
            &mut scratch,
        )
        .expect("fits")
        .sphere
        .radius
            - base.sphere.radius;
        assert!(
            (planes_term - refit.abs()).abs() < 0.1 * refit.abs() + 2e-6,
            "stated {planes_term} against the re-fit {refit}"
        );
        // The same σ uncorrelated is another number: the correlation is used.
        let uncorrelated =
            sqrt(stated(Some(&identity(0.0, noise.tilt))).powi(2) - focal_only.powi(2));
        assert!(
            (planes_term - uncorrelated).abs() > 0.2 * uncorrelated,
            "{planes_term} {uncorrelated}"
        );
    }

    /// The stated covariance comes from the residuals: the points' σ set only their relative
    /// errors, so scaling every σ leaves the sphere and its covariance unchanged (without the
    /// Tukey rounds, whose cut is floored at one σ).
    #[test]
    fn the_covariance_is_the_datas_not_the_sigmas_scale() {
        let params = SphereFitParams {
            rounds: 0,
            ..SphereFitParams::default()
        };
        let (a, b) = (fit(1.0, &params), fit(10.0, &params));
        assert!((a.sphere.radius - b.sphere.radius).abs() < 1e-5 * a.sphere.radius);
        let (sa, sb) = (a.sigma_radius(), b.sigma_radius());
        assert!(sa > 0.0 && ((sa - sb) / sa).abs() < 1e-4, "{sa} vs {sb}");
    }

    /// The weights do not depend on `κ`, so neither does the sphere; the stated σ does (it
    /// is the errors' model).
    #[test]
    fn kappa_changes_the_sigma_not_the_sphere() {
        let small = SphereFitParams {
            direction_free_share: 0.0,
            ..SphereFitParams::default()
        };
        let large = SphereFitParams {
            direction_free_share: 2.0,
            ..SphereFitParams::default()
        };
        let (a, b) = (fit(1.0, &small), fit(1.0, &large));
        assert_eq!(a.sphere, b.sphere);
        assert!(b.sigma_radius() != a.sigma_radius());
        assert!(a.sigma_radius() > 0.0 && b.sigma_radius() > 0.0);
    }
}
