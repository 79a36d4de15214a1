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
use tangent_host::calibrate::{corners, laser, refine, report, Board};
use tangent_host::calibration_file::{self, CalibrationToml, CameraToml, DistortionToml};
use tangent_host::capture::Capture;

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
        /// Directory for the report (text, and one PNG per capture: corners and stripes).
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

    // An existing output keeps its id and planes (re-calibrating the camera of a unit).
    let existing = if out.exists() {
        Some(calibration_file::read_camera(out)?)
    } else {
        None
    };
    let c = cal.camera;
    let d = c.distortion;
    let file = CalibrationToml {
        id: id.or(existing.as_ref().map(|e| e.0)).unwrap_or(0),
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
        planes: existing.map(|e| e.2).unwrap_or_default(),
        road: None,
    };
    std::fs::write(out, toml::to_string(&file)?)
        .with_context(|| format!("writing {}", out.display()))?;
    eprintln!("wrote {}", out.display());
    if let Some(dir) = report_dir {
        report::write_camera_report(dir, &cal, &grays, &skipped)
            .with_context(|| format!("writing the report in {}", dir.display()))?;
        eprintln!("report in {}", dir.display());
    }
    Ok(ExitCode::SUCCESS)
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
    // The error names the file.
    let (id, camera, _) = calibration_file::read_camera(camera_file)?;

    let mut prepared = Vec::new();
    let mut skipped = Vec::new();
    for dir in captures {
        let name = dir.display().to_string();
        let got = Capture::read(dir)
            .map_err(|e| e.to_string())
            .and_then(|cap| laser::board_capture(&camera, &board, &cap, &name));
        match got {
            Ok(c) => {
                for (k, px) in &c.stripes {
                    eprintln!(
                        "{name}: laser {k}: {} stripe pixels, {} corners",
                        px.len(),
                        c.view.corners.len()
                    );
                }
                prepared.push(c);
            }
            Err(e) => {
                eprintln!("skipping {name}: {e}");
                skipped.push((name, e));
            }
        }
    }
    if prepared.is_empty() {
        bail!("no usable capture");
    }
    let cals = laser::calibrate_lasers(&camera, &board, &prepared)?;
    let mut text = String::new();
    for (name, why) in &skipped {
        text.push_str(&format!("skipped {name}: {why}\n"));
    }
    for (k, cal) in cals.iter().enumerate() {
        text.push_str(&report::laser_text(k, cal));
    }
    print!("{text}");
    let planes: Vec<_> = cals.iter().map(|c| c.plane).collect();
    let calibration = tangent_core::calibration::Calibration::new(id, camera, &planes)
        .map_err(|e| anyhow::anyhow!("calibration: {e:?}"))?;
    let out = out.unwrap_or(camera_file);
    calibration_file::write(out, &calibration)?;
    eprintln!("wrote {}", out.display());
    if let Some(dir) = report_dir {
        report::write_laser_report(dir, &text, &prepared, &cals)
            .with_context(|| format!("writing the report in {}", dir.display()))?;
        eprintln!("report in {}", dir.display());
    }
    Ok(ExitCode::SUCCESS)
}
