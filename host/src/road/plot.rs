//! The road profile plot of `tangent measure --plot` (`docs/road.md`): the raw profile with
//! its drop-outs marked, the standard's filtered profile (slope suppressed) and each
//! segment's two peaks and mean level.

use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use tangent_core::instrument::road::RoadParams;

use super::{mpd_of_profile, RoadOutcome};
use crate::plot::init_fonts;

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plot: {e:?}")
}

/// Writes the profile plot of one road capture.
pub fn road_png(
    path: &Path,
    outcome: &RoadOutcome,
    params: &RoadParams,
    title: &str,
) -> Result<()> {
    init_fonts();
    let root = BitMapBackend::new(path, (1200, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, ("sans-serif", 18)).map_err(err)?;
    let mm = |v: f64| v * 1e3;
    let raw = &outcome.profile;
    let filtered = mpd_of_profile(raw, params).ok();
    let valid = raw.iter().filter(|p| p.y.is_finite());
    let (lo, hi) = valid.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
        (a.min(p.y), b.max(p.y))
    });
    let (lo, hi) = if lo.is_finite() {
        (mm(lo) - 0.5, mm(hi) + 0.5)
    } else {
        (-1.0, 1.0)
    };
    let s0 = mm(params.profile.window_start);
    let s1 = s0 + mm(params.profile.window_length);
    let mut chart = ChartBuilder::on(&root)
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(s0..s1, lo..hi)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("position along the line (mm)")
        .y_desc("height (mm, up)")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(
            raw.iter()
                .filter(|p| p.y.is_finite())
                .map(|p| Circle::new((mm(p.x), mm(p.y)), 1, RGBColor(120, 120, 120).filled())),
        )
        .map_err(err)?
        .label("raw profile")
        .legend(|(x, y)| Circle::new((x, y), 2, RGBColor(120, 120, 120).filled()));
    chart
        .draw_series(raw.iter().filter(|p| !p.y.is_finite()).map(|p| {
            PathElement::new(
                vec![(mm(p.x), lo), (mm(p.x), lo + 0.15)],
                RED.stroke_width(1),
            )
        }))
        .map_err(err)?
        .label("drop-out")
        .legend(|(x, y)| PathElement::new(vec![(x, y - 4), (x, y + 4)], RED));
    if let Some((m, segments, _, resampled)) = filtered {
        let step = params.mpd.spacing;
        // The resampled profile is slope-suppressed per segment; draw it about each segment's
        // regression line's zero (the raw profile's mean level is near it).
        chart
            .draw_series(LineSeries::new(
                resampled
                    .iter()
                    .enumerate()
                    .map(|(k, h)| (s0 + mm((k + 1) as f64 * step), mm(*h))),
                BLUE.stroke_width(2),
            ))
            .map_err(err)?
            .label(format!("filtered (2.4 mm), MPD {:.3} mm", m.mpd * 1e3))
            .legend(|(x, y)| PathElement::new(vec![(x - 8, y), (x + 8, y)], BLUE));
        for g in &segments {
            chart
                .draw_series(
                    g.peaks
                        .iter()
                        .map(|p| TriangleMarker::new((mm(p.x), mm(p.y)), 7, RED.filled())),
                )
                .map_err(err)?;
            let end = mm(g.start) + mm(params.mpd.segment_length);
            let level = mm(g.peaks[0].y + g.peaks[1].y) / 2.0;
            chart
                .draw_series(LineSeries::new(
                    vec![(mm(g.start), level), (end, level)],
                    RED.stroke_width(1),
                ))
                .map_err(err)?;
            chart
                .draw_series(LineSeries::new(
                    vec![(mm(g.start), 0.0), (end, 0.0)],
                    BLACK.stroke_width(1),
                ))
                .map_err(err)?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)
}
