//! `tangent calibrate camera IMAGES… --board 9x6 --square 25mm`,
//! `tangent calibrate laser CAPTURES… --camera FILE` and
//! `tangent calibrate ball CAPTURES… --calib FILE [--diameter-mm D]`,
//! `tangent calibrate road CAPTURES… --steps-mm 0,0.1,… --calib FILE` and
//! `tangent calibrate accelerometer POSES.toml --calib FILE`.
//!
//! The camera command writes a calibration file whose `[camera]` is the new calibration;
//! if the output file already exists its id and laser planes are kept, otherwise it has no
//! `[[planes]]` yet (a camera-only file, which `calibrate laser` completes). The laser
//! command reads the camera from such a file and writes the complete calibration. The road
//! command (a road head's piezo height-scale calibration, `docs/road.md`) fits the measured
//! heights of a flat target against the stage's known steps and writes the result with its
//! residuals into the file's `[road]` table. The ball command refines the laser planes
//! against each other on sphere-mode captures of one ball (`docs/calibration.md`, section 12)
//! and rewrites the file's `[[planes]]`. The accelerometer command solves the sensor's
//! bias, scale and alignment to the camera from static poses (`docs/hardware.md`,
//! "Accelerometer calibration") and writes the file's `[accelerometer]` table.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context as _};
use clap::Subcommand;
use tangent_core::instrument::road::RoadParams;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::protocol::codes::Failure;
use tangent_host::calibrate::reference::{self, ReferenceView};
use tangent_host::calibrate::{corners, laser, refine, report, Board};
use tangent_host::calibration_file::{
    self, AccelerometerToml, CalibrationToml, CameraToml, DistortionToml, RoadToml,
};
use tangent_host::capture::Capture;
use tangent_host::measure::measure_road_dir;
use tangent_host::road::height_scale::fit_height_scale;

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
    /// Laser planes refined against each other on sphere-mode captures of one ball at
    /// several distances (`docs/calibration.md`, section 12); rewrites `[[planes]]` in --calib.
    Ball {
        /// Capture directories of the ball (sphere mode), at least three, at 0.5–1.6 m, both
        /// lines across the ball.
        #[arg(required = true)]
        captures: Vec<PathBuf>,
        /// The head's calibration file: its planes are the start and the prior; they are
        /// rewritten, every other key kept.
        #[arg(long)]
        calib: PathBuf,
        /// The ball's certified diameter in millimetres, if it has one (adds the common scale).
        #[arg(long)]
        diameter_mm: Option<f64>,
        /// 1σ of that diameter in millimetres.
        #[arg(long, default_value_t = 0.005)]
        diameter_sigma_mm: f64,
        /// Print the result without writing the file.
        #[arg(long)]
        dry_run: bool,
    },
    /// Laser planes refined against each other on wall-mode captures of one flat wall at
    /// several distances, every line on it (`docs/calibration.md`, section 13); rewrites
    /// `[[planes]]` in --calib.
    Wall {
        /// Capture directories of the wall (wall mode), at least three, at 1–3 m, turned
        /// and tilted a little differently each time.
        #[arg(required = true)]
        captures: Vec<PathBuf>,
        /// The head's calibration file: its planes are the start and the prior; they are
        /// rewritten, every other key kept.
        #[arg(long)]
        calib: PathBuf,
        /// Print the result without writing the file.
        #[arg(long)]
        dry_run: bool,
    },
    /// Road head: height scale from a flat target on a piezo stage raised in known steps
    /// (`docs/road.md`, "Height-scale calibration"); writes `[road]` into the --calib file.
    Road {
        /// Capture directories of the flat target, one per stage position, in the order of
        /// --steps-mm.
        #[arg(required = true)]
        captures: Vec<PathBuf>,
        /// The stage's known positions in millimetres (towards the head), one per capture:
        /// `0,0.1,0.2`.
        #[arg(
            long,
            value_delimiter = ',',
            required = true,
            allow_negative_numbers = true
        )]
        steps_mm: Vec<f64>,
        /// The head's calibration file: its camera and plane measure the captures, and its
        /// `[road]` table is (re)written; every other key is kept.
        #[arg(long)]
        calib: PathBuf,
    },
    /// Accelerometer bias, scale and alignment to the camera from static poses, each the
    /// sensor's mean reading and gravity in the camera frame from the chessboard lying level
    /// (`docs/hardware.md`, "Accelerometer calibration"); writes `[accelerometer]` into the
    /// --calib file.
    Accelerometer {
        /// The poses: a TOML file of `[[pose]]` tables (`docs/formats.md`, "Accelerometer
        /// poses").
        poses: PathBuf,
        /// The device's calibration file: its `[accelerometer]` table is (re)written; every
        /// other key is kept.
        #[arg(long)]
        calib: PathBuf,
    },
}

/// The poses file of `tangent calibrate accelerometer`.
#[derive(serde::Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct PosesFile {
    pose: Vec<PoseToml>,
}

/// One `[[pose]]`.
#[derive(serde::Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct PoseToml {
    /// Mean specific force over the pose (sensor axes, m/s²).
    mean_m_s2: [f64; 3],
    /// 1σ of that mean per axis (m/s²).
    sigma_m_s2: f64,
    /// Gravity in the camera frame (down, any length), from the chessboard's pose.
    gravity_camera: [f64; 3],
    /// 1σ of its direction about each axis across it (radians).
    direction_sigma_rad: f64,
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
        Which::Road {
            captures,
            steps_mm,
            calib,
        } => road_cmd(&captures, &steps_mm, &calib),
        Which::Ball {
            captures,
            calib,
            diameter_mm,
            diameter_sigma_mm,
            dry_run,
        } => reference_cmd(
            &captures,
            &calib,
            Reference::Ball(diameter_mm.map(|d| (d, diameter_sigma_mm))),
            dry_run,
        ),
        Which::Wall {
            captures,
            calib,
            dry_run,
        } => reference_cmd(&captures, &calib, Reference::Wall, dry_run),
        Which::Accelerometer { poses, calib } => accelerometer_cmd(&poses, &calib),
    }
}

/// `tangent calibrate accelerometer`: the poses solved ([`accelerometer::calibrate`]), the
/// result printed with its σ and residuals, `[accelerometer]` written.
fn accelerometer_cmd(poses: &Path, calib: &Path) -> anyhow::Result<ExitCode> {
    use tangent_core::accelerometer::{self, Pose, STANDARD_GRAVITY};
    use tangent_core::real::Vec3;
    let text =
        std::fs::read_to_string(poses).with_context(|| format!("reading {}", poses.display()))?;
    let file: PosesFile =
        toml::from_str(&text).with_context(|| format!("{}: not a poses file", poses.display()))?;
    let v = |a: [f64; 3]| Vec3::new(a[0], a[1], a[2]);
    let poses_in: Vec<Pose> = file
        .pose
        .iter()
        .map(|p| Pose {
            mean_m_s2: v(p.mean_m_s2),
            sigma_m_s2: p.sigma_m_s2,
            gravity_camera: v(p.gravity_camera),
            direction_sigma_rad: p.direction_sigma_rad,
        })
        .collect();
    let cal = accelerometer::calibrate(&poses_in).map_err(|e| {
        anyhow::anyhow!(
            "{}: the poses do not determine the calibration ({e}): give at least three poses, \
             with gravity along two independent directions at least (e.g. the six faces), \
             every σ positive",
            poses.display()
        )
    })?;
    let mg = 1e-3 * STANDARD_GRAVITY;
    println!("pose  residual (mg)");
    for (i, p) in poses_in.iter().enumerate() {
        if let Some(r) = accelerometer::residual(p, &cal) {
            println!("{i:4}  {:+.3} {:+.3} {:+.3}", r.x / mg, r.y / mg, r.z / mg);
        }
    }
    let b = cal.bias_m_s2 / mg;
    let bs = cal.bias_sigma_m_s2 / mg;
    let a = cal.camera_from_sensor_rad.map(f64::to_degrees);
    let as_ = cal.alignment_sigma_rad.map(f64::to_degrees);
    println!(
        "bias [{:+.3}, {:+.3}, {:+.3}] mg ± [{:.3}, {:.3}, {:.3}] mg",
        b.x, b.y, b.z, bs.x, bs.y, bs.z
    );
    println!(
        "camera_from_sensor [{:+.4}, {:+.4}, {:+.4}]° ± [{:.4}, {:.4}, {:.4}]°",
        a.x, a.y, a.z, as_.x, as_.y, as_.z
    );
    println!(
        "scale {:.5} ± {:.5}, residual RMS {:.3} mg, χ²/dof {:.2} over {} poses",
        cal.scale,
        cal.scale_sigma,
        cal.rms_m_s2 / mg,
        cal.chi2,
        cal.poses
    );
    calibration_file::write_accelerometer(calib, &AccelerometerToml::from_calibration(&cal))?;
    eprintln!("wrote [accelerometer] in {}", calib.display());
    Ok(ExitCode::SUCCESS)
}

/// `tangent calibrate road`: each capture's mean profile height, measured with no height
/// correction, fitted against the stage's steps ([`fit_height_scale`]); the table of
/// residuals is printed and `[road]` written.
/// The reference surface of `tangent calibrate ball` or `wall`.
enum Reference {
    /// A ball, with its certified diameter and σ in millimetres if it has one.
    Ball(Option<(f64, f64)>),
    /// A flat wall.
    Wall,
}

/// `tangent calibrate ball` and `wall`: each capture measured with the file's calibration,
/// the planes refined ([`reference::refine_planes`], prior the error model's calibration σ),
/// the corrections and the views' fits printed, `[[planes]]` rewritten.
fn reference_cmd(
    captures: &[PathBuf],
    calib: &Path,
    which: Reference,
    dry_run: bool,
) -> anyhow::Result<ExitCode> {
    let calibration = calibration_file::read(calib)?;
    let diameter_mm = match which {
        Reference::Ball(d) => d,
        Reference::Wall => None,
    };
    let known = match diameter_mm {
        Some((d, s)) if d > 0.0 && s > 0.0 && d.is_finite() && s.is_finite() => {
            Some(reference::KnownDiameter {
                diameter: d * 1e-3,
                sigma: s * 1e-3,
            })
        }
        Some((d, s)) => {
            bail!("--diameter-mm {d} --diameter-sigma-mm {s}: both must be positive and finite")
        }
        None => None,
    };
    let mut views = Vec::with_capacity(captures.len());
    for dir in captures {
        let name = dir.display().to_string();
        // A capture that cannot be read is the user's mistake: refused, named. One the
        // sphere solver refuses with this calibration (its sections disagree too much, or a
        // line misses the ball) is skipped with its reason, as `calibrate laser` skips a pose.
        let capture = Capture::read(dir).map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        let view = match which {
            Reference::Ball(_) => ReferenceView::of_ball(&capture, &calibration, &name),
            Reference::Wall => ReferenceView::of_wall(&capture, &calibration, &name),
        };
        match view {
            Ok(v) => views.push(v),
            Err(e @ tangent_host::calibrate::CalibrateError::NotAReferenceCapture(..)) => {
                return Err(e.into())
            }
            Err(e) => eprintln!("skipping {e}"),
        }
    }
    let prior = tangent_core::noise::NoiseModel::reference();
    let fit = reference::refine_planes(&calibration, &views, &prior, known)?;
    for why in &fit.skipped {
        eprintln!("skipped {why}");
    }
    let size = match which {
        Reference::Ball(_) => "diameter",
        Reference::Wall => "depth   ",
    };
    println!("view                                   distance   {size} before → after   RMS before → after   points");
    for v in &fit.views {
        println!(
            "{:<38} {:6.3} m   {:9.2} → {:9.2} mm   {:6.3} → {:6.3} mm   {}/{}",
            v.name,
            v.distance,
            v.size.0 * 1e3,
            v.size.1 * 1e3,
            v.rms.0 * 1e3,
            v.rms.1 * 1e3,
            v.kept.0,
            v.kept.1
        );
    }
    for (k, c) in fit.corrections.iter().enumerate() {
        println!(
            "laser {k}: e {:+.3} ± {:.3} mm, δ {:+.4} ± {:.4} mrad",
            c.baseline * 1e3,
            c.baseline_sigma * 1e3,
            c.tilt * 1e3,
            c.tilt_sigma * 1e3
        );
    }
    for (k, (tilt, baseline)) in fit.relative.iter().enumerate() {
        println!(
            "laser {} against laser 0: δ ± {:.4} mrad, e ± {:.3} mm (the board calibration's: ± {:.4} mrad, ± {:.3} mm)",
            k + 1,
            tilt * 1e3,
            baseline * 1e3,
            std::f64::consts::SQRT_2 * prior.tilt * 1e3,
            std::f64::consts::SQRT_2 * prior.baseline * 1e3
        );
    }
    if dry_run {
        eprintln!("--dry-run: {} not written", calib.display());
    } else {
        calibration_file::write_planes(calib, &fit.calibration)?;
        eprintln!(
            "wrote [[planes]] and their [planes_uncertainty] in {}",
            calib.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn road_cmd(captures: &[PathBuf], steps_mm: &[f64], calib: &Path) -> anyhow::Result<ExitCode> {
    if captures.len() != steps_mm.len() {
        bail!(
            "{} captures but {} --steps-mm values: give one stage position per capture",
            captures.len(),
            steps_mm.len()
        );
    }
    let calibration = calibration_file::read(calib)?;
    let config = PipelineConfig::default();
    // The stage is measured uncorrected: the fit is what the correction is made from.
    let params = RoadParams::default();
    let mut measured = Vec::with_capacity(captures.len());
    for dir in captures {
        let outcome = measure_road_dir(dir, Some(&calibration), &config, &params)
            .with_context(|| format!("measuring {}", dir.display()))?;
        let solution = outcome.result.map_err(|e| {
            anyhow::anyhow!(
                "{}: no profile of the flat target: {}",
                dir.display(),
                Failure::of(&e)
            )
        })?;
        measured.push(solution.profile.mean_height);
    }
    let steps: Vec<f64> = steps_mm.iter().map(|s| s * 1e-3).collect();
    let Some(fit) = fit_height_scale(&steps, &measured) else {
        bail!("the stage's steps must take at least two distinct values and the measured heights must rise with them");
    };
    println!("step (mm)  measured (mm)  residual (µm)");
    for ((s, m), r) in fit
        .steps_m
        .iter()
        .zip(&fit.measured_m)
        .zip(&fit.residuals_m)
    {
        println!("{:9.4}  {:13.4}  {:+13.2}", s * 1e3, m * 1e3, r * 1e6);
    }
    println!(
        "gain {:.5}, offset {:+.4} mm, residual RMS {:.2} µm -> height_scale = {:.5}",
        fit.gain,
        fit.offset_m * 1e3,
        fit.residual_rms_m * 1e6,
        fit.height_scale
    );
    let road = RoadToml {
        height_scale: fit.height_scale,
        residual_rms_m: fit.residual_rms_m,
        steps: fit.steps_m.len(),
        step_positions_m: fit.steps_m.clone(),
        residuals_m: fit.residuals_m.clone(),
    };
    // The file's own check refuses a scale outside its accepted range, naming the key.
    calibration_file::write_road(calib, &road)?;
    eprintln!("wrote [road] in {}", calib.display());
    Ok(ExitCode::SUCCESS)
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
        // A refinement's covariance was of the planes seen through the old camera.
        planes_uncertainty: None,
        road: None,
        accelerometer: None,
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
