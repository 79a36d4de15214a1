//! Curve points located during the read-out (`docs/pipeline.md`, "Streaming"): the subpixel
//! extraction of a column's stripe needs only the difference frame's rows around the
//! stripe, so it is done as soon as those rows are in, not after the last pixel.
//!
//! Which pixel seeds a curve's point in a column (its brightest pixel of the curve's object)
//! is only known after the frame — the threshold, the objects and the planes are. But every
//! object pixel is a candidate pixel (above the provisional threshold, which every threshold
//! is raised to), so each column's *candidate segments* (vertical runs of candidate pixels)
//! are tracked as the rows arrive, and the point is located at each segment's brightest
//! pixel once the rows `± half_window` around it are in. After the frame the extraction
//! looks each seed up here by `(column, row)` and locates only the seeds it does not find
//! (a segment split by the final threshold into two objects, a fit left over when the
//! block's budget ran out, a stripe at the frame's bottom). The outcome of the estimator is
//! a function of the column's samples alone, except for the saturation level, which depends
//! on the laser-off mean known after the frame: a point is located with no saturation level
//! and kept only while its brightest sample is below the final level
//! ([`crate::curve::locate_seeded`]). So the points are exactly those of the extraction after
//! the frame, and a lookup that misses costs only the time it would have cost anyway.
//!
//! The work is bounded per block of [`super::BLOCK_ROWS`] rows ([`BLOCK_WORK`]) so that
//! the read-out stays within the pixel clock's budget, and segments whose brightest pixel is
//! below every threshold the frame can still get (the floors with the largest difference seen
//! so far) are not located at all.

use crate::curve::{self, CurvePoint, ExtractParams};
use crate::image::threshold::Floors;
use crate::image::{Frame, Pixel};
use crate::real::Real;

/// Most points located during one frame's read-out (the table [`ReadoutBuffers`] holds): two
/// planes' curves across the 752 columns, and room for specks.
pub const MAX_READOUT_FITS: usize = 2048;

/// Work one block of [`super::BLOCK_ROWS`] rows may spend on the read-out extraction, in
/// instructions of the emulated Cortex-M7 (`docs/performance.md`, "Read-out budget"). The
/// tracking of its candidate pixels ([`TRACK_COST`] each) is charged first — it cannot be
/// skipped, the segments must be followed as the rows pass, so it is not capped — and points
/// ([`FIT_COST`] each) are located only while the charge stays within it. Measured there, a
/// block's subtraction, histogram and candidate runs take ≈ 83,000 instructions (6.9 per
/// pixel); with this the worst block of the bench's stems is 15.4 per pixel, inside the 18
/// cycles per pixel the 26.66 MHz pixel clock leaves at 480 MHz. A block the stripe crosses
/// spends most of it on tracking and locates few points; the blocks below the stripe, with
/// nothing to track, locate up to 66 each. The budget only decides *when* a point is
/// located: the points are the same ones either way.
pub const BLOCK_WORK: u32 = 100_000;

/// Instructions to track one candidate pixel (its column's segment: brightest pixel, end),
/// measured on the emulated core with the candidate runs' scan (≈ 42–45).
pub const TRACK_COST: u32 = 45;

/// Instructions to locate one point during the read-out (the column's samples, the Gaussian
/// fit and the block's scan for the segments whose rows are in), measured on the emulated
/// core (≈ 1,450–1,560).
pub const FIT_COST: u32 = 1_500;

/// End of a column's fit list.
const NO_FIT: u16 = u16::MAX;

/// One column's state during the read-out: its open candidate segment (if any) and the
/// points located in it so far (a list through [`ReadoutFit::next`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ColumnTrack {
    /// One past the last row of the segment not yet located (0: none).
    end: u16,
    /// Row of the segment's brightest pixel (the first from the top among equals).
    best_row: u16,
    /// Its difference value.
    best_value: u16,
    /// First point of the column in the fit table, or `NO_FIT`.
    first_fit: u16,
    /// Row of the brightest pixel of a closed segment waiting to be located (a new segment
    /// in the column closed it while the block had no budget left, or before its window was
    /// in; `NO_ROW`: none). One is enough for two planes' stripes; a third segment in the
    /// column before it is located is left to the extraction after the frame.
    pending_row: u16,
    /// Its difference value.
    pending_value: u16,
}

/// No pending segment ([`ColumnTrack::pending_row`]).
const NO_ROW: u16 = u16::MAX;

impl ColumnTrack {
    /// No segment and no point (usable in `const`/`static`).
    pub const EMPTY: ColumnTrack = ColumnTrack {
        end: 0,
        best_row: 0,
        best_value: 0,
        first_fit: NO_FIT,
        pending_row: NO_ROW,
        pending_value: 0,
    };
}

/// A point located during the read-out at a column's seed row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReadoutFit {
    /// Subpixel row, amplitude and stripe width of the point ([`CurvePoint`]).
    row: Real,
    pub(super) amplitude: Real,
    width: Real,
    /// The seed row it was located from.
    seed_row: u16,
    /// Brightest difference sample the estimator read (the point holds below this
    /// saturation level and above).
    brightest: u16,
    /// Next point of the same column, or `NO_FIT`.
    next: u16,
    /// The estimator found a point (else: it failed there, which is kept too).
    pub(super) found: bool,
}

impl ReadoutFit {
    /// An all-zero entry (usable in `const`/`static`).
    pub const ZERO: ReadoutFit = ReadoutFit {
        row: 0.0,
        amplitude: 0.0,
        width: 0.0,
        seed_row: 0,
        brightest: 0,
        next: NO_FIT,
        found: false,
    };
}

/// The read-out extraction's tables for frames up to `COLUMNS` wide: a [`ColumnTrack`] per
/// column and `FITS` located points. Const-constructible, so a board places it in a static
/// (the H743: SRAM4, `docs/hardware.md`).
#[derive(Debug)]
pub struct ReadoutBuffers<const COLUMNS: usize = 752, const FITS: usize = MAX_READOUT_FITS> {
    pub(super) columns: [ColumnTrack; COLUMNS],
    pub(super) fits: [ReadoutFit; FITS],
}

impl<const COLUMNS: usize, const FITS: usize> ReadoutBuffers<COLUMNS, FITS> {
    /// Empty tables.
    pub const fn new() -> Self {
        ReadoutBuffers {
            columns: [ColumnTrack::EMPTY; COLUMNS],
            fits: [ReadoutFit::ZERO; FITS],
        }
    }
}

impl<const COLUMNS: usize, const FITS: usize> Default for ReadoutBuffers<COLUMNS, FITS> {
    fn default() -> Self {
        Self::new()
    }
}

/// The read-out extraction of one frame: its parameters and how much of the tables it used.
/// Lives in [`super::ProfileStream`]; the tables are the workspace's.
#[derive(Debug, Clone, Copy)]
pub(super) struct ReadoutFits {
    /// The tables are large enough for the frame's width (else nothing is located early).
    enabled: bool,
    params: ExtractParams,
    floors: Floors,
    /// Points in the table.
    used: usize,
    /// Work spent in this block so far ([`BLOCK_WORK`]'s units).
    spent: u32,
    /// Largest candidate difference so far: a lower bound of the frame's largest difference.
    brightest: u32,
}

impl ReadoutFits {
    /// Starts a frame of `width × height`: clears the tracks of its columns. Rows are kept as
    /// `u16` with one past the last, so a frame of 65,535 rows or more is not tracked.
    pub(super) fn begin(
        columns: &mut [ColumnTrack],
        fits: &[ReadoutFit],
        (width, height): (usize, usize),
        params: ExtractParams,
        floors: Floors,
    ) -> Self {
        let enabled = columns.len() >= width && !fits.is_empty() && height < u16::MAX as usize;
        if enabled {
            columns[..width].fill(ColumnTrack::EMPTY);
        }
        ReadoutFits {
            enabled,
            params: ExtractParams {
                saturation: None,
                ..params
            },
            floors,
            used: 0,
            spent: 0,
            brightest: 0,
        }
    }

    /// Lowest threshold the frame can still get: pixels at or below it are in no object.
    fn floor(&self) -> u32 {
        self.floors.apply(0, self.brightest, 0.0)
    }

    /// The candidate runs `runs` (`start..end` columns) of row `y`, which is in `diff`
    /// (`width` columns, `height` rows, rows `..=y` subtracted): extends or opens each
    /// column's segment; a column's segment that a new one replaces is located first when
    /// its rows are in (else it is left to the extraction after the frame).
    pub(super) fn row<P: Pixel>(
        &mut self,
        tables: (&mut [ColumnTrack], &mut [ReadoutFit]),
        diff: &Frame<P, &[P]>,
        y: usize,
        runs: impl Iterator<Item = (usize, usize)>,
    ) {
        if !self.enabled {
            return;
        }
        let (columns, fits) = tables;
        let row = diff.row(y);
        let y16 = y as u16;
        for (start, end) in runs {
            let (Some(values), Some(tracks)) = (row.get(start..end), columns.get_mut(start..end))
            else {
                continue;
            };
            self.spent = self
                .spent
                .saturating_add(TRACK_COST.saturating_mul(values.len() as u32));
            for (x, (track, &v)) in (start..).zip(tracks.iter_mut().zip(values)) {
                let v: u32 = v.into();
                self.brightest = self.brightest.max(v);
                let v = v.min(u16::MAX as u32) as u16;
                if track.end == y16 && y16 != 0 {
                    // The segment goes on; `>` keeps the first brightest from the top.
                    if v > track.best_value {
                        track.best_row = y16;
                        track.best_value = v;
                    }
                    track.end = y16 + 1;
                    continue;
                }
                if track.end != 0 {
                    // A new segment in this column: the previous one now, or when a later
                    // block has its window and the budget for it.
                    self.locate_or_defer(track, fits, diff, x, y);
                }
                track.end = y16 + 1;
                track.best_row = y16;
                track.best_value = v;
            }
        }
    }

    /// After row `y`, at the end of a block: locates the segments closed before row `y`
    /// whose rows `± half_window` are in, within the block's budget, and renews the budget
    /// for the next block. Returns the work the block left of [`BLOCK_WORK`] (the faint
    /// search's responses may use it: `pipeline::faint_sums`).
    pub(super) fn block_done<P: Pixel>(
        &mut self,
        tables: (&mut [ColumnTrack], &mut [ReadoutFit]),
        diff: &Frame<P, &[P]>,
        y: usize,
    ) -> u32 {
        if !self.enabled {
            return BLOCK_WORK;
        }
        let (columns, fits) = tables;
        let hw = self.params.half_window as usize;
        for (x, track) in columns.iter_mut().take(diff.width()).enumerate() {
            if !self.affordable() {
                break;
            }
            if track.pending_row != NO_ROW && track.pending_row as usize + hw <= y {
                let pending = (track.pending_row, track.pending_value);
                if self.locate_at(track, fits, diff, (x, y), pending) {
                    track.pending_row = NO_ROW;
                }
            }
            if !self.affordable() {
                break;
            }
            let end = track.end as usize;
            if end != 0 && end <= y && track.best_row as usize + hw <= y {
                self.locate(track, fits, diff, x, y);
            }
        }
        let left = BLOCK_WORK.saturating_sub(self.spent);
        self.spent = 0;
        left
    }

    /// Whether this block's work allows one more point.
    fn affordable(&self) -> bool {
        self.spent.saturating_add(FIT_COST) <= BLOCK_WORK
    }

    /// Closes `track`'s segment in column `x` (a new one opens at row `y`): locates it now
    /// if it can be ([`Self::locate`]), else keeps it as the column's pending segment for a
    /// later block when the column has none yet and it can still be in an object.
    fn locate_or_defer<P: Pixel>(
        &mut self,
        track: &mut ColumnTrack,
        fits: &mut [ReadoutFit],
        diff: &Frame<P, &[P]>,
        x: usize,
        y: usize,
    ) {
        let (row, value) = (track.best_row, track.best_value);
        if !self.locate(track, fits, diff, x, y)
            && track.pending_row == NO_ROW
            && value as u32 > self.floor()
        {
            track.pending_row = row;
            track.pending_value = value;
        }
    }

    /// Locates `track`'s segment in column `x` if rows `..=y` hold its window, it can still
    /// be in an object and the budget and table allow; closes the segment either way.
    /// Returns whether the segment was dealt with: located, or not worth locating.
    fn locate<P: Pixel>(
        &mut self,
        track: &mut ColumnTrack,
        fits: &mut [ReadoutFit],
        diff: &Frame<P, &[P]>,
        x: usize,
        y: usize,
    ) -> bool {
        track.end = 0;
        self.locate_at(
            track,
            fits,
            diff,
            (x, y),
            (track.best_row, track.best_value),
        )
    }

    /// Locates the segment of column `x` whose brightest pixel is `(row, value)` into the
    /// column's fit list if rows `..=y` hold its window, it can still be in an object and the
    /// budget and table allow. Returns whether it was dealt with: located, or not worth
    /// locating (it cannot be in an object).
    fn locate_at<P: Pixel>(
        &mut self,
        track: &mut ColumnTrack,
        fits: &mut [ReadoutFit],
        diff: &Frame<P, &[P]>,
        (x, y): (usize, usize),
        (row, value): (u16, u16),
    ) -> bool {
        let seed = row as usize;
        let last_row = diff.height().saturating_sub(1);
        let complete = (seed + self.params.half_window as usize).min(last_row) <= y;
        if value as u32 <= self.floor() {
            return true;
        }
        if !complete || !self.affordable() || self.used >= fits.len().min(NO_FIT as usize) {
            return false;
        }
        self.spent += FIT_COST;
        let (point, brightest) = curve::locate_seeded(diff, x, seed, &self.params, Real::INFINITY);
        let Some(slot) = fits.get_mut(self.used) else {
            return false;
        };
        *slot = ReadoutFit {
            row: point.map_or(0.0, |p| p.row),
            amplitude: point.map_or(0.0, |p| p.amplitude),
            width: point.map_or(0.0, |p| p.width),
            seed_row: row,
            brightest: brightest.min(u16::MAX as u32) as u16,
            next: track.first_fit,
            found: point.is_some(),
        };
        track.first_fit = self.used as u16;
        self.used += 1;
        true
    }

    /// The point located during the read-out at column `x` from seed `row`, if there is one
    /// that holds at `saturation` and was located with `params`' estimator and window:
    /// `Some(None)` when the estimator failed there. For
    /// [`crate::curve::extract_seeded_with`] and the growth (`super::grow`).
    #[inline]
    pub(super) fn lookup(
        &self,
        tables: (&[ColumnTrack], &[ReadoutFit]),
        params: &ExtractParams,
        x: usize,
        row: u16,
        saturation: Real,
    ) -> Option<Option<CurvePoint>> {
        if !self.enabled
            || params.estimator != self.params.estimator
            || params.half_window != self.params.half_window
        {
            return None;
        }
        let (columns, fits) = tables;
        let mut i = columns.get(x)?.first_fit;
        while let Some(fit) = fits.get(i as usize).filter(|_| (i as usize) < self.used) {
            if fit.seed_row == row {
                // A NaN level keeps nothing: only a sample surely below it is unclipped.
                if (fit.brightest as Real) >= saturation || saturation.is_nan() {
                    return None;
                }
                return Some(fit.found.then_some(CurvePoint {
                    column: x.min(u16::MAX as usize) as u16,
                    row: fit.row,
                    amplitude: fit.amplitude,
                    curve: 0,
                    saturated: false,
                    width: fit.width,
                }));
            }
            i = fit.next;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::super::tests::{buffers, calibration, frames, render};
    use super::super::{extract_profile, PipelineConfig};
    use super::*;
    use std::vec::Vec;

    const W: usize = 752;

    /// The profile, curve points and 3-D points of a pair, with the read-out extraction
    /// (`early`) or with every point located after the frame; and how many points the
    /// read-out located.
    fn run(
        off: &[u8],
        on: &[u8],
        planes: usize,
        early: bool,
    ) -> (super::super::Profile, Vec<CurvePoint>, usize) {
        let cal = calibration(planes);
        let (off_f, on_f) = frames(off, on);
        let mut b = buffers(planes);
        let mut ws = b.workspace();
        if !early {
            ws.column_tracks = &mut [];
        }
        let profile = extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws)
            .expect("a profile");
        let n: usize = profile.plane_points[..planes]
            .iter()
            .map(|(s, e)| e - s)
            .sum();
        let located = ws.readout_fits.iter().filter(|f| f.found).count();
        (
            profile,
            ws.curve[..n].to_vec(),
            if early { located } else { 0 },
        )
    }

    /// Points located during the read-out are exactly the points located after the frame,
    /// for two planes (two segments per column), specks above the provisional threshold, and
    /// a stripe bright enough to saturate (whose points the saturation level, known only
    /// after the frame, changes: they are located again).
    #[test]
    fn points_located_during_the_readout_are_those_after_the_frame() {
        for (amplitude, planes) in [(130.0, 2), (60.0, 1), (900.0, 1)] {
            let cal = calibration(planes);
            let plane_list: Vec<usize> = (0..planes).collect();
            let (off, mut on) = render(&cal, &plane_list, 0.9, 120..640, amplitude, 9);
            for k in 0..300 {
                let i = (k * 7919 + 13) % on.len();
                on[i] = on[i].saturating_add(9 + (k % 5) as u8);
            }
            let (early, early_points, located) = run(&off, &on, planes, true);
            let (late, late_points, _) = run(&off, &on, planes, false);
            assert_eq!(early, late, "amplitude {amplitude}");
            assert_eq!(early_points, late_points, "amplitude {amplitude}");
            // A wall's stripe is level: every column's window completes in the same block,
            // and the per-block budget spreads the points over the blocks below it (stripes
            // at rows ≈ 284 and 340: ≥ 8 blocks with nothing else to do), which hold all
            // of one plane's 520 columns.
            let per_empty_block = (BLOCK_WORK / FIT_COST) as usize;
            assert!(
                located >= (8 * per_empty_block).min(500 * planes),
                "amplitude {amplitude}: {located} located"
            );
            if amplitude > 255.0 {
                assert!(early.saturated_points > 0, "the stripe saturates");
            }
        }
    }

    /// A segment whose brightest pixel is below every threshold the frame can still get is
    /// not located, and the budget bounds the points of one block.
    #[test]
    fn faint_segments_are_skipped_and_blocks_are_bounded() {
        let cal = calibration(1);
        let (off, mut on) = render(&cal, &[0], 0.9, 120..640, 200.0, 9);
        // Faint specks (10 DN above the ambient) in the first rows, before the stripe.
        for x in (0..W).step_by(3) {
            on[2 * W + x] = on[2 * W + x].saturating_add(10);
        }
        let (_, _, located) = run(&off, &on, 1, true);
        assert!(located <= MAX_READOUT_FITS);
        let mut columns = [ColumnTrack::EMPTY; W];
        let mut fits = [ReadoutFit::ZERO; 64];
        let mut early = ReadoutFits::begin(
            &mut columns,
            &fits,
            (W, 480),
            ExtractParams::default(),
            Floors::default(),
        );
        // The brightest pixel so far is 200: the floor is 8 % of it = 16 > the specks' 10.
        early.brightest = 200;
        let diff: Vec<u8> = on
            .iter()
            .zip(&off)
            .map(|(a, b)| a.saturating_sub(*b))
            .collect();
        let frame = Frame::new(&diff[..], W, 480, W).unwrap();
        let specks: Vec<(usize, usize)> = (0..W).step_by(3).map(|x| (x, x + 1)).collect();
        early.row((&mut columns, &mut fits), &frame, 2, specks.iter().copied());
        early.block_done((&mut columns, &mut fits), &frame, 40);
        assert_eq!(early.used, 0, "specks below the floor are not located");
        assert!(columns.iter().all(|c| c.end == 0));
        // Bright segments in every column: one block locates what its work leaves after
        // tracking them.
        let mut bright = diff.clone();
        for x in 0..W {
            bright[3 * W + x] = 120;
        }
        let frame = Frame::new(&bright[..], W, 480, W).unwrap();
        early.row((&mut columns, &mut fits), &frame, 3, [(0, W)].into_iter());
        early.block_done((&mut columns, &mut fits), &frame, 40);
        let affordable = ((BLOCK_WORK - TRACK_COST * W as u32) / FIT_COST) as usize;
        assert!(affordable > 0 && affordable < W);
        assert_eq!(early.used, affordable.min(fits.len()));
    }

    /// A column's segment that a second one closes while the block has no budget left (two
    /// planes' stripes in the same columns) waits for a later block and is located there; a
    /// segment closed while another of its column is still waiting is left to the extraction
    /// after the frame.
    #[test]
    fn a_segment_closed_without_budget_is_located_by_a_later_block() {
        const COLS: usize = 8;
        let mut image = std::vec![0u8; COLS * 480];
        // Stripes (3 rows, peak 120) at rows 20 and 40, and at row 60 in column 0 only.
        for x in 0..COLS {
            for (row, v) in [(19, 60), (20, 120), (21, 60), (39, 60), (40, 120), (41, 60)] {
                image[row * COLS + x] = v;
            }
        }
        for (row, v) in [(59, 60), (60, 120), (61, 60)] {
            image[row * COLS] = v;
        }
        let frame = Frame::new(&image[..], COLS, 480, COLS).unwrap();
        let mut columns = [ColumnTrack::EMPTY; COLS];
        let mut fits = [ReadoutFit::ZERO; 64];
        let params = ExtractParams::default();
        let mut early =
            ReadoutFits::begin(&mut columns, &fits, (COLS, 480), params, Floors::default());
        for y in 0..96 {
            if y == 39 || y == 59 {
                // The blocks the second and third stripes open in have spent their budget.
                early.spent = BLOCK_WORK;
            }
            let row = &image[y * COLS..(y + 1) * COLS];
            let lit = row.iter().filter(|&&v| v > 0).count();
            // The lit pixels of these rows are the first `lit` columns.
            early.row((&mut columns, &mut fits), &frame, y, [(0, lit)].into_iter());
            if y % 16 == 15 {
                early.block_done((&mut columns, &mut fits), &frame, y);
            }
        }
        let located = |x: usize, row: u16| {
            early
                .lookup((&columns, &fits), &params, x, row, Real::INFINITY)
                .flatten()
                .map(|p| p.row)
        };
        for x in 0..COLS {
            let first = located(x, 20).expect("the first stripe, located by a later block");
            assert!((first - 20.0).abs() < 0.05, "column {x}: {first}");
            assert_eq!(
                located(x, 40).is_some(),
                x > 0,
                "column {x}: the second stripe"
            );
        }
        assert!(located(0, 60).is_some(), "column 0's third stripe");
    }
}
