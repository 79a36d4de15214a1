//! `tangent inspect <capture>`: a PNG of a capture's frames with the true and the extracted
//! laser curves.
//!
//! Panels, top to bottom: laser-off frame; laser-on frame; difference (on − off, stretched
//! to its 99.9th percentile) with the true curve (green: plane 0, cyan: plane 1, …) and the
//! curve extracted by `tangent_core::pipeline` (red: plane 0, magenta: plane 1, …); a ×4
//! zoom of the difference around the middle of the first plane's true curve with the same overlays at
//! subpixel position (true: 1-pixel line; extracted: 3×3 dots).
//!
//! Memory is bounded by the capture's declared frame size, which the format caps at
//! `capture::MAX_FRAME_PIXELS` (`docs/formats.md`, "Bounds"): about 60 bytes per pixel
//! (the frames, the difference, the 4-panel image): ≈ 250 MB at the cap, 20 MB (measured)
//! for the sensor.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use image::{Rgb, RgbImage};
use tangent_core::image::{Frame, Pixel};
use tangent_core::pipeline::{self, OwnedBuffers, PipelineConfig};
use tangent_host::capture::Capture;
use tangent_host::pgm::{Pgm, PgmSamples};

/// Arguments of `tangent inspect`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Capture directory.
    capture: PathBuf,
    /// Output PNG (default: `<capture directory name>.png` in the current directory, so
    /// that inspecting a corpus capture does not add a file to it).
    #[arg(long)]
    out: Option<PathBuf>,
}

const TRUTH_COLOURS: [[u8; 3]; 4] = [[0, 230, 0], [0, 220, 255], [255, 255, 0], [255, 160, 0]];
const EXTRACTED_COLOURS: [[u8; 3]; 4] = [
    [255, 40, 40],
    [255, 0, 255],
    [255, 255, 255],
    [160, 80, 255],
];

/// Extracted curve points per plane: `(plane, column, row)`, or the pipeline's error text.
fn extract(capture: &Capture, on: &Pgm) -> Result<Vec<(usize, f64, f64)>, String> {
    fn run<P: Pixel>(
        off: &[P],
        on: &[P],
        bits: u8,
        c: &Capture,
    ) -> Result<Vec<(usize, f64, f64)>, String> {
        let (w, h) = (c.meta.width as usize, c.meta.height as usize);
        let off = Frame::new(off, w, h, w)
            .and_then(|f| f.with_bit_depth(bits))
            .map_err(|e| e.to_string())?;
        let on = Frame::new(on, w, h, w)
            .and_then(|f| f.with_bit_depth(bits))
            .map_err(|e| e.to_string())?;
        let mut hw = OwnedBuffers::<P>::for_frame(w, h, bits, c.calibration.planes.len());
        let profile = pipeline::extract_profile(
            &off,
            &on,
            &c.calibration,
            &PipelineConfig::default(),
            &mut hw.workspace(),
        )
        .map_err(|e| e.to_string())?;
        let mut out = Vec::new();
        for plane in 0..profile.planes {
            let (s, e) = profile.plane_points[plane];
            for p in hw.curve().get(s..e).unwrap_or(&[]) {
                out.push((plane, f64::from(p.column), p.row));
            }
        }
        Ok(out)
    }
    let bits = capture.meta.bit_depth;
    match (&capture.off_frame().samples, &on.samples) {
        (PgmSamples::U8(a), PgmSamples::U8(b)) => run(a, b, bits, capture),
        (PgmSamples::U16(a), PgmSamples::U16(b)) => run(a, b, bits, capture),
        _ => Err("frames of different sample widths".into()),
    }
}

fn grey_panel(img: &mut RgbImage, pgm: &Pgm, y0: u32, scale: f64) {
    for y in 0..pgm.height {
        for x in 0..pgm.width {
            let v = (pgm.get(x, y).unwrap_or(0) as f64 * scale).clamp(0.0, 255.0) as u8;
            img.put_pixel(x as u32, y0 + y as u32, Rgb([v, v, v]));
        }
    }
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: [u8; 3]) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, Rgb(c));
    }
}

/// Runs `tangent inspect`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    // A capture's errors name its files relative to it; put the directory in front.
    let c = Capture::read(&args.capture).with_context(|| args.capture.display().to_string())?;
    let (w, h) = (c.meta.width, c.meta.height);
    let off = c.off_frame();
    let (lit, on) = c.on_frames().next().context("no laser-on frame")?;
    let full = ((1u32 << c.meta.bit_depth) - 1) as f64;
    let mut img = RgbImage::new(w, 4 * h);
    grey_panel(&mut img, off, 0, 255.0 / full);
    grey_panel(&mut img, on, h, 255.0 / full);

    // Difference, stretched to its 99.9th percentile so a weak stripe is visible.
    let diff: Vec<f64> = (0..(w * h) as usize)
        .map(|i| {
            let (x, y) = (i % w as usize, i / w as usize);
            on.get(x, y).unwrap_or(0) as f64 - off.get(x, y).unwrap_or(0) as f64
        })
        .collect();
    let mut positive: Vec<f64> = diff.iter().map(|d| d.max(0.0)).collect();
    let rank = (positive.len() as f64 * 0.999) as usize;
    let (_, &mut top, _) = positive.select_nth_unstable_by(rank, f64::total_cmp);
    let top = top.max(1.0);
    for (i, d) in diff.iter().enumerate() {
        let v = (d.max(0.0) / top * 255.0).clamp(0.0, 255.0) as u8;
        img.put_pixel(i as u32 % w, 2 * h + i as u32 / w, Rgb([v, v, v]));
    }

    let truth: Vec<(usize, f64, f64)> = c
        .truth_curve
        .iter()
        .flatten()
        .filter(|p| lit.contains(&p.plane))
        .map(|p| (p.plane, p.column as f64, p.row_px))
        .collect();
    let extracted = extract(&c, on);
    for &(plane, u, v) in &truth {
        put(
            &mut img,
            u as i64,
            (2 * h) as i64 + v.round() as i64,
            TRUTH_COLOURS[plane % 4],
        );
    }
    if let Ok(points) = &extracted {
        for &(plane, u, v) in points {
            put(
                &mut img,
                u as i64,
                (2 * h) as i64 + v.round() as i64 + 2,
                EXTRACTED_COLOURS[plane % 4],
            );
        }
    }

    // ×4 zoom around the middle truth point (or the image centre).
    let zoom = 4.0;
    let (cw, ch) = (w as f64 / zoom, h as f64 / zoom);
    let first: Vec<_> = truth
        .iter()
        .filter(|t| Some(t.0) == truth.first().map(|f| f.0))
        .collect();
    let centre = first
        .get(first.len() / 2)
        .map(|&&(_, u, v)| (u, v))
        .unwrap_or((w as f64 / 2.0, h as f64 / 2.0));
    let x0 = (centre.0 - cw / 2.0).clamp(-0.5, w as f64 - 0.5 - cw);
    let y0 = (centre.1 - ch / 2.0).clamp(-0.5, h as f64 - 0.5 - ch);
    for py in 0..h {
        for px in 0..w {
            // Panel pixel (px, py) shows image point (x0 + (px + 0.5)/zoom, …), nearest pixel.
            let u = x0 + (px as f64 + 0.5) / zoom;
            let v = y0 + (py as f64 + 0.5) / zoom;
            let (i, j) = (
                u.round().clamp(0.0, w as f64 - 1.0) as usize,
                v.round().clamp(0.0, h as f64 - 1.0) as usize,
            );
            let d = diff[j * w as usize + i];
            let g = (d.max(0.0) / top * 255.0).clamp(0.0, 255.0) as u8;
            img.put_pixel(px, 3 * h + py, Rgb([g, g, g]));
        }
    }
    let to_panel = |u: f64, v: f64| ((u - x0) * zoom - 0.5, (v - y0) * zoom - 0.5);
    for &(plane, u, v) in &truth {
        let (px, py) = to_panel(u, v);
        for dx in -1..=1 {
            put(
                &mut img,
                px.round() as i64 + dx,
                (3 * h) as i64 + py.round() as i64,
                TRUTH_COLOURS[plane % 4],
            );
        }
    }
    if let Ok(points) = &extracted {
        for &(plane, u, v) in points {
            let (px, py) = to_panel(u, v);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if dx == 0 && dy == 0 {
                        continue;
                    }
                    let (x, y) = (
                        px.round() as i64 + dx,
                        (3 * h) as i64 + py.round() as i64 + dy,
                    );
                    put(&mut img, x, y, EXTRACTED_COLOURS[plane % 4]);
                }
            }
        }
    }

    let out = args.out.unwrap_or_else(|| {
        let name = args
            .capture
            .file_name()
            .map_or("capture".into(), |n| n.to_string_lossy().into_owned());
        PathBuf::from(format!("{name}.png"))
    });
    img.save(&out)
        .with_context(|| format!("writing {}", out.display()))?;
    println!("{}: {}", out.display(), c.meta.description);
    println!(
        "panels: off | on | on − off (×{:.1}) with curves | ×4 zoom",
        255.0 / top
    );
    println!(
        "true curve: {} points (green = plane 0, cyan = plane 1)",
        truth.len()
    );
    match &extracted {
        Ok(p) => println!("extracted curve (tangent_core::pipeline): {} points (red = plane 0, magenta = plane 1; drawn 2 px low in panel 3)", p.len()),
        Err(e) => println!("extracted curve: none ({e})"),
    }
    Ok(ExitCode::SUCCESS)
}
