//! The faint search's block sums, gathered during the read-out: each row of the difference
//! frame, as the streaming front end makes it, is summed over every block of `B` columns
//! into a block-major table (`Workspace::block_sums`, `block × height + row`), so that the
//! search after the frame reads one sum per block and row instead of `B` pixels, and
//! correlates them in integers (`docs/performance.md`, "Issue 17, session 13").
//!
//! The noise pass over the band (each block's `Σ|r|` and strongest response, for the
//! responses' σ and the first track's seed) runs during the read-out too, in the work each
//! block of rows leaves of the read-out's budget ([`FaintReadout`]); the search after the
//! frame does only the rows it did not reach.
//!
//! The sums are the very integers the search formed from the pixels, and the responses are
//! exact integers either way, so the search finds the same responses, σ, seed and tracks
//! with or without the table or the read-out pass (`faint_tests.rs` compares them at every
//! row and edge, and end to end).

use core::ops::Range;

use crate::image::Pixel;

use super::faint::RING;
use super::FaintParams;

/// Largest block sum the table serves: non-negative 16-bit lanes for the dual
/// multiply–accumulates, and responses far below 2³¹ (at most `Σ|w|·MAX_SUM`).
const MAX_SUM: u32 = (1 << 12) - 1;

/// The block width of the table the stream gathers for frames of `width × height` pixels of
/// `bit_depth` bits, or 0 when it gathers none: no faint search configured, the table
/// (`table_len` entries) too short, or sums that could exceed [`MAX_SUM`].
pub(super) fn table_block(
    faint: Option<FaintParams>,
    (width, height): (usize, usize),
    bit_depth: u8,
    table_len: usize,
) -> usize {
    let Some(params) = faint else { return 0 };
    let b = params.block_columns.max(1);
    let fits = width
        .div_ceil(b)
        .checked_mul(height)
        .is_some_and(|n| n <= table_len);
    let max_sum = (b as u64).saturating_mul((1u64 << bit_depth.min(16)) - 1);
    if fits && max_sum <= MAX_SUM as u64 {
        b
    } else {
        0
    }
}

/// Adds row `y` of the difference frame (`row`, `width` pixels) to the table: the sum of
/// each block of `b` columns at `table[block × height + y]`. Blocks of 8 are summed in the
/// subtraction's pass instead (`DifferenceHistogram::row_with_block_sums`, ≈ 0.5
/// instructions per pixel on the device); this serves the other block widths.
pub(super) fn gather_row<P: Pixel>(
    row: &[P],
    b: usize,
    y: usize,
    height: usize,
    table: &mut [u16],
) {
    if y >= height {
        return;
    }
    for (px, col) in row.chunks(b.max(1)).zip(table.chunks_exact_mut(height)) {
        if let Some(slot) = col.get_mut(y) {
            *slot = px.iter().map(|&p| Into::<u32>::into(p)).sum::<u32>() as u16;
        }
    }
}

/// The kernel in the form the table's correlation uses: the core's taps packed in pairs of
/// 16-bit lanes (rows `2j + 2`, `2j + 3` of the window; row 2 is the upper ring's, tap 0
/// here) for dual multiply–accumulates, and `2·w₀` for the rings. `None` unless the kernel
/// has [`RING`]-row rings of one non-positive tap on both sides (every kernel of
/// `faint::kernel` has), taps of at most 2¹⁰ and a length [`column_responses`] serves.
#[derive(Debug, Clone, Copy)]
pub(super) struct IntKernel {
    pairs: [u32; MAX_PAIRS],
    len: usize,
    ring2: i32,
    /// Rows whose `|r|` can be added in `u32` without wrapping (`|r| ≤ Σ|w|·MAX_SUM`).
    chunk_rows: usize,
}

/// Pairs of core taps of the longest kernel served (15 rows: rows 2–11).
const MAX_PAIRS: usize = 5;

impl IntKernel {
    /// The integer form of `taps`, when it has one (above).
    pub(super) fn new(taps: &[i64]) -> Option<Self> {
        let len = taps.len();
        if !matches!(len, 9 | 11 | 13 | 15) {
            return None;
        }
        let w0 = taps[0];
        let mut rings = taps[..RING].iter().chain(&taps[len - RING..]);
        if w0 > 0 || rings.any(|&w| w != w0) || taps.iter().any(|w| w.abs() > 1 << 10) {
            return None;
        }
        let tap = |i: usize| {
            if (RING..len - RING).contains(&i) {
                taps[i]
            } else {
                0
            }
        };
        let mut pairs = [0u32; MAX_PAIRS];
        for (j, p) in pairs.iter_mut().enumerate().take((len - 5) / 2) {
            let (lo, hi) = (tap(2 * j + 2), tap(2 * j + 3));
            *p = (lo as i16 as u16 as u32) | (hi as i16 as u16 as u32) << 16;
        }
        let abs_taps = taps[RING..len - RING]
            .iter()
            .map(|w| w.unsigned_abs())
            .sum::<u64>()
            + 2 * RING as u64 * w0.unsigned_abs();
        let bound = (abs_taps * u64::from(MAX_SUM)).max(1);
        Some(IntKernel {
            pairs,
            len,
            ring2: 2 * w0 as i32,
            chunk_rows: (u64::from(u32::MAX) / bound).max(1) as usize,
        })
    }
}

/// Rows `i`, `i + 1` of `win` as the low and high 16-bit lanes of a word (one unaligned word
/// load on the device).
#[inline(always)]
fn pair(win: &[u16], i: usize) -> u32 {
    u32::from(win[i]) | u32::from(win[i + 1]) << 16
}

/// Both lanes in one.
const ONES: u32 = 0x0001_0001;

/// `acc + x₀·k₀ + x₁·k₁`, the lanes signed 16-bit: `SMLAD` on the Cortex-M7 (the
/// `core::arch::arm` intrinsic is not stable Rust, inline assembly is).
#[cfg(all(feature = "cortex-m7", target_arch = "arm"))]
#[inline(always)]
#[allow(unsafe_code)]
pub(super) fn dot2(acc: i32, x: u32, k: u32) -> i32 {
    let r: i32;
    // SAFETY: SMLAD reads three registers and writes one; it may set the Q flag (never here:
    // the sums stay far below 2³¹), which nothing reads.
    unsafe {
        core::arch::asm!(
            "smlad {r}, {x}, {k}, {acc}",
            r = lateout(reg) r,
            x = in(reg) x,
            k = in(reg) k,
            acc = in(reg) acc,
            options(pure, nomem, nostack),
        );
    }
    r
}

/// `acc + x₀·k₀ + x₁·k₁`, the lanes signed 16-bit (the device's `SMLAD`, bit for bit).
#[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
#[inline(always)]
pub(super) fn dot2(acc: i32, x: u32, k: u32) -> i32 {
    let lane = |w: u32, i: u32| (w >> (16 * i)) as u16 as i16 as i32;
    acc.wrapping_add(lane(x, 0) * lane(k, 0))
        .wrapping_add(lane(x, 1) * lane(k, 1))
}

/// The ridge response at the centre of `win` (`LEN` consecutive block sums): the core's
/// taps times the sums, plus the rings. With the rings' tap `w₀ ≤ 0`, the definition's
/// `w₀·(upper + lower) − |w₀|·|upper − lower|` is `2·w₀·max(upper, lower)`: the same
/// integer, with no absolute value. Sums below 2¹² are non-negative 16-bit lanes.
#[inline(always)]
fn respond<const LEN: usize>(win: &[u16; LEN], k: &IntKernel) -> i32 {
    let upper = dot2(i32::from(win[2]), pair(win, 0), ONES);
    let lower = dot2(i32::from(win[LEN - 1]), pair(win, LEN - 3), ONES);
    let mut core = 0i32;
    for j in 0..(LEN - 5) / 2 {
        core = dot2(core, pair(win, 2 * j + 2), k.pairs[j]);
    }
    core + k.ring2 * upper.max(lower)
}

/// What the noise pass takes from a block's responses: the sum of `|r|` and the strongest
/// response with its row (the first of equals; `(0, 0)` when none is positive).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct ColumnStats {
    /// `Σ |r|` over the rows.
    pub(super) abs_sum: u64,
    /// The largest positive response (0 when none is).
    pub(super) best: i32,
    /// Its row.
    pub(super) best_row: usize,
}

/// [`ColumnStats`] of the responses at `rows` of the block whose sums are `col`.
pub(super) fn column_stats(col: &[u16], rows: Range<usize>, k: &IntKernel) -> ColumnStats {
    match k.len {
        9 => stats::<9>(col, rows, k),
        11 => stats::<11>(col, rows, k),
        13 => stats::<13>(col, rows, k),
        _ => stats::<15>(col, rows, k),
    }
}

fn stats<const LEN: usize>(col: &[u16], rows: Range<usize>, k: &IntKernel) -> ColumnStats {
    let mut out = ColumnStats::default();
    let take = |v: usize, r: i32, out: &mut ColumnStats| {
        out.abs_sum += u64::from(r.unsigned_abs());
        if r > out.best {
            (out.best, out.best_row) = (r, v);
        }
    };
    let (before, inner, after) = split::<LEN>(col.len(), &rows);
    for v in before {
        take(v, edge_response::<LEN>(col, v, k), &mut out);
    }
    let half = LEN / 2;
    let mut start = inner.start;
    while start < inner.end {
        let end = (start + k.chunk_rows).min(inner.end);
        let (abs_sum, best, at) = run::<LEN>(&col[start - half..end + half], *k, out.best);
        out.abs_sum += u64::from(abs_sum);
        if best > out.best {
            (out.best, out.best_row) = (best, start + at);
        }
        start = end;
    }
    for v in after {
        take(v, edge_response::<LEN>(col, v, k), &mut out);
    }
    out
}

/// The responses of every window of `span` (at most `chunk_rows`): `Σ|r|` in `u32`, the
/// strongest above `floor` (the first of equals) and its window's index. Not inlined: the
/// loop keeps its sums, the kernel and the strongest in registers (the search around it
/// holds many values; inlined there, they were spilled).
#[inline(never)]
fn run<const LEN: usize>(span: &[u16], k: IntKernel, floor: i32) -> (u32, i32, usize) {
    let (mut abs_sum, mut best, mut at) = (0u32, floor, 0usize);
    for (i, win) in span.windows(LEN).enumerate() {
        let Some(win) = win.first_chunk::<LEN>() else {
            break;
        };
        let r = respond(win, &k);
        abs_sum = abs_sum.wrapping_add(r.unsigned_abs());
        if r > best {
            (best, at) = (r, i);
        }
    }
    (abs_sum, best, at)
}

/// `rows` (cut to the frame) in three: the rows whose window reaches above the frame, those
/// whose window lies inside it, and those whose window reaches below it.
fn split<const LEN: usize>(
    height: usize,
    rows: &Range<usize>,
) -> (Range<usize>, Range<usize>, Range<usize>) {
    let half = LEN / 2;
    let rows = rows.start..rows.end.min(height);
    if rows.is_empty() {
        return (0..0, 0..0, 0..0);
    }
    let lo = rows.start.max(half).min(rows.end);
    let hi = rows.end.min(height.saturating_sub(half)).max(lo);
    (rows.start..lo, lo..hi, hi..rows.end)
}

/// The response at row `v` with the rows beyond the frame's edges reading the edge row.
fn edge_response<const LEN: usize>(col: &[u16], v: usize, k: &IntKernel) -> i32 {
    let half = LEN / 2;
    let last = col.len().saturating_sub(1);
    let mut win = [0u16; LEN];
    for (i, w) in win.iter_mut().enumerate() {
        *w = col
            .get((v + i).saturating_sub(half).min(last))
            .copied()
            .unwrap_or(0);
    }
    respond(&win, k)
}

/// Calls `f(row, response)` for each of `rows` (ascending) of the block whose sums are `col`
/// (one per row of the frame), rows beyond the frame's edges reading the edge row, as the
/// search's definition has it.
pub(super) fn column_responses(
    col: &[u16],
    rows: Range<usize>,
    k: &IntKernel,
    f: impl FnMut(usize, i32),
) {
    match k.len {
        9 => responses::<9>(col, rows, k, f),
        11 => responses::<11>(col, rows, k, f),
        13 => responses::<13>(col, rows, k, f),
        _ => responses::<15>(col, rows, k, f),
    }
}

fn responses<const LEN: usize>(
    col: &[u16],
    rows: Range<usize>,
    k: &IntKernel,
    mut f: impl FnMut(usize, i32),
) {
    let (before, inner, after) = split::<LEN>(col.len(), &rows);
    for v in before {
        f(v, edge_response::<LEN>(col, v, k));
    }
    if !inner.is_empty() {
        let half = LEN / 2;
        let span = &col[inner.start - half..inner.end + half];
        for (v, win) in inner.clone().zip(span.windows(LEN)) {
            if let Some(win) = win.first_chunk::<LEN>() {
                f(v, respond(win, k));
            }
        }
    }
    for v in after {
        f(v, edge_response::<LEN>(col, v, k));
    }
}

/// Instructions one response costs the noise pass on the emulated Cortex-M7 (≈ 36 for the
/// default 11-row kernel, measured: `docs/performance.md`, "Issue 17, session 13").
pub(super) const RESPONSE_COST: u32 = 40;
/// Instructions of one block's call in a read-out step (its rows, the merge).
pub(super) const COLUMN_COST: u32 = 120;

/// One block's faint-search statistics gathered during the read-out (an entry of
/// `Workspace::faint_columns`): the rows of its band and the [`ColumnStats`] of its
/// responses at the band's rows done so far.
#[derive(Debug, Clone, Copy)]
pub struct FaintColumn {
    band: (u16, u16),
    stats: ColumnStats,
}

impl FaintColumn {
    /// An empty entry (all zero).
    pub const ZERO: FaintColumn = FaintColumn {
        band: (0, 0),
        stats: ColumnStats {
            abs_sum: 0,
            best: 0,
            best_row: 0,
        },
    };

    /// The rows of the block's band.
    pub(super) fn band(&self) -> Range<usize> {
        self.band.0 as usize..self.band.1 as usize
    }

    /// The statistics of the band's rows before `done`.
    pub(super) fn stats(&self) -> ColumnStats {
        self.stats
    }
}

impl ColumnStats {
    /// Adds the statistics of the rows after this one's (the first of equal strongest stays).
    pub(super) fn merge(&mut self, later: ColumnStats) {
        self.abs_sum += later.abs_sum;
        if later.best > self.best {
            (self.best, self.best_row) = (later.best, later.best_row);
        }
    }
}

/// The faint search's noise pass during the read-out: the responses of the rows whose
/// windows are in, computed in the work each block of rows leaves of the read-out's budget
/// (`readout_fits::BLOCK_WORK`, after the curve points it locates: those are never
/// displaced), into each block's [`FaintColumn`]. What the budget did not allow is done
/// after the frame, only if the search runs; the statistics are the same either way.
#[derive(Debug, Clone, Copy)]
pub(super) struct FaintReadout {
    kernel: IntKernel,
    blocks: usize,
    height: usize,
    /// Rows `..next` of every block's band are in its statistics.
    next: usize,
}

impl FaintReadout {
    /// Starts a frame of `height` rows in `blocks` blocks whose bands are `band(block)`;
    /// `None` when `columns` is too short or a row does not fit `u16`.
    pub(super) fn begin(
        kernel: IntKernel,
        blocks: usize,
        height: usize,
        columns: &mut [FaintColumn],
        band: impl Fn(usize) -> Range<usize>,
    ) -> Option<Self> {
        if height >= u16::MAX as usize {
            return None;
        }
        for (blk, c) in columns.get_mut(..blocks)?.iter_mut().enumerate() {
            let rows = band(blk);
            *c = FaintColumn {
                band: (rows.start as u16, rows.end.min(height) as u16),
                ..FaintColumn::ZERO
            };
        }
        Some(FaintReadout {
            kernel,
            blocks,
            height,
            next: 0,
        })
    }

    /// Rows `..rows_done()` of every band are in the blocks' statistics.
    pub(super) fn rows_done(&self) -> usize {
        self.next
    }

    /// After row `y` is in (its sums in `table`): the responses of the rows whose windows are
    /// in, as far as `work` (instructions) allows.
    pub(super) fn step(&mut self, table: &[u16], columns: &mut [FaintColumn], y: usize, work: u32) {
        let ready = (y + 1).saturating_sub(self.kernel.len / 2);
        let per_row = RESPONSE_COST.saturating_mul(self.blocks as u32).max(1);
        let affordable =
            work.saturating_sub(COLUMN_COST.saturating_mul(self.blocks as u32)) / per_row;
        let n = ready.saturating_sub(self.next).min(affordable as usize);
        if n == 0 {
            return;
        }
        let (from, to) = (self.next, self.next + n);
        let cols = table.chunks_exact(self.height);
        for (c, col) in columns.iter_mut().take(self.blocks).zip(cols) {
            let rows = from.max(c.band.0 as usize)..to.min(c.band.1 as usize);
            if !rows.is_empty() {
                c.stats.merge(column_stats(col, rows, &self.kernel));
            }
        }
        self.next = to;
    }
}
