//! `tangent flash`: build the STM32H743 firmware and flash it through probe-rs (or print
//! the exact probe-rs command when probe-rs is not installed).

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use anyhow::{bail, Context, Result};

/// The chip of the Tangent board.
pub const CHIP: &str = "STM32H743ZITx";

/// Arguments of `tangent flash`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Repository root (holds `firmware/Cargo.toml`; default: found from the current
    /// directory upwards).
    #[arg(long)]
    repo: Option<PathBuf>,
    /// Only print the commands.
    #[arg(long)]
    dry_run: bool,
}

fn find_repo(start: &Path) -> Option<PathBuf> {
    start
        .ancestors()
        .find(|d| d.join("firmware/Cargo.toml").is_file())
        .map(Path::to_path_buf)
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|d| d.join(program).is_file()))
}

/// Builds, then flashes.
pub fn run(args: Args) -> Result<ExitCode> {
    let repo = match args.repo {
        Some(r) => r,
        None => {
            let cwd = std::env::current_dir()?;
            find_repo(&cwd).with_context(|| {
                format!(
                    "no firmware/Cargo.toml in {} or above: run from the repository or give --repo",
                    cwd.display()
                )
            })?
        }
    };
    let manifest = repo.join("firmware/Cargo.toml");
    let target_dir = repo.join("firmware/target");
    let elf = target_dir.join("thumbv7em-none-eabihf/release/tangent-h743");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let build = [
        "build",
        "--manifest-path",
        &manifest.to_string_lossy(),
        "--release",
        "--target",
        "thumbv7em-none-eabihf",
        "--target-dir",
        &target_dir.to_string_lossy(),
    ]
    .map(String::from);
    let flash = ["run", "--chip", CHIP, &elf.to_string_lossy()].map(String::from);
    println!("{cargo} {}", build.join(" "));
    if !args.dry_run {
        let status = Command::new(&cargo)
            .args(&build)
            .current_dir(&repo)
            .status()
            .with_context(|| format!("cannot run {cargo}"))?;
        if !status.success() {
            bail!("the firmware build failed (see above)");
        }
    }
    let command = format!("probe-rs {}", flash.join(" "));
    if args.dry_run {
        println!("{command}");
        return Ok(ExitCode::SUCCESS);
    }
    if !on_path("probe-rs") {
        eprintln!(
            "probe-rs is not installed (https://probe.rs: `cargo install probe-rs-tools`). \
             Connect the debug probe to the board's SWD header and run:\n  {command}"
        );
        return Ok(ExitCode::from(2));
    }
    println!("{command}");
    let status = Command::new("probe-rs")
        .args(&flash)
        .status()
        .context("cannot run probe-rs")?;
    Ok(if status.success() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
