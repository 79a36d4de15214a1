//! The calibration's part of the whole-arc cylinder fit's radius σ (`docs/cylinder.md`,
//! "Calibration errors of the two-plane fit", (Cy-cal)): each calibration error moves every
//! point it touches, and the fit, linearised at its solution with its own weights, moves
//! with them. As the sphere's (S-cal) ([`crate::solvers::sphere_fit::calibration_sigma_radius`]),
//! of which this is the cylinder's counterpart.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, Real, Vec3};

use super::{basis, Cylinder, CylinderFit, M5, V5};
use crate::calibration::{PlanesUncertainty, MAX_PLANES};
use crate::laser_plane::LaserPlane;
use crate::noise::{self, NoiseModel};
use crate::solvers::lm::spd_inverse;
use crate::solvers::SolveError;

/// 1σ of the fitted radius from the calibration's errors, (Cy-cal): the pixel kept, each
/// point `xⱼ` re-triangulated with the focal length or one plane's baseline `e` or tilt `δ`
/// moved by its 1σ (`δXⱼ`), its residual moves by `ρ̂ⱼ·δXⱼ` (`ρ̂ⱼ` the radial direction
/// from the axis), and the fit by `δθ = A⁻¹ Σ cⱼ Jⱼ (ρ̂ⱼ·δXⱼ)`, `A = Σ cⱼ Jⱼ Jⱼᵀ`, with the
/// fit's own weights `cⱼ` and Jacobian `Jⱼ` (axis point, axis direction, radius).
///
/// The focal length is one error common to every point. Each plane's `e` and `δ` are
/// calibrated from its own board poses, independent of the other plane's: a difference
/// between them shifts one section against the other along the line of sight, which the fit
/// reads as a lean of the axis and a change of radius — the term the one-plane path's common
/// scale ([`noise::calibration_relative_sigma`]) misses (`docs/accuracy.md`, "calibration
/// errors": held out, within 2σ fell from 96 to 79 % without it). With `uncertainty` (planes
/// refined against each other on a reference, `docs/calibration.md` §14) each plane's `e`
/// and `δ` move by their posterior 1σ and the radius's shifts combine through the
/// correlation ([`PlanesUncertainty::spread_under`]).
///
/// `fit` and `weights` ([`super::fit_weights`]) from the [`super::fit_cylinder_weighted`] of
/// `curves`; `planes` the curves' planes; `calibration` the board's σ; `focal_px` the
/// camera's. Errors: fewer weights than points, a point that cannot be re-triangulated, or a
/// singular normal matrix ([`SolveError::Degenerate`]); a non-finite result
/// ([`SolveError::NonFinite`]).
pub fn calibration_sigma_radius(
    fit: &CylinderFit,
    curves: &[&[Vec3]],
    weights: &[Real],
    planes: &[LaserPlane],
    calibration: &NoiseModel,
    focal_px: Real,
    uncertainty: Option<&PlanesUncertainty>,
) -> Result<Real, SolveError> {
    let n = curves.len().min(planes.len()).min(MAX_PLANES);
    let Cylinder {
        point: p,
        axis: u,
        radius: length,
    } = fit.cylinder;
    // The axis's tilt in units of the radius (a length), so that every column of `A` is of
    // the same order in f32; the radius's row is unchanged by that choice.
    if !(length > 0.0) {
        return Err(SolveError::Degenerate);
    }
    let (e1, e2) = basis(u);
    let mut a = M5::zeros();
    // Right-hand sides: the focal length's, then each plane's `e` and `δ`.
    let mut focal = V5::zeros();
    let mut per_plane = [[V5::zeros(); 2]; MAX_PLANES];
    let mut weights = weights.iter();
    for k in 0..n {
        let plane = &planes[k];
        let (by_e, ray_scale, by_tilt) =
            noise::perturbed(plane, focal_px, &calibration.for_plane(k, uncertainty))
                .map_err(|_| SolveError::Degenerate)?;
        for &x in curves[k].iter() {
            let c = *weights.next().ok_or(SolveError::Degenerate)?;
            if !(c > 0.0) {
                continue;
            }
            let w = x - p;
            let along = w.dot(&u);
            let q = w - u * along;
            let rho = norm(&q);
            if !(rho > 0.0) {
                continue;
            }
            let radial = q / rho;
            let (g1, g2) = (radial.dot(&e1), radial.dot(&e2));
            let along = along / length;
            let j = V5::new(g1, g2, along * g1, along * g2, 1.0);
            // The upper triangle, mirrored below (as the fit's own normal equations).
            for r in 0..5 {
                for s in r..5 {
                    a[(r, s)] += j[r] * j[s] * c;
                }
            }
            // `noise::retriangulate` for a point already on its pixel's ray `x`: the ray
            // meets a plane `(n, d)` at `x·d/(n·x)`, so the residual moves by
            // `ρ̂·x·(d'/(n'·x) − d/(n·x))` (the nominal plane's own re-triangulation
            // subtracted: a point off its plane, a test's jitter, moves only by the error);
            // with the focal length scaled the ray is `x` with its `x` and `y` scaled. A dot
            // product and a division per error, not a ray intersection with its checks: this
            // loop runs over every point on the device.
            let on_x = radial.dot(&x);
            let at = |plane: &LaserPlane, ray: Vec3| {
                let denom = plane.normal.dot(&ray);
                if denom > 0.0 {
                    Ok(plane.offset / denom)
                } else {
                    Err(SolveError::Degenerate)
                }
            };
            let nominal = on_x * at(plane, x)?;
            let shift = |plane: &LaserPlane, ray: Vec3, on_ray: Real| {
                at(plane, ray).map(|t| c * (on_ray * t - nominal))
            };
            let scaled = Vec3::new(x.x * ray_scale, x.y * ray_scale, x.z);
            focal += j * shift(plane, scaled, radial.dot(&scaled))?;
            per_plane[k][0] += j * shift(&by_e, x, on_x)?;
            per_plane[k][1] += j * shift(&by_tilt, x, on_x)?;
        }
    }
    for r in 0..5 {
        for s in 0..r {
            a[(r, s)] = a[(s, r)];
        }
    }
    let inverse = spd_inverse(&a).ok_or(SolveError::Degenerate)?;
    let radius_of = |b: &V5| (inverse * b)[4];
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
    use crate::real::sqrt;
    use crate::real::{Vec2, PI};
    use crate::solvers::circle::RobustParams;
    use crate::solvers::cylinder_fit::tests::{section, tilted_cylinder};
    use crate::solvers::cylinder_fit::{
        fit_cylinder_weighted, fit_weights, WeightedCylinderFit, CYLINDER_SCRATCH_PER_POINT,
    };
    use std::vec::Vec;

    /// Both reference planes' sections of a 300 mm stem at 1.4 m leaning 15° and 20°, each
    /// point moved along its noise direction (in its plane, as a stripe's row error moves
    /// it) by a deterministic ±0.3 mm pattern.
    fn stem() -> (Calibration, [Vec<Vec3>; 2], Cylinder) {
        let cal = Calibration::reference_design();
        let deg = PI / 180.0;
        let truth = tilted_cylinder(
            15.0 * deg,
            20.0 * deg,
            0.15,
            Vec2::new(0.05, 1.4),
            &cal.planes[0],
        );
        let mut out = [Vec::new(), Vec::new()];
        for (k, curve) in out.iter_mut().enumerate() {
            section(&truth, &cal.planes[k], 1200, curve);
            let field = noise::DisplacementField::of(&cal.planes[k]);
            for (i, x) in curve.iter_mut().enumerate() {
                let wiggle = [1.0, -0.6, 0.3, -1.2, 0.8, -0.4, 0.1][i % 7];
                *x += field.direction(*x) * (3e-4 * wiggle);
            }
        }
        (cal, out, truth)
    }

    /// Every point 0.5 mm along its plane's noise direction.
    fn noise_of<'a>(
        cal: &'a Calibration,
        curves: &'a [Vec<Vec3>; 2],
    ) -> impl Fn(usize, usize) -> Vec3 + Copy + 'a {
        move |k, i| noise::DisplacementField::of(&cal.planes[k]).direction(curves[k][i]) * 5e-4
    }

    /// The weighted fit of `curves` from `start`, and its points' weights.
    fn fit(
        cal: &Calibration,
        curves: &[Vec<Vec3>; 2],
        start: Cylinder,
    ) -> (CylinderFit, Vec<Real>) {
        let refs: [&[Vec3]; 2] = [&curves[0], &curves[1]];
        let points = curves[0].len() + curves[1].len();
        let mut scratch = std::vec![0.0; CYLINDER_SCRATCH_PER_POINT * points];
        let WeightedCylinderFit { fit, .. } = fit_cylinder_weighted(
            &refs,
            noise_of(cal, curves),
            start,
            &RobustParams::default(),
            &mut scratch,
        )
        .expect("fits");
        (
            fit,
            fit_weights(&scratch, points).expect("scratch").to_vec(),
        )
    }

    /// `curves` with plane `k`'s points (every plane's with `None`) re-triangulated under
    /// the calibration error `which` (0: `e`, 1: `f`, 2: `δ`) of `noise`.
    fn moved(
        cal: &Calibration,
        curves: &[Vec<Vec3>; 2],
        k: Option<usize>,
        which: usize,
        noise: &NoiseModel,
    ) -> [Vec<Vec3>; 2] {
        let mut c = curves.clone();
        for (j, curve) in c.iter_mut().enumerate() {
            if k.is_some_and(|k| k != j) {
                continue;
            }
            let (pe, pf, pd) = noise::perturbed(&cal.planes[j], 1000.0, noise).unwrap();
            for x in curve.iter_mut() {
                *x = match which {
                    0 => noise::retriangulate(*x, &pe, 1.0),
                    1 => noise::retriangulate(*x, &cal.planes[j], pf),
                    _ => noise::retriangulate(*x, &pd, 1.0),
                }
                .unwrap();
            }
        }
        c
    }

    /// The calibration σ a unit refined on a reference has, about a tenth of the board's
    /// budget (`docs/calibration.md` §12–13): small enough for the fit's response to be
    /// linear. At the full budget a plane's tilt error shifts its section by ≈ 4 mm at
    /// 1.4 m, the axis leans by degrees, and the re-fit's radius change is up to twice the
    /// linear one for a single error (`docs/cylinder.md`, (Cy-cal): measured over drawn
    /// calibrations instead).
    fn refined() -> NoiseModel {
        let board = NoiseModel::reference();
        NoiseModel {
            baseline: 0.1 * board.baseline,
            tilt: 0.1 * board.tilt,
            focal_px: 0.1 * board.focal_px,
            ..board
        }
    }

    /// The stated σ against re-fits: each calibration error applied to the points it moves
    /// (re-triangulated, exact), the cylinder fitted again, the radius changes added in
    /// quadrature.
    #[test]
    fn the_calibration_sigma_is_the_refits_spread() {
        let (cal, curves, truth) = stem();
        let noise = refined();
        let base = fit(&cal, &curves, truth);
        let refs: [&[Vec3]; 2] = [&curves[0], &curves[1]];
        let stated =
            calibration_sigma_radius(&base.0, &refs, &base.1, &cal.planes, &noise, 1000.0, None)
                .expect("evaluates");
        let change = |c: [Vec<Vec3>; 2]| {
            fit(&cal, &c, base.0.cylinder).0.cylinder.radius - base.0.cylinder.radius
        };
        let mut variance = change(moved(&cal, &curves, None, 1, &noise)).powi(2);
        for k in 0..2 {
            for which in [0, 2] {
                variance += change(moved(&cal, &curves, Some(k), which, &noise)).powi(2);
            }
        }
        let refits = sqrt(variance);
        // Tens of micrometres on the radius at a tenth of the budget: far above the fits'
        // convergence (≈ 1 % of the fit's σ, 0.25 µm here).
        assert!(refits > 2e-5, "{refits}");
        assert!(
            ((stated - refits) / refits).abs() < 0.1,
            "stated {stated} against re-fits {refits}"
        );
    }

    /// Under a refinement's covariance the planes' errors are correlated: with both tilts
    /// off by the same 1σ (correlation 1) the stated planes' term is the re-fit's change
    /// under that common move, far below what the same σ uncorrelated give; with the σ as
    /// independent planes and no correlation it is the independent term.
    #[test]
    fn the_calibration_sigma_follows_the_planes_correlation() {
        let (cal, curves, truth) = stem();
        let noise = refined();
        let base = fit(&cal, &curves, truth);
        let refs: [&[Vec3]; 2] = [&curves[0], &curves[1]];
        let stated = |u: Option<&PlanesUncertainty>| {
            calibration_sigma_radius(&base.0, &refs, &base.1, &cal.planes, &noise, 1000.0, u)
                .expect("evaluates")
        };
        let independent = |e: Real, t: Real| {
            PlanesUncertainty::new(
                &[e, t, e, t],
                &[
                    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
                ],
            )
            .unwrap()
        };
        let board = stated(None);
        let same = stated(Some(&independent(noise.baseline, noise.tilt)));
        assert!(((same - board) / board).abs() < 1e-5, "{same} {board}");
        let focal_only = stated(Some(&independent(0.0, 0.0)));
        let common_tilt = PlanesUncertainty::new(
            &[0.0, noise.tilt, 0.0, noise.tilt],
            &[
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0,
            ],
        )
        .unwrap();
        let planes_term = sqrt((stated(Some(&common_tilt)).powi(2) - focal_only.powi(2)).max(0.0));
        let both = moved(&cal, &curves, None, 2, &noise);
        let refit =
            (fit(&cal, &both, base.0.cylinder).0.cylinder.radius - base.0.cylinder.radius).abs();
        assert!(
            (planes_term - refit).abs() < 0.1 * refit + 1e-6,
            "stated {planes_term} against the re-fit {refit}"
        );
        let uncorrelated = sqrt(
            (stated(Some(&independent(0.0, noise.tilt))).powi(2) - focal_only.powi(2)).max(0.0),
        );
        assert!(
            uncorrelated > 3.0 * planes_term,
            "{uncorrelated} {planes_term}"
        );
    }
}
