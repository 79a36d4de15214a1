//! Histogram, automatic thresholds (Otsu) and multi-level thresholds (thesis §5.3.2–5.3.3;
//! derivations in `docs/image-processing.md`, section "Histogram and thresholds").
//!
//! **Threshold convention (everywhere in Tangent):** a threshold `t` splits the grey levels into
//! `[0, t]` (background) and `[t + 1, max]` (foreground): a pixel is foreground iff
//! `value > t`. Multi-level thresholds `t0 < t1 < …` split the levels into classes
//! `[0, t0]`, `[t0 + 1, t1]`, …; the class index of a pixel is the number of thresholds it
//! exceeds.
//!
//! **Mask convention:** [`threshold_mask`] writes `0` for background and [`MASK_FOREGROUND`]
//! (`1`) for foreground, so that a mask can be fed back to [`crate::image::segment`] with a
//! threshold of `0`, summed to count pixels, or used as a weight. Multiply by 255 for display.

use core::fmt;

use super::{Frame, FrameError, Pixel};
use crate::real::Real;

/// Value written by [`threshold_mask`] for a foreground pixel (background is `0`).
pub const MASK_FOREGROUND: u8 = 1;

/// Why a histogram or a threshold cannot be computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ThresholdError {
    /// A frame argument is malformed or two frames differ in size.
    Frame(FrameError),
    /// The histogram buffer has fewer bins than the frame has grey levels (`2^bit_depth`).
    HistogramTooSmall {
        /// Bins needed (`2^bit_depth`).
        needed: usize,
        /// Bins given.
        actual: usize,
    },
    /// The frame has more pixels than a `u32` bin can count.
    TooManyPixels,
    /// The histogram has fewer distinct non-empty grey levels than the method needs (a flat or
    /// dark image cannot be split into classes).
    NotEnoughLevels {
        /// Non-empty grey levels in the histogram.
        present: usize,
        /// Non-empty grey levels the method needs (classes).
        needed: usize,
    },
    /// Multi-level thresholds must be strictly increasing and at most 255 of them.
    BadThresholds,
}

impl From<FrameError> for ThresholdError {
    fn from(e: FrameError) -> Self {
        ThresholdError::Frame(e)
    }
}

impl fmt::Display for ThresholdError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ThresholdError::Frame(e) => write!(f, "{e}"),
            ThresholdError::HistogramTooSmall { needed, actual } => {
                write!(f, "histogram has {actual} bins, {needed} needed")
            }
            ThresholdError::TooManyPixels => write!(f, "frame has more than 2^32 - 1 pixels"),
            ThresholdError::NotEnoughLevels { present, needed } => write!(
                f,
                "histogram has {present} non-empty grey levels, {needed} needed to threshold"
            ),
            ThresholdError::BadThresholds => {
                write!(f, "thresholds must be strictly increasing, at most 255")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ThresholdError {}

fn pixel_count<P: Pixel, S>(frame: &Frame<P, S>) -> Result<u32, ThresholdError> {
    frame
        .width()
        .checked_mul(frame.height())
        .and_then(|n| u32::try_from(n).ok())
        .ok_or(ThresholdError::TooManyPixels)
}

/// Number of histogram bins a frame needs: `2^bit_depth` (256 for 8-bit, 1024 for 10-bit).
pub fn histogram_len<P: Pixel, S>(frame: &Frame<P, S>) -> usize {
    frame.max_value() as usize + 1
}

/// Counts the pixels of each grey level into `bins` (cleared first) and returns the number of
/// pixels counted (`width × height`).
///
/// `bins` needs at least [`histogram_len`] entries; extra entries are cleared and stay zero.
/// Values above the frame's declared saturation level (bad data: a 10-bit frame holding 1100)
/// are counted in the top bin `2^bit_depth - 1`, i.e. treated as saturated.
pub fn histogram<P: Pixel>(
    frame: &Frame<P, impl AsRef<[P]>>,
    bins: &mut [u32],
) -> Result<u32, ThresholdError> {
    let levels = histogram_len(frame);
    if bins.len() < levels {
        return Err(ThresholdError::HistogramTooSmall {
            needed: levels,
            actual: bins.len(),
        });
    }
    let total = pixel_count(frame)?;
    bins.fill(0);
    let top = levels - 1;
    // Re-slice to exactly `levels` so that the clamped index below provably stays in bounds
    // (the compiler elides the check: idx <= top < len).
    let bins = &mut bins[..levels];
    for y in 0..frame.height() {
        for &p in frame.row(y) {
            let v: u32 = p.into();
            let idx = (v as usize).min(top);
            if let Some(b) = bins.get_mut(idx) {
                *b += 1;
            }
        }
    }
    Ok(total)
}

/// Index of the first non-empty bin strictly after `from`, if any.
fn next_nonempty(hist: &[u32], from: usize) -> Option<usize> {
    let start = from.checked_add(1)?;
    hist.get(start..)?
        .iter()
        .position(|&c| c > 0)
        .map(|i| start + i)
}

/// The threshold placed in the middle of the empty gap `[a, b - 1]` between the last level `a`
/// of a class and the first non-empty level `b` of the next one. Every threshold in that gap
/// gives the same partition (the same criterion value); the middle is the most robust choice
/// against noise that slightly widens either mode.
fn gap_middle(a: usize, b: usize) -> u32 {
    let t = a + (b.saturating_sub(1).saturating_sub(a)) / 2;
    t as u32
}

/// Otsu's automatic threshold: the `t` maximising the between-class variance
/// `σ_B²(t) = (N·S₀(t) − S·n₀(t))² / (N² · n₀(t) · n₁(t))` of the two classes `[0, t]` and
/// `[t + 1, …]` (derivation: docs/image-processing.md, "Otsu's threshold").
///
/// `hist[k]` is the number of pixels of grey level `k` (from [`histogram`]). Ties between
/// thresholds that give the same partition (empty bins between the modes) are resolved to the
/// middle of the gap; ties between distinct partitions to the lowest threshold.
/// The criterion is evaluated exactly in integers (`i128`) up to the final ratio, which is in
/// `f64` whatever [`crate::real::Real`] is: the criterion is a ratio of integers of up to ~2^80
/// and `f32`'s 24-bit mantissa would pick arbitrarily among near-equal candidates. The cost is
/// one division per non-empty level, not per pixel (the M7 has a double-precision FPU).
///
/// Errors: [`ThresholdError::NotEnoughLevels`] if fewer than 2 levels are non-empty.
pub fn otsu_threshold(hist: &[u32]) -> Result<u32, ThresholdError> {
    let (n_total, s_total, present) = totals(hist);
    if present < 2 {
        return Err(ThresholdError::NotEnoughLevels { present, needed: 2 });
    }
    let n = n_total as i128;
    let s = s_total as i128;
    // Every product and count below `N·S`: where that is below 2^53 (any frame of the
    // device) they are exact in `i64` and convert exactly with `exact_f64`, the same `f64`s
    // as the `i128` path's library conversions, which cost ~170 instructions a level on
    // the device (`docs/performance.md`, issue 17).
    let small = n_total.checked_mul(s_total).is_some_and(|p| p < EXACT_F64);
    let mut n0: u64 = 0;
    let mut s0: u64 = 0;
    let mut best: Option<(f64, usize)> = None;
    for (k, &c) in hist.iter().enumerate() {
        if c == 0 {
            continue;
        }
        n0 += c as u64;
        s0 += c as u64 * k as u64;
        let n1 = n_total - n0;
        if n1 == 0 {
            break; // `k` is the last non-empty level: no class above it.
        }
        let (num, n0f, n1f) = if small {
            let num = n_total as i64 * s0 as i64 - s_total as i64 * n0 as i64;
            (exact_f64(num), exact_f64(n0 as i64), exact_f64(n1 as i64))
        } else {
            (
                (n * s0 as i128 - s * n0 as i128) as f64,
                n0 as f64,
                n1 as f64,
            )
        };
        let crit = num * num / (n0f * n1f);
        if best.is_none_or(|(b, _)| crit > b) {
            best = Some((crit, k));
        }
    }
    let a = best.map(|(_, k)| k).unwrap_or(0);
    let b = next_nonempty(hist, a).unwrap_or(a + 1);
    Ok(gap_middle(a, b))
}

/// 2^53: integers of smaller magnitude are exact in `f64`.
const EXACT_F64: u64 = 1 << 53;

/// `v as f64` for `|v| < 2^53` (exact): two 32-bit halves, each converted by one FPU
/// instruction; the scaled high half and the sum are exact too.
#[inline]
fn exact_f64(v: i64) -> f64 {
    ((v >> 32) as i32 as f64) * 4_294_967_296.0 + (v as u32 as f64)
}

/// Total count, total grey-level sum and number of non-empty levels of a histogram.
fn totals(hist: &[u32]) -> (u64, u64, usize) {
    let mut n = 0u64;
    let mut s = 0u64;
    let mut present = 0usize;
    for (k, &c) in hist.iter().enumerate() {
        n += c as u64;
        s += c as u64 * k as u64;
        present += (c > 0) as usize;
    }
    (n, s, present)
}

/// Two-threshold (three-class) Otsu, thesis §5.3.3: the pair `t0 < t1` maximising the
/// between-class variance of `[0, t0]`, `[t0 + 1, t1]`, `[t1 + 1, …]`, which is equivalent to
/// maximising `Σ_k S_k² / n_k` over the three classes (docs/image-processing.md,
/// "Multi-level thresholds").
///
/// Used when the difference image has three modes (background, ambient change or laser seen
/// through foliage, and the laser curve itself): the laser is the top class, `value > t1`.
/// Exhaustive over pairs of non-empty levels: `O(K·L)` for `K` non-empty levels out of `L`
/// (at most 256·256 steps for 8-bit data). Same tie rules and `f64` reasoning as
/// [`otsu_threshold`].
///
/// Errors: [`ThresholdError::NotEnoughLevels`] if fewer than 3 levels are non-empty.
pub fn otsu_two_thresholds(hist: &[u32]) -> Result<[u32; 2], ThresholdError> {
    let (n_total, s_total, present) = totals(hist);
    if present < 3 {
        return Err(ThresholdError::NotEnoughLevels { present, needed: 3 });
    }
    let mut n0: u64 = 0;
    let mut s0: u64 = 0;
    let mut best: Option<(f64, usize, usize)> = None;
    for (a, &ca) in hist.iter().enumerate() {
        if ca == 0 {
            continue;
        }
        n0 += ca as u64;
        s0 += ca as u64 * a as u64;
        if n_total - n0 == 0 {
            break;
        }
        let c0 = (s0 as f64) * (s0 as f64) / n0 as f64;
        let mut n1: u64 = 0;
        let mut s1: u64 = 0;
        let rest = hist.get(a + 1..).unwrap_or(&[]);
        for (i, &cb) in rest.iter().enumerate() {
            if cb == 0 {
                continue;
            }
            n1 += cb as u64;
            let b = a + 1 + i;
            s1 += cb as u64 * b as u64;
            let n2 = n_total - n0 - n1;
            if n2 == 0 {
                break;
            }
            let s2 = s_total - s0 - s1;
            let crit =
                c0 + (s1 as f64) * (s1 as f64) / n1 as f64 + (s2 as f64) * (s2 as f64) / n2 as f64;
            if best.is_none_or(|(v, _, _)| crit > v) {
                best = Some((crit, a, b));
            }
        }
    }
    let (a, b) = best.map(|(_, a, b)| (a, b)).unwrap_or((0, 1));
    let a_next = next_nonempty(hist, a).unwrap_or(a + 1);
    let b_next = next_nonempty(hist, b).unwrap_or(b + 1);
    Ok([gap_middle(a, a_next), gap_middle(b, b_next)])
}

/// How the pipeline chooses the threshold of the difference image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ThresholdMethod {
    /// A fixed threshold (grey levels; foreground is `value > t`).
    Fixed(u32),
    /// Otsu's two-class threshold ([`otsu_threshold`]).
    Otsu,
    /// The upper threshold of three-class Otsu ([`otsu_two_thresholds`]): keeps only the
    /// brightest mode (the laser) when a middle mode of ambient change is present.
    OtsuUpperOfThree,
}

impl ThresholdMethod {
    /// The threshold this method gives for histogram `hist`.
    pub fn threshold(&self, hist: &[u32]) -> Result<u32, ThresholdError> {
        match *self {
            ThresholdMethod::Fixed(t) => Ok(t),
            ThresholdMethod::Otsu => otsu_threshold(hist),
            ThresholdMethod::OtsuUpperOfThree => otsu_two_thresholds(hist).map(|[_, t1]| t1),
        }
    }
}

/// Noise σ (grey levels) of a difference image `max(on − off, 0)`, from its histogram.
///
/// With `on − off = X ~ N(0, σ²)` off the stripe, the clamped difference has
/// `E[max(X, 0)] = σ/√(2π)`, so `σ̂ = √(2π)·mean`. The mean is taken over all pixels: the
/// stripe's few hundred pixels inflate it slightly, which only makes the tests that use `σ̂`
/// more conservative. Sensor noise, shot noise on bright ambient and the structure left by
/// hand motion all count as noise here, as they should. Returns 0 for an empty histogram.
pub fn difference_noise(histogram: &[u32]) -> Real {
    let (mut n, mut sum) = (0u64, 0u64);
    for (level, &count) in histogram.iter().enumerate() {
        n += count as u64;
        sum += count as u64 * level as u64;
    }
    if n == 0 {
        return 0.0;
    }
    let two_pi: Real = 2.0 * crate::real::PI;
    crate::real::sqrt(two_pi) * (sum as Real / n as Real)
}

/// The floors that keep sensor noise out of a difference image's darkness test and threshold
/// (`docs/pipeline.md`, "Contrast and threshold"). `noise` below is the image's σ̂
/// ([`difference_noise`]). [`Default`] suits the reference hardware.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Floors {
    /// Lowest threshold the automatic methods may return (grey levels of the difference
    /// image). Keeps sensor noise out of the segmentation when the laser is weak.
    pub min_threshold: u32,
    /// Fraction of the brightest difference below which a pixel never counts as laser: the
    /// threshold is at least `relative_threshold × max_difference`.
    pub relative_threshold: Real,
    /// Noise-relative floor of the threshold: `threshold_snr × σ̂` (a Gaussian pixel exceeds
    /// 5 σ with probability 3·10⁻⁷, i.e. < 1 false pixel per frame), so that dim stripe ends
    /// are segmented as far as the noise allows.
    pub threshold_snr: Real,
    /// Absolute floor of the darkness test: the brightest difference must reach at least this
    /// many grey levels, or the pair is "dark" (the laser did not reach anything in range).
    pub min_contrast: u32,
    /// Noise-relative darkness test: the brightest difference must also reach
    /// `contrast_snr × σ̂`. The max of `N` ≈ 3.6·10⁵ noise pixels is ≈ 4.5 σ, so 8 σ is never
    /// reached by noise alone while a stripe 10 grey levels high over σ ≈ 0.8 passes.
    pub contrast_snr: Real,
}

impl Default for Floors {
    fn default() -> Self {
        Floors {
            min_threshold: 6,
            relative_threshold: 0.08,
            // Off by default: σ̂ includes the stripe's own pixels, so on bright stripes it
            // would raise the threshold and cut the stripe ends (measured: worse fits).
            threshold_snr: 0.0,
            // Kept at 20 DN: stripes peaking at 9–19 DN (far, dark bark) are well above the
            // noise (σ̂ ≈ 0.7–1.2 DN) but their fits err by 10–50 mm (measured on the
            // evaluation's development seeds); the noise-relative test still applies.
            min_contrast: 20,
            contrast_snr: 8.0,
        }
    }
}

impl Floors {
    /// Whether a brightest difference of `max_difference` over noise `noise` is laser light:
    /// at least `min_contrast` and `contrast_snr × noise`.
    pub fn is_lit(&self, max_difference: u32, noise: Real) -> bool {
        let floor = (self.min_contrast as Real).max(self.contrast_snr * noise);
        // `floor` is finite: `difference_noise` of a histogram always is.
        max_difference as Real >= floor
    }

    /// The threshold applied: `automatic` raised to `min_threshold`,
    /// `relative_threshold × max_difference` and `threshold_snr × noise`.
    pub fn apply(&self, automatic: u32, max_difference: u32, noise: Real) -> u32 {
        let relative = (self.relative_threshold * max_difference as Real) as u32;
        let noise_floor: Real = <Real as crate::real::Float>::ceil(self.threshold_snr * noise);
        let noise_floor = if noise_floor.is_finite() && noise_floor > 0.0 {
            noise_floor as u32
        } else {
            0
        };
        automatic
            .max(self.min_threshold)
            .max(relative)
            .max(noise_floor)
    }
}

/// Writes the binary mask of `frame`: [`MASK_FOREGROUND`] where `value > threshold`, `0`
/// elsewhere. Returns the number of foreground pixels. `mask` must have the frame's size.
pub fn threshold_mask<P: Pixel>(
    frame: &Frame<P, impl AsRef<[P]>>,
    threshold: u32,
    mask: &mut Frame<u8, impl AsMut<[u8]>>,
) -> Result<u32, ThresholdError> {
    frame.check_same_size(mask)?;
    pixel_count(frame)?;
    let mut count = 0u32;
    for y in 0..frame.height() {
        let mut row_count = 0u32;
        for (m, &p) in mask.row_mut(y).iter_mut().zip(frame.row(y)) {
            let v: u32 = p.into();
            let fg = (v > threshold) as u8;
            *m = fg;
            row_count += fg as u32;
        }
        count += row_count;
    }
    Ok(count)
}

/// Multi-level classification: writes for each pixel the number of `thresholds` its value
/// exceeds (class `0..=thresholds.len()`). `thresholds` must be strictly increasing and at most
/// 255 long ([`ThresholdError::BadThresholds`]). With one threshold this is
/// [`threshold_mask`].
pub fn classify<P: Pixel>(
    frame: &Frame<P, impl AsRef<[P]>>,
    thresholds: &[u32],
    out: &mut Frame<u8, impl AsMut<[u8]>>,
) -> Result<(), ThresholdError> {
    frame.check_same_size(out)?;
    if thresholds.len() > 255 || thresholds.windows(2).any(|w| w[0] >= w[1]) {
        return Err(ThresholdError::BadThresholds);
    }
    for y in 0..frame.height() {
        for (o, &p) in out.row_mut(y).iter_mut().zip(frame.row(y)) {
            let v: u32 = p.into();
            // Thresholds are sorted: the class is the count of those below the value.
            *o = thresholds.iter().take_while(|&&t| v > t).count() as u8;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// `difference_noise` recovers σ of Gaussian noise from the clamped difference's histogram
    /// (E[max(X,0)] = σ/√(2π)); 1-DN rounding adds ≈ 1/12 DN² of variance, so the tolerance
    /// is 5 % at σ = 3 DN.
    /// The split conversion is the exact one below 2^53, either sign.
    #[test]
    fn exact_f64_is_the_conversion() {
        let big = (EXACT_F64 - 1) as i64;
        for v in [
            0i64,
            1,
            -1,
            12345,
            -98765,
            1 << 32,
            -(1 << 32),
            (1 << 40) + 3,
            big,
            -big,
        ] {
            assert_eq!(exact_f64(v).to_bits(), (v as f64).to_bits(), "{v}");
        }
    }

    #[test]
    fn difference_noise_recovers_gaussian_sigma() {
        let mut hist = std::vec![0u32; 256];
        let mut rng = crate::solvers::circle::tests::Rng::new(7);
        let sigma: f64 = 3.0;
        for _ in 0..200_000 {
            let x = (sigma * rng.gauss()).round().max(0.0) as usize;
            hist[x.min(255)] += 1;
        }
        let est = difference_noise(&hist);
        assert!((est as f64 / sigma - 1.0).abs() < 0.05, "σ̂ = {est}");
        assert_eq!(difference_noise(&[0; 4]), 0.0);
    }

    /// The threshold is the largest of the automatic one and the three floors.
    #[test]
    fn floors_raise_the_threshold() {
        let floors = Floors {
            min_threshold: 6,
            relative_threshold: 0.1,
            threshold_snr: 5.0,
            min_contrast: 20,
            contrast_snr: 8.0,
        };
        assert_eq!(floors.apply(3, 40, 0.0), 6);
        assert_eq!(floors.apply(3, 200, 0.0), 20);
        assert_eq!(floors.apply(3, 40, 2.1), 11);
        assert_eq!(floors.apply(30, 200, 2.1), 30);
        assert!(floors.is_lit(20, 2.0));
        assert!(!floors.is_lit(19, 0.0));
        assert!(!floors.is_lit(30, 4.0));
    }

    /// Between-class variance of the partition `[0, t]` / `[t+1, ..]`, computed from first
    /// principles (class weights and means by direct summation), independently of the
    /// cumulative formula used by `otsu_threshold`.
    fn brute_between_variance(h: &[u32], t: usize) -> Option<f64> {
        let total: f64 = h.iter().map(|&c| c as f64).sum();
        let (mut w0, mut m0, mut w1, mut m1) = (0.0, 0.0, 0.0, 0.0);
        for (k, &c) in h.iter().enumerate() {
            if k <= t {
                w0 += c as f64;
                m0 += c as f64 * k as f64;
            } else {
                w1 += c as f64;
                m1 += c as f64 * k as f64;
            }
        }
        if w0 == 0.0 || w1 == 0.0 {
            return None;
        }
        m0 /= w0;
        m1 /= w1;
        Some((w0 / total) * (w1 / total) * (m0 - m1) * (m0 - m1))
    }

    /// Sampled Gaussian mode of `weight` pixels around `mean` with spread `sigma`.
    fn add_mode(h: &mut [u32], mean: f64, sigma: f64, weight: f64) {
        for (k, c) in h.iter_mut().enumerate() {
            let z = (k as f64 - mean) / sigma;
            *c += (weight * (-0.5 * z * z).exp()).round() as u32;
        }
    }

    #[test]
    fn histogram_counts_and_buffer_checks() {
        let px: [u16; 6] = [0, 3, 3, 1023, 1500, 7];
        let f = Frame::new(&px, 3, 2, 3)
            .unwrap()
            .with_bit_depth(10)
            .unwrap();
        let mut small = [0u32; 1023];
        assert_eq!(
            histogram(&f, &mut small).unwrap_err(),
            ThresholdError::HistogramTooSmall {
                needed: 1024,
                actual: 1023
            }
        );
        let mut bins = [9u32; 1030];
        assert_eq!(histogram(&f, &mut bins).unwrap(), 6);
        assert_eq!((bins[0], bins[3], bins[7]), (1, 2, 1));
        // 1023 and the out-of-range 1500 both land in the saturation bin.
        assert_eq!(bins[1023], 2);
        assert_eq!(bins.iter().sum::<u32>(), 6);
    }

    #[test]
    fn otsu_bimodal_matches_brute_force() {
        // Dense bimodal histogram (no empty gap): dark mode at 40 (3x the pixels), bright at 180.
        // A floor of one pixel per level keeps every bin non-empty, so every threshold gives a
        // distinct partition and the maximum is unique (gaps are tested separately below).
        let mut h = [1u32; 256];
        add_mode(&mut h, 40.0, 12.0, 3000.0);
        add_mode(&mut h, 180.0, 15.0, 1000.0);
        let t = otsu_threshold(&h).unwrap() as usize;
        let best = (0..255)
            .filter_map(|k| brute_between_variance(&h, k).map(|v| (v, k)))
            .fold((f64::MIN, 0), |a, b| if b.0 > a.0 { b } else { a });
        assert_eq!(t, best.1);
        assert!(t > 40 && t < 180, "t = {t} must lie between the modes");
    }

    #[test]
    fn otsu_puts_threshold_in_middle_of_empty_gap() {
        // Modes occupy 10..=20 and 200..=210: every t in 20..=199 gives the same partition and the
        // same (maximal) variance; the middle of the gap is (20 + 199) / 2 = 109.
        let mut h = [0u32; 256];
        h[10..=20].fill(50);
        h[200..=210].fill(5);
        let v20 = brute_between_variance(&h, 20).unwrap();
        let v199 = brute_between_variance(&h, 199).unwrap();
        assert_eq!(v20, v199);
        for k in 0..255 {
            if let Some(v) = brute_between_variance(&h, k) {
                assert!(v <= v20);
            }
        }
        assert_eq!(otsu_threshold(&h).unwrap(), 109);
    }

    #[test]
    fn two_thresholds_on_trimodal_match_brute_force() {
        let mut h = [1u32; 256]; // noise floor: no empty bins, see the bimodal test
        add_mode(&mut h, 30.0, 8.0, 2000.0);
        add_mode(&mut h, 110.0, 10.0, 800.0);
        add_mode(&mut h, 210.0, 9.0, 300.0);
        let [t0, t1] = otsu_two_thresholds(&h).unwrap();
        // Brute force: between-class variance of three classes from direct sums.
        let total: f64 = h.iter().map(|&c| c as f64).sum();
        let mean: f64 = h
            .iter()
            .enumerate()
            .map(|(k, &c)| k as f64 * c as f64)
            .sum::<f64>()
            / total;
        let class = |lo: usize, hi: usize| {
            let w: f64 = h[lo..=hi].iter().map(|&c| c as f64).sum();
            let s: f64 = (lo..=hi).map(|k| k as f64 * h[k] as f64).sum();
            (w, if w > 0.0 { s / w } else { 0.0 })
        };
        let mut best = (f64::MIN, 0, 0);
        for a in 0..254 {
            for b in a + 1..255 {
                let parts = [class(0, a), class(a + 1, b), class(b + 1, 255)];
                if parts.iter().any(|p| p.0 == 0.0) {
                    continue;
                }
                let v: f64 = parts
                    .iter()
                    .map(|(w, m)| w / total * (m - mean) * (m - mean))
                    .sum();
                if v > best.0 {
                    best = (v, a, b);
                }
            }
        }
        assert_eq!((t0 as usize, t1 as usize), (best.1, best.2));
        assert!(30 < t0 && t0 < 110 && 110 < t1 && t1 < 210, "{t0} {t1}");
        assert_eq!(ThresholdMethod::OtsuUpperOfThree.threshold(&h).unwrap(), t1);
    }

    #[test]
    fn too_few_levels_is_an_error() {
        let mut h = [0u32; 16];
        h[4] = 100;
        assert_eq!(
            otsu_threshold(&h).unwrap_err(),
            ThresholdError::NotEnoughLevels {
                present: 1,
                needed: 2
            }
        );
        h[9] = 3;
        assert_eq!(otsu_threshold(&h).unwrap(), 6); // gap [4, 8], middle 6
        assert_eq!(
            otsu_two_thresholds(&h).unwrap_err(),
            ThresholdError::NotEnoughLevels {
                present: 2,
                needed: 3
            }
        );
        h[12] = 1;
        // Only one three-class partition exists: {4}, {9}, {12}; gaps [4,8] and [9,11].
        assert_eq!(otsu_two_thresholds(&h).unwrap(), [6, 10]);
    }

    #[test]
    fn mask_and_classes() {
        let px: [u8; 6] = [0, 10, 11, 200, 50, 10];
        let f = Frame::new(&px, 3, 2, 3).unwrap();
        let mut m = [7u8; 6];
        let mut fm = Frame::new(&mut m, 3, 2, 3).unwrap();
        assert_eq!(threshold_mask(&f, 10, &mut fm).unwrap(), 3);
        assert_eq!(m, [0, 0, 1, 1, 1, 0]);
        let mut fm = Frame::new(&mut m, 3, 2, 3).unwrap();
        classify(&f, &[10, 60], &mut fm).unwrap();
        assert_eq!(m, [0, 0, 1, 2, 1, 0]);
        let mut fm = Frame::new(&mut m, 3, 2, 3).unwrap();
        assert_eq!(
            classify(&f, &[60, 10], &mut fm).unwrap_err(),
            ThresholdError::BadThresholds
        );
        let mut fm = Frame::new(&mut m, 2, 3, 2).unwrap();
        assert!(matches!(
            threshold_mask(&f, 10, &mut fm).unwrap_err(),
            ThresholdError::Frame(FrameError::SizeMismatch { .. })
        ));
    }
}
