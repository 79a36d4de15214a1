//! Laser-on minus laser-off subtraction (thesis §5.3.1; derivation in
//! `docs/image-processing.md`, section "Subtraction").
//!
//! Two frames are exposed back to back, one with the laser on and one with it off. Everything
//! the laser does not light (bark, sky, leaves in sunlight) is, to first order, the same in both
//! and cancels; the laser curve remains. The difference is clamped at zero (saturating), since a
//! negative difference is ambient change or noise, never laser light.
//!
//! The same pass gathers the statistics the pipeline needs to decide whether the pair is usable
//! (laser too weak, scene too bright), so that no second pass over the frames is needed.

use super::threshold::{histogram_len, ThresholdError};
use super::{lanes, Frame, FrameError, Pixel};
use crate::real::Real;

/// Statistics gathered while subtracting a frame pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SubtractStats {
    /// Largest `on - off` difference (after clamping at zero). A pair whose largest difference
    /// is below the noise floor is dark: the laser did not reach the object.
    pub max_difference: u32,
    /// Mean of the laser-off frame, in pixel units: the ambient light level (a laser-off frame
    /// near full scale is clipped: nothing can be seen in it).
    pub off_mean: Real,
}

/// Writes `out = max(on - off, 0)` pixel by pixel and returns the pair's [`SubtractStats`].
///
/// All three frames must have the same width and height ([`FrameError::SizeMismatch`]
/// otherwise, with `expected` the size of `on`). Strides may differ, so any of the three can
/// be a window of a larger buffer. The output's bit depth is not changed: the difference of two
/// values in `[0, max]` is in `[0, max]`, so it never saturates the output type.
///
/// Cost: one pass, a handful of integer operations per pixel, no floating point per pixel.
/// [`subtract_with_histogram`] is the pipeline's faster form of the same.
pub fn subtract<P: Pixel>(
    on: &Frame<P, impl AsRef<[P]>>,
    off: &Frame<P, impl AsRef<[P]>>,
    out: &mut Frame<P, impl AsMut<[P]>>,
) -> Result<SubtractStats, FrameError> {
    on.check_same_size(off)?;
    on.check_same_size(out)?;
    let (max_difference, off_sum) = subtract_pixels(on, off, out, |_| {});
    Ok(SubtractStats {
        max_difference,
        off_mean: mean(off_sum, on),
    })
}

/// The per-pixel loop of [`subtract`] (and of [`subtract_with_histogram`] for other than
/// 8-bit frames): writes `out`, calls `each` with every difference, returns the largest
/// difference and the laser-off sum. Sizes are checked by the callers.
fn subtract_pixels<P: Pixel>(
    on: &Frame<P, impl AsRef<[P]>>,
    off: &Frame<P, impl AsRef<[P]>>,
    out: &mut Frame<P, impl AsMut<[P]>>,
    mut each: impl FnMut(u32),
) -> (u32, u64) {
    let (mut max_difference, mut off_sum) = (0u32, 0u64);
    for y in 0..on.height() {
        let (a_row, b_row, o_row) = (on.row(y), off.row(y), out.row_mut(y));
        for ((o, &a), &b) in o_row.iter_mut().zip(a_row).zip(b_row) {
            let (a, b): (u32, u32) = (a.into(), b.into());
            let d = a.saturating_sub(b);
            *o = P::saturate_from(d);
            max_difference = max_difference.max(d);
            off_sum += b as u64;
            each(d);
        }
    }
    (max_difference, off_sum)
}

/// `sum / (width · height)` of `frame` (a Frame is never empty).
fn mean<P: Pixel, S>(sum: u64, frame: &Frame<P, S>) -> Real {
    let pixels = (frame.width() as u64)
        .saturating_mul(frame.height() as u64)
        .max(1);
    (sum as f64 / pixels as f64) as Real
}

/// Counts the four byte lanes of `d` in `bins` (words with a difference ≥ 4: rare).
#[inline(never)]
fn count_lanes(bins: &mut [u32; 256], d: u32) {
    for i in 0..4 {
        bins[((d >> (8 * i)) & 0xFF) as usize] += 1;
    }
}

/// The subtraction of a streamed frame pair and the histogram of its difference, gathered
/// row by row: the laser-off frame is stored, the laser-on frame arrives in blocks of rows,
/// and each row of it is subtracted into the stored laser-off row **in place** (the difference
/// frame replaces the laser-off frame) while the histogram and the statistics accumulate.
/// After the last row, [`DifferenceHistogram::finish`] completes the histogram and returns
/// the pair's [`SubtractStats`] — exactly those of [`subtract`] and
/// [`threshold::histogram`](super::threshold::histogram) of the difference.
///
/// Cost: for 8-bit frames of bit depth 8 (the reference sensor) the pixels are processed four
/// to a `u32` word, two words per loop iteration (`image::lanes`: the saturating difference
/// and the laser-off sum are one DSP instruction each on the Cortex-M7), and the four
/// differences of a word that are all below 4 (most of a laser image: the difference of two
/// exposures of an unlit scene is noise of a grey level or two) are counted with one
/// increment of a 256-entry table indexed by the four 2-bit values, which is spread into the
/// histogram at the end. The largest difference is then the highest non-empty bin. Other
/// pixel types and bit depths take a plain per-pixel loop.
#[derive(Debug, Clone)]
pub struct DifferenceHistogram {
    /// Counts of the words whose four differences are all < 4, by their 2-bit values.
    quads: [u32; 256],
    off_sum: u64,
    pixels: u64,
    levels: usize,
    max_difference: u32,
    /// The 8-bit word path applies.
    words: bool,
}

impl DifferenceHistogram {
    /// Starts a pair of frames of full scale `max_value` (`2^bit_depth − 1`) stored as `P`:
    /// clears `bins[..max_value + 1]`. Errors: `bins` shorter than that.
    pub fn new<P: Pixel>(max_value: u32, bins: &mut [u32]) -> Result<Self, ThresholdError> {
        let levels = max_value as usize + 1;
        let Some(bins) = bins.get_mut(..levels) else {
            return Err(ThresholdError::HistogramTooSmall {
                needed: levels,
                actual: bins.len(),
            });
        };
        bins.fill(0);
        Ok(DifferenceHistogram {
            quads: [0; 256],
            off_sum: 0,
            pixels: 0,
            levels,
            max_difference: 0,
            words: P::STORAGE_BITS == 8 && max_value == 255,
        })
    }

    /// Subtracts one row: `off_diff = max(on − off_diff, 0)` pixel by pixel (the common
    /// length of the two), counting the differences in `bins` (the slice given to
    /// [`DifferenceHistogram::new`]).
    pub fn row<P: Pixel>(&mut self, on: &[P], off_diff: &mut [P], bins: &mut [u32]) {
        let n = on.len().min(off_diff.len());
        let (on, off_diff) = (&on[..n], &mut off_diff[..n]);
        self.pixels += n as u64;
        if self.words {
            if let Some(bins) = bins.first_chunk_mut::<256>() {
                self.row_words(on, off_diff, bins);
                return;
            }
        }
        let top = self.levels - 1;
        let Some(bins) = bins.get_mut(..self.levels) else {
            return;
        };
        let (mut max_d, mut sum) = (self.max_difference, 0u64);
        for (o, &a) in off_diff.iter_mut().zip(on) {
            let (a, b): (u32, u32) = (a.into(), (*o).into());
            let d = a.saturating_sub(b);
            *o = P::saturate_from(d);
            max_d = max_d.max(d);
            sum += b as u64;
            if let Some(c) = bins.get_mut((d as usize).min(top)) {
                *c += 1;
            }
        }
        self.max_difference = max_d;
        self.off_sum += sum;
    }

    /// [`DifferenceHistogram::row`] that also sums the differences of each block of 8
    /// pixels (pixels `8k .. 8k + 8`, the last block cut by the row's end) into row `y` of
    /// column `k` of `columns` (columns of `height` entries, one after the other:
    /// `columns[k × height + y]`; those beyond `columns` are not written). On the 8-bit word
    /// path the sums are taken from the difference words as they are made (two `USADA8` per
    /// block on the Cortex-M7); elsewhere from the row afterwards.
    pub fn row_with_block_sums<P: Pixel>(
        &mut self,
        on: &[P],
        off_diff: &mut [P],
        bins: &mut [u32],
        columns: &mut [u16],
        (y, height): (usize, usize),
    ) {
        let n = on.len().min(off_diff.len());
        let (on, off_diff) = (&on[..n], &mut off_diff[..n]);
        if y >= height {
            return self.row(on, off_diff, bins);
        }
        if self.words && n <= 1 << 18 {
            if let Some(bins) = bins.first_chunk_mut::<256>() {
                self.pixels += n as u64;
                let quads = &mut self.quads;
                // < 2^18 pixels: the laser-off sum stays below 2^26 in `u32`.
                let mut sum = 0u32;
                // The whole blocks that have a column.
                let done = 8 * (n / 8).min(columns.len() / height);
                let a8 = on[..done].chunks_exact(8);
                let o8 = off_diff[..done].chunks_exact_mut(8);
                for ((a, o), col) in a8.zip(o8).zip(columns.chunks_exact_mut(height)) {
                    let (a0, a1) = a.split_at(4);
                    let (o0, o1) = o.split_at_mut(4);
                    let d0 = difference_word(a0, o0, &mut sum, quads, bins);
                    let d1 = difference_word(a1, o1, &mut sum, quads, bins);
                    if let Some(c) = col.get_mut(y) {
                        *c = lanes::add_lane_sum(lanes::add_lane_sum(0, d0), d1) as u16;
                    }
                }
                // Blocks beyond the columns, and the row's last pixels.
                self.off_sum += sum as u64;
                self.pixels -= (n - done) as u64;
                let (on, off_diff) = (&on[done..], &mut off_diff[done..]);
                self.row(on, off_diff, bins);
                add_block_sums(off_diff, done / 8, columns, (y, height));
                return;
            }
        }
        self.row(on, off_diff, bins);
        add_block_sums(off_diff, 0, columns, (y, height));
    }

    /// The 8-bit word path of [`DifferenceHistogram::row`].
    #[inline(always)]
    fn row_words<P: Pixel>(&mut self, on: &[P], off_diff: &mut [P], bins: &mut [u32; 256]) {
        let quads = &mut self.quads;
        // Laser-off sums in u32 over chunks of 2^18 pixels (≤ 2^18 · 255 < 2^26), added into
        // the u64 frame total (a row may be arbitrarily long here).
        for (a_blk, o_blk) in on.chunks(1 << 18).zip(off_diff.chunks_mut(1 << 18)) {
            let mut sum = 0u32;
            let mut a8 = a_blk.chunks_exact(8);
            let mut o8 = o_blk.chunks_exact_mut(8);
            for (a, o) in (&mut a8).zip(&mut o8) {
                let (a0, a1) = a.split_at(4);
                let (o0, o1) = o.split_at_mut(4);
                difference_word(a0, o0, &mut sum, quads, bins);
                difference_word(a1, o1, &mut sum, quads, bins);
            }
            let (a, o) = (a8.remainder(), o8.into_remainder());
            let split = a.len().min(o.len()) & !3;
            if split == 4 {
                difference_word(a, o, &mut sum, quads, bins);
            }
            for (o, &a) in o[split..].iter_mut().zip(&a[split..]) {
                let (a, b): (u32, u32) = (a.into(), (*o).into());
                let d = a.saturating_sub(b);
                *o = P::saturate_from(d);
                sum += b;
                bins[(d & 0xFF) as usize] += 1;
            }
            self.off_sum += sum as u64;
        }
    }

    /// Completes the histogram in `bins` and returns the statistics of the rows subtracted.
    pub fn finish(&mut self, bins: &mut [u32]) -> SubtractStats {
        if self.words {
            if let Some(bins) = bins.first_chunk_mut::<256>() {
                for (code, count) in self.quads.iter_mut().enumerate() {
                    if *count != 0 {
                        for i in 0..4 {
                            bins[(code >> (2 * i)) & 3] += *count;
                        }
                        *count = 0;
                    }
                }
                // No difference exceeds 255 = top, so the highest non-empty bin is the maximum.
                self.max_difference = bins.iter().rposition(|&c| c != 0).unwrap_or(0) as u32;
            }
        }
        let off_mean = (self.off_sum as f64 / self.pixels.max(1) as f64) as Real;
        SubtractStats {
            max_difference: self.max_difference,
            off_mean,
        }
    }
}

/// The block sums of [`DifferenceHistogram::row_with_block_sums`] for the row's pixels
/// `row` from block `first` on: `columns[k × height + y]` = the sum of block `k`'s pixels.
fn add_block_sums<P: Pixel>(
    row: &[P],
    first: usize,
    columns: &mut [u16],
    (y, height): (usize, usize),
) {
    for (k, block) in row.chunks(8).enumerate() {
        let Some(c) = (first + k)
            .checked_mul(height)
            .and_then(|i| columns.get_mut(i + y))
        else {
            return;
        };
        *c = block.iter().map(|&p| Into::<u32>::into(p)).sum::<u32>() as u16;
    }
}

/// The 8-bit word path of [`DifferenceHistogram::row`] for one word of 4 pixels: replaces the
/// laser-off word `o` by the difference `a − o`, adds the laser-off lanes to `off_sum` and
/// counts the differences, in `quads` when all four are below 4 (indexed by their 2-bit
/// values, pixel 0 in the low bits), else in `bins`. Returns the difference word.
#[inline(always)]
fn difference_word<P: Pixel>(
    a: &[P],
    o: &mut [P],
    off_sum: &mut u32,
    quads: &mut [u32; 256],
    bins: &mut [u32; 256],
) -> u32 {
    let (a, b) = (lanes::pack4(a), lanes::pack4(o));
    let d = lanes::sub_sat(a, b);
    for (i, o) in o.iter_mut().take(4).enumerate() {
        *o = P::saturate_from((d >> (8 * i)) & 0xFF);
    }
    *off_sum = lanes::add_lane_sum(*off_sum, b);
    if d & 0xFCFC_FCFC == 0 {
        // The four 2-bit values to bits 24–31 (lane i's to bits 24 + 2i) by one multiplication:
        // the other partial products land below bit 24 in disjoint 2-bit fields or beyond 31.
        quads[(d.wrapping_mul(0x0104_1040) >> 24) as usize] += 1;
    } else {
        count_lanes(bins, d);
    }
    d
}

/// [`subtract`] and the histogram of the difference
/// ([`threshold::histogram`](super::threshold::histogram) of `out`) in one pass, through
/// [`DifferenceHistogram`] (the laser-off rows copied into `out`, then subtracted in place):
/// `bins` is cleared and then holds the count of each grey level of `out`; the returned
/// statistics and `out` are those of [`subtract`].
///
/// Errors: those of [`subtract`] (as [`ThresholdError::Frame`]) and of
/// [`threshold::histogram`](super::threshold::histogram) (`bins` shorter than `2^bit_depth`
/// of `out`, more than 2^32 − 1 pixels), checked before any pixel is written.
pub fn subtract_with_histogram<P: Pixel>(
    on: &Frame<P, impl AsRef<[P]>>,
    off: &Frame<P, impl AsRef<[P]>>,
    out: &mut Frame<P, impl AsMut<[P]>>,
    bins: &mut [u32],
) -> Result<SubtractStats, ThresholdError> {
    on.check_same_size(off)?;
    on.check_same_size(out)?;
    let levels = histogram_len(out);
    if bins.len() < levels {
        return Err(ThresholdError::HistogramTooSmall {
            needed: levels,
            actual: bins.len(),
        });
    }
    if out
        .width()
        .checked_mul(out.height())
        .and_then(|n| u32::try_from(n).ok())
        .is_none()
    {
        return Err(ThresholdError::TooManyPixels);
    }
    bins.fill(0);
    let mut acc = DifferenceHistogram::new::<P>(out.max_value(), bins)?;
    // The word path needs the laser-on frame at full 8-bit scale too.
    acc.words &= on.max_value() == 255;
    for y in 0..on.height() {
        for (o, &b) in out.row_mut(y).iter_mut().zip(off.row(y)) {
            *o = b;
        }
        acc.row(on.row(y), out.row_mut(y), bins);
    }
    Ok(acc.finish(bins))
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn saturating_difference_and_stats_u8() {
        // 3x2 frames; `on` has one saturated pixel (255) and one pixel darker than `off`
        // (ambient change), which must clamp to 0 rather than wrap to 2xx.
        let on: [u8; 6] = [10, 255, 5, 100, 0, 50];
        let off: [u8; 6] = [4, 5, 9, 100, 7, 20];
        let mut out = [77u8; 6];
        let fon = Frame::new(&on, 3, 2, 3).unwrap();
        let foff = Frame::new(&off, 3, 2, 3).unwrap();
        let mut fout = Frame::new(&mut out, 3, 2, 3).unwrap();
        let s = subtract(&fon, &foff, &mut fout).unwrap();
        assert_eq!(out, [6, 250, 0, 0, 0, 30]);
        assert_eq!(s.max_difference, 250);
        // (4+5+9+100+7+20)/6 = 145/6, exactly representable to well below f32 precision.
        assert!((s.off_mean - 145.0 / 6.0).abs() < 1e-5);
    }

    #[test]
    fn ten_bit_frames_and_strides() {
        // 10-bit data stored in u16, with a padded `on` row stride of 3 and an output window.
        let on: [u16; 6] = [1023, 500, 9999, 1023, 0, 9999];
        let off: [u16; 4] = [23, 600, 1000, 0];
        let mut out = [0u16; 8];
        let fon = Frame::new(&on, 2, 2, 3)
            .unwrap()
            .with_bit_depth(10)
            .unwrap();
        let foff = Frame::new(&off, 2, 2, 2)
            .unwrap()
            .with_bit_depth(10)
            .unwrap();
        let mut fout = Frame::new(&mut out, 2, 2, 4).unwrap();
        let s = subtract(&fon, &foff, &mut fout).unwrap();
        assert_eq!(out, [1000, 0, 0, 0, 23, 0, 0, 0]);
        assert_eq!(s.max_difference, 1000);
        assert!((s.off_mean - 1623.0 / 4.0).abs() < 1e-3);
    }

    /// Pseudo-random frames (LCG) whose values mix the cases the word path treats apart:
    /// differences below 4 (the 2-bit table), above, negative (clamped), saturated laser-on
    /// pixels, laser-off values above and below 128 (both halves of `any_byte_greater`).
    fn random_frame(seed: &mut u32, len: usize, on: bool) -> std::vec::Vec<u8> {
        (0..len)
            .map(|_| {
                *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let r = *seed >> 8;
                match (r % 8, on) {
                    (0, true) => 255,
                    (1, _) => (r >> 8) as u8,
                    (2, _) => 120 + (r >> 8) as u8 % 20,
                    _ => 40 + (r >> 8) as u8 % 4,
                }
            })
            .collect()
    }

    #[test]
    fn fused_histogram_equals_subtract_then_histogram() {
        use crate::image::threshold::histogram;
        let mut seed = 99u32;
        // Widths around the 4-pixel word and the 8-pixel loop step, padded strides, and
        // bit depths 8 (word path) and 7 (per-pixel path, with out-of-range data).
        for &(w, h, stride, bits) in &[
            (752usize, 7usize, 752usize, 8u8),
            (1029, 3, 1031, 8),
            (6, 5, 9, 8),
            (12, 3, 12, 8),
            (3, 4, 3, 8),
            (37, 6, 40, 7),
        ] {
            let len = (h - 1) * stride + w;
            let on = random_frame(&mut seed, len, true);
            let off = random_frame(&mut seed, len, false);
            let fon = Frame::new(&on, w, h, stride)
                .unwrap()
                .with_bit_depth(bits)
                .unwrap();
            let foff = Frame::new(&off, w, h, stride)
                .unwrap()
                .with_bit_depth(bits)
                .unwrap();
            let mut out_a = std::vec![0u8; w * h];
            let mut out_b = std::vec![7u8; w * h];
            let mut bins_a = std::vec![0u32; 256];
            let mut bins_b = std::vec![5u32; 300];
            let mut fa = Frame::new(&mut out_a, w, h, w)
                .unwrap()
                .with_bit_depth(bits)
                .unwrap();
            let sa = subtract(&fon, &foff, &mut fa).unwrap();
            let total = histogram(&fa, &mut bins_a).unwrap();
            let mut fb = Frame::new(&mut out_b, w, h, w)
                .unwrap()
                .with_bit_depth(bits)
                .unwrap();
            let sb = subtract_with_histogram(&fon, &foff, &mut fb, &mut bins_b).unwrap();
            assert_eq!(out_a, out_b, "{w}x{h}");
            assert_eq!(sa, sb, "{w}x{h}");
            assert_eq!(&bins_a[..], &bins_b[..256], "{w}x{h}");
            assert!(bins_b[256..].iter().all(|&c| c == 0));
            assert_eq!(bins_b.iter().sum::<u32>(), total);
        }
        // u16 frames take the per-pixel path.
        let on: [u16; 4] = [1023, 7, 500, 3];
        let off: [u16; 4] = [3, 9, 100, 3];
        let fon = Frame::new(&on, 2, 2, 2)
            .unwrap()
            .with_bit_depth(10)
            .unwrap();
        let foff = Frame::new(&off, 2, 2, 2)
            .unwrap()
            .with_bit_depth(10)
            .unwrap();
        let mut out = [0u16; 4];
        let mut fo = Frame::new(&mut out, 2, 2, 2)
            .unwrap()
            .with_bit_depth(10)
            .unwrap();
        let mut bins = [0u32; 1024];
        assert_eq!(
            subtract_with_histogram(&fon, &foff, &mut fo, &mut bins[..1000]).unwrap_err(),
            ThresholdError::HistogramTooSmall {
                needed: 1024,
                actual: 1000
            }
        );
        let s = subtract_with_histogram(&fon, &foff, &mut fo, &mut bins).unwrap();
        assert_eq!(out, [1020, 0, 400, 0]);
        assert_eq!(s.max_difference, 1020);
        assert_eq!((bins[0], bins[400], bins[1020]), (2, 1, 1));
    }

    #[test]
    fn block_sums_in_the_pass_are_the_sums_of_the_difference() {
        let mut seed = 7u32;
        // Whole blocks, a cut last block, a row shorter than a block, 7-bit (per-pixel path),
        // and a table with fewer columns than the row has blocks.
        for &(w, h, bits, columns) in &[
            (752usize, 5usize, 8u8, 94usize),
            (37, 4, 8, 5),
            (5, 3, 8, 1),
            (37, 4, 7, 5),
            (37, 4, 8, 3),
        ] {
            let on = random_frame(&mut seed, w * h, true);
            let off = random_frame(&mut seed, w * h, false);
            let max = (1u32 << bits) - 1;
            let (mut plain, mut summed) = (off.clone(), off.clone());
            let (mut bins_a, mut bins_b) = (std::vec![0u32; 256], std::vec![0u32; 256]);
            let mut a = DifferenceHistogram::new::<u8>(max, &mut bins_a).unwrap();
            let mut b = DifferenceHistogram::new::<u8>(max, &mut bins_b).unwrap();
            let mut table = std::vec![u16::MAX; columns * h];
            for y in 0..h {
                let rows = y * w..(y + 1) * w;
                a.row(&on[rows.clone()], &mut plain[rows.clone()], &mut bins_a);
                b.row_with_block_sums(
                    &on[rows.clone()],
                    &mut summed[rows],
                    &mut bins_b,
                    &mut table,
                    (y, h),
                );
            }
            assert_eq!(plain, summed, "{w} × {h}");
            assert_eq!(a.finish(&mut bins_a), b.finish(&mut bins_b));
            assert_eq!(bins_a, bins_b);
            for y in 0..h {
                for k in 0..columns {
                    let block = &plain[y * w + (8 * k).min(w)..y * w + (8 * k + 8).min(w)];
                    let sum: u32 = block.iter().map(|&p| p as u32).sum();
                    let expect = if 8 * k < w { sum as u16 } else { u16::MAX };
                    assert_eq!(table[k * h + y], expect, "{w} × {h}, row {y}, block {k}");
                }
            }
        }
    }

    #[test]
    fn rejects_mismatched_sizes() {
        let a = [0u8; 12];
        let b = [0u8; 12];
        let mut o = [0u8; 12];
        let fa = Frame::new(&a, 4, 3, 4).unwrap();
        let fb = Frame::new(&b, 3, 4, 3).unwrap();
        let mut fo = Frame::new(&mut o, 4, 3, 4).unwrap();
        assert_eq!(
            subtract(&fa, &fb, &mut fo).unwrap_err(),
            FrameError::SizeMismatch {
                expected: (4, 3),
                actual: (3, 4)
            }
        );
        let fb = Frame::new(&b, 4, 3, 4).unwrap();
        let mut fo = Frame::new(&mut o, 6, 2, 6).unwrap();
        assert_eq!(
            subtract(&fa, &fb, &mut fo).unwrap_err(),
            FrameError::SizeMismatch {
                expected: (4, 3),
                actual: (6, 2)
            }
        );
    }
}
