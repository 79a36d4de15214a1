//! `tangent devices`: the serial ports that look like a Tangent (its USB VID/PID,
//! `protocol::codes::USB_VID`/`USB_PID`).

use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use tangent_core::protocol::codes::{USB_PID, USB_VID};
use tangent_host::link;

/// Arguments of `tangent devices`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Also list serial ports that are not Tangents.
    #[arg(long)]
    all: bool,
}

/// Lists ports; exits with failure when no Tangent is connected.
pub fn run(args: Args) -> Result<ExitCode> {
    let ports = link::list_ports().context("cannot list the serial ports")?;
    let tangents: Vec<_> = ports.iter().filter(|p| p.is_tangent).collect();
    for p in &tangents {
        println!(
            "{}\tTangent (USB {:04x}:{:04x}, serial {})",
            p.path,
            USB_VID,
            USB_PID,
            p.serial_number.as_deref().unwrap_or("unknown")
        );
    }
    if args.all || tangents.is_empty() {
        for p in ports.iter().filter(|p| !p.is_tangent) {
            let what = match (p.usb, &p.product) {
                (Some((v, d)), Some(name)) => format!("USB {v:04x}:{d:04x} {name}"),
                (Some((v, d)), None) => format!("USB {v:04x}:{d:04x}"),
                (None, _) => "not USB".to_string(),
            };
            println!("{}\tnot a Tangent ({what})", p.path);
        }
    }
    if tangents.is_empty() {
        eprintln!(
            "no Tangent found (looking for USB {USB_VID:04x}:{USB_PID:04x}): \
             plug the caliper in and switch it on. The emulated device is not USB: \
             use the pty path `firmware/qemu/run.sh --serial pty` prints, with --port."
        );
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

/// The port to use: `--port` if given, else the only Tangent connected.
pub fn resolve_port(port: Option<String>) -> Result<String> {
    if let Some(p) = port {
        return Ok(p);
    }
    let ports = link::list_ports().context("cannot list the serial ports")?;
    let tangents: Vec<_> = ports.into_iter().filter(|p| p.is_tangent).collect();
    match tangents.as_slice() {
        [one] => Ok(one.path.clone()),
        [] => bail!("no Tangent connected: plug it in, or give --port PATH (`tangent devices` lists the ports)"),
        many => bail!(
            "several Tangents connected ({}): choose one with --port",
            many.iter().map(|p| p.path.as_str()).collect::<Vec<_>>().join(", ")
        ),
    }
}
