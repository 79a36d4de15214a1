//! Laser-on minus laser-off subtraction (thesis §5.3.1; derivation in
//! `docs/image-processing.md`, section "Subtraction").
//!
//! Two frames are exposed back to back, one with the laser on and one with it off. Everything
//! the laser does not light (bark, sky, leaves in sunlight) is, to first order, the same in both
//! and cancels; the laser curve remains. The difference is clamped at zero (saturating), since a
//! negative difference is ambient change or noise, never laser light.
//!
//! The same pass gathers the statistics the pipeline needs to decide whether the pair is usable
//! (laser too weak, sensor saturated by the sun, scene too bright), so that no second pass over
//! the frames is needed.

use super::threshold::{histogram_len, ThresholdError};
use super::{Frame, FrameError, FrameMut, Pixel};
use crate::real::Real;

/// Statistics gathered while subtracting a frame pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SubtractStats {
    /// Largest `on - off` difference (after clamping at zero). A pair whose largest difference
    /// is below the noise floor is dark: the laser did not reach the object.
    pub max_difference: u32,
    /// Number of pixels of the laser-on frame at (or above) its saturation level
    /// [`Frame::max_value`]. Saturated pixels flatten the laser profile and bias subpixel
    /// estimators (docs/subpixel.md).
    pub on_saturated: u32,
    /// Mean of the laser-off frame, in pixel units: the ambient light level.
    pub off_mean: Real,
    /// Largest value of the laser-off frame (ambient light alone close to saturation means the
    /// laser cannot be seen there whatever its power).
    pub off_max: u32,
}

/// Writes `out = max(on - off, 0)` pixel by pixel and returns the pair's [`SubtractStats`].
///
/// All three frames must have the same width and height ([`FrameError::SizeMismatch`]
/// otherwise, with `expected` the size of `on`). Strides may differ, so any of the three can
/// be a window of a larger buffer. The output's bit depth is not changed: the difference of two
/// values in `[0, max]` is in `[0, max]`, so it never saturates the output type.
///
/// Cost: one pass, a handful of integer operations per pixel, no floating point per pixel.
pub fn subtract<P: Pixel>(
    on: &Frame<'_, P>,
    off: &Frame<'_, P>,
    out: &mut FrameMut<'_, P>,
) -> Result<SubtractStats, FrameError> {
    on.check_same_size(off)?;
    on.check_same_size(&out.as_frame())?;

    let width = on.width();
    let height = on.height();
    let saturation = on.max_value();
    let mut max_difference = 0u32;
    let mut on_saturated = 0u32;
    let mut off_max = 0u32;
    let mut off_sum = 0u64;

    // Chunks of at most 65 536 pixels: a chunk's sum of values < 2^16 fits a u32, so the
    // per-pixel accumulation is 32-bit (one ADD on the M7 instead of ADDS/ADC and a register
    // pair); chunk sums are added into the u64 frame total.
    const CHUNK: usize = 1 << 16;
    for y in 0..height {
        let on_row = on.row(y);
        let off_row = off.row(y);
        let out_row = out.row_mut(y);
        for ((o_c, a_c), b_c) in out_row
            .chunks_mut(CHUNK)
            .zip(on_row.chunks(CHUNK))
            .zip(off_row.chunks(CHUNK))
        {
            let mut sum = 0u32;
            let mut max_diff = 0u32;
            let mut off_hi = 0u32;
            let mut saturated = 0u32;
            for (o, (&a, &b)) in o_c.iter_mut().zip(a_c.iter().zip(b_c.iter())) {
                let a: u32 = a.into();
                let b: u32 = b.into();
                let d = a.saturating_sub(b);
                *o = P::saturate_from(d);
                max_diff = max_diff.max(d);
                off_hi = off_hi.max(b);
                saturated += (a >= saturation) as u32;
                sum += b;
            }
            max_difference = max_difference.max(max_diff);
            off_max = off_max.max(off_hi);
            on_saturated = on_saturated.saturating_add(saturated);
            off_sum += sum as u64;
        }
    }

    // width * height >= 1 (a Frame is never empty).
    let pixels = (width as u64).saturating_mul(height as u64).max(1);
    Ok(SubtractStats {
        max_difference,
        on_saturated,
        off_mean: (off_sum as f64 / pixels as f64) as Real,
        off_max,
    })
}

/// Lane mask of the four bytes of a `u32` word (SWAR: "SIMD within a register").
const LOW7: u32 = 0x7F7F_7F7F;
/// The top bit of each byte lane.
const HIGH: u32 = 0x8080_8080;
/// One in each byte lane.
const ONES: u32 = 0x0101_0101;
/// Even byte lanes (bytes 0 and 2) of a word, as two 16-bit lanes.
const EVEN: u32 = 0x00FF_00FF;

/// Per-lane `max(a − b, 0)` of four bytes packed in `u32`s (no lane borrows from another).
///
/// `t = (a | 0x80) − (b & 0x7F)` per lane is `128 + a_lo − b_lo ∈ [1, 255]`, so the word
/// subtraction never borrows across lanes, and bit 7 of `t` says `a_lo ≥ b_lo` (`x_lo` = the
/// low 7 bits). The true lane difference is `t` with bit 7 flipped when `a_7 == b_7`; `a ≥ b`
/// iff `a_7 > b_7`, or `a_7 == b_7` and `a_lo ≥ b_lo`. That bit, spread to the whole lane
/// (`2·g − g/128` per lane), masks the negative differences to 0. About 13 ALU instructions
/// per 4 pixels on a Cortex-M (no DSP intrinsics: they are unstable in Rust).
#[inline(always)]
fn saturating_sub_bytes(a: u32, b: u32) -> u32 {
    let t = (a | HIGH).wrapping_sub(b & !HIGH);
    let ab = a ^ b;
    let d = t ^ (!ab & HIGH);
    let ge = ((a & !b) | (t & !ab)) & HIGH;
    let mask = (ge << 1).wrapping_sub(ge >> 7);
    d & mask
}

/// Non-zero iff some byte lane of `x` is greater than `m` (`m ≤ 254`): the low 7 bits of each
/// lane plus `127 − (m mod 128)` reach bit 7 iff `x_lo > m mod 128` (never carrying into the
/// next lane: at most 127 + 127); for `m < 128` a lane with bit 7 set is greater anyway, for
/// `m ≥ 128` it must also have bit 7 set.
#[cfg(test)]
fn any_byte_greater(x: u32, m: u32) -> u32 {
    ByteGreater::new(m).test(x)
}

/// The word test of [`any_byte_greater`] for a fixed `m ≤ 254`, its constant precomputed
/// (for loops that test every word of a frame against one level).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ByteGreater {
    add: u32,
    high: bool,
}

impl ByteGreater {
    /// The test against level `m` (`m ≤ 254`; at 255 it would never fire, which is also right).
    #[inline(always)]
    pub(crate) fn new(m: u32) -> Self {
        ByteGreater {
            add: (127 - (m & 127)) * ONES,
            high: m >= 128,
        }
    }
    /// Non-zero iff some byte lane of `x` is greater than the level.
    #[inline(always)]
    pub(crate) fn test(self, x: u32) -> u32 {
        let t = (x & LOW7) + self.add;
        if self.high {
            t & x & HIGH
        } else {
            (t | x) & HIGH
        }
    }
}

/// The maximum of `m` and the byte lanes of `x`, with its [`ByteGreater`] constant
/// `(127 − (max mod 128))·0x01010101` (rare: a laser-off pixel above the running maximum; at
/// 255 the constant is 0 and the test never fires, as nothing is greater).
#[inline(never)]
fn raise_max(m: u32, x: u32) -> (u32, u32) {
    let m = m.max(x & 0xFF).max((x >> 8) & 0xFF);
    let m = m.max((x >> 16) & 0xFF).max(x >> 24);
    (m, (127 - (m & 127)) * ONES)
}

/// Counts the four byte lanes of `d` in `bins` (words with a difference ≥ 4: rare).
#[inline(never)]
fn count_lanes(bins: &mut [u32; 256], d: u32) {
    for i in 0..4 {
        bins[((d >> (8 * i)) & 0xFF) as usize] += 1;
    }
}

/// Packs 4 pixels of at most 8 bits (little-endian, pixel 0 in the low byte). For `u8` the
/// compiler turns the four byte loads into one word load.
#[inline(always)]
pub(crate) fn pack4<P: Pixel>(p: &[P]) -> u32 {
    match *p {
        [p0, p1, p2, p3, ..] => {
            let (p0, p1, p2, p3): (u32, u32, u32, u32) =
                (p0.into(), p1.into(), p2.into(), p3.into());
            (p0 & 0xFF) | (p1 & 0xFF) << 8 | (p2 & 0xFF) << 16 | (p3 & 0xFF) << 24
        }
        _ => 0,
    }
}

/// [`subtract`] and the histogram of the difference
/// ([`threshold::histogram`](super::threshold::histogram) of `out`) in one pass over the
/// frames: `bins` is cleared and then holds the count of each grey level of `out`, exactly as
/// if `threshold::histogram(&out.as_frame(), bins)` had been called after [`subtract`]; the
/// returned statistics and `out` are those of [`subtract`].
///
/// Errors: those of [`subtract`] (as [`ThresholdError::Frame`]) and of
/// [`threshold::histogram`](super::threshold::histogram) (`bins` shorter than `2^bit_depth`
/// of `out`, more than 2^32 − 1 pixels), checked before any pixel is written.
///
/// Cost: for 8-bit frames whose bit depth is 8 (the reference sensor) the pixels are processed
/// four to a `u32` word: the saturating difference, the laser-off sum and the rare-event tests
/// (a laser-off pixel above the running maximum, a saturated laser-on pixel) are word
/// operations, and the four differences of a word that are all below 4 (most of a laser
/// image: the difference of two exposures of an unlit scene is noise of a grey level or two)
/// are counted with one increment of a 256-entry table indexed by the four 2-bit values, which
/// is spread into the histogram at the end. The largest difference is then the highest
/// non-empty bin. Other pixel types and bit depths take a plain per-pixel loop.
pub fn subtract_with_histogram<P: Pixel>(
    on: &Frame<'_, P>,
    off: &Frame<'_, P>,
    out: &mut FrameMut<'_, P>,
    bins: &mut [u32],
) -> Result<SubtractStats, ThresholdError> {
    on.check_same_size(off)?;
    on.check_same_size(&out.as_frame())?;
    let out_frame = out.as_frame();
    let levels = histogram_len(&out_frame);
    if bins.len() < levels {
        return Err(ThresholdError::HistogramTooSmall {
            needed: levels,
            actual: bins.len(),
        });
    }
    let out_max = out_frame.max_value();
    if out_frame
        .width()
        .checked_mul(out_frame.height())
        .and_then(|n| u32::try_from(n).ok())
        .is_none()
    {
        return Err(ThresholdError::TooManyPixels);
    }
    bins.fill(0);
    let top = levels - 1;
    let bins = &mut bins[..levels];
    let (width, height) = (on.width(), on.height());
    let saturation = on.max_value();

    let mut stats = SubtractStats {
        max_difference: 0,
        on_saturated: 0,
        off_mean: 0.0,
        off_max: 0,
    };
    let mut off_sum = 0u64;
    if P::STORAGE_BITS == 8 && saturation == 255 && out_max == 255 {
        // Fixed-size views: the byte-valued indices below need no bounds check.
        let Some(bins) = bins.first_chunk_mut::<256>() else {
            return Err(ThresholdError::HistogramTooSmall {
                needed: 256,
                actual: levels,
            });
        };
        // Counts of the words whose four differences are all < 4, by their 2-bit values.
        let mut quads = [0u32; 256];
        // Running laser-off maximum and its `ByteGreater` constant.
        let (mut off_max, mut off_add) = (0u32, 127 * ONES);
        let mut on_saturated = 0u32;
        for y in 0..height {
            let (a_row, b_row, o_row) = (on.row(y), off.row(y), out.row_mut(y));
            let n = a_row.len().min(b_row.len()).min(o_row.len());
            let (a_row, b_row, o_row) = (&a_row[..n], &b_row[..n], &mut o_row[..n]);
            let split = n - n % 4;
            let (a_words, a_tail) = a_row.split_at(split);
            let (b_words, b_tail) = b_row.split_at(split);
            let (o_words, o_tail) = o_row.split_at_mut(split);
            // The frames' statistics in a loop of their own: fused into the difference loop
            // below they push its live values past the M7's registers (spills cost more than
            // reading the words again).
            for (a_blk, b_blk) in a_words.chunks(4 * 128).zip(b_words.chunks(4 * 128)) {
                // Laser-off sum in 16-bit lanes, bytes 0 + 1 and 2 + 3 of each word (≤ 510
                // per word, 128 words per block); saturated laser-on lanes (== 255: exactly
                // the lanes flagged) counted in byte lanes.
                let (mut sum_lanes, mut sat_lanes) = (0u32, 0u32);
                for (a4, b4) in a_blk.chunks_exact(4).zip(b_blk.chunks_exact(4)) {
                    let (a, b) = (pack4(a4), pack4(b4));
                    sum_lanes += (b & EVEN) + ((b >> 8) & EVEN);
                    sat_lanes += ((((a & LOW7) + ONES) & a) >> 7) & ONES;
                    let t = (b & LOW7) + off_add;
                    let greater = if off_max < 128 {
                        (t | b) & HIGH
                    } else {
                        t & b & HIGH
                    };
                    if greater != 0 {
                        (off_max, off_add) = raise_max(off_max, b);
                    }
                }
                off_sum += ((sum_lanes & 0xFFFF) + (sum_lanes >> 16)) as u64;
                on_saturated += (sat_lanes & 0xFF)
                    + ((sat_lanes >> 8) & 0xFF)
                    + ((sat_lanes >> 16) & 0xFF)
                    + (sat_lanes >> 24);
            }
            for ((a4, b4), o4) in a_words
                .chunks_exact(4)
                .zip(b_words.chunks_exact(4))
                .zip(o_words.chunks_exact_mut(4))
            {
                let d = saturating_sub_bytes(pack4(a4), pack4(b4));
                for (i, o) in o4.iter_mut().enumerate() {
                    *o = P::saturate_from((d >> (8 * i)) & 0xFF);
                }
                if d & 0xFCFC_FCFC == 0 {
                    quads[((d | d >> 6 | d >> 12 | d >> 18) & 0xFF) as usize] += 1;
                } else {
                    count_lanes(bins, d);
                }
            }
            for ((o, &a), &b) in o_tail.iter_mut().zip(a_tail).zip(b_tail) {
                let (a, b): (u32, u32) = (a.into(), b.into());
                let d = a.saturating_sub(b);
                *o = P::saturate_from(d);
                off_max = off_max.max(b);
                on_saturated += (a >= saturation) as u32;
                off_sum += b as u64;
                bins[(d & 0xFF) as usize] += 1;
            }
        }
        for (code, &count) in quads.iter().enumerate() {
            if count != 0 {
                for i in 0..4 {
                    bins[(code >> (2 * i)) & 3] += count;
                }
            }
        }
        // No difference exceeds 255 = top, so the highest non-empty bin is the maximum.
        stats.max_difference = bins.iter().rposition(|&c| c != 0).unwrap_or(0) as u32;
        stats.off_max = off_max;
        stats.on_saturated = on_saturated;
    } else {
        let (mut max_difference, mut off_max, mut on_saturated) = (0u32, 0u32, 0u32);
        for y in 0..height {
            let (a_row, b_row, o_row) = (on.row(y), off.row(y), out.row_mut(y));
            for ((o, &a), &b) in o_row.iter_mut().zip(a_row).zip(b_row) {
                let (a, b): (u32, u32) = (a.into(), b.into());
                let d = a.saturating_sub(b);
                *o = P::saturate_from(d);
                max_difference = max_difference.max(d);
                off_max = off_max.max(b);
                on_saturated = on_saturated.saturating_add((a >= saturation) as u32);
                off_sum += b as u64;
                if let Some(c) = bins.get_mut((d as usize).min(top)) {
                    *c += 1;
                }
            }
        }
        stats.max_difference = max_difference;
        stats.off_max = off_max;
        stats.on_saturated = on_saturated;
    }
    // width * height >= 1 (a Frame is never empty).
    let pixels = (width as u64).saturating_mul(height as u64).max(1);
    stats.off_mean = (off_sum as f64 / pixels as f64) as Real;
    Ok(stats)
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
        let mut fout = FrameMut::new(&mut out, 3, 2, 3).unwrap();
        let s = subtract(&fon, &foff, &mut fout).unwrap();
        assert_eq!(out, [6, 250, 0, 0, 0, 30]);
        assert_eq!(s.max_difference, 250);
        assert_eq!(s.on_saturated, 1);
        assert_eq!(s.off_max, 100);
        // (4+5+9+100+7+20)/6 = 145/6, exactly representable to well below f32 precision.
        assert!((s.off_mean - 145.0 / 6.0).abs() < 1e-5);
    }

    #[test]
    fn ten_bit_saturation_level_and_strides() {
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
        let mut fout = FrameMut::new(&mut out, 2, 2, 4).unwrap();
        let s = subtract(&fon, &foff, &mut fout).unwrap();
        assert_eq!(out, [1000, 0, 0, 0, 23, 0, 0, 0]);
        assert_eq!(s.on_saturated, 2);
        assert_eq!(s.max_difference, 1000);
        assert_eq!(s.off_max, 1000);
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
        // Widths around the 4-pixel word and the 1024-pixel flush block, padded strides, and
        // bit depths 8 (word path) and 7 (per-pixel path, with out-of-range data).
        for &(w, h, stride, bits) in &[
            (752usize, 7usize, 752usize, 8u8),
            (1029, 3, 1031, 8),
            (6, 5, 9, 8),
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
            let mut fa = FrameMut::new(&mut out_a, w, h, w)
                .unwrap()
                .with_bit_depth(bits)
                .unwrap();
            let sa = subtract(&fon, &foff, &mut fa).unwrap();
            let total = histogram(&fa.as_frame(), &mut bins_a).unwrap();
            let mut fb = FrameMut::new(&mut out_b, w, h, w)
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
        let mut fo = FrameMut::new(&mut out, 2, 2, 2)
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
        assert_eq!(
            (s.max_difference, s.on_saturated, s.off_max),
            (1020, 1, 100)
        );
        assert_eq!((bins[0], bins[400], bins[1020]), (2, 1, 1));
    }

    #[test]
    fn word_helpers_match_per_lane_arithmetic() {
        // Exhaustive over one lane pair in every position, with the other lanes fixed.
        for a in 0..=255u32 {
            for b in 0..=255u32 {
                for lane in 0..4 {
                    let fill_a = 0x9C5A_37E1 & !(0xFF << (8 * lane));
                    let fill_b = 0x21B4_7F9C & !(0xFF << (8 * lane));
                    let wa = fill_a | a << (8 * lane);
                    let wb = fill_b | b << (8 * lane);
                    let d = saturating_sub_bytes(wa, wb);
                    for k in 0..4 {
                        let (x, y) = ((wa >> (8 * k)) & 0xFF, (wb >> (8 * k)) & 0xFF);
                        assert_eq!((d >> (8 * k)) & 0xFF, x.saturating_sub(y));
                    }
                }
                if b < 255 {
                    let w = a * ONES;
                    assert_eq!(any_byte_greater(w, b) != 0, a > b, "{a} > {b}");
                    let w = a << 16 | 0x0300_0003;
                    let expect = a > b || 3 > b;
                    assert_eq!(any_byte_greater(w, b) != 0, expect, "{a} {b}");
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
        let mut fo = FrameMut::new(&mut o, 4, 3, 4).unwrap();
        assert_eq!(
            subtract(&fa, &fb, &mut fo).unwrap_err(),
            FrameError::SizeMismatch {
                expected: (4, 3),
                actual: (3, 4)
            }
        );
        let fb = Frame::new(&b, 4, 3, 4).unwrap();
        let mut fo = FrameMut::new(&mut o, 6, 2, 6).unwrap();
        assert_eq!(
            subtract(&fa, &fb, &mut fo).unwrap_err(),
            FrameError::SizeMismatch {
                expected: (4, 3),
                actual: (6, 2)
            }
        );
    }
}
