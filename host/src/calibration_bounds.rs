//! Physical ranges of a loaded calibration (`docs/calibration.md`, "When calibration
//! refuses"): a file whose values no instrument of this kind can have is refused when it is
//! loaded, naming the key, rather than failing later in a measurement.

use tangent_core::camera::Camera;
use tangent_core::real::Vec3;

/// A loaded calibration value outside its physical range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("calibration.{key} = {} is outside {range}", readable(*.value))]
pub struct OutOfRange {
    /// The key, as in the file (`camera.fx_px`, `planes[0].offset_m`).
    pub key: String,
    /// Its value.
    pub value: f64,
    /// The range, with unit and reason.
    pub range: String,
}

/// `value` as people write it: plain between 0.001 and 1e6, else in exponent form.
fn readable(value: f64) -> String {
    if value == 0.0 || (1e-3..1e6).contains(&value.abs()) {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

/// Focal lengths a camera of this instrument can have (pixels): a 100 px focal length on
/// a 752 px sensor is a 150° field, 100 000 px a 0.4° one.
pub const FOCAL_RANGE_PX: (f64, f64) = (100.0, 100_000.0);

/// Largest plane offset and source distance from the camera (metres): the instrument is
/// handheld, its lasers are centimetres from the lens.
pub const MAX_PLANE_DISTANCE_M: f64 = 2.0;

/// Checks a loaded camera against physical ranges, naming the first key outside.
pub fn check_camera(c: &Camera) -> Result<(), OutOfRange> {
    let out = |key: &str, value: f64, range: String| {
        Err(OutOfRange {
            key: format!("camera.{key}"),
            value,
            range,
        })
    };
    let (lo, hi) = FOCAL_RANGE_PX;
    for (key, v) in [("fx_px", c.fx), ("fy_px", c.fy)] {
        if !(lo..=hi).contains(&v) {
            return out(key, v, format!("{lo}..{hi} px"));
        }
    }
    let (w, h) = (c.width as f64, c.height as f64);
    if !(0.0..=w).contains(&c.cx) {
        return out("cx_px", c.cx, format!("0..{w} px (inside the image)"));
    }
    if !(0.0..=h).contains(&c.cy) {
        return out("cy_px", c.cy, format!("0..{h} px (inside the image)"));
    }
    // No lens moves a point at the image corner by more than its own radius: |k_i|·r^(2i)
    // ≤ 1 and 3|p|·r² ≤ 1 (r the normalised radius of the farthest corner).
    let r = corner_radius(c);
    let d = c.distortion;
    for (key, v, bound) in [
        ("k1", d.k1, 1.0 / r.powi(2)),
        ("k2", d.k2, 1.0 / r.powi(4)),
        ("k3", d.k3, 1.0 / r.powi(6)),
        ("p1", d.p1, 1.0 / (3.0 * r * r)),
        ("p2", d.p2, 1.0 / (3.0 * r * r)),
    ] {
        if !(0.0..=bound).contains(&v.abs()) {
            return out(
                &format!("distortion.{key}"),
                v,
                format!("±{bound:.3e} (its term may not exceed the radius at the image corner, r = {r:.2})"),
            );
        }
    }
    Ok(())
}

/// Checks loaded plane `index` (`normal`, `offset_m`, `source_m` as in the file) against
/// physical ranges, naming the first key outside (the core then validates the plane
/// itself: the source on the plane, the camera off it).
pub fn check_plane(
    index: usize,
    normal: Vec3,
    offset: f64,
    source: Vec3,
) -> Result<(), OutOfRange> {
    let out = |key: &str, value: f64, range: String| {
        Err(OutOfRange {
            key: format!("planes[{index}].{key}"),
            value,
            range,
        })
    };
    // Written with 5 or more digits a unit normal is within 1e-4 of 1; 1 % is a typo.
    let len = normal.norm();
    if !(0.99..=1.01).contains(&len) {
        return out("normal", len, "length 0.99..1.01 (a unit normal)".into());
    }
    let d = MAX_PLANE_DISTANCE_M;
    if !(1e-3..=d).contains(&offset.abs()) {
        return out("offset_m", offset, format!("±(0.001..{d}) m"));
    }
    if !(0.0..=d).contains(&source.norm()) {
        return out(
            "source_m",
            source.norm(),
            format!("0..{d} m from the camera (distance given)"),
        );
    }
    Ok(())
}

/// Normalised radius of the image corner farthest from the principal point (at least a
/// small positive value, so the bounds stay finite).
pub fn corner_radius(c: &Camera) -> f64 {
    let dx = c.cx.abs().max((c.width as f64 - c.cx).abs()) / c.fx;
    let dy = c.cy.abs().max((c.height as f64 - c.cy).abs()) / c.fy;
    dx.hypot(dy).max(1e-3)
}
