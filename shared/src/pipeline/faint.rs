//! Faint stripes: finding a laser stripe that no threshold separates from the noise, by its
//! coherence — a matched filter across the stripe, summed over a block of columns, and
//! continuity along it (`docs/image-processing.md`, "Faint stripes"; what the physics allows:
//! `docs/error-model.md`, "Detection at low SNR").
//!
//! It takes over when the thresholded chain finds no curve (the pair is "dark", no object
//! looks like a stripe, a plane's curve is missing or too short, or the clutter of a sunlit,
//! moving scene fills the object table). It reads the difference frame the streaming front
//! end left in the workspace, so it needs neither frame again:
//!
//! ```text
//! blocks of B columns ─► column sums ─► zero-sum Gaussian kernel across the stripe
//!   (a ridge, not an edge) ─► responses in units of their own noise
//! strongest response (seed) ─► track block by block left and right (± D rows)
//!   ─► best-scoring stretch (Kadane on q − β) ─► accepted when its score ≥ h
//! each column of the stretch ─► mean profile of 2m + 1 columns around the track
//!   ─► 3-point Gaussian centre, amplitude and width ─► curve point
//! ```
//!
//! The points carry the mean profile's amplitude and width, and the profile reports the
//! difference frame's per-pixel noise, so each point's σ ([`super::point_sigmas`]) is that of
//! a single column's estimate although it read 2m + 1: neighbouring points share columns, and
//! the fit's σ then counts each independent stretch of 2m + 1 columns once
//! (`docs/error-model.md`, "Detection at low SNR").

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::ops::Range;

use crate::calibration::{Calibration, MAX_PLANES};
use crate::curve::CurvePoint;
use crate::image::{Frame, Pixel};
use crate::peaks::{self, Estimator};
use crate::real::{Float, Real, Vec3};

use super::faint_sums::{self, IntKernel};
use super::planes;
use super::profile::{self, Profile, Subtracted};
use super::{PipelineConfig, PipelineError, Workspace};

/// Parameters of the faint-stripe search. Scores are in units of the block response's noise
/// σ (estimated from the frame itself); `docs/error-model.md`, "Detection at low SNR", derives
/// the defaults (set on synthetic frames and the tuning seeds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaintParams {
    /// Expected σ of the stripe's cross profile (pixels): the kernel's Gaussian core.
    pub profile_sigma_px: Real,
    /// Columns summed per block (`B`).
    pub block_columns: usize,
    /// Largest row change of the track from one block to the next (`D`).
    pub max_step_px: usize,
    /// Per-block drift `β` of the track's score (σ): the expected best of the `2D + 1`
    /// noise responses a block offers the track, so that noise does not accumulate.
    pub block_bias: Real,
    /// Score a stretch must reach to count as a stripe (`h`, σ).
    pub min_score: Real,
    /// Fewest blocks a stretch must span.
    pub min_blocks: usize,
    /// A block whose best response is below this (σ) is a miss; this many misses in a row
    /// end the track.
    pub miss_level: Real,
    /// Consecutive misses that end the track.
    pub max_misses: usize,
    /// Half-width `m` of the mean profile each point is read from (`2m + 1` columns).
    pub average_half_width: usize,
    /// Nearest and farthest depth (metres) at which the aimed object's lit points can lie:
    /// only the rows a plane lights there are searched.
    pub depth_range_m: (Real, Real),
}

impl Default for FaintParams {
    fn default() -> Self {
        FaintParams {
            profile_sigma_px: 1.0,
            block_columns: 8,
            max_step_px: 6,
            block_bias: 3.0,
            min_score: 25.0,
            min_blocks: 4,
            miss_level: 2.0,
            max_misses: 3,
            average_half_width: 2,
            depth_range_m: (0.4, 3.6),
        }
    }
}

/// Whether the faint search may take over after the thresholded chain failed with `e`.
pub(super) fn takes_over(e: &PipelineError, config: &PipelineConfig) -> bool {
    config.faint.is_some()
        && matches!(
            e,
            PipelineError::NoLaserLight { .. }
                | PipelineError::NoCurve
                | PipelineError::CurveTooShort { .. }
                | PipelineError::Segment(_)
        )
}

/// Most rows of the cross-profile kernel.
const MAX_KERNEL: usize = 15;
/// Rows of the zero ring on each side of the kernel's Gaussian core.
pub(super) const RING: usize = 3;
/// Rows added on each side of the rows a plane can light within the depth range (the
/// stripe's half-width at 2σ and the sampling's slack): a stripe from beyond the range stays
/// outside.
const BAND_MARGIN_PX: Real = 4.0;
/// Rows excluded on each side of a found track when searching the next plane's.
const EXCLUDE_PX: usize = 8;

/// The thresholded chain's result, or, when it failed in a way the faint search can answer
/// ([`takes_over`]), the faint search's profile; the thresholded chain's error stands when
/// the search finds nothing either.
pub(super) fn or_search<P: Pixel>(
    read: Result<Profile, PipelineError>,
    ws: &mut Workspace<'_, P>,
    pair: Subtracted,
    calibration: &Calibration,
    config: &PipelineConfig,
) -> Result<Profile, PipelineError> {
    match read {
        Err(e) if takes_over(&e, config) => match search(ws, pair, calibration, config) {
            Some(Ok(profile)) => Ok(profile),
            _ => Err(e),
        },
        r => r,
    }
}

/// The faint search: `None` when no stripe reaches the score (or a track reaches the frame's
/// edge), else the profile (or why its points could not be triangulated).
fn search<P: Pixel>(
    ws: &mut Workspace<'_, P>,
    pair: Subtracted,
    calibration: &Calibration,
    config: &PipelineConfig,
) -> Option<Result<Profile, PipelineError>> {
    let params = config.faint?;
    let (width, height) = (pair.width, pair.height);
    let n_planes = calibration.planes.len().min(MAX_PLANES);
    let pixels = width * height;
    let b = params.block_columns.max(1);
    let blocks = width.div_ceil(b);
    let diff = Frame::new(ws.diff.get(..pixels)?, width, height, width)
        .ok()?
        .with_bit_depth(pair.bit_depth)
        .ok()?;
    let (taps, len) = kernel(params.profile_sigma_px);
    let taps = &taps[..len];
    // The block sums gathered during the read-out, when the stream gathered them for this
    // block width (`faint_sums`): the same responses, from one sum per block and row.
    let table = match (pair.block_sums == b, IntKernel::new(taps)) {
        (true, Some(kernel)) => ws.block_sums.get(..blocks * height).map(|table| Table {
            table,
            height,
            kernel,
        }),
        _ => None,
    };
    let table = table.as_ref();
    // Rows whose responses the read-out already took into each block's statistics.
    let done = if table.is_some() { pair.faint_rows } else { 0 };
    // Scratch: column sums and responses of one block (height + kernel each).
    let (sums, rest) = ws
        .scratch_values
        .split_at_mut_checked(height + MAX_KERNEL)?;
    let responses = rest.get_mut(..height)?;
    // Track rows per block, one track per plane, in the seed buffer.
    let tracks = ws.seeds.get_mut(..blocks * n_planes)?;
    let band = |blk: usize| band_rows(calibration, &params, blk * b, ((blk + 1) * b).min(width));

    // The responses' noise σ from their mean absolute value over every searched cell
    // (Gaussian: σ = √(π/2)·mean|r|; the stripe's few cells barely move it).
    // The responses are integers (below 2²⁴, exact in `f32`): summed as integers, the device
    // and the host find the same σ. The same pass finds the first plane's seed, the strongest
    // response (nothing is excluded yet): one pass over the band instead of two.
    let (mut abs_sum, mut count) = (0u64, 0u64);
    let mut strongest = Seed::NONE;
    for blk in 0..blocks {
        if let Some(t) = table {
            // In integers, as the responses are: the strongest by an integer comparison
            // (the first of equals stays, as in `Seed::offer`); the rows the read-out did
            // not reach here (the band as the stream found it: the same function of the
            // calibration).
            let (rows, mut stats) = match ws.faint_columns.get(blk).filter(|_| done > 0) {
                Some(c) => (c.band(), c.stats()),
                None => (band(blk), faint_sums::ColumnStats::default()),
            };
            let rest = rows.start.max(done)..rows.end;
            if !rest.is_empty() {
                stats.merge(faint_sums::column_stats(t.column(blk), rest, &t.kernel));
            }
            abs_sum += stats.abs_sum;
            count += rows.len() as u64;
            strongest.offer(stats.best as Real, blk, stats.best_row);
            continue;
        }
        let rows = band(blk);
        block_responses(&diff, None, blk * b, b, &rows, taps, sums, responses);
        for v in rows {
            let r = responses[v];
            // |r| < 2³² for frames up to 16 bits: through `u32`, one conversion instruction
            // on the device (`as u64` from `f32` is a library call there).
            abs_sum += u64::from(r.abs() as u32);
            count += 1;
            strongest.offer(r, blk, v);
        }
    }
    if count == 0 || abs_sum == 0 {
        return None;
    }
    let sigma = Float::sqrt(crate::real::PI / 2.0) * (abs_sum as f64 / count as f64) as Real;

    let mut found = [Track::NONE; MAX_PLANES];
    let mut n_found = 0;
    for (k, slot) in found.iter_mut().enumerate().take(n_planes) {
        let (done, rest) = tracks.split_at_mut(k * blocks);
        let track = &mut rest[..blocks];
        let excluded = |blk: usize, v: usize| {
            (0..k).any(|j| {
                let row = done[j * blocks + blk];
                row != NO_ROW && (v as isize - row as isize).unsigned_abs() <= EXCLUDE_PX
            })
        };
        let seed = if k == 0 { Some(strongest) } else { None };
        let Some(t) = find_track(
            &diff, table, &params, taps, sigma, blocks, &band, &excluded, seed, sums, responses,
            track,
        ) else {
            break;
        };
        *slot = t;
        n_found += 1;
    }
    // A track that reaches the frame's left or right edge is not answered for: the
    // measurement would be refused as cut by the frame anyway, and in a scene that moved
    // between the two frames such a track is the motion's residue along the horizon, not a
    // stripe — the thresholded chain's refusal names that cause.
    if n_found == 0
        || found[..n_found]
            .iter()
            .any(|t| t.first == 0 || t.last + 1 >= blocks)
    {
        return None;
    }
    Some(extract_and_triangulate(
        ws,
        pair,
        calibration,
        config,
        &params,
        &found[..n_found],
        blocks,
    ))
}

/// Marks a block without a track row.
const NO_ROW: u16 = u16::MAX;

/// A track found in the seed buffer: its stretch of blocks, score and mean row.
#[derive(Debug, Clone, Copy)]
struct Track {
    first: usize,
    last: usize,
    mean_row: Real,
}

impl Track {
    const NONE: Track = Track {
        first: 0,
        last: 0,
        mean_row: 0.0,
    };
}

/// The strongest response found so far: `(response, block, row)`.
#[derive(Debug, Clone, Copy)]
struct Seed {
    response: Real,
    block: usize,
    row: usize,
}

impl Seed {
    /// No response yet (a seed must be positive).
    const NONE: Seed = Seed {
        response: 0.0,
        block: 0,
        row: 0,
    };

    /// Takes `(response, block, row)` if it is stronger (the first of equals stays).
    fn offer(&mut self, response: Real, block: usize, row: usize) {
        if response > self.response {
            *self = Seed {
                response,
                block,
                row,
            };
        }
    }
}

/// The strongest track outside `excluded`: seed at the strongest response (`seed`, when the
/// caller found it already with nothing excluded), followed block by block both ways, cut to
/// its best-scoring stretch. Writes its row per block to `track` (`NO_ROW` outside the
/// stretch).
#[allow(clippy::too_many_arguments)]
fn find_track<P: Pixel>(
    diff: &Frame<P, &[P]>,
    table: Option<&Table<'_>>,
    params: &FaintParams,
    taps: &[i64],
    sigma: Real,
    blocks: usize,
    band: &impl Fn(usize) -> Range<usize>,
    excluded: &impl Fn(usize, usize) -> bool,
    seed: Option<Seed>,
    sums: &mut [Real],
    responses: &mut [Real],
    track: &mut [u16],
) -> Option<Track> {
    let b = params.block_columns.max(1);
    // Seed: the strongest response anywhere outside `excluded`.
    let seed = seed.unwrap_or_else(|| {
        let mut seed = Seed::NONE;
        for blk in 0..blocks {
            let rows = band(blk);
            block_responses(diff, table, blk * b, b, &rows, taps, sums, responses);
            for v in rows {
                if !excluded(blk, v) {
                    seed.offer(responses[v], blk, v);
                }
            }
        }
        seed
    });
    if !(seed.response > 0.0) {
        return None;
    }
    track.fill(NO_ROW);
    // Gains q − β per block, kept in the track's sign: the tracks rows go to `track`, the
    // gains are recomputed for the stretch below.
    let (b0, v0) = (seed.block, seed.row);
    track[b0] = v0 as u16;
    for dir in [1isize, -1] {
        let (mut v, mut misses) = (v0, 0usize);
        let mut blk = b0 as isize + dir;
        while blk >= 0 && (blk as usize) < blocks && misses < params.max_misses {
            let bu = blk as usize;
            let rows = band(bu);
            let lo = v.saturating_sub(params.max_step_px).max(rows.start);
            let hi = (v + params.max_step_px + 1).min(rows.end);
            if lo >= hi {
                break;
            }
            block_responses(diff, table, bu * b, b, &(lo..hi), taps, sums, responses);
            let best = (lo..hi)
                .filter(|&u| !excluded(bu, u))
                .max_by(|&a, &c| responses[a].total_cmp(&responses[c]));
            let Some(best) = best else { break };
            if responses[best] / sigma >= params.miss_level {
                v = best;
                misses = 0;
            } else {
                misses += 1;
            }
            track[bu] = best as u16;
            blk += dir;
        }
    }
    // Best-scoring stretch (Kadane over q − β).
    let (mut run, mut run_start) = (0.0 as Real, 0usize);
    let (mut kept, mut first, mut last) = (Real::NEG_INFINITY, 0usize, 0usize);
    for (blk, &v) in track.iter().enumerate() {
        if v == NO_ROW {
            run = 0.0;
            continue;
        }
        let v = v as usize;
        block_responses(diff, table, blk * b, b, &(v..v + 1), taps, sums, responses);
        let gain = responses[v] / sigma - params.block_bias;
        if run <= 0.0 {
            (run, run_start) = (gain, blk);
        } else {
            run += gain;
        }
        if run > kept {
            (kept, first, last) = (run, run_start, blk);
        }
    }
    if !(kept >= params.min_score) || last + 1 - first < params.min_blocks {
        return None;
    }
    let mut row_sum = 0.0 as Real;
    for (blk, v) in track.iter_mut().enumerate() {
        if blk < first || blk > last {
            *v = NO_ROW;
        } else {
            row_sum += *v as Real;
        }
    }
    Some(Track {
        first,
        last,
        mean_row: row_sum / (last + 1 - first) as Real,
    })
}

/// Reads each column of the found tracks into curve points (planes matched by row order,
/// as the thresholded chain's objects are), then smooths and triangulates them.
fn extract_and_triangulate<P: Pixel>(
    ws: &mut Workspace<'_, P>,
    pair: Subtracted,
    calibration: &Calibration,
    config: &PipelineConfig,
    params: &FaintParams,
    found: &[Track],
    blocks: usize,
) -> Result<Profile, PipelineError> {
    let (width, height) = (pair.width, pair.height);
    let n_planes = calibration.planes.len().min(MAX_PLANES);
    let diff = Frame::new(&ws.diff[..width * height], width, height, width)?
        .with_bit_depth(pair.bit_depth)?;
    // Tracks sorted by mean row, matched to the planes sorted by their row at that depth.
    let mut order = [0usize; MAX_PLANES];
    for (i, o) in order.iter_mut().enumerate() {
        *o = i;
    }
    let order = &mut order[..found.len()];
    order.sort_unstable_by(|&a, &c| found[a].mean_row.total_cmp(&found[c].mean_row));
    let (planes_order, rows) = planes::planes_by_row(calibration, found[order[0]].mean_row);
    let mut plane_of = [usize::MAX; MAX_PLANES];
    if found.len() == n_planes {
        for (&t, &plane) in order.iter().zip(planes_order.iter()) {
            plane_of[t] = plane;
        }
    } else {
        for (t, track) in found.iter().enumerate() {
            let mut best = (Real::INFINITY, 0usize);
            for &k in planes_order.iter().take(n_planes) {
                let d = (rows[k] - track.mean_row).abs();
                if d < best.0 {
                    best = (d, k);
                }
            }
            plane_of[t] = best.1;
        }
    }
    let b = params.block_columns.max(1);
    let m = params.average_half_width;
    let mut plane_points = [(0usize, 0usize); MAX_PLANES];
    let mut n = 0usize;
    for (plane, range) in plane_points.iter_mut().enumerate().take(n_planes) {
        let start = n;
        for (t, track) in found.iter().enumerate() {
            if plane_of[t] != plane {
                continue;
            }
            let rows = &ws.seeds[t * blocks..(t + 1) * blocks];
            let x0 = track.first * b;
            let x1 = ((track.last + 1) * b).min(width);
            for x in x0..x1 {
                let Some(row) = track_row(rows, b, x) else {
                    continue;
                };
                let Some(point) = read_column(&diff, x, row, m, params, pair.noise) else {
                    continue;
                };
                let slot = ws
                    .curve
                    .get_mut(n)
                    .ok_or(PipelineError::WorkspaceTooSmall {
                        buffer: "curve",
                        needed: n + 1,
                        actual: n,
                    })?;
                *slot = CurvePoint {
                    curve: t as u8,
                    ..point
                };
                n += 1;
            }
        }
        *range = (start, n);
    }
    super::workspace::need("points", n, ws.points.len())?;
    let (saturated_points, touches_edge) = profile::smooth_and_triangulate(
        &mut ws.curve[..n],
        &plane_points,
        calibration,
        config,
        width,
        ws.points,
    )?;
    Ok(Profile {
        subtract: pair.stats,
        // No threshold separated the stripe: 0 says the faint search read it.
        threshold: 0,
        noise: pair.noise,
        objects: 0,
        candidates: found.len(),
        unused_candidates: 0,
        largest_unused: 0,
        smallest_used: 0,
        planes: calibration.planes.len(),
        plane_points,
        saturated_points,
        touches_edge,
        faint: true,
    })
}

/// The track's row at column `x`: linear between the centres of the blocks around it.
fn track_row(rows: &[u16], b: usize, x: usize) -> Option<Real> {
    let centre = |blk: usize| blk as Real * b as Real + (b as Real - 1.0) / 2.0;
    let blk = x / b;
    let here = *rows.get(blk).filter(|&&v| v != NO_ROW)? as Real;
    let xr = x as Real;
    let other = if xr < centre(blk) {
        blk.checked_sub(1)
    } else {
        Some(blk + 1)
    };
    match other.and_then(|o| rows.get(o).filter(|&&v| v != NO_ROW).map(|&v| (o, v))) {
        Some((o, v)) => {
            let (c0, c1) = (centre(blk), centre(o));
            let w = (xr - c0) / (c1 - c0);
            Some(here + w * (v as Real - here))
        }
        None => Some(here),
    }
}

/// Half-height of the window searched around the track's row, per column.
const READ_HALF_WINDOW: usize = 3;

/// One column's point: the mean profile of columns `x − m ..= x + m` around `row`, its peak
/// within ± [`READ_HALF_WINDOW`] rows, located by the 3-point Gaussian estimator (which at
/// this SNR beats the wide-window fit: it spends nothing on samples that are mostly noise).
/// `None` where the peak is not a stripe: not above 2σ of the mean's noise, at the window's
/// edge, or of implausible width.
fn read_column<P: Pixel>(
    diff: &Frame<P, &[P]>,
    x: usize,
    row: Real,
    m: usize,
    params: &FaintParams,
    noise: Real,
) -> Option<CurvePoint> {
    let height = diff.height();
    let width = diff.width();
    let centre = Float::round(row) as isize;
    let half = READ_HALF_WINDOW as isize + 1;
    let (lo, hi) = (centre - half, centre + half + 1);
    if lo < 0 || hi as usize > height {
        return None;
    }
    let (c0, c1) = (x.saturating_sub(m), (x + m + 1).min(width));
    let mut profile = [0.0 as Real; 2 * READ_HALF_WINDOW + 3];
    for (i, y) in (lo as usize..hi as usize).enumerate() {
        let r = diff.row(y);
        let s: u32 = r[c0..c1].iter().map(|&p| Into::<u32>::into(p)).sum();
        profile[i] = s as Real / (c1 - c0) as Real;
    }
    let len = (hi - lo) as usize;
    let profile = &profile[..len];
    let peak = (1..len - 1).max_by(|&a, &c| profile[a].total_cmp(&profile[c]))?;
    // Off-stripe level of the clamped difference: its mean, σ/√(2π); remove it so that the
    // estimator sees the stripe's own shape.
    let floor = noise / Float::sqrt(2.0 * crate::real::PI);
    let mut lifted = [0.0 as Real; 2 * READ_HALF_WINDOW + 3];
    for (l, &p) in lifted.iter_mut().zip(profile) {
        *l = (p - floor).max(0.0);
    }
    let lifted = &lifted[..len];
    let mean_noise = noise / Float::sqrt((c1 - c0) as Real);
    if !(lifted[peak] >= 2.0 * mean_noise) {
        return None;
    }
    // The log-parabola needs both neighbours above the floor; where noise put one below,
    // the raw mean profile (floor included) still gives the centre.
    let located = peaks::locate(lifted, peak, Estimator::Gaussian3)
        .or_else(|_| {
            peaks::locate(profile, peak, Estimator::Gaussian3).map(|p| peaks::Peak {
                amplitude: p.amplitude - floor,
                ..p
            })
        })
        .ok()?;
    let sigma = located.sigma?;
    let max_sigma = 4.0 * params.profile_sigma_px.max(1.0);
    if !(sigma > 0.3 && sigma < max_sigma) || (located.position - peak as Real).abs() > 1.0 {
        return None;
    }
    Some(CurvePoint {
        column: x as u16,
        row: lo as Real + located.position,
        amplitude: located.amplitude,
        curve: 0,
        saturated: false,
        width: sigma,
    })
}

/// The rows any plane can light in columns `x0..x1` at the search's depths, widened by the
/// kernel's reach and the sampling's slack (all rows when the geometry says nothing).
pub(super) fn band_rows(
    calibration: &Calibration,
    params: &FaintParams,
    x0: usize,
    x1: usize,
) -> Range<usize> {
    let cam = &calibration.camera;
    let height = cam.height as usize;
    let (near, far) = params.depth_range_m;
    let (mut lo, mut hi) = (Real::INFINITY, Real::NEG_INFINITY);
    for plane in calibration.planes.iter().take(MAX_PLANES) {
        let n = plane.normal;
        if n.y.abs() < 1e-3 {
            return 0..height;
        }
        for x in [x0 as Real, x1 as Real] {
            let xn = (x - cam.cx) / cam.fx;
            for z in [near, far] {
                // n·X = d with X = (xn·z, y, z).
                let y = (plane.offset - n.x * xn * z - n.z * z) / n.y;
                if let Ok(px) = cam.project(Vec3::new(xn * z, y, z)) {
                    lo = lo.min(px.y);
                    hi = hi.max(px.y);
                }
            }
        }
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return 0..height;
    }
    let margin = BAND_MARGIN_PX;
    let lo = (lo - margin).max(0.0) as usize;
    let hi = ((hi + margin).max(0.0) as usize).min(height);
    lo.min(hi)..hi
}

/// The integer cross-profile kernel: `g_k = round(16·exp(−k²/2σ²))` on the core
/// `|k| ≤ ⌈2σ⌉`, 0 on a ring of [`RING`] rows beyond, made zero-sum (`w = n·g − Σg`).
pub(super) fn kernel(sigma_px: Real) -> ([i64; MAX_KERNEL], usize) {
    let sigma = if sigma_px.is_finite() && sigma_px > 0.25 {
        sigma_px.min(2.0)
    } else {
        0.25
    };
    let core = Float::ceil(2.0 * sigma) as usize;
    let half = (core + RING).min(MAX_KERNEL / 2);
    let len = 2 * half + 1;
    let mut g = [0i64; MAX_KERNEL];
    for (i, gi) in g.iter_mut().enumerate().take(len) {
        let k = i as Real - half as Real;
        if k.abs() <= core as Real {
            *gi = Float::round(16.0 * Float::exp(-(k * k) / (2.0 * sigma * sigma))) as i64;
        }
    }
    let sum: i64 = g[..len].iter().sum();
    let mut w = [0i64; MAX_KERNEL];
    for (wi, gi) in w.iter_mut().zip(g.iter()).take(len) {
        *wi = len as i64 * gi - sum;
    }
    (w, len)
}

/// The block sums gathered during the read-out (`Workspace::block_sums`, block-major) and
/// the kernel in integers.
#[derive(Debug, Clone, Copy)]
struct Table<'a> {
    table: &'a [u16],
    height: usize,
    kernel: IntKernel,
}

impl Table<'_> {
    /// The sums of block `blk`, one per row (empty beyond the table).
    fn column(&self, blk: usize) -> &[u16] {
        self.table
            .get(blk * self.height..(blk + 1) * self.height)
            .unwrap_or(&[])
    }
}

/// The ridge responses of the block of `b` columns from `x0`, at `rows`, into
/// `responses[rows]`: the column sums correlated with `taps`, minus the imbalance of the two
/// rings (a stripe is a ridge with both rings near the floor; the edge of something that
/// moved between the two frames is a step, and gets no credit). With `table` the sums are
/// the ones gathered during the read-out and correlated in integers
/// (`faint_sums::column_responses`): the same values.
///
/// Rows beyond the frame's edges read the edge row. Every value is an integer (the column
/// sums of integer samples, the integer taps): below 2²⁴ for frames up to 8 bits, so exact in
/// `f32` whatever the order of the additions — the device and the host get the same
/// responses. `sums[j]` holds the column sum of row `rows.start + j − half` (clamped to the
/// frame), so that each response reads `taps.len()` consecutive sums without index
/// arithmetic (the search's cost is this loop: `docs/performance.md`, "The faint search's
/// cost"). `taps` is a kernel of [`kernel`]: symmetric, its outer taps the ring's.
#[allow(clippy::too_many_arguments)]
fn block_responses<P: Pixel>(
    diff: &Frame<P, &[P]>,
    table: Option<&Table<'_>>,
    x0: usize,
    b: usize,
    rows: &Range<usize>,
    taps: &[i64],
    sums: &mut [Real],
    responses: &mut [Real],
) {
    if let Some(t) = table {
        faint_sums::column_responses(t.column(x0 / b.max(1)), rows.clone(), &t.kernel, |v, r| {
            if let Some(out) = responses.get_mut(v) {
                *out = r as Real;
            }
        });
        return;
    }
    let (width, height) = (diff.width(), diff.height());
    let len = taps.len();
    let half = len / 2;
    let x1 = (x0 + b).min(width);
    if rows.is_empty() || x0 >= x1 || height == 0 || len == 0 {
        return;
    }
    let extended = rows.len() + len - 1;
    let Some(sums) = sums.get_mut(..extended) else {
        return;
    };
    for (j, s) in sums.iter_mut().enumerate() {
        let y = (rows.start + j).saturating_sub(half).min(height - 1);
        let total: u32 = diff.row(y)[x0..x1]
            .iter()
            .map(|&p| Into::<u32>::into(p))
            .sum();
        *s = total as Real;
    }
    let ring = taps.iter().take_while(|&&w| w == taps[0]).count().min(RING);
    // The taps of [`kernel`] are symmetric, so both rings' taps are `w₀`:
    // `Σ w_k·s_k = w₀·(upper + lower) + Σ_core w_k·s_k` — the ring sums the imbalance needs
    // anyway, and only the core's multiplications. Exact integers either way (above).
    let ring_tap = taps[0] as Real;
    let mut weights = [0.0 as Real; MAX_KERNEL];
    for (w, &t) in weights.iter_mut().zip(taps) {
        *w = t as Real;
    }
    let core = &weights[ring..len - ring];
    let ring_weight = taps[0].unsigned_abs() as Real;
    let Some(out) = responses.get_mut(rows.clone()) else {
        return;
    };
    for (out, window) in out.iter_mut().zip(sums.windows(len)) {
        let upper: Real = window[..ring].iter().sum();
        let lower: Real = window[len - ring..].iter().sum();
        let mut r = ring_tap * (upper + lower);
        for (&w, &s) in core.iter().zip(&window[ring..]) {
            r += w * s;
        }
        *out = r - ring_weight * (upper - lower).abs();
    }
}

#[cfg(test)]
#[path = "faint_tests.rs"]
pub(super) mod tests;
