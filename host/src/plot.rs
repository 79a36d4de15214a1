//! PNG plots a person can look at (plotters on a bitmap).
//!
//! The font is shipped in `host/assets/` (DejaVu Sans, free licence) and compiled in, so plots
//! look the same on every machine and need no system font library.

use std::path::Path;
use std::sync::Once;

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use tangent_core::real::Vec2;

use crate::measure::{Outcome, Solved};

static FONT: Once = Once::new();

/// Registers the shipped font as plotters' `sans-serif` (once per process).
pub fn init_fonts() {
    FONT.call_once(|| {
        // The bytes are a valid TrueType font compiled in; registration cannot fail for them.
        let _ = register_font(
            "sans-serif",
            FontStyle::Normal,
            include_bytes!("../assets/DejaVuSans.ttf"),
        );
    });
}

/// Colours of the curves of planes 0, 1, 2, 3.
pub const PLANE_COLOURS: [RGBColor; 4] = [
    RGBColor(230, 40, 40),
    RGBColor(30, 120, 255),
    RGBColor(0, 170, 0),
    RGBColor(200, 0, 200),
];

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plot: {e:?}")
}

/// Writes the measurement plot of one capture: the difference frame with the extracted curve
/// (one colour per plane), and the section in plane 0 with the points and the fitted circle.
pub fn measurement_png(path: &Path, outcome: &Outcome, title: &str) -> Result<()> {
    init_fonts();
    let cal = &outcome.calibration;
    let (w, h) = (cal.camera.width as usize, cal.camera.height as usize);
    let root = BitMapBackend::new(path, (w as u32 + 560, h as u32 + 60)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, ("sans-serif", 20)).map_err(err)?;
    let (left, right) = root.split_horizontally(w as u32 + 10);

    // Difference frame, stretched to its 99.9th percentile so the stripe is visible.
    let mut sorted: Vec<u16> = outcome.diff.iter().copied().take(w * h).collect();
    sorted.sort_unstable();
    let top = sorted
        .get(sorted.len().saturating_sub(1) * 999 / 1000)
        .copied()
        .unwrap_or(1)
        .max(1) as f64;
    for y in 0..h {
        for x in 0..w {
            let v = outcome.diff.get(y * w + x).copied().unwrap_or(0) as f64;
            let g = (255.0 * (v / top).min(1.0)) as u8;
            left.draw_pixel((x as i32, y as i32), &RGBColor(g, g, g))
                .map_err(err)?;
        }
    }
    let (planes, ranges) = match &outcome.result {
        Ok(m) => (m.profile().planes, m.profile().plane_points),
        Err(_) => (0, Default::default()),
    };
    for (k, &(s, e)) in ranges.iter().enumerate().take(planes) {
        let colour = PLANE_COLOURS[k % PLANE_COLOURS.len()];
        for p in outcome.curve.get(s..e).unwrap_or(&[]) {
            left.draw_pixel((p.column as i32, p.row.round() as i32), &colour)
                .map_err(err)?;
        }
    }

    // Section in plane 0 (in-plane coordinates a, b: metres from the laser source).
    let plane0 = match cal.planes.first() {
        Some(p) => *p,
        None => return root.present().map_err(err),
    };
    let mut pts: Vec<(usize, Vec2)> = Vec::new();
    for (k, &(s, e)) in ranges.iter().enumerate().take(planes) {
        for p in outcome.points.get(s..e).unwrap_or(&[]) {
            pts.push((k, plane0.to_plane_coords(*p)));
        }
    }
    // The solution's traces in plane 0's coordinates: the stem's circle; for a sphere, the
    // circle it cuts in each plane (centre `C − h·n`, radius `√(R² − h²)`; the reference
    // design's planes are parallel, so each lies flat in this view).
    let mut circles: Vec<(Vec2, f64)> = Vec::new();
    match &outcome.result {
        Ok(Solved::Stem(m)) => circles.push((
            plane0.to_plane_coords(m.solution.centre),
            m.solution.diameter / 2.0,
        )),
        Ok(Solved::Sphere(m)) => {
            let (c, r) = (m.solution.centre, m.solution.diameter / 2.0);
            for plane in cal.planes.iter().take(planes) {
                let h = plane.signed_distance(c);
                if h.abs() < r {
                    let foot = c - plane.normal * h;
                    circles.push((plane0.to_plane_coords(foot), (r * r - h * h).sqrt()));
                }
            }
        }
        Ok(Solved::Wall(_)) | Err(_) => {}
    }
    let (mut a0, mut a1, mut b0, mut b1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (_, q) in &pts {
        a0 = a0.min(q.x);
        a1 = a1.max(q.x);
        b0 = b0.min(q.y);
        b1 = b1.max(q.y);
    }
    for &(c, r) in &circles {
        a0 = a0.min(c.x - r);
        a1 = a1.max(c.x + r);
        b0 = b0.min(c.y - r);
        b1 = b1.max(c.y + r);
    }
    if !a0.is_finite() {
        return root.present().map_err(err);
    }
    // Equal scales on both axes so a circle looks round.
    let span = (a1 - a0).max(b1 - b0) * 1.1 + 1e-3;
    let (am, bm) = ((a0 + a1) / 2.0, (b0 + b1) / 2.0);
    let mut chart = ChartBuilder::on(&right)
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .caption(
            "sections, in laser plane 0's coordinates",
            ("sans-serif", 16),
        )
        .build_cartesian_2d(
            (am - span / 2.0)..(am + span / 2.0),
            (bm + span / 2.0)..(bm - span / 2.0),
        )
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("a (m, across)")
        .y_desc("b (m, from the laser)")
        .draw()
        .map_err(err)?;
    chart
        .draw_series(
            pts.iter()
                .map(|(k, q)| Circle::new((q.x, q.y), 1, PLANE_COLOURS[k % 4].filled())),
        )
        .map_err(err)?;
    for &(c, r) in &circles {
        chart
            .draw_series(LineSeries::new(
                (0..=360).map(|i| {
                    let t = (i as f64).to_radians();
                    (c.x + r * t.cos(), c.y + r * t.sin())
                }),
                BLACK.stroke_width(1),
            ))
            .map_err(err)?;
    }
    root.present().map_err(err)
}
