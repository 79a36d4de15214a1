//! Optics and sensor: radiometry, PSF, speckle statistics, shot/read noise, gain,
//! quantisation, saturation (`docs/simulator.md`, "Optics" and "Sensor").

// `!(x > 0.0)` is deliberate: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rand::{Rng, RngExt};
use rand_distr::{Distribution, Gamma, Poisson, StandardNormal};
use serde::{Deserialize, Serialize};

/// Planck constant × speed of light (J·m), for the photon energy `hc/λ`.
const HC: f64 = 6.626_070_15e-34 * 299_792_458.0;

/// Lens and filter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpticsParams {
    /// Aperture f-number `N`.
    pub f_number: f64,
    /// Transmission of the 650 nm band-pass filter (and lens) in its band.
    pub filter_transmission: f64,
    /// Standard deviation of the lens PSF (pixels), lumping aberrations and defocus;
    /// modelled as a Gaussian blur of the irradiance before sampling by the pixels.
    pub psf_sigma_px: f64,
    /// Natural `cos⁴θ` vignetting on or off.
    pub vignetting: bool,
    /// Radius (pixels) of the geometric blur disc of a defocused lens, applied on top of the
    /// Gaussian PSF: `c = f²·|s − s_f| / (N·s·(s_f − f))` for an object at `s` and focus at
    /// `s_f` (`docs/simulator.md`, "Physics models"). 0 = in focus.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub defocus_radius_px: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Default for OpticsParams {
    /// An f/2.4 M12 lens with a 90 %-transmission interference filter and a 0.5 px PSF.
    fn default() -> Self {
        OpticsParams {
            f_number: 2.4,
            filter_transmission: 0.9,
            psf_sigma_px: 0.5,
            vignetting: true,
            defocus_radius_px: 0.0,
        }
    }
}

/// The image sensor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorParams {
    /// Name written to `capture.toml`.
    pub name: String,
    /// Pixel pitch (metres).
    pub pixel_pitch_m: f64,
    /// Quantum efficiency at the laser wavelength.
    pub quantum_efficiency: f64,
    /// Full-well capacity (electrons): the signal saturates there.
    pub full_well_e: f64,
    /// Read noise (electrons RMS).
    pub read_noise_e: f64,
    /// Output bit depth (8 or 10 for the MT9V034).
    pub bit_depth: u8,
    /// Black level (digital numbers at unity gain, added before quantisation).
    pub black_level_dn: f64,
    /// Photo-response non-uniformity: RMS of the fixed per-pixel gain deviation (EMVA 1288
    /// `PRNU`, fraction; 0.01 = 1 %). The same in every frame of a capture.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub prnu: f64,
    /// Temporal row noise (electrons RMS): one offset per row and frame, from the row's
    /// shared readout chain. Unlike the fixed pattern it does not cancel in the subtraction.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub row_noise_e: f64,
}

impl Default for SensorParams {
    /// MT9V034: 6 µm pixels; maximum SNR 42 dB ⇒ full well `10^(42/20)² ≈ 16 000 e⁻`;
    /// dynamic range 55 dB ⇒ read noise `16 000 / 10^(55/20) ≈ 28 e⁻`; QE ≈ 0.4 at 650 nm;
    /// 8-bit output with a black level of 2 DN (`docs/simulator.md`).
    fn default() -> Self {
        SensorParams {
            name: "simulated MT9V034".into(),
            pixel_pitch_m: 6e-6,
            quantum_efficiency: 0.4,
            full_well_e: 16_000.0,
            read_noise_e: 28.0,
            bit_depth: 8,
            black_level_dn: 2.0,
            prnu: 0.0,
            row_noise_e: 0.0,
        }
    }
}

impl SensorParams {
    /// Largest digital number, `2^bits − 1`.
    pub fn max_dn(&self) -> u16 {
        ((1u32 << self.bit_depth.clamp(1, 16)) - 1) as u16
    }

    /// Electron rate (e⁻/s) per unit "albedo × irradiance" (W/m²) of a Lambertian surface
    /// seen on the optical axis:
    ///
    /// ```text
    /// K = A_pix · QE · T · λ / (4 N² h c)
    /// ```
    ///
    /// (radiance `ρE/π`, image irradiance `π L / (4 N²)`, photons `λ/(hc)` per joule;
    /// `docs/simulator.md`, "Radiometry").
    pub fn electrons_per_s(&self, optics: &OpticsParams, wavelength_m: f64) -> f64 {
        let a_pix = self.pixel_pitch_m * self.pixel_pitch_m;
        a_pix * self.quantum_efficiency * optics.filter_transmission * wavelength_m
            / (4.0 * optics.f_number * optics.f_number * HC)
    }

    /// Converts a mean electron count into a digital number: Poisson shot noise, clipping at
    /// the full well, Gaussian read noise, gain, black level, rounding and clipping to
    /// `[0, max_dn]`.
    pub fn expose_pixel<R: Rng + ?Sized>(&self, mean_e: f64, gain: f64, rng: &mut R) -> u16 {
        self.expose_pixel_with_offset(mean_e, 0.0, gain, rng)
    }

    /// [`SensorParams::expose_pixel`] with `offset_e` electrons added to the read noise (a
    /// row's temporal offset, [`SensorParams::row_noise_e`]).
    pub fn expose_pixel_with_offset<R: Rng + ?Sized>(
        &self,
        mean_e: f64,
        offset_e: f64,
        gain: f64,
        rng: &mut R,
    ) -> u16 {
        let electrons = if mean_e > 0.0 {
            Poisson::new(mean_e).map(|p| p.sample(rng)).unwrap_or(0.0)
        } else {
            0.0
        };
        let electrons = electrons.min(self.full_well_e);
        let read: f64 = rng.sample(StandardNormal);
        let dn_per_e = gain * self.max_dn() as f64 / self.full_well_e;
        let dn = self.black_level_dn + dn_per_e * (electrons + self.read_noise_e * read + offset_e);
        dn.round().clamp(0.0, self.max_dn() as f64) as u16
    }

    /// Predicted mean and variance (DN, DN²) of [`SensorParams::expose_pixel`] away from
    /// clipping: `μ = b + g·μₑ`, `σ² = g²(μₑ + σ_r²) + 1/12` with `g` = DN per electron
    /// (the 1/12 is uniform quantisation noise).
    pub fn predicted_stats(&self, mean_e: f64, gain: f64) -> (f64, f64) {
        let g = gain * self.max_dn() as f64 / self.full_well_e;
        (
            self.black_level_dn + g * mean_e,
            g * g * (mean_e + self.read_noise_e * self.read_noise_e) + 1.0 / 12.0,
        )
    }
}

/// Speckle intensity-correlation width on the sensor (metres): `σ_c = 0.594·λ·N`.
///
/// The lens's intensity PSF is approximated by a Gaussian of σ = 0.42 λN (the Airy core);
/// its amplitude PSF then has σ_h = √2·0.42 λN, and the speckle intensity correlation
/// `|μ(Δ)|² = exp(−Δ²/(2σ_h²))`, so σ_c = σ_h (`docs/simulator.md`, "Speckle").
pub fn speckle_correlation_m(wavelength_m: f64, f_number: f64) -> f64 {
    std::f64::consts::SQRT_2 * 0.42 * wavelength_m * f_number
}

/// Number of speckle "cells" `M` integrated by a square pixel of side `pitch` (Goodman,
/// *Speckle Phenomena in Optics*, §5.6): `1/M = [ (1/L)∫_{−L}^{L} (1 − |x|/L)·|μ(x)|² dx ]²`
/// for a separable Gaussian `|μ|²` of width σ_c. The integrated intensity is then
/// Gamma-distributed with shape `M` (contrast `1/√M`).
pub fn speckle_cells(pitch_m: f64, sigma_c_m: f64) -> f64 {
    if !(sigma_c_m > 0.0) {
        return f64::INFINITY;
    }
    // Midpoint rule with 2000 intervals on a smooth integrand: error ≪ 1e-6.
    let n = 2000;
    let l = pitch_m;
    let dx = 2.0 * l / n as f64;
    let integral: f64 = (0..n)
        .map(|i| {
            let x = -l + (i as f64 + 0.5) * dx;
            (1.0 - x.abs() / l) * (-x * x / (2.0 * sigma_c_m * sigma_c_m)).exp() * dx
        })
        .sum();
    let one_d = integral / l;
    1.0 / (one_d * one_d)
}

/// Speckle contrast left by a broadband laser on a rough surface (Goodman, *Speckle
/// Phenomena in Optics*, §3.6, Gaussian spectrum of FWHM-like width `Δλ`, Gaussian heights
/// of RMS `σ_h`, reflection so the path differences are `2h`):
/// `C_λ = [1 + (2π·Δλ·2σ_h/λ²)²]^(−1/4)`. A multimode 650 nm diode (`Δλ` ≈ 1 nm, coherence
/// length λ²/Δλ ≈ 0.4 mm) on bark (σ_h ≈ 1 mm) leaves C_λ ≈ 0.18.
pub fn spectral_speckle_contrast(
    wavelength_m: f64,
    spectral_width_m: f64,
    roughness_m: f64,
) -> f64 {
    let x = 2.0 * std::f64::consts::PI * spectral_width_m * 2.0 * roughness_m
        / (wavelength_m * wavelength_m);
    (1.0 + x * x).powf(-0.25)
}

/// One multiplicative speckle factor (mean 1, variance `1/M`, i.e. contrast `1/√M`) for a
/// pixel: Gamma-distributed with shape `M` (Goodman §5.6).
pub fn speckle_factor<R: Rng + ?Sized>(cells: f64, rng: &mut R) -> f64 {
    if !cells.is_finite() {
        return 1.0;
    }
    Gamma::new(cells, 1.0 / cells)
        .map(|g| g.sample(rng))
        .unwrap_or(1.0)
}

/// One speckle factor per pixel of a `w × h` image whose speckle grains are comparable to
/// the pixel: a unit Gaussian field correlated by a Gaussian kernel of σ = `grain_px`
/// (taps normalised so the field keeps unit variance), mapped to the Gamma(`M`, 1/`M`)
/// marginal of [`speckle_factor`] by the Wilson–Hilferty transform
/// `m = max(0, 1 − 1/(9M) + g/(3√M))³` (`docs/simulator.md`, "Speckle"). `white` holds
/// `w × h` independent unit normals.
pub fn correlated_speckle(
    white: &[f64],
    w: usize,
    h: usize,
    grain_px: f64,
    cells: f64,
) -> Vec<f64> {
    let mut g = white.to_vec();
    gaussian_blur(&mut g, w, h, grain_px);
    // Σh² of the separable kernel (per axis, the same as in `gaussian_blur`), to restore unit
    // variance after the filter.
    let r = (3.0 * grain_px).ceil() as isize;
    let taps: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * grain_px * grain_px)).exp())
        .collect();
    let sum: f64 = taps.iter().sum();
    let sum_sq: f64 = taps.iter().map(|t| (t / sum) * (t / sum)).sum();
    let scale = 1.0 / sum_sq; // 2-D: (Σh²)² in variance, so 1/Σh² in amplitude
    if !cells.is_finite() {
        return vec![1.0; g.len()];
    }
    let a = 1.0 - 1.0 / (9.0 * cells);
    let b = 1.0 / (3.0 * cells.sqrt());
    g.iter()
        .map(|x| (a + b * x * scale).max(0.0).powi(3))
        .collect()
}

/// Blur by a uniform disc of radius `radius` pixels (geometric defocus), each pixel's weight
/// the exact-enough area of the disc over it (16 × 16 sub-samples), edges clamped.
pub fn disc_blur(img: &mut [f64], w: usize, h: usize, radius: f64) {
    if !(radius > 0.0) || w == 0 || h == 0 {
        return;
    }
    let r = radius.ceil() as isize;
    let n = 16;
    let mut kernel = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            let mut inside = 0usize;
            for b in 0..n {
                for a in 0..n {
                    let x = dx as f64 + (a as f64 + 0.5) / n as f64 - 0.5;
                    let y = dy as f64 + (b as f64 + 0.5) / n as f64 - 0.5;
                    inside += (x * x + y * y <= radius * radius) as usize;
                }
            }
            if inside > 0 {
                kernel.push((dx, dy, inside as f64));
            }
        }
    }
    let total: f64 = kernel.iter().map(|k| k.2).sum();
    let src = img.to_vec();
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for &(dx, dy, k) in &kernel {
                let xx = (x as isize + dx).clamp(0, w as isize - 1) as usize;
                let yy = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                acc += k * src[yy * w + xx];
            }
            img[y * w + x] = acc / total;
        }
    }
}

/// Separable Gaussian blur (σ in pixels, kernel ±⌈3σ⌉, edges clamped) of a `w × h` image.
pub fn gaussian_blur(img: &mut [f64], w: usize, h: usize, sigma: f64) {
    if !(sigma > 0.0) || w == 0 || h == 0 {
        return;
    }
    let r = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / sum).collect();
    let mut tmp = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for (k, kv) in kernel.iter().enumerate() {
                let xx = (x as isize + k as isize - r).clamp(0, w as isize - 1) as usize;
                acc += kv * img[y * w + xx];
            }
            tmp[y * w + x] = acc;
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut acc = 0.0;
            for (k, kv) in kernel.iter().enumerate() {
                let yy = (y as isize + k as isize - r).clamp(0, h as isize - 1) as usize;
                acc += kv * tmp[yy * w + x];
            }
            img[y * w + x] = acc;
        }
    }
}
