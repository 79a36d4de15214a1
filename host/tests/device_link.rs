//! The serial link against the firmware's application on a test board behind a pty
//! (`test_device`), with faults: bytes dropped and corrupted both ways, the link cut and
//! restored, a reboot, another protocol version, a port that is not a Tangent. The invariant checked everywhere: the readings the
//! link delivers are exactly 1..=N, in order, each with its own content — none lost, none
//! duplicated — unless they fell out of the device's 64-reading history, which the link must
//! then count exactly.

mod test_device;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tangent_core::protocol::{FrameSel, PROTOCOL_VERSION};
use tangent_host::link::{Link, LinkConfig, LinkError, LinkEvent};
use test_device::{diameter_of, test_frame, Faults, NotATangent, Setup, TestDevice, HISTORY};

fn cfg() -> LinkConfig {
    LinkConfig {
        reply_timeout: Duration::from_millis(300),
        attempts: 8,
        reconnect_timeout: Some(Duration::from_secs(10)),
        idle_check: Duration::from_millis(300),
    }
}

fn open(dev: &TestDevice) -> Link {
    Link::open(dev.path().to_str().unwrap(), cfg()).expect("open the test device")
}

/// Reads until `done` holds of what has arrived and the link's counters (at most
/// `timeout`), checking each reading's content.
fn read_until(
    link: &mut Link,
    seqs: &mut Vec<u32>,
    what: &str,
    timeout: Duration,
    done: impl Fn(&[u32], &tangent_host::link::LinkCounters) -> bool,
) {
    let end = Instant::now() + timeout;
    while !done(seqs, &link.counters()) {
        assert!(
            Instant::now() < end,
            "{what}: got {seqs:?}, {:?}",
            link.counters()
        );
        if let Some(r) = link.next_reading(Duration::from_millis(100)).unwrap() {
            assert_eq!(
                r.measurement.value(),
                f64::from(diameter_of(r.seq)),
                "content of reading {}",
                r.seq
            );
            seqs.push(r.seq);
        }
    }
}

/// Collects readings until `n` arrived (at most `timeout`), checking order and content.
fn collect(link: &mut Link, n: u32, timeout: Duration) -> Vec<u32> {
    let mut seqs = Vec::new();
    let what = format!("{n} readings");
    read_until(link, &mut seqs, &what, timeout, |s, _| s.len() as u32 >= n);
    // Nothing more may come (a duplicate would show up here).
    let extra = link.next_reading(Duration::from_millis(700)).unwrap();
    assert_eq!(extra.map(|r| r.seq), None, "reading beyond the {n} issued");
    seqs
}

fn one_to(n: u32) -> Vec<u32> {
    (1..=n).collect()
}

#[test]
fn clean_link_delivers_every_reading_once() {
    let dev = TestDevice::start();
    let mut link = open(&dev);
    assert_eq!(link.identity().fw_version, tangent_firmware::VERSION);
    dev.press(40, Duration::from_millis(5));
    assert_eq!(collect(&mut link, 40, Duration::from_secs(20)), one_to(40));
    let c = link.counters();
    assert_eq!(
        (c.malformed, c.duplicates, c.lost, c.reconnects),
        (0, 0, 0, 0)
    );
}

#[test]
fn dropped_and_corrupted_bytes_lose_and_duplicate_nothing() {
    let dev = TestDevice::start();
    let mut link = open(&dev);
    // 1 % of bytes dropped and 1 % corrupted in each direction: a reading frame (~30 bytes)
    // is damaged with probability ≈ 1 − 0.98^30 ≈ 45 %, so the recovery path runs often.
    // The CRC misses a damaged frame with probability 2^-16 per frame; over the few
    // hundred frames here that is < 1 %, and the xorshift sequence is fixed, so the test
    // is deterministic given the thread timing.
    dev.faults(Faults {
        drop_out: 10,
        corrupt_out: 10,
        drop_in: 10,
        corrupt_in: 10,
    });
    let n = 60; // fewer than the history (64), so every loss is recoverable
    dev.press(n, Duration::from_millis(10));
    let seqs = collect(&mut link, n, Duration::from_secs(60));
    assert_eq!(seqs, one_to(n));
    let c = link.counters();
    assert!(c.malformed > 5, "faults were injected: {c:?}");
    assert!(
        c.history_requests > 1,
        "gaps were recovered from the history: {c:?}"
    );
    assert_eq!(c.lost, 0);
    eprintln!("faulty link: {c:?}");
}

const MINUTE: Duration = Duration::from_secs(60);

/// Two cable cuts, each while readings are still on their way and with ten more made while
/// the cable is out; ordered by events (what arrived, the link's reconnects), not by time.
#[test]
fn cut_and_restored_link_recovers_readings_made_meanwhile() {
    let dev = TestDevice::start();
    let mut link = open(&dev);
    let events = Arc::new(Mutex::new(Vec::new()));
    let e = events.clone();
    link.on_event(move |ev| e.lock().unwrap().push(ev.clone()));
    let mut seqs = Vec::new();
    for cut in 1..=2u64 {
        // Fifteen presses; the cable goes once ten of them have arrived.
        dev.press(15, Duration::from_millis(10));
        let arrived = seqs.len() + 10;
        read_until(&mut link, &mut seqs, "ten readings", MINUTE, |s, _| {
            s.len() >= arrived
        });
        dev.unplug();
        dev.wait_presses(Duration::from_secs(30));
        dev.press(10, Duration::from_millis(5));
        dev.wait_presses(Duration::from_secs(30));
        dev.plug();
        read_until(&mut link, &mut seqs, "the reconnect", MINUTE, |_, c| {
            c.reconnects >= cut
        });
    }
    seqs.extend(collect(
        &mut link,
        50 - seqs.len() as u32,
        Duration::from_secs(30),
    ));
    assert_eq!(seqs, one_to(50));
    assert_eq!(dev.issued(), 50);
    let c = link.counters();
    assert_eq!(c.reconnects, 2, "{c:?}");
    assert_eq!(c.lost, 0);
    let ev = events.lock().unwrap();
    assert!(ev.iter().any(|e| matches!(e, LinkEvent::Lost(_))), "{ev:?}");
}

#[test]
fn readings_beyond_the_history_are_counted_exactly_as_lost() {
    let dev = TestDevice::start();
    let mut link = open(&dev);
    let events = Arc::new(Mutex::new(Vec::new()));
    let e = events.clone();
    link.on_event(move |ev| e.lock().unwrap().push(ev.clone()));
    // 5 readings, then the cable is out while 80 more are made: the device keeps the last
    // 64 (22..=85), so 6..=21 (16 readings) are gone for good.
    dev.press(5, Duration::from_millis(2));
    assert_eq!(collect(&mut link, 5, Duration::from_secs(10)), one_to(5));
    dev.cut(Duration::from_millis(1500));
    std::thread::sleep(Duration::from_millis(50));
    dev.press(80, Duration::from_millis(2));
    let got = collect(&mut link, 64, Duration::from_secs(30));
    let first_kept = 85 - HISTORY as u32 + 1;
    assert_eq!(got, (first_kept..=85).collect::<Vec<_>>());
    assert_eq!(link.counters().lost, (first_kept - 6) as u64);
    let ev = events.lock().unwrap();
    assert!(
        ev.contains(&LinkEvent::Unrecoverable {
            from: 6,
            to: first_kept - 1
        }),
        "{ev:?}"
    );
}

#[test]
fn reboot_restarts_the_sequence_without_losing_new_readings() {
    let dev = TestDevice::start();
    let mut link = open(&dev);
    dev.press(10, Duration::from_millis(5));
    assert_eq!(collect(&mut link, 10, Duration::from_secs(10)), one_to(10));
    dev.reboot();
    std::thread::sleep(Duration::from_millis(50));
    dev.press(7, Duration::from_millis(5));
    assert_eq!(collect(&mut link, 7, Duration::from_secs(10)), one_to(7));
    assert_eq!(link.counters().reboots, 1);
}

#[test]
fn stream_and_measure_requests() {
    let dev = TestDevice::start();
    let mut link = open(&dev);
    link.measure().unwrap();
    link.measure().unwrap();
    assert_eq!(collect(&mut link, 2, Duration::from_secs(5)), one_to(2));
    dev.press(0, Duration::from_millis(10));
    link.start_stream().unwrap();
    let mut seqs = Vec::new();
    while seqs.len() < 10 {
        if let Some(r) = link.next_reading(Duration::from_secs(2)).unwrap() {
            assert!(r.stats.is_some());
            seqs.push(r.seq);
        }
    }
    link.stop_stream().unwrap();
    // Readings made before the stop took effect still arrive, once each, in order.
    while let Some(r) = link.next_reading(Duration::from_millis(700)).unwrap() {
        seqs.push(r.seq);
    }
    let last = *seqs.last().unwrap();
    assert_eq!(seqs, (3..=last).collect::<Vec<_>>());
    assert_eq!(dev.issued(), last);
}

#[test]
fn frame_dump_and_calibration_over_a_faulty_link() {
    let dev = TestDevice::start_with(Setup {
        calibrated: false,
        ..Setup::default()
    });
    let mut link = open(&dev);
    dev.faults(Faults {
        drop_out: 2,
        corrupt_out: 2,
        drop_in: 2,
        corrupt_in: 2,
    });
    let info = link.capture_frames().unwrap();
    for sel in [FrameSel::Off, FrameSel::On] {
        let got = link.read_frame(&info, sel, |_| {}).unwrap();
        assert!(
            got == test_frame(info.capture, sel),
            "{sel:?} frame differs"
        );
    }
    // The firmware lit both lasers for the laser-on frame only, and switched them off.
    let switches = dev.laser_switches();
    assert_eq!(switches.last(), Some(&0), "{switches:?}");
    assert!(
        switches.contains(&0b11) && switches.iter().all(|&m| m == 0 || m == 0b11),
        "{switches:?}"
    );
    let cal = tangent_core::protocol::WireCalibration::from(
        &tangent_core::calibration::Calibration::reference_design(),
    );
    assert_eq!(link.read_calibration().unwrap(), None);
    link.write_calibration(&cal).unwrap();
    assert_eq!(link.read_calibration().unwrap(), Some(cal));
}

#[test]
fn another_protocol_version_is_named() {
    let dev = TestDevice::start_with(Setup {
        protocol_version: PROTOCOL_VERSION + 1,
        ..Setup::default()
    });
    let err = Link::open(dev.path().to_str().unwrap(), cfg())
        .err()
        .expect("must fail");
    assert!(
        matches!(
            err,
            LinkError::VersionMismatch {
                device,
                host: PROTOCOL_VERSION,
                ..
            } if device == PROTOCOL_VERSION + 1
        ),
        "{err:?}"
    );
    let text = err.to_string();
    assert!(
        text.contains(&format!("version {}", PROTOCOL_VERSION + 1))
            && text.contains(&format!("version {PROTOCOL_VERSION}")),
        "{text}"
    );
}

#[test]
fn a_port_that_is_not_a_tangent_is_refused() {
    let dev = NotATangent::start();
    let err = Link::open(dev.path().to_str().unwrap(), cfg())
        .err()
        .expect("must fail");
    match &err {
        LinkError::NotATangent { bytes, .. } => assert!(*bytes > 0, "{err:?}"),
        other => panic!("{other:?}"),
    }
    assert!(err.to_string().contains("does not look like a Tangent"));
}

#[test]
fn a_missing_port_says_so() {
    let err = Link::open("/dev/does-not-exist-tangent", cfg())
        .err()
        .unwrap();
    assert!(matches!(err, LinkError::Open { .. }), "{err:?}");
    assert!(err.to_string().contains("tangent devices"));
}

// ---------------------------------------------------------------------------------------
// End to end: the real `tangent` binary against the emulated firmware under QEMU, through
// a pty (`firmware/qemu/run.sh --serial pty`), optionally through a faulty relay.
// ---------------------------------------------------------------------------------------

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use tangent_host::capture::Capture;
use tangent_host::fieldlog::{FieldLog, Record};
use test_device::Relay;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The emulated firmware on a pty; killed on drop.
struct Emulated {
    child: Child,
    pty: PathBuf,
}

impl Drop for Emulated {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Boots the emulated firmware on the frames of `capture` (without a calibration); `None`,
/// with the reason printed, when the ELF is not built or QEMU is missing. CI builds the ELF
/// (`cargo firmware-qemu`) before the host tests.
fn boot_emulated(capture: &Path) -> Option<Emulated> {
    boot_emulated_with(capture, &[])
}

/// [`boot_emulated`] with more of the firmware's options (`--mode-store FILE`) before the
/// frames.
fn boot_emulated_with(capture: &Path, options: &[&str]) -> Option<Emulated> {
    let elf = repo().join("firmware/target/thumbv7em-none-eabihf/release/tangent-qemu");
    if !elf.is_file() {
        eprintln!(
            "SKIPPED: {} is not built (run `cargo firmware-qemu`)",
            elf.display()
        );
        return None;
    }
    if Command::new("qemu-system-arm")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("SKIPPED: qemu-system-arm is not installed");
        return None;
    }
    let mut child = Command::new(repo().join("firmware/qemu/run.sh"))
        .args(["--serial", "pty", "--"])
        .args(options)
        .arg(capture.join("off.pgm"))
        .arg(capture.join("on.pgm"))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run firmware/qemu/run.sh");
    // QEMU announces "char device redirected to /dev/pts/N (label serial0)" on one of its
    // streams; watch both.
    let (tx, rx) = std::sync::mpsc::channel();
    for stream in [
        Box::new(child.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>,
        Box::new(child.stderr.take().unwrap()),
    ] {
        let tx = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stream).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
    }
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        if let Ok(line) = rx.recv_timeout(Duration::from_millis(200)) {
            if let Some(rest) = line.split("redirected to ").nth(1) {
                let pty = PathBuf::from(rest.split_whitespace().next().unwrap());
                // Give the firmware a moment to boot (its banner is not needed).
                std::thread::sleep(Duration::from_millis(300));
                return Some(Emulated { child, pty });
            }
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    panic!("QEMU did not announce its pty");
}

fn tangent(args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "tangent {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn logged(log: &Path) -> Vec<tangent_host::fieldlog::TreeRecord> {
    FieldLog::read(log)
        .unwrap()
        .into_iter()
        .filter_map(|r| match r {
            Record::Tree(t) => Some(t),
            Record::Plot(_) => None,
        })
        .collect()
}

const SOURCE: &str = "tests/captures/cyl-d300-z150-shade";

/// Calibration round trip, measurements, a stream and a recorded capture equal to its
/// source, all through the `tangent` binary.
#[test]
fn emulated_device_end_to_end() {
    let source = repo().join(SOURCE);
    let Some(dev) = boot_emulated(&source) else {
        return;
    };
    let port = dev.pty.to_str().unwrap().to_string();
    let dir = tempfile::tempdir().unwrap();
    let src = Capture::read(&source).unwrap();

    // Calibration: push the capture's, pull it back, identical.
    let cal_in = dir.path().join("cal.toml");
    tangent_host::calibration_file::write(&cal_in, &src.calibration).unwrap();
    tangent(&[
        "device-calibration",
        "push",
        "--port",
        &port,
        cal_in.to_str().unwrap(),
    ]);
    let cal_out = dir.path().join("pulled.toml");
    tangent(&[
        "device-calibration",
        "pull",
        "--port",
        &port,
        cal_out.to_str().unwrap(),
    ]);
    assert_eq!(
        tangent_host::calibration_file::read(&cal_out).unwrap(),
        src.calibration
    );

    // Three measurements (as trigger presses), then a stream of five.
    let log = dir.path().join("field.log");
    let l = log.to_str().unwrap();
    tangent(&[
        "listen",
        "--port",
        &port,
        "--log",
        l,
        "--plot-id",
        "E2E",
        "--species",
        "PIAB",
        "--measure",
        "3",
    ]);
    tangent(&[
        "listen", "--port", &port, "--log", l, "--stream", "--count", "5",
    ]);
    let trees = logged(&log);
    assert_eq!(
        trees.iter().map(|t| t.seq).collect::<Vec<_>>(),
        (1..=8).collect::<Vec<_>>()
    );
    // Truth: a 300 mm stem. The reading must lie within 3 of its own predicted standard
    // uncertainties (the error model's claim; the f32 device adds < 1e-4 relative).
    let truth_mm = 300.0;
    for t in &trees {
        assert!(
            (t.diameter_mm - truth_mm).abs() < 3.0 * t.uncertainty_mm,
            "{} mm ± {} vs {truth_mm}",
            t.diameter_mm,
            t.uncertainty_mm
        );
        assert_eq!(t.calib_id, src.calibration.id);
        assert_eq!(t.device_id, "emulated");
    }
    // Tree ids: one per press (1, 2, 3), the stream is one held trigger (tree 4).
    assert_eq!(
        trees.iter().map(|t| t.tree_id).collect::<Vec<_>>(),
        [1, 2, 3, 4, 4, 4, 4, 4]
    );

    // Record a capture: the frames equal the source's, the calibration is the device's.
    let rec = dir.path().join("rec");
    tangent(&["record", "--port", &port, rec.to_str().unwrap()]);
    let got = Capture::read(&rec).unwrap();
    assert_eq!(got.calibration, src.calibration);
    assert!(
        got.off_frame() == src.off_frame(),
        "off frame differs from the source"
    );
    let (lit_got, on_got) = got.on_frames().next().unwrap();
    let (lit_src, on_src) = src.on_frames().next().unwrap();
    assert_eq!(lit_got, lit_src);
    assert!(on_got == on_src, "on frame differs from the source");
}

/// Bytes dropped and corrupted between host and emulated device, and the cable pulled
/// twice while the forester keeps measuring: the log holds every reading the device made,
/// once, in order (a request corrupted on the way makes no reading; that is not a loss).
#[test]
fn emulated_device_through_a_faulty_cut_link() {
    let source = repo().join(SOURCE);
    let Some(dev) = boot_emulated(&source) else {
        return;
    };
    let src = Capture::read(&source).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cal = dir.path().join("cal.toml");
    tangent_host::calibration_file::write(&cal, &src.calibration).unwrap();
    tangent(&[
        "device-calibration",
        "push",
        "--port",
        dev.pty.to_str().unwrap(),
        cal.to_str().unwrap(),
    ]);

    let relay = Relay::start(&dev.pty);
    relay.faults(Faults {
        drop_out: 3,
        corrupt_out: 3,
        drop_in: 3,
        corrupt_in: 3,
    });
    let log = dir.path().join("field.log");
    let n = 30;
    let mut child = Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args(["listen", "--port", relay.path().to_str().unwrap(), "--log"])
        .arg(&log)
        .args(["--measure", &n.to_string(), "--plot-id", "F"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    for _ in 0..2 {
        std::thread::sleep(Duration::from_millis(1500));
        relay.cut(Duration::from_millis(500));
    }
    let deadline = Instant::now() + Duration::from_secs(180);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(Instant::now() < deadline, "listen did not finish");
        std::thread::sleep(Duration::from_millis(100));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    eprintln!("{err}");
    assert!(status.success(), "{err}");
    drop(relay);
    // What the device made, asked directly (no relay).
    let mut direct = Link::open(dev.pty.to_str().unwrap(), LinkConfig::default()).unwrap();
    let made = direct.device_info().unwrap().last_seq;
    let seqs: Vec<u32> = logged(&log).iter().map(|t| t.seq).collect();
    assert_eq!(seqs, (1..=made).collect::<Vec<_>>(), "{err}");
    assert!(made >= n / 2, "only {made} of {n} measurements made: {err}");
    assert!(err.contains("link lost"), "the cuts happened: {err}");
}

/// `Link::set_mode` on the real firmware application: a measured mode is taken and shows in
/// the identity, any other is refused with the device's sentence naming the mode.
#[test]
fn the_link_sets_the_mode_and_names_a_refusal() {
    use tangent_core::instrument;
    use tangent_core::measurement::Mode;
    let dev = TestDevice::start();
    let mut link = open(&dev);
    assert_eq!(link.identity().mode, Mode::Cylinder);
    for mode in Mode::ALL {
        match link.set_mode(mode) {
            Ok(()) => {
                assert!(instrument::supports(mode));
                assert_eq!(link.identity().mode, mode);
                assert_eq!(link.device_info().unwrap().mode, mode);
            }
            Err(e) => {
                assert!(!instrument::supports(mode));
                let text = e.to_string();
                assert!(
                    text.contains("SetMode") && text.contains(mode.name()),
                    "{text}"
                );
                assert_ne!(link.device_info().unwrap().mode, mode);
            }
        }
    }
}

/// The mode survives a reboot in the firmware itself: a fresh link (which never set a mode)
/// finds the mode set before the reboot, read from the device's mode store.
#[test]
fn the_mode_set_before_a_reboot_is_the_mode_after_it() {
    use tangent_core::measurement::Mode;
    use tangent_core::protocol::ModeStoreState;
    let dev = TestDevice::start();
    {
        let mut link = open(&dev);
        assert_eq!(link.identity().mode_store, ModeStoreState::Empty);
        link.set_mode(Mode::Sphere).unwrap();
        assert_eq!(
            link.identity().mode_store,
            ModeStoreState::Loaded(Mode::Sphere)
        );
    }
    dev.reboot();
    let mut link = open(&dev);
    let info = link.device_info().unwrap();
    assert!(info.uptime_ms < 5_000, "a fresh boot");
    assert_eq!(info.mode, Mode::Sphere);
    assert_eq!(info.mode_store, ModeStoreState::Loaded(Mode::Sphere));
}

/// The emulated device keeps its mode across a restart of the emulator in its mode store
/// file (`--mode-store`, the H743's flash sector), and a damaged file gives the default mode
/// with the reason, which `tangent listen` prints.
#[test]
fn the_emulated_device_remembers_its_mode_across_a_restart() {
    use tangent_core::measurement::Mode;
    use tangent_core::protocol::ModeStoreState;
    let source = repo().join(SOURCE);
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("modes.bin");
    let store_arg = store.to_str().unwrap();
    let Some(dev) = boot_emulated_with(&source, &["--mode-store", store_arg]) else {
        return;
    };
    {
        let mut link = Link::open(dev.pty.to_str().unwrap(), LinkConfig::default()).unwrap();
        assert_eq!(link.identity().mode, Mode::Cylinder);
        assert_eq!(link.identity().mode_store, ModeStoreState::Empty);
        link.set_mode(Mode::Sphere).unwrap();
    }
    // Power off: the emulator ends, the file stays.
    drop(dev);
    assert!(store.is_file(), "the mode store file was written");
    let dev = boot_emulated_with(&source, &["--mode-store", store_arg]).unwrap();
    {
        let mut link = Link::open(dev.pty.to_str().unwrap(), LinkConfig::default()).unwrap();
        let info = link.device_info().unwrap();
        assert_eq!(info.mode, Mode::Sphere, "remembered across the restart");
        assert_eq!(info.mode_store, ModeStoreState::Loaded(Mode::Sphere));
        // Changes append to the log; the last one wins after the next restart.
        link.set_mode(Mode::Wall).unwrap();
    }
    drop(dev);
    let dev = boot_emulated_with(&source, &["--mode-store", store_arg]).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args(["listen", "--port", dev.pty.to_str().unwrap(), "--log"])
        .arg(dir.path().join("field.log"))
        .args(["--measure", "0"])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("mode wall"), "{err}");
    drop(dev);

    // A damaged store: every word garbage. The default, and the reason.
    std::fs::write(&store, vec![0x5Au8; 64 * 32]).unwrap();
    let dev = boot_emulated_with(&source, &["--mode-store", store_arg]).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args(["listen", "--port", dev.pty.to_str().unwrap(), "--log"])
        .arg(dir.path().join("field.log"))
        .args(["--measure", "0"])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("mode cylinder") && err.contains("damaged"),
        "{err}"
    );
    let link = Link::open(dev.pty.to_str().unwrap(), LinkConfig::default()).unwrap();
    assert_eq!(link.identity().mode_store, ModeStoreState::Corrupt);
}
