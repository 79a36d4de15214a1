//! The firmware's real application (`tangent_firmware::app::App`, built for the host) on a
//! test board behind a pseudo-terminal, with fault injection.
//!
//! The host opens it by path (a symlink to the pty's slave side, like udev's
//! `/dev/serial/by-id/...` links), exactly as it opens a real device. Everything the device
//! says and does — command handling, history, streams, trigger presses, frame dumps,
//! calibration checks and storage, version rejection — is the firmware's own code; the test
//! board only supplies the ports (`tangent_firmware::ports`):
//!
//! * camera: deterministic frames ([`test_frame`]) after a short read-out time; the laser-on
//!   frame only when the strobe really lit a laser;
//! * lasers: record every switch ([`TestDevice::laser_switches`]);
//! * trigger: presses on command ([`TestDevice::press`]);
//! * link: the pty, which can drop and corrupt bytes in both directions (deterministic
//!   xorshift, per-mille rates), be cut (the host sees a hang-up and the path disappears;
//!   after a while it comes back on a new pty behind the same path, as a USB cable plugged
//!   back in), or speak another protocol version (frames re-encoded both ways, so the firmware
//!   sees a host of that version);
//! * measurer: reading `seq` has diameter [`diameter_of`]`(seq)` so a test can check each
//!   reading's content (the pipeline itself is checked on the emulated board,
//!   `tests/emulated_device.rs`).
//!
//! The application runs on a small polling executor in its own thread ([`block_on`]), as
//! on the emulated board. [`TestDevice::reboot`] restarts it (sequence numbers restart at 1).
//! [`NotATangent`] is a port that only sends line noise; [`Relay`] puts the same faults
//! between the host and another serial peer (the emulated firmware).

#![allow(dead_code)]

mod board;
mod pty;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tangent_core::calibration::Calibration;
use tangent_core::protocol::codes::HISTORY_LEN;
use tangent_core::protocol::{self, FrameSel, WireCalibration, MAX_FRAME_LEN};
use tangent_firmware::app::{App, Buffers};
use tangent_firmware::mode_log::ModeLog;
use tangent_firmware::ports::{Devices, Geometry};

use board::{
    block_on, NoWatchdog, PtyLink, RamStore, RamWords, RecordingLaser, TestBoard, TestCamera,
    TestClock, TestMeasurer, TestTrigger,
};
// Each test binary that includes this module uses a part of it.
#[allow(unused_imports)]
pub use pty::{Faults, NotATangent, Relay};

/// Readings the device keeps for `History` (the firmware's).
pub const HISTORY: usize = HISTORY_LEN;

/// The diameter the test measurer reports for reading `seq` (metres, as sent in `f32`).
pub fn diameter_of(seq: u32) -> f32 {
    0.1 + seq as f32 * 0.001
}

/// The test camera's frames: the reference design's 752 columns (so the firmware accepts
/// the reference calibration), a window of 2 rows (so a frame dump over a faulty link, three
/// chunks per frame, stays quick).
pub const FRAME: Geometry = Geometry {
    width: 752,
    height: 2,
    row_offset: 239,
};

/// Read-out time of one test frame (a measurement takes two).
const FRAME_TIME: Duration = Duration::from_millis(1);

/// The frame the test camera delivers for capture `capture` (counted from 1, as the
/// firmware numbers captures): deterministic, different for every capture and frame.
pub fn test_frame(capture: u32, sel: FrameSel) -> Vec<u8> {
    let mut x = 0x1234_5678u32 ^ capture.wrapping_mul(0x9E37_79B9) ^ (sel == FrameSel::On) as u32;
    (0..FRAME.frame_len())
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u8
        })
        .collect()
}

/// How a [`TestDevice`] starts.
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    /// The calibration store holds the reference design's calibration (without one the
    /// firmware refuses to measure).
    pub calibrated: bool,
    /// Protocol version on the wire (the firmware's own unless changed).
    pub protocol_version: u8,
}

impl Default for Setup {
    fn default() -> Self {
        Setup {
            calibrated: true,
            protocol_version: protocol::PROTOCOL_VERSION,
        }
    }
}

/// What the test and the board's devices share.
#[derive(Default)]
struct Control {
    presses: u32,
    press_interval: Duration,
    next_press: Option<Instant>,
    faults: Faults,
    cut_until: Option<Instant>,
    /// Ends the cut in force now ([`TestDevice::plug`]).
    plug: bool,
    reboot: bool,
    /// Boots so far (the first one included).
    boots: u32,
    stop: bool,
    /// Readings the measurer produced since the last boot (= the firmware's last `seq`).
    issued: u32,
    /// Every `Laser::set` since the start.
    laser_switches: Vec<u8>,
}

type Shared = Arc<Mutex<Control>>;

/// A running test device.
pub struct TestDevice {
    path: PathBuf,
    control: Shared,
    thread: Option<JoinHandle<()>>,
    _dir: tempfile::TempDir,
}

impl TestDevice {
    /// Starts a calibrated device of this protocol version; [`TestDevice::path`] is where
    /// the host opens it.
    pub fn start() -> TestDevice {
        TestDevice::start_with(Setup::default())
    }

    /// Starts a device as `setup` says.
    pub fn start_with(setup: Setup) -> TestDevice {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ttyTANGENT");
        let control: Shared = Arc::new(Mutex::new(Control {
            press_interval: Duration::from_millis(20),
            ..Control::default()
        }));
        let link = PtyLink::new(path.clone(), control.clone(), setup.protocol_version);
        let calibration = setup
            .calibrated
            .then(|| WireCalibration::from(&Calibration::reference_design()));
        let c = control.clone();
        let thread = std::thread::spawn(move || {
            let mut link = link;
            let mut store = RamStore(calibration);
            let mut modes = ModeLog::new(RamWords::new());
            while let Some((l, s, m)) = boot(link, store, modes, &c) {
                (link, store, modes) = (l, s, m);
            }
        });
        TestDevice {
            path,
            control,
            thread: Some(thread),
            _dir: dir,
        }
    }

    /// The path to open.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Presses the trigger `n` more times, one press every `interval`.
    pub fn press(&self, n: u32, interval: Duration) {
        let mut c = self.control.lock().unwrap();
        c.presses += n;
        c.press_interval = interval;
    }

    /// Sets the faults.
    pub fn faults(&self, f: Faults) {
        self.control.lock().unwrap().faults = f;
    }

    /// Cuts the link for `d` (then it comes back behind the same path).
    pub fn cut(&self, d: Duration) {
        self.control.lock().unwrap().cut_until = Some(Instant::now() + d);
    }

    /// Pulls the cable until [`TestDevice::plug`]: what the device does meanwhile depends on
    /// no clock.
    pub fn unplug(&self) {
        let mut c = self.control.lock().unwrap();
        c.cut_until = Some(Instant::now() + Duration::from_secs(3600));
        c.plug = false;
    }

    /// Plugs the cable back in (it comes back behind the same path).
    pub fn plug(&self) {
        let mut c = self.control.lock().unwrap();
        c.cut_until = None;
        c.plug = true;
    }

    /// Reboots the device and waits until it is up again (the firmware starts afresh:
    /// sequence numbers restart, history emptied; the stored calibration stays).
    pub fn reboot(&self) {
        let booted = {
            let mut c = self.control.lock().unwrap();
            c.reboot = true;
            c.boots
        };
        let end = Instant::now() + Duration::from_secs(5);
        while self.control.lock().unwrap().boots == booted {
            assert!(Instant::now() < end, "the test device did not reboot");
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Readings made since the last boot (the last sequence number).
    pub fn issued(&self) -> u32 {
        self.control.lock().unwrap().issued
    }

    /// Presses not yet made.
    pub fn presses_left(&self) -> u32 {
        self.control.lock().unwrap().presses
    }

    /// Waits until every press has been made.
    pub fn wait_presses(&self, timeout: Duration) {
        let end = Instant::now() + timeout;
        while self.presses_left() > 0 {
            assert!(
                Instant::now() < end,
                "the test device did not finish its presses"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Every laser mask the firmware has set, in order.
    pub fn laser_switches(&self) -> Vec<u8> {
        self.control.lock().unwrap().laser_switches.clone()
    }
}

impl Drop for TestDevice {
    fn drop(&mut self) {
        self.control.lock().unwrap().stop = true;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// What survives a reboot of the test device: the link (the USB cable), the calibration
/// store and the mode store (the flash).
type Kept = (PtyLink, RamStore, ModeLog<RamWords>);

/// Runs the firmware from a (re)boot until the test stops it (`None`) or reboots it (the
/// link and stores survive a reboot, as the USB cable and the flash do).
fn boot(
    link: PtyLink,
    store: RamStore,
    modes: ModeLog<RamWords>,
    control: &Shared,
) -> Option<Kept> {
    let mut off = vec![0u8; FRAME.frame_len()];
    let mut on = vec![0u8; FRAME.frame_len()];
    let mut rx = vec![0u8; MAX_FRAME_LEN];
    let devices = Devices::<TestBoard> {
        camera: TestCamera { captures: 0 },
        laser: RecordingLaser(control.clone()),
        trigger: TestTrigger(control.clone()),
        link,
        clock: TestClock(Instant::now()),
        store,
        modes,
        watchdog: NoWatchdog,
        accelerometer: tangent_firmware::adxl355::Adxl355::new(
            tangent_firmware::i2c_target::TargetBus::new(None),
        ),
    };
    let measurer = TestMeasurer {
        control: control.clone(),
        made: 0,
    };
    let buffers = Buffers {
        off: &mut off,
        on: &mut on,
        rx: &mut rx,
    };
    let mut app = App::new(devices, measurer, buffers);
    block_on(app.announce());
    {
        let mut c = control.lock().unwrap();
        c.issued = 0;
        c.boots += 1;
    }
    loop {
        {
            let mut c = control.lock().unwrap();
            if c.stop {
                return None;
            }
            if std::mem::take(&mut c.reboot) {
                break;
            }
        }
        // At most the firmware's idle tick (100 ms) long.
        block_on(app.step());
    }
    let Devices {
        link, store, modes, ..
    } = app.dev;
    Some((link, store, modes))
}
