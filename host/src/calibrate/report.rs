//! The calibration report: text summary and PNG figures.
//!
//! Figures are drawn with the `image` crate; their captions with plotters and the font
//! shipped with the crate ([`crate::plot::init_fonts`]), so no system font is needed. The
//! text report says in full what each figure shows.

use std::fmt::Write as _;
use std::path::Path;

use image::{GrayImage, Rgb, RgbImage};
use tangent_core::real::Vec2;

use super::laser::{BoardCapture, LaserCalibration};
use super::refine::{CameraCalibration, INTRINSIC_NAMES};

/// Magnification of the residual vectors drawn on the per-view overlays.
pub const RESIDUAL_MAGNIFICATION: f64 = 20.0;

/// The text report of a camera calibration. `skipped` lists the images not used, with why.
pub fn camera_text(cal: &CameraCalibration, skipped: &[(String, String)]) -> String {
    let c = &cal.camera;
    let d = c.distortion;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Camera calibration (Zhang closed form + Levenberg-Marquardt)"
    );
    let _ = writeln!(
        s,
        "views used: {}   corners: {}   iterations: {}",
        cal.view_names.len(),
        cal.corner_count(),
        cal.iterations
    );
    let _ = writeln!(s, "image: {} x {} px", c.width, c.height);
    let values = [c.fx, c.fy, c.cx, c.cy, d.k1, d.k2, d.p1, d.p2, d.k3];
    let _ = writeln!(
        s,
        "\nparameter        value        std dev   (closed-form start)"
    );
    let init = &cal.initial;
    let starts = [
        init.fx,
        init.fy,
        init.cx,
        init.cy,
        init.distortion.k1,
        init.distortion.k2,
        init.distortion.p1,
        init.distortion.p2,
        init.distortion.k3,
    ];
    for k in 0..INTRINSIC_NAMES.len() {
        let unit = if k < 4 { "px" } else { "  " };
        let _ = writeln!(
            s,
            "{:<6} {:>16.6} {:>14.6} {}   ({:.6})",
            INTRINSIC_NAMES[k], values[k], cal.std_dev[k], unit, starts[k]
        );
    }
    let _ = writeln!(
        s,
        "\nRMS reprojection error: {:.4} px (sqrt of mean squared corner error); sigma per coordinate {:.4} px",
        cal.rms, cal.sigma
    );
    let _ = writeln!(
        s,
        "\nview                                     corners   RMS px"
    );
    for (k, name) in cal.view_names.iter().enumerate() {
        let flag = if cal.outlier_views.contains(&k) {
            "  OUTLIER"
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "{:<40} {:>7} {:>8.4}{}",
            name,
            cal.residuals[k].len(),
            cal.per_view_rms[k],
            flag
        );
    }
    if !cal.outlier_views.is_empty() {
        let _ = writeln!(
            s,
            "\n{} outlier view(s): RMS above {}x the median view RMS; check them (blur, bad detection) and consider removing them.",
            cal.outlier_views.len(),
            super::refine::OUTLIER_VIEW_FACTOR
        );
    }
    for (name, why) in skipped {
        let _ = writeln!(s, "skipped {name}: {why}");
    }
    s
}

/// The text report of a laser-plane calibration.
pub fn laser_text(index: usize, cal: &LaserCalibration) -> String {
    let mut s = String::new();
    let p = &cal.plane;
    let (e, delta) = p.baseline_tilt();
    let _ = writeln!(s, "Laser plane {index}");
    let _ = writeln!(
        s,
        "normal {:.6} {:.6} {:.6}   offset {:.3} mm   source {:.3} {:.3} {:.3} mm",
        p.normal.x,
        p.normal.y,
        p.normal.z,
        p.offset * 1e3,
        p.source.x * 1e3,
        p.source.y * 1e3,
        p.source.z * 1e3
    );
    let _ = writeln!(
        s,
        "baseline e = {:.3} mm   tilt delta = {:.4} deg   roll rho = {:.4} deg",
        e * 1e3,
        delta.to_degrees(),
        p.roll().to_degrees()
    );
    let _ = writeln!(
        s,
        "fit: {} points ({} inliers) from {} poses, RMS distance {:.4} mm",
        cal.fit.points,
        cal.fit.inliers,
        cal.per_pose.len(),
        cal.fit.rms * 1e3
    );
    for (k, pts) in cal.per_pose.iter().enumerate() {
        let _ = writeln!(s, "  pose {k}: {} stripe points on the board", pts.len());
    }
    if let Some(r) = &cal.repeatability {
        let _ = writeln!(
            s,
            "repeatability (leave-one-pose-out): std error e {:.4} mm, delta {:.5} deg, rho {:.5} deg; spread e {:.4} mm, delta {:.5} deg, rho {:.5} deg",
            r.std_error.0 * 1e3,
            r.std_error.1.to_degrees(),
            r.std_error.2.to_degrees(),
            r.spread.0 * 1e3,
            r.spread.1.to_degrees(),
            r.spread.2.to_degrees()
        );
    }
    s
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, c);
    }
}

fn line(img: &mut RgbImage, a: Vec2, b: Vec2, c: Rgb<u8>) {
    let n = ((b - a).norm().ceil() as usize).max(1);
    for k in 0..=n {
        let p = a + (b - a) * (k as f64 / n as f64);
        put(img, p.x.round() as i64, p.y.round() as i64, c);
    }
}

fn circle(img: &mut RgbImage, centre: Vec2, r: f64, c: Rgb<u8>) {
    let n = ((2.0 * std::f64::consts::PI * r).ceil() as usize).max(8);
    for k in 0..n {
        let t = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
        put(
            img,
            (centre.x + r * t.cos()).round() as i64,
            (centre.y + r * t.sin()).round() as i64,
            c,
        );
    }
}

/// Per-view overlay: the image (dimmed), a green cross on every detected corner and a red
/// segment from it along the reprojection residual magnified [`RESIDUAL_MAGNIFICATION`]×.
pub fn view_overlay(img: &GrayImage, residuals: &[(Vec2, Vec2)]) -> RgbImage {
    let mut out = RgbImage::from_fn(img.width(), img.height(), |x, y| {
        let v = (img.get_pixel(x, y)[0] as f64 * 0.6) as u8;
        Rgb([v, v, v])
    });
    for &(p, r) in residuals {
        let green = Rgb([0, 255, 0]);
        line(
            &mut out,
            p - Vec2::new(4.0, 0.0),
            p + Vec2::new(4.0, 0.0),
            green,
        );
        line(
            &mut out,
            p - Vec2::new(0.0, 4.0),
            p + Vec2::new(0.0, 4.0),
            green,
        );
        line(
            &mut out,
            p,
            p + r * RESIDUAL_MAGNIFICATION,
            Rgb([255, 40, 40]),
        );
    }
    out
}

/// Summary figure, 900 × 450: left, every corner residual `(du, dv)` as a dot (scale:
/// 150 figure pixels per image pixel; grey circles at 0.25, 0.5 and 1 px; outlier views in
/// red); right, one bar per view with its RMS (same vertical scale, 300 figure pixels per
/// image pixel, outliers in red) and a blue line at the overall RMS.
pub fn summary_figure(cal: &CameraCalibration) -> RgbImage {
    let mut img = RgbImage::from_pixel(900, 450, Rgb([255, 255, 255]));
    let centre = Vec2::new(225.0, 225.0);
    let scale = 150.0;
    for r in [0.25, 0.5, 1.0] {
        circle(&mut img, centre, r * scale, Rgb([180, 180, 180]));
    }
    line(
        &mut img,
        Vec2::new(20.0, 225.0),
        Vec2::new(430.0, 225.0),
        Rgb([200, 200, 200]),
    );
    line(
        &mut img,
        Vec2::new(225.0, 20.0),
        Vec2::new(225.0, 430.0),
        Rgb([200, 200, 200]),
    );
    for (v, res) in cal.residuals.iter().enumerate() {
        let colour = if cal.outlier_views.contains(&v) {
            Rgb([220, 0, 0])
        } else {
            Rgb([0, 0, 0])
        };
        for &(_, r) in res {
            let p = centre + r * scale;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                put(
                    &mut img,
                    p.x.round() as i64 + dx,
                    p.y.round() as i64 + dy,
                    colour,
                );
            }
        }
    }
    let n = cal.per_view_rms.len().max(1);
    let (x0, x1, base) = (480.0, 880.0, 420.0);
    let bar_scale = 300.0;
    let w = (x1 - x0) / n as f64;
    for (v, &e) in cal.per_view_rms.iter().enumerate() {
        let colour = if cal.outlier_views.contains(&v) {
            Rgb([220, 0, 0])
        } else {
            Rgb([60, 60, 60])
        };
        let top = (base - e * bar_scale).max(5.0);
        let (a, b) = (
            x0 + v as f64 * w + 0.15 * w,
            x0 + (v as f64 + 1.0) * w - 0.15 * w,
        );
        for x in a.round() as i64..=b.round() as i64 {
            line(
                &mut img,
                Vec2::new(x as f64, base),
                Vec2::new(x as f64, top),
                colour,
            );
        }
    }
    let y = (base - cal.rms * bar_scale).max(5.0);
    line(
        &mut img,
        Vec2::new(x0, y),
        Vec2::new(x1, y),
        Rgb([0, 80, 255]),
    );
    line(
        &mut img,
        Vec2::new(x0, base),
        Vec2::new(x1, base),
        Rgb([0, 0, 0]),
    );
    img
}

/// Writes `report.txt`, `residuals.png` and one `view_NN.png` per view (when its image is
/// given) into `dir`, creating it.
pub fn write_camera_report(
    dir: &Path,
    cal: &CameraCalibration,
    images: &[Option<GrayImage>],
    skipped: &[(String, String)],
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut text = camera_text(cal, skipped);
    text.push_str(
        "\nFigures: residuals.png (left: every corner's reprojection residual, 150 figure px per image px, circles at 0.25/0.5/1 px; right: RMS per view, 300 figure px per image px, blue line = overall RMS; outlier views in red).\n",
    );
    text.push_str(&format!(
        "view_NN.png: detected corners (green) and residuals magnified {RESIDUAL_MAGNIFICATION}x (red), views in the order above.\n"
    ));
    std::fs::write(dir.join("report.txt"), text)?;
    let mut summary = summary_figure(cal);
    caption(
        &mut summary,
        &format!(
            "corner residuals (circles 0.25/0.5/1 px) | RMS per view, overall {:.3} px",
            cal.rms
        ),
    );
    summary.save(dir.join("residuals.png"))?;
    for (k, img) in images.iter().enumerate() {
        if let (Some(img), Some(res)) = (img, cal.residuals.get(k)) {
            let mut fig = view_overlay(img, res);
            let name = cal.view_names.get(k).map_or("", String::as_str);
            let rms = cal.per_view_rms.get(k).copied().unwrap_or(f64::NAN);
            caption(
                &mut fig,
                &format!("{name}: RMS {rms:.3} px, residuals x{RESIDUAL_MAGNIFICATION}"),
            );
            fig.save(dir.join(format!("view_{k:02}.png")))?;
        }
    }
    Ok(())
}

/// Colours of the stripes of lasers 0, 1, 2, 3 on the laser report figures.
const LASER_COLOURS: [Rgb<u8>; 4] = [
    Rgb([255, 40, 40]),
    Rgb([40, 140, 255]),
    Rgb([0, 200, 0]),
    Rgb([220, 0, 220]),
];

/// Writes a caption in the top-left corner of a figure (white on a dark band), with the
/// shipped font. Drawing errors only lose the caption, never the figure.
pub fn caption(img: &mut RgbImage, text: &str) {
    use plotters::prelude::*;
    crate::plot::init_fonts();
    let (w, h) = img.dimensions();
    for y in 0..h.min(22) {
        for x in 0..w {
            let p = img.get_pixel_mut(x, y);
            p.0 = p.0.map(|c| c / 4);
        }
    }
    let root = BitMapBackend::with_buffer(img, (w, h)).into_drawing_area();
    let style = ("sans-serif", 16).into_font().color(&WHITE);
    let _ = root.draw(&Text::new(text.to_string(), (6, 3), style));
    let _ = root.present();
}

/// Per capture figure of the laser calibration: the laser-off frame (dimmed), the detected
/// corners (green crosses) and each laser's stripe pixels (red = laser 0, blue = laser 1,
/// green = 2, magenta = 3), captioned.
pub fn laser_capture_figure(capture: &BoardCapture) -> RgbImage {
    let mut out = RgbImage::from_fn(capture.image.width(), capture.image.height(), |x, y| {
        let v = (capture.image.get_pixel(x, y)[0] as f64 * 0.6) as u8;
        Rgb([v, v, v])
    });
    for c in &capture.view.corners {
        let p = c.pixel;
        let g = Rgb([0, 230, 0]);
        line(
            &mut out,
            p - Vec2::new(4.0, 0.0),
            p + Vec2::new(4.0, 0.0),
            g,
        );
        line(
            &mut out,
            p - Vec2::new(0.0, 4.0),
            p + Vec2::new(0.0, 4.0),
            g,
        );
    }
    for (k, pixels) in &capture.stripes {
        let colour = LASER_COLOURS[k % LASER_COLOURS.len()];
        for p in pixels {
            put(&mut out, p.x.round() as i64, p.y.round() as i64, colour);
        }
    }
    let stripes: Vec<String> = capture
        .stripes
        .iter()
        .map(|(k, p)| format!("laser {k}: {} px", p.len()))
        .collect();
    caption(
        &mut out,
        &format!(
            "{}: {} corners; {}",
            capture.view.name,
            capture.view.corners.len(),
            stripes.join(", ")
        ),
    );
    out
}

/// Writes `laser-report.txt` (the given text plus a legend) and `capture_NN.png` per
/// capture ([`laser_capture_figure`]) into `dir`, creating it.
pub fn write_laser_report(
    dir: &Path,
    text: &str,
    captures: &[BoardCapture],
    cals: &[LaserCalibration],
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut text = text.to_string();
    let _ = writeln!(
        text,
        "\nFigures: capture_NN.png, one per capture in the order given: laser-off frame, detected corners (green), stripe pixels of laser 0 (red), 1 (blue), 2 (green), 3 (magenta). {} plane(s) calibrated.",
        cals.len()
    );
    std::fs::write(dir.join("laser-report.txt"), text)?;
    for (k, c) in captures.iter().enumerate() {
        laser_capture_figure(c).save(dir.join(format!("capture_{k:02}.png")))?;
    }
    Ok(())
}
