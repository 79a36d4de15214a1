//! The piezo-stage height-scale calibration and the furrow-block validation (`docs/road.md`,
//! "Height-scale calibration" and "Furrow validation"; thesis Figures 12.5–12.6 and
//! 12.8–12.9).

use serde::Serialize;
use tangent_core::real::Vec2;

/// The height-scale fit: measured mean heights against the stage's known steps.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HeightScaleFit {
    /// Known steps (metres).
    pub steps_m: Vec<f64>,
    /// Measured mean heights (metres, uncorrected).
    pub measured_m: Vec<f64>,
    /// Slope of measured on known: the head's height gain.
    pub gain: f64,
    /// Intercept (metres): where the stage's zero sits against the stand-off.
    pub offset_m: f64,
    /// The correction stored in the calibration: `height_scale = 1 / gain`.
    pub height_scale: f64,
    /// Residual of each step after the line (metres).
    pub residuals_m: Vec<f64>,
    /// RMS of the residuals (metres).
    pub residual_rms_m: f64,
}

/// Least-squares line `measured = offset + gain·step`; `None` with fewer than two distinct
/// steps.
pub fn fit_height_scale(steps: &[f64], measured: &[f64]) -> Option<HeightScaleFit> {
    let n = steps.len().min(measured.len());
    if n < 2 {
        return None;
    }
    let nf = n as f64;
    let ms = steps[..n].iter().sum::<f64>() / nf;
    let mm = measured[..n].iter().sum::<f64>() / nf;
    let sss: f64 = steps[..n].iter().map(|s| (s - ms) * (s - ms)).sum();
    if sss <= 0.0 {
        return None;
    }
    let ssm: f64 = steps[..n]
        .iter()
        .zip(&measured[..n])
        .map(|(s, m)| (s - ms) * (m - mm))
        .sum();
    let gain = ssm / sss;
    if gain.is_nan() || gain <= 0.0 {
        return None;
    }
    let offset = mm - gain * ms;
    let residuals: Vec<f64> = steps[..n]
        .iter()
        .zip(&measured[..n])
        .map(|(s, m)| m - (offset + gain * s))
        .collect();
    let rms = (residuals.iter().map(|r| r * r).sum::<f64>() / nf).sqrt();
    Some(HeightScaleFit {
        steps_m: steps[..n].to_vec(),
        measured_m: measured[..n].to_vec(),
        gain,
        offset_m: offset,
        height_scale: 1.0 / gain,
        residuals_m: residuals,
        residual_rms_m: rms,
    })
}

/// A furrow block's depth from a profile: the profile folded on the block's pitch as the
/// instrument sees it (detrended first), the furrow found as the lowest `width`-wide stretch
/// of the fold, and `depth = median(land) − median(floor)` with the floor the furrow's
/// central half-width and the land the stretch from one width to 1.5 widths either side of
/// its centre. The pitch is the block's nominal one rescaled by the instrument's lateral
/// scale: a unit whose stand-off is off by 1 % reads positions 1 % off, which over 25
/// furrows drifts the fold by a whole furrow width and smears it; the scale within ±3 % that
/// gives the sharpest fold (largest variance of its bins) is taken (`docs/road.md`,
/// "Furrow validation").
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FurrowDepth {
    /// Depth (metres).
    pub depth_m: f64,
    /// Phase of the furrow centre within the pitch (metres).
    pub centre_m: f64,
    /// The pitch the profile was folded on (metres): the nominal one in the instrument's
    /// lateral scale.
    pub pitch_m: f64,
    /// The folded profile: phase (metres), mean height (metres), in `BIN` steps.
    pub folded: Vec<(f64, f64)>,
}

/// Bin of the folded profile (metres).
pub const BIN: f64 = 0.05e-3;

/// See [`FurrowDepth`]; drop-outs (NaN) are skipped. `None` with too few samples.
pub fn furrow_depth(profile: &[Vec2], pitch: f64, width: f64) -> Option<FurrowDepth> {
    let valid: Vec<Vec2> = profile
        .iter()
        .copied()
        .filter(|p| p.y.is_finite())
        .collect();
    if valid.len() < 20 || pitch.is_nan() || pitch <= 4.0 * BIN {
        return None;
    }
    // Detrend (regression line).
    let n = valid.len() as f64;
    let ms = valid.iter().map(|p| p.x).sum::<f64>() / n;
    let mh = valid.iter().map(|p| p.y).sum::<f64>() / n;
    let sss: f64 = valid.iter().map(|p| (p.x - ms).powi(2)).sum();
    let ssh: f64 = valid.iter().map(|p| (p.x - ms) * (p.y - mh)).sum();
    let slope = if sss > 0.0 { ssh / sss } else { 0.0 };
    let residual = |p: &Vec2| p.y - mh - slope * (p.x - ms);
    let fold = |pitch: f64| -> Option<Vec<(f64, f64)>> {
        let bins = (pitch / BIN).round() as usize;
        let (mut sum, mut count) = (vec![0.0; bins], vec![0usize; bins]);
        for p in &valid {
            let k = ((p.x.rem_euclid(pitch)) / (pitch / bins as f64)) as usize % bins;
            sum[k] += residual(p);
            count[k] += 1;
        }
        if count.contains(&0) {
            return None;
        }
        Some(
            (0..bins)
                .map(|k| {
                    (
                        (k as f64 + 0.5) * pitch / bins as f64,
                        sum[k] / count[k] as f64,
                    )
                })
                .collect(),
        )
    };
    let sharpness = |f: &[(f64, f64)]| {
        let m = f.iter().map(|b| b.1).sum::<f64>() / f.len() as f64;
        f.iter().map(|b| (b.1 - m).powi(2)).sum::<f64>() / f.len() as f64
    };
    // Lateral scale within ±3 % in 0.05 % steps (a 0.05 % error drifts the fold by 0.025 mm
    // over the 50 mm half-window).
    let (pitch, folded) = (-60..=60)
        .filter_map(|k| {
            let p = pitch * (1.0 + k as f64 * 5e-4);
            fold(p).map(|f| (p, f))
        })
        .max_by(|a, b| sharpness(&a.1).total_cmp(&sharpness(&b.1)))?;
    let bins = folded.len();
    // The furrow: the lowest mean over a `width` stretch (circular).
    let span = ((width / (pitch / bins as f64)).round() as usize).max(1);
    let mean_at = |c: usize| (0..span).map(|j| folded[(c + j) % bins].1).sum::<f64>() / span as f64;
    let start = (0..bins).min_by(|&a, &b| mean_at(a).total_cmp(&mean_at(b)))?;
    let centre = (start as f64 + span as f64 / 2.0) * pitch / bins as f64;
    let phase_distance = |x: f64| {
        let d = (x - centre).rem_euclid(pitch);
        d.min(pitch - d)
    };
    let median = |mut v: Vec<f64>| -> Option<f64> {
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        Some(v[v.len() / 2])
    };
    let floor = median(
        folded
            .iter()
            .filter(|(x, _)| phase_distance(*x) <= width / 4.0)
            .map(|f| f.1)
            .collect(),
    )?;
    let land = median(
        folded
            .iter()
            .filter(|(x, _)| (width..=1.5 * width).contains(&phase_distance(*x)))
            .map(|f| f.1)
            .collect(),
    )?;
    Some(FurrowDepth {
        depth_m: land - floor,
        centre_m: centre.rem_euclid(pitch),
        pitch_m: pitch,
        folded,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_fit_recovers_a_gain_and_its_residuals() {
        let steps: Vec<f64> = (0..=10).map(|k| k as f64 * 1e-4).collect();
        let measured: Vec<f64> = steps.iter().map(|s| 2e-5 + 1.02 * s).collect();
        let f = fit_height_scale(&steps, &measured).unwrap();
        assert!((f.gain - 1.02).abs() < 1e-9 && (f.offset_m - 2e-5).abs() < 1e-12);
        assert!((f.height_scale - 1.0 / 1.02).abs() < 1e-9);
        assert!(f.residual_rms_m < 1e-12);
        assert!(fit_height_scale(&[1e-4, 1e-4], &[0.0, 1e-4]).is_none());
    }

    #[test]
    fn a_rectangular_furrow_train_reads_its_depth() {
        let profile: Vec<Vec2> = (0..700)
            .map(|i| {
                let x = -0.05 + i as f64 * 0.15e-3;
                let phase = (x - 0.3e-3).rem_euclid(4e-3);
                let in_furrow = (phase - 2e-3).abs() < 0.5e-3;
                Vec2::new(x, if in_furrow { -146e-6 } else { 0.0 } + 0.01 * x)
            })
            .collect();
        let f = furrow_depth(&profile, 4e-3, 1e-3).unwrap();
        assert!((f.depth_m - 146e-6).abs() < 1e-6, "{}", f.depth_m);
        assert!((f.centre_m - 2.3e-3).abs() < 0.1e-3, "{}", f.centre_m);
        assert!((f.pitch_m - 4e-3).abs() < 1e-6, "{}", f.pitch_m);
    }

    /// A unit reading positions 1 % short (its stand-off 1 % off): folded on the nominal
    /// pitch the furrows would smear over a furrow's width; the fold finds their pitch.
    #[test]
    fn a_furrow_train_read_at_the_wrong_lateral_scale_keeps_its_depth() {
        let profile: Vec<Vec2> = (0..700)
            .map(|i| {
                let x = -0.05 + i as f64 * 0.15e-3;
                let phase = (x - 0.3e-3).rem_euclid(4e-3);
                let in_furrow = (phase - 2e-3).abs() < 0.5e-3;
                Vec2::new(0.99 * x, if in_furrow { -630e-6 } else { 0.0 })
            })
            .collect();
        let f = furrow_depth(&profile, 4e-3, 1e-3).unwrap();
        assert!((f.depth_m - 630e-6).abs() < 2e-6, "{}", f.depth_m);
        assert!((f.pitch_m - 3.96e-3).abs() < 4e-6, "{}", f.pitch_m);
    }
}
