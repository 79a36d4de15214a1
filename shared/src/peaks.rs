//! Subpixel location of a laser-stripe peak on a 1-D intensity profile (thesis §5.7.1–5.7.3).
//!
//! A column of the laser-on minus laser-off difference image crosses the laser stripe as a
//! bell-shaped profile (the laser sheet has a Gaussian cross-section, blurred by the optics and
//! integrated over each pixel). Given the index of a local maximum of that profile, [`locate`]
//! estimates where the true centre of the stripe lies between pixels.
//!
//! Profiles are `&[Real]`: the caller converts its integer pixels (8/10/16-bit) once, which
//! keeps one implementation for every pixel type and lets the host feed noisy or
//! synthetic profiles. Sample `i` is the pixel whose centre is at coordinate `i` (the
//! architecture's pixel-centre convention), so [`Peak::position`] is in the same coordinate.
//!
//! The estimators and their derivations are in `docs/subpixel.md`; their bias and noise under
//! quantisation, saturation, DC offset, threshold, noise and speckle are measured by
//! `tangent study subpixel` (`docs/subpixel-study.md`).
//!
//! Every estimator runs in bounded time (at most `2·MAX_HALF_WINDOW + 1` samples; the only
//! iteration, the fit's refinement of saturated peaks, is capped at `GN_ITERATIONS` steps)
//! and never allocates or panics: bad data gives a [`PeakError`].
// `!(x > 0.0)` is deliberate throughout: a NaN must fail the check, as `x <= 0.0` would not.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::fmt;

use crate::real::{sqrt, Float, Real};

/// Largest half window any estimator reads (samples on each side of the peak): bounds the
/// work per peak and the stack profile buffer of [`crate::curve`].
pub const MAX_HALF_WINDOW: u8 = 12;

/// Fraction of the peak sample above which [`Estimator::GaussianFit`] includes samples.
///
/// The weighted log-fit gives a sample of value `x` the weight `x²` (its log has variance
/// `σ_n²/x²`, `docs/subpixel.md` §6), so samples near the cut carry little weight anyway; the
/// cut mainly keeps `ln` away from zero and negative noise, and keeps a neighbouring
/// stripe out of the window.
pub const FIT_FRACTION: Real = 0.05;

/// A subpixel peak estimator (derivations in `docs/subpixel.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Estimator {
    /// Parabola through the logarithms of the three samples around the peak (§2): exact on
    /// point-sampled Gaussians, noisy on wide stripes, fails when a neighbour is `≤ 0`.
    Gaussian3,
    /// Centre of mass of `2·half_window + 1` samples centred on the peak (§3): biased toward
    /// the peak pixel when the window truncates the stripe, noisy when it is wider.
    CentreOfMass {
        /// Samples on each side of the peak, `1..=MAX_HALF_WINDOW`.
        half_window: u8,
    },
    /// Parabola through the three samples around the peak (§4): biased on Gaussians.
    Parabolic,
    /// Blais–Rioux 4th-order derivative filter, linear interpolation of its zero crossing (§5).
    BlaisRioux4,
    /// Blais–Rioux 8th-order derivative filter, linear interpolation of its zero crossing (§5).
    BlaisRioux8,
    /// Weighted least-squares Gaussian fit (§6): a parabola fitted to `ln x` over the
    /// contiguous samples above [`FIT_FRACTION`] of the peak (at most `MAX_HALF_WINDOW` on each
    /// side), weighted by `x²`, excluding saturated samples — so it also locates a clipped peak
    /// from its flanks.
    GaussianFit,
}

/// The estimator the measurement chain uses: the weighted Gaussian fit. It is the only one
/// of the set whose worst-case bias stays ≤ 0.02 px over stripe σ 0.7–3 px including a
/// saturated peak, with the lowest noise of the set at 1 % additive noise (within 1.3× of
/// the quietest, biased, estimators on saturated peaks) (`docs/subpixel.md` §7, numbers in
/// `docs/subpixel-study.md`).
pub const DEFAULT_ESTIMATOR: Estimator = Estimator::GaussianFit;

impl Estimator {
    /// Short name used in tables and logs.
    pub fn name(&self) -> &'static str {
        match self {
            Estimator::Gaussian3 => "Gaussian 3-point",
            Estimator::CentreOfMass { .. } => "centre of mass",
            Estimator::Parabolic => "parabolic",
            Estimator::BlaisRioux4 => "Blais–Rioux 4",
            Estimator::BlaisRioux8 => "Blais–Rioux 8",
            Estimator::GaussianFit => "Gaussian LS fit",
        }
    }

    /// Samples needed on each side of the peak (the fit needs one and reads up to
    /// [`MAX_HALF_WINDOW`] when available).
    pub fn half_window(&self) -> usize {
        match self {
            Estimator::Gaussian3 | Estimator::Parabolic | Estimator::GaussianFit => 1,
            Estimator::CentreOfMass { half_window } => *half_window as usize,
            // F(p-1), F(p), F(p+1) read x(p-3) .. x(p+3).
            Estimator::BlaisRioux4 => 3,
            // The 8-tap filter reads 4 samples each side: x(p-5) .. x(p+5).
            Estimator::BlaisRioux8 => 5,
        }
    }
}

/// A located peak.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    /// Subpixel position of the stripe centre, in profile-index coordinates (sample `i` is
    /// centred on `i`).
    pub position: Real,
    /// Peak height: the vertex of the fitted model for the Gaussian and parabolic
    /// estimators (for a saturated peak the fit extrapolates above the clipping level), the
    /// peak sample for the centre of mass and Blais–Rioux.
    pub amplitude: Real,
    /// Gaussian σ of the profile in samples, for the estimators that model it
    /// ([`Estimator::Gaussian3`], [`Estimator::GaussianFit`]); includes the pixel's own width
    /// (σ² + 1/12 for a pixel-integrated Gaussian, `docs/subpixel.md` §6).
    pub sigma: Option<Real>,
    /// At least one sample the estimator read was at or above the saturation level.
    pub saturated: bool,
    /// Number of samples the estimator used (saturated samples excluded by the fit).
    pub samples: u8,
}

/// Why a peak could not be located.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PeakError {
    /// The peak index is not inside the profile.
    PeakOutOfRange {
        /// Requested peak index.
        peak: usize,
        /// Profile length.
        len: usize,
    },
    /// The estimator's window runs past an end of the profile.
    Border {
        /// Requested peak index.
        peak: usize,
        /// Samples needed on each side.
        half_window: usize,
        /// Profile length.
        len: usize,
    },
    /// The centre-of-mass half window is 0 or larger than [`MAX_HALF_WINDOW`].
    WindowOutOfRange {
        /// The half window asked for.
        half_window: u8,
    },
    /// A sample in the window is NaN or infinite.
    NonFinite {
        /// Index of the sample.
        index: usize,
    },
    /// The peak sample is smaller than a neighbour.
    NotAMaximum {
        /// Requested peak index.
        peak: usize,
    },
    /// The profile is flat or not positive around the peak (no curvature, no signal, or no
    /// sign change of the Blais–Rioux filter).
    Flat,
    /// A logarithmic estimator met a sample `≤ 0` (e.g. a neighbour cut by a threshold).
    NonPositive {
        /// Index of the sample.
        index: usize,
    },
    /// The Gaussian fit found fewer than 3 unsaturated samples above the cut.
    TooFewSamples {
        /// Usable samples found.
        found: u8,
    },
    /// The estimate fell outside the samples it was computed from.
    OffsetOutOfRange,
}

impl fmt::Display for PeakError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PeakError::PeakOutOfRange { peak, len } => {
                write!(f, "peak index {peak} outside a profile of {len} samples")
            }
            PeakError::Border {
                peak,
                half_window,
                len,
            } => write!(
                f,
                "peak {peak} needs {half_window} samples on each side in a profile of {len}"
            ),
            PeakError::WindowOutOfRange { half_window } => {
                write!(f, "half window {half_window} outside 1..={MAX_HALF_WINDOW}")
            }
            PeakError::NonFinite { index } => write!(f, "sample {index} is not finite"),
            PeakError::NotAMaximum { peak } => write!(f, "sample {peak} is not a local maximum"),
            PeakError::Flat => write!(f, "profile is flat or not positive around the peak"),
            PeakError::NonPositive { index } => {
                write!(f, "sample {index} is not positive (logarithmic estimator)")
            }
            PeakError::TooFewSamples { found } => {
                write!(
                    f,
                    "only {found} unsaturated samples above the fit cut, 3 needed"
                )
            }
            PeakError::OffsetOutOfRange => write!(f, "estimate fell outside its window"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for PeakError {}

/// Locates the stripe centre near the local maximum `profile[peak]` with `estimator`,
/// assuming no sample is saturated (see [`locate_with_saturation`]).
pub fn locate(profile: &[Real], peak: usize, estimator: Estimator) -> Result<Peak, PeakError> {
    locate_with_saturation(profile, peak, estimator, Real::INFINITY)
}

/// Locates the stripe centre near the local maximum `profile[peak]` with `estimator`;
/// samples `≥ saturation` are flagged as saturated ([`Peak::saturated`]) and left out by
/// [`Estimator::GaussianFit`]. For a difference frame the level is the sensor's full scale
/// minus the laser-off level (the caller's choice, see [`crate::curve::ExtractParams`]).
pub fn locate_with_saturation(
    profile: &[Real],
    peak: usize,
    estimator: Estimator,
    saturation: Real,
) -> Result<Peak, PeakError> {
    let len = profile.len();
    if peak >= len {
        return Err(PeakError::PeakOutOfRange { peak, len });
    }
    if let Estimator::CentreOfMass { half_window } = estimator {
        if half_window == 0 || half_window > MAX_HALF_WINDOW {
            return Err(PeakError::WindowOutOfRange { half_window });
        }
    }
    let h = estimator.half_window();
    if peak < h || peak + h >= len {
        return Err(PeakError::Border {
            peak,
            half_window: h,
            len,
        });
    }
    // In range by the check above; `get` keeps the code free of panicking paths anyway.
    let window = profile.get(peak - h..=peak + h).ok_or(PeakError::Flat)?;
    let mut saturated = false;
    for (k, &x) in window.iter().enumerate() {
        if !x.is_finite() {
            return Err(PeakError::NonFinite {
                index: peak - h + k,
            });
        }
        saturated |= x >= saturation;
    }
    // Window-relative samples: `s(k)` is profile[peak + k], k in -h..=h.
    let s = |k: isize| -> Real {
        window
            .get((h as isize + k) as usize)
            .copied()
            .unwrap_or(0.0)
    };
    let (xm, x0, xp) = (s(-1), s(0), s(1));
    if x0 < xm || x0 < xp {
        return Err(PeakError::NotAMaximum { peak });
    }
    if x0 <= 0.0 {
        return Err(PeakError::Flat);
    }
    let n = window.len() as u8;
    let p = peak as Real;
    match estimator {
        Estimator::Gaussian3 => {
            for (k, x) in [(-1isize, xm), (1, xp)] {
                if x <= 0.0 {
                    return Err(PeakError::NonPositive {
                        index: (peak as isize + k) as usize,
                    });
                }
            }
            let (la, lb, lc) = (Float::ln(xm), Float::ln(x0), Float::ln(xp));
            let (delta, vertex, den) = parabola_vertex(la, lb, lc)?;
            Ok(Peak {
                position: p + delta,
                amplitude: Float::exp(vertex),
                sigma: Some(sqrt(-1.0 / den)),
                saturated,
                samples: n,
            })
        }
        Estimator::Parabolic => {
            let (delta, vertex, _) = parabola_vertex(xm, x0, xp)?;
            Ok(Peak {
                position: p + delta,
                amplitude: vertex,
                sigma: None,
                saturated,
                samples: n,
            })
        }
        Estimator::CentreOfMass { .. } => {
            let (mut m0, mut m1) = (0.0 as Real, 0.0 as Real);
            for (k, &x) in window.iter().enumerate() {
                m0 += x;
                m1 += x * (k as Real - h as Real);
            }
            if !(m0 > 0.0) {
                return Err(PeakError::Flat);
            }
            let delta = m1 / m0;
            if !(delta.abs() <= h as Real) {
                return Err(PeakError::OffsetOutOfRange);
            }
            Ok(Peak {
                position: p + delta,
                amplitude: x0,
                sigma: None,
                saturated,
                samples: n,
            })
        }
        Estimator::BlaisRioux4 => {
            // F(i) = x(i-2) + x(i-1) - x(i+1) - x(i+2)
            let f = |i: isize| s(i - 2) + s(i - 1) - s(i + 1) - s(i + 2);
            let delta = zero_crossing(f(-1), f(0), f(1))?;
            Ok(Peak {
                position: p + delta,
                amplitude: x0,
                sigma: None,
                saturated,
                samples: n,
            })
        }
        Estimator::BlaisRioux8 => {
            // F(i) = x(i-4) + … + x(i-1) - x(i+1) - … - x(i+4)
            let f = |i: isize| {
                s(i - 4) + s(i - 3) + s(i - 2) + s(i - 1)
                    - s(i + 1)
                    - s(i + 2)
                    - s(i + 3)
                    - s(i + 4)
            };
            let delta = zero_crossing(f(-1), f(0), f(1))?;
            Ok(Peak {
                position: p + delta,
                amplitude: x0,
                sigma: None,
                saturated,
                samples: n,
            })
        }
        Estimator::GaussianFit => gaussian_fit(profile, peak, saturation),
    }
}

/// Vertex of the parabola through `(-1, a)`, `(0, b)`, `(1, c)` with `b ≥ a, c`:
/// returns `(offset, value, a - 2b + c)` (`docs/subpixel.md` §2). `|offset| ≤ ½` follows from
/// `b` being the maximum.
fn parabola_vertex(a: Real, b: Real, c: Real) -> Result<(Real, Real, Real), PeakError> {
    let den = a - 2.0 * b + c;
    if !(den < 0.0) {
        return Err(PeakError::Flat);
    }
    // |a − c| ≤ |den| exactly when b is the maximum; rounding can exceed it by an ulp
    // (two equal samples, stripe half-way between them), hence the clamp.
    let delta = (0.5 * (a - c) / den).clamp(-0.5, 0.5);
    let vertex = b - (c - a) * (c - a) / (8.0 * den);
    Ok((delta, vertex, den))
}

/// Offset of the zero crossing of a derivative filter sampled at -1, 0, 1 (negative left of
/// the peak, positive right of it), by linear interpolation between the two samples that
/// bracket it (`docs/subpixel.md` §5).
fn zero_crossing(fm: Real, f0: Real, fp: Real) -> Result<Real, PeakError> {
    if f0 <= 0.0 && fp > 0.0 {
        // Crossing in [0, 1).
        Ok(f0 / (f0 - fp))
    } else if fm <= 0.0 && f0 > 0.0 {
        // Crossing in [-1, 0).
        Ok(-1.0 + fm / (fm - f0))
    } else {
        Err(PeakError::Flat)
    }
}

/// Index of the middle of the plateau of samples equal to `profile[peak]` that contains
/// `peak` (rounded down), or `peak` when it has no equal neighbour.
///
/// A saturated stripe is a run of equal samples at the clipping level; an arg-max returns
/// its first sample, up to half the plateau away from the centre, and the 3-sample
/// estimators then stay there. Starting from the middle keeps them within half a pixel.
pub fn plateau_centre(profile: &[Real], peak: usize) -> usize {
    let Some(&v) = profile.get(peak) else {
        return peak;
    };
    let mut lo = peak;
    while lo > 0 && profile.get(lo - 1) == Some(&v) {
        lo -= 1;
    }
    let mut hi = peak;
    while profile.get(hi + 1) == Some(&v) {
        hi += 1;
    }
    lo + (hi - lo) / 2
}

/// Largest number of samples the fit holds (`2·MAX_HALF_WINDOW + 1`).
const FIT_CAP: usize = 2 * MAX_HALF_WINDOW as usize + 1;

/// Determinant of the 3×3 matrix with rows `a`, `b`, `c`.
fn det3(a: [Real; 3], b: [Real; 3], c: [Real; 3]) -> Real {
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}

/// Solves the symmetric 3×3 system `m x = r` by Cramer's rule; `None` when `m` is singular
/// relative to its diagonal (Hadamard: `|det| ≤ m00·m11·m22` for a positive semi-definite
/// matrix, so the ratio is a relative conditioning measure).
fn solve3(m: [[Real; 3]; 3], r: [Real; 3]) -> Option<[Real; 3]> {
    let det = det3(m[0], m[1], m[2]);
    let scale = m[0][0] * m[1][1] * m[2][2];
    if !(det.abs() > 64.0 * crate::real::EPSILON * scale.abs()) {
        return None;
    }
    let col = |k: usize| {
        let mut rows = m;
        for (row, rv) in rows.iter_mut().zip(r) {
            row[k] = rv;
        }
        det3(rows[0], rows[1], rows[2]) / det
    };
    Some([col(0), col(1), col(2)])
}

/// Weighted least-squares Gaussian fit (`docs/subpixel.md` §6).
///
/// 1. The contiguous run of samples above `FIT_FRACTION · x0` around the peak (at most
///    `MAX_HALF_WINDOW` each side) gives, leaving out saturated samples, a parabola fitted
///    to `ln x` with weights `x²` (linearised least squares: `var(ln x) ≈ σ_n²/x²`).
/// 2. With only two unsaturated samples (a narrow clipped stripe), the parabola is taken
///    through them and the end of the plateau that binds (the widest Gaussian through the
///    flanks that stays at or above the clipping level over the plateau), as a start.
/// 3. A saturated peak is then refined by at most `GN_ITERATIONS` Gauss–Newton steps of the
///    Gaussian `A·exp(-(t-μ)²/2s²)` on the raw (linear) samples of a ±3s window, saturated
///    samples excluded: the maximum-likelihood fit for additive Gaussian noise, which the
///    log-parabola on a few flank samples is not.
fn gaussian_fit(profile: &[Real], peak: usize, saturation: Real) -> Result<Peak, PeakError> {
    let len = profile.len();
    let raw0 = profile
        .get(peak)
        .copied()
        .ok_or(PeakError::PeakOutOfRange { peak, len })?;
    let reach = MAX_HALF_WINDOW as usize;
    let (mut lo, mut hi) = fit_run(profile, peak, FIT_FRACTION * raw0)?;
    // A pedestal (DC left by the subtraction) keeps the whole ±reach window above the cut;
    // then the mean of the two window ends estimates it, and the run is found again above
    // it. Without a pedestal the run stops before the reach (σ ≤ 4 px: the cut is at
    // ≤ 2.5σ), and the baseline stays 0.
    let mut base = 0.0 as Real;
    if peak - lo == reach && hi - peak == reach {
        let ends =
            profile.get(lo).copied().unwrap_or(0.0) + profile.get(hi).copied().unwrap_or(0.0);
        base = 0.5 * ends;
        (lo, hi) = fit_run(profile, peak, base + FIT_FRACTION * (raw0 - base))?;
    }
    let x0 = raw0 - base;
    if !(x0 > 0.0) {
        return Err(PeakError::Flat);
    }
    let run = profile.get(lo..=hi).ok_or(PeakError::Flat)?;
    // Normal equations of min Σ w (ln x - a - b t - c t²)², t = i - peak, w = (x/x0)²
    // (x0 > 0 was checked by the caller; normalising keeps the sums O(1) in f32).
    let mut s = [0.0 as Real; 5]; // Σ w t^k, k = 0..4
    let mut r = [0.0 as Real; 3]; // Σ w t^k ln x, k = 0..2
    let mut used: u8 = 0;
    let mut saturated = false;
    // Flank samples (t, ln x/x0), kept for the two-sample start; saturated plateau ends.
    let mut flank = [(0.0 as Real, 0.0 as Real); 2];
    let (mut sat_first, mut sat_last) = (None::<Real>, None::<Real>);
    for (k, &x) in run.iter().enumerate() {
        let t = (lo + k) as Real - peak as Real;
        if x >= saturation {
            saturated = true;
            sat_first.get_or_insert(t);
            sat_last = Some(t);
            continue;
        }
        let xr = (x - base) / x0;
        if !(xr > 0.0) {
            return Err(PeakError::Flat);
        }
        let w = xr * xr;
        let y = Float::ln(xr);
        if let Some(f) = flank.get_mut(used as usize) {
            *f = (t, y);
        }
        let mut tk = w;
        for (j, sj) in s.iter_mut().enumerate() {
            *sj += tk;
            if let Some(rj) = r.get_mut(j) {
                *rj += tk * y;
            }
            tk *= t;
        }
        used += 1;
    }
    let [s0, s1, s2, s3, s4] = s;
    let start = if used >= 3 {
        solve3([[s0, s1, s2], [s1, s2, s3], [s2, s3, s4]], r)
            .ok_or(PeakError::TooFewSamples { found: used })?
    } else if let (2, Some(first), Some(last)) = (used, sat_first, sat_last) {
        two_flank_start(flank, first, last, Float::ln((saturation - base) / x0))
            .ok_or(PeakError::TooFewSamples { found: used })?
    } else {
        return Err(PeakError::TooFewSamples { found: used });
    };
    let [a, b, c] = start;
    if !(c < 0.0) {
        return Err(PeakError::Flat);
    }
    // Vertex form: μ = -b/2c, s² = -1/2c, A = x0·exp(a - b²/4c).
    let mut mu = -b / (2.0 * c);
    let mut sig = sqrt(-0.5 / c);
    let mut amp = x0 * Float::exp(a - b * b / (4.0 * c));
    let mut samples = used;
    if saturated {
        if let Some((m, sg, am, n)) = refine(profile, peak, saturation, base, [amp, mu, sig]) {
            (mu, sig, amp, samples) = (m, sg, am, n);
        }
    }
    let position = peak as Real + mu;
    if !(position >= lo as Real - 0.5 && position <= hi as Real + 0.5) {
        return Err(PeakError::OffsetOutOfRange);
    }
    Ok(Peak {
        position,
        amplitude: amp,
        sigma: Some(sig),
        saturated,
        samples,
    })
}

/// The contiguous run `lo..=hi` of samples above `cut` around `peak`, at most
/// `MAX_HALF_WINDOW` on each side.
fn fit_run(profile: &[Real], peak: usize, cut: Real) -> Result<(usize, usize), PeakError> {
    let reach = MAX_HALF_WINDOW as usize;
    let len = profile.len();
    let mut lo = peak;
    while lo > 0 && peak - (lo - 1) <= reach {
        match profile.get(lo - 1) {
            Some(&x) if !x.is_finite() => return Err(PeakError::NonFinite { index: lo - 1 }),
            Some(&x) if x > cut => lo -= 1,
            _ => break,
        }
    }
    let mut hi = peak;
    while hi + 1 < len && hi + 1 - peak <= reach {
        match profile.get(hi + 1) {
            Some(&x) if !x.is_finite() => return Err(PeakError::NonFinite { index: hi + 1 }),
            Some(&x) if x > cut => hi += 1,
            _ => break,
        }
    }
    Ok((lo, hi))
}

/// Start of the fit from two flank samples `(t, ln x/x0)` around a saturated plateau
/// `first..=last`: the parabola in `ln` through both flanks and the plateau end at the
/// clipping level `ln_sat` for which the other plateau end stays at or above it — the widest
/// Gaussian consistent with the clipping (`docs/subpixel.md` §6). Returns `(a, b, c)` of
/// `a + b t + c t²`.
fn two_flank_start(
    flank: [(Real, Real); 2],
    first: Real,
    last: Real,
    ln_sat: Real,
) -> Option<[Real; 3]> {
    let [(t1, y1), (t2, y2)] = flank;
    let mut best: Option<[Real; 3]> = None;
    for (tb, other) in [(first, last), (last, first)] {
        // Parabola through (t1, y1), (tb, ln_sat), (t2, y2): Lagrange → monomial coefficients.
        let pts = [(t1, y1), (tb, ln_sat), (t2, y2)];
        let m = [
            [1.0, pts[0].0, pts[0].0 * pts[0].0],
            [1.0, pts[1].0, pts[1].0 * pts[1].0],
            [1.0, pts[2].0, pts[2].0 * pts[2].0],
        ];
        let det = det3(m[0], m[1], m[2]);
        if !(det.abs() > 0.0) {
            continue;
        }
        let rhs = [pts[0].1, pts[1].1, pts[2].1];
        let col = |k: usize| {
            let mut rows = m;
            for (row, rv) in rows.iter_mut().zip(rhs) {
                row[k] = rv;
            }
            det3(rows[0], rows[1], rows[2]) / det
        };
        let abc = [col(0), col(1), col(2)];
        let at_other = abc[0] + abc[1] * other + abc[2] * other * other;
        // Tolerance: rounding of ln in the core's precision.
        if abc[2] < 0.0 && at_other >= ln_sat - 1e3 * crate::real::EPSILON {
            best = Some(abc);
            break;
        }
    }
    best
}

/// Gauss–Newton steps of the saturated-peak refinement.
const GN_ITERATIONS: usize = 6;

/// Maximum-likelihood refinement of the clipped Gaussian
/// `min(base + A·exp(-(t-μ)²/2s²), saturation)` (`t = i - peak`) on the samples of
/// `peak ± ceil(3s + |μ|)` (bounded by `MAX_HALF_WINDOW` and the profile), equal weights
/// (additive Gaussian noise), at most `GN_ITERATIONS` Gauss–Newton steps, each halved up to
/// 4 times until the residual decreases. Modelling the clipping keeps the saturated samples
/// as information: a model that dips below the clipping level where the sensor saturated
/// is penalised, one above it is not (its Jacobian there is zero). `None` when the system is
/// singular or the result is not sane (the caller then keeps the start).
/// `start` and the result are `[A, μ, s]`; the result also gives the samples used.
fn refine(
    profile: &[Real],
    peak: usize,
    saturation: Real,
    base: Real,
    start: [Real; 3],
) -> Option<(Real, Real, Real, u8)> {
    let [a0, mu0, s0] = start;
    let reach = Float::ceil(3.0 * s0 + Float::abs(mu0)).min(MAX_HALF_WINDOW as Real) as usize;
    let lo = peak.saturating_sub(reach.max(2));
    let hi = (peak + reach.max(2)).min(profile.len().checked_sub(1)?);
    let mut t_buf = [0.0 as Real; FIT_CAP];
    let mut x_buf = [0.0 as Real; FIT_CAP];
    let mut n = 0usize;
    let mut unsaturated = 0usize;
    for i in lo..=hi {
        let x = *profile.get(i)?;
        if !x.is_finite() {
            return None;
        }
        unsaturated += usize::from(x < saturation);
        *t_buf.get_mut(n)? = i as Real - peak as Real;
        *x_buf.get_mut(n)? = x;
        n += 1;
    }
    let (t, x) = (t_buf.get(..n)?, x_buf.get(..n)?);
    if unsaturated < 3 {
        return None;
    }
    // Clipped model value and whether it is clipped.
    let model = |a: Real, mu: Real, s: Real, ti: Real| -> (Real, Real, bool) {
        let d = ti - mu;
        let e = Float::exp(-0.5 * d * d / (s * s));
        let m = base + a * e;
        if m >= saturation {
            (saturation, e, true)
        } else {
            (m, e, false)
        }
    };
    let sse = |a: Real, mu: Real, s: Real| -> Real {
        t.iter()
            .zip(x)
            .map(|(&ti, &xi)| {
                let r = xi - model(a, mu, s, ti).0;
                r * r
            })
            .sum()
    };
    let (mut a, mut mu, mut s) = (a0, mu0, s0);
    let mut cost = sse(a, mu, s);
    for _ in 0..GN_ITERATIONS {
        let mut jtj = [[0.0 as Real; 3]; 3];
        let mut jtr = [0.0 as Real; 3];
        for (&ti, &xi) in t.iter().zip(x) {
            let (m, e, clipped) = model(a, mu, s, ti);
            if clipped {
                continue;
            }
            let d = ti - mu;
            let ae = a * e;
            let j = [e, ae * d / (s * s), ae * d * d / (s * s * s)];
            let res = xi - m;
            for p in 0..3 {
                jtr[p] += j[p] * res;
                for q in 0..3 {
                    jtj[p][q] += j[p] * j[q];
                }
            }
        }
        let step = solve3(jtj, jtr)?;
        let mut h = 1.0 as Real;
        let mut improved = false;
        for _ in 0..5 {
            let (na, nmu, ns) = (a + h * step[0], mu + h * step[1], s + h * step[2]);
            if ns > 0.0 && na > 0.0 {
                let nc = sse(na, nmu, ns);
                if nc < cost {
                    (a, mu, s, cost) = (na, nmu, ns, nc);
                    improved = true;
                    break;
                }
            }
            h *= 0.5;
        }
        if !improved {
            break;
        }
    }
    if !(mu.is_finite() && s.is_finite() && a.is_finite()) || Float::abs(mu) > reach as Real {
        return None;
    }
    Some((mu, s, a, n as u8))
}

#[cfg(test)]
mod tests;
