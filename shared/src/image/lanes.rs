//! Four 8-bit pixels in one `u32` word: the lane operations of the per-pixel passes
//! (subtraction, histogram, segmentation's background scan; `docs/performance.md`).
//!
//! Every operation acts on the four byte lanes of a word independently. With the crate
//! feature `cortex-m7` on an ARM target (the firmware enables it) they are the
//! single DSP-extension instructions `UQSUB8` (per-lane saturating subtraction) and `USADA8`
//! (sum of the four lanes, accumulated) through inline assembly — the `core::arch::arm`
//! intrinsics for them are not stable Rust, inline assembly is. Everywhere else they are
//! portable SWAR ("SIMD within a register") expressions with the same results bit for bit;
//! `word_ops_match_per_lane_arithmetic` checks them exhaustively per lane, and the emulated
//! firmware's readings equal the host's (`host/tests/emulated_device.rs`).

use super::Pixel;

/// One in each byte lane.
pub(crate) const ONES: u32 = 0x0101_0101;
/// Lane mask of the low 7 bits of each byte.
#[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
const LOW7: u32 = 0x7F7F_7F7F;
/// The top bit of each byte lane.
#[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
const HIGH: u32 = 0x8080_8080;
/// Even byte lanes (bytes 0 and 2) of a word, as two 16-bit lanes.
#[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
const EVEN: u32 = 0x00FF_00FF;

/// Per-lane `max(a − b, 0)`.
#[cfg(all(feature = "cortex-m7", target_arch = "arm"))]
#[inline(always)]
#[allow(unsafe_code)]
pub(crate) fn sub_sat(a: u32, b: u32) -> u32 {
    let d: u32;
    // SAFETY: UQSUB8 reads two registers and writes one; no memory, stack or flags.
    unsafe {
        core::arch::asm!(
            "uqsub8 {d}, {a}, {b}",
            d = lateout(reg) d,
            a = in(reg) a,
            b = in(reg) b,
            options(pure, nomem, nostack, preserves_flags),
        );
    }
    d
}

/// Per-lane `max(a − b, 0)`.
///
/// `t = (a | 0x80) − (b & 0x7F)` per lane is `128 + a_lo − b_lo ∈ [1, 255]`, so the word
/// subtraction never borrows across lanes, and bit 7 of `t` says `a_lo ≥ b_lo` (`x_lo` = the
/// low 7 bits). The true lane difference is `t` with bit 7 flipped when `a_7 == b_7`; `a ≥ b`
/// iff `a_7 > b_7`, or `a_7 == b_7` and `a_lo ≥ b_lo`. That bit, spread to the whole lane
/// (`2·g − g/128` per lane), masks the negative differences to 0.
#[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
#[inline(always)]
pub(crate) fn sub_sat(a: u32, b: u32) -> u32 {
    let t = (a | HIGH).wrapping_sub(b & !HIGH);
    let ab = a ^ b;
    let d = t ^ (!ab & HIGH);
    let ge = ((a & !b) | (t & !ab)) & HIGH;
    let mask = (ge << 1).wrapping_sub(ge >> 7);
    d & mask
}

/// `acc` plus the sum of the four lanes of `x` (wrapping; callers keep it below 2^32).
#[cfg(all(feature = "cortex-m7", target_arch = "arm"))]
#[inline(always)]
#[allow(unsafe_code)]
pub(crate) fn add_lane_sum(acc: u32, x: u32) -> u32 {
    let s: u32;
    // SAFETY: USADA8 reads three registers and writes one; no memory, stack or flags.
    unsafe {
        core::arch::asm!(
            "usada8 {s}, {x}, {zero}, {acc}",
            s = lateout(reg) s,
            x = in(reg) x,
            zero = in(reg) 0u32,
            acc = in(reg) acc,
            options(pure, nomem, nostack, preserves_flags),
        );
    }
    s
}

/// `acc` plus the sum of the four lanes of `x` (wrapping; callers keep it below 2^32).
/// The two 16-bit lane pairs `x₀ + x₁`, `x₂ + x₃` (≤ 510) are added by the multiplication
/// into the top half.
#[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
#[inline(always)]
pub(crate) fn add_lane_sum(acc: u32, x: u32) -> u32 {
    let pairs = (x & EVEN) + ((x >> 8) & EVEN);
    acc.wrapping_add(pairs.wrapping_mul(0x0001_0001) >> 16)
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

/// The test "some lane of the word is greater than level `m`" for a fixed `m ≤ 255`, its
/// constant precomputed (for loops that test every word of a frame against one level).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ByteGreater {
    #[cfg(all(feature = "cortex-m7", target_arch = "arm"))]
    level: u32,
    #[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
    add: u32,
    #[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
    high: bool,
}

impl ByteGreater {
    /// The test against level `m` (at 255 or above it never fires: nothing is greater).
    #[inline(always)]
    pub(crate) fn new(m: u32) -> Self {
        let m = m.min(255);
        #[cfg(all(feature = "cortex-m7", target_arch = "arm"))]
        {
            ByteGreater { level: m * ONES }
        }
        #[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
        {
            // At 255 the constant is 0 and `t & x & HIGH` never fires (t ≤ 127 per lane).
            ByteGreater {
                add: (127 - (m & 127)) * ONES,
                high: m >= 128,
            }
        }
    }

    /// Non-zero iff some byte lane of `x` is greater than the level.
    ///
    /// Portable form: the low 7 bits of each lane plus `127 − (m mod 128)` reach bit 7 iff
    /// `x_lo > m mod 128` (never carrying into the next lane: at most 127 + 127); for
    /// `m < 128` a lane with bit 7 set is greater anyway, for `m ≥ 128` it must also have
    /// bit 7 set.
    #[inline(always)]
    pub(crate) fn test(self, x: u32) -> u32 {
        #[cfg(all(feature = "cortex-m7", target_arch = "arm"))]
        {
            sub_sat(x, self.level)
        }
        #[cfg(not(all(feature = "cortex-m7", target_arch = "arm")))]
        {
            let t = (x & LOW7) + self.add;
            if self.high {
                t & x & HIGH
            } else {
                (t | x) & HIGH
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn word_ops_match_per_lane_arithmetic() {
        // Exhaustive over one lane pair in every position, with the other lanes fixed.
        for a in 0..=255u32 {
            for b in 0..=255u32 {
                for lane in 0..4 {
                    let fill_a = 0x9C5A_37E1 & !(0xFF << (8 * lane));
                    let fill_b = 0x21B4_7F9C & !(0xFF << (8 * lane));
                    let wa = fill_a | a << (8 * lane);
                    let wb = fill_b | b << (8 * lane);
                    let d = sub_sat(wa, wb);
                    let mut sum = 0;
                    for k in 0..4 {
                        let (x, y) = ((wa >> (8 * k)) & 0xFF, (wb >> (8 * k)) & 0xFF);
                        assert_eq!((d >> (8 * k)) & 0xFF, x.saturating_sub(y));
                        sum += x;
                    }
                    assert_eq!(add_lane_sum(7, wa), 7 + sum);
                }
                let w = a * ONES;
                assert_eq!(ByteGreater::new(b).test(w) != 0, a > b, "{a} > {b}");
                let w = a << 16 | 0x0300_0003;
                let expect = a > b || 3 > b;
                assert_eq!(ByteGreater::new(b).test(w) != 0, expect, "{a} {b}");
            }
        }
        assert_eq!(ByteGreater::new(300).test(u32::MAX), 0);
    }
}
