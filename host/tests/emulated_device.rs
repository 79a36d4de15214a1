//! The emulated firmware (QEMU mps2-an500) as a real serial peer: protocol round trips,
//! frame dumps, calibration storage, link fault tolerance, and — the CI check of the
//! firmware issue — on-device measurements equal to the host's on the same frames.
//!
//! Needs `qemu-system-arm` (CI installs it; without it each test prints why it is skipped)
//! and builds the emulated firmware (`cargo firmware-qemu`) on first use.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use tangent_core::calibration::{Calibration, PlanesUncertainty};
use tangent_core::measurement::{Measurement, Mode};
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::{
    self, calibration_record, DeviceError, ErrorCode, FrameSel, FromDevice, Request, Response,
    ToDevice, WireCalibration, FRAME_CHUNK_MAX, PROTOCOL_VERSION,
};

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Builds the emulated firmware once per test process; `None` (with the reason printed)
/// when QEMU is missing.
fn firmware_elf() -> Option<PathBuf> {
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
struct Device {
    child: Child,
    stdin: std::process::ChildStdin,
    rx: Receiver<Vec<u8>>,
    pending: Vec<u8>,
    next_tag: u16,
    log: PathBuf,
    _dir: tempfile::TempDir,
}

impl Device {
    /// Boots the firmware on `pairs` of (off, on) PGM files, with `calibration` stored.
    fn boot(elf: &Path, pairs: &[(PathBuf, PathBuf)], calibration: Option<&Calibration>) -> Device {
        Device::boot_with(elf, pairs, calibration, "")
    }

    /// [`Device::boot`] with more of the emulated board's options (`--accel …`).
    fn boot_with(
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

    fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    fn send_raw(&mut self, bytes: &[u8]) {
        self.stdin.write_all(bytes).unwrap();
        self.stdin.flush().unwrap();
    }

    /// Sends a request; returns its tag.
    fn send(&mut self, request: Request) -> u16 {
        let tag = self.next_tag;
        self.next_tag += 1;
        let mut enc = protocol::FrameEncoder::new();
        let frame = enc.encode(&ToDevice { tag, request }).unwrap().to_vec();
        self.send_raw(&frame);
        tag
    }

    /// The next frame's COBS bytes (without the delimiter).
    fn next_frame(&mut self, timeout: Duration) -> Vec<u8> {
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
    fn expect<T>(&mut self, tag: u16, f: impl FnOnce(Response<'_>) -> T) -> T {
        loop {
            let mut frame = self.next_frame(Duration::from_secs(20));
            let msg: FromDevice = protocol::decode(&mut frame).expect("device frame decodes");
            if msg.tag == tag {
                return f(msg.response);
            }
        }
    }

    fn request<T>(&mut self, request: Request, f: impl FnOnce(Response<'_>) -> T) -> T {
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
fn write_pgm(path: &Path, width: usize, height: usize, data: &[u8]) {
    let mut bytes = format!("P5\n{width} {height}\n255\n").into_bytes();
    bytes.extend_from_slice(data);
    std::fs::write(path, bytes).unwrap();
}

/// A deterministic frame pair of the sensor's size: a textured background (xorshift) and a
/// bright horizontal band in the on frame.
fn synthetic_pair(dir: &Path, name: &str) -> (PathBuf, PathBuf, Vec<u8>, Vec<u8>) {
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

#[test]
fn boot_banner_info_and_calibration_round_trip() {
    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off, on, _, _) = synthetic_pair(dir.path(), "a");
    let cal = Calibration::reference_design();
    let mut dev = Device::boot(&elf, &[(off, on)], Some(&cal));

    // The unsolicited banner names the protocol and the stored calibration.
    dev.expect(protocol::UNSOLICITED, |r| match r {
        Response::Info(i) => {
            assert_eq!(i.protocol_version, PROTOCOL_VERSION);
            assert_eq!(i.board, protocol::Board::Emulated);
            assert_eq!(i.calib_id, Some(cal.id));
            assert_eq!((i.frame_width, i.frame_height), (752, 480));
        }
        other => panic!("expected the boot banner, got {other:?}"),
    });

    let wire = dev.request(Request::ReadCalibration, |r| match r {
        Response::Calibration(c) => c,
        other => panic!("{other:?}"),
    });
    assert_eq!(wire, WireCalibration::from(&cal));
    // The device computes in f32: what it returns is the f32 rounding of what it got.
    assert_eq!(wire.to_calibration().unwrap().id, cal.id);

    let mut new = cal.clone();
    new.id = 4242;
    new.camera.cx = 371.25;
    dev.request(
        Request::WriteCalibration(WireCalibration::from(&new)),
        |r| assert_eq!(r, Response::Ack),
    );
    let back = dev.request(Request::ReadCalibration, |r| match r {
        Response::Calibration(c) => c,
        other => panic!("{other:?}"),
    });
    assert_eq!(back.id, 4242);
    assert_eq!(back.intrinsics[2], 371.25);

    // An invalid calibration is refused and the previous one stays active.
    let mut bad = WireCalibration::from(&new);
    bad.intrinsics[0] = f64::NAN;
    dev.request(Request::WriteCalibration(bad), |r| match r {
        Response::Error(DeviceError { code, .. }) => {
            assert_eq!(code, ErrorCode::InvalidCalibration)
        }
        other => panic!("{other:?}"),
    });
    dev.request(Request::DeviceInfo, |r| match r {
        Response::Info(i) => assert_eq!(i.calib_id, Some(4242)),
        other => panic!("{other:?}"),
    });
}

#[test]
fn frame_dump_equals_the_source_frames() {
    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off_path, on_path, off, on) = synthetic_pair(dir.path(), "dump");
    let mut dev = Device::boot(&elf, &[(off_path, on_path)], None);
    let info = dev.request(Request::CaptureFrames, |r| match r {
        Response::FramesReady(i) => i,
        other => panic!("{other:?}"),
    });
    assert_eq!((info.width, info.height, info.bit_depth), (752, 480, 8));
    assert_ne!(info.laser_mask, 0);
    for (sel, want) in [(FrameSel::Off, &off), (FrameSel::On, &on)] {
        let mut got = Vec::new();
        while got.len() < want.len() {
            let request = Request::ReadFrameChunk {
                capture: info.capture,
                frame: sel,
                offset: got.len() as u32,
                max_len: FRAME_CHUNK_MAX as u16,
            };
            dev.request(request, |r| match r {
                Response::FrameChunk {
                    offset,
                    total,
                    data,
                    ..
                } => {
                    assert_eq!(offset as usize, got.len());
                    assert_eq!(total as usize, want.len());
                    assert!(!data.is_empty() && data.len() <= FRAME_CHUNK_MAX);
                    got.extend_from_slice(data);
                }
                other => panic!("{other:?}"),
            });
        }
        assert!(got == *want, "{sel:?} frame differs from its source");
    }
    // Past the end, and a capture that no longer exists.
    let request = Request::ReadFrameChunk {
        capture: info.capture,
        frame: FrameSel::On,
        offset: off.len() as u32,
        max_len: 16,
    };
    dev.request(request, |r| {
        assert!(matches!(
            r,
            Response::Error(DeviceError {
                code: ErrorCode::OutOfRange,
                ..
            })
        ))
    });
    let request = Request::ReadFrameChunk {
        capture: info.capture + 1,
        frame: FrameSel::On,
        offset: 0,
        max_len: 16,
    };
    dev.request(request, |r| {
        assert!(matches!(
            r,
            Response::Error(DeviceError {
                code: ErrorCode::StaleCapture,
                ..
            })
        ))
    });
}

#[test]
fn garbage_corruption_oversize_and_other_versions_are_counted_not_fatal() {
    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off, on, _, _) = synthetic_pair(dir.path(), "g");
    let mut dev = Device::boot(&elf, &[(off, on)], None);
    dev.expect(protocol::UNSOLICITED, |_| ());

    // 1. Line noise then a delimiter: one malformed frame.
    dev.send_raw(&[0x13, 0x37, 0xFF, 0x42, 0x00]);
    // 2. A valid frame with one corrupted byte: malformed (CRC).
    let mut enc = protocol::FrameEncoder::new();
    let mut frame = enc
        .encode(&ToDevice {
            tag: 99,
            request: Request::DeviceInfo,
        })
        .unwrap()
        .to_vec();
    frame[3] ^= 0x10;
    if frame[3] == 0 {
        frame[3] = 0x77;
    }
    dev.send_raw(&frame);
    // 3. An oversize frame (no delimiter for 5000 bytes).
    dev.send_raw(&vec![0x5Au8; 5000]);
    dev.send_raw(&[0x00]);
    // 4. A frame of another protocol version: answered with UnsupportedVersion.
    let mut scratch = [0u8; protocol::MAX_RAW_LEN];
    let raw = protocol::encode_raw(
        &ToDevice {
            tag: 7,
            request: Request::DeviceInfo,
        },
        PROTOCOL_VERSION + 1,
        &mut scratch,
    )
    .unwrap();
    let mut out = [0u8; protocol::MAX_FRAME_LEN];
    let n = protocol::cobs_frame(raw, &mut out).unwrap();
    dev.send_raw(&out[..n]);
    dev.expect(protocol::UNSOLICITED, |r| match r {
        Response::Error(DeviceError { code, detail }) => {
            assert_eq!(code, ErrorCode::UnsupportedVersion);
            assert_eq!(detail, u32::from(PROTOCOL_VERSION + 1));
        }
        other => panic!("{other:?}"),
    });
    // The device still answers, and counted each fault once.
    dev.request(Request::DeviceInfo, |r| match r {
        Response::Info(i) => {
            assert_eq!(i.link.malformed, 2, "{:?}", i.link);
            assert_eq!(i.link.oversize, 1, "{:?}", i.link);
            assert_eq!(i.link.version_mismatch, 1, "{:?}", i.link);
            assert_eq!(i.link.frames_ok, 1, "{:?}", i.link);
        }
        other => panic!("{other:?}"),
    });
}

#[test]
fn measure_without_calibration_is_a_clear_error() {
    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off, on, _, _) = synthetic_pair(dir.path(), "nc");
    let mut dev = Device::boot(&elf, &[(off, on)], None);
    dev.request(Request::Measure, |r| match r {
        Response::Error(DeviceError { code, .. }) => assert_eq!(code, ErrorCode::NoCalibration),
        other => panic!("{other:?}"),
    });
    dev.request(Request::History { after_seq: 0 }, |r| {
        assert_eq!(r, Response::HistoryEnd { last_seq: 0 })
    });
}

/// The mode from the host on the real firmware: the device boots in the stem's mode and says
/// so in `Info`; every mode this build measures is taken and read back; any other is refused
/// with the `UnsupportedMode` sentence and the mode stays; a reading is of the set mode's kind
/// (a nothing-lit pair: the chain's failure, not the refusal of the mode).
#[test]
fn the_mode_is_set_from_the_host_and_read_back() {
    use tangent_core::instrument;

    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off, on, _, _) = synthetic_pair(dir.path(), "mode");
    let pairs = vec![(off.clone(), on.clone()), (off, on)];
    let mut dev = Device::boot(&elf, &pairs, Some(&Calibration::reference_design()));
    let mode_now = |dev: &mut Device| {
        dev.request(Request::DeviceInfo, |r| match r {
            Response::Info(i) => i.mode,
            other => panic!("{other:?}"),
        })
    };
    assert_eq!(
        mode_now(&mut dev),
        Mode::Cylinder,
        "boots in the stem's mode"
    );
    let mut taken = Vec::new();
    for mode in Mode::ALL {
        let before = mode_now(&mut dev);
        dev.request(Request::SetMode(mode), |r| match r {
            Response::Ack => {
                assert!(
                    instrument::supports(mode),
                    "{mode:?} taken without a solver"
                );
                taken.push(mode);
            }
            Response::Error(DeviceError { code, detail }) => {
                assert!(!instrument::supports(mode), "{mode:?} refused");
                assert_eq!(code, ErrorCode::MeasurementFailed);
                assert_eq!(Failure::from_detail(detail), Failure::UnsupportedMode(mode));
            }
            other => panic!("{other:?}"),
        });
        let after = mode_now(&mut dev);
        let expected = if taken.last() == Some(&mode) {
            mode
        } else {
            before
        };
        assert_eq!(after, expected, "mode after SetMode({mode:?})");
    }
    assert!(taken.contains(&Mode::Cylinder));
    // Measuring in each taken mode runs that mode's chain: this pair has a lit band across
    // the frame, so whatever the outcome, it is not the refusal of the mode.
    for mode in taken.iter().take(pairs.len()) {
        dev.request(Request::SetMode(*mode), |r| assert_eq!(r, Response::Ack));
        dev.request(Request::Measure, |r| match r {
            Response::Reading(reading) => assert_eq!(reading.measurement.mode(), *mode),
            Response::Error(DeviceError { code, detail }) => {
                assert_eq!(code, ErrorCode::MeasurementFailed);
                assert_ne!(
                    Failure::from_detail(detail),
                    Failure::UnsupportedMode(*mode)
                );
            }
            other => panic!("{other:?}"),
        });
    }
}

/// The sphere issue's CI check: in sphere mode the emulated firmware (f32) gives the host's
/// sphere (f64) on the same frames — same method, diameters within 1e-4 relative (the
/// argument of `on_device_measurements_equal_the_hosts`), same flags — or the same refusal.
/// Whether [`device_equals_host`] sets the instrument's mode before measuring.
#[derive(Clone, Copy, PartialEq)]
enum SetMode {
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
fn device_equals_host(
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
        let off_pgm = capture.off_frame();
        let (lit, on_pgm) = capture.on_frames().next().expect("an on frame");
        let planes = capture.calibration.planes.len();
        assert_eq!(lit.len(), planes, "{name}: all planes lit in one frame");
        let (w, h) = (off_pgm.width, off_pgm.height);
        let (off, on) = (to_u8(off_pgm), to_u8(on_pgm));
        let off_path = dir.path().join(format!("{name}-off.pgm"));
        let on_path = dir.path().join(format!("{name}-on.pgm"));
        write_pgm(&off_path, w, h, &off);
        write_pgm(&on_path, w, h, &on);
        pairs.push((off_path, on_path));
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

/// 8-bit version of a capture frame: 8-bit data as is, deeper data reduced to its top 8
/// bits (what the device's 8-bit DCMI bus on D9..D2 sees, and what the emulated camera does
/// with a 16-bit PGM).
fn to_u8(pgm: &tangent_host::pgm::Pgm) -> Vec<u8> {
    let bits = pgm.bit_depth() as u32;
    pgm.to_u16()
        .into_iter()
        .map(|v| (v >> bits.saturating_sub(8)).min(255) as u8)
        .collect()
}

#[test]
fn on_device_spheres_equal_the_hosts() {
    let wanted = [
        "sphere-d100-z080-matt-2p",
        "sphere-d150-z100-offcentre-2p",
        "sphere-d250-z150-shiny-offcentre-2p",
        "sphere-d400-z200-matt-2p",
        "sphere-d080-z090-floor-offcentre-2p",
        "sphere-d055-z120-nearpole-2p",
        "notsphere-wall-z120-2p",
    ];
    // Three balls are measured with planes refined on a reference: the calibration carries
    // their covariance (`[planes_uncertainty]`, protocol v6), which sets the stated σ; the
    // device receives it with the calibration and must state the host's σ.
    let refined = PlanesUncertainty::new(
        &[2e-4, 1.9e-4, 2e-4, 1.9e-4],
        &[
            1.0, 0.0, 0.9, 0.0, //
            0.0, 1.0, 0.0, 0.94, //
            0.9, 0.0, 1.0, 0.0, //
            0.0, 0.94, 0.0, 1.0,
        ],
    )
    .unwrap();
    let with_covariance = [
        "sphere-d150-z100-offcentre-2p",
        "sphere-d400-z200-matt-2p",
        "sphere-d055-z120-nearpole-2p",
    ];
    let entries = tangent_host::simulate::sphere_corpus::entries()
        .into_iter()
        .map(|mut e| {
            if with_covariance.contains(&e.name.as_str()) {
                e.spec.calibration = e.spec.calibration.with_uncertainty(refined).unwrap();
            }
            e
        })
        .collect();
    let same = |name: &str, h: &Measurement, d: &Measurement| {
        let (Measurement::Sphere(h), Measurement::Sphere(d)) = (h, d) else {
            panic!("{name}: sphere readings, got host {h:?}, device {d:?}")
        };
        let rel = (d.diameter - h.diameter).abs() / h.diameter;
        eprintln!(
            "{name}: host {:.4} mm {:?}, device {:.4} mm {:?}, relative difference {rel:.2e}",
            h.diameter * 1e3,
            h.method,
            d.diameter * 1e3,
            d.method
        );
        assert_eq!(d.method, h.method, "{name}: method");
        assert!(
            rel <= 1e-4,
            "{name}: device {} m vs host {} m",
            d.diameter,
            h.diameter
        );
        assert_eq!(d.flags, h.flags, "{name}: flags");
        // The stated σ too: its covariance inverts a normal matrix whose determinant can be
        // beyond f32's range (`solvers::lm::spd_inverse`: a closed-form inverse gave a zero
        // covariance in f32 for the core's near-pole unit test ball).
        let rel_sigma = (d.uncertainty - h.uncertainty).abs() / h.uncertainty;
        eprintln!(
            "{name}: σ host {:.4} mm, device {:.4} mm",
            h.uncertainty * 1e3,
            d.uncertainty * 1e3
        );
        assert!(
            d.uncertainty > 0.0 && rel_sigma <= 1e-2,
            "{name}: σ device {} m vs host {} m",
            d.uncertainty,
            h.uncertainty
        );
    };
    let Some(compared) = device_equals_host(entries, &wanted, Mode::Sphere, SetMode::Yes, same)
    else {
        return;
    };
    assert!(
        compared >= 3,
        "only {compared} balls measured on both sides"
    );
}

/// The firmware issue's CI check: the emulated firmware, running the shared pipeline in
/// `f32` on the Cortex-M7, gives the host's results (pipeline in `f64`) on the same frames:
/// same method, diameters within 1e-4 relative, or a failure where the host fails.
///
/// Why 1e-4 holds: the device's only difference is `f32` arithmetic (ε = 6e-8). The
/// subpixel rows carry ≈ 1e-4 px of rounding after the ~10 operations of the estimator
/// (row ≈ 400 × 6e-8 × a few), and the diameter of a fit to N ≈ 100–700 points moves by
/// about (rounding / noise) of its statistical error — below 1e-5 relative — unless a
/// decision (outlier rejection, method choice) flips, which the method comparison catches.
#[test]
fn on_device_measurements_equal_the_hosts() {
    let wanted = [
        "cyl-d050-z050-shade",
        "cyl-d300-z150-shade",
        "cyl-d600-z150-shade",
        "cyl-d300-z150-sun",
        "cyl-d300-z150-10bit",
        "cyl-d300-z150-vertical-2p",
        "cyl-d300-z150-tilt10-right-2p",
        "cyl-d500-z200-tilt15-diagonal-2p",
        "nothing-in-range",
    ];
    let same = |name: &str, h: &Measurement, d: &Measurement| {
        let rel = (d.value() - h.value()).abs() / h.value();
        eprintln!(
            "{name}: host {:.4} mm {:?}, device {:.4} mm {:?}, relative difference {rel:.2e}",
            h.value() * 1e3,
            h.method(),
            d.value() * 1e3,
            d.method()
        );
        assert_eq!(d.kind(), "stem", "{name}: kind");
        assert_eq!(d.method(), h.method(), "{name}: method");
        assert!(
            rel <= 1e-4,
            "{name}: device {} m vs host {} m",
            d.value(),
            h.value()
        );
        assert_eq!(d.flags(), h.flags(), "{name}: flags");
    };
    // The stem is the caliper's instrument at boot: no mode is set.
    let Some(compared) = device_equals_host(
        tangent_host::simulate::corpus::entries(),
        &wanted,
        Mode::Cylinder,
        SetMode::AtBoot,
        same,
    ) else {
        return;
    };
    assert!(
        compared >= 5,
        "only {compared} captures measured on both sides"
    );
}

/// Several exposures on the device (`Request::SetExposures`, `docs/error-model.md` §6,
/// (E7)): the emulated firmware measures four frame pairs per `Measure` and combines them;
/// the host measures the same pairs one by one and combines them with the same core
/// function. The readings agree as one pair's do (each pair within the f32 rounding, the
/// mean of four no further), name four exposures, and a count the device cannot take is
/// refused by name with the count unchanged.
#[test]
fn on_device_exposures_combine_as_the_hosts() {
    use tangent_core::instrument::stem::Stem;
    use tangent_core::instrument::{measure_with, InstrumentParams};
    use tangent_core::pipeline::{OwnedBuffers, PipelineConfig};
    use tangent_core::solvers::stem::combine_exposures;
    use tangent_host::simulate::simulate;

    let Some(elf) = firmware_elf() else {
        return;
    };
    const PAIRS: usize = 4;
    let wanted = ["cyl-d300-z150-shade", "cyl-d300-z150-tilt10-right-2p"];
    let dir = tempfile::tempdir().unwrap();
    let (mut files, mut cases) = (Vec::new(), Vec::new());
    for entry in tangent_host::simulate::corpus::entries()
        .into_iter()
        .filter(|e| wanted.contains(&e.name.as_str()))
    {
        let name = entry.name;
        let mut spec = entry.spec;
        spec.params.exposure_pairs = PAIRS;
        let (capture, _) = simulate(&spec).expect("simulate the capture");
        assert_eq!(capture.pairs(), PAIRS, "{name}");
        let mut solutions = Vec::new();
        for k in 0..PAIRS {
            let pair = capture.exposure_pair(k).expect("a pair");
            let (off_pgm, (_, on_pgm)) = (pair.off_frame(), pair.on_frames().next().unwrap());
            let (w, h) = (off_pgm.width, off_pgm.height);
            let (off, on) = (to_u8(off_pgm), to_u8(on_pgm));
            let off_path = dir.path().join(format!("{name}-p{k}-off.pgm"));
            let on_path = dir.path().join(format!("{name}-p{k}-on.pgm"));
            write_pgm(&off_path, w, h, &off);
            write_pgm(&on_path, w, h, &on);
            files.push((off_path, on_path));
            let off_f = tangent_core::image::Frame::new(&off, w, h, w).unwrap();
            let on_f = tangent_core::image::Frame::new(&on, w, h, w).unwrap();
            let planes = capture.calibration.planes.len();
            let mut ws = OwnedBuffers::<u8>::for_frame(w, h, 8, planes);
            let measured = measure_with::<Stem, u8>(
                &off_f,
                &on_f,
                &capture.calibration,
                &PipelineConfig::default(),
                &InstrumentParams::default().cylinder,
                &mut ws.workspace(),
            )
            .unwrap_or_else(|e| panic!("{name}: pair {k} reads on the host: {e}"));
            solutions.push(measured.solution);
        }
        let host = Measurement::from(&combine_exposures(&solutions).expect("combines"));
        cases.push((name, capture.calibration.clone(), host));
    }
    assert_eq!(cases.len(), wanted.len(), "corpus entries missing");

    let mut dev = Device::boot(&elf, &files, None);
    for bad in [0u8, 17] {
        dev.request(Request::SetExposures(bad), |r| {
            assert_eq!(
                r,
                Response::Error(DeviceError {
                    code: ErrorCode::InvalidSetting,
                    detail: bad as u32
                })
            )
        });
    }
    let info = dev.request(Request::DeviceInfo, |r| match r {
        Response::Info(i) => i.exposures,
        other => panic!("{other:?}"),
    });
    assert_eq!(info, 4, "the default count, unchanged by the refused ones");
    dev.request(Request::SetExposures(PAIRS as u8), |r| {
        assert_eq!(r, Response::Ack)
    });
    for (name, cal, host) in &cases {
        dev.request(Request::WriteCalibration(WireCalibration::from(cal)), |r| {
            assert_eq!(r, Response::Ack, "{name}")
        });
        dev.request(Request::Measure, |r| {
            let Response::Reading(reading) = r else {
                panic!("{name}: device {r:?}");
            };
            let (Measurement::Stem(d), Measurement::Stem(h)) = (&reading.measurement, host) else {
                panic!("{name}: not stems: {:?}, {host:?}", reading.measurement);
            };
            let rel = (d.diameter - h.diameter).abs() / h.diameter;
            eprintln!(
                "{name}: host {:.4} ± {:.4} mm, device {:.4} ± {:.4} mm ({} exposures), \
                 relative difference {rel:.2e}",
                h.diameter * 1e3,
                h.uncertainty * 1e3,
                d.diameter * 1e3,
                d.uncertainty * 1e3,
                d.exposures
            );
            assert_eq!(
                (d.exposures, h.exposures),
                (PAIRS as u8, PAIRS as u8),
                "{name}"
            );
            assert_eq!(d.method, h.method, "{name}: method");
            assert_eq!(d.flags, h.flags, "{name}: flags");
            assert!(rel <= 1e-4, "{name}: diameter");
            // σ: rounding moves each pair by ≈ 1e-5 of d, against a scatter of ≈ 1e-3 of d.
            let rel_sigma = (d.uncertainty - h.uncertainty).abs() / h.uncertainty;
            assert!(rel_sigma <= 1e-2, "{name}: σ differs by {rel_sigma:.2e}");
        });
    }
}

/// The road instrument on the emulated device (mode set from the host) gives the host's
/// reading on the same frames: MPD within 1 µm (f32 against f64: heights are differences of
/// depths ≈ 0.3 m, rounded at ≈ 4e-8 m, far below), the same segments; a refusal reads the
/// same sentence.
#[test]
fn road_profiles_on_the_device_equal_the_hosts() {
    let wanted = ["road-head-stone-mastic", "road-head-tilted-10deg"];
    let same = |name: &str, h: &Measurement, d: &Measurement| {
        let (Measurement::Road(h), Measurement::Road(d)) = (h, d) else {
            panic!("{name}: road readings, got host {h:?}, device {d:?}")
        };
        eprintln!(
            "{name}: host MPD {:.4} mm, device {:.4} mm",
            h.mpd * 1e3,
            d.mpd * 1e3
        );
        assert!((d.mpd - h.mpd).abs() <= 1e-6, "{name}: {d:?} vs {h:?}");
        assert_eq!(d.segments, h.segments, "{name}");
    };
    device_equals_host(
        tangent_host::simulate::corpus::entries(),
        &wanted,
        Mode::Road,
        SetMode::Yes,
        same,
    );
}

/// The wall instrument on the device: set to `Mode::Wall` from the host, the emulated
/// firmware (f32) reads the corpus's walls as the host (f64) does — same number of walls,
/// axis distance within 1e-4 relative, angles within 0.01° — or fails with the same sentence
/// (`docs/building.md`).
#[test]
fn on_device_wall_readings_equal_the_hosts() {
    let wanted = [
        "wall-z150-frontal",
        "wall-corner-z200",
        "wall-corner-z150-a100-brick",
        "wall-z200-one-line",
    ];
    let same = |name: &str, h: &Measurement, d: &Measurement| {
        let (Measurement::Wall(h), Measurement::Wall(d)) = (h, d) else {
            panic!("{name}: wall readings, got host {h:?}, device {d:?}")
        };
        eprintln!("{name}: host {h:?}\n{name}: device {d:?}");
        assert_eq!(d.walls, h.walls, "{name}: walls");
        assert!(
            (d.distance - h.distance).abs() <= 1e-4 * h.distance,
            "{name}"
        );
        let deg = 0.01f64.to_radians() as tangent_core::real::Real;
        assert!((d.yaw.value - h.yaw.value).abs() <= deg, "{name}: yaw");
        match (d.corner, h.corner) {
            (Some(a), Some(b)) => assert!((a.value - b.value).abs() <= deg, "{name}"),
            (None, None) => {}
            other => panic!("{name}: corners {other:?}"),
        }
    };
    let Some(compared) = device_equals_host(
        tangent_host::simulate::corpus::entries(),
        &wanted,
        Mode::Wall,
        SetMode::Yes,
        same,
    ) else {
        return;
    };
    assert!(
        compared >= 3,
        "only {compared} wall captures measured on both sides"
    );
}

/// The vertical on the device (issue 15): the emulated board's ADXL355 (its register model,
/// through the same driver as the H743's) senses each wall capture's recorded specific force
/// with the part's noise; the device averages 16 samples, sends the mean with the wall
/// reading and computes the plumb with the accelerometer calibration pushed with the
/// camera's. The host, given the device's mean and the same calibration, computes the same
/// plumb (`tangent_core::accelerometer::vertical` on both sides; f32 against f64: within
/// 0.01°, σ within 1 %). Without a part the reading says so and has no plumb.
#[test]
fn on_device_plumb_equals_the_hosts() {
    use tangent_core::instrument::{measure, InstrumentParams};
    use tangent_core::pipeline::{OwnedBuffers, PipelineConfig};
    use tangent_core::protocol::{AccelReading, WireAccelerometer};
    use tangent_host::simulate::simulate;

    let Some(elf) = firmware_elf() else {
        return;
    };
    let wanted = [
        "wall-z150-frontal",
        "wall-corner-z200",
        "wall-z300-yaw25-concrete",
    ];
    let dir = tempfile::tempdir().unwrap();
    let mut compared = 0;
    for entry in tangent_host::simulate::corpus::entries()
        .into_iter()
        .filter(|e| wanted.contains(&e.name.as_str()))
    {
        let name = entry.name;
        let (capture, _) = simulate(&entry.spec).expect("simulate the corpus capture");
        let record = capture
            .meta
            .accelerometer
            .clone()
            .expect("a wall capture records its accelerometer");
        let (_, alignment) = record.to_core();
        let mut wire = WireCalibration::from(&capture.calibration);
        wire.accelerometer = Some(WireAccelerometer::from(&alignment));
        let off_pgm = capture.off_frame();
        let (_, on_pgm) = capture.on_frames().next().expect("an on frame");
        let (w, h) = (off_pgm.width, off_pgm.height);
        let (off, on) = (to_u8(off_pgm), to_u8(on_pgm));
        let pair = (
            dir.path().join(format!("{name}-off.pgm")),
            dir.path().join(format!("{name}-on.pgm")),
        );
        write_pgm(&pair.0, w, h, &off);
        write_pgm(&pair.1, w, h, &on);
        let force = record.mean_m_s2.map(|x| x as f32);
        let device_reading = |options: &str| {
            let mut dev = Device::boot_with(&elf, std::slice::from_ref(&pair), None, options);
            dev.request(Request::SetMode(Mode::Wall), |r| {
                assert_eq!(r, Response::Ack)
            });
            dev.request(Request::WriteCalibration(wire.clone()), |r| {
                assert_eq!(r, Response::Ack, "{name}")
            });
            dev.request(Request::Measure, |r| match r {
                Response::Reading(reading) => reading,
                other => panic!("{name}: {other:?}"),
            })
        };
        let host = |gravity| {
            let mut params = InstrumentParams::default();
            params.wall.walls.gravity = gravity;
            let off_f = tangent_core::image::Frame::new(&off, w, h, w).unwrap();
            let on_f = tangent_core::image::Frame::new(&on, w, h, w).unwrap();
            let mut ws = OwnedBuffers::<u8>::for_frame(w, h, 8, capture.calibration.planes.len());
            let m = measure(
                Mode::Wall,
                &off_f,
                &on_f,
                &capture.calibration,
                &PipelineConfig::default(),
                &params,
                &mut ws.workspace(),
            )
            .expect("the host reads the wall");
            let Measurement::Wall(m) = m else {
                panic!("{name}: {m:?}")
            };
            m
        };

        let reading = device_reading(&format!("--accel {},{},{}", force[0], force[1], force[2]));
        let Some(accel @ AccelReading::Mean { m_s2, samples, .. }) = reading.accelerometer else {
            panic!("{name}: {:?}", reading.accelerometer)
        };
        // The emulated part's noise, averaged: within 5σ/√16 of the sensed force.
        let sigma = tangent_firmware::adxl355::SAMPLE_SIGMA_M_S2 / (samples as f32).sqrt();
        for (got, want) in m_s2.iter().zip(force) {
            assert!(
                (got - want).abs() < 5.0 * sigma,
                "{name}: {m_s2:?} vs {force:?}"
            );
        }
        let v = tangent_core::accelerometer::vertical(&accel.mean().unwrap(), &alignment)
            .expect("the device was at rest");
        let h = host(Some((v.down, v.sigma_rad)));
        let Measurement::Wall(d) = reading.measurement else {
            panic!("{name}: {:?}", reading.measurement)
        };
        let (Some(dp), Some(hp)) = (d.plumb, h.plumb) else {
            panic!("{name}: plumb device {:?}, host {:?}", d.plumb, h.plumb)
        };
        eprintln!(
            "{name}: plumb host {:+.4}° ± {:.4}°, device {:+.4}° ± {:.4}°",
            hp.value.to_degrees(),
            hp.sigma.to_degrees(),
            dp.value.to_degrees(),
            dp.sigma.to_degrees()
        );
        assert!(
            (dp.value - hp.value).abs() <= 0.01f64.to_radians(),
            "{name}: plumb"
        );
        assert!(
            (dp.sigma - hp.sigma).abs() <= 0.01 * hp.sigma,
            "{name}: plumb σ"
        );
        compared += 1;

        if compared == 1 {
            // No part fitted: the reading is made, says why it has no plumb, and the host
            // without a vertical agrees.
            let reading = device_reading("");
            assert_eq!(reading.accelerometer, Some(AccelReading::Absent), "{name}");
            let Measurement::Wall(d) = reading.measurement else {
                panic!("{name}: {:?}", reading.measurement)
            };
            assert_eq!((d.plumb, host(None).plumb), (None, None), "{name}");
        }
    }
    assert_eq!(compared, wanted.len(), "corpus entries missing");
}
