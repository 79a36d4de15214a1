//! The laser planes refined against each other on captures of a reference surface: a ball
//! (`tangent calibrate ball`) or a flat wall (`tangent calibrate wall`; `docs/calibration.md`,
//! section 12, "Refining the planes on a ball", and section 13, "… on a flat wall").
//!
//! The board calibration ([`super::laser`]) fixes each plane's baseline `e` and tilt `δ` to
//! the σ the error model carries (0.2 mm, 0.2 mrad), each plane from its own stripe points.
//! One plane's tilt error moves its section along the line of sight by `z²·Δδ/e`; a fit that
//! combines two sections (a ball, a leaning stem) reads that as size or lean
//! (`docs/error-model.md`, "Calibration errors across two planes"). A ball, of any size, cut
//! by two planes is a check of exactly that: both sections must lie on one sphere. Seen at
//! several distances it determines the planes' *relative* `e` and `δ` (the shift grows as `z`
//! for `e` and as `z²` for `δ`). A flat wall lit by lines that cross is a stronger check:
//! every line must lie in one plane.
//!
//! The refinement: every point of plane `k` was triangulated with the plane `(n, d)`; on the
//! plane `(n', d')` of the corrected `e`, `δ` the same pixel's ray gives `X' = X·d'/(n'·X)`
//! (the camera, hence the ray, is unchanged). The corrections `u` (in units of their prior
//! σ) minimise `|u|² + Σ_views min_surface Σ_points (t/s)²`, `t` a point's distance along
//! its stripe's displacement line to the view's surface: the prior keeps what the reference
//! cannot see (the common scale) at the board's value, and each view's surface is re-fitted
//! for every `u` (variable projection). `s` is a view
//! plane's robust residual scale times the square root of its residuals' correlation length,
//! so the posterior covariance `(JᵀJ)⁻¹` counts correlated speckle once.

// `!(x > 0.0)` is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use nalgebra::{DMatrix, SMatrix, SVector};
use tangent_core::calibration::{Calibration, CalibrationError, PlanesUncertainty};
use tangent_core::laser_plane::LaserPlane;
use tangent_core::noise::NoiseModel;
use tangent_core::real::{Real, Vec2, Vec3};
use tangent_core::solvers::circle::{fit_hyper, fit_robust, RobustParams};
use tangent_core::solvers::correlation::correlation_length;
use tangent_core::solvers::lm::{minimise, Evaluated, LeastSquares, LmParams, NormalEquations};
use tangent_core::solvers::SolveError;

use super::CalibrateError;

mod surface;
mod views;

use surface::{fit_fixed, Observed};
pub use surface::{KnownDiameter, Surface};
pub use views::ReferenceView;

/// Fewest views: a relative `e` and `δ` per extra plane from shifts that grow as `z` and
/// `z²` need at least two distances, and a third checks them.
pub const MIN_VIEWS: usize = 3;

/// Fewest points a plane's section must keep in a view: a section shorter than this
/// determines its circle too poorly to check the other (as the sphere solver's own arcs).
pub const MIN_SECTION_POINTS: usize = 30;

/// Smallest `|cos|` of the angle between a point's displacement direction `L` and its
/// section's radius for the point to be used (60°; see [`prepare`]).
pub const MIN_RADIAL_SHARE: f64 = 0.5;

/// Tukey-style hard cut (robust-scale units) that sets a point aside as not on the reference
/// (a stand, a floor, a cable): the biweight's zero-weight point, as in the sphere fits.
pub const OUTLIER_CUT: f64 = 4.685;

/// Largest posterior σ of the planes' relative tilt the refinement accepts, as a share of
/// its prior σ (`√2·σ_δ` for two independently calibrated planes): views that shrink it by
/// less than half (one distance only, tiny sections) did not determine it.
pub const MAX_RELATIVE_TILT_SHARE: f64 = 0.5;

/// One plane's correction with its posterior σ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneCorrection {
    /// Change of the baseline `e` (metres).
    pub baseline: f64,
    /// Its 1σ (metres).
    pub baseline_sigma: f64,
    /// Change of the tilt `δ` (radians).
    pub tilt: f64,
    /// Its 1σ (radians).
    pub tilt_sigma: f64,
}

/// How one view fits before and after.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewFit {
    /// The view's name.
    pub name: String,
    /// Distance of the ball's centre, or the wall's depth on the axis (metres).
    pub distance: f64,
    /// Diameter of the sphere, or depth on the axis of the plane, through the kept points,
    /// before and after (metres).
    pub size: (f64, f64),
    /// RMS of the kept points' distance to that surface, before and after (metres).
    pub rms: (f64, f64),
    /// Points kept / given.
    pub kept: (usize, usize),
}

/// The result of [`refine_planes`].
#[derive(Debug, Clone)]
pub struct Refinement {
    /// The calibration with the refined planes (camera and id unchanged).
    pub calibration: Calibration,
    /// Each plane's correction.
    pub corrections: Vec<PlaneCorrection>,
    /// Posterior 1σ of plane 1's tilt relative to plane 0's (radians).
    pub relative_tilt_sigma: f64,
    /// Posterior 1σ of plane 1's baseline relative to plane 0's (metres).
    pub relative_baseline_sigma: f64,
    /// For each plane `k ≥ 1`: posterior 1σ of its tilt (radians) and baseline (metres)
    /// relative to plane 0's.
    pub relative: Vec<(f64, f64)>,
    /// Each view's fit.
    pub views: Vec<ViewFit>,
    /// The views set aside, each with its reason (no sphere with the uncorrected planes).
    pub skipped: Vec<String>,
}

/// Unit direction in which a point `x` of `plane` moves when its stripe's centre moves: the
/// line the plane shares with the image column's plane through `x` (normal `(z, 0, −x)`), or
/// for a row-wise plane (the crossing line, whose centre is found along each row) the row's
/// plane (normal `(0, z, −y)`).
fn displacement(plane: &LaserPlane, x: &Vec3) -> Vec3 {
    let across = if plane.is_row_wise() {
        Vec3::new(0.0, x.z, -x.y)
    } else {
        Vec3::new(x.z, 0.0, -x.x)
    };
    plane
        .normal
        .cross(&across)
        .try_normalize(0.0)
        .unwrap_or_else(Vec3::zeros)
}

/// The planes of `nominal` with the corrections `u` (prior-σ units: `u[2k]` of `e`,
/// `u[2k+1]` of `δ`).
fn corrected_planes(
    nominal: &[LaserPlane],
    u: &[f64],
    prior: &NoiseModel,
) -> Result<Vec<LaserPlane>, SolveError> {
    nominal
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let (e, delta) = p.baseline_tilt();
            LaserPlane::from_baseline_tilt_roll(
                e + prior.baseline * u[2 * k],
                delta + prior.tilt * u[2 * k + 1],
                p.roll(),
            )
            .map_err(|_| SolveError::Degenerate)
        })
        .collect()
}

/// The posterior `cov` of the corrections (prior-σ units; `scale(i)` the prior σ of
/// parameter `i`) as the planes' covariance the calibration carries (σ in SI, correlation):
/// what a reading's calibration σ then uses (`docs/calibration.md` §14).
fn posterior<const N: usize>(
    cov: &SMatrix<f64, N, N>,
    scale: impl Fn(usize) -> f64,
) -> Result<PlanesUncertainty, CalibrationError> {
    let sd: Vec<f64> = (0..N).map(|i| cov[(i, i)].max(0.0).sqrt()).collect();
    let sigma: Vec<Real> = (0..N).map(|i| (sd[i] * scale(i)) as Real).collect();
    let mut correlation = vec![0.0 as Real; N * N];
    for i in 0..N {
        for j in 0..N {
            correlation[i * N + j] = if i == j {
                1.0
            } else if sd[i] > 0.0 && sd[j] > 0.0 {
                (cov[(i, j)] / (sd[i] * sd[j])).clamp(-1.0, 1.0) as Real
            } else {
                0.0
            };
        }
    }
    PlanesUncertainty::new(&sigma, &correlation).map_err(CalibrationError::Uncertainty)
}

/// A triangulated point moved along its ray onto the plane `to` (`X' = X·d'/(n'·X)`).
fn retriangulate(x: &Vec3, to: &LaserPlane) -> Vec3 {
    x * (to.offset / to.normal.dot(x))
}

/// A point of a plane re-triangulated on the corrected plane `to` ((B1)), with its
/// displacement line and σ carried along: a pixel's move that moved `x` by `σ·L` moves
/// `X' = x·g(x)`, `g = d'/(n'·x)`, by `σ·(g·L + x·(∇g·L))`, `∇g = −d'·n'/(n'·x)²`. Without
/// this a correction that shrinks the depth scale would shrink every residual in metres
/// and be preferred for it (`docs/calibration.md` §13).
fn moved(o: &Observed, to: &LaserPlane) -> Observed {
    let nx = to.normal.dot(&o.x);
    let g = to.offset / nx;
    let rate = o.along * g - o.x * (to.offset * to.normal.dot(&o.along) / (nx * nx));
    let scale = rate.norm();
    Observed {
        x: o.x * g,
        along: rate / scale,
        sigma: o.sigma * scale,
    }
}

/// One view's kept points and each plane's scale `s` (see the module documentation).
#[derive(Debug, Clone)]
struct Prepared {
    /// The view's name.
    name: String,
    /// Points the view gave.
    given: usize,
    /// Plane of each kept point, and the point (σ: its plane's scale).
    kept: Vec<(usize, Observed)>,
    /// The surface with the uncorrected planes (start of every re-fit).
    surface: Surface,
}

/// A straight line through 2-D points by orthogonal regression, refitted once without the
/// points beyond [`OUTLIER_CUT`] robust scales: its centroid and unit normal. `None` for
/// fewer than two points or no direction.
fn fit_line(points: &[Vec2]) -> Option<(Vec2, Vec2)> {
    let fit = |pts: &[&Vec2]| -> Option<(Vec2, Vec2)> {
        if pts.len() < 2 {
            return None;
        }
        let n = pts.len() as f64;
        let c = pts.iter().fold(Vec2::zeros(), |acc, p| acc + **p) / n;
        let mut m = nalgebra::Matrix2::<f64>::zeros();
        for p in pts {
            let d = **p - c;
            m += d * d.transpose();
        }
        let eig = nalgebra::SymmetricEigen::new(m);
        // The normal: the eigenvector of the smaller eigenvalue.
        let i = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
            0
        } else {
            1
        };
        let normal = Vec2::new(eig.eigenvectors[(0, i)], eig.eigenvectors[(1, i)]);
        Some((c, normal.try_normalize(0.0)?))
    };
    let all: Vec<&Vec2> = points.iter().collect();
    let (c, normal) = fit(&all)?;
    let r: Vec<f64> = points.iter().map(|p| (p - c).dot(&normal)).collect();
    let cut = OUTLIER_CUT * robust_scale(&r);
    let kept: Vec<&Vec2> = points
        .iter()
        .zip(&r)
        .filter(|(_, ri)| ri.abs() <= cut)
        .map(|(p, _)| p)
        .collect();
    fit(&kept)
}

/// A section's own shape at an in-plane point: its normal there and the point's distance.
type OwnShape = dyn Fn(&Vec2) -> Option<(Vec2, f64)>;

/// The robust scale `1.4826·median|r|`.
fn robust_scale(r: &[f64]) -> f64 {
    let mut a: Vec<f64> = r.iter().map(|x| x.abs()).collect();
    a.sort_by(f64::total_cmp);
    if a.is_empty() {
        return 0.0;
    }
    1.4826 * a[a.len() / 2]
}

/// The outer problem: corrections `u` of every plane.
struct Planes<'a> {
    nominal: &'a [LaserPlane],
    prior: &'a NoiseModel,
    prepared: &'a [Prepared],
    known: Option<KnownDiameter>,
}

impl Planes<'_> {
    /// The residual vector at `u`: the prior's, then every view's at its re-fitted sphere.
    fn residuals(&self, u: &[f64]) -> Result<(Vec<f64>, Vec<Surface>), SolveError> {
        let planes = corrected_planes(self.nominal, u, self.prior)?;
        let mut r: Vec<f64> = u.to_vec();
        let mut spheres = Vec::with_capacity(self.prepared.len());
        let mut pts = Vec::new();
        for prep in self.prepared {
            pts.clear();
            pts.extend(prep.kept.iter().map(|(k, o)| moved(o, &planes[*k])));
            spheres.push(fit_fixed(&pts, self.known, &prep.surface, &mut r)?);
        }
        Ok((r, spheres))
    }
}

/// Central-difference step of the corrections (prior-σ units): the points move by
/// ≈ 10⁻² σ of a tilt (µm at 1 m), far above the inner fit's convergence and far inside the
/// linear range.
const JACOBIAN_STEP: f64 = 1e-2;

impl<const N: usize> LeastSquares<N> for Planes<'_> {
    type Params = SVector<f64, N>;
    type Extra = ();

    fn evaluate(&self, p: &Self::Params) -> Result<(NormalEquations<N>, ()), SolveError> {
        let (r0, _) = self.residuals(p.as_slice())?;
        let mut jac = DMatrix::<f64>::zeros(r0.len(), N);
        for i in 0..N {
            let mut plus = *p;
            let mut minus = *p;
            plus[i] += JACOBIAN_STEP;
            minus[i] -= JACOBIAN_STEP;
            let (rp, _) = self.residuals(plus.as_slice())?;
            let (rm, _) = self.residuals(minus.as_slice())?;
            if rp.len() != r0.len() || rm.len() != r0.len() {
                return Err(SolveError::Degenerate);
            }
            for (row, (a, b)) in rp.iter().zip(&rm).enumerate() {
                jac[(row, i)] = (a - b) / (2.0 * JACOBIAN_STEP);
            }
        }
        let r = nalgebra::DVector::from_vec(r0);
        let jtj_d = jac.transpose() * &jac;
        let jtr_d = jac.transpose() * &r;
        let jtj = SMatrix::<f64, N, N>::from_fn(|i, j| jtj_d[(i, j)]);
        let jtr = SVector::<f64, N>::from_fn(|i, _| jtr_d[i]);
        let cost = r.norm_squared();
        Ok((NormalEquations { jtj, jtr, cost }, ()))
    }

    fn step(&self, p: &Self::Params, delta: &SVector<f64, N>) -> Self::Params {
        p + delta
    }

    fn step_scale(&self, p: &Self::Params) -> f64 {
        1.0 + p.norm()
    }

    /// Settled when the cost drops by less than 10⁻⁴: a hundredth of a σ of any correction.
    fn settled(&self, before: f64, after: f64) -> bool {
        before - after < 1e-4
    }
}

/// Each view's points on the reference with their `L` and σ: every section alone is fitted by its
/// own shape in its plane (a robust circle on a ball, a straight line on a wall). A
/// calibration error moves and scales a whole section, which its own shape absorbs, so these residuals are the points' noise alone, whatever the
/// calibration's error. Each residual is turned into the move along `L` that explains it
/// (`d/(L·m̂)`, `m̂` the circle's radial direction); points where `L` is more than 60° off
/// the radial direction (the limbs: a move there hardly leaves the surface, so they carry
/// little and only second-order information) and points beyond the Tukey cut (a stand, a
/// floor) are set aside. σ is the robust scale of the moves times the square root of their
/// correlation length.
///
/// A view that yields no sphere with the planes as they are is set aside with its reason.
fn prepare(nominal: &[LaserPlane], views: &[ReferenceView]) -> (Vec<Prepared>, Vec<String>) {
    let mut out = Vec::with_capacity(views.len());
    let mut skipped = Vec::new();
    for view in views {
        match prepare_view(nominal, view) {
            Ok(p) => out.push(p),
            Err(e) => skipped.push(e.to_string()),
        }
    }
    (out, skipped)
}

/// One view of [`prepare`].
fn prepare_view(nominal: &[LaserPlane], view: &ReferenceView) -> Result<Prepared, CalibrateError> {
    let robust = RobustParams {
        min_scale: 0.0,
        ..RobustParams::default()
    };
    let mut kept = Vec::new();
    for (k, pts) in view.planes.iter().enumerate() {
        let refuse =
            |why: String| CalibrateError::Refinement(format!("{}: laser {k}: {why}", view.name));
        let too_few = |n: usize| {
            refuse(format!(
                "{n} points on the reference, at least {MIN_SECTION_POINTS} needed; aim \
                 so that every line crosses it"
            ))
        };
        if pts.len() < MIN_SECTION_POINTS {
            return Err(too_few(pts.len()));
        }
        let plane = &nominal[k];
        let a = plane.normal.cross(&Vec3::z()).normalize();
        let b = plane.normal.cross(&a);
        let flat: Vec<Vec2> = pts
            .iter()
            .map(|x| Vec2::new(x.dot(&a), x.dot(&b)))
            .collect();
        // The section's own shape: a circle on a ball, a straight line on a wall; for a
        // point, the shape's in-plane normal there and the point's distance from it.
        let own: Box<OwnShape> = match view.start {
            Surface::Sphere(_) => {
                let mut scratch = vec![0.0; flat.len()];
                let circle = fit_hyper(&flat)
                    .and_then(|c| fit_robust(&flat, c, &robust, &mut scratch))
                    .map_err(|e| refuse(format!("no circle through the section: {e}")))?
                    .circle;
                Box::new(move |f: &Vec2| {
                    let radial = (f - circle.centre).try_normalize(0.0)?;
                    Some((radial, (f - circle.centre).norm() - circle.radius))
                })
            }
            Surface::Plane { .. } => {
                let (centre, normal) = fit_line(&flat)
                    .ok_or_else(|| refuse("its points do not make a line".into()))?;
                Box::new(move |f: &Vec2| Some((normal, (f - centre).dot(&normal))))
            }
        };
        // (index, L, move along L) of the points whose L is within 60° of the normal.
        let moves: Vec<(usize, Vec3, f64)> = pts
            .iter()
            .zip(&flat)
            .enumerate()
            .filter_map(|(i, (x, f))| {
                let along = displacement(plane, x);
                let (normal, d) = own(f)?;
                let cos = Vec2::new(along.dot(&a), along.dot(&b)).dot(&normal);
                (cos.abs() >= MIN_RADIAL_SHARE).then_some((i, along, d / cos))
            })
            .collect();
        let t: Vec<f64> = moves.iter().map(|m| m.2).collect();
        let cut = OUTLIER_CUT * robust_scale(&t);
        let on_reference: Vec<&(usize, Vec3, f64)> =
            moves.iter().filter(|m| m.2.abs() <= cut).collect();
        if on_reference.len() < MIN_SECTION_POINTS {
            return Err(too_few(on_reference.len()));
        }
        let kept_t: Vec<f64> = on_reference.iter().map(|m| m.2).collect();
        let sigma = robust_scale(&kept_t) * correlation_length(&kept_t).max(1.0).sqrt();
        if !(sigma > 0.0 && sigma.is_finite()) {
            return Err(refuse("the points have no spread about their shape".into()));
        }
        kept.extend(on_reference.iter().map(|&&(i, along, _)| {
            (
                k,
                Observed {
                    x: pts[i],
                    along,
                    sigma,
                },
            )
        }));
    }
    // The surface of the uncorrected planes, the start of every re-fit.
    let all: Vec<Observed> = kept.iter().map(|(_, o)| *o).collect();
    let surface = fit_fixed(&all, None, &view.start, &mut Vec::new()).map_err(|e| {
        CalibrateError::Refinement(format!("{}: no surface through its points: {e}", view.name))
    })?;
    Ok(Prepared {
        name: view.name.clone(),
        given: view.planes.iter().map(Vec::len).sum(),
        kept,
        surface,
    })
}

/// Refines the planes of `calibration` (each plane's `e` and `δ`; roll and camera kept) on
/// `views` of one reference (a ball or a flat wall), each plane's prior the board
/// calibration's σ in `prior` (`NoiseModel::baseline`, `::tilt`). With `known` a ball's
/// certified diameter joins.
///
/// Errors: fewer than [`MIN_VIEWS`] views or two planes; a view whose section keeps
/// fewer than [`MIN_SECTION_POINTS`]; no convergence; views that leave the relative tilt
/// undetermined (posterior σ above [`MAX_RELATIVE_TILT_SHARE`] of its prior).
pub fn refine_planes(
    calibration: &Calibration,
    views: &[ReferenceView],
    prior: &NoiseModel,
    known: Option<KnownDiameter>,
) -> Result<Refinement, CalibrateError> {
    let nominal: &[LaserPlane] = &calibration.planes;
    if nominal.len() < 2 {
        return Err(CalibrateError::Undetermined(
            "a reference refines the planes against each other: the calibration has one plane"
                .into(),
        ));
    }
    if views.len() < MIN_VIEWS {
        return Err(CalibrateError::TooFewViews {
            found: views.len(),
            needed: MIN_VIEWS,
        });
    }
    if let Some(v) = views.iter().find(|v| v.planes.len() != nominal.len()) {
        return Err(CalibrateError::Refinement(format!(
            "{}: {} planes' points, the calibration has {}",
            v.name,
            v.planes.len(),
            nominal.len()
        )));
    }
    if !(prior.baseline > 0.0 && prior.tilt > 0.0) {
        return Err(CalibrateError::Refinement(
            "the prior σ of e and δ must be positive".into(),
        ));
    }
    match nominal.len() {
        2 => refine_n::<4>(calibration, views, prior, known),
        3 => refine_n::<6>(calibration, views, prior, known),
        n => Err(CalibrateError::Refinement(format!(
            "{n} planes: the refinement handles two or three"
        ))),
    }
}

fn refine_n<const N: usize>(
    calibration: &Calibration,
    views: &[ReferenceView],
    prior: &NoiseModel,
    known: Option<KnownDiameter>,
) -> Result<Refinement, CalibrateError> {
    let nominal: &[LaserPlane] = &calibration.planes;
    let (prepared, skipped) = prepare(nominal, views);
    if prepared.len() < MIN_VIEWS {
        return Err(CalibrateError::Undetermined(format!(
            "{} of {} views give a sphere, at least {MIN_VIEWS} needed: {}",
            prepared.len(),
            views.len(),
            skipped.join("; ")
        )));
    }
    let problem = Planes {
        nominal,
        prior,
        prepared: &prepared,
        known,
    };
    let fail = |e: SolveError| CalibrateError::Refinement(format!("plane corrections: {e}"));
    let start = Evaluated::at(&problem, SVector::<f64, N>::zeros()).map_err(fail)?;
    let (min, _) = minimise(&problem, start, &LmParams::default()).map_err(fail)?;
    let (u, normal) = (min.params, min.normal);
    let cov = normal.jtj.try_inverse().ok_or_else(|| {
        CalibrateError::Refinement("the corrections' normal matrix is singular".into())
    })?;
    let scales = |i: usize| {
        if i.is_multiple_of(2) {
            prior.baseline
        } else {
            prior.tilt
        }
    };
    let corrections: Vec<PlaneCorrection> = (0..nominal.len())
        .map(|k| PlaneCorrection {
            baseline: u[2 * k] * prior.baseline,
            baseline_sigma: cov[(2 * k, 2 * k)].max(0.0).sqrt() * prior.baseline,
            tilt: u[2 * k + 1] * prior.tilt,
            tilt_sigma: cov[(2 * k + 1, 2 * k + 1)].max(0.0).sqrt() * prior.tilt,
        })
        .collect();
    // σ of a difference of two corrections from the covariance (prior-σ units → SI).
    let difference_sigma = |i: usize, j: usize| {
        let v = cov[(i, i)] + cov[(j, j)] - 2.0 * cov[(i, j)];
        v.max(0.0).sqrt() * scales(i)
    };
    let relative_tilt_sigma = difference_sigma(1, 3);
    let relative_baseline_sigma = difference_sigma(0, 2);
    let relative = (1..nominal.len())
        .map(|k| (difference_sigma(1, 2 * k + 1), difference_sigma(0, 2 * k)))
        .collect();
    if relative_tilt_sigma > MAX_RELATIVE_TILT_SHARE * std::f64::consts::SQRT_2 * prior.tilt {
        return Err(CalibrateError::Undetermined(format!(
            "the views determine the planes' relative tilt to σ = {:.3} mrad only (the \
             board's {:.3} mrad); add views at other distances (a ball at 0.5–1.5 m, a wall \
             at 1–3 m) with every line across the reference",
            relative_tilt_sigma * 1e3,
            std::f64::consts::SQRT_2 * prior.tilt * 1e3
        )));
    }
    let planes = corrected_planes(nominal, u.as_slice(), prior)
        .map_err(|e| CalibrateError::Refinement(format!("corrected planes: {e}")))?;
    let refined = Calibration::new(calibration.id, calibration.camera, &planes)
        .and_then(|c| c.with_uncertainty(posterior(&cov, scales)?))
        .map_err(|e| CalibrateError::Refinement(format!("refined calibration: {e}")))?;
    let surfaces = |u: &[f64]| {
        let plain = Planes {
            known: None,
            ..problem
        };
        plain
            .residuals(u)
            .map(|(_, s)| s)
            .map_err(|e| CalibrateError::Refinement(format!("surfaces of the views: {e}")))
    };
    let before = surfaces(&[0.0; N])?;
    let after = surfaces(u.as_slice())?;
    let rms = |prep: &Prepared, planes: &[LaserPlane], s: &Surface| {
        let sum: f64 = prep
            .kept
            .iter()
            .map(|(k, o)| s.distance(&retriangulate(&o.x, &planes[*k])).powi(2))
            .sum();
        (sum / prep.kept.len().max(1) as f64).sqrt()
    };
    let views_fit = prepared
        .iter()
        .zip(before.iter().zip(&after))
        .map(|(prep, (b, a))| ViewFit {
            name: prep.name.clone(),
            distance: a.range(),
            size: (b.size(), a.size()),
            rms: (rms(prep, nominal, b), rms(prep, &planes, a)),
            kept: (prep.kept.len(), prep.given),
        })
        .collect();
    Ok(Refinement {
        calibration: refined,
        corrections,
        relative_tilt_sigma,
        relative_baseline_sigma,
        relative,
        views: views_fit,
        skipped,
    })
}

#[cfg(test)]
#[path = "reference_tests.rs"]
mod tests;
