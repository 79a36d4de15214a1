//! Ray tracing of the irradiance layers and the exact laser-curve truth
//! (`docs/simulator.md`, "Rendering" and "True curve").
//!
//! Every (sub)pixel is traced through the camera model ([`Camera::pixel_to_ray`]), so lens
//! distortion is exact. A pixel gets one ray at its centre, except where something changes
//! inside it: an object edge, or a laser plane passing within `3 w` of its footprint
//! (`w` the sheet's half-thickness) — those pixels get `n × n` rays. The stripe's profile
//! is thus integrated over the pixel area (anti-aliased), the rest costs one ray.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tangent_core::calibration::{Calibration, MAX_PLANES};
use tangent_core::camera::Camera;
use tangent_core::real::{Vec2, Vec3};

use super::laser::LaserParams;
use super::reflectance::Reflectance;
use super::scene::{fbm, Scene};
use crate::truth::TruthPoint;

/// Ambient light (in the filter's band).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lighting {
    /// Diffuse (sky / canopy) irradiance on a surface facing up, in the filter band (W/m²).
    /// A surface facing sideways gets half, facing down none: `E = E_d (1 + n·up)/2`.
    pub diffuse_w_m2: f64,
    /// Direct sun irradiance on a surface facing the sun, in the filter band (W/m²).
    /// Full sun at 650 nm through a 10 nm filter is ≈ 15 W/m².
    pub sun_w_m2: f64,
    /// Direction towards the sun (camera frame; normalised on use).
    pub sun_direction: [f64; 3],
    /// Albedo × irradiance (W/m²) of the distant background (rays that hit nothing),
    /// modulated by a ±50 % canopy texture.
    pub background_w_m2: f64,
}

impl Lighting {
    /// Dim forest shade: 0.3 W/m² diffuse in band (≈ 2 % of full sun), no direct sun.
    pub fn shade() -> Self {
        Lighting {
            diffuse_w_m2: 0.3,
            sun_w_m2: 0.0,
            sun_direction: [0.3, -1.0, -0.3],
            background_w_m2: 0.06,
        }
    }
}

/// Rigid displacement of the device between the laser-off and the laser-on frame (the
/// hand moving): the off frame's camera frame is `X_off = R·X + t`, `R` from the rotation
/// vector `rotation_rad` (axis × angle).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandMotion {
    /// Rotation vector (radians).
    pub rotation_rad: [f64; 3],
    /// Translation (metres).
    pub translation_m: [f64; 3],
}

impl HandMotion {
    /// Origin and direction, in the scene (laser-on) frame, of the ray whose direction in
    /// the displaced camera frame is `d`: `X = Rᵀ(s·d − t)`.
    fn transform_ray(&self, d: Vec3) -> (Vec3, Vec3) {
        let rv = Vec3::new(
            self.rotation_rad[0],
            self.rotation_rad[1],
            self.rotation_rad[2],
        );
        let t = Vec3::new(
            self.translation_m[0],
            self.translation_m[1],
            self.translation_m[2],
        );
        // Rᵀ = rotation by −θ about the same axis (Rodrigues' formula).
        let theta = rv.norm();
        let rot_t = |v: Vec3| {
            if theta == 0.0 {
                return v;
            }
            let k = rv / theta;
            let (s, c) = (-theta).sin_cos();
            v * c + k.cross(&v) * s + k * (k.dot(&v) * (1.0 - c))
        };
        (rot_t(-t), rot_t(d))
    }
}

/// What a frame's irradiance layers depend on.
pub struct RenderSetup<'a> {
    /// Camera and planes.
    pub calibration: &'a Calibration,
    /// The scene.
    pub scene: &'a Scene,
    /// Ambient light.
    pub lighting: &'a Lighting,
    /// The lasers.
    pub laser: &'a LaserParams,
    /// The surfaces' BRDF.
    pub reflectance: &'a Reflectance,
    /// Apply `cos⁴θ` vignetting.
    pub vignetting: bool,
    /// `n` of the `n × n` supersampling of edge and stripe pixels.
    pub supersampling: usize,
}

/// Per-pixel "albedo × irradiance × vignetting" (W/m²) of one frame, row-major.
pub struct Layers {
    /// Ambient light.
    pub ambient: Vec<f64>,
    /// One layer per calibration plane (all zero for planes not rendered).
    pub lasers: Vec<Vec<f64>>,
}

#[derive(Clone, Copy)]
struct Sample {
    ambient: f64,
    laser: [f64; MAX_PLANES],
}

#[derive(Clone, Copy)]
struct Corner {
    /// Object hit (−1 nothing, −2 no valid ray).
    object: i64,
    /// Reflectance region of the hit ([`Scene::region`]: a board's square, else 0).
    region: i64,
    s: [f64; MAX_PLANES],
    w: [f64; MAX_PLANES],
}

fn ray(camera: &Camera, u: f64, v: f64) -> Option<Vec3> {
    camera.pixel_to_ray(Vec2::new(u, v)).ok()
}

impl RenderSetup<'_> {
    fn origin_dir(&self, d: Vec3, motion: Option<&HandMotion>) -> (Vec3, Vec3) {
        match motion {
            Some(m) => m.transform_ray(d),
            None => (Vec3::zeros(), d),
        }
    }

    fn corner(&self, u: f64, v: f64, motion: Option<&HandMotion>, lasers: bool) -> Corner {
        let mut c = Corner {
            object: -2,
            region: 0,
            s: [f64::INFINITY; MAX_PLANES],
            w: [0.0; MAX_PLANES],
        };
        let Some(d) = ray(&self.calibration.camera, u, v) else {
            return c;
        };
        let (o, dir) = self.origin_dir(d, motion);
        match self.scene.intersect(o, dir, f64::INFINITY) {
            None => c.object = -1,
            Some(h) => {
                c.object = h.object as i64;
                c.region = self.scene.region(h.object, h.point);
                if lasers {
                    for (i, p) in self.calibration.planes.iter().enumerate() {
                        c.s[i] = p.signed_distance(h.point);
                        c.w[i] = self.laser.half_width((h.point - p.source).norm());
                    }
                }
            }
        }
        c
    }

    fn sample(
        &self,
        u: f64,
        v: f64,
        motion: Option<&HandMotion>,
        lit: &[bool; MAX_PLANES],
    ) -> Sample {
        let mut out = Sample {
            ambient: 0.0,
            laser: [0.0; MAX_PLANES],
        };
        let Some(d) = ray(&self.calibration.camera, u, v) else {
            return out;
        };
        let vig = if self.vignetting {
            1.0 / d.norm_squared().powi(2)
        } else {
            1.0
        };
        let (o, dir) = self.origin_dir(d, motion);
        let l = self.lighting;
        let Some(h) = self.scene.intersect(o, dir, f64::INFINITY) else {
            // Background: a canopy-like pattern fixed to directions (far away).
            let dn = dir.normalize();
            let pattern = fbm(dn.x * 12.0, dn.y * 12.0, 0xBAC6, 4);
            out.ambient = l.background_w_m2 * (0.5 + pattern) * vig;
            return out;
        };
        let rho = self.scene.albedo(h.object, h.point);
        let n = h.normal;
        let up = Vec3::new(0.0, -1.0, 0.0);
        let reflectance = self
            .scene
            .reflectance(h.object)
            .unwrap_or(*self.reflectance);
        let lambertian = reflectance.is_lambertian();
        // Towards the viewer (the camera of this frame).
        let v = -dir.normalize();
        let e_sky = l.diffuse_w_m2 * 0.5 * (1.0 + n.dot(&up));
        // Lambertian: ρ·(E_sky + E_sun) as one product (the reference rendering, bit for bit);
        // other BRDFs weigh the sky and the sun separately.
        let mut e = e_sky;
        let mut ambient = reflectance.diffuse_factor(rho) * e_sky;
        if l.sun_w_m2 > 0.0 {
            let sun = Vec3::new(l.sun_direction[0], l.sun_direction[1], l.sun_direction[2]);
            let sn = sun.norm();
            if sn > 0.0 {
                let sun = sun / sn;
                let cos_sun = n.dot(&sun);
                if cos_sun > 0.0 && !self.scene.occluded(h.point, h.point + sun * 1e3) {
                    e += l.sun_w_m2 * cos_sun;
                    ambient += reflectance.pi_brdf(rho, n, sun, v) * l.sun_w_m2 * cos_sun;
                }
            }
        }
        out.ambient = if lambertian {
            rho * e * vig
        } else {
            ambient * vig
        };
        for (i, plane) in self.calibration.planes.iter().enumerate() {
            if !lit[i] {
                continue;
            }
            let irr = self.laser.irradiance(plane, h.point, n);
            if irr > 0.0 && !self.scene.occluded(h.point, plane.source) {
                let brdf = if lambertian {
                    rho
                } else {
                    let to_source = (plane.source - h.point).normalize();
                    reflectance.pi_brdf(rho, n, to_source, v)
                };
                out.laser[i] = brdf * irr * vig;
            }
        }
        out
    }

    /// Renders the layers of one frame. `motion` displaces the camera (laser-off frame);
    /// `lit[i]` selects the laser planes whose layer is computed.
    pub fn render(&self, motion: Option<&HandMotion>, lit: &[bool; MAX_PLANES]) -> Layers {
        let cam = &self.calibration.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let any_laser = lit.iter().any(|&b| b);
        let nplanes = self.calibration.planes.len().min(MAX_PLANES);
        // Corner grid: (w+1) × (h+1) rays at pixel corners.
        let corners: Vec<Vec<Corner>> = (0..=h)
            .into_par_iter()
            .map(|j| {
                (0..=w)
                    .map(|i| self.corner(i as f64 - 0.5, j as f64 - 0.5, motion, any_laser))
                    .collect()
            })
            .collect();
        let n = self.supersampling.max(1);
        let rows: Vec<Vec<Sample>> = (0..h)
            .into_par_iter()
            .map(|j| {
                (0..w)
                    .map(|i| {
                        let cs = [
                            corners[j][i],
                            corners[j][i + 1],
                            corners[j + 1][i],
                            corners[j + 1][i + 1],
                        ];
                        let edge = cs
                            .iter()
                            .any(|c| c.object != cs[0].object || c.region != cs[0].region);
                        let stripe = (0..nplanes).any(|p| {
                            lit[p] && {
                                let lo = cs.iter().map(|c| c.s[p]).fold(f64::INFINITY, f64::min);
                                let hi =
                                    cs.iter().map(|c| c.s[p]).fold(f64::NEG_INFINITY, f64::max);
                                let wmax = cs.iter().map(|c| c.w[p]).fold(0.0, f64::max);
                                lo <= 3.0 * wmax && hi >= -3.0 * wmax
                            }
                        });
                        if (edge || stripe) && n > 1 {
                            let mut acc = Sample {
                                ambient: 0.0,
                                laser: [0.0; MAX_PLANES],
                            };
                            for b in 0..n {
                                for a in 0..n {
                                    let du = (a as f64 + 0.5) / n as f64 - 0.5;
                                    let dv = (b as f64 + 0.5) / n as f64 - 0.5;
                                    let s = self.sample(i as f64 + du, j as f64 + dv, motion, lit);
                                    acc.ambient += s.ambient;
                                    for p in 0..MAX_PLANES {
                                        acc.laser[p] += s.laser[p];
                                    }
                                }
                            }
                            let k = 1.0 / (n * n) as f64;
                            acc.ambient *= k;
                            acc.laser.iter_mut().for_each(|x| *x *= k);
                            acc
                        } else {
                            self.sample(i as f64, j as f64, motion, lit)
                        }
                    })
                    .collect()
            })
            .collect();
        let mut ambient = Vec::with_capacity(w * h);
        let mut lasers = vec![Vec::with_capacity(w * h); nplanes];
        for row in &rows {
            for s in row {
                ambient.push(s.ambient);
                for (p, layer) in lasers.iter_mut().enumerate() {
                    layer.push(s.laser[p]);
                }
            }
        }
        Layers { ambient, lasers }
    }
}

/// Step (pixels) of the march down each column that brackets the true curve's roots.
/// Two crossings of one plane closer than this in a column (a plane grazing a surface) can
/// be missed; elsewhere every crossing is bracketed and then bisected to 1e-12 px.
pub const TRUTH_STEP_PX: f64 = 0.5;

/// The exact laser curves of the lit `planes`: for each pixel-centre column `u = i`, every
/// row `v` where the ray of `(u, v)` meets the scene exactly on a plane, at a point the
/// laser lights (inside the fan, facing the source, segment to the source free).
///
/// Roots of `s(v) = n·X(v) − d` (`X(v)` the first hit of the ray of `(u, v)`) are bracketed
/// by a march of [`TRUTH_STEP_PX`] and bisected; brackets across an object edge are
/// discarded (the curve jumps there, it does not cross).
pub fn truth_curve(setup: &RenderSetup<'_>, planes: &[usize]) -> Vec<TruthPoint> {
    let cam = &setup.calibration.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let steps = ((h as f64) / TRUTH_STEP_PX).ceil() as usize;
    let hit_at = |u: f64, v: f64| {
        ray(cam, u, v).and_then(|d| setup.scene.intersect(Vec3::zeros(), d, f64::INFINITY))
    };
    let columns: Vec<Vec<TruthPoint>> = (0..w)
        .into_par_iter()
        .map(|i| {
            let u = i as f64;
            let vs: Vec<f64> = (0..=steps)
                .map(|k| (-0.5 + k as f64 * TRUTH_STEP_PX).min(h as f64 - 0.5))
                .collect();
            let hits: Vec<_> = vs.iter().map(|&v| hit_at(u, v)).collect();
            let mut out = Vec::new();
            for &p in planes {
                let Some(plane) = setup.calibration.planes.get(p) else {
                    continue;
                };
                for k in 0..steps {
                    let (Some(ha), Some(hb)) = (hits[k], hits[k + 1]) else {
                        continue;
                    };
                    if ha.object != hb.object {
                        continue;
                    }
                    let (sa, sb) = (
                        plane.signed_distance(ha.point),
                        plane.signed_distance(hb.point),
                    );
                    // A crossing in (a, b]: strict sign change, or an exact zero at b (a zero
                    // at a belongs to the previous bracket, so no root is counted twice).
                    if !(sa * sb < 0.0 || (sb == 0.0 && sa != 0.0)) {
                        continue;
                    }
                    let (mut lo, mut hi, mut slo) = (vs[k], vs[k + 1], sa);
                    let mut ok = true;
                    for _ in 0..50 {
                        let mid = 0.5 * (lo + hi);
                        match hit_at(u, mid) {
                            Some(hm) if hm.object == ha.object => {
                                let sm = plane.signed_distance(hm.point);
                                if (sm > 0.0) == (slo > 0.0) {
                                    lo = mid;
                                    slo = sm;
                                } else {
                                    hi = mid;
                                }
                            }
                            _ => {
                                ok = false;
                                break;
                            }
                        }
                    }
                    if !ok {
                        continue;
                    }
                    let v = 0.5 * (lo + hi);
                    let Some(hm) = hit_at(u, v) else { continue };
                    let x = hm.point;
                    let facing = hm.normal.dot(&(plane.source - x)) > 0.0;
                    if !facing
                        || !setup.laser.in_fan(plane, x)
                        || setup.scene.occluded(x, plane.source)
                    {
                        continue;
                    }
                    out.push(TruthPoint {
                        plane: p,
                        column: i as u32,
                        row_px: v,
                        point_m: [x.x, x.y, x.z],
                        object: hm.object,
                    });
                }
            }
            out
        })
        .collect();
    let mut all: Vec<TruthPoint> = columns.into_iter().flatten().collect();
    all.sort_by(|a, b| {
        (a.plane, a.column)
            .cmp(&(b.plane, b.column))
            .then(a.row_px.total_cmp(&b.row_px))
    });
    all
}
