//! `tangent record --port P OUT/`: capture raw frame pairs on the device and write them as
//! capture directories (`docs/formats.md`) with the device's calibration.

use std::path::PathBuf;
use std::process::ExitCode;
use std::str::FromStr;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use tangent_core::calibration::Calibration;
use tangent_core::protocol::{Board, FrameSel, FrameSetInfo};
use tangent_host::capture::{Capture, CaptureMeta, FrameEntry, Mode, FORMAT_VERSION};
use tangent_host::link::{Link, LinkConfig};
use tangent_host::pgm::Pgm;
use tangent_host::{calibration_file, fieldlog};

use super::devices::resolve_port;

/// Arguments of `tangent record`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial port (default: the connected Tangent).
    #[arg(long)]
    port: Option<String>,
    /// Output capture directory (with --count > 1: a directory of captures 001/, 002/, …).
    out: PathBuf,
    /// Number of frame pairs to record.
    #[arg(long, default_value_t = 1)]
    count: u32,
    /// Calibration file to store in the captures when the device has none.
    #[arg(long)]
    calib: Option<PathBuf>,
    /// What the captures measure.
    #[arg(long, default_value = "cylinder")]
    mode: String,
    /// Free-text description stored in each capture.
    #[arg(long, default_value = "")]
    description: String,
}

/// Records the captures.
pub fn run(args: Args) -> Result<ExitCode> {
    let mode: Mode = toml::Value::String(args.mode.clone())
        .try_into()
        .map_err(|_| anyhow::anyhow!("--mode must be cylinder, sphere, wall or road"))?;
    let path = resolve_port(args.port.clone())?;
    let mut link = Link::open(&path, LinkConfig::default())?;
    let board = link.identity().board;
    let device_cal = link.read_calibration()?;
    let calibration = match (device_cal, &args.calib) {
        // The error names the file.
        (_, Some(file)) => calibration_file::read(file)?,
        (Some(w), None) => w
            .to_calibration()
            .map_err(|e| anyhow::anyhow!("the device's calibration is invalid: {e:?}"))?,
        (None, None) => bail!(
            "the device has no calibration and a capture needs one: push one \
             (`tangent device-calibration push`) or give --calib FILE"
        ),
    };
    for i in 0..args.count {
        let dir = if args.count == 1 {
            args.out.clone()
        } else {
            args.out.join(format!("{:03}", i + 1))
        };
        let info = link.capture_frames()?;
        let total = 2 * info.width as u64 * info.height as u64;
        let bar = ProgressBar::new(total).with_style(
            ProgressStyle::with_template("{msg} [{bar:40}] {bytes}/{total_bytes} {bytes_per_sec}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_message(format!("pair {}/{}", i + 1, args.count));
        let frame_len = info.width as u64 * info.height as u64;
        let off = link.read_frame(&info, FrameSel::Off, |n| bar.set_position(n as u64))?;
        let on = link.read_frame(&info, FrameSel::On, |n| {
            bar.set_position(frame_len + n as u64)
        })?;
        bar.finish_and_clear();
        let capture = build_capture(&info, off, on, &calibration, board, mode, &args.description)?;
        // A capture's errors name its files relative to it.
        capture
            .write(&dir)
            .with_context(|| format!("cannot write the capture {}", dir.display()))?;
        eprintln!(
            "{}: {}×{} pair, exposure {} µs, lasers {:#04b}",
            dir.display(),
            info.width,
            info.height,
            info.exposure_us,
            info.laser_mask
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// The capture of one dumped pair. A frame that is a window of sensor rows gets the
/// calibration of that window (principal point moved up by the row offset).
pub fn build_capture(
    info: &FrameSetInfo,
    off: Vec<u8>,
    on: Vec<u8>,
    calibration: &Calibration,
    board: Board,
    mode: Mode,
    description: &str,
) -> Result<Capture> {
    let (w, h) = (info.width as usize, info.height as usize);
    let mut cal = calibration.clone();
    if info.row_offset != 0 || cal.camera.height != h as u32 {
        cal.camera.cy -= info.row_offset as f64;
        cal.camera.height = h as u32;
    }
    if cal.camera.width != w as u32 {
        bail!(
            "the calibration is for {} px wide frames, the device sent {w}",
            cal.camera.width
        );
    }
    let lasers_on: Vec<usize> = (0..8)
        .filter(|i| info.laser_mask & (1 << i) != 0 && *i < cal.planes.len())
        .collect();
    if lasers_on.is_empty() {
        bail!(
            "the laser-on frame lit no calibrated laser (mask {:#04b})",
            info.laser_mask
        );
    }
    let sensor = match board {
        Board::H743 => "MT9V034",
        Board::Emulated => "emulated MT9V034",
    };
    let mut text = format!(
        "recorded from the device: capture {}, device time {} ms, sensor rows {}..{}",
        info.capture,
        info.timestamp_ms,
        info.row_offset,
        info.row_offset as usize + h
    );
    if !description.is_empty() {
        text = format!("{description} ({text})");
    }
    let meta = CaptureMeta {
        format_version: FORMAT_VERSION,
        sensor: sensor.to_string(),
        width: w as u32,
        height: h as u32,
        bit_depth: info.bit_depth,
        exposure_s: info.exposure_us as f64 * 1e-6,
        gain: 1.0,
        mode,
        timestamp: toml::value::Datetime::from_str(&fieldlog::now_rfc3339())
            .context("timestamp")?,
        description: text,
        frames: vec![
            FrameEntry {
                file: "off.pgm".into(),
                lasers_on: vec![],
                pair: 0,
            },
            FrameEntry {
                file: "on.pgm".into(),
                lasers_on,
                pair: 0,
            },
        ],
        calibration: toml::Value::Table(Default::default()),
        truth: None,
        simulation: None,
        accelerometer: None,
    };
    let maxval = ((1u32 << info.bit_depth.clamp(1, 8)) - 1) as u8;
    Ok(Capture {
        meta,
        calibration: cal,
        frames: vec![
            Pgm::from_u8(w, h, maxval, off)?,
            Pgm::from_u8(w, h, maxval, on)?,
        ],
        truth_curve: None,
        truth_curve_unreadable: None,
    })
}
