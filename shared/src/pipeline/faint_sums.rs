//! The faint search's block sums, gathered during the read-out: each row of the difference
//! frame, as the streaming front end makes it, is summed over every block of `B` columns
//! into a block-major table (`Workspace::block_sums`, `block × height + row`), so that the
//! search after the frame reads one sum per block and row instead of `B` pixels, and
//! correlates them in integers (`docs/performance.md`, "Issue 17, session 13").
//!
//! The sums are the very integers the search formed from the pixels, and the responses are
//! exact integers either way, so the search finds the same responses, σ, seed and tracks
//! with or without the table (`faint_tests.rs` compares both at every row and edge).

use core::ops::Range;

use crate::image::{lanes, Pixel};

use super::faint::RING;
use super::FaintParams;

/// Largest block sum the table serves: sums below 2¹² keep every response below 2²⁶
/// (the kernel's absolute taps add up to < 2¹⁴), so `u32` sums of 64 of them cannot wrap.
const MAX_SUM: u32 = (1 << 12) - 1;

/// Rows whose `|response|` are added in `u32` before going into the `u64` total.
pub(super) const ABS_CHUNK: usize = 64;

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
/// each block of `b` columns at `table[block × height + y]`. 8-bit pixels in blocks of 8
/// take two word loads and two lane sums (`USADA8` on the device) per block: ≈ 0.5
/// instructions per pixel during the read-out.
#[inline]
pub(super) fn gather_row<P: Pixel>(
    row: &[P],
    b: usize,
    y: usize,
    height: usize,
    table: &mut [u16],
) {
    let Some(slots) = table.get_mut(y..) else {
        return;
    };
    let slots = slots.iter_mut().step_by(height.max(1));
    if b == 8 && P::STORAGE_BITS == 8 {
        let mut blocks = row.chunks_exact(8);
        for (px, slot) in (&mut blocks).zip(slots) {
            let (p0, p1) = px.split_at(4);
            let s = lanes::add_lane_sum(lanes::add_lane_sum(0, lanes::pack4(p0)), lanes::pack4(p1));
            *slot = s as u16;
        }
        let rest = blocks.remainder();
        if !rest.is_empty() {
            if let Some(slot) = table.get_mut(row.len() / 8 * height + y) {
                *slot = rest.iter().map(|&p| Into::<u32>::into(p)).sum::<u32>() as u16;
            }
        }
    } else {
        for (px, slot) in row.chunks(b.max(1)).zip(slots) {
            *slot = px.iter().map(|&p| Into::<u32>::into(p)).sum::<u32>() as u16;
        }
    }
}

/// The kernel in the form the table's correlation uses: the taps as `i32`, and `2·w₀` for
/// the rings. `None` unless the kernel has [`RING`]-row rings of one non-positive tap on
/// both sides (every kernel of `faint::kernel` has) and a length [`column_responses`]
/// serves.
#[derive(Debug, Clone, Copy)]
pub(super) struct IntKernel {
    taps: [i32; MAX_LEN],
    len: usize,
    ring2: i32,
}

/// Longest kernel served (`faint::MAX_KERNEL`).
const MAX_LEN: usize = 15;

impl IntKernel {
    /// The integer form of `taps`, when it has one (above).
    pub(super) fn new(taps: &[i64]) -> Option<Self> {
        let len = taps.len();
        if !matches!(len, 9 | 11 | 13 | 15) {
            return None;
        }
        let w0 = taps[0];
        let rings = taps[..RING].iter().chain(&taps[len - RING..]);
        if w0 > 0 || rings.clone().any(|&w| w != w0) || taps.iter().any(|w| w.abs() > 1 << 10) {
            return None;
        }
        let mut out = [0i32; MAX_LEN];
        for (o, &t) in out.iter_mut().zip(taps) {
            *o = t as i32;
        }
        Some(IntKernel {
            taps: out,
            len,
            ring2: 2 * w0 as i32,
        })
    }
}

/// The ridge response at the centre of `win` (`LEN` consecutive block sums): the core's
/// taps times the sums, plus the rings. With the rings' tap `w₀ ≤ 0`, the definition's
/// `w₀·(upper + lower) − |w₀|·|upper − lower|` is `2·w₀·max(upper, lower)`: the same
/// integer, with no absolute value.
#[inline(always)]
fn respond<const LEN: usize>(win: &[u16; LEN], k: &IntKernel) -> i32 {
    let s = |i: usize| win[i] as i32;
    let upper = s(0) + s(1) + s(2);
    let lower = s(LEN - 3) + s(LEN - 2) + s(LEN - 1);
    let mut r = k.ring2 * upper.max(lower);
    for i in RING..LEN - RING {
        r += k.taps[i] * s(i);
    }
    r
}

/// Calls `f(row, response)` for each of `rows` (ascending) of the block whose sums are `col`
/// (one per row of the frame), rows beyond the frame's edges reading the edge row, as the
/// search's definition has it.
#[inline]
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

#[inline(always)]
fn responses<const LEN: usize>(
    col: &[u16],
    rows: Range<usize>,
    k: &IntKernel,
    mut f: impl FnMut(usize, i32),
) {
    let height = col.len();
    let half = LEN / 2;
    let rows = rows.start..rows.end.min(height);
    if rows.is_empty() {
        return;
    }
    // Rows whose window lies inside the frame read the column in place; the others a
    // window with the edge rows repeated.
    let inner = rows.start.max(half).min(rows.end)..rows.end.min(height.saturating_sub(half));
    let edge = |v: usize, f: &mut dyn FnMut(usize, i32)| {
        let mut win = [0u16; LEN];
        for (i, w) in win.iter_mut().enumerate() {
            *w = col[(v + i).saturating_sub(half).min(height - 1)];
        }
        f(v, respond(&win, k));
    };
    if inner.is_empty() {
        for v in rows {
            edge(v, &mut f);
        }
        return;
    }
    for v in rows.start..inner.start {
        edge(v, &mut f);
    }
    let span = &col[inner.start - half..inner.end + half];
    for (j, win) in span.windows(LEN).enumerate() {
        if let Some(win) = win.first_chunk::<LEN>() {
            f(inner.start + j, respond(win, k));
        }
    }
    for v in inner.end..rows.end {
        edge(v, &mut f);
    }
}
