//! Column-wise extraction of the laser curve(s) from a difference frame and its segmentation
//! labels, and smoothing of the extracted curve (thesis §5.7).
//!
//! For every column and every selected object (label), the extraction finds the brightest
//! pixel of that object in the column, takes the difference-frame profile around it — wider
//! than the labelled pixels, because the threshold that produced the labels cut the stripe's
//! tails, which the estimator needs — and locates the stripe centre with a
//! [`crate::peaks`] estimator. Several lit laser planes give several curves per column.
//! Derivations: `docs/subpixel.md` (§8 for the extraction and the smoothing).
// `!(x > 0.0)` is deliberate throughout: a NaN must fail the check, as `x <= 0.0` would not.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::fmt;

use crate::image::{Frame, FrameError, Pixel};
use crate::peaks::{self, Estimator, DEFAULT_ESTIMATOR, MAX_HALF_WINDOW};
use crate::real::Real;

/// Most curves (selected labels) extracted at once; bounds the per-column state on the stack.
pub const MAX_CURVES: usize = 8;

/// Largest half window of [`smooth`].
pub const MAX_SMOOTH_HALF_WINDOW: u8 = 8;

/// Profile buffer length: the largest window [`extract`] hands to an estimator.
const PROFILE_CAP: usize = 2 * MAX_HALF_WINDOW as usize + 1;

/// One point of a laser curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvePoint {
    /// Column (image `u`).
    pub column: u16,
    /// Subpixel row of the stripe centre (image `v`, pixel centres at integers).
    pub row: Real,
    /// Stripe amplitude from the estimator (difference-frame units), see
    /// [`peaks::Peak::amplitude`].
    pub amplitude: Real,
    /// Curve index: the position of the point's label in the `selected` slice.
    pub curve: u8,
    /// A sample the estimator read was at or above the saturation level.
    pub saturated: bool,
    /// Gaussian σ of the stripe's cross profile (pixels, [`peaks::Peak::sigma`]); 0 when the
    /// estimator does not model it. With `amplitude` and the image noise it gives the point's
    /// own σ ([`crate::noise::NoiseModel::stripe_centre_px`]).
    pub width: Real,
}

impl CurvePoint {
    /// An all-zero point, for initialising caller-owned buffers (usable in `const`/`static`).
    pub const ZERO: CurvePoint = CurvePoint {
        column: 0,
        row: 0.0,
        amplitude: 0.0,
        curve: 0,
        saturated: false,
        width: 0.0,
    };
}

/// Parameters of [`extract`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtractParams {
    /// Subpixel estimator.
    pub estimator: Estimator,
    /// Difference-frame samples taken on each side of the column maximum (`1..=`
    /// [`MAX_HALF_WINDOW`]); must cover the estimator's window.
    pub half_window: u8,
    /// Difference-frame level at or above which a sample counts as saturated. `None` uses the
    /// frame's full scale ([`Frame::max_value`]). A laser-on pixel that clipped at full scale
    /// shows in the difference frame as full scale minus its laser-off level, so a caller that
    /// knows the laser-off level (a few DN behind a band-pass filter) should pass
    /// `full scale − that level`.
    pub saturation: Option<u32>,
}

impl Default for ExtractParams {
    fn default() -> Self {
        ExtractParams {
            estimator: DEFAULT_ESTIMATOR,
            half_window: MAX_HALF_WINDOW,
            saturation: None,
        }
    }
}

/// Parameters of [`smooth`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmoothParams {
    /// Half window of the quadratic Savitzky–Golay filter (`0..=`[`MAX_SMOOTH_HALF_WINDOW`];
    /// 0 and 1 leave the curve unchanged).
    pub half_window: u8,
    /// Largest row step between adjacent columns inside one run; a larger step (an occlusion
    /// edge, a trunk's silhouette) starts a new run, which smoothing does not cross.
    pub max_row_jump: Real,
}

impl Default for SmoothParams {
    fn default() -> Self {
        SmoothParams {
            half_window: 3,
            max_row_jump: 2.0,
        }
    }
}

/// Why curves could not be extracted or smoothed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CurveError {
    /// The difference and label frames differ in size.
    Frame(FrameError),
    /// More labels selected than [`MAX_CURVES`].
    TooManyCurves {
        /// Labels selected.
        selected: usize,
    },
    /// The half window is outside its range.
    WindowOutOfRange {
        /// The half window asked for.
        half_window: u8,
    },
    /// `out` filled up before the frame was scanned; it holds `capacity` valid points.
    OutputFull {
        /// Length of `out`.
        capacity: usize,
    },
    /// No column gave a point of any selected curve.
    NoCurve,
}

impl fmt::Display for CurveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CurveError::Frame(e) => write!(f, "frames: {e}"),
            CurveError::TooManyCurves { selected } => {
                write!(f, "{selected} labels selected, at most {MAX_CURVES}")
            }
            CurveError::WindowOutOfRange { half_window } => {
                write!(f, "half window {half_window} out of range")
            }
            CurveError::OutputFull { capacity } => {
                write!(f, "curve buffer of {capacity} points is full")
            }
            CurveError::NoCurve => write!(f, "no laser curve found"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CurveError {}

impl From<FrameError> for CurveError {
    fn from(e: FrameError) -> Self {
        CurveError::Frame(e)
    }
}

/// Extracts the laser curves: for each column (left to right) and each label of `selected`
/// (in order; the index is [`CurvePoint::curve`]), one point at the subpixel row of the
/// stripe. Writes into `out` and returns the number of points.
///
/// A column where an object has no pixel gives no point for that curve; a column where the
/// estimator fails (stripe at the frame border, flat profile) is skipped, since one missing
/// column costs the solvers less than a wrong point. When a label has several runs in a
/// column, its brightest pixel decides.
///
/// Cost: one pass over the label column (a compare per pixel, plus a lookup in `selected`
/// for labelled pixels) and one estimator call per curve per column, so the work is
/// dominated by the scan of `height` labels per column. [`extract_window`] scans only a
/// bounding box of the selected objects and gives the same points.
pub fn extract<P: Pixel>(
    diff: &Frame<P, impl AsRef<[P]>>,
    labels: &Frame<u16, impl AsRef<[u16]>>,
    selected: &[u16],
    params: &ExtractParams,
    out: &mut [CurvePoint],
) -> Result<usize, CurveError> {
    extract_window(
        diff,
        labels,
        selected,
        0..diff.width(),
        0..diff.height(),
        params,
        out,
    )
}

/// [`extract`] restricted to the label pixels of `columns × rows` (clamped to the frame).
///
/// Only the search for each object's brightest labelled pixel is restricted: the profile
/// around it is still read from the whole difference frame (up to `half_window` rows above
/// and below, clamped to the frame as in [`extract`]). So when the window contains every pixel
/// of the selected objects — e.g. the union of their bounding boxes
/// ([`ObjectFeatures`](crate::image::segment::ObjectFeatures) `min_x..=max_x`,
/// `min_y..=max_y`) — the points are exactly those of [`extract`], at a cost proportional to
/// the window's area instead of the frame's (a few thousand pixels for a laser curve instead
/// of the 360 k label reads of a 752 × 480 frame). Columns outside the window give no point.
pub fn extract_window<P: Pixel>(
    diff: &Frame<P, impl AsRef<[P]>>,
    labels: &Frame<u16, impl AsRef<[u16]>>,
    selected: &[u16],
    columns: core::ops::Range<usize>,
    rows: core::ops::Range<usize>,
    params: &ExtractParams,
    out: &mut [CurvePoint],
) -> Result<usize, CurveError> {
    diff.check_same_size(labels)?;
    if selected.len() > MAX_CURVES {
        return Err(CurveError::TooManyCurves {
            selected: selected.len(),
        });
    }
    let hw = params.half_window;
    if hw == 0 || hw > MAX_HALF_WINDOW {
        return Err(CurveError::WindowOutOfRange { half_window: hw });
    }
    let hw = hw as usize;
    let saturation = params.saturation.unwrap_or(diff.max_value()) as Real;
    let (width, height) = (diff.width(), diff.height());
    let mut n = 0usize;
    let columns = columns.start.min(width)..columns.end.min(width);
    let rows = rows.start.min(height)..rows.end.min(height);
    for x in columns {
        // Brightest labelled pixel of each selected object in this column.
        let mut best: [Option<(usize, u32)>; MAX_CURVES] = [None; MAX_CURVES];
        for y in rows.clone() {
            let label = labels.get(x, y).unwrap_or(0);
            if label == 0 {
                continue;
            }
            let Some(k) = selected.iter().position(|&s| s == label) else {
                continue;
            };
            let v: u32 = diff.get(x, y).map_or(0, Into::into);
            if let Some(slot) = best.get_mut(k) {
                match slot {
                    Some((_, bv)) if *bv >= v => {}
                    _ => *slot = Some((y, v)),
                }
            }
        }
        for (k, slot) in best.iter().enumerate().take(selected.len()) {
            let Some((row, _)) = *slot else { continue };
            let (Some(mut point), _) = locate(diff, x, row, hw, params, saturation) else {
                continue;
            };
            point.curve = k as u8;
            push(out, &mut n, point)?;
        }
    }
    if n == 0 {
        Err(CurveError::NoCurve)
    } else {
        Ok(n)
    }
}

/// Column value of a [`extract_seeded`] seed: no pixel of that curve in that column.
pub const NO_SEED: u16 = u16::MAX;

/// [`extract`] from seeds instead of a label frame: `seeds[(x − columns.start) · curves + k]`
/// is the row of curve `k`'s brightest pixel in column `x` (the first such row from the top
/// when several are equally bright), or [`NO_SEED`]. With the seeds of the label frame's
/// objects the points are exactly those of [`extract_window`]; the pipeline finds them from
/// the objects' runs (`image::segment::Run`), so no label frame is needed.
pub fn extract_seeded<P: Pixel>(
    diff: &Frame<P, impl AsRef<[P]>>,
    seeds: &[u16],
    curves: usize,
    columns: core::ops::Range<usize>,
    params: &ExtractParams,
    out: &mut [CurvePoint],
) -> Result<usize, CurveError> {
    extract_seeded_with(diff, seeds, curves, columns, params, out, |_, _, _| None)
}

/// [`extract_seeded`] with points located earlier: `known(x, row, saturation)` returns the
/// outcome of [`locate_seeded`] at column `x` and seed `row` when the caller has it for this
/// saturation level (`Some(None)`: the estimator failed there), or `None` to have it located
/// now. The pipeline locates most points during the read-out (`pipeline::readout_fits`);
/// with correct earlier outcomes the points are exactly [`extract_seeded`]'s.
pub fn extract_seeded_with<P: Pixel>(
    diff: &Frame<P, impl AsRef<[P]>>,
    seeds: &[u16],
    curves: usize,
    columns: core::ops::Range<usize>,
    params: &ExtractParams,
    out: &mut [CurvePoint],
    mut known: impl FnMut(usize, u16, Real) -> Option<Option<CurvePoint>>,
) -> Result<usize, CurveError> {
    if curves > MAX_CURVES {
        return Err(CurveError::TooManyCurves { selected: curves });
    }
    let hw = params.half_window;
    if hw == 0 || hw > MAX_HALF_WINDOW {
        return Err(CurveError::WindowOutOfRange { half_window: hw });
    }
    let saturation = params.saturation.unwrap_or(diff.max_value()) as Real;
    let columns = columns.start.min(diff.width())..columns.end.min(diff.width());
    let mut n = 0usize;
    if curves > 0 {
        for (x, column) in columns.zip(seeds.chunks_exact(curves)) {
            for (k, &row) in column.iter().enumerate() {
                if row == NO_SEED || row as usize >= diff.height() {
                    continue;
                }
                let located = match known(x, row, saturation) {
                    Some(point) => point,
                    None => locate(diff, x, row as usize, hw as usize, params, saturation).0,
                };
                let Some(mut point) = located else {
                    continue;
                };
                point.curve = k as u8;
                push(out, &mut n, point)?;
            }
        }
    }
    if n == 0 {
        Err(CurveError::NoCurve)
    } else {
        Ok(n)
    }
}

/// The point [`extract_seeded`] locates in column `x` from the seed `row` (its `curve` set to
/// 0) with the samples at or above `saturation` treated as clipped, or `None` where the
/// estimator fails; and the brightest difference-frame sample it read. The outcome is the
/// same for every saturation level above that sample, so a caller that does not know the
/// level yet locates with [`Real::INFINITY`] and keeps the outcome while the sample stays
/// below the level (`docs/pipeline.md`, "Streaming"). The rows `row ± half_window` (clamped
/// to the frame) are the only ones read.
pub fn locate_seeded<P: Pixel>(
    diff: &Frame<P, impl AsRef<[P]>>,
    x: usize,
    row: usize,
    params: &ExtractParams,
    saturation: Real,
) -> (Option<CurvePoint>, u32) {
    let hw = params.half_window.clamp(1, MAX_HALF_WINDOW);
    locate(diff, x, row, hw as usize, params, saturation)
}

/// The point of curve `k` in column `x` whose brightest labelled pixel is at `row`: the
/// difference profile of `±hw` rows around it (clamped to the frame), climbed to its local
/// maximum and located by the estimator (`curve` 0); `None` where the estimator fails. Also
/// returns the brightest sample read.
fn locate<P: Pixel>(
    diff: &Frame<P, impl AsRef<[P]>>,
    x: usize,
    row: usize,
    hw: usize,
    params: &ExtractParams,
    saturation: Real,
) -> (Option<CurvePoint>, u32) {
    let mut profile = [0.0 as Real; PROFILE_CAP];
    let lo = row.saturating_sub(hw);
    let Some(last) = diff.height().checked_sub(1) else {
        return (None, 0);
    };
    let hi = (row + hw).min(last);
    let Some(buf) = (hi + 1)
        .checked_sub(lo)
        .and_then(|len| profile.get_mut(..len))
    else {
        return (None, 0);
    };
    let mut brightest = 0u32;
    for (j, s) in buf.iter_mut().enumerate() {
        let v: u32 = diff.get(x, lo + j).map_or(0, Into::into);
        brightest = brightest.max(v);
        *s = v as Real;
    }
    (
        locate_profile(buf, x, row - lo, hw, lo, params, saturation),
        brightest,
    )
}

/// [`locate`] on the column's profile `buf` (rows from `lo`), the seed at `buf[seed]`.
fn locate_profile(
    buf: &[Real],
    x: usize,
    seed: usize,
    hw: usize,
    lo: usize,
    params: &ExtractParams,
    saturation: Real,
) -> Option<CurvePoint> {
    // The labelled maximum may sit on a shoulder of a brighter unlabelled neighbour
    // (a speckle filter or a multi-level threshold can leave that); climb to the
    // local maximum of the profile, at most `hw` steps.
    let mut peak = seed;
    for _ in 0..hw {
        let here = buf.get(peak).copied().unwrap_or(0.0);
        let up = buf.get(peak + 1).copied().unwrap_or(Real::NEG_INFINITY);
        let down = if peak > 0 {
            buf.get(peak - 1).copied()
        } else {
            None
        };
        let down = down.unwrap_or(Real::NEG_INFINITY);
        if up > here && up >= down {
            peak += 1;
        } else if down > here {
            peak -= 1;
        } else {
            break;
        }
    }
    let peak = peaks::plateau_centre(buf, peak);
    let p = peaks::locate_with_saturation(buf, peak, params.estimator, saturation).ok()?;
    Some(CurvePoint {
        column: x.min(u16::MAX as usize) as u16,
        row: lo as Real + p.position,
        amplitude: p.amplitude,
        curve: 0,
        saturated: p.saturated,
        width: p.sigma.unwrap_or(0.0),
    })
}

/// Coefficient `j` of the quadratic Savitzky–Golay smoothing filter of half window `m`:
/// `c_j = 3(3m² + 3m − 1 − 5j²) / ((2m+1)(4m² + 4m − 3))` (`docs/subpixel.md` §8).
fn savitzky_golay(m: usize, j: isize) -> Real {
    let m = m as Real;
    let j = j as Real;
    3.0 * (3.0 * m * m + 3.0 * m - 1.0 - 5.0 * j * j)
        / ((2.0 * m + 1.0) * (4.0 * m * m + 4.0 * m - 3.0))
}

/// Index of the next point of curve `c` after `i`.
fn next_of(points: &[CurvePoint], c: u8, i: usize) -> Option<usize> {
    // A curve's points are usually consecutive: try the next one before searching.
    if points.get(i + 1)?.curve == c {
        return Some(i + 1);
    }
    points
        .get(i + 1..)?
        .iter()
        .position(|p| p.curve == c)
        .map(|k| i + 1 + k)
}

/// Smooths the rows of each curve along the columns, in place, with a quadratic
/// Savitzky–Golay filter (`docs/subpixel.md` §8), which removes speckle jitter while keeping
/// the curve's slope and curvature (a moving average would flatten the curvature near a
/// trunk's edge by `m(m+1)/6` times the second difference).
///
/// The points are those of [`extract`]: each curve's points in increasing column order
/// (curves may be interleaved). A curve is cut into runs at a missing column, a column that
/// does not increase, or a row step larger than `max_row_jump`; each run is filtered on its
/// own, with the window shrunk symmetrically near the ends of the run (so a straight or
/// parabolic run stays exact up to its ends). Points of curves `≥ MAX_CURVES` are left alone.
pub fn smooth(points: &mut [CurvePoint], params: &SmoothParams) -> Result<(), CurveError> {
    if params.half_window > MAX_SMOOTH_HALF_WINDOW {
        return Err(CurveError::WindowOutOfRange {
            half_window: params.half_window,
        });
    }
    let h = params.half_window as usize;
    if h < 2 {
        return Ok(());
    }
    // The curves present, so that each absent one does not cost a scan of every point.
    let present = points.iter().fold(0u32, |m, p| {
        m | 1u32.checked_shl(p.curve as u32).unwrap_or(0)
    });
    for c in (0..MAX_CURVES as u8).filter(|&c| present & (1 << c) != 0) {
        let mut start = points.iter().position(|p| p.curve == c);
        while let Some(s) = start {
            // The run: s, then successors while the columns are contiguous and rows close.
            let joined = |a: &CurvePoint, b: &CurvePoint| {
                b.column as u32 == a.column as u32 + 1
                    && (b.row - a.row).abs() <= params.max_row_jump
            };
            // First the successors that are the next points (one curve per plane: all of
            // them), pairwise without the search for the next point.
            let consecutive = points
                .get(s..)
                .unwrap_or(&[])
                .windows(2)
                .take_while(|w| w[1].curve == c && joined(&w[0], &w[1]))
                .count();
            let mut end = s + consecutive;
            let mut count = 1 + consecutive;
            let mut next = next_of(points, c, end);
            while let (Some(j), Some(a)) = (next, points.get(end)) {
                let Some(b) = points.get(j) else { break };
                if !joined(a, b) {
                    break;
                }
                end = j;
                count += 1;
                next = next_of(points, c, j);
            }
            // Only curve c's points between s and end: the run is a plain slice.
            match points
                .get_mut(s..s + count)
                .filter(|_| end + 1 == s + count)
            {
                Some(run) => smooth_contiguous(run, h),
                None => smooth_run(points, c, s, count, h),
            }
            start = next;
        }
    }
    Ok(())
}

/// Filters the `n` points of curve `c` starting at index `start` (one run).
fn smooth_run(points: &mut [CurvePoint], c: u8, start: usize, n: usize, h: usize) {
    // Ring of the run's original rows and indices: element k lives at slot k & MASK; the
    // filter at k reads k-h..=k+h, and loading k+h overwrites k+h-RING < k-h. A power of
    // two, so that a slot is a mask and not a division (this loop is the per-point cost of
    // the smoothing on the device, `docs/performance.md`).
    let mut idx = [0usize; RING];
    let mut val = [0.0 as Real; RING];
    let Some(first) = points.get(start) else {
        return;
    };
    idx[0] = start;
    val[0] = first.row;
    let mut loaded = 1usize;
    let mut cursor = start;
    // The coefficients depend on the half window alone, which changes only near the run's
    // ends: computed when it changes, not per tap.
    let mut coefficients = [0.0 as Real; RING];
    let mut coefficients_half = 0usize;
    for k in 0..n {
        let half = h.min(k).min(n - 1 - k);
        while loaded <= k + half {
            let Some(j) = next_of(points, c, cursor) else {
                return;
            };
            cursor = j;
            let slot = loaded & MASK;
            idx[slot] = j;
            val[slot] = points.get(j).map_or(0.0, |p| p.row);
            loaded += 1;
        }
        if half < 2 {
            // The quadratic through 3 points is the points themselves: nothing to do.
            continue;
        }
        if half != coefficients_half {
            for (j, w) in (-(half as isize)..=half as isize).zip(coefficients.iter_mut()) {
                *w = savitzky_golay(half, j);
            }
            coefficients_half = half;
        }
        // Taps k - half ..= k + half, in that order. The common full windows are unrolled
        // (this loop's iterator was most of the smoothing's cost on the device); the sum is
        // formed in the same order either way.
        let first = k - half;
        let acc = match 2 * half + 1 {
            5 => taps(&coefficients, &val, first, 5),
            7 => taps(&coefficients, &val, first, 7),
            9 => taps(&coefficients, &val, first, 9),
            n => taps(&coefficients, &val, first, n),
        };
        if let Some(p) = points.get_mut(idx[k & MASK]) {
            p.row = acc;
        }
    }
}

/// [`smooth_run`] of a run whose points are consecutive (`run`, the common case: one curve
/// per plane): no index ring and no search for the next point, and the full windows of the
/// run's middle in one loop with the window's taps unrolled. Same taps in the same order,
/// so the same rows (this was most of the smoothing's cost on the device,
/// `docs/performance.md`, issue 17).
fn smooth_contiguous(run: &mut [CurvePoint], h: usize) {
    let n = run.len();
    // Ring of the run's original rows: row k lives at slot k & MASK (see `smooth_run`).
    let mut val = [0.0 as Real; RING];
    let mut coefficients = [0.0 as Real; RING];
    let mut coefficients_half = 0usize;
    let mut loaded = 0usize;
    let mut k = 0usize;
    while k < n {
        let half = h.min(k).min(n - 1 - k);
        while loaded <= k + half {
            val[loaded & MASK] = run.get(loaded).map_or(0.0, |p| p.row);
            loaded += 1;
        }
        if half < 2 {
            k += 1;
            continue;
        }
        if half != coefficients_half {
            for (j, w) in (-(half as isize)..=half as isize).zip(coefficients.iter_mut()) {
                *w = savitzky_golay(half, j);
            }
            coefficients_half = half;
        }
        if half == h {
            // The full windows: k ..= n − 1 − h, each loading row k + h.
            let middle = k..n - h;
            k = middle.end;
            match 2 * h + 1 {
                5 => full_windows(run, &mut val, &coefficients, middle, h, 5),
                7 => full_windows(run, &mut val, &coefficients, middle, h, 7),
                9 => full_windows(run, &mut val, &coefficients, middle, h, 9),
                taps => full_windows(run, &mut val, &coefficients, middle, h, taps),
            }
            loaded = k + h;
            continue;
        }
        let acc = taps(&coefficients, &val, k - half, 2 * half + 1);
        if let Some(p) = run.get_mut(k) {
            p.row = acc;
        }
        k += 1;
    }
}

/// The full windows `ks` of [`smooth_contiguous`], each loading its last row `k + h` (still
/// the original: only rows before `k` are written). Inlined, so that a literal `n` unrolls
/// the taps.
#[inline(always)]
fn full_windows(
    run: &mut [CurvePoint],
    val: &mut [Real; RING],
    c: &[Real; RING],
    ks: core::ops::Range<usize>,
    h: usize,
    n: usize,
) {
    for k in ks {
        val[(k + h) & MASK] = run.get(k + h).map_or(0.0, |p| p.row);
        let acc = taps(c, val, k - h, n);
        if let Some(p) = run.get_mut(k) {
            p.row = acc;
        }
    }
}

/// Slots of [`smooth_run`]'s ring of rows (a power of two: a slot is a mask).
const RING: usize = (2 * MAX_SMOOTH_HALF_WINDOW as usize + 1).next_power_of_two();
/// `RING − 1`.
const MASK: usize = RING - 1;

/// `Σ_{t<n} c_t·v[(first + t) mod RING]`, summed in order of `t`. Inlined, so that a
/// literal `n` unrolls it.
#[inline(always)]
fn taps(c: &[Real; RING], v: &[Real; RING], first: usize, n: usize) -> Real {
    let mut acc = 0.0 as Real;
    for t in 0..n.min(RING) {
        acc += c[t] * v[(first + t) & MASK];
    }
    acc
}

/// Stores `point` at `out[*n]` and counts it, or says the caller's buffer is full.
fn push(out: &mut [CurvePoint], n: &mut usize, point: CurvePoint) -> Result<(), CurveError> {
    let capacity = out.len();
    let slot = out.get_mut(*n).ok_or(CurveError::OutputFull { capacity })?;
    *slot = point;
    *n += 1;
    Ok(())
}

#[cfg(test)]
mod tests;
