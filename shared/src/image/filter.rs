//! Speckle filter: low-pass Gaussian 2-D FIR filter (thesis §5.7.2; derivation, frequency
//! response and error bounds in `docs/image-processing.md`, section "Speckle filter").
//!
//! The laser light scattered by bark is coherent, so the curve is modulated by speckle: a
//! random granular pattern of grain size ≈ the optical resolution. Speckle shifts the
//! subpixel centre of each column at random; a Gaussian low-pass filter averages the grains
//! over a neighbourhood of ≈ σ pixels before the curve is located.
//!
//! The 2-D Gaussian is separable, `g(x, y) = g(x)·g(y)`, so the 2-D convolution is a vertical
//! 1-D pass followed by a horizontal one: `2(2r + 1)` multiplications per pixel instead of
//! `(2r + 1)²` (and `2(r + 1)` using the kernel's symmetry, as done here). Weights are integers
//! in Q15 (`Σ = 2^15` exactly), so the filter has a DC gain of exactly 1, integer arithmetic
//! per pixel (`u32` only), and a rounding error below 0.75 grey level. Borders are handled by
//! clamping (the edge pixel is repeated), which also preserves constants exactly.

use core::fmt;

use super::{Frame, FrameError, Pixel};
// `Float` supplies ceil/exp/round in no_std builds; with `std` the inherent methods win.
#[cfg_attr(feature = "std", allow(unused_imports))]
use crate::real::{Float, Real};

/// Largest kernel radius supported (taps = `2·radius + 1` ≤ 33; σ up to 5 px with the
/// default 3σ truncation).
pub const MAX_RADIUS: usize = 16;

/// Fixed-point precision of the weights: `Σ weights = 2^WEIGHT_BITS`.
pub const WEIGHT_BITS: u32 = 15;

const ONE: u32 = 1 << WEIGHT_BITS;

/// Why a kernel cannot be built or a frame filtered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FilterError {
    /// Input and output frames differ in size (or are malformed).
    Frame(FrameError),
    /// σ is not a finite positive number.
    BadSigma(Real),
    /// The requested radius is 0 or exceeds [`MAX_RADIUS`].
    BadRadius {
        /// Radius requested.
        radius: usize,
    },
    /// The scratch buffer holds fewer than `width` entries (see [`scratch_len`]).
    ScratchTooSmall {
        /// Entries needed.
        needed: usize,
        /// Entries given.
        actual: usize,
    },
}

impl From<FrameError> for FilterError {
    fn from(e: FrameError) -> Self {
        FilterError::Frame(e)
    }
}

impl fmt::Display for FilterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FilterError::Frame(e) => write!(f, "{e}"),
            FilterError::BadSigma(s) => write!(f, "Gaussian sigma {s} is not finite and positive"),
            FilterError::BadRadius { radius } => {
                write!(f, "kernel radius {radius} is not in 1..={MAX_RADIUS}")
            }
            FilterError::ScratchTooSmall { needed, actual } => {
                write!(f, "filter scratch holds {actual} entries, {needed} needed")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for FilterError {}

/// A symmetric, truncated, normalised sampled Gaussian kernel in Q15 fixed point.
///
/// `weight(k) ≈ 2^15 · exp(−k²/2σ²) / Σ_{|m|≤r} exp(−m²/2σ²)` for `|k| ≤ r`, rounded so that
/// the weights sum to exactly `2^15`; every weight is within 1.5 units (`1.5·2^-15`) of the
/// exact normalised value (docs/image-processing.md, "Kernel quantisation").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussianKernel {
    sigma: Real,
    radius: usize,
    /// `weights[k]` is the weight of offsets `±k` (`weights[0]` the centre).
    weights: [u32; MAX_RADIUS + 1],
}

impl GaussianKernel {
    /// Kernel of standard deviation `sigma` (pixels) truncated at `radius = ⌈3σ⌉` (at least 1):
    /// the discarded tails hold 0.27 % of the Gaussian's mass, which the normalisation gives
    /// back to the kept taps.
    pub fn new(sigma: Real) -> Result<Self, FilterError> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(FilterError::BadSigma(sigma));
        }
        let r = (3.0 * sigma).ceil();
        if r > MAX_RADIUS as Real {
            return Err(FilterError::BadRadius { radius: r as usize });
        }
        Self::with_radius(sigma, (r as usize).max(1))
    }

    /// Kernel of standard deviation `sigma` truncated at an explicit `radius` (1..=[`MAX_RADIUS`]).
    pub fn with_radius(sigma: Real, radius: usize) -> Result<Self, FilterError> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(FilterError::BadSigma(sigma));
        }
        if radius == 0 || radius > MAX_RADIUS {
            return Err(FilterError::BadRadius { radius });
        }
        // Unnormalised samples and their sum over -r..=r.
        let mut w = [0.0 as Real; MAX_RADIUS + 1];
        let mut total: Real = 0.0;
        for (k, wk) in w.iter_mut().enumerate().take(radius + 1) {
            let x = k as Real / sigma;
            *wk = (-0.5 * x * x).exp();
            total += if k == 0 { *wk } else { 2.0 * *wk };
        }
        // Exact fixed-point targets, their roundings, and the residual to reach exactly 2^15.
        let scale = ONE as Real / total;
        let mut target = [0.0 as Real; MAX_RADIUS + 1];
        let mut q = [0i64; MAX_RADIUS + 1];
        let mut sum: i64 = 0;
        for k in 0..=radius {
            target[k] = w[k] * scale;
            q[k] = target[k].round() as i64;
            sum += if k == 0 { q[k] } else { 2 * q[k] };
        }
        let mut residual = ONE as i64 - sum;
        // Each side pair moves the sum by 2: give pairs to the side taps whose rounding erred
        // most in the needed direction (largest-remainder method); the centre takes what is
        // left (|residual| <= 1). At most `radius` iterations (|residual| <= radius + 1/2).
        for _ in 0..radius {
            if residual.abs() < 2 {
                break;
            }
            let dir: i64 = residual.signum();
            let mut best = 0usize;
            let mut best_err = Real::NEG_INFINITY;
            for k in 1..=radius {
                let err = (target[k] - q[k] as Real) * dir as Real;
                if err > best_err {
                    best_err = err;
                    best = k;
                }
            }
            if best == 0 {
                break;
            }
            q[best] += dir;
            residual -= 2 * dir;
        }
        q[0] += residual;
        let mut weights = [0u32; MAX_RADIUS + 1];
        for k in 0..=radius {
            // Weights are non-negative by construction (targets >= 0, corrections of at most
            // one unit go to taps whose target exceeds their rounding); clamp for safety.
            weights[k] = q[k].clamp(0, ONE as i64) as u32;
        }
        Ok(GaussianKernel {
            sigma,
            radius,
            weights,
        })
    }

    /// Standard deviation in pixels.
    pub fn sigma(&self) -> Real {
        self.sigma
    }

    /// Radius `r` (the kernel has `2r + 1` taps).
    pub fn radius(&self) -> usize {
        self.radius
    }

    /// Q15 weight of offset `k` (0 outside `-r..=r`).
    pub fn weight(&self, k: isize) -> u32 {
        let a = k.unsigned_abs();
        if a > self.radius {
            0
        } else {
            self.weights.get(a).copied().unwrap_or(0)
        }
    }

    /// Weight of offset `k` as a fraction (the Q15 weight / 2^15).
    pub fn weight_real(&self, k: isize) -> Real {
        self.weight(k) as Real / ONE as Real
    }

    /// Frequency response of the 1-D kernel at `omega` radians per pixel:
    /// `H(ω) = Σ_k w_k cos(kω) = w_0 + 2 Σ_{k≥1} w_k cos(kω)` (real: the kernel is symmetric,
    /// so the filter has zero phase and does not shift the curve). The 2-D response is
    /// `H(ωx)·H(ωy)`. For σ ≳ 1 it is within ~0.3 % of the continuous Gaussian's
    /// `exp(−σ²ω²/2)` (truncation), half power at `ω = √(ln 2)/σ`.
    pub fn frequency_response(&self, omega: Real) -> Real {
        let mut h = self.weight_real(0);
        for k in 1..=self.radius {
            h += 2.0 * self.weight_real(k as isize) * (k as Real * omega).cos();
        }
        h
    }
}

/// Scratch entries [`gaussian_filter`] needs for a frame `width` pixels wide (one row of
/// `u32`: the vertical pass of one row at full precision).
pub fn scratch_len(width: usize) -> usize {
    width
}

/// Row index `y + d` clamped to `0..height` (border handling: repeat the edge row).
#[inline]
fn clamp_index(y: usize, d: isize, len: usize) -> usize {
    let v = y as isize + d;
    if v < 0 {
        0
    } else if v as usize >= len {
        len - 1
    } else {
        v as usize
    }
}

/// Filters `input` with the separable Gaussian `kernel` into `out` (same size; the bit depth
/// of `out` is not changed: a normalised non-negative kernel never exceeds the input's maximum).
///
/// For each output row: a vertical pass `v(x) = Σ_k w_k · I(x, y + k)` into `scratch`
/// (exact, `< 2^(b+15)` for `b` storage bits), rounded to `v' = ⌊(v + 2^(s−1)) / 2^s⌋` with
/// `s = b − 2` (17 bits), then a horizontal pass `O = ⌊(Σ_k w_k · v'(x + k) + 2^(29−s)) / 2^(30−s)⌋`,
/// all in `u32`. The result is within `0.5 + 0.5·2^(s−15)` grey level of the exact convolution
/// with the Q15 kernel (0.501 for `u8`, 0.75 for `u16`), and constants are reproduced exactly.
/// Pixels outside the frame are the nearest edge pixel.
///
/// `scratch` needs [`scratch_len`]`(width)` entries.
pub fn gaussian_filter<P: Pixel>(
    input: &Frame<P, impl AsRef<[P]>>,
    kernel: &GaussianKernel,
    scratch: &mut [u32],
    out: &mut Frame<P, impl AsMut<[P]>>,
) -> Result<(), FilterError> {
    input.check_same_size(out)?;
    let (width, height) = (input.width(), input.height());
    let needed = scratch_len(width);
    let Some(v) = scratch.get_mut(..needed) else {
        return Err(FilterError::ScratchTooSmall {
            needed,
            actual: scratch.len(),
        });
    };
    let r = kernel.radius;
    let w = &kernel.weights[..=r.min(MAX_RADIUS)];
    let (w0, side) = match w.split_first() {
        Some((&c, s)) => (c, s),
        None => return Ok(()), // unreachable: weights has MAX_RADIUS + 1 >= 1 entries
    };
    // Fixed-point bookkeeping (docs/image-processing.md, "Fixed-point ranges and rounding"):
    // after the vertical pass v < 2^(bits + 15); it is rounded down to 17 bits (`shift` =
    // bits - 2), so that Σ w·v < 2^15·2^17 = 2^32 fits a u32 with its rounding constant.
    let shift = P::STORAGE_BITS as u32 - 2;
    let v_round = 1u32 << (shift - 1);
    let out_shift = 2 * WEIGHT_BITS - shift;
    let out_round = 1u32 << (out_shift - 1);

    for y in 0..height {
        // ---- Vertical pass into v (u32: ≤ 2^15 · 65535 < 2^31). ----
        for (a, &p) in v.iter_mut().zip(input.row(y)) {
            let p: u32 = p.into();
            *a = w0 * p;
        }
        for (k, &wk) in side.iter().enumerate() {
            let d = k as isize + 1;
            let above = input.row(clamp_index(y, -d, height));
            let below = input.row(clamp_index(y, d, height));
            for ((a, &p), &q) in v.iter_mut().zip(above).zip(below) {
                let (p, q): (u32, u32) = (p.into(), q.into());
                *a += wk * (p + q);
            }
        }

        // ---- Rescale v to at most 17 bits, so that the horizontal pass fits u32. ----
        for a in v.iter_mut() {
            *a = (*a + v_round) >> shift;
        }

        // ---- Horizontal pass from v into the output row (u32 accumulators). ----
        let o = out.row_mut(y);
        let v: &[u32] = v;
        let taps = 2 * r + 1;
        if width >= taps {
            // Interior x in r..width-r: a sliding window, no clamping. Small radii get a
            // copy with the tap loop unrolled at compile time.
            match r {
                1 => horizontal_interior::<P, 1>(v, o, &kernel.weights, out_round, out_shift),
                2 => horizontal_interior::<P, 2>(v, o, &kernel.weights, out_round, out_shift),
                3 => horizontal_interior::<P, 3>(v, o, &kernel.weights, out_round, out_shift),
                4 => horizontal_interior::<P, 4>(v, o, &kernel.weights, out_round, out_shift),
                5 => horizontal_interior::<P, 5>(v, o, &kernel.weights, out_round, out_shift),
                6 => horizontal_interior::<P, 6>(v, o, &kernel.weights, out_round, out_shift),
                _ => horizontal_interior_any(v, o, r, &kernel.weights, out_round, out_shift),
            }
            for x in (0..r).chain(width - r..width) {
                if let Some(ox) = o.get_mut(x) {
                    *ox =
                        P::saturate_from((horizontal_at(v, x, w0, side) + out_round) >> out_shift);
                }
            }
        } else {
            for (x, ox) in o.iter_mut().enumerate() {
                *ox = P::saturate_from((horizontal_at(v, x, w0, side) + out_round) >> out_shift);
            }
        }
    }
    Ok(())
}

/// Horizontal convolution at `x` with clamped indices (border pixels and narrow frames).
#[inline]
fn horizontal_at(v: &[u32], x: usize, w0: u32, side: &[u32]) -> u32 {
    let width = v.len();
    let mut acc = w0 * v.get(x).copied().unwrap_or(0);
    for (k, &wk) in side.iter().enumerate() {
        let d = k as isize + 1;
        let a = v.get(clamp_index(x, -d, width)).copied().unwrap_or(0);
        let b = v.get(clamp_index(x, d, width)).copied().unwrap_or(0);
        acc += wk * (a + b);
    }
    acc
}

/// Horizontal convolution of the interior columns `R..width-R` with a compile-time radius:
/// the tap loop unrolls and every index is a constant inside a window of known length.
#[inline]
fn horizontal_interior<P: Pixel, const R: usize>(
    v: &[u32],
    o: &mut [P],
    w: &[u32; MAX_RADIUS + 1],
    round: u32,
    shift: u32,
) {
    for (ox, win) in o.iter_mut().skip(R).zip(v.windows(2 * R + 1)) {
        if win.len() != 2 * R + 1 || R > MAX_RADIUS {
            continue; // never: `windows` yields exactly 2R + 1 values (lets the checks go)
        }
        let mut acc = w[0] * win[R];
        for k in 1..=R {
            acc += w[k] * (win[R - k] + win[R + k]);
        }
        *ox = P::saturate_from((acc + round) >> shift);
    }
}

/// [`horizontal_interior`] for any radius (a run-time tap loop).
fn horizontal_interior_any<P: Pixel>(
    v: &[u32],
    o: &mut [P],
    r: usize,
    w: &[u32; MAX_RADIUS + 1],
    round: u32,
    shift: u32,
) {
    let side = w.get(1..=r).unwrap_or(&[]);
    for (ox, win) in o.iter_mut().skip(r).zip(v.windows(2 * r + 1)) {
        let (left, rest) = win.split_at(r.min(win.len()));
        let Some((&c, right)) = rest.split_first() else {
            continue;
        };
        let mut acc = w[0] * c;
        for ((&a, &b), &wk) in left.iter().rev().zip(right).zip(side) {
            acc += wk * (a + b);
        }
        *ox = P::saturate_from((acc + round) >> shift);
    }
}

#[cfg(test)]
// `Real as f64` casts are no-ops without the `f32` feature and needed with it.
#[allow(clippy::unnecessary_cast)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec;

    /// Exact normalised truncated sampled Gaussian in f64, computed independently.
    fn g(sigma: f64, r: usize, k: isize) -> f64 {
        let e = |m: f64| (-0.5 * (m / sigma) * (m / sigma)).exp();
        let total: f64 = (-(r as isize)..=r as isize).map(|m| e(m as f64)).sum();
        e(k as f64) / total
    }

    #[test]
    fn kernel_weights_are_the_normalised_sampled_gaussian() {
        for &sigma in &[0.4, 0.8, 1.0, 1.7, 3.0, 5.0] {
            let k = GaussianKernel::new(sigma as Real).unwrap();
            assert_eq!(k.sigma(), sigma as Real);
            let r = k.radius();
            assert_eq!(r, ((3.0 * sigma).ceil() as usize).max(1));
            let sum: u32 = (-(r as isize)..=r as isize).map(|i| k.weight(i)).sum();
            assert_eq!(sum, 1 << 15);
            for i in -(r as isize)..=r as isize {
                // Bound: 1.5 Q15 units (docs: kernel quantisation), plus the error of computing
                // the target in Real (f32: ~2^-24 relative of 2^15 ≈ 0.002 unit).
                let err = (k.weight(i) as f64 - g(sigma, r, i) * 32768.0).abs();
                assert!(err <= 1.5 + 0.01, "sigma {sigma} k {i} err {err}");
                assert_eq!(k.weight(i), k.weight(-i));
            }
            assert_eq!(k.weight(r as isize + 1), 0);
        }
        assert!(matches!(
            GaussianKernel::new(0.0),
            Err(FilterError::BadSigma(_))
        ));
        assert!(matches!(
            GaussianKernel::new(Real::NAN),
            Err(FilterError::BadSigma(_))
        ));
        assert_eq!(
            GaussianKernel::new(6.0).unwrap_err(),
            FilterError::BadRadius { radius: 18 }
        );
        assert_eq!(
            GaussianKernel::with_radius(1.0, 0).unwrap_err(),
            FilterError::BadRadius { radius: 0 }
        );
    }

    #[test]
    fn frequency_response_is_the_gaussians() {
        // DC gain exactly 1; vs the continuous Gaussian exp(-σ²ω²/2): truncation at 3σ moves the
        // response by at most twice the discarded tail mass (0.27 %); sampling aliases the
        // spectrum (Poisson summation: H_sampled(ω) = Σ_m G(ω + 2πm)), the nearest aliases adding
        // G(2π - ω) + G(2π + ω); the Q15 rounding adds ≤ (2r+1)·1.5/2^15.
        for &sigma in &[0.8f64, 1.0, 2.0] {
            let k = GaussianKernel::new(sigma as Real).unwrap();
            assert_eq!(k.frequency_response(0.0), 1.0);
            let gauss = |w: f64| (-0.5 * sigma * sigma * w * w).exp();
            let two_pi = 2.0 * core::f64::consts::PI;
            for i in 0..=20 {
                let w = i as f64 * core::f64::consts::PI / 20.0;
                let alias = gauss(two_pi - w) + gauss(two_pi + w);
                let tol = 2.0 * 0.0027 + alias + (2 * k.radius() + 1) as f64 * 1.5 / 32768.0;
                let h = k.frequency_response(w as Real) as f64;
                let expected = gauss(w);
                assert!(
                    (h - expected).abs() <= tol,
                    "sigma {sigma} w {w} {h} {expected}"
                );
            }
        }
    }

    #[test]
    fn constant_image_is_preserved_including_borders() {
        for &c in &[0u16, 1, 777, 1023, 65535] {
            let (w, h) = (9, 7);
            let img = vec![c; w * h];
            let mut out = vec![0u16; w * h];
            let mut scratch = [0u32; 9];
            let k = GaussianKernel::new(1.3).unwrap(); // r = 4: borders everywhere
            let fi = Frame::new(&img, w, h, w).unwrap();
            let mut fo = Frame::new(&mut out, w, h, w).unwrap();
            gaussian_filter(&fi, &k, &mut scratch, &mut fo).unwrap();
            assert!(out.iter().all(|&v| v == c), "{c}");
        }
        // Narrower than the kernel (all-border path), u8.
        let img = [200u8; 6];
        let mut out = [0u8; 6];
        let fi = Frame::new(&img, 2, 3, 2).unwrap();
        let mut fo = Frame::new(&mut out, 2, 3, 2).unwrap();
        let mut scratch = [0u32; 2];
        gaussian_filter(
            &fi,
            &GaussianKernel::new(2.0).unwrap(),
            &mut scratch,
            &mut fo,
        )
        .unwrap();
        assert_eq!(out, [200; 6]);
    }

    /// Impulse of amplitude `a` in a `P` frame through a σ = 1.2 kernel.
    fn impulse_case<P: Pixel>(a: u32) {
        let sigma = 1.2;
        let k = GaussianKernel::new(sigma as Real).unwrap();
        let r = k.radius() as isize;
        let (w, h) = (21usize, 17usize);
        let (x0, y0) = (10isize, 8isize);
        let mut img = vec![P::default(); w * h];
        img[y0 as usize * w + x0 as usize] = P::saturate_from(a);
        let mut out = vec![P::default(); w * h];
        let mut scratch = vec![0u32; scratch_len(w)];
        let fi = Frame::new(&img, w, h, w).unwrap();
        let mut fo = Frame::new(&mut out, w, h, w).unwrap();
        gaussian_filter(&fi, &k, &mut scratch, &mut fo).unwrap();
        // Intermediate rounding to 17 bits: ≤ 0.5·2^(s−15) grey level, s = storage bits − 2.
        let s = P::STORAGE_BITS as i32 - 2;
        let inter = 0.5 * 2f64.powi(s - 15);
        let a = a as f64;
        for y in 0..h as isize {
            for x in 0..w as isize {
                let (dx, dy) = (x - x0, y - y0);
                let got: u32 = out[y as usize * w + x as usize].into();
                let got = got as f64;
                // Exact convolution with the Q15 kernel, then final + intermediate rounding.
                let q_exact = a * k.weight(dx) as f64 * k.weight(dy) as f64 / 1073741824.0;
                assert!(
                    (got - q_exact).abs() <= 0.5 + inter + 1e-9,
                    "({dx},{dy}) {got}"
                );
                // Analytic truth A·g(dx)·g(dy); error model: each weight within 1.5/2^15
                // (kernel quantisation) -> A·1.5/2^15·(g(dx)+g(dy)) + A·(1.5/2^15)², plus the
                // roundings above.
                let (gx, gy) = if dx.abs() <= r && dy.abs() <= r {
                    (g(sigma, r as usize, dx), g(sigma, r as usize, dy))
                } else {
                    (0.0, 0.0)
                };
                let q = 1.5 / 32768.0;
                let tol = a * (q * (gx + gy) + q * q) + 0.5 + inter + 1e-9;
                assert!((got - a * gx * gy).abs() <= tol, "({dx},{dy}) {got}");
            }
        }
    }

    #[test]
    fn impulse_becomes_the_sampled_gaussian() {
        impulse_case::<u16>(65535);
        impulse_case::<u16>(1023);
        impulse_case::<u8>(255);
    }

    #[test]
    fn sinusoid_is_attenuated_by_the_frequency_response() {
        // I(x) = 2000 + 1000 cos(ωx) along rows; away from the borders the output is
        // 2000 + 1000·H(ω)·cos(ωx) up to the final rounding (±0.5) and the kernel rounding.
        let k = GaussianKernel::new(1.0).unwrap();
        let omega: f64 = 2.0 * core::f64::consts::PI / 8.0;
        let (w, h) = (64usize, 5usize);
        let img: std::vec::Vec<u16> = (0..w * h)
            .map(|i| (2000.0 + 1000.0 * (omega * (i % w) as f64).cos()).round() as u16)
            .collect();
        let mut out = vec![0u16; w * h];
        let mut scratch = vec![0u32; w];
        let fi = Frame::new(&img, w, h, w).unwrap();
        let mut fo = Frame::new(&mut out, w, h, w).unwrap();
        gaussian_filter(&fi, &k, &mut scratch, &mut fo).unwrap();
        let hw = k.frequency_response(omega as Real) as f64;
        // Input rounding (±0.5) passes through a gain ≤ 1, output rounding ±0.5, intermediate
        // rounding of u16 data ±0.25 (see `gaussian_filter`).
        for x in 4..w - 4 {
            let expected = 2000.0 + 1000.0 * hw * (omega * x as f64).cos();
            let got = out[2 * w + x] as f64;
            // + 2e-3: H(ω) evaluated in Real (f32: ~1e-6 relative, times the amplitude 1000).
            assert!(
                (got - expected).abs() <= 1.25 + 2e-3,
                "x {x}: {got} vs {expected}"
            );
        }
    }

    #[test]
    fn size_and_scratch_checks() {
        let img = [0u8; 12];
        let mut out = [0u8; 12];
        let k = GaussianKernel::new(1.0).unwrap();
        let fi = Frame::new(&img, 4, 3, 4).unwrap();
        let mut fo = Frame::new(&mut out, 4, 3, 4).unwrap();
        let mut small = [0u32; 3];
        assert_eq!(
            gaussian_filter(&fi, &k, &mut small, &mut fo).unwrap_err(),
            FilterError::ScratchTooSmall {
                needed: 4,
                actual: 3
            }
        );
        let mut fo = Frame::new(&mut out, 3, 4, 3).unwrap();
        let mut scratch = [0u32; 4];
        assert!(matches!(
            gaussian_filter(&fi, &k, &mut scratch, &mut fo).unwrap_err(),
            FilterError::Frame(FrameError::SizeMismatch { .. })
        ));
    }
}
