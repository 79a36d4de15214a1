//! The emulated firmware (QEMU mps2-an500) as a serial peer, shared by the emulated-device
//! tests: building the firmware, booting it on frame files, speaking the protocol, and the
//! device-against-host comparison of one instrument. Each test binary uses part of it.
#![allow(dead_code)]

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use tangent_core::calibration::Calibration;
use tangent_core::measurement::{Measurement, Mode};
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::{
    self, calibration_record, DeviceError, ErrorCode, FromDevice, Request, Response, ToDevice,
    WireCalibration,
};

pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Builds the emulated firmware once per test process; `None` (with the reason printed)
/// when QEMU is missing.
pub fn firmware_elf() -> Option<PathBuf> {
    static ELF: OnceLock<Option<PathBuf>> = OnceLock::new();
    ELF.get_or_init(|| {
        if Command::new("qemu-system-arm")
            .arg("--version")
            .output()
            .is_err()
        {
            eprintln!(
                "SKIPPED: qemu-system-arm is not installed (apt-get install qemu-system-arm); \
                 the emulated-firmware tests did not run"
            );
            return None;
        }
        let root = repo_root();
        let status = Command::new(env!("CARGO"))
            .current_dir(&root)
            .args([
                "build",
                "--manifest-path",
                "firmware/Cargo.toml",
                "--release",
                "--target",
                "thumbv7em-none-eabihf",
                "--no-default-features",
                "--features",
                "qemu",
                "--bin",
                "tangent-qemu",
                // Explicit, so a CARGO_TARGET_DIR set for the host build does not move it.
                "--target-dir",
                "firmware/target",
            ])
            .status()
            .expect("run cargo to build the emulated firmware");
        assert!(status.success(), "building the emulated firmware failed");
        Some(root.join("firmware/target/thumbv7em-none-eabihf/release/tangent-qemu"))
    })
    .clone()
}

/// A running emulated device, its UART on our pipes.
pub struct Device {
    pub child: Child,
    pub stdin: std::process::ChildStdin,
    pub rx: Receiver<Vec<u8>>,
    pub pending: Vec<u8>,
    pub next_tag: u16,
    pub log: PathBuf,
    pub _dir: tempfile::TempDir,
}

impl Device {
    /// Boots the firmware on `pairs` of (off, on) PGM files, with `calibration` stored.
    pub fn boot(
        elf: &Path,
        pairs: &[(PathBuf, PathBuf)],
        calibration: Option<&Calibration>,
    ) -> Device {
        Device::boot_with(elf, pairs, calibration, "")
    }

    /// [`Device::boot`] with more of the emulated board's options (`--accel …`).
    pub fn boot_with(
        elf: &Path,
        pairs: &[(PathBuf, PathBuf)],
        calibration: Option<&Calibration>,
        options: &str,
    ) -> Device {
        let dir = tempfile::tempdir().unwrap();
        // QEMU passes "<kernel file> <append>" as the semihosting command line.
        let mut args = format!(" {options}");
        if let Some(cal) = calibration {
            let mut rec = [0u8; calibration_record::MAX_RECORD];
            let n = calibration_record::encode(&WireCalibration::from(cal), &mut rec).unwrap();
            let path = dir.path().join("calib.bin");
            std::fs::write(&path, &rec[..n]).unwrap();
            args += &format!(" --calib {}", path.display());
        }
        for (off, on) in pairs {
            args += &format!(" {} {}", off.display(), on.display());
        }
        let log = dir.path().join("semihosting.log");
        let mut child = tangent_host::emulator::qemu_command(elf, "stdio", false, &args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            // The firmware's semihosting log goes to QEMU's stderr.
            .stderr(Stdio::from(std::fs::File::create(&log).unwrap()))
            .spawn()
            .expect("start qemu-system-arm");
        let stdin = child.stdin.take().unwrap();
        let mut stdout = child.stdout.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = stdout.read(&mut buf) {
                if n == 0 || tx.send(buf[..n].to_vec()).is_err() {
                    break;
                }
            }
        });
        Device {
            child,
            stdin,
            rx,
            pending: Vec::new(),
            next_tag: 1,
            log,
            _dir: dir,
        }
    }

    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    pub fn send_raw(&mut self, bytes: &[u8]) {
        self.stdin.write_all(bytes).unwrap();
        self.stdin.flush().unwrap();
    }

    /// Sends a request; returns its tag.
    pub fn send(&mut self, request: Request) -> u16 {
        let tag = self.next_tag;
        self.next_tag += 1;
        let mut enc = protocol::FrameEncoder::new();
        let frame = enc.encode(&ToDevice { tag, request }).unwrap().to_vec();
        self.send_raw(&frame);
        tag
    }

    /// The next frame's COBS bytes (without the delimiter).
    pub fn next_frame(&mut self, timeout: Duration) -> Vec<u8> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(i) = self.pending.iter().position(|&b| b == 0) {
                let frame: Vec<u8> = self.pending.drain(..=i).collect();
                if frame.len() > 1 {
                    return frame[..frame.len() - 1].to_vec();
                }
                continue;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(bytes) => self.pending.extend_from_slice(&bytes),
                Err(_) => panic!(
                    "no frame from the device within {timeout:?}; firmware log:\n{}",
                    self.log_text()
                ),
            }
        }
    }

    /// Waits for the next message with `tag` and hands it to `f` (skipping others).
    pub fn expect<T>(&mut self, tag: u16, f: impl FnOnce(Response<'_>) -> T) -> T {
        loop {
            let mut frame = self.next_frame(Duration::from_secs(20));
            let msg: FromDevice = protocol::decode(&mut frame).expect("device frame decodes");
            if msg.tag == tag {
                return f(msg.response);
            }
        }
    }

    pub fn request<T>(&mut self, request: Request, f: impl FnOnce(Response<'_>) -> T) -> T {
        let tag = self.send(request);
        self.expect(tag, f)
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Writes an 8-bit binary PGM.
pub fn write_pgm(path: &Path, width: usize, height: usize, data: &[u8]) {
    let mut bytes = format!("P5\n{width} {height}\n255\n").into_bytes();
    bytes.extend_from_slice(data);
    std::fs::write(path, bytes).unwrap();
}

/// A deterministic frame pair of the sensor's size: a textured background (xorshift) and a
/// bright horizontal band in the on frame.
pub fn synthetic_pair(dir: &Path, name: &str) -> (PathBuf, PathBuf, Vec<u8>, Vec<u8>) {
    let (w, h) = (752, 480);
    let mut x = 0x9E37_79B9u32 ^ name.len() as u32;
    let off: Vec<u8> = (0..w * h)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x % 40) as u8
        })
        .collect();
    let mut on = off.clone();
    for col in 0..w {
        on[(300 + col % 3) * w + col] = 220;
    }
    let off_path = dir.join(format!("{name}-off.pgm"));
    let on_path = dir.join(format!("{name}-on.pgm"));
    write_pgm(&off_path, w, h, &off);
    write_pgm(&on_path, w, h, &on);
    (off_path, on_path, off, on)
}

/// The sphere issue's CI check: in sphere mode the emulated firmware (f32) gives the host's
/// sphere (f64) on the same frames — same method, diameters within 1e-4 relative (the
/// argument of `on_device_measurements_equal_the_hosts`), same flags — or the same refusal.
/// Whether [`device_equals_host`] sets the instrument's mode before measuring.
#[derive(Clone, Copy, PartialEq)]
pub enum SetMode {
    /// `Request::SetMode` first.
    Yes,
    /// The device's boot mode.
    AtBoot,
}

/// One instrument's CI check: the emulated firmware, running the shared pipeline in `f32` on
/// the Cortex-M7, and the host (`f64`) measure the same frames of the `wanted` corpus
/// entries in `mode`. Each capture's on frame lights all its planes; a reading on both sides
/// is of the same kind and `same(name, host, device)` holds; where the host refuses, the
/// device refuses with the same sentence. Returns how many readings were compared (`None`
/// when QEMU is missing).
pub fn device_equals_host(
    corpus: Vec<tangent_host::simulate::corpus::CorpusEntry>,
    wanted: &[&str],
    mode: Mode,
    set_mode: SetMode,
    same: impl Fn(&str, &Measurement, &Measurement),
) -> Option<usize> {
    use tangent_core::instrument::{measure, InstrumentParams};
    use tangent_core::pipeline::{OwnedBuffers, PipelineConfig};
    use tangent_host::simulate::simulate;

    let elf = firmware_elf()?;
    let dir = tempfile::tempdir().unwrap();
    let (mut pairs, mut cases) = (Vec::new(), Vec::new());
    for entry in corpus
        .into_iter()
        .filter(|e| wanted.contains(&e.name.as_str()))
    {
        let name = entry.name;
        let (capture, _) = simulate(&entry.spec).expect("simulate the corpus capture");
        let planes = capture.calibration.planes.len();
        let (paths, (off, on), (w, h)) = write_pair(dir.path(), &name, &capture);
        pairs.push(paths);
        let off_f = tangent_core::image::Frame::new(&off, w, h, w).unwrap();
        let on_f = tangent_core::image::Frame::new(&on, w, h, w).unwrap();
        let mut ws = OwnedBuffers::<u8>::for_frame(w, h, 8, planes);
        let host = measure(
            mode,
            &off_f,
            &on_f,
            &capture.calibration,
            &PipelineConfig::default(),
            &InstrumentParams::default(),
            &mut ws.workspace(),
        );
        cases.push((name, capture.calibration.clone(), host));
    }
    assert_eq!(
        cases.len(),
        wanted.len(),
        "{mode:?}: corpus entries missing"
    );

    let mut dev = Device::boot(&elf, &pairs, None);
    if set_mode == SetMode::Yes {
        dev.request(Request::SetMode(mode), |r| assert_eq!(r, Response::Ack));
    }
    // One frame pair per reading, as the host measures these captures (several pairs:
    // `on_device_exposures_combine_as_the_hosts`).
    dev.request(Request::SetExposures(1), |r| assert_eq!(r, Response::Ack));
    let mut compared = 0;
    for (name, cal, host) in &cases {
        // Each Measure consumes the next frame pair; each capture has its own calibration.
        dev.request(Request::WriteCalibration(WireCalibration::from(cal)), |r| {
            assert_eq!(r, Response::Ack, "{name}")
        });
        dev.request(Request::Measure, |r| match (host, r) {
            (Ok(h), Response::Reading(reading)) => {
                let d = &reading.measurement;
                assert_eq!(d.kind(), h.kind(), "{name}: kind");
                same(name, h, d);
                compared += 1;
            }
            (Err(e), Response::Error(DeviceError { code, detail })) => {
                eprintln!("{name}: host and device both refuse ({e})");
                assert_eq!(code, ErrorCode::MeasurementFailed, "{name}");
                // The forester reads the same sentence from the caliper as from the file.
                assert_eq!(
                    Failure::from_detail(detail).to_string(),
                    Failure::of(e).to_string(),
                    "{name}"
                );
            }
            (h, r) => panic!("{name}: host {h:?}, device {r:?}"),
        });
    }
    Some(compared)
}

/// What [`write_pair`] wrote: the two files' paths, their 8-bit pixels, their width and height.
pub type WrittenPair = ((PathBuf, PathBuf), (Vec<u8>, Vec<u8>), (usize, usize));

/// A capture's laser-off frame and first laser-on frame (which must light every plane)
/// written to `dir` as the 8-bit PGMs `<name>-off.pgm` and `<name>-on.pgm` the emulated
/// camera serves: their paths, their pixels and their size.
pub fn write_pair(dir: &Path, name: &str, capture: &tangent_host::capture::Capture) -> WrittenPair {
    let off_pgm = capture.off_frame();
    let (lit, on_pgm) = capture.on_frames().next().expect("an on frame");
    let planes = capture.calibration.planes.len();
    assert_eq!(lit.len(), planes, "{name}: all planes lit in one frame");
    let (w, h) = (off_pgm.width, off_pgm.height);
    let (off, on) = (to_u8(off_pgm), to_u8(on_pgm));
    let off_path = dir.join(format!("{name}-off.pgm"));
    let on_path = dir.join(format!("{name}-on.pgm"));
    write_pgm(&off_path, w, h, &off);
    write_pgm(&on_path, w, h, &on);
    ((off_path, on_path), (off, on), (w, h))
}

/// 8-bit version of a capture frame: 8-bit data as is, deeper data reduced to its top 8
/// bits (what the device's 8-bit DCMI bus on D9..D2 sees, and what the emulated camera does
/// with a 16-bit PGM).
pub fn to_u8(pgm: &tangent_host::pgm::Pgm) -> Vec<u8> {
    let bits = pgm.bit_depth() as u32;
    pgm.to_u16()
        .into_iter()
        .map(|v| (v >> bits.saturating_sub(8)).min(255) as u8)
        .collect()
}
