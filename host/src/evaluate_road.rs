//! The road instrument against the simulator's truth (`tangent evaluate --road`, written to
//! `docs/accuracy.md`'s road section): MPD on every surface type (fresh seeds, never used for
//! tuning) beside a naive baseline, the furrow depths, the piezo height-scale calibration of
//! a unit built with a 1 % baseline error, the vertical resolution on a flat target, the
//! cross-check against captif-slp, and the refusals of bad input.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use rayon::prelude::*;
use tangent_core::calibration::Calibration;
use tangent_core::instrument::road::RoadParams;
use tangent_core::laser_plane::LaserPlane;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::real::Vec2;

use crate::measure::measure_road;
use crate::road::crosscheck::{captif_mpd, write_profile_csv};
use crate::road::height_scale::{fit_height_scale, furrow_depth};
use crate::road::{true_profile, RoadOutcome};
use crate::simulate::road_corpus::{
    furrow_spec, piezo_spec, road_spec, tilted_spec, Condition, Surface, FURROW_PITCH, FURROW_WIDTH,
};
use crate::simulate::{simulate, SimSpec};

/// A spec simulated and measured (`calibration`: the one the unit believes, if not the
/// simulation's).
fn run(
    spec: &SimSpec,
    calibration: Option<&Calibration>,
    params: &RoadParams,
) -> Result<RoadOutcome> {
    let (capture, _) = simulate(spec)?;
    Ok(measure_road(
        &capture,
        calibration,
        &PipelineConfig::default(),
        params,
    )?)
}

/// The naive baseline: the raw profile's highest sample minus its mean over the window
/// (no drop-out rule, no filter, no halves, no slope suppression).
pub fn naive_depth(profile: &[Vec2]) -> Option<f64> {
    let v: Vec<f64> = profile
        .iter()
        .map(|p| p.y)
        .filter(|h| h.is_finite())
        .collect();
    if v.is_empty() {
        return None;
    }
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    Some(v.iter().copied().fold(f64::NEG_INFINITY, f64::max) - mean)
}

/// The profiles of each surface type taken as one ISO 13473-1 section: its MPD is the mean of
/// its segments' depths, its truth the mean of theirs (`docs/road.md`, "Ambulatory use").
#[derive(Default)]
struct SurfaceSections {
    /// Per surface (in first-seen order): each profile's reading.
    rows: Vec<(String, Vec<ProfileReading>)>,
}

/// One profile's `(truth, MPD, u)` (metres).
type ProfileReading = (f64, f64, f64);

impl SurfaceSections {
    fn add(&mut self, name: &str, truth: f64, mpd: f64, u: f64) {
        if !(truth.is_finite() && mpd.is_finite()) {
            return;
        }
        match self.rows.iter_mut().find(|(n, _)| n == name) {
            Some((_, v)) => v.push((truth, mpd, u)),
            None => self.rows.push((name.into(), vec![(truth, mpd, u)])),
        }
    }

    /// One row per surface: the section's error and the per-profile spread against the
    /// instrument's own `u` (an honest `u` covers ≈ 95 % of the errors at 2u).
    fn write(&self, doc: &mut String) -> std::fmt::Result {
        writeln!(
            doc,
            "Each surface type as one section (ISO 13473-1: the MPD of a measurement is the mean \
             of its segments' depths; truth likewise). Per-profile SD and coverage: the spread \
             of single 100 mm segments and how many of them lie within 2u of their truth.\n\n\
             | surface | profiles | section truth (mm) | section MPD (mm) | section error (mm) | per-profile SD (mm) | largest single-profile error (mm, absolute) | mean u (mm) | within 2u |\n\
             |---|---|---|---|---|---|---|---|---|"
        )?;
        let (mut covered, mut total) = (0, 0);
        for (name, v) in &self.rows {
            let n = v.len() as f64;
            let errors: Vec<f64> = v.iter().map(|(t, m, _)| m - t).collect();
            let mean_error = errors.iter().sum::<f64>() / n;
            let sd = (errors.iter().map(|e| (e - mean_error).powi(2)).sum::<f64>()
                / (n - 1.0).max(1.0))
            .sqrt();
            let largest = errors.iter().fold(0.0f64, |a, e| a.max(e.abs()));
            let within = v
                .iter()
                .filter(|(t, m, u)| (m - t).abs() <= 2.0 * u)
                .count();
            covered += within;
            total += v.len();
            writeln!(
                doc,
                "| {name} | {} | {:.3} | {:.3} | {:+.3} | {:.3} | {:.3} | {:.3} | {within}/{} |",
                v.len(),
                v.iter().map(|r| r.0).sum::<f64>() / n * 1e3,
                v.iter().map(|r| r.1).sum::<f64>() / n * 1e3,
                mean_error * 1e3,
                sd * 1e3,
                largest * 1e3,
                v.iter().map(|r| r.2).sum::<f64>() / n * 1e3,
                v.len()
            )?;
        }
        writeln!(doc, "\nWithin 2u: **{covered} of {total}** profiles.\n")
    }
}

/// Writes the evaluation as Markdown; `seeds` fresh seeds per surface type from `first_seed`.
pub fn report(first_seed: u64, seeds: u64, repo: &Path, scratch: &Path) -> Result<String> {
    let params = RoadParams::default();
    let mut doc = String::new();
    // --- MPD per surface -------------------------------------------------------------------
    let mut cases = Vec::new();
    for (k, s) in Surface::ALL.iter().enumerate() {
        for i in 0..seeds {
            cases.push((*s, Condition::default(), first_seed + 100 * k as u64 + i));
        }
    }
    for (i, c) in [(true, false), (false, true)].iter().enumerate() {
        for j in 0..seeds {
            cases.push((
                Surface::StoneMastic,
                Condition {
                    wet: c.0,
                    polished: c.1,
                },
                first_seed + 1000 + 100 * i as u64 + j,
            ));
        }
    }
    let outcomes: Vec<_> = cases
        .par_iter()
        .map(|&(s, c, seed)| run(&road_spec(s, c, seed), None, &params).map(|o| (s, c, seed, o)))
        .collect::<Result<_>>()?;
    writeln!(
        doc,
        "### MPD against the true surface\n\n\
         Each row: one fresh simulated profile (road head, speckle on), measured by \
         `tangent_core::instrument::Road`; *truth* is the same ISO 13473-1 chain on the true \
         profile along the laser sheet sampled every 0.02 mm; *naive* is max − mean of the raw \
         profile (no filter, no halves); *± u* the instrument's own 1σ (`docs/road.md`, \
         \"Uncertainty\"). Target: |MPD − truth| ≤ 0.03 mm; captif-slp on the same measured \
         profile within 0.005 mm.\n\n\
         | surface | seed | truth (mm) | MPD (mm) | ± u (mm) | error (mm) | naive error (mm) | drop-outs | captif-slp − ours (mm) |\n\
         |---|---|---|---|---|---|---|---|---|"
    )?;
    let mut files = Vec::new();
    for (i, (.., o)) in outcomes.iter().enumerate() {
        let f = scratch.join(format!("profile-{i}.csv"));
        if !o.profile.is_empty() {
            write_profile_csv(
                &f,
                &o.profile,
                params.profile.window_start,
                params.profile.window_length,
            )?;
        }
        files.push(f);
    }
    let existing: Vec<_> = files.iter().filter(|f| f.exists()).cloned().collect();
    let captif = captif_mpd(repo, &existing)?;
    let mut worst = 0.0f64;
    let mut worst_captif = 0.0f64;
    let mut sections = SurfaceSections::default();
    for (i, (s, c, seed, o)) in outcomes.iter().enumerate() {
        let name = format!(
            "{}{}{}",
            s.name(),
            if c.wet { ", wet" } else { "" },
            if c.polished { ", polished" } else { "" }
        );
        let truth = o.truth_mpd.unwrap_or(f64::NAN);
        let (mpd, u, dropouts) = match &o.result {
            Ok(r) => (
                r.depth.mpd,
                r.uncertainty,
                format!("{:.1} %", 100.0 * r.profile.dropout_fraction()),
            ),
            Err(e) => (f64::NAN, f64::NAN, format!("refused: {e}")),
        };
        sections.add(&name, truth, mpd, u);
        let naive = naive_depth(&o.profile).unwrap_or(f64::NAN);
        let cap = match &captif {
            Ok(m) => m
                .get(&files[i])
                .copied()
                .flatten()
                .map(|v| format!("{:+.6}", (v - mpd) * 1e3))
                .unwrap_or_else(|| "—".into()),
            Err(reason) => format!("skipped: {reason}"),
        };
        if let Ok(m) = &captif {
            if let Some(Some(v)) = m.get(&files[i]) {
                worst_captif = worst_captif.max((v - mpd).abs());
            }
        }
        worst = worst.max((mpd - truth).abs());
        writeln!(
            doc,
            "| {name} | {seed} | {:.3} | {:.3} | {:.3} | {:+.3} | {:+.3} | {dropouts} | {cap} |",
            truth * 1e3,
            mpd * 1e3,
            u * 1e3,
            (mpd - truth) * 1e3,
            (naive - truth) * 1e3
        )?;
    }
    writeln!(
        doc,
        "\nLargest |MPD − truth|: **{:.3} mm**; largest |captif-slp − ours|: **{:.6} mm**.\n",
        worst * 1e3,
        worst_captif * 1e3
    )?;
    sections.write(&mut doc)?;

    // --- Piezo calibration of a unit with a 1 % baseline error -----------------------------
    let believed = crate::simulate::road_corpus::calibration();
    let mut built = believed.clone();
    let p0 = built.planes[0];
    let (e, tilt) = p0.baseline_tilt();
    built.planes[0] = LaserPlane::from_baseline_tilt(e * 1.01, tilt)?;
    let steps: Vec<f64> = (0..=10).map(|k| k as f64 * 0.1e-3).collect();
    let piezo: Vec<_> = steps
        .par_iter()
        .enumerate()
        .map(|(k, &step)| {
            let mut spec = piezo_spec(step, first_seed + 2000 + k as u64);
            spec.calibration = built.clone();
            run(&spec, Some(&believed), &params)
        })
        .collect::<Result<_>>()?;
    let measured: Vec<f64> = piezo
        .iter()
        .map(|o| {
            o.result
                .as_ref()
                .map(|r| r.profile.mean_height)
                .unwrap_or(f64::NAN)
        })
        .collect();
    writeln!(
        doc,
        "### Height-scale calibration on the piezo stage\n\n\
         A unit built with its laser 1 % farther from the camera than its calibration says \
         (101 mm for 100 mm) measures a flat target raised 0–1 mm in 0.1 mm steps.\n"
    )?;
    let fit = fit_height_scale(&steps, &measured);
    let mut flat_rms = Vec::new();
    if let Some(f) = &fit {
        writeln!(
            doc,
            "| step (mm) | measured (mm) | residual (µm) |\n|---|---|---|"
        )?;
        for ((s, m), r) in f.steps_m.iter().zip(&f.measured_m).zip(&f.residuals_m) {
            writeln!(doc, "| {:.1} | {:.4} | {:+.1} |", s * 1e3, m * 1e3, r * 1e6)?;
        }
        writeln!(
            doc,
            "\nGain {:.4} → `height_scale = {:.4}` stored in the calibration (`[road]`); residual RMS {:.1} µm.\n",
            f.gain,
            f.height_scale,
            f.residual_rms_m * 1e6
        )?;
    }
    // Vertical resolution: each flat step's raw profile about its regression line.
    for o in &piezo {
        let v: Vec<Vec2> = o
            .profile
            .iter()
            .copied()
            .filter(|p| p.y.is_finite())
            .collect();
        if let Some(r) = detrended_rms(&v) {
            flat_rms.push(r);
        }
    }
    if !flat_rms.is_empty() {
        let mean = flat_rms.iter().sum::<f64>() / flat_rms.len() as f64;
        let max = flat_rms.iter().copied().fold(0.0, f64::max);
        writeln!(
            doc,
            "### Vertical resolution\n\nRMS of the raw profile (0.15 mm columns) about its regression line on the flat target, {} captures: mean **{:.1} µm**, largest {:.1} µm (target ≤ 50 µm).\n",
            flat_rms.len(),
            mean * 1e6,
            max * 1e6
        )?;
    }

    // --- Furrows -----------------------------------------------------------------------------
    let scale = fit.as_ref().map(|f| f.height_scale).unwrap_or(1.0);
    writeln!(
        doc,
        "### Furrow block\n\n1 mm furrows every 4 mm, measured by the calibrated unit above \
         (`height_scale` applied) and by its uncorrected self; depth from the profile folded on \
         the pitch (`road::height_scale::furrow_depth`), truth by the same rule on the true \
         profile. Targets: ±10 µm at 146 µm, ±15 µm at 630 µm.\n\n\
         | nominal (µm) | seed | truth (µm) | measured (µm) | error (µm) | uncorrected error (µm) |\n|---|---|---|---|---|---|"
    )?;
    let mut corrected = params;
    corrected.profile.height_scale = scale;
    for (k, depth) in [146e-6, 630e-6].iter().enumerate() {
        for i in 0..seeds.max(2) {
            let seed = first_seed + 3000 + 10 * k as u64 + i;
            let mut spec = furrow_spec(*depth, seed);
            spec.calibration = built.clone();
            let (capture, _) = simulate(&spec)?;
            let measure = |p: &RoadParams| -> Result<Option<f64>> {
                let o = measure_road(&capture, Some(&believed), &PipelineConfig::default(), p)?;
                Ok(furrow_depth(&o.profile, FURROW_PITCH, FURROW_WIDTH).map(|f| f.depth_m))
            };
            let m = measure(&corrected)?.unwrap_or(f64::NAN);
            let u = measure(&params)?.unwrap_or(f64::NAN);
            let truth = true_profile(&spec.objects, &built, &params)
                .and_then(|p| furrow_depth(&p, FURROW_PITCH, FURROW_WIDTH))
                .map(|f| f.depth_m)
                .unwrap_or(f64::NAN);
            writeln!(
                doc,
                "| {:.0} | {seed} | {:.1} | {:.1} | {:+.1} | {:+.1} |",
                depth * 1e6,
                truth * 1e6,
                m * 1e6,
                (m - truth) * 1e6,
                (u - truth) * 1e6
            )?;
        }
    }

    // --- Bad input ---------------------------------------------------------------------------
    writeln!(doc, "\n### Bad input\n\n| case | result |\n|---|---|")?;
    let tilted = run(&tilted_spec(10.0, first_seed + 4000), None, &params)?;
    writeln!(doc, "| head tilted 10° | {} |", verdict(&tilted))?;
    let mut lifted = road_spec(
        Surface::DenseAsphalt,
        Condition::default(),
        first_seed + 4001,
    );
    if let Some(crate::truth::Object::Road(r)) = lifted.objects.first_mut() {
        r.distance_m += 0.03;
    }
    let lifted = run(&lifted, None, &params)?;
    writeln!(
        doc,
        "| head lifted 30 mm off the road | {} |",
        verdict(&lifted)
    )?;
    let (mut capture, _) = simulate(&road_spec(
        Surface::StoneMastic,
        Condition {
            wet: true,
            polished: false,
        },
        first_seed + 4002,
    ))?;
    wet_mirror_patch(&mut capture, 330..430);
    let wet = measure_road(&capture, None, &PipelineConfig::default(), &params)?;
    writeln!(
        doc,
        "| wet mirror patch (15 mm without return) | {} |",
        verdict(&wet)
    )?;
    let (mut capture, _) = simulate(&road_spec(
        Surface::DenseAsphalt,
        Condition::default(),
        first_seed + 4003,
    ))?;
    dropout_runs(&mut capture, 7, 14);
    let sparse = measure_road(&capture, None, &PipelineConfig::default(), &params)?;
    writeln!(
        doc,
        "| 7 patches of 14 columns (2.1 mm) without return (≈ 15 % drop-outs) | {} |",
        verdict(&sparse)
    )?;
    Ok(doc)
}

fn verdict(o: &RoadOutcome) -> String {
    match &o.result {
        Ok(r) => format!("measured, MPD {:.3} mm", r.depth.mpd * 1e3),
        Err(e) => format!("refused: {e}"),
    }
}

/// RMS of samples about their regression line.
pub fn detrended_rms(v: &[Vec2]) -> Option<f64> {
    if v.len() < 3 {
        return None;
    }
    let n = v.len() as f64;
    let ms = v.iter().map(|p| p.x).sum::<f64>() / n;
    let mh = v.iter().map(|p| p.y).sum::<f64>() / n;
    let sss: f64 = v.iter().map(|p| (p.x - ms).powi(2)).sum();
    let ssh: f64 = v.iter().map(|p| (p.x - ms) * (p.y - mh)).sum();
    let b = if sss > 0.0 { ssh / sss } else { 0.0 };
    Some(
        (v.iter()
            .map(|p| (p.y - mh - b * (p.x - ms)).powi(2))
            .sum::<f64>()
            / n)
            .sqrt(),
    )
}

/// A wet film acts as a mirror: the laser is reflected away from the camera over the patch,
/// whose pixels in the laser-on frame are then those of the laser-off frame.
pub fn wet_mirror_patch(capture: &mut crate::capture::Capture, columns: std::ops::Range<usize>) {
    blank_columns(capture, |u| columns.contains(&u));
}

/// `runs` stretches of `columns` columns each return nothing (dark, porous patches), spread
/// evenly over the image's width. At most 7 runs: the pipeline keeps the 8 fragments of a
/// broken line nearest the centre (`curve::MAX_CURVES`), so an 8th break would lose a whole
/// fragment (`docs/road.md`, "Bad input").
pub fn dropout_runs(capture: &mut crate::capture::Capture, runs: usize, columns: usize) {
    let width = capture.off_frame().width;
    let pitch = width / (runs + 1);
    blank_columns(capture, |u| {
        (1..=runs).any(|k| {
            let start = k * pitch - columns / 2;
            (start..start + columns).contains(&u)
        })
    });
}

/// Every `every`-th column returns nothing: drop-outs scattered column by column, as on a
/// dark or porous surface.
pub fn scattered_dropouts(capture: &mut crate::capture::Capture, every: usize) {
    blank_columns(capture, |u| every > 0 && u % every == 0);
}

fn blank_columns(capture: &mut crate::capture::Capture, blank: impl Fn(usize) -> bool) {
    use crate::pgm::PgmSamples;
    let off = capture.off_frame().clone();
    let w = off.width;
    let lit: Vec<bool> = capture
        .meta
        .frames
        .iter()
        .map(|f| !f.lasers_on.is_empty())
        .collect();
    for (f, _) in capture.frames.iter_mut().zip(lit).filter(|(_, l)| *l) {
        match (&mut f.samples, &off.samples) {
            (PgmSamples::U8(on), PgmSamples::U8(o)) => {
                for (i, v) in on.iter_mut().enumerate() {
                    if blank(i % w) {
                        *v = o[i];
                    }
                }
            }
            (PgmSamples::U16(on), PgmSamples::U16(o)) => {
                for (i, v) in on.iter_mut().enumerate() {
                    if blank(i % w) {
                        *v = o[i];
                    }
                }
            }
            _ => {}
        }
    }
}
