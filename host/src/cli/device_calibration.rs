//! `tangent device-calibration push|pull`: store a calibration file on the device, or read
//! the device's back, as the calibration TOML file of `docs/formats.md`. (Computing a
//! calibration is `tangent calibrate`.)

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use tangent_core::protocol::{WireAccelerometer, WireCalibration};
use tangent_host::calibration_file;
use tangent_host::link::{Link, LinkConfig};

use super::devices::resolve_port;

/// Arguments of `tangent device-calibration`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Store a calibration file on the device (validated there, then active); read back
    /// and compared.
    Push {
        /// Serial port (default: the connected Tangent).
        #[arg(long)]
        port: Option<String>,
        /// Calibration TOML (from `tangent calibrate`).
        file: PathBuf,
    },
    /// Read the device's calibration as TOML (to FILE, or standard output).
    Pull {
        /// Serial port (default: the connected Tangent).
        #[arg(long)]
        port: Option<String>,
        /// Where to write it.
        file: Option<PathBuf>,
    },
}

/// The `[accelerometer]` table as the device takes it: one σ for every axis, the largest
/// of the three (the device's σ of gravity then covers every direction).
fn wire_accelerometer(a: &calibration_file::AccelerometerToml) -> WireAccelerometer {
    let largest = |v: [f64; 3]| v.into_iter().fold(0.0, f64::max);
    WireAccelerometer {
        bias_m_s2: a.bias_m_s2,
        bias_sigma_m_s2: largest(a.bias_sigma_m_s2),
        camera_from_sensor_rad: a.camera_from_sensor_rad,
        alignment_sigma_rad: largest(a.alignment_sigma_rad),
    }
}

/// Runs `tangent device-calibration …`.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.command {
        Command::Push { port, file } => {
            // The error names the file.
            let cal = calibration_file::read(&file)?;
            let mut wire = WireCalibration::from(&cal);
            // The accelerometer's calibration travels with the camera's: the device turns
            // its readings into the plumb with it (`docs/building.md` §6).
            wire.accelerometer = calibration_file::read_accelerometer(&file)?
                .as_ref()
                .map(wire_accelerometer);
            let path = resolve_port(port)?;
            let mut link = Link::open(&path, LinkConfig::default())?;
            link.write_calibration(&wire)?;
            match link.read_calibration()? {
                Some(back) if back == wire => {}
                Some(_) => {
                    bail!("the device stored a different calibration than was sent: push again")
                }
                None => bail!("the device acknowledged the calibration but does not report one"),
            }
            eprintln!(
                "calibration {} stored on the device at {path} and verified",
                cal.id
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Pull { port, file } => {
            let path = resolve_port(port)?;
            let mut link = Link::open(&path, LinkConfig::default())?;
            let Some(wire) = link.read_calibration()? else {
                bail!(
                    "the device at {path} has no calibration: push one with `tangent device-calibration push`"
                );
            };
            let cal = wire
                .to_calibration()
                .map_err(|e| anyhow::anyhow!("the device's calibration is invalid: {e:?}"))?;
            let text = calibration_file::to_string(&cal);
            match file {
                Some(f) => {
                    std::fs::write(&f, text)
                        .with_context(|| format!("cannot write {}", f.display()))?;
                    eprintln!("calibration {} written to {}", cal.id, f.display());
                }
                None => print!("{text}"),
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}
