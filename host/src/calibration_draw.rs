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

use crate::calibrate::reference::{refine_planes, ReferenceView};
use crate::capture::Capture;
use crate::simulate::simulate;
use crate::simulate::sphere_corpus::reference_ball_spec;
use crate::simulate::wall_corpus::reference_wall_spec;

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

/// Views per reference session ([`reference_ball_spec`], [`reference_wall_spec`]).
pub const VIEWS_PER_SESSION: u64 = 6;

/// The reference a session views.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReferenceKind {
    /// The 145 mm matt ball, on the two-plane head (`tangent calibrate ball`).
    Ball,
    /// A flat plaster wall, on the two-plane head or (`crossing`) the three-line head
    /// (`tangent calibrate wall`).
    Wall {
        /// The head with the crossing line.
        crossing: bool,
    },
}

/// Rendered sessions of a reference, each a unit's `tangent calibrate ball` or `wall`
/// (`docs/calibration.md`, sections 12 and 13).
#[derive(Debug)]
pub struct ReferenceSessions {
    kind: ReferenceKind,
    head: Calibration,
    sessions: Vec<Vec<Capture>>,
}

impl ReferenceSessions {
    /// `count` sessions (≥ 1) of `kind`, each of [`VIEWS_PER_SESSION`] views with its own
    /// noise.
    pub fn render(kind: ReferenceKind, count: u64) -> anyhow::Result<ReferenceSessions> {
        use rayon::prelude::*;
        let spec = |i: u64, session: u64| match kind {
            ReferenceKind::Ball => reference_ball_spec(i, session),
            ReferenceKind::Wall { crossing } => reference_wall_spec(i, session, crossing),
        };
        let head = spec(0, 0).calibration;
        let sessions = (0..count.max(1))
            .into_par_iter()
            .map(|session| {
                (0..VIEWS_PER_SESSION)
                    .map(|i| {
                        simulate(&spec(i, session)).map(|(c, _)| c).map_err(|e| {
                            anyhow::anyhow!("reference session {session}, view {i}: {e}")
                        })
                    })
                    .collect::<anyhow::Result<Vec<Capture>>>()
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        Ok(ReferenceSessions {
            kind,
            head,
            sessions,
        })
    }

    /// `calibration` (off by a draw) refined on session `seed mod count` as `tangent
    /// calibrate ball` or `wall` does, its prior `noise`'s calibration σ; `None` when the
    /// calibration is of another head than the sessions were rendered with (its number of
    /// planes), which the sessions cannot refine.
    pub fn refine(
        &self,
        calibration: &Calibration,
        noise: &NoiseModel,
        seed: u64,
    ) -> anyhow::Result<Option<Calibration>> {
        if calibration.planes.len() != self.head.planes.len() {
            return Ok(None);
        }
        let session = &self.sessions[(seed % self.sessions.len() as u64) as usize];
        // A view the solver refuses with this calibration is left out, as the command skips
        // it (three are needed).
        let views: Vec<ReferenceView> = session
            .iter()
            .enumerate()
            .filter_map(|(i, c)| {
                let name = format!("reference view {i}");
                match self.kind {
                    ReferenceKind::Ball => ReferenceView::of_ball(c, calibration, &name),
                    ReferenceKind::Wall { .. } => ReferenceView::of_wall(c, calibration, &name),
                }
                .ok()
            })
            .collect();
        let fit = refine_planes(calibration, &views, noise, None)
            .map_err(|e| anyhow::anyhow!("seed {seed}: {e}"))?;
        Ok(Some(fit.calibration))
    }
}

/// Which calibration an evaluation measures with.
#[derive(Debug, Clone, Copy)]
pub enum CalibrationUsed<'a> {
    /// The exact one each capture was rendered with (only the random σ is exercised).
    Exact,
    /// The exact one off by a draw of the calibration σ ([`drawn`]).
    Drawn,
    /// The drawn one refined on a reference session ([`ReferenceSessions::refine`]) where
    /// the head is the sessions' (a one-plane head, which no reference can refine, keeps
    /// the drawn one).
    Refined(&'a ReferenceSessions),
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
            CalibrationUsed::Refined(sessions) => {
                match sessions.refine(&drawn.calibration, noise, seed)? {
                    Some(calibration) => Ok(Some(Capture {
                        calibration,
                        ..drawn
                    })),
                    None if drawn.calibration.planes.len() < 2 => Ok(Some(drawn)),
                    None => anyhow::bail!(
                        "seed {seed}: a {}-plane head; the reference sessions were rendered \
                         with the {}-plane head",
                        drawn.calibration.planes.len(),
                        sessions.head.planes.len()
                    ),
                }
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

    /// What an evaluation measures with under `--ball-sessions`: a two-plane capture's drawn
    /// calibration refined (its planes' relative tilt nearer the truth than the draw), a
    /// one-plane capture's left drawn (no reference refines one plane), and a capture of
    /// another head refused with both heads named.
    #[test]
    fn the_sessions_refine_their_own_head_and_leave_one_plane_drawn() {
        let sessions = ReferenceSessions::render(ReferenceKind::Ball, 1).unwrap();
        let noise = NoiseModel {
            focal_px: 0.0,
            ..NoiseModel::reference()
        };
        let capture = sessions.sessions[0][2].clone();
        let truth = capture.calibration.clone();
        let used = CalibrationUsed::Refined(&sessions);
        let relative =
            |c: &Calibration| c.planes[1].baseline_tilt().1 - c.planes[0].baseline_tilt().1;
        let seed = 5;
        let drawn_cal = drawn(&truth, &noise, seed).unwrap();
        let refined = used.apply(&capture, &noise, seed).unwrap().unwrap();
        let before = (relative(&drawn_cal) - relative(&truth)).abs();
        let after = (relative(&refined.calibration) - relative(&truth)).abs();
        assert!(after < 0.5 * before, "{before} → {after}");

        let one = Calibration::new(truth.id, truth.camera, &truth.planes[..1]).unwrap();
        let one_plane = Capture {
            calibration: one.clone(),
            ..capture.clone()
        };
        let kept = used.apply(&one_plane, &noise, seed).unwrap().unwrap();
        assert_eq!(kept.calibration, drawn(&one, &noise, seed).unwrap());

        let three = crate::simulate::rig::three_plane_calibration();
        let other_head = Capture {
            calibration: three,
            ..capture
        };
        let err = used
            .apply(&other_head, &noise, seed)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("3-plane head") && err.contains("2-plane head"),
            "{err}"
        );
    }
}
