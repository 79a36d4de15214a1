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

#[cfg(test)]
mod tests {
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
