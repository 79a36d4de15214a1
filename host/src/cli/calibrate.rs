//! `tangent calibrate camera IMAGES… --board 9x6 --square 25mm` and
//! `tangent calibrate laser CAPTURES… --camera FILE`.
//!
//! The camera command writes a calibration file whose `[camera]` is the new calibration;
//! if the output file already exists its id and laser planes are kept, otherwise it has no
//! `[[planes]]` yet (a camera-only file, which `calibrate laser` completes). The laser
//! command reads the camera from such a file and writes the complete calibration.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context as _};
use clap::Subcommand;
use tangent_core::real::Vec2;
use tangent_host::calibrate::{corners, laser, refine, report, Board, View};
use tangent_host::calibration_file::{
    self, CalibrationToml, CameraToml, DistortionToml, PlaneToml,
};
use tangent_host::capture::Capture;
use tangent_host::pgm::Pgm;

/// Arguments of `tangent calibrate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    which: Which,
}

#[derive(Subcommand, Debug)]
enum Which {
    /// Camera intrinsics and distortion from chessboard images (Zhang + Levenberg–Marquardt).
    Camera {
        /// Images of the chessboard (PNG, JPEG or PGM), all from the same camera.
        #[arg(required = true)]
        images: Vec<PathBuf>,
        /// Inner corners of the board, COLSxROWS.
        #[arg(long, default_value = "9x6")]
        board: String,
        /// Side of one square, with unit (mm, cm, m).
        #[arg(long, default_value = "25mm")]
        square: String,
        /// Calibration file to write (existing planes and id in it are kept).
        #[arg(long, default_value = "calib.toml")]
        out: PathBuf,
        /// Directory for the report (text and PNG figures).
        #[arg(long)]
        report: Option<PathBuf>,
        /// Calibration id to write (default: the existing file's, else 0).
        #[arg(long)]
        id: Option<u32>,
    },
    /// Laser planes from captures of the laser on the chessboard at several poses.
    Laser {
        /// Capture directories (capture.toml + frames): the laser-off frame shows the board,
        /// each laser-on frame lighting one laser gives that laser's stripe.
        #[arg(required = true)]
        captures: Vec<PathBuf>,
        /// Calibration file with the camera (from `calibrate camera`).
        #[arg(long)]
        camera: PathBuf,
        /// Inner corners of the board, COLSxROWS.
        #[arg(long, default_value = "9x6")]
        board: String,
        /// Side of one square, with unit (mm, cm, m).
        #[arg(long, default_value = "25mm")]
        square: String,
        /// Calibration file to write (default: update the --camera file).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Directory for the text report.
        #[arg(long)]
        report: Option<PathBuf>,
    },
}

/// Runs `tangent calibrate`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    match args.which {
        Which::Camera {
            images,
            board,
            square,
            out,
            report: report_dir,
            id,
        } => camera(&images, &board, &square, &out, report_dir.as_deref(), id),
        Which::Laser {
            captures,
            camera,
            board,
            square,
            out,
            report: report_dir,
        } => laser_cmd(
            &captures,
            &camera,
            &board,
            &square,
            out.as_deref(),
            report_dir.as_deref(),
        ),
    }
}

/// Reads a calibration file leniently: a camera-only file (no planes) is accepted.
fn read_lenient(path: &Path) -> anyhow::Result<CalibrationToml> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str::<CalibrationToml>(&text).with_context(|| format!("parsing {}", path.display()))
}

fn camera(
    images: &[PathBuf],
    board: &str,
    square: &str,
    out: &Path,
    report_dir: Option<&Path>,
    id: Option<u32>,
) -> anyhow::Result<ExitCode> {
    let board = Board::parse(board, square).map_err(anyhow::Error::msg)?;
    let mut views = Vec::new();
    let mut grays = Vec::new();
    let mut skipped = Vec::new();
    for path in images {
        let name = path.display().to_string();
        let img = match image::open(path) {
            Ok(i) => i.to_luma8(),
            Err(e) => {
                eprintln!("skipping {name}: {e}");
                skipped.push((name, e.to_string()));
                continue;
            }
        };
        match corners::detect(&img, &board, &name) {
            Ok(v) => {
                let partial = if v.corners.len() < board.len() {
                    " (partial board)"
                } else {
                    ""
                };
                eprintln!("{name}: {} corners{partial}", v.corners.len());
                views.push(v);
                grays.push(Some(img));
            }
            Err(e) => {
                eprintln!("skipping {name}: {e}");
                skipped.push((name, e.to_string()));
            }
        }
    }
    if let Some(first) = views.first() {
        let (w, h) = (first.width, first.height);
        if let Some(v) = views.iter().find(|v| (v.width, v.height) != (w, h)) {
            bail!(
                "{} is {}x{}, the first image is {w}x{h}: one camera, one image size",
                v.name,
                v.width,
                v.height
            );
        }
    }
    let cal = refine::calibrate_camera(&views, &board)?;
    print!("{}", report::camera_text(&cal, &skipped));

    let existing = if out.exists() {
        Some(read_lenient(out)?)
    } else {
        None
    };
    let c = cal.camera;
    let d = c.distortion;
    let file = CalibrationToml {
        id: id.or(existing.as_ref().map(|e| e.id)).unwrap_or(0),
        camera: CameraToml {
            width_px: c.width,
            height_px: c.height,
            fx_px: c.fx,
            fy_px: c.fy,
            cx_px: c.cx,
            cy_px: c.cy,
            distortion: DistortionToml {
                k1: d.k1,
                k2: d.k2,
                k3: d.k3,
                p1: d.p1,
                p2: d.p2,
            },
        },
        planes: existing.map(|e| e.planes).unwrap_or_default(),
    };
    std::fs::write(out, toml::to_string(&file)?)
        .with_context(|| format!("writing {}", out.display()))?;
    eprintln!("wrote {}", out.display());
    if let Some(dir) = report_dir {
        report::write_camera_report(dir, &cal, &grays, &skipped)?;
        eprintln!("report in {}", dir.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// A PGM frame as an 8-bit grey image (scaled by 255 / maxval) and as `f64` samples.
fn pgm_to_gray(p: &Pgm) -> (image::GrayImage, Vec<f64>) {
    let raw = p.to_u16();
    let scale = 255.0 / p.maxval.max(1) as f64;
    let bytes = raw
        .iter()
        .map(|&v| (v as f64 * scale).round().min(255.0) as u8)
        .collect();
    let img =
        image::GrayImage::from_raw(p.width as u32, p.height as u32, bytes).unwrap_or_default();
    (img, raw.iter().map(|&v| v as f64).collect())
}

fn laser_cmd(
    captures: &[PathBuf],
    camera_file: &Path,
    board: &str,
    square: &str,
    out: Option<&Path>,
    report_dir: Option<&Path>,
) -> anyhow::Result<ExitCode> {
    let board = Board::parse(board, square).map_err(anyhow::Error::msg)?;
    let mut file = read_lenient(camera_file)?;
    let c = &file.camera;
    let camera = tangent_core::camera::Camera {
        width: c.width_px,
        height: c.height_px,
        fx: c.fx_px,
        fy: c.fy_px,
        cx: c.cx_px,
        cy: c.cy_px,
        distortion: tangent_core::camera::Distortion {
            k1: c.distortion.k1,
            k2: c.distortion.k2,
            k3: c.distortion.k3,
            p1: c.distortion.p1,
            p2: c.distortion.p2,
        },
    };
    camera
        .validate()
        .map_err(|e| anyhow::anyhow!("camera in {}: {e}", camera_file.display()))?;

    // Per laser index: (board view, stripe pixels) of every pose.
    let mut per_plane: Vec<Vec<(View, Vec<Vec2>)>> = Vec::new();
    for dir in captures {
        let name = dir.display().to_string();
        let cap = match Capture::read(dir) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("skipping {name}: {e}");
                continue;
            }
        };
        let (off_img, off) = pgm_to_gray(cap.off_frame());
        if (off_img.width(), off_img.height()) != (camera.width, camera.height) {
            eprintln!("skipping {name}: frame size differs from the camera's");
            continue;
        }
        let view = match corners::detect(&off_img, &board, &name) {
            Ok(v) => v,
            Err(e) => {
                eprintln!("skipping {name}: board: {e}");
                continue;
            }
        };
        for (lasers, frame) in cap.on_frames() {
            if lasers.len() != 1 {
                eprintln!(
                    "{name}: skipping a frame lighting {} lasers (calibrate one laser per frame)",
                    lasers.len()
                );
                continue;
            }
            let (_, on) = pgm_to_gray(frame);
            let diff: Vec<f64> = on.iter().zip(&off).map(|(a, b)| a - b).collect();
            let pixels = laser::stripe_pixels(&diff, frame.width, frame.height);
            let k = lasers[0];
            if per_plane.len() <= k {
                per_plane.resize_with(k + 1, Vec::new);
            }
            eprintln!(
                "{name}: laser {k}: {} stripe pixels, {} corners",
                pixels.len(),
                view.corners.len()
            );
            per_plane[k].push((view.clone(), pixels));
        }
    }
    if per_plane.is_empty() {
        bail!("no usable capture");
    }
    let mut text = String::new();
    let mut planes = Vec::new();
    for (k, poses) in per_plane.iter().enumerate() {
        if poses.is_empty() {
            bail!("laser {k}: no capture lights it alone; planes must be calibrated 0..n");
        }
        let cal = laser::calibrate_plane(&camera, &board, poses, None)
            .with_context(|| format!("laser {k}"))?;
        text.push_str(&report::laser_text(k, &cal));
        let p = cal.plane;
        planes.push(PlaneToml {
            normal: [p.normal.x, p.normal.y, p.normal.z],
            offset_m: p.offset,
            source_m: [p.source.x, p.source.y, p.source.z],
        });
    }
    print!("{text}");
    file.planes = planes;
    let calibration = file.to_calibration()?;
    let out = out.unwrap_or(camera_file);
    calibration_file::write(out, &calibration)?;
    eprintln!("wrote {}", out.display());
    if let Some(dir) = report_dir {
        std::fs::create_dir_all(dir)?;
        std::fs::write(dir.join("laser-report.txt"), &text)?;
    }
    Ok(ExitCode::SUCCESS)
}
