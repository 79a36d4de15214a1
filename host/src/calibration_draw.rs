//! A calibration as a real unit's would be: the exact one of a simulated capture, off by a
//! draw from the calibration uncertainties the error model states (`NoiseModel`'s `e`, `f`
//! and `δ` σ; `docs/error-model.md`, "Calibration errors"). An evaluation that measures
//! with it checks a reading's whole stated σ, calibration term included — with the exact
//! calibration only the random part is exercised (`docs/accuracy.md`, "Spheres").

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;
use tangent_core::calibration::Calibration;
use tangent_core::laser_plane::LaserPlane;
use tangent_core::noise::NoiseModel;

use crate::calibrate::ball::{refine_planes, BallView};
use crate::capture::Capture;
use crate::simulate::rig::two_plane_calibration;
use crate::simulate::simulate;
use crate::simulate::sphere_corpus::reference_ball_spec;

/// `calibration` off by one draw from `noise`'s calibration σ, seeded by `seed` (a stream of
/// its own: the capture's frames do not depend on it). The focal length is the camera's,
/// common to every plane (`fx` and `fy` scaled together); each plane's baseline `e` and tilt
/// `δ` are calibrated from its own board poses, so each draws its own errors. The roll
/// and everything else stay exact.
pub fn drawn(
    calibration: &Calibration,
    noise: &NoiseModel,
    seed: u64,
) -> Result<Calibration, String> {
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xCA11_B5A7_0000_0000);
    let mut unit = || -> f64 { StandardNormal.sample(&mut rng) };
    let mut out = calibration.clone();
    let scale = 1.0 + noise.focal_px * unit() / calibration.camera.fx;
    out.camera.fx *= scale;
    out.camera.fy *= scale;
    for (k, plane) in out.planes.iter_mut().enumerate() {
        let (e, delta) = plane.baseline_tilt();
        let roll = plane.roll();
        let e = e + noise.baseline * unit();
        let delta = delta + noise.tilt * unit();
        *plane = LaserPlane::from_baseline_tilt_roll(e, delta, roll)
            .map_err(|err| format!("plane {k} off by its calibration σ: {err}"))?;
    }
    Ok(out)
}

/// `capture` with its calibration replaced by [`drawn`] (seed `seed`): what the evaluations
/// measure with `--calibration-errors`.
pub fn with_drawn(capture: Capture, noise: &NoiseModel, seed: u64) -> anyhow::Result<Capture> {
    let calibration = drawn(&capture.calibration, noise, seed)
        .map_err(|e| anyhow::anyhow!("seed {seed}: {e}"))?;
    Ok(Capture {
        calibration,
        ..capture
    })
}

/// Views per ball-calibration session ([`crate::simulate::sphere_corpus::reference_ball_spec`]).
pub const VIEWS_PER_SESSION: u64 = 6;

/// Rendered sessions of the reference ball on the two-plane head, each a unit's
/// `tangent calibrate ball` (`docs/calibration.md`, section 12).
#[derive(Debug)]
pub struct BallSessions {
    sessions: Vec<Vec<Capture>>,
}

impl BallSessions {
    /// `count` sessions (≥ 1), each of [`VIEWS_PER_SESSION`] views with its own noise.
    pub fn render(count: u64) -> anyhow::Result<BallSessions> {
        use rayon::prelude::*;
        let sessions = (0..count.max(1))
            .into_par_iter()
            .map(|session| {
                (0..VIEWS_PER_SESSION)
                    .map(|i| {
                        simulate(&reference_ball_spec(i, session))
                            .map(|(c, _)| c)
                            .map_err(|e| anyhow::anyhow!("ball session {session}, view {i}: {e}"))
                    })
                    .collect::<anyhow::Result<Vec<Capture>>>()
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        Ok(BallSessions { sessions })
    }

    /// `calibration` (a two-plane head's, off by a draw) refined on session `seed mod count`
    /// as `tangent calibrate ball` does, its prior `noise`'s calibration σ. Errors: a
    /// calibration of another head than the sessions were rendered with.
    pub fn refine(
        &self,
        calibration: &Calibration,
        noise: &NoiseModel,
        seed: u64,
    ) -> anyhow::Result<Calibration> {
        let session = &self.sessions[(seed % self.sessions.len() as u64) as usize];
        let head = two_plane_calibration();
        if calibration.planes.len() != head.planes.len() {
            anyhow::bail!(
                "seed {seed}: {} planes; the ball sessions were rendered with the {}-plane head",
                calibration.planes.len(),
                head.planes.len()
            );
        }
        // A view the sphere solver refuses with this calibration is left out, as
        // `tangent calibrate ball` skips it (three are needed).
        let views: Vec<BallView> = session
            .iter()
            .enumerate()
            .filter_map(|(i, c)| BallView::measure(c, calibration, &format!("ball view {i}")).ok())
            .collect();
        let fit = refine_planes(calibration, &views, noise, None)
            .map_err(|e| anyhow::anyhow!("seed {seed}: {e}"))?;
        Ok(fit.calibration)
    }
}

/// Which calibration an evaluation measures with.
#[derive(Debug, Clone, Copy)]
pub enum CalibrationUsed<'a> {
    /// The exact one each capture was rendered with (only the random σ is exercised).
    Exact,
    /// The exact one off by a draw of the calibration σ ([`drawn`]).
    Drawn,
    /// The drawn one refined on a reference-ball session ([`BallSessions::refine`]) where
    /// the head has two planes; a one-plane head keeps the drawn one (a ball needs two).
    BallRefined(&'a BallSessions),
}

impl CalibrationUsed<'_> {
    /// `capture` with the calibration to measure it with (seed `seed`'s draw); `None` for
    /// [`CalibrationUsed::Exact`] (measure the capture as it is).
    pub fn apply(
        &self,
        capture: &Capture,
        noise: &NoiseModel,
        seed: u64,
    ) -> anyhow::Result<Option<Capture>> {
        let drawn = match self {
            CalibrationUsed::Exact => return Ok(None),
            _ => with_drawn(capture.clone(), noise, seed)?,
        };
        match self {
            CalibrationUsed::BallRefined(sessions) if drawn.calibration.planes.len() >= 2 => {
                let calibration = sessions.refine(&drawn.calibration, noise, seed)?;
                Ok(Some(Capture {
                    calibration,
                    ..drawn
                }))
            }
            _ => Ok(Some(drawn)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With no calibration σ the drawn calibration is the exact one (the planes rebuilt from
    /// their `e`, `δ` and roll); with the reference σ the draws scatter by those σ.
    #[test]
    fn the_draws_scatter_by_the_stated_calibration_sigma() {
        let cal = Calibration::reference_design();
        let exact = NoiseModel {
            baseline: 0.0,
            focal_px: 0.0,
            tilt: 0.0,
            ..NoiseModel::reference()
        };
        let same = drawn(&cal, &exact, 7).unwrap();
        assert_eq!(same.camera.fx, cal.camera.fx);
        for (a, b) in same.planes.iter().zip(cal.planes.iter()) {
            assert!((a.normal - b.normal).norm() < 1e-12, "{a:?} {b:?}");
            assert!((a.offset - b.offset).abs() < 1e-12);
        }
        let noise = NoiseModel::reference();
        let n = 2000;
        let (mut fx2, mut e2, mut d2) = (0.0, 0.0, 0.0);
        for seed in 0..n {
            let c = drawn(&cal, &noise, seed).unwrap();
            fx2 += (c.camera.fx - cal.camera.fx).powi(2);
            let (e, d) = c.planes[1].baseline_tilt();
            let (e0, d0) = cal.planes[1].baseline_tilt();
            e2 += (e - e0).powi(2);
            d2 += (d - d0).powi(2);
        }
        let rms = |s: f64| (s / n as f64).sqrt();
        // 2000 draws: the RMS is within ≈ 5 % of the σ (3.2 standard errors of 1.6 %).
        assert!(
            (rms(fx2) / noise.focal_px - 1.0).abs() < 0.05,
            "{}",
            rms(fx2)
        );
        assert!((rms(e2) / noise.baseline - 1.0).abs() < 0.05, "{}", rms(e2));
        assert!((rms(d2) / noise.tilt - 1.0).abs() < 0.05, "{}", rms(d2));
    }
}
