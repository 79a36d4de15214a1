//! The readings' σ from the calibration's errors (`docs/building.md`, "Calibration errors",
//! (B10)): what the walls' plane fits cannot see in their own scatter — a baseline or tilt
//! error of a laser plane, or of the focal length, moves every point of its line coherently
//! and so tilts, shifts and scales the walls.
//!
//! As for the sphere ((S-cal), `docs/sphere.md`): each error moves each point by its
//! re-triangulation `δXⱼ` (the pixel kept, the point re-triangulated with the plane or focal
//! length off by its 1σ); each wall's plane follows by the linearised weighted fit, the
//! readings are taken again from the moved walls by the same functions, and their changes are
//! combined — independent per plane, or through the covariance a refinement on a reference
//! left (`docs/calibration.md` §14, (C3)).

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Real, Vec3};
use nalgebra::{Matrix3, Vector3};

use super::super::plane_pca::{
    orientation, parallel_distance, plumb_deviation, Estimate, PlaneFit,
};
use super::readings::{corner_between, parallel_pair};
use super::{line_samples, Wall, WallInput, WallParams, WallSolution, MAX_WALLS};
use crate::calibration::{PlanesUncertainty, MAX_PLANES, PLANE_PARAMS};
use crate::laser_plane::LaserPlane;
use crate::noise::{self, NoiseModel};
use crate::solvers::SolveError;

/// The readings a calibration error moves, in the order [`Shifts`] holds them.
const READINGS: usize = 7;
const YAW: usize = 0;
const PITCH: usize = 1;
const AXIS_DISTANCE: usize = 2;
const CORNER: usize = 3;
const PARALLEL: usize = 4;
const SEGMENT: usize = 5;
const PLUMB: usize = 6;

/// Every reading's value (0 where the solution has none).
type Readings = [Real; READINGS];

/// One calibration error applied: the curves' planes as it moves them, and the ray scale of the
/// focal length (1 when it is a plane's error).
struct Perturbation {
    planes: [LaserPlane; MAX_PLANES],
    /// Which curves it moves (bit `k`: curve `k`).
    moves: u8,
    ray_scale: Real,
}

impl Perturbation {
    /// How the point `x` of curve `k` moves (zero for a curve this error does not touch).
    fn shift(&self, k: usize, x: Vec3) -> Result<Vec3, SolveError> {
        if self.moves & (1 << k) == 0 {
            return Ok(Vec3::zeros());
        }
        noise::retriangulate(x, &self.planes[k], self.ray_scale)
            .map(|y| y - x)
            .map_err(|_| SolveError::Degenerate)
    }
}

/// Adds to each reading of `solution` its σ from the calibration's errors: the focal
/// length's (`noise.focal_px`, independent) and each laser plane's baseline and tilt — at
/// the budget's σ and independent (`uncertainty` `None`), or as `uncertainty` states them
/// (indexed as `input.planes`). The sum is in quadrature with the σ the fits state.
///
/// Errors: a point or plane that cannot be re-triangulated, or a wall whose moved plane
/// cannot be solved for ([`SolveError::Degenerate`]).
pub fn add_calibration_sigma(
    input: &WallInput<'_>,
    params: &WallParams,
    solution: &mut WallSolution,
    noise: &NoiseModel,
    uncertainty: Option<&PlanesUncertainty>,
) -> Result<(), SolveError> {
    let n = input.planes.len().min(input.curves.len()).min(MAX_PLANES);
    if n == 0 {
        return Err(SolveError::PlaneCount);
    }
    let base = readings(params, solution, &solution.walls)?;
    let mut planes = [input.planes[0]; MAX_PLANES];
    planes[..n].copy_from_slice(&input.planes[..n]);
    // The focal length: every curve, one error.
    let (_, ray_scale, _) = noise::perturbed(&input.planes[0], params.focal_px, noise)
        .map_err(|_| SolveError::Degenerate)?;
    let focal = Perturbation {
        planes,
        moves: u8::MAX,
        ray_scale,
    };
    let focal_shift = moved(input, params, solution, &focal, &base)?;
    // Each plane's baseline and tilt, each moved by its own 1σ.
    let mut shifts = [[0.0; PLANE_PARAMS]; READINGS];
    for k in 0..n {
        let plane_noise = noise.for_plane(k, uncertainty);
        let (by_e, _, by_tilt) = noise::perturbed(&input.planes[k], params.focal_px, &plane_noise)
            .map_err(|_| SolveError::Degenerate)?;
        for (which, plane) in [by_e, by_tilt].into_iter().enumerate() {
            let mut error = Perturbation {
                planes,
                moves: 1 << k,
                ray_scale: 1.0,
            };
            error.planes[k] = plane;
            let d = moved(input, params, solution, &error, &base)?;
            for r in 0..READINGS {
                shifts[r][2 * k + which] = d[r];
            }
        }
    }
    let sigma = |r: usize| {
        let planes = PlanesUncertainty::spread_under(uncertainty, &shifts[r][..2 * n]);
        sqrt(focal_shift[r] * focal_shift[r] + planes * planes)
    };
    let widen = |e: &mut Estimate, r: usize| {
        let c = sigma(r);
        e.sigma = sqrt(e.sigma * e.sigma + c * c);
    };
    widen(&mut solution.orientation.yaw, YAW);
    widen(&mut solution.orientation.pitch, PITCH);
    widen(&mut solution.orientation.axis_distance, AXIS_DISTANCE);
    if let Some(c) = solution.corner.as_mut() {
        widen(&mut c.angle, CORNER);
    }
    if let Some(p) = solution.parallel.as_mut() {
        widen(p, PARALLEL);
    }
    if let Some(s) = solution.segment.as_mut() {
        widen(&mut s.length, SEGMENT);
    }
    if let Some(p) = solution.plumb.as_mut() {
        widen(p, PLUMB);
    }
    Ok(())
}

/// The readings' changes under `error`: each wall moved ([`moved_plane`]), the readings taken
/// again, the segment's ends placed again on the moved wall and laser plane.
fn moved(
    input: &WallInput<'_>,
    params: &WallParams,
    solution: &WallSolution,
    error: &Perturbation,
    base: &Readings,
) -> Result<Readings, SolveError> {
    let mut walls: heapless::Vec<Wall, MAX_WALLS> = heapless::Vec::new();
    for (w, wall) in solution.walls.iter().enumerate() {
        let plane = moved_plane(input, params, solution, w, &wall.plane, error)?;
        // Same capacity as the solution's: cannot fail.
        let _ = walls.push(Wall { plane, ..*wall });
    }
    let mut after = readings(params, solution, &walls)?;
    if let Some(s) = &solution.segment {
        // Each end is where the wall's plane and its line's laser plane cross the end's
        // image column (`readings::segment`): all three move.
        let wall = &walls
            .get(solution.aimed)
            .ok_or(SolveError::Degenerate)?
            .plane;
        let laser = if error.moves & (1 << s.curve) != 0 {
            error.planes.get(s.curve)
        } else {
            input.planes.get(s.curve)
        }
        .ok_or(SolveError::Degenerate)?;
        let end = |x: Vec3| -> Result<Vec3, SolveError> {
            let column = x.x / x.z * error.ray_scale;
            let m = Matrix3::from_rows(&[
                wall.normal.transpose(),
                laser.normal.transpose(),
                Vec3::new(1.0, 0.0, -column).transpose(),
            ]);
            m.try_inverse()
                .map(|inv| inv * Vec3::new(wall.offset, laser.offset, 0.0))
                .ok_or(SolveError::Degenerate)
        };
        after[SEGMENT] = norm(&(end(s.ends[1])? - end(s.ends[0])?));
    }
    let mut d = [0.0; READINGS];
    for r in 0..READINGS {
        d[r] = after[r] - base[r];
    }
    Ok(d)
}

/// The readings from `walls` (the solution's, or moved ones), each between the walls the
/// solution took it from (a moved pair must not trade places with another near the parallel
/// or corner threshold); the segment's length is the solution's (its ends move separately).
fn readings(
    params: &WallParams,
    solution: &WallSolution,
    walls: &[Wall],
) -> Result<Readings, SolveError> {
    let aimed = &walls
        .get(solution.aimed)
        .ok_or(SolveError::Degenerate)?
        .plane;
    let o = orientation(aimed).ok_or(SolveError::Degenerate)?;
    let mut r = [0.0; READINGS];
    r[YAW] = o.yaw.value;
    r[PITCH] = o.pitch.value;
    r[AXIS_DISTANCE] = o.axis_distance.value;
    if let Some(c) = &solution.corner {
        r[CORNER] = corner_between(walls, c.walls.0, c.walls.1).angle.value;
    }
    if let Some((a, b)) = parallel_pair(&solution.walls, params) {
        r[PARALLEL] = parallel_distance(&walls[a].plane, &walls[b].plane).value;
    }
    r[SEGMENT] = solution.segment.map_or(0.0, |s| s.length.value);
    r[PLUMB] = params
        .gravity
        .and_then(|(g, s)| plumb_deviation(aimed, g, s))
        .map_or(0.0, |p| p.value);
    Ok(r)
}

/// Wall `w`'s plane after its points moved by `error`, to first order: with `t₁, t₂` its
/// in-plane axes and `c` its centroid, the weighted least squares of
/// `n·δXⱼ + a₁ t₁·(Xⱼ − c) + a₂ t₂·(Xⱼ − c) − b` over its points (weights `1/σⱼ²` as in its
/// fit) gives the normal `n + a₁t₁ + a₂t₂` (normalised) and the centroid `c` moved by the
/// points' mean shift (`docs/building.md`, (B10)).
fn moved_plane(
    input: &WallInput<'_>,
    params: &WallParams,
    solution: &WallSolution,
    w: usize,
    plane: &PlaneFit,
    error: &Perturbation,
) -> Result<PlaneFit, SolveError> {
    let (n, c) = (plane.normal, plane.centroid);
    let [t1, t2] = plane.axes;
    let mut a = Matrix3::<Real>::zeros();
    let mut rhs = Vector3::<Real>::zeros();
    let (mut weight, mut mean) = (0.0, Vec3::zeros());
    let wall = w as u8;
    let take = move |_: usize, r: &super::Run| r.wall == Some(wall);
    let mut failed = false;
    for (k, x, s) in line_samples(
        input,
        &solution.runs,
        take,
        Some(n),
        params.trim_points,
        params.roughness,
    ) {
        let Ok(dx) = error.shift(k, x) else {
            failed = true;
            continue;
        };
        let wj = 1.0 / (s * s).max(Real::MIN_POSITIVE);
        let arm = x - c;
        let row = Vector3::new(t1.dot(&arm), t2.dot(&arm), -1.0);
        a += row * row.transpose() * wj;
        rhs -= row * (n.dot(&dx) * wj);
        weight += wj;
        mean += dx * wj;
    }
    if failed || !(weight > 0.0) {
        return Err(SolveError::Degenerate);
    }
    let sol = a
        .try_inverse()
        .map(|inv| inv * rhs)
        .ok_or(SolveError::Degenerate)?;
    let normal = (n + t1 * sol[0] + t2 * sol[1])
        .try_normalize(0.0)
        .ok_or(SolveError::Degenerate)?;
    let centroid = c + mean / weight;
    Ok(PlaneFit {
        normal,
        offset: normal.dot(&centroid),
        centroid,
        ..*plane
    })
}
