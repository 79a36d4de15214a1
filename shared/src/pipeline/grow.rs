//! Growing each plane's thresholded curve along its stripe, column by column outward from its
//! ends, with a threshold relative to the noise instead of the segmentation's
//! (`docs/pipeline.md`, "Growing the curve").
//!
//! On a glossy stem auto exposure puts the specular highlight near full scale and Otsu's
//! threshold falls between the highlight and the diffuse stripe: the diffuse sides, well above
//! the noise, are dropped and the fit sees a short arc (`docs/accuracy.md`, session 3). Here a
//! column beyond a curve's end is accepted when its brightest pixel near the row the track
//! predicts is at least `min_snr` noise σ, and the point is then located exactly as the
//! thresholded columns are ([`curve::locate_seeded`], the same estimator and window), so the
//! grown points are the same kind of point as the others.

// `!(x >= y)` is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::calibration::MAX_PLANES;
use crate::curve::{self, CurvePoint, ExtractParams};
use crate::image::{Frame, Pixel};
use crate::real::{Float, Real};

/// Parameters of the growth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GrowParams {
    /// A column is accepted when its brightest pixel in the search window is at least this
    /// many noise σ of the difference frame. The default 4 keeps the chance that noise alone
    /// extends an end below 10⁻³: `(max_misses + 1)·(2·half_window + 1)·Q(4)` = 21 · 3.2·10⁻⁵
    /// (`docs/pipeline.md`, "Growing the curve").
    pub min_snr: Real,
    /// Rows searched either side of the row extrapolated from the track (the continuity
    /// bound: the row's change per column beyond the linear prediction).
    pub half_window_px: usize,
    /// Consecutive columns without an accepted point that end the growth.
    pub max_misses: usize,
}

impl Default for GrowParams {
    fn default() -> Self {
        GrowParams {
            min_snr: 4.0,
            half_window_px: 3,
            max_misses: 2,
        }
    }
}

/// Points used for the track's slope at its end.
const SLOPE_SPAN: usize = 4;

/// Grows each plane's curve (`curve[..n]`, each plane's points contiguous and ordered by
/// column, ranges in `plane_points`) outward from its first and last column, inserting the
/// new points in column order and updating the ranges; returns the new point count. The free
/// tail of `curve` is the scratch space: growth stops where it is full. `located(params, x,
/// row, saturation)` returns the point located during the read-out from seed `row` in column `x`
/// where there is one (`super::readout_fits`, the same point the estimator gives here), so
/// that a grown column whose stripe was a candidate is not located twice.
#[allow(clippy::too_many_arguments)]
pub(super) fn grow_curves<P: Pixel>(
    diff: &Frame<P, &[P]>,
    curve: &mut [CurvePoint],
    mut n: usize,
    plane_points: &mut [(usize, usize); MAX_PLANES],
    n_planes: usize,
    extract: &ExtractParams,
    noise: Real,
    params: &GrowParams,
    mut located: impl FnMut(&ExtractParams, usize, u16, Real) -> Option<Option<CurvePoint>>,
) -> usize {
    let level = params.min_snr * noise;
    if !(level > 0.0) {
        return n;
    }
    for plane in (0..n_planes.min(MAX_PLANES)).rev() {
        for leftward in [true, false] {
            let (s, e) = plane_points[plane];
            if e <= s || e > n {
                continue;
            }
            let g = grow_end(
                diff,
                curve,
                n,
                (s, e),
                leftward,
                extract,
                level,
                params,
                &mut located,
            );
            if g == 0 {
                continue;
            }
            // The grown points sit at `n..n + g`, outward from the end; move them into place.
            let at = if leftward { s } else { e };
            insert_grown(curve, at, n, g, leftward);
            plane_points[plane].1 += g;
            for later in plane_points.iter_mut().take(n_planes).skip(plane + 1) {
                later.0 += g;
                later.1 += g;
            }
            n += g;
        }
    }
    n
}

/// Moves the `g` points grown at `curve[n..n + g]` (outward order: reversed first when
/// `reverse`) to `curve[at..]`, shifting `curve[at..n]` up by `g`. Through the free tail
/// beyond them where it has room: the grown points parked there and the points after `at`
/// moved once, where rotating them into place swapped them element by element (27,000
/// instructions for the tilted stem's four ends on the device, `docs/performance.md`,
/// issue 17); else the rotation.
fn insert_grown(curve: &mut [CurvePoint], at: usize, n: usize, g: usize, reverse: bool) {
    if n + 2 * g <= curve.len() {
        let (body, spare) = curve.split_at_mut(n + g);
        let parked = &mut spare[..g];
        parked.copy_from_slice(&body[n..]);
        if reverse {
            parked.reverse();
        }
        // Point by point from the top (the ranges overlap): a point's four words per step,
        // where the library's `memmove` took about twice as many instructions.
        for i in (at..n).rev() {
            body[i + g] = body[i];
        }
        body[at..at + g].copy_from_slice(parked);
    } else {
        if reverse {
            curve[n..n + g].reverse();
        }
        curve[at..n + g].rotate_right(g);
    }
}

/// Grows one end of the plane's curve `curve[s..e]` into `curve[n..]`; returns the number of
/// points written (outward order).
#[allow(clippy::too_many_arguments)]
fn grow_end<P: Pixel>(
    diff: &Frame<P, &[P]>,
    curve: &mut [CurvePoint],
    n: usize,
    (s, e): (usize, usize),
    leftward: bool,
    extract: &ExtractParams,
    level: Real,
    params: &GrowParams,
    located: &mut impl FnMut(&ExtractParams, usize, u16, Real) -> Option<Option<CurvePoint>>,
) -> usize {
    let (width, height) = (diff.width(), diff.height());
    let saturation = extract
        .saturation
        .map_or(diff.max_value() as Real, |v| v as Real);
    let w = params.half_window_px.max(1) as isize;
    // The last SLOPE_SPAN + 1 points of the track, nearest the end first.
    let mut history = [(0.0 as Real, 0.0 as Real); SLOPE_SPAN + 1];
    let mut known = 0usize;
    let inward = (e - s).min(SLOPE_SPAN + 1);
    for k in 0..inward {
        let p = if leftward {
            curve[s + k]
        } else {
            curve[e - 1 - k]
        };
        history[k] = (p.column as Real, p.row);
        known += 1;
    }
    let id = if leftward {
        curve[s].curve
    } else {
        curve[e - 1].curve
    };
    let mut x = history[0].0 as isize;
    let mut grown = 0usize;
    let mut misses = 0usize;
    loop {
        x += if leftward { -1 } else { 1 };
        if x < 0 || x as usize >= width || n + grown >= curve.len() {
            break;
        }
        let (x_end, r_end) = history[0];
        let (x_in, r_in) = history[known - 1];
        let slope = if known > 1 && x_end != x_in {
            (r_end - r_in) / (x_end - x_in)
        } else {
            0.0
        };
        let predicted = r_end + slope * (x as Real - x_end);
        let accepted = column_point(
            diff, x as usize, predicted, w, height, extract, saturation, level, located,
        );
        match accepted {
            Some(mut point) => {
                point.curve = id;
                curve[n + grown] = point;
                grown += 1;
                misses = 0;
                history.copy_within(0..SLOPE_SPAN, 1);
                history[0] = (x as Real, point.row);
                known = (known + 1).min(SLOPE_SPAN + 1);
            }
            None => {
                misses += 1;
                if misses > params.max_misses {
                    break;
                }
            }
        }
    }
    grown
}

/// The stripe's point in column `x` near row `predicted`: the brightest pixel within ± `w`
/// rows, if it is inside the window (not a slope into something beyond it) and at least
/// `level`, located by the chain's estimator, and only if the located row stays within the
/// window.
#[allow(clippy::too_many_arguments)]
fn column_point<P: Pixel>(
    diff: &Frame<P, &[P]>,
    x: usize,
    predicted: Real,
    w: isize,
    height: usize,
    extract: &ExtractParams,
    saturation: Real,
    level: Real,
    located: &mut impl FnMut(&ExtractParams, usize, u16, Real) -> Option<Option<CurvePoint>>,
) -> Option<CurvePoint> {
    if !predicted.is_finite() {
        return None;
    }
    let centre = Float::round(predicted) as isize;
    let (lo, hi) = (centre - w, centre + w);
    if lo < 0 || hi as usize >= height {
        return None;
    }
    let mut best = (0u32, lo);
    for y in lo..=hi {
        let v: u32 = diff.get(x, y as usize).map_or(0, Into::into);
        if v > best.0 {
            best = (v, y);
        }
    }
    if best.1 == lo || best.1 == hi || !(best.0 as Real >= level) {
        return None;
    }
    let point = match located(extract, x, best.1 as u16, saturation) {
        Some(point) => point,
        None => curve::locate_seeded(diff, x, best.1 as usize, extract, saturation).0,
    };
    point.filter(|p| (p.row - predicted).abs() <= w as Real)
}

#[cfg(test)]
#[path = "grow_tests.rs"]
mod tests;
