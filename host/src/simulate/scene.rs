//! Scene objects, ray intersection and surface reflectance (`docs/simulator.md`, "Scene").
//!
//! The objects are the truth types of [`crate::truth`] (the `[[truth.objects]]` of
//! `capture.toml`), so the truth of a capture is exactly what was rendered.

// `!(x > 0.0)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use tangent_core::real::Vec3;

use super::reflectance::Reflectance;
use crate::truth::{Object, Texture, Wave};

/// Why a scene is invalid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneError {
    /// Object `index` has an impossible parameter.
    #[error("scene object {index}: {message}")]
    Invalid {
        /// Index of the object.
        index: usize,
        /// What is wrong.
        message: String,
    },
}

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

fn unit(a: [f64; 3]) -> Option<Vec3> {
    let v = v3(a);
    let n = v.norm();
    (n.is_finite() && n > 1e-12).then(|| v / n)
}

/// A ray–surface hit.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    /// Ray parameter (`point = origin + t·direction`).
    pub t: f64,
    /// The point (metres, scene frame).
    pub point: Vec3,
    /// Unit surface normal, on the side the ray came from.
    pub normal: Vec3,
    /// Index of the object.
    pub object: usize,
}

#[derive(Debug, Clone)]
enum Shape {
    Cylinder {
        c: Vec3,
        axis: Vec3,
        m: Vec3,
        k: Vec3,
        a: f64,
        b: f64,
        extent: Option<[f64; 2]>,
    },
    Sphere {
        c: Vec3,
        r: f64,
        /// Semi-axes relative to `r` along `x, y, z` (an ellipsoid), if stretched.
        stretch: Option<Vec3>,
    },
    Plane {
        p: Vec3,
        n: Vec3,
        u: Vec3,
        w: Vec3,
        /// The box `(min, max)` the plane is cut to, if any.
        bounds: Option<(Vec3, Vec3)>,
        /// A disc of this radius about `p` (an end face), if any.
        disc_radius: Option<f64>,
    },
    Road {
        z0: f64,
        waves: Vec<Wave>,
        amp: f64,
        min_wavelength: f64,
        max_slope: f64,
    },
    Board {
        o: Vec3,
        x: Vec3,
        y: Vec3,
        n: Vec3,
        square: f64,
        cols: usize,
        rows: usize,
        border: f64,
        dark: f64,
    },
}

#[derive(Debug, Clone)]
struct Prepared {
    shape: Shape,
    albedo: f64,
    texture: Texture,
    contrast: f64,
    seed: u64,
    /// The object's own BRDF (a steel ball's lobe), overriding the scene's.
    reflectance: Option<Reflectance>,
}

/// A validated scene, ready for ray casting.
#[derive(Debug, Clone)]
pub struct Scene {
    objects: Vec<Prepared>,
    /// Feature size of every texture relative to its nominal one (1 = as documented).
    texture_scale: f64,
}

/// Smallest ray parameter accepted as a hit (metres for unit directions): avoids a shadow
/// ray re-hitting the surface it starts on (1 µm ≫ rounding of 1 m coordinates, 1e-16 m).
pub const T_MIN: f64 = 1e-6;

impl Scene {
    /// Validates and prepares `objects`; `seed` varies the textures.
    pub fn new(objects: &[Object], seed: u64) -> Result<Self, SceneError> {
        let mut out = Vec::with_capacity(objects.len());
        for (index, o) in objects.iter().enumerate() {
            let bad = |message: &str| SceneError::Invalid {
                index,
                message: message.to_string(),
            };
            let (albedo, texture, contrast) = match o {
                Object::Cylinder(c) => (c.albedo, c.texture, c.texture_contrast),
                Object::Sphere(s) => (s.albedo, s.texture, s.texture_contrast),
                Object::Plane(p) => (p.albedo, p.texture, p.texture_contrast),
                Object::Road(r) => (r.albedo, r.texture, r.texture_contrast),
                Object::Board(b) => (b.albedo, Texture::None, 0.0),
                Object::Disc(d) => (d.albedo, d.texture, d.texture_contrast),
            };
            if !(0.0..=1.0).contains(&albedo) || !(0.0..=1.0).contains(&contrast) {
                return Err(bad("albedo and texture_contrast must be in [0, 1]"));
            }
            let shape = match o {
                Object::Cylinder(c) => {
                    let axis = unit(c.axis_direction).ok_or_else(|| bad("zero axis direction"))?;
                    let (a, b, major) = match (c.radius_m, c.semi_axes_m) {
                        (Some(r), None) => {
                            // Any perpendicular direction will do for a circle.
                            let helper = if axis.x.abs() < 0.9 {
                                Vec3::x()
                            } else {
                                Vec3::y()
                            };
                            (r, r, helper)
                        }
                        (None, Some([a, b])) => {
                            let m = c
                                .major_axis_direction
                                .ok_or_else(|| bad("semi_axes_m needs major_axis_direction"))?;
                            (a, b, v3(m))
                        }
                        _ => return Err(bad("give exactly one of radius_m and semi_axes_m")),
                    };
                    if !(a.is_finite() && b.is_finite() && a > 0.0 && b > 0.0) {
                        return Err(bad("radius / semi-axes must be positive"));
                    }
                    let m = major - axis * axis.dot(&major);
                    let mn = m.norm();
                    if !(mn > 1e-9) {
                        return Err(bad("major_axis_direction is parallel to the axis"));
                    }
                    let m = m / mn;
                    let k = axis.cross(&m);
                    Shape::Cylinder {
                        c: v3(c.axis_point_m),
                        axis,
                        m,
                        k,
                        a,
                        b,
                        extent: c.extent_m,
                    }
                }
                Object::Sphere(s) => {
                    if !(s.radius_m.is_finite() && s.radius_m > 0.0) {
                        return Err(bad("radius must be positive"));
                    }
                    if s.stretch
                        .is_some_and(|f| !f.iter().all(|x| x.is_finite() && *x > 0.0))
                    {
                        return Err(bad("stretch factors must be positive"));
                    }
                    if s.specular.is_some_and(|l| {
                        !((0.0..=1.0).contains(&l.fraction)
                            && l.exponent.is_finite()
                            && l.exponent >= 0.0)
                    }) {
                        return Err(bad(
                            "specular fraction must be in [0, 1] and its exponent ≥ 0",
                        ));
                    }
                    Shape::Sphere {
                        c: v3(s.centre_m),
                        r: s.radius_m,
                        stretch: s.stretch.filter(|f| *f != [1.0; 3]).map(v3),
                    }
                }
                Object::Plane(p) => {
                    let n = unit(p.normal).ok_or_else(|| bad("zero normal"))?;
                    let helper = if n.y.abs() < 0.9 {
                        Vec3::y()
                    } else {
                        Vec3::x()
                    };
                    let u = helper.cross(&n).normalize();
                    let w = n.cross(&u);
                    Shape::Plane {
                        p: v3(p.point_m),
                        n,
                        u,
                        w,
                        bounds: p.bounds_m.map(|[a, b]| (v3(a), v3(b))),
                        disc_radius: None,
                    }
                }
                Object::Disc(d) => {
                    let n = unit(d.normal).ok_or_else(|| bad("zero normal"))?;
                    if !(d.radius_m.is_finite() && d.radius_m > 0.0) {
                        return Err(bad("radius must be positive"));
                    }
                    let helper = if n.y.abs() < 0.9 {
                        Vec3::y()
                    } else {
                        Vec3::x()
                    };
                    let u = helper.cross(&n).normalize();
                    Shape::Plane {
                        p: v3(d.centre_m),
                        n,
                        u,
                        w: n.cross(&u),
                        bounds: None,
                        disc_radius: Some(d.radius_m),
                    }
                }
                Object::Road(r) => {
                    if !(r.distance_m.is_finite() && r.distance_m > 0.0) {
                        return Err(bad("distance_m must be positive"));
                    }
                    if r.waves
                        .iter()
                        .any(|w| !(w.wavelength_m > 0.0 && w.amplitude_m.is_finite()))
                    {
                        return Err(bad("wave wavelengths must be positive"));
                    }
                    let amp = r.waves.iter().map(|w| w.amplitude_m.abs()).sum();
                    let min_wavelength = r
                        .waves
                        .iter()
                        .map(|w| w.wavelength_m)
                        .fold(f64::INFINITY, f64::min);
                    let max_slope = r
                        .waves
                        .iter()
                        .map(|w| 2.0 * std::f64::consts::PI * w.amplitude_m.abs() / w.wavelength_m)
                        .sum();
                    Shape::Road {
                        z0: r.distance_m,
                        waves: r.waves.clone(),
                        amp,
                        min_wavelength,
                        max_slope,
                    }
                }
                Object::Board(b) => {
                    let x = unit(b.x_axis).ok_or_else(|| bad("zero x_axis"))?;
                    let y = v3(b.y_axis) - x * x.dot(&v3(b.y_axis));
                    let yn = y.norm();
                    if !(yn > 1e-9) {
                        return Err(bad("y_axis is parallel to x_axis"));
                    }
                    let [cols, rows] = b.inner_corners;
                    if cols < 2 || rows < 2 {
                        return Err(bad("a board needs at least 2 × 2 inner corners"));
                    }
                    if !(b.square_m.is_finite()
                        && b.square_m > 0.0
                        && b.border_m.is_finite()
                        && b.border_m >= 0.0)
                    {
                        return Err(bad("square_m must be positive and border_m ≥ 0"));
                    }
                    if !(0.0..=1.0).contains(&b.dark_albedo) {
                        return Err(bad("dark_albedo must be in [0, 1]"));
                    }
                    let y = y / yn;
                    Shape::Board {
                        o: v3(b.origin_m),
                        x,
                        y,
                        n: x.cross(&y),
                        square: b.square_m,
                        cols,
                        rows,
                        border: b.border_m,
                        dark: b.dark_albedo,
                    }
                }
            };
            out.push(Prepared {
                shape,
                albedo,
                texture,
                contrast,
                seed: splitmix(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)),
                reflectance: match o {
                    Object::Sphere(s) => s.specular.map(|l| Reflectance::Glossy {
                        specular_fraction: l.fraction,
                        exponent: l.exponent,
                    }),
                    _ => None,
                },
            });
        }
        Ok(Scene {
            objects: out,
            texture_scale: 1.0,
        })
    }

    /// Nearest hit of the ray `origin + t·dir` with `t ∈ (T_MIN, t_max)`.
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, o) in self.objects.iter().enumerate() {
            let limit = best.map_or(t_max, |h| h.t);
            if let Some((t, normal)) = o.shape.intersect(origin, dir, limit) {
                let n = if normal.dot(&dir) > 0.0 {
                    -normal
                } else {
                    normal
                };
                best = Some(Hit {
                    t,
                    point: origin + dir * t,
                    normal: n,
                    object: i,
                });
            }
        }
        best
    }

    /// True when something lies on the segment `from → to` (excluding its ends).
    pub fn occluded(&self, from: Vec3, to: Vec3) -> bool {
        let d = to - from;
        // t runs over (T_MIN, 1 − 1e-6): the far end (a light source) is not an occluder.
        self.objects.iter().any(|o| {
            o.shape
                .intersect(from, d, 1.0 - 1e-6)
                .is_some_and(|(t, _)| t * d.norm() > T_MIN)
        })
    }

    /// Albedo of object `object` at `point`, texture included.
    pub fn albedo(&self, object: usize, point: Vec3) -> f64 {
        let Some(o) = self.objects.get(object) else {
            return 0.0;
        };
        if let Some((a, b)) = o.shape.board_square(point) {
            return if (a + b).rem_euclid(2) == 0 {
                board_dark(&o.shape)
            } else {
                o.albedo
            };
        }
        if o.texture == Texture::None || o.contrast == 0.0 {
            return o.albedo;
        }
        let (s1, s2) = o.shape.surface_coords(point);
        let (s1, s2) = (s1 / self.texture_scale, s2 / self.texture_scale);
        let pattern = match o.texture {
            Texture::None => 0.0,
            // Furrows: features 8 cm long along the axis, 1.5 cm across, plus fine detail.
            Texture::Bark => {
                let coarse = fbm(s1 / 0.08, s2 / 0.015, o.seed, 3);
                let ridges = (1.0 - (2.0 * coarse - 1.0).abs()).powi(3);
                0.75 * ridges + 0.25 * fbm(s1 / 0.01, s2 / 0.004, o.seed ^ 1, 2)
            }
            Texture::Stone => fbm(s1 / 0.05, s2 / 0.05, o.seed, 4),
            Texture::Asphalt => fbm(s1 / 0.005, s2 / 0.005, o.seed, 2),
        };
        o.albedo * (1.0 - o.contrast * pattern.clamp(0.0, 1.0))
    }
}

impl Scene {
    /// The same scene with every texture's features `scale` times larger (bark furrows,
    /// stone grains; a physics-model parameter, `docs/simulator.md`, "Physics models").
    /// Non-positive or non-finite scales leave the textures as they are.
    pub fn with_texture_scale(mut self, scale: f64) -> Self {
        if scale.is_finite() && scale > 0.0 {
            self.texture_scale = scale;
        }
        self
    }

    /// Reflectance region of `point` on object `object`: the square index of a board (a
    /// different value for every square, 0 on its border), 0 on every other object. The
    /// renderer supersamples pixels whose corners see different regions, so the squares'
    /// edges are anti-aliased like object edges (`docs/simulator.md`, "Rendering").
    pub fn region(&self, object: usize, point: Vec3) -> i64 {
        self.objects
            .get(object)
            .and_then(|o| o.shape.board_square(point))
            .map_or(0, |(a, b)| 1 + (a + 1) + (b + 1) * 1_000_003)
    }

    /// The BRDF of object `object` when it has its own (a steel ball), else `None` (the
    /// scene's applies).
    pub fn reflectance(&self, object: usize) -> Option<Reflectance> {
        self.objects.get(object).and_then(|o| o.reflectance)
    }
}

fn board_dark(shape: &Shape) -> f64 {
    match shape {
        Shape::Board { dark, .. } => *dark,
        _ => 0.0,
    }
}

impl Shape {
    /// Square `(a, b)` of a board containing `p` (on its plane), `None` on the border or
    /// for other shapes.
    fn board_square(&self, p: Vec3) -> Option<(i64, i64)> {
        let Shape::Board {
            o,
            x,
            y,
            square,
            cols,
            rows,
            ..
        } = self
        else {
            return None;
        };
        let rel = p - o;
        let (a, b) = ((rel.dot(x) / square).floor(), (rel.dot(y) / square).floor());
        let inside = a >= -1.0 && a <= *cols as f64 - 1.0 && b >= -1.0 && b <= *rows as f64 - 1.0;
        inside.then_some((a as i64, b as i64))
    }

    fn intersect(&self, o: Vec3, d: Vec3, t_max: f64) -> Option<(f64, Vec3)> {
        let accept = |t: f64| t.is_finite() && t > T_MIN / d.norm().max(1e-300) && t < t_max;
        match self {
            Shape::Cylinder {
                c,
                axis,
                m,
                k,
                a,
                b,
                extent,
            } => {
                let rel = o - c;
                let (ox, oy, os) = (rel.dot(m) / a, rel.dot(k) / b, rel.dot(axis));
                let (dx, dy, ds) = (d.dot(m) / a, d.dot(k) / b, d.dot(axis));
                // (ox + t dx)² + (oy + t dy)² = 1, scaled to the unit circle.
                let qa = dx * dx + dy * dy;
                if qa <= 0.0 {
                    return None;
                }
                let qb = ox * dx + oy * dy;
                let qc = ox * ox + oy * oy - 1.0;
                let (t0, t1) = ordered_roots(qa, qb, qc)?;
                for t in [t0, t1] {
                    if !accept(t) {
                        continue;
                    }
                    let s = os + t * ds;
                    if extent.is_some_and(|[s0, s1]| s < s0 || s > s1) {
                        continue;
                    }
                    let (x, y) = (ox + t * dx, oy + t * dy);
                    let n = (*m * (x / a) + *k * (y / b)).normalize();
                    return Some((t, n));
                }
                None
            }
            Shape::Sphere {
                c,
                r,
                stretch: Some(f),
            } => {
                // The unit sphere in coordinates scaled by the semi-axes `r·f`; the normal is
                // the gradient of |X'|² in the original frame.
                let axes = *f * *r;
                let rel = (o - c).component_div(&axes);
                let dd = d.component_div(&axes);
                let qa = dd.dot(&dd);
                let qb = rel.dot(&dd);
                let qc = rel.dot(&rel) - 1.0;
                let (t0, t1) = ordered_roots(qa, qb, qc)?;
                [t0, t1].into_iter().find(|&t| accept(t)).map(|t| {
                    let x = (rel + dd * t).component_div(&axes);
                    (t, x.normalize())
                })
            }
            Shape::Sphere {
                c,
                r,
                stretch: None,
            } => {
                let rel = o - c;
                let qa = d.dot(&d);
                let qb = rel.dot(&d);
                let qc = rel.dot(&rel) - r * r;
                let (t0, t1) = ordered_roots(qa, qb, qc)?;
                [t0, t1]
                    .into_iter()
                    .find(|&t| accept(t))
                    .map(|t| (t, (o + d * t - c) / *r))
            }
            Shape::Plane {
                p,
                n,
                bounds,
                disc_radius,
                ..
            } => {
                let den = n.dot(&d);
                if den.abs() < 1e-15 {
                    return None;
                }
                let t = n.dot(&(p - o)) / den;
                let inside = |(lo, hi): &(Vec3, Vec3)| {
                    let x = o + d * t;
                    (0..3).all(|k| x[k] >= lo[k] && x[k] <= hi[k])
                };
                let in_disc = |r: &f64| (o + d * t - p).norm() <= *r;
                (accept(t)
                    && bounds.as_ref().is_none_or(inside)
                    && disc_radius.as_ref().is_none_or(in_disc))
                .then_some((t, *n))
            }
            Shape::Road {
                z0,
                waves,
                amp,
                min_wavelength,
                max_slope,
            } => {
                // g(t) = z(t) − surface(x(t), y(t)); the surface lies within z0 ± amp, so the
                // first root is in the t-range where z crosses that slab. March to the first
                // sign change, then refine by regula falsi.
                if d.z <= 0.0 {
                    return None;
                }
                let g = |t: f64| {
                    let p = o + d * t;
                    p.z - z0 - road_height(waves, p.x, p.y)
                };
                let t_lo = ((z0 - amp - 1e-9 - o.z) / d.z).max(0.0);
                let t_hi = (z0 + amp + 1e-9 - o.z) / d.z;
                if t_hi <= t_lo || t_lo >= t_max {
                    return None;
                }
                // Steps: at least λ_min/16 of lateral travel (a crest narrower than that
                // could be skipped), and larger while far from the surface: g changes at
                // most L = d_z + |d_xy|·S per unit t (S = Σ 2πA/λ, the largest slope), so
                // no root lies within |g|/L of t (conservative advancement).
                let dxy = (d.x * d.x + d.y * d.y).sqrt();
                let lipschitz = d.z + dxy * max_slope;
                let dt_min = if dxy > 0.0 {
                    min_wavelength / 16.0 / dxy
                } else {
                    f64::INFINITY
                }
                .min((t_hi - t_lo) / 16.0);
                let (mut ta, mut ga) = (t_lo, g(t_lo));
                if ga >= 0.0 {
                    return None; // ray starts behind the surface
                }
                while ta < t_hi {
                    let tb = (ta + dt_min.max(-ga / lipschitz)).min(t_hi);
                    let gb = g(tb);
                    if gb >= 0.0 {
                        // Illinois regula falsi on [ta, tb] (superlinear; ~10 evaluations).
                        let (mut lo, mut hi, mut glo, mut ghi) = (ta, tb, ga, gb);
                        let mut side = 0i8;
                        for _ in 0..60 {
                            let t = (lo * ghi - hi * glo) / (ghi - glo);
                            let gt = g(t);
                            if gt >= 0.0 {
                                hi = t;
                                ghi = gt;
                                if side == 1 {
                                    glo *= 0.5;
                                }
                                side = 1;
                            } else {
                                lo = t;
                                glo = gt;
                                if side == -1 {
                                    ghi *= 0.5;
                                }
                                side = -1;
                            }
                            if (hi - lo) * d.z < 1e-12 || gt.abs() < 1e-13 {
                                break;
                            }
                        }
                        let t = if ghi.abs() < glo.abs() { hi } else { lo };
                        if !accept(t) {
                            return None;
                        }
                        let p = o + d * t;
                        let (hx, hy) = road_gradient(waves, p.x, p.y);
                        return Some((t, Vec3::new(hx, hy, -1.0).normalize()));
                    }
                    ta = tb;
                    ga = gb;
                }
                None
            }
            Shape::Board {
                o: p0,
                x,
                y,
                n,
                square,
                cols,
                rows,
                border,
                ..
            } => {
                let den = n.dot(&d);
                if den.abs() < 1e-15 {
                    return None;
                }
                let t = n.dot(&(p0 - o)) / den;
                if !accept(t) {
                    return None;
                }
                // Inside the rectangle: squares −1..=cols (−1..=rows) plus the border.
                let rel = o + d * t - p0;
                let (bx, by) = (rel.dot(x), rel.dot(y));
                let lo = -square - border;
                let (hx, hy) = (
                    *cols as f64 * square + border,
                    *rows as f64 * square + border,
                );
                (bx >= lo && bx <= hx && by >= lo && by <= hy).then_some((t, *n))
            }
        }
    }

    fn surface_coords(&self, p: Vec3) -> (f64, f64) {
        match self {
            Shape::Cylinder {
                c,
                axis,
                m,
                k,
                a,
                b,
                ..
            } => {
                let rel = p - c;
                let ang = (rel.dot(k) / b).atan2(rel.dot(m) / a);
                (rel.dot(axis), ang * 0.5 * (a + b))
            }
            Shape::Sphere { c, r, .. } => {
                let rel = (p - c) / *r;
                (rel.y.clamp(-1.0, 1.0).asin() * r, rel.z.atan2(rel.x) * r)
            }
            Shape::Plane { p: p0, u, w, .. } => {
                let rel = p - p0;
                (rel.dot(u), rel.dot(w))
            }
            Shape::Road { .. } => (p.x, p.y),
            Shape::Board { o, x, y, .. } => {
                let rel = p - o;
                (rel.dot(x), rel.dot(y))
            }
        }
    }
}

/// Height of a road profile at `(x, y)` (metres).
pub fn road_height(waves: &[Wave], x: f64, y: f64) -> f64 {
    waves
        .iter()
        .map(|w| {
            let (s, c) = w.direction_rad.sin_cos();
            w.amplitude_m
                * (2.0 * std::f64::consts::PI * (x * c + y * s) / w.wavelength_m + w.phase_rad)
                    .sin()
        })
        .sum()
}

fn road_gradient(waves: &[Wave], x: f64, y: f64) -> (f64, f64) {
    waves.iter().fold((0.0, 0.0), |(gx, gy), w| {
        let (s, c) = w.direction_rad.sin_cos();
        let k = 2.0 * std::f64::consts::PI / w.wavelength_m;
        let d = w.amplitude_m * k * (k * (x * c + y * s) + w.phase_rad).cos();
        (gx + d * c, gy + d * s)
    })
}

/// SplitMix64: a bijective 64-bit mixer (Steele et al. 2014), used to derive independent
/// seeds and lattice hashes.
pub fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn lattice(ix: i64, iy: i64, seed: u64) -> f64 {
    let h = splitmix(
        seed ^ splitmix((ix as u64).wrapping_mul(0x1000_0000_01B3) ^ (iy as u64).rotate_left(32)),
    );
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Value noise in `[0, 1)`: smooth (C¹) interpolation of hashed lattice values.
pub fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as i64, fy as i64);
    let (tx, ty) = (x - fx, y - fy);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(tx), s(ty));
    let a = lattice(ix, iy, seed);
    let b = lattice(ix + 1, iy, seed);
    let c = lattice(ix, iy + 1, seed);
    let d = lattice(ix + 1, iy + 1, seed);
    let top = a + (b - a) * sx;
    let bottom = c + (d - c) * sx;
    top + (bottom - top) * sy
}

/// Fractal sum of `octaves` value-noise octaves, normalised to `[0, 1)`.
pub fn fbm(x: f64, y: f64, seed: u64, octaves: u32) -> f64 {
    let (mut sum, mut norm, mut amp, mut freq) = (0.0, 0.0, 1.0, 1.0);
    for o in 0..octaves {
        sum += amp * value_noise(x * freq, y * freq, seed.wrapping_add(o as u64));
        norm += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / norm
}

/// The real roots `t0 ≤ t1` of `qa·t² + 2·qb·t + qc = 0` (`qa > 0`), or `None` when the ray
/// misses. Computed as `q = −(qb + sign(qb)·√disc)`, `t = q/qa` and `qc/q`, which avoids the
/// cancellation of the textbook formula when one root is near zero.
fn ordered_roots(qa: f64, qb: f64, qc: f64) -> Option<(f64, f64)> {
    let disc = qb * qb - qa * qc;
    if disc < 0.0 {
        return None;
    }
    let q = -(qb + qb.signum() * disc.sqrt());
    let (t0, t1) = (q / qa, if q != 0.0 { qc / q } else { -qb / qa });
    Some(if t0 > t1 { (t1, t0) } else { (t0, t1) })
}
