//! The naive baseline of the accuracy evaluation (`docs/accuracy.md`, "Evaluation across
//! physics models"): what a straightforward laser-triangulation pipeline — the segmentation
//! of Horus (subtraction, a global threshold, per-column centre of mass) followed by a Kåsa
//! circle fit — reads on the same captures with the same calibration. It exists to be beaten:
//! every reading Tangent reports is tabulated beside it.
//!
//! Steps, each the core's own piece where one exists:
//! 1. `on − off`, clamped at 0 ([`tangent_core::image::subtract::subtract`]);
//! 2. the core's darkness test (the one Tangent applies: no reading when the largest
//!    difference is below 20 grey levels or 8σ̂ of the noise), then Otsu's threshold of the difference histogram
//!    ([`tangent_core::image::threshold::otsu_threshold`]), floored at 5σ̂ of the difference
//!    noise ([`tangent_core::image::threshold::difference_noise`]) — on a sparse stripe Otsu
//!    alone separates the zeros from the noise;
//! 3. per image column, the runs of rows above the threshold; the `k` runs with the brightest
//!    peaks (`k` = planes) are the stripes, given to the planes in index order from the top
//!    (the reference design's planes are parallel and plane 0 is the upper stripe); each
//!    gives the intensity-weighted centre of mass of its thresholded rows within
//!    ±[`WINDOW_ROWS`] of its peak (Horus's windowed centre of mass);
//! 4. triangulation on the calibrated plane ([`tangent_core::laser_plane::triangulate`]),
//!    in-plane coordinates, Kåsa's circle ([`tangent_core::solvers::circle::fit_kasa`]);
//! 5. diameter `2r`; with several planes the mean of the planes' diameters (a naive pipeline
//!    knows nothing of lean: a tilted stem's section is an ellipse, read as a circle).

use std::borrow::Cow;

use tangent_core::calibration::Calibration;
use tangent_core::image::subtract::subtract;
use tangent_core::image::threshold::{
    difference_noise, histogram, histogram_len, otsu_threshold, Floors,
};
use tangent_core::image::Frame;
use tangent_core::laser_plane::triangulate;
use tangent_core::real::{Real, Vec2};
use tangent_core::solvers::circle::fit_kasa;

use crate::capture::Capture;
use crate::measure::composite_on_frame;
use crate::pgm::Pgm;

/// Half-height (rows) of the window around a column's peak whose thresholded pixels enter
/// the centre of mass (Horus's "window"; a stripe of σ ≤ 1.7 px lies within ±3σ of it).
pub const WINDOW_ROWS: usize = 5;

/// Floor of the threshold in units of the difference image's noise σ̂
/// ([`difference_noise`]): a Gaussian pixel exceeds 5σ with probability 3·10⁻⁷.
pub const NOISE_FLOOR_SIGMAS: f64 = 5.0;

/// Why the baseline gave no diameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BaselineError {
    /// The capture has no laser-on frame with every plane (nor frames to compose one).
    #[error("no laser-on frame lights all {0} planes")]
    NoFullFrame(usize),
    /// Frame sizes or depths disagree, or a frame is malformed.
    #[error("frames: {0}")]
    Frame(String),
    /// The pair fails the core's darkness test ([`Floors::is_lit`], the same Tangent
    /// applies): no laser light to segment.
    #[error("no laser light (largest difference {max_difference})")]
    Dark {
        /// Largest `on − off` difference.
        max_difference: u32,
    },
    /// Otsu's threshold could not be computed (a flat difference image).
    #[error("threshold: {0}")]
    Threshold(String),
    /// Fewer than 3 stripe points of a plane.
    #[error("plane {plane}: {points} stripe points (3 needed)")]
    TooFewPoints {
        /// The plane.
        plane: usize,
        /// Points found.
        points: usize,
    },
    /// The circle fit failed.
    #[error("plane {plane}: circle fit: {message}")]
    Fit {
        /// The plane.
        plane: usize,
        /// The solver's error.
        message: String,
    },
}

/// The baseline's reading of one capture.
#[derive(Debug, Clone, PartialEq)]
pub struct BaselineReading {
    /// Diameter (metres).
    pub diameter_m: f64,
    /// Stripe points used, all planes.
    pub points: usize,
}

/// Steps 1–4 of the naive pipeline on `capture` with `calibration` (its own when `None`):
/// each plane's stripe points in its in-plane coordinates ([`LaserPlane::to_plane_coords`]).
///
/// [`LaserPlane::to_plane_coords`]: tangent_core::laser_plane::LaserPlane::to_plane_coords
pub fn stripe_points(
    capture: &Capture,
    calibration: Option<&Calibration>,
) -> Result<Vec<Vec<Vec2>>, BaselineError> {
    let cal = calibration.unwrap_or(&capture.calibration);
    let planes = cal.planes.len();
    let off = capture.off_frame();
    let on: Cow<'_, Pgm> = match capture
        .on_frames()
        .find(|(lit, _)| (0..planes).all(|k| lit.contains(&k)))
    {
        Some((_, f)) => Cow::Borrowed(f),
        None => Cow::Owned(
            composite_on_frame(capture, planes).ok_or(BaselineError::NoFullFrame(planes))?,
        ),
    };
    let (w, h) = (off.width, off.height);
    if (on.width, on.height, on.maxval) != (w, h, off.maxval) {
        return Err(BaselineError::Frame(
            "laser-on and laser-off frames differ in size or depth".into(),
        ));
    }
    let bits = off.bit_depth();
    let frame_err = |e: tangent_core::image::FrameError| BaselineError::Frame(e.to_string());
    let (on_px, off_px) = (on.to_u16(), off.to_u16());
    let on_f = Frame::new(on_px.as_slice(), w, h, w)
        .and_then(|f| f.with_bit_depth(bits))
        .map_err(frame_err)?;
    let off_f = Frame::new(off_px.as_slice(), w, h, w)
        .and_then(|f| f.with_bit_depth(bits))
        .map_err(frame_err)?;
    let mut diff = vec![0u16; w * h];
    let mut diff_f = Frame::new(diff.as_mut_slice(), w, h, w)
        .and_then(|f| f.with_bit_depth(bits))
        .map_err(frame_err)?;
    let stats = subtract(&on_f, &off_f, &mut diff_f).map_err(frame_err)?;
    let mut bins = vec![0u32; histogram_len(&diff_f)];
    histogram(&diff_f, &mut bins).map_err(|e| BaselineError::Threshold(e.to_string()))?;
    let noise = difference_noise(&bins);
    if !Floors::default().is_lit(stats.max_difference, noise) {
        return Err(BaselineError::Dark {
            max_difference: stats.max_difference,
        });
    }
    // Otsu alone splits the zeros from the noise when the stripe is a small share of the
    // image; the floor of 5σ of the difference noise keeps noise pixels out (< 1 a frame).
    let otsu = otsu_threshold(&bins).map_err(|e| BaselineError::Threshold(e.to_string()))?;
    let noise_floor = (NOISE_FLOOR_SIGMAS * noise as f64).ceil() as u32;
    let t = otsu.max(noise_floor);

    // Per column: the runs of rows above the threshold; the `k` runs with the brightest
    // peaks are the stripes, taken in row order; each gives the centre of mass of its
    // thresholded rows within ±WINDOW_ROWS of its peak.
    let mut per_plane: Vec<Vec<Vec2>> = vec![Vec::new(); planes];
    let mut runs: Vec<(usize, usize, u32)> = Vec::new(); // (first row, peak row, peak value)
    for x in 0..w {
        runs.clear();
        let value = |y: usize| diff[y * w + x] as u32;
        let mut y = 0;
        while y < h {
            if value(y) <= t {
                y += 1;
                continue;
            }
            let first = y;
            let mut peak = y;
            while y < h && value(y) > t {
                if value(y) > value(peak) {
                    peak = y;
                }
                y += 1;
            }
            runs.push((first, peak, value(peak)));
        }
        if runs.len() < planes {
            continue;
        }
        runs.sort_by(|a, b| b.2.cmp(&a.2).then(a.0.cmp(&b.0)));
        runs.truncate(planes);
        runs.sort_by_key(|r| r.0);
        for (k, &(_, peak, _)) in runs.iter().enumerate() {
            let lo = peak.saturating_sub(WINDOW_ROWS);
            let hi = (peak + WINDOW_ROWS).min(h - 1);
            let (mut m0, mut m1) = (0.0, 0.0);
            for yy in lo..=hi {
                let v = value(yy);
                if v > t {
                    m0 += v as f64;
                    m1 += yy as f64 * v as f64;
                }
            }
            let pixel = Vec2::new(x as Real, (m1 / m0) as Real);
            let plane = &cal.planes[k];
            if let Ok(p) = triangulate(&cal.camera, plane, pixel) {
                per_plane[k].push(plane.to_plane_coords(p));
            }
        }
    }
    Ok(per_plane)
}

/// Runs the naive pipeline on `capture` with `calibration` (its own when `None`).
pub fn measure(
    capture: &Capture,
    calibration: Option<&Calibration>,
) -> Result<BaselineReading, BaselineError> {
    let per_plane = stripe_points(capture, calibration)?;
    let planes = per_plane.len();
    let mut sum = 0.0;
    let mut points = 0;
    for (plane, pts) in per_plane.iter().enumerate() {
        if pts.len() < 3 {
            return Err(BaselineError::TooFewPoints {
                plane,
                points: pts.len(),
            });
        }
        let c = fit_kasa(pts).map_err(|e| BaselineError::Fit {
            plane,
            message: e.to_string(),
        })?;
        sum += 2.0 * c.radius as f64;
        points += pts.len();
    }
    Ok(BaselineReading {
        diameter_m: sum / planes.max(1) as f64,
        points,
    })
}
