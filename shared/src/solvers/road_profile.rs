//! The road profile: the laser curve's 3-D points as height against position along the line,
//! in metric road coordinates, with every missing sample marked as a drop-out
//! (`docs/road.md`, "The profile").
//!
//! Road frame of the road head (`docs/hardware.md`, "Road head"): the camera looks straight
//! down at the road, so the road's nominal normal is the optical axis. Position `s` is the
//! camera's `x` (along the laser line); height is
//!
//! ```text
//! h = k · (z_ref − z)          (up = towards the head)
//! ```
//!
//! with `z_ref` the depth at which the laser plane crosses the optical axis (the head's
//! stand-off, [`LaserPlane::axis_crossing`]) and `k` the height-scale correction of the
//! piezo-stage calibration (`docs/road.md`, "Height-scale calibration"; 1 uncalibrated).
//!
//! The pipeline leaves one point per image column that held the curve, ordered by column;
//! a column without a point is a drop-out. They are found from the spacing of the points: a
//! step longer than 1.5 typical steps holds `round(step / typical) − 1` missing samples, and
//! samples missing before the first point or after the last one inside the evaluation
//! window are drop-outs too. A drop-out is a sample whose height is NaN: nothing here
//! invents a height for it ([`crate::solvers::mpd`] corrects drop-outs explicitly, counting
//! them, as ISO 13473-1 prescribes).

use core::fmt;

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{Real, Vec2, Vec3};

/// Why a road profile gives no texture reading (each names what the user should do).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RoadError {
    /// Too few points on the laser line to form a profile.
    TooFewPoints {
        /// Points found.
        points: usize,
    },
    /// A caller-provided buffer is too short for the profile.
    BufferTooSmall {
        /// Entries needed.
        needed: usize,
        /// Entries provided.
        actual: usize,
    },
    /// A parameter is out of its documented domain.
    InvalidParameter(&'static str),
    /// The laser plane does not cross the optical axis in front of the camera: not a road
    /// head calibration.
    NotARoadHead,
    /// More of the profile's samples are drop-outs than ISO 13473-1 allows (10 %).
    TooManyDropouts {
        /// Drop-out share of the evaluation window (0–1).
        fraction: Real,
        /// Drop-out samples (0 when unknown: the wire carries the share alone).
        dropouts: usize,
        /// Separate runs they form: as many as drop-outs when scattered sample by sample
        /// (0 when unknown).
        runs: usize,
        /// Positions of the first and the last drop-out along the line (metres; NaN when
        /// unknown).
        span: (Real, Real),
    },
    /// One contiguous stretch returned no light: a wet (mirror) patch, a hole or an
    /// obstacle shadowing the line.
    DropoutGap {
        /// Position of the gap's start along the line (metres).
        start: Real,
        /// Length of the gap (metres).
        length: Real,
    },
    /// The road is tilted against the head by more than the allowed angle: the head is not
    /// standing on the road.
    Tilted {
        /// Tilt of the profile's regression line (radians).
        angle: Real,
    },
    /// The road is farther from the stand-off than the head's depth range.
    OutOfRange {
        /// Mean height of the profile relative to the stand-off (metres; + nearer).
        height: Real,
    },
    /// More samples were spikes than ISO 13473-1 allows (5 %).
    TooManySpikes {
        /// Spike share of the resampled profile (0–1).
        fraction: Real,
    },
    /// The profile is shorter than one evaluation segment.
    TooShort {
        /// Length covered (metres).
        length: Real,
    },
}

impl fmt::Display for RoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            RoadError::TooFewPoints { points } => write!(
                f,
                "only {points} points on the laser line: no road profile (is the head on the road?)"
            ),
            RoadError::BufferTooSmall { needed, actual } => {
                write!(f, "road profile buffer holds {actual}, {needed} needed")
            }
            RoadError::InvalidParameter(name) => write!(f, "road parameter `{name}` out of range"),
            RoadError::NotARoadHead => write!(
                f,
                "the laser plane does not cross the optical axis ahead: not a road-head calibration"
            ),
            RoadError::TooManyDropouts {
                fraction,
                dropouts,
                runs,
                span: (first, last),
            } => {
                write!(f, "{:.0} % of the profile are drop-outs", fraction * 100.0)?;
                if dropouts > 0 && runs > 0 && first.is_finite() && last.is_finite() {
                    // A mean run under 2 samples is the signature of a dark or porous
                    // surface returning too little light, not of one patch.
                    let how = if 2 * runs > dropouts {
                        "scattered"
                    } else {
                        "grouped"
                    };
                    write!(
                        f,
                        " ({dropouts} samples, {how} in {runs} runs from {:+.1} to {:+.1} mm along the line)",
                        first * 1e3,
                        last * 1e3
                    )?;
                }
                write!(f, "; ISO 13473-1 allows 10 %: profile excluded")
            }
            RoadError::DropoutGap { start, length } => {
                write!(f, "no return over {:.1} mm", length * 1e3)?;
                if start.is_finite() {
                    write!(f, " from {:.1} mm along the line", start * 1e3)?;
                }
                write!(f, ": a wet (mirror) patch or a hole; measure a dry spot")
            }
            RoadError::Tilted { angle } => write!(
                f,
                "the road is tilted {:.1}° against the head: stand the head flat on the road",
                angle.to_degrees()
            ),
            RoadError::OutOfRange { height } => write!(
                f,
                "the road is {:.1} mm {} the head's stand-off: outside its depth range",
                height.abs() * 1e3,
                if height > 0.0 {
                    "nearer than"
                } else {
                    "beyond"
                }
            ),
            RoadError::TooManySpikes { fraction } => write!(
                f,
                "{:.0} % of the profile are spikes (ISO 13473-1 allows 5 %): profile excluded",
                fraction * 100.0
            ),
            RoadError::TooShort { length } => write!(
                f,
                "the profile covers {:.1} mm, less than one 100 mm segment",
                length * 1e3
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for RoadError {}

impl RoadError {
    /// The error as one wire number (the device's failure detail, `docs/protocol.md`): its
    /// kind in bits 0–3, the number its sentence quotes in bits 4–19 (0.1 mm, 0.1°, ‰ or a
    /// count, saturated) and that number's sign in bit 20.
    pub fn wire(&self) -> u32 {
        let q = |x: Real, unit: Real| {
            let v = (x / unit).round();
            // `as` saturates and maps NaN to 0.
            let m = (v.abs() as u32).min(0xFFFF);
            (m << 4) | (u32::from(v < 0.0) << 20)
        };
        match *self {
            RoadError::TooFewPoints { points } => (points.min(0xFFFF) as u32) << 4,
            RoadError::BufferTooSmall { needed, .. } => 1 | (needed.min(0xFFFF) as u32) << 4,
            RoadError::InvalidParameter(_) => 2,
            RoadError::NotARoadHead => 3,
            RoadError::TooManyDropouts { fraction, .. } => 4 | q(fraction, 1e-3),
            RoadError::DropoutGap { length, .. } => 5 | q(length, 1e-4),
            RoadError::Tilted { angle } => 6 | q(angle.to_degrees(), 0.1),
            RoadError::OutOfRange { height } => 7 | q(height, 1e-4),
            RoadError::TooManySpikes { fraction } => 8 | q(fraction, 1e-3),
            RoadError::TooShort { length } => 9 | q(length, 1e-4),
        }
    }

    /// The error a wire number carries ([`RoadError::wire`]'s inverse, to its resolution;
    /// a gap's start, a parameter's name and the drop-outs' count, runs and span do not
    /// travel).
    pub fn from_wire(n: u32) -> Option<RoadError> {
        let magnitude = ((n >> 4) & 0xFFFF) as Real;
        let v = |unit: Real| {
            if n & (1 << 20) != 0 {
                -magnitude * unit
            } else {
                magnitude * unit
            }
        };
        Some(match n & 0xF {
            0 => RoadError::TooFewPoints {
                points: magnitude as usize,
            },
            1 => RoadError::BufferTooSmall {
                needed: magnitude as usize,
                actual: 0,
            },
            2 => RoadError::InvalidParameter("a road parameter"),
            3 => RoadError::NotARoadHead,
            4 => RoadError::TooManyDropouts {
                fraction: v(1e-3),
                dropouts: 0,
                runs: 0,
                span: (Real::NAN, Real::NAN),
            },
            5 => RoadError::DropoutGap {
                start: Real::NAN,
                length: v(1e-4),
            },
            6 => RoadError::Tilted {
                angle: v(0.1).to_radians(),
            },
            7 => RoadError::OutOfRange { height: v(1e-4) },
            8 => RoadError::TooManySpikes { fraction: v(1e-3) },
            9 => RoadError::TooShort { length: v(1e-4) },
            _ => return None,
        })
    }
}

/// How the points become a profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileParams {
    /// Start of the evaluation window along the line (metres, camera `x`).
    pub window_start: Real,
    /// Length of the evaluation window (metres; 0.1 = one ISO 13473-1 segment).
    pub window_length: Real,
    /// Height-scale correction `k` of the piezo calibration (1 uncalibrated).
    pub height_scale: Real,
    /// Largest tilt of the road against the head (radians).
    pub max_tilt: Real,
    /// Largest mean height away from the stand-off (metres): the head's depth range.
    pub max_height: Real,
    /// Longest contiguous drop-out stretch (metres) before the profile is refused as a wet
    /// patch or hole.
    pub max_gap: Real,
}

impl Default for ProfileParams {
    /// One 100 mm segment centred on the axis, no scale correction, 5° tilt, ±15 mm depth
    /// range, 10 mm longest gap (`docs/road.md`, "Bad input").
    fn default() -> Self {
        ProfileParams {
            window_start: -0.05,
            window_length: 0.1,
            height_scale: 1.0,
            max_tilt: 5.0 * crate::real::PI / 180.0,
            max_height: 0.015,
            max_gap: 0.010,
        }
    }
}

/// What [`road_profile`] wrote: `n` samples `(s, h)` (metres) in its output, and counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileSummary {
    /// Samples written (valid and drop-outs) in the evaluation window.
    pub samples: usize,
    /// Drop-out samples among them (height NaN).
    pub dropouts: usize,
    /// Typical spacing of the samples (metres).
    pub spacing: Real,
    /// Mean height of the valid samples (metres, relative to the stand-off).
    pub mean_height: Real,
    /// Tilt of the regression line of `h` on `s` (radians).
    pub tilt: Real,
    /// Longest contiguous drop-out stretch (metres) and where it starts.
    pub longest_gap: (Real, Real),
}

impl ProfileSummary {
    /// Drop-out share of the window (0–1).
    pub fn dropout_fraction(&self) -> Real {
        if self.samples == 0 {
            1.0
        } else {
            self.dropouts as Real / self.samples as Real
        }
    }
}

/// `true` when a profile sample is a drop-out.
pub fn is_dropout(sample: &Vec2) -> bool {
    !sample.y.is_finite()
}

/// The road profile of one laser plane's points (camera frame, ordered by column): writes
/// `(s, h)` samples of the evaluation window into `out`, drop-outs with NaN height, and
/// returns their summary. Refuses (with the reason) a profile mostly missing, with a long
/// gap, tilted against the head or outside its depth range. `steps` is scratch at least as
/// long as `points`.
pub fn road_profile(
    points: &[Vec3],
    z_ref: Real,
    params: &ProfileParams,
    steps: &mut [Real],
    out: &mut [Vec2],
) -> Result<ProfileSummary, RoadError> {
    check_params(params)?;
    if !(z_ref > 0.0) || !z_ref.is_finite() {
        return Err(RoadError::NotARoadHead);
    }
    let (s0, s1) = (
        params.window_start,
        params.window_start + params.window_length,
    );
    // Points inside the window, as (s, h); non-finite points are drop-outs too (skipped).
    let inside = |p: &&Vec3| p.x >= s0 && p.x <= s1 && p.x.is_finite() && p.z.is_finite();
    let n_inside = points.iter().filter(inside).count();
    if n_inside < MIN_POINTS {
        return Err(RoadError::TooFewPoints { points: n_inside });
    }
    let spacing = typical_step(points.iter().filter(inside).map(|p| p.x), steps, 0.5)?;
    // Drop-outs are counted in the image's normalised coordinate `x/z`, where one column is
    // `1/f` whatever the height, against the single-column step: the median of the steps
    // within 1.5× the lower decile — one column even when most columns are dark (drop-outs
    // scattered one column in three would make the median of all steps two columns and
    // hide them).
    let decile = typical_step(points.iter().filter(inside).map(|p| p.x / p.z), steps, 0.1)?;
    // `typical_step` left the `n_inside − 1` steps sorted at the front of `steps`.
    let sorted = &steps[..(n_inside - 1).min(steps.len())];
    let single = sorted.iter().take_while(|&&d| d <= 1.5 * decile).count();
    let column = sorted.get(single / 2).copied().unwrap_or(decile);
    let mut w = Writer {
        out,
        n: 0,
        dropouts: 0,
        runs: 0,
        span: (Real::NAN, Real::NAN),
    };
    let mut gap = Gap::default();
    let mut previous: Option<(Real, Real)> = None;
    for p in points.iter().filter(inside) {
        let h = params.height_scale * (z_ref - p.z);
        // Missing samples before this point: from the window start, or since the previous.
        let (from, missing) = match previous {
            None => (s0 - spacing, missing_before(p.x - s0, spacing)),
            Some((prev, prev_q)) => (prev, missing_between((p.x / p.z - prev_q).abs(), column)),
        };
        let step = (p.x - from) / (missing + 1) as Real;
        for k in 1..=missing {
            w.push(Vec2::new(from + step * k as Real, Real::NAN))?;
        }
        gap.add(from, p.x, missing, spacing);
        w.push(Vec2::new(p.x, h))?;
        previous = Some((p.x, p.x / p.z));
    }
    if let Some((last, _)) = previous {
        let missing = missing_before(s1 - last, spacing);
        for k in 1..=missing {
            w.push(Vec2::new(last + spacing * k as Real, Real::NAN))?;
        }
        gap.add(last, s1 + spacing, missing, spacing);
    }
    let (samples, dropouts, runs, span) = (w.n, w.dropouts, w.runs, w.span);
    let (mean_height, tilt) = regression(&out[..samples]);
    let summary = ProfileSummary {
        samples,
        dropouts,
        spacing,
        mean_height,
        tilt,
        longest_gap: (gap.start, gap.length),
    };
    if gap.length > params.max_gap {
        return Err(RoadError::DropoutGap {
            start: gap.start,
            length: gap.length,
        });
    }
    if summary.dropout_fraction() > MAX_DROPOUT_FRACTION {
        return Err(RoadError::TooManyDropouts {
            fraction: summary.dropout_fraction(),
            dropouts,
            runs,
            span,
        });
    }
    if tilt.abs() > params.max_tilt {
        return Err(RoadError::Tilted { angle: tilt });
    }
    if mean_height.abs() > params.max_height {
        return Err(RoadError::OutOfRange {
            height: mean_height,
        });
    }
    Ok(summary)
}

/// Largest drop-out share of a profile (ISO 13473-1:2019, 7.3: 10 %).
pub const MAX_DROPOUT_FRACTION: Real = 0.10;
/// Fewest points a profile needs.
const MIN_POINTS: usize = 16;

fn check_params(p: &ProfileParams) -> Result<(), RoadError> {
    let ok = |x: Real| x.is_finite() && x > 0.0;
    if !p.window_start.is_finite() {
        return Err(RoadError::InvalidParameter("window_start"));
    }
    for (name, x) in [
        ("window_length", p.window_length),
        ("height_scale", p.height_scale),
        ("max_tilt", p.max_tilt),
        ("max_height", p.max_height),
        ("max_gap", p.max_gap),
    ] {
        if !ok(x) {
            return Err(RoadError::InvalidParameter(name));
        }
    }
    Ok(())
}

/// The `quantile` (0–1) of the steps between consecutive positions: with 0.5 the column
/// footprint, robust to the drop-outs' long steps.
fn typical_step(
    positions: impl Iterator<Item = Real>,
    steps: &mut [Real],
    quantile: Real,
) -> Result<Real, RoadError> {
    let mut n = 0;
    let mut previous: Option<Real> = None;
    for s in positions {
        if let Some(p) = previous {
            let slot = steps.get_mut(n).ok_or(RoadError::BufferTooSmall {
                needed: n + 1,
                actual: n,
            })?;
            *slot = (s - p).abs();
            n += 1;
        }
        previous = Some(s);
    }
    let steps = &mut steps[..n];
    steps.sort_unstable_by(|a, b| a.partial_cmp(b).unwrap_or(core::cmp::Ordering::Equal));
    let rank = ((n as Real * quantile) as usize).min(n.saturating_sub(1));
    let step = steps.get(rank).copied().unwrap_or(0.0);
    if !(step > 0.0) {
        return Err(RoadError::TooFewPoints { points: n + 1 });
    }
    Ok(step)
}

/// Samples missing in a step of `d` between two points `spacing` apart nominally.
fn missing_between(d: Real, spacing: Real) -> usize {
    if d > 1.5 * spacing {
        // `as` saturates; d/spacing is finite here.
        ((d / spacing).round() as usize).saturating_sub(1)
    } else {
        0
    }
}

/// Samples missing over a distance `d` before the first (or after the last) point.
fn missing_before(d: Real, spacing: Real) -> usize {
    // `as` saturates and maps NaN to 0.
    (d / spacing).round().max(0.0) as usize
}

/// The output buffer and its counts.
struct Writer<'a> {
    out: &'a mut [Vec2],
    n: usize,
    dropouts: usize,
    /// Runs of consecutive drop-outs.
    runs: usize,
    /// First and last drop-out position.
    span: (Real, Real),
}

impl Writer<'_> {
    fn push(&mut self, v: Vec2) -> Result<(), RoadError> {
        let actual = self.out.len();
        let slot = self.out.get_mut(self.n).ok_or(RoadError::BufferTooSmall {
            needed: self.n + 1,
            actual,
        })?;
        *slot = v;
        let follows_dropout = self.n > 0 && is_dropout(&self.out[self.n - 1]);
        self.n += 1;
        if is_dropout(&v) {
            self.dropouts += 1;
            self.runs += usize::from(!follows_dropout);
            if self.dropouts == 1 {
                self.span.0 = v.x;
            }
            self.span.1 = v.x;
        }
        Ok(())
    }
}

/// The longest run of drop-outs seen.
#[derive(Default)]
struct Gap {
    start: Real,
    length: Real,
}

impl Gap {
    /// A step from `from` to `to` holding `missing` drop-outs: they cover `to − from − spacing`.
    fn add(&mut self, from: Real, to: Real, missing: usize, spacing: Real) {
        if missing == 0 {
            return;
        }
        let length = to - from - spacing;
        if length > self.length {
            self.length = length;
            self.start = from + spacing / 2.0;
        }
    }
}

/// Mean height and regression tilt of the valid samples.
fn regression(samples: &[Vec2]) -> (Real, Real) {
    let (mut n, mut ms, mut mh) = (0.0, 0.0, 0.0);
    for p in samples.iter().filter(|p| !is_dropout(p)) {
        n += 1.0;
        ms += p.x;
        mh += p.y;
    }
    if n < 2.0 {
        return (0.0, 0.0);
    }
    ms /= n;
    mh /= n;
    let (mut sss, mut ssh) = (0.0, 0.0);
    for p in samples.iter().filter(|p| !is_dropout(p)) {
        sss += (p.x - ms) * (p.x - ms);
        ssh += (p.x - ms) * (p.y - mh);
    }
    let slope = if sss > 0.0 { ssh / sss } else { 0.0 };
    (mh, slope.atan())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn line(n: usize, step: Real, z: impl Fn(Real) -> Real) -> [Vec3; 800] {
        let mut pts = [Vec3::zeros(); 800];
        for (i, p) in pts.iter_mut().enumerate().take(n) {
            let x = -0.06 + step * i as Real;
            *p = Vec3::new(x, 0.0, z(x));
        }
        pts
    }

    #[test]
    fn a_flat_road_at_the_stand_off_has_zero_height_and_no_dropouts() {
        let pts = line(800, 0.15e-3, |_| 0.3);
        let mut steps = [0.0; 800];
        let mut out = [Vec2::zeros(); 900];
        let s = road_profile(&pts, 0.3, &ProfileParams::default(), &mut steps, &mut out).unwrap();
        assert_eq!(s.dropouts, 0);
        assert!(
            (s.samples as Real - 0.1 / 0.15e-3).abs() <= 1.0,
            "{}",
            s.samples
        );
        assert!(s.mean_height.abs() < 1e-12 && s.tilt.abs() < 1e-9);
        assert!((s.spacing - 0.15e-3).abs() < 1e-9);
    }

    #[test]
    fn missing_columns_are_marked_not_filled() {
        let mut pts = line(800, 0.15e-3, |x| 0.3 - 0.001 * (x * 300.0).sin());
        // Drop 20 columns in the middle (3 mm): they come back as NaN samples.
        let kept: usize = 800 - 20;
        pts.copy_within(420..800, 400);
        let mut steps = [0.0; 800];
        let mut out = [Vec2::zeros(); 900];
        let s = road_profile(
            &pts[..kept],
            0.3,
            &ProfileParams::default(),
            &mut steps,
            &mut out,
        )
        .unwrap();
        assert_eq!(s.dropouts, 20);
        let nan = out[..s.samples].iter().filter(|p| is_dropout(p)).count();
        assert_eq!(nan, 20);
        assert!(
            (s.longest_gap.1 - 20.0 * 0.15e-3).abs() < 0.2e-3,
            "{:?}",
            s.longest_gap
        );
        // Positions stay monotonic through the gap.
        assert!(out[..s.samples].windows(2).all(|w| w[1].x > w[0].x));
    }

    #[test]
    fn bad_profiles_are_refused_with_their_reason() {
        let params = ProfileParams::default();
        let mut steps = [0.0; 800];
        let mut out = [Vec2::zeros(); 900];
        // A wet patch: 15 mm with no return.
        let mut pts = line(800, 0.15e-3, |_| 0.3);
        pts.copy_within(500..800, 400);
        let e = road_profile(&pts[..700], 0.3, &params, &mut steps, &mut out).unwrap_err();
        assert!(
            matches!(e, RoadError::DropoutGap { length, .. } if (length - 0.015).abs() < 0.5e-3),
            "{e:?}"
        );
        // Mostly drop-outs: 2 columns of every 10 missing → 20 %.
        let pts = line(800, 0.15e-3, |_| 0.3);
        let mut sparse = [Vec3::zeros(); 800];
        let mut k = 0;
        for (i, p) in pts.iter().enumerate() {
            if i % 10 < 8 {
                sparse[k] = *p;
                k += 1;
            }
        }
        let e = road_profile(&sparse[..k], 0.3, &params, &mut steps, &mut out);
        assert!(
            matches!(e, Err(RoadError::TooManyDropouts { fraction, dropouts, runs, .. })
                if (fraction - 0.2).abs() < 0.01 && runs > 60 && dropouts == 2 * runs),
            "{e:?}"
        );
        // One column in three dark: half the steps are two columns, still counted.
        let mut thirds = [Vec3::zeros(); 800];
        let mut k = 0;
        for (i, p) in pts.iter().enumerate() {
            if i % 3 != 0 {
                thirds[k] = *p;
                k += 1;
            }
        }
        let e = road_profile(&thirds[..k], 0.3, &params, &mut steps, &mut out);
        assert!(
            matches!(e, Err(RoadError::TooManyDropouts { fraction, .. }) if (fraction - 1.0 / 3.0).abs() < 0.01),
            "{e:?}"
        );
        // Scattered (one column in four dark): named with how many, where and the limit.
        let mut scattered = [Vec3::zeros(); 800];
        let mut k = 0;
        for (i, p) in pts.iter().enumerate() {
            if i % 4 != 0 {
                scattered[k] = *p;
                k += 1;
            }
        }
        let e = road_profile(&scattered[..k], 0.3, &params, &mut steps, &mut out).unwrap_err();
        let RoadError::TooManyDropouts {
            dropouts,
            runs,
            span,
            ..
        } = e
        else {
            panic!("{e:?}")
        };
        assert_eq!(runs, dropouts);
        assert!(span.0 < -0.049 && span.1 > 0.049, "{span:?}");
        let text = std::format!("{e}");
        assert!(
            text.contains("25 % of the profile")
                && text.contains("scattered in")
                && text.contains("ISO 13473-1 allows 10 %"),
            "{text}"
        );
        // Tilted 8°.
        let pts = line(800, 0.15e-3, |x| 0.3 + x * (8.0 as Real).to_radians().tan());
        let e = road_profile(&pts, 0.3, &params, &mut steps, &mut out).unwrap_err();
        assert!(
            matches!(e, RoadError::Tilted { angle } if (angle.abs().to_degrees() - 8.0).abs() < 0.1),
            "{e:?}"
        );
        // 30 mm too far.
        let pts = line(800, 0.15e-3, |_| 0.33);
        let e = road_profile(&pts, 0.3, &params, &mut steps, &mut out).unwrap_err();
        assert!(
            matches!(e, RoadError::OutOfRange { height } if height < -0.029),
            "{e:?}"
        );
        assert!(std::format!("{e}").contains("beyond"));
        // Nothing at all.
        let e = road_profile(&[], 0.3, &params, &mut steps, &mut out).unwrap_err();
        assert_eq!(e, RoadError::TooFewPoints { points: 0 });
        // Every refusal travels as one number and reads the same at the other end.
        for e in [
            RoadError::TooManyDropouts {
                fraction: 0.234,
                dropouts: 0,
                runs: 0,
                span: (Real::NAN, Real::NAN),
            },
            RoadError::Tilted { angle: -0.15 },
            RoadError::OutOfRange { height: 0.0213 },
            RoadError::TooFewPoints { points: 7 },
        ] {
            let back = RoadError::from_wire(e.wire()).unwrap();
            assert_eq!(std::format!("{back}"), std::format!("{e}"));
        }
        assert_eq!(RoadError::from_wire(15), None);
        // Not a road head (plane parallel to the axis).
        let e = road_profile(&pts, Real::NAN, &params, &mut steps, &mut out).unwrap_err();
        assert_eq!(e, RoadError::NotARoadHead);
    }
}
