//! Predicted uncertainty of a reading (thesis chapter 7; derivations in
//! `docs/error-model.md`).
//!
//! [`predict_diameter_sigma`] propagates the point noise of [`crate::noise`] (stripe-centre
//! noise along `∂X/∂v`, grazing-ray columns, calibration) to the diameter of a transversal
//! stem for both one-plane methods of the solvers (three-tangent and circle fit), sampling
//! the lit and visible arc one point per image column ([`crate::noise::sample_columns`]), as the pipeline
//! does. It sits above the solvers: it re-solves simulated points with them.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::fmt;

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Real, Vec2};

use crate::camera::Camera;
use crate::laser_plane::LaserPlane;
use crate::noise::{
    displacement_per_pixel, perturbed, point_sigma, retriangulate, sample_columns, NoiseError,
    NoiseModel, PointSigma,
};
use crate::solvers::circle::{self, Circle};
use crate::solvers::lm::LmParams;
use crate::solvers::three_tangent::{three_tangent, ThreeTangentParams};
use crate::solvers::SolveError;
use nalgebra::{SMatrix, SVector};

/// Why a prediction could not be made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorModelError {
    /// The point is not in front of the camera, or the plane/ray geometry is degenerate.
    InvalidGeometry,
    /// The stem is not seen (no lit and visible column), or too few columns.
    NotVisible,
    /// The scratch buffer is too short (needs `2 × camera width`).
    ScratchTooSmall,
    /// A solver failed on the simulated points.
    Solve(SolveError),
}

impl fmt::Display for ErrorModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ErrorModelError::InvalidGeometry => f.write_str("invalid geometry for the error model"),
            ErrorModelError::NotVisible => f.write_str("stem not visible to the camera"),
            ErrorModelError::ScratchTooSmall => f.write_str("scratch buffer too small"),
            ErrorModelError::Solve(e) => write!(f, "error model: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ErrorModelError {}

impl From<NoiseError> for ErrorModelError {
    fn from(e: NoiseError) -> Self {
        match e {
            NoiseError::InvalidGeometry => ErrorModelError::InvalidGeometry,
            NoiseError::ScratchTooSmall => ErrorModelError::ScratchTooSmall,
        }
    }
}

impl From<SolveError> for ErrorModelError {
    fn from(e: SolveError) -> Self {
        ErrorModelError::Solve(e)
    }
}

/// A transversal stem for [`predict_diameter_sigma`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StemGeometry {
    /// In-plane distance from the laser source to the nearest point of the stem, which lies
    /// straight ahead along the plane's depth axis `b` (metres).
    pub distance: Real,
    /// Diameter (metres).
    pub diameter: Real,
}

/// 1σ of a diameter by one method, by source (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MethodSigma {
    /// From the random stripe-centre noise (subpixel + speckle) of all points.
    pub random: Real,
    /// From the grazing-ray columns (three-tangent only; 0 for the fit).
    pub edges: Real,
    /// From the calibration uncertainties (`e`, `f`, `δ` in quadrature; systematic for one
    /// device, random over devices).
    pub calibration: Real,
    /// All in quadrature.
    pub total: Real,
}

/// Prediction for one stem and both methods.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiameterPrediction {
    /// Three-tangent method; `None` when a grazing ray is outside the image.
    pub three_tangent: Option<MethodSigma>,
    /// Geometric circle fit.
    pub circle_fit: Option<MethodSigma>,
    /// Columns that see the stem.
    pub points: usize,
    /// Angle of the lit and visible arc, seen from the stem's centre (radians).
    pub arc_angle: Real,
    /// σ of one point at the stem's nearest point (random noise).
    pub point: PointSigma,
}

/// Predicts the 1σ diameter error of a transversal stem for the three-tangent method and the
/// geometric circle fit (`docs/error-model.md`, "Diameter"): random noise by linear
/// propagation (exact for small noise), edges from `edge_px`, calibration by re-solving the
/// exactly re-triangulated points with the perturbed calibration.
///
/// `scratch` needs `2 × camera.width` entries.
pub fn predict_diameter_sigma(
    plane: &LaserPlane,
    camera: &Camera,
    stem: &StemGeometry,
    noise: &NoiseModel,
    scratch: &mut [Vec2],
) -> Result<DiameterPrediction, ErrorModelError> {
    let r = 0.5 * stem.diameter;
    if !(r > 0.0 && stem.distance > 0.0 && r.is_finite() && stem.distance.is_finite()) {
        return Err(ErrorModelError::InvalidGeometry);
    }
    let w = camera.width as usize;
    if scratch.len() < 2 * w {
        return Err(ErrorModelError::ScratchTooSmall);
    }
    let (pts, rest) = scratch.split_at_mut(w);
    let c = Circle::new(Vec2::new(0.0, stem.distance + r), r);
    let (n, cut) = sample_columns(plane, camera, c.centre, c.radius, pts)?;
    if n < 8 {
        return Err(ErrorModelError::NotVisible);
    }
    let pts = &pts[..n];
    let (a, b) = plane.plane_axes();
    let sigma_v = noise.image_px();
    let fy = camera.fy;
    let noise_of = |q: Vec2| -> Vec2 {
        let x = plane.from_plane_coords(q);
        match displacement_per_pixel(plane, fy, x) {
            Ok(g) => Vec2::new(g.dot(&a), g.dot(&b)) * sigma_v,
            Err(_) => Vec2::zeros(),
        }
    };
    let near = Vec2::new(0.0, stem.distance);
    let point = point_sigma(plane, fy, plane.from_plane_coords(near), sigma_v)?;
    // Arc angle seen from the centre.
    let ang = |q: &Vec2| (q.x - c.centre.x).atan2(-(q.y - c.centre.y));
    let (mut lo, mut hi) = (Real::INFINITY, Real::NEG_INFINITY);
    for q in pts {
        lo = lo.min(ang(q));
        hi = hi.max(ang(q));
    }
    let arc_angle = hi - lo;

    // --- circle fit: random part by the sandwich formula.
    let fit_random = circle::circle_radius_sigma(&c, pts.iter().map(|q| (*q, noise_of(*q))));

    // --- three-tangent: α from the end columns, D from the window parabola.
    let u_c = Vec2::new(0.0, 1.0);
    let tt_random_edges = if cut {
        None
    } else {
        let psi = |q: Vec2| q.x.atan2(q.y);
        let dpsi_first = (psi(pts[1]) - psi(pts[0])).abs();
        let dpsi_last = (psi(pts[n - 1]) - psi(pts[n - 2])).abs();
        let s_alpha = 0.5 * noise.edge_px * sqrt(dpsi_first * dpsi_first + dpsi_last * dpsi_last);
        let win = ThreeTangentParams::default().nearest_window * r;
        let mut xtx = SMatrix::<Real, 3, 3>::zeros();
        let mut xsx = SMatrix::<Real, 3, 3>::zeros();
        for q in pts {
            let t = q.x;
            if t.abs() > win {
                continue;
            }
            let tau = t / win;
            let xv = SVector::<Real, 3>::new(1.0, tau, tau * tau);
            let s = noise_of(*q).dot(&u_c);
            xtx += xv * xv.transpose();
            xsx += xv * xv.transpose() * (s * s);
        }
        let inv = xtx.try_inverse().ok_or(ErrorModelError::NotVisible)?;
        let s_d = sqrt((inv * xsx * inv)[(0, 0)].max(0.0));
        let sin_a = r / (stem.distance + r);
        let alpha = sin_a.asin();
        let k = 1.0 - sin_a;
        let dr_da = stem.distance * alpha.cos() / (k * k);
        let dr_dd = sin_a / k;
        Some((dr_dd * s_d, dr_da * s_alpha))
    };

    // --- calibration: re-triangulate, re-solve, difference.
    let base_tt = if cut {
        None
    } else {
        three_tangent(pts, &ThreeTangentParams::default())
            .ok()
            .map(|t| t.radius)
    };
    let fit_of = |p: &[Vec2]| -> Result<Real, ErrorModelError> {
        let init = circle::fit_hyper(p)?;
        Ok(circle::fit_geometric(p, init, &LmParams::default())?
            .circle
            .radius)
    };
    let base_fit = fit_of(pts)?;
    let (pe, pf, pd) = perturbed(plane, camera.fx, noise)?;
    let (mut cal_tt, mut cal_fit) = (0.0, 0.0);
    let moved = &mut rest[..n];
    for k in 0..3 {
        let (pl, s) = match k {
            0 => (&pe, 1.0),
            1 => (plane, pf),
            _ => (&pd, 1.0),
        };
        for (o, q) in moved.iter_mut().zip(pts) {
            let x = retriangulate(plane.from_plane_coords(*q), pl, s)?;
            *o = pl.to_plane_coords(x);
        }
        if let Some(r0) = base_tt {
            if let Ok(t) = three_tangent(moved, &ThreeTangentParams::default()) {
                cal_tt += (t.radius - r0).powi(2);
            }
        }
        cal_fit += (fit_of(moved)? - base_fit).powi(2);
    }
    let fit = MethodSigma {
        random: 2.0 * fit_random,
        edges: 0.0,
        calibration: 2.0 * sqrt(cal_fit),
        total: 2.0 * sqrt(fit_random * fit_random + cal_fit),
    };
    let tt = match (tt_random_edges, base_tt) {
        (Some((rnd, edg)), Some(_)) => Some(MethodSigma {
            random: 2.0 * rnd,
            edges: 2.0 * edg,
            calibration: 2.0 * sqrt(cal_tt),
            total: 2.0 * sqrt(rnd * rnd + edg * edg + cal_tt),
        }),
        _ => None,
    };
    Ok(DiameterPrediction {
        three_tangent: tt,
        circle_fit: Some(fit),
        points: n,
        arc_angle,
        point,
    })
}

#[cfg(test)]
#[allow(clippy::unnecessary_cast)]
mod tests {
    extern crate std;
    use super::*;
    use crate::calibration::Calibration;
    use crate::noise::calibration_displacements;
    use crate::real::{Vec3, PI};
    use crate::solvers::circle::tests::Rng;
    use std::println;

    fn reference() -> (LaserPlane, Camera) {
        let cal = Calibration::reference_design();
        (cal.planes[0], cal.camera)
    }

    /// Prediction vs Monte-Carlo spread of both methods (the check: within a
    /// factor 1.5). Noise is injected exactly as the model assumes: along ∂X/∂v of each
    /// column's point, Gaussian with σ = image_px.
    #[test]
    fn prediction_matches_monte_carlo() {
        let (plane, cam) = reference();
        let noise = NoiseModel::reference();
        let mut scratch = std::vec![Vec2::zeros(); 2 * cam.width as usize];
        let mut rng = Rng::new(2024);
        for (dist, diam) in [(1.5, 0.3), (1.0, 0.1), (2.5, 0.6)] {
            let stem = StemGeometry {
                distance: dist,
                diameter: diam,
            };
            let pred = predict_diameter_sigma(&plane, &cam, &stem, &noise, &mut scratch).unwrap();
            let c = Circle::new(Vec2::new(0.0, dist + diam / 2.0), diam / 2.0);
            let mut base = std::vec![Vec2::zeros(); cam.width as usize];
            let (n, _) = sample_columns(&plane, &cam, c.centre, c.radius, &mut base).unwrap();
            let (a, b) = plane.plane_axes();
            let mut pts = std::vec![Vec2::zeros(); n];
            let trials = 300;
            let (mut st, mut st2, mut sf, mut sf2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for _ in 0..trials {
                for (p, q) in pts.iter_mut().zip(&base[..n]) {
                    let x = plane.from_plane_coords(*q);
                    let g = displacement_per_pixel(&plane, cam.fy, x).unwrap();
                    *p = q + Vec2::new(g.dot(&a), g.dot(&b))
                        * (noise.image_px() * rng.gauss() as Real);
                }
                let t = three_tangent(&pts, &ThreeTangentParams::default())
                    .unwrap()
                    .radius as f64;
                let f = circle::fit_geometric(
                    &pts,
                    circle::fit_hyper(&pts).unwrap(),
                    &LmParams::default(),
                )
                .unwrap()
                .circle
                .radius as f64;
                st += t;
                st2 += t * t;
                sf += f;
                sf2 += f * f;
            }
            let m = trials as f64;
            let sd_t = 2.0 * (st2 / m - (st / m).powi(2)).max(0.0).sqrt();
            let sd_f = 2.0 * (sf2 / m - (sf / m).powi(2)).max(0.0).sqrt();
            let pt = pred.three_tangent.unwrap().random as f64;
            let pf = pred.circle_fit.unwrap().random as f64;
            println!("d={dist} D={diam}: 3T obs {sd_t:.2e} pred {pt:.2e}; fit obs {sd_f:.2e} pred {pf:.2e}");
            assert!(sd_t / pt < 1.5 && pt / sd_t < 1.5, "3T {sd_t} vs {pt}");
            assert!(sd_f / pf < 1.5 && pf / sd_f < 1.5, "fit {sd_f} vs {pf}");
        }
    }

    /// Prints the tables of docs/error-model.md (`cargo test -p tangent-core --lib
    /// error_model::tests::tables -- --nocapture`). Checks only that every prediction in
    /// the field of view exists and is positive.
    #[test]
    fn tables() {
        let (plane, cam) = reference();
        let noise = NoiseModel::reference();
        println!(
            "speckle σ = {:.3} px, total image σ = {:.3} px",
            noise.speckle_px(),
            noise.image_px()
        );
        println!("| z (m) | σx sub (mm) | σy sub | σz sub | σz speckle | Δz e | Δz f | Δz δ | Δx e | Δx f | Δx δ |");
        println!("|---|---|---|---|---|---|---|---|---|---|---|");
        for z in [0.5, 1.0, 1.5, 2.0, 3.0] {
            let z: Real = z;
            // Point at x_n = 0.2 (image column ≈ 576), on the plane at depth z.
            let ray = Vec3::new(0.2, 0.0, 1.0);
            let (e, d) = plane.baseline_tilt();
            let yn = e / z - d.tan();
            let x = plane.intersect_ray(Vec3::new(ray.x, yn, 1.0)).unwrap();
            let s = point_sigma(&plane, cam.fy, x, noise.subpixel_px).unwrap();
            let sp = point_sigma(&plane, cam.fy, x, noise.speckle_px()).unwrap();
            let c = calibration_displacements(&plane, cam.fx, x, &noise).unwrap();
            let mm = 1000.0;
            println!(
                "| {z:.1} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
                s.x * mm, s.y * mm, s.z * mm, sp.z * mm,
                c[0].z * mm, c[1].z * mm, c[2].z * mm, c[0].x * mm, c[1].x * mm, c[2].x * mm
            );
            assert!(s.z > 0.0 && sp.z > 0.0);
        }
        let mut scratch = std::vec![Vec2::zeros(); 2 * cam.width as usize];
        println!("| distance (m) | diameter (cm) | columns | arc (°) | 3T random | 3T edges | 3T calib | 3T total | fit random | fit calib | fit total |");
        println!("|---|---|---|---|---|---|---|---|---|---|---|");
        for dist in [0.5, 1.0, 1.5, 2.0, 3.0] {
            for diam in [0.05, 0.1, 0.2, 0.4, 0.6, 1.0] {
                let stem = StemGeometry {
                    distance: dist,
                    diameter: diam,
                };
                let mm = 1000.0;
                match predict_diameter_sigma(&plane, &cam, &stem, &noise, &mut scratch) {
                    Ok(p) => {
                        let f = p.circle_fit.unwrap();
                        assert!(f.total > 0.0);
                        let tt = match p.three_tangent {
                            Some(t) => {
                                assert!(t.total > 0.0);
                                std::format!(
                                    "{:.3} | {:.3} | {:.3} | {:.3}",
                                    t.random * mm,
                                    t.edges * mm,
                                    t.calibration * mm,
                                    t.total * mm
                                )
                            }
                            None => "cut | cut | cut | cut".into(),
                        };
                        println!(
                            "| {dist:.1} | {:.0} | {} | {:.0} | {tt} | {:.3} | {:.3} | {:.3} |",
                            diam * 100.0,
                            p.points,
                            p.arc_angle * 180.0 / PI,
                            f.random * mm,
                            f.calibration * mm,
                            f.total * mm
                        );
                    }
                    Err(e) => println!("| {dist:.1} | {:.0} | – | {e} |", diam * 100.0),
                }
            }
        }
    }
}
