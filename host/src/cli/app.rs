//! `tangent app`: serves the field app (`app/`, built by `bash app/build.sh`) on localhost
//! and bridges a caliper to it over a WebSocket (`tangent_host::bridge`): a serial port
//! (`--port`), or the emulated caliper under QEMU (`--emulator`, with the corpus's stems
//! as its camera's scenes). Without either, the page talks to the caliper itself through
//! the browser's Web Serial.

use std::io::Read;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{ExitCode, Stdio};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use tangent_core::protocol::{calibration_record, WireCalibration};
use tangent_host::bridge::{self, Bridge};
use tangent_host::link::BAUD;
use tangent_host::simulate::{corpus, simulate};

/// Corpus stems the emulated caliper's camera cycles through: one calibration (the
/// one-plane reference design), several diameters, and an elliptic stem (a reading with
/// warnings).
const SCENES: [&str; 6] = [
    "cyl-d300-z150-shade",
    "cyl-d450-z100-shade",
    "cyl-d200-z050-shade",
    "cyl-d600-z150-shade",
    "ell-a350-b250-z200-rot45",
    "cyl-d100-z100-shade",
];

/// Arguments of `tangent app`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Address to serve on (port 0: any free port; the URL is printed).
    #[arg(long, default_value = "127.0.0.1:8787")]
    listen: String,
    /// The built app (default: app/dist of this repository).
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Bridge this serial port to the page (for browsers without Web Serial).
    #[arg(long, conflicts_with = "emulator")]
    port: Option<String>,
    /// Bridge the emulated caliper (QEMU) to the page, and offer /control/ to pull its
    /// trigger and its cable (tests).
    #[arg(long)]
    emulator: bool,
    /// The emulated firmware (default: firmware/target/…/release/tangent-qemu, built by
    /// `cargo firmware-qemu`).
    #[arg(long, requires = "emulator")]
    elf: Option<PathBuf>,
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Runs the server until interrupted.
pub fn run(args: Args) -> Result<ExitCode> {
    let dir = args.dir.unwrap_or_else(|| repo_root().join("app/dist"));
    if !dir.join("index.html").is_file() {
        bail!(
            "{} has no built app (index.html): build it with `bash app/build.sh`",
            dir.display()
        );
    }
    let listener = TcpListener::bind(&args.listen)
        .with_context(|| format!("cannot listen on {}", args.listen))?;
    let bridge = if let Some(port) = &args.port {
        Some(serial_bridge(port)?)
    } else if args.emulator {
        let elf = args.elf.unwrap_or_else(|| {
            repo_root().join("firmware/target/thumbv7em-none-eabihf/release/tangent-qemu")
        });
        Some(emulator_bridge(&elf)?)
    } else {
        None
    };
    let url = format!("http://{}/", listener.local_addr()?);
    println!("field app: {url}");
    match &bridge {
        Some(_) => println!(
            "caliper bridged at {}bridge (WebSocket)",
            url.replace("http", "ws")
        ),
        None => println!("no caliper bridged: connect it in the page (Web Serial)"),
    }
    let bridge = bridge.unwrap_or_else(|| Bridge::new(Box::new(std::io::sink()), false));
    bridge::serve(listener, dir, bridge);
    Ok(ExitCode::SUCCESS)
}

/// A serial port behind the bridge, re-opened when it comes back after an unplug.
fn serial_bridge(path: &str) -> Result<Arc<Bridge>> {
    let open = |path: &str| {
        serialport::new(path, BAUD)
            .timeout(Duration::from_millis(50))
            .open()
    };
    let port = open(path).with_context(|| format!("cannot open {path}"))?;
    let writer = port.try_clone().context("cannot share the serial port")?;
    let bridge = Bridge::new(Box::new(writer), false);
    let b = bridge.clone();
    let path = path.to_string();
    std::thread::spawn(move || {
        let mut port = port;
        let mut buf = [0u8; 1024];
        loop {
            match port.read(&mut buf) {
                Ok(0) => {}
                Ok(n) => b.from_device(&buf[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => {
                    eprintln!("{path}: {e}; waiting for the caliper to come back");
                    b.drop_page();
                    port = loop {
                        std::thread::sleep(Duration::from_millis(200));
                        if let Ok(p) = open(&path) {
                            break p;
                        }
                    };
                    if let Ok(w) = port.try_clone() {
                        b.replace_device(Box::new(w));
                    }
                }
            }
        }
    });
    Ok(bridge)
}

/// The emulated caliper under QEMU, its UART on our pipes, the corpus stems as its scenes.
fn emulator_bridge(elf: &Path) -> Result<Arc<Bridge>> {
    if !elf.is_file() {
        bail!(
            "no emulated firmware at {}: build it with `cargo firmware-qemu`",
            elf.display()
        );
    }
    let scenes = scene_files()?;
    let mut args = format!(" --calib {}", scenes.calib.display());
    for (off, on) in &scenes.pairs {
        args += &format!(" {} {}", off.display(), on.display());
    }
    let mut cmd = tangent_host::emulator::qemu_command(elf, "stdio", false, &args);
    cmd.stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    // QEMU goes when we go (a killed `tangent app` must not leave the emulator running).
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        // SAFETY: prctl is async-signal-safe; it only sets a flag of the child process.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
    }
    let mut child = cmd
        .spawn()
        .context("cannot start qemu-system-arm (apt-get install qemu-system-arm)")?;
    let stdin = child.stdin.take().context("QEMU's stdin")?;
    let mut stdout = child.stdout.take().context("QEMU's stdout")?;
    let bridge = Bridge::new(Box::new(stdin), true);
    let b = bridge.clone();
    std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        while let Ok(n) = stdout.read(&mut buf) {
            if n == 0 {
                eprintln!("the emulated caliper stopped");
                b.drop_page();
                break;
            }
            b.from_device(&buf[..n]);
        }
        let _ = child.wait();
    });
    Ok(bridge)
}

/// Frame pairs and the calibration record of the emulated caliper's scenes.
struct Scenes {
    calib: PathBuf,
    pairs: Vec<(PathBuf, PathBuf)>,
}

/// Renders [`SCENES`] once into a cache directory (reused while its files are there).
fn scene_files() -> Result<Scenes> {
    let dir = std::env::temp_dir().join("tangent-app-scenes-2");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let calibration = corpus::one_plane_calibration();
    let calib = dir.join("calib.bin");
    let mut record = [0u8; calibration_record::MAX_RECORD];
    let n = calibration_record::encode(&WireCalibration::from(&calibration), &mut record)
        .context("cannot encode the calibration record")?;
    write_atomically(&calib, &record[..n])?;
    let entries = corpus::entries();
    let mut pairs = Vec::new();
    for name in SCENES {
        let off = dir.join(format!("{name}-off.pgm"));
        let on = dir.join(format!("{name}-on.pgm"));
        if !(off.is_file() && on.is_file()) {
            let entry = entries
                .iter()
                .find(|e| e.name == name)
                .with_context(|| format!("no corpus entry {name}"))?;
            if entry.spec.calibration != calibration {
                bail!("corpus entry {name} has another calibration than the emulated caliper's");
            }
            let (capture, _) =
                simulate(&entry.spec).with_context(|| format!("simulating {name}"))?;
            let (_, on_frame) = capture.on_frames().next().context("an on frame")?;
            write_atomically(&off, &pgm_u8(capture.off_frame()))?;
            write_atomically(&on, &pgm_u8(on_frame))?;
        }
        pairs.push((off, on));
    }
    Ok(Scenes { calib, pairs })
}

/// An 8-bit PGM of `frame` (deeper frames reduced to their top 8 bits, as the device's
/// camera delivers them).
fn pgm_u8(frame: &tangent_host::pgm::Pgm) -> Vec<u8> {
    let bits = frame.bit_depth() as u32;
    let mut out = format!("P5\n{} {}\n255\n", frame.width, frame.height).into_bytes();
    out.extend(
        frame
            .to_u16()
            .into_iter()
            .map(|v| (v >> bits.saturating_sub(8)).min(255) as u8),
    );
    out
}

fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(&tmp, bytes).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))
}
