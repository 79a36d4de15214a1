//! Mean profile depth (ISO 13473-1:2019) of a road profile, and microtexture indicators on one
//! macrotexture peak (`docs/road.md`, "Mean profile depth" and "Microtexture").
//!
//! From the profile of [`super::road_profile`] (samples `(s, h)`, drop-outs NaN):
//!
//! 1. drop-out share of each segment (refused above 10 %); drop-outs corrected explicitly:
//!    held at the first / last valid height at the ends, linear in position inside;
//! 2. resampling to `Δ` = 0.5 mm by averaging the samples of each bin `((k−1)Δ, kΔ]`
//!    (positions from the window start);
//! 3. spike removal: a jump `|h_{k+1} − h_k| ≥ α·Δ` marks both samples; they are corrected
//!    like drop-outs (refused above 5 %);
//! 4. the standard's low-pass filter: second-order Butterworth, cut-off wavelength 2.4 mm,
//!    run forwards and backwards (zero phase), odd extension of 3·(2·1 + 1) = 9 samples at
//!    each end and the filter's step-response steady state as initial condition;
//! 5. 100 mm segments; in each, the regression line removed (slope suppression), then
//!    `MSD = (peak of first half + peak of second half) / 2 − mean`;
//! 6. `MPD` = mean MSD of the valid segments, `ETD = 0.2 mm + 0.8·MPD`.

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Real, Vec2, PI};

use super::road_profile::{is_dropout, RoadError, MAX_DROPOUT_FRACTION};

/// Settings of the MPD computation (defaults: ISO 13473-1:2019).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpdParams {
    /// Resampling interval Δ (metres; 0.5 mm).
    pub spacing: Real,
    /// Segment length (metres; 100 mm).
    pub segment_length: Real,
    /// Cut-off wavelength of the low-pass filter (metres; 2.4 mm).
    pub lowpass_cutoff: Real,
    /// Spike threshold as a multiple α of Δ (3).
    pub spike_alpha: Real,
    /// Largest spike share of a valid segment (5 %).
    pub max_spike_fraction: Real,
    /// Half-width of the window about the chosen macrotexture peak for the microtexture
    /// indicators (metres; 2 mm).
    pub micro_half_window: Real,
    /// Upper wavelength of the microtexture (metres; 0.5 mm).
    pub micro_cutoff: Real,
}

impl Default for MpdParams {
    fn default() -> Self {
        MpdParams {
            spacing: 0.5e-3,
            segment_length: 0.1,
            lowpass_cutoff: 2.4e-3,
            spike_alpha: 3.0,
            max_spike_fraction: 0.05,
            micro_half_window: 2.0e-3,
            micro_cutoff: 0.5e-3,
        }
    }
}

/// One segment's depth.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SegmentDepth {
    /// Start of the segment along the line (metres).
    pub start: Real,
    /// Mean segment depth (metres).
    pub msd: Real,
    /// The peak of each half `(s, h)` after slope suppression (metres).
    pub peaks: [Vec2; 2],
    /// Drop-out share of the segment's raw samples.
    pub dropout_fraction: Real,
    /// Spike share of the segment's resampled samples.
    pub spike_fraction: Real,
    /// Within the standard's drop-out and spike limits.
    pub valid: bool,
}

/// The MPD of a profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanProfileDepth {
    /// Segments evaluated (written to the caller's slice).
    pub segments: usize,
    /// Valid segments among them.
    pub valid_segments: usize,
    /// Mean profile depth (metres): the mean MSD of the valid segments.
    pub mpd: Real,
    /// Estimated texture depth `0.2 mm + 0.8·MPD` (metres).
    pub etd: Real,
    /// Resampled samples (in the caller's slice).
    pub resampled: usize,
    /// Spikes removed.
    pub spikes: usize,
}

/// Microtexture indicators on one macrotexture peak.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Microtexture {
    /// Position of the peak (metres along the line).
    pub peak: Real,
    /// RMS height of the wavelengths below `micro_cutoff` within the window (metres).
    pub rms_height: Real,
    /// Curvature at the peak's top (1/m, positive convex): least-squares parabola over
    /// `± micro_cutoff` about the highest raw sample.
    pub curvature: Real,
    /// Raw samples used.
    pub samples: usize,
}

/// `ETD = 0.2 mm + 0.8·MPD` (ISO 13473-1, metres).
pub fn estimated_texture_depth(mpd: Real) -> Real {
    0.2e-3 + 0.8 * mpd
}

/// Step 1: `heights` ← the profile's heights with drop-outs corrected (held at the ends,
/// linear in position inside). Returns the number of drop-outs corrected.
pub fn correct_dropouts(profile: &[Vec2], heights: &mut [Real]) -> Result<usize, RoadError> {
    let n = profile.len();
    let heights = take(heights, n)?;
    for (h, p) in heights.iter_mut().zip(profile) {
        *h = p.y;
    }
    let mut previous: Option<usize> = None;
    let mut missing = 0;
    for i in 0..n {
        if is_dropout(&profile[i]) {
            missing += 1;
            continue;
        }
        let from = previous.unwrap_or(i);
        for j in from + 1..i {
            let t = (profile[j].x - profile[from].x) / (profile[i].x - profile[from].x);
            heights[j] = profile[from].y + t * (profile[i].y - profile[from].y);
        }
        if previous.is_none() {
            heights[..i].fill(profile[i].y);
        }
        previous = Some(i);
    }
    match previous {
        Some(last) => heights[last + 1..].fill(profile[last].y),
        None => {
            return Err(RoadError::TooManyDropouts {
                fraction: 1.0,
                dropouts: n,
                runs: usize::from(n > 0),
                span: (
                    profile.first().map_or(Real::NAN, |p| p.x),
                    profile.last().map_or(Real::NAN, |p| p.x),
                ),
            })
        }
    }
    Ok(missing)
}

/// Step 2: averages `heights` (at the profile's positions, ascending) into bins
/// `((k−1)Δ, kΔ]` of the position from `start`, `k = 1…`, sample `k − 1` standing for
/// `start + kΔ`; a position exactly at `start` joins bin 1. Empty bins are interpolated
/// like drop-outs ([`fill_gaps`]). Returns the number of resampled samples (up to the last
/// occupied bin) and of empty bins filled.
pub fn resample(
    profile: &[Vec2],
    heights: &[Real],
    start: Real,
    length: Real,
    spacing: Real,
    out: &mut [Real],
) -> Result<(usize, usize), RoadError> {
    if !(spacing > 0.0) || !(length > 0.0) || !start.is_finite() {
        return Err(RoadError::InvalidParameter("spacing"));
    }
    // A bin count within 1e-6 of an integer is that integer (100 mm / 0.5 mm = 200).
    let bins = (length / spacing - 1e-6).ceil() as usize;
    let out = take(out, bins)?;
    out.fill(Real::NAN);
    let bin_of = |s: Real| -> Option<usize> {
        let k = ((s - start) / spacing - 1e-9).ceil().max(1.0);
        (s >= start && k <= bins as Real).then_some(k as usize - 1)
    };
    let (mut current, mut sum, mut count) = (None, 0.0, 0.0);
    let mut last = None;
    for (p, h) in profile.iter().zip(heights) {
        let b = bin_of(p.x);
        if b != current {
            if let Some(c) = current {
                out[c] = sum / count;
                last = Some(c);
            }
            (current, sum, count) = (b, 0.0, 0.0);
        }
        sum += *h;
        count += 1.0;
    }
    if let Some(c) = current {
        out[c] = sum / count;
        last = Some(last.map_or(c, |l: usize| l.max(c)));
    }
    let n = last.ok_or(RoadError::TooShort { length: 0.0 })? + 1;
    let filled = fill_gaps(&mut out[..n]);
    Ok((n, filled))
}

/// Replaces each NaN of evenly spaced `values` by linear interpolation between its valid
/// neighbours, or by the nearest valid value at the ends; returns how many it replaced
/// (all NaN: none replaced, the NaNs stay).
pub fn fill_gaps(values: &mut [Real]) -> usize {
    let mut previous: Option<usize> = None;
    let mut filled = 0;
    for i in 0..values.len() {
        if !values[i].is_finite() {
            continue;
        }
        match previous {
            Some(p) => {
                for j in p + 1..i {
                    let t = (j - p) as Real / (i - p) as Real;
                    values[j] = values[p] + t * (values[i] - values[p]);
                    filled += 1;
                }
            }
            None => {
                let first = values[i];
                values[..i].fill(first);
                filled += i;
            }
        }
        previous = Some(i);
    }
    if let Some(p) = previous {
        let last = values[p];
        filled += values.len() - p - 1;
        values[p + 1..].fill(last);
    }
    filled
}

/// Step 3: marks (NaN in `marks`, else the height) the samples on either side of a jump
/// `≥ threshold` and corrects them like drop-outs ([`fill_gaps`]). Returns the number of
/// spikes.
pub fn remove_spikes(
    heights: &mut [Real],
    threshold: Real,
    marks: &mut [Real],
) -> Result<usize, RoadError> {
    let n = heights.len();
    let marks = take(marks, n)?;
    let mut spikes = 0;
    for i in 0..n {
        let jump_before = i > 0 && (heights[i] - heights[i - 1]).abs() >= threshold;
        let jump_after = i + 1 < n && (heights[i + 1] - heights[i]).abs() >= threshold;
        let spike = jump_before || jump_after;
        spikes += usize::from(spike);
        marks[i] = if spike { Real::NAN } else { heights[i] };
    }
    if spikes > 0 {
        heights.copy_from_slice(marks);
        if fill_gaps(heights) == 0 {
            return Err(RoadError::TooManySpikes { fraction: 1.0 });
        }
    }
    Ok(spikes)
}

/// A second-order section `b0 + b1 z⁻¹ + b2 z⁻²` over `1 + a1 z⁻¹ + a2 z⁻²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Biquad {
    /// Numerator.
    pub b: [Real; 3],
    /// Denominator `a1`, `a2` (`a0` = 1).
    pub a: [Real; 2],
}

impl Biquad {
    /// The second-order Butterworth low-pass of cut-off wavelength `cutoff` on samples
    /// `spacing` apart (bilinear transform, pre-warped: `K = tan(π Δ / λc)`).
    pub fn butterworth_lowpass(spacing: Real, cutoff: Real) -> Biquad {
        let k = (PI * spacing / cutoff).tan();
        let r2 = sqrt(2.0);
        let norm = 1.0 + r2 * k + k * k;
        let b0 = k * k / norm;
        Biquad {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) / norm, (1.0 - r2 * k + k * k) / norm],
        }
    }

    /// Noise gain `G = Σ g_k²` of the zero-phase (forward–backward) filter's impulse
    /// response `g`: white noise of variance σ² leaves it with `G σ²`. `g` is the
    /// autocorrelation of the one-way response `h`, computed over 64 samples (the poles'
    /// radius ≤ 0.6 for `Δ/λc ≥ 0.1` leaves < 1e-12 beyond).
    pub fn noise_gain(&self) -> Real {
        const N: usize = 64;
        let mut h = [0.0 as Real; N];
        let mut z = [0.0; 2];
        for (k, v) in h.iter_mut().enumerate() {
            *v = self.step(&mut z, if k == 0 { 1.0 } else { 0.0 });
        }
        let mut gain = 0.0;
        for lag in 0..N {
            let g: Real = (0..N - lag).map(|k| h[k] * h[k + lag]).sum();
            gain += if lag == 0 { g * g } else { 2.0 * g * g };
        }
        gain
    }

    /// Transposed direct-form state after a unit step has settled (output = DC gain).
    fn step_state(&self) -> [Real; 2] {
        let gain = (self.b[0] + self.b[1] + self.b[2]) / (1.0 + self.a[0] + self.a[1]);
        let z2 = self.b[2] - self.a[1] * gain;
        let z1 = self.b[1] - self.a[0] * gain + z2;
        [z1, z2]
    }

    fn step(&self, z: &mut [Real; 2], x: Real) -> Real {
        let y = self.b[0] * x + z[0];
        z[0] = self.b[1] * x - self.a[0] * y + z[1];
        z[1] = self.b[2] * x - self.a[1] * y;
        y
    }
}

/// Samples of odd extension at each end of the zero-phase filter (3 × (2·sections + 1)).
pub const FILTER_PAD: usize = 9;

/// Step 4: zero-phase filtering in place (forwards, then backwards), each pass started in
/// the steady state of its first input, over the odd extension of [`FILTER_PAD`] samples.
pub fn filter_zero_phase(filter: &Biquad, x: &mut [Real]) -> Result<(), RoadError> {
    let n = x.len();
    if n <= FILTER_PAD {
        return Err(RoadError::TooShort { length: 0.0 });
    }
    let unit = filter.step_state();
    let (first, last) = (x[0], x[n - 1]);
    let pre = |j: usize| 2.0 * first - x[FILTER_PAD - j];
    let mut pre_values = [0.0; FILTER_PAD];
    for (j, v) in pre_values.iter_mut().enumerate() {
        *v = pre(j);
    }
    let mut post = [0.0; FILTER_PAD];
    for (j, v) in post.iter_mut().enumerate() {
        *v = 2.0 * last - x[n - 2 - j];
    }
    // Forward over pre-pad, signal, post-pad.
    let mut z = [unit[0] * pre_values[0], unit[1] * pre_values[0]];
    for v in pre_values {
        filter.step(&mut z, v);
    }
    for v in x.iter_mut() {
        *v = filter.step(&mut z, *v);
    }
    for v in post.iter_mut() {
        *v = filter.step(&mut z, *v);
    }
    // Backward from the end of the post-pad.
    let end = post[FILTER_PAD - 1];
    let mut z = [unit[0] * end, unit[1] * end];
    for v in post.iter().rev() {
        filter.step(&mut z, *v);
    }
    for v in x.iter_mut().rev() {
        *v = filter.step(&mut z, *v);
    }
    Ok(())
}

/// Step 5: the MSD of one segment (heights at positions `start + (k+1)Δ`): slope suppressed
/// in place, then the peaks of the halves against the mean.
pub fn segment_depth(heights: &mut [Real], start: Real, spacing: Real) -> SegmentDepth {
    let n = heights.len();
    let pos = |k: usize| start + (k + 1) as Real * spacing;
    let nf = n as Real;
    let ms = (0..n).map(pos).sum::<Real>() / nf;
    let mh = heights.iter().sum::<Real>() / nf;
    let (mut sss, mut ssh) = (0.0, 0.0);
    for (k, h) in heights.iter().enumerate() {
        sss += (pos(k) - ms) * (pos(k) - ms);
        ssh += (pos(k) - ms) * (h - mh);
    }
    let slope = if sss > 0.0 { ssh / sss } else { 0.0 };
    for (k, h) in heights.iter_mut().enumerate() {
        *h -= mh + slope * (pos(k) - ms);
    }
    let mean = heights.iter().sum::<Real>() / nf;
    let mid = n / 2;
    let peak = |range: core::ops::Range<usize>| {
        let mut best = Vec2::new(pos(range.start), Real::NEG_INFINITY);
        for k in range {
            if heights[k] > best.y {
                best = Vec2::new(pos(k), heights[k]);
            }
        }
        best
    };
    let peaks = [peak(0..mid), peak(mid..n)];
    SegmentDepth {
        start,
        msd: (peaks[0].y + peaks[1].y) / 2.0 - mean,
        peaks,
        dropout_fraction: 0.0,
        spike_fraction: 0.0,
        valid: true,
    }
}

/// The whole chain (steps 1–6) on a profile whose evaluation starts at `start` and spans
/// `length`: `heights` (as long as the profile) receives the drop-out-corrected raw
/// heights, `resampled` the filtered profile (slope-suppressed per segment), `marks` is
/// scratch, `segments` receives each segment's depth. A profile whose every segment is
/// invalid is refused with the reason of the first.
#[allow(clippy::too_many_arguments)]
pub fn mean_profile_depth(
    profile: &[Vec2],
    start: Real,
    length: Real,
    params: &MpdParams,
    heights: &mut [Real],
    resampled: &mut [Real],
    marks: &mut [Real],
    segments: &mut [SegmentDepth],
) -> Result<MeanProfileDepth, RoadError> {
    let spacing = params.spacing;
    let per_segment = (params.segment_length / spacing).round() as usize;
    if per_segment < 2 * FILTER_PAD {
        return Err(RoadError::InvalidParameter("segment_length"));
    }
    correct_dropouts(profile, heights)?;
    let heights = &heights[..profile.len()];
    let (n, _empty) = resample(profile, heights, start, length, spacing, resampled)?;
    let resampled = &mut resampled[..n];
    let spikes = remove_spikes(resampled, params.spike_alpha * spacing, marks)?;
    let spike_marks = &marks[..n];
    let filter = Biquad::butterworth_lowpass(spacing, params.lowpass_cutoff);
    filter_zero_phase(&filter, resampled)?;
    // Segments: complete ones, or a last one at least 90 % long.
    let mut written = 0;
    let mut valid = 0;
    let mut sum = 0.0;
    let mut first_error = None;
    let mut k0 = 0;
    while k0 < n {
        let k1 = (k0 + per_segment).min(n);
        if ((k1 - k0) as Real) < 0.9 * per_segment as Real {
            break;
        }
        let seg_start = start + k0 as Real * spacing;
        let mut seg = segment_depth(&mut resampled[k0..k1], seg_start, spacing);
        let raw = profile
            .iter()
            .filter(|p| p.x > seg_start && p.x <= seg_start + (k1 - k0) as Real * spacing);
        let (mut raw_n, mut raw_drop, mut runs) = (0usize, 0usize, 0usize);
        let mut span = (Real::NAN, Real::NAN);
        let mut previous_dropout = false;
        for p in raw {
            raw_n += 1;
            let dropout = is_dropout(p);
            if dropout {
                raw_drop += 1;
                runs += usize::from(!previous_dropout);
                if raw_drop == 1 {
                    span.0 = p.x;
                }
                span.1 = p.x;
            }
            previous_dropout = dropout;
        }
        seg.dropout_fraction = raw_drop as Real / raw_n.max(1) as Real;
        let spiked = spike_marks[k0..k1]
            .iter()
            .filter(|m| !m.is_finite())
            .count();
        seg.spike_fraction = spiked as Real / (k1 - k0) as Real;
        if seg.dropout_fraction > MAX_DROPOUT_FRACTION {
            seg.valid = false;
            first_error.get_or_insert(RoadError::TooManyDropouts {
                fraction: seg.dropout_fraction,
                dropouts: raw_drop,
                runs,
                span,
            });
        } else if seg.spike_fraction > params.max_spike_fraction {
            seg.valid = false;
            first_error.get_or_insert(RoadError::TooManySpikes {
                fraction: seg.spike_fraction,
            });
        }
        if seg.valid {
            valid += 1;
            sum += seg.msd;
        }
        let slot = segments.get_mut(written).ok_or(RoadError::BufferTooSmall {
            needed: written + 1,
            actual: written,
        })?;
        *slot = seg;
        written += 1;
        k0 = k1;
    }
    if written == 0 {
        return Err(RoadError::TooShort {
            length: n as Real * spacing,
        });
    }
    if valid == 0 {
        return Err(first_error.unwrap_or(RoadError::TooShort { length: 0.0 }));
    }
    let mpd = sum / valid as Real;
    Ok(MeanProfileDepth {
        segments: written,
        valid_segments: valid,
        mpd,
        etd: estimated_texture_depth(mpd),
        resampled: n,
        spikes,
    })
}

/// Microtexture indicators about the macrotexture peak at `peak` (metres along the line),
/// from the drop-out-corrected raw `heights` at the profile's positions: the RMS of
/// `h − (h averaged over ± micro_cutoff / 2)` about its mean within `± micro_half_window`, and the
/// curvature of the parabola fitted over `± micro_cutoff` about the window's highest sample.
pub fn microtexture(
    profile: &[Vec2],
    heights: &[Real],
    peak: Real,
    params: &MpdParams,
) -> Result<Microtexture, RoadError> {
    let half = params.micro_half_window;
    let box_half = params.micro_cutoff / 2.0;
    let pairs = || {
        profile
            .iter()
            .zip(heights)
            .filter(|(p, _)| !is_dropout(p))
            .map(|(p, h)| (p.x, *h))
    };
    let (mut n, mut sum, mut sum2) = (0usize, 0.0, 0.0);
    let mut top = (peak, Real::NEG_INFINITY);
    for (s, h) in pairs().filter(|(s, _)| (s - peak).abs() <= half) {
        let (mut m, mut c) = (0.0, 0.0);
        for (_, hb) in pairs().filter(|(sb, _)| (sb - s).abs() <= box_half) {
            m += hb;
            c += 1.0;
        }
        let r = h - m / c;
        sum += r;
        sum2 += r * r;
        n += 1;
        if h > top.1 {
            top = (s, h);
        }
    }
    if n < 5 {
        return Err(RoadError::TooFewPoints { points: n });
    }
    // Parabola h = c0 + c1 u + c2 u², u = s − s_top, by the normal equations.
    let mut m = [[0.0 as Real; 3]; 3];
    let mut v = [0.0 as Real; 3];
    let mut used = 0;
    for (s, h) in pairs().filter(|(s, _)| (s - top.0).abs() <= params.micro_cutoff) {
        let u = s - top.0;
        let basis = [1.0, u, u * u];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += basis[i] * basis[j];
            }
            v[i] += basis[i] * h;
        }
        used += 1;
    }
    let c2 = solve3(m, v)
        .map(|c| c[2])
        .ok_or(RoadError::TooFewPoints { points: used })?;
    Ok(Microtexture {
        peak: top.0,
        // About the residual's own mean: a crest's curvature κ biases the local mean by
        // κ·w²/6 everywhere alike, which is no microtexture.
        rms_height: sqrt((sum2 / n as Real - (sum / n as Real).powi(2)).max(0.0)),
        curvature: -2.0 * c2,
        samples: n,
    })
}

/// Solves a 3×3 system by Cramer's rule (`None` if singular).
fn solve3(m: [[Real; 3]; 3], v: [Real; 3]) -> Option<[Real; 3]> {
    let det = |a: [[Real; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(m);
    if !(d.abs() > Real::EPSILON * 1e-30) || !d.is_finite() {
        return None;
    }
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let mut a = m;
        for r in 0..3 {
            a[r][c] = v[r];
        }
        *o = det(a) / d;
    }
    Some(out)
}

/// The first `n` entries of a caller buffer, or the error naming the shortfall.
fn take<T>(buffer: &mut [T], n: usize) -> Result<&mut [T], RoadError> {
    let actual = buffer.len();
    buffer
        .get_mut(..n)
        .ok_or(RoadError::BufferTooSmall { needed: n, actual })
}

#[cfg(test)]
mod tests;
