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

use std::fs::File;
use std::future::{poll_fn, Future};
use std::io::{ErrorKind, Read, Write};
use std::os::fd::FromRawFd;
use std::path::{Path, PathBuf};
use std::pin::pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, Waker};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tangent_core::calibration::Calibration;
use tangent_core::protocol::{
    self, FrameSel, FromDevice, Method, ToDevice, WireCalibration, MAX_FRAME_LEN, MAX_RAW_LEN,
};
use tangent_firmware::app::{App, Buffers, HISTORY_LEN};
use tangent_firmware::measure::{FramePair, Measurer, Outcome};
use tangent_firmware::ports::{
    Board, CalibrationStore, Camera, CameraError, Clock, Devices, Geometry, Laser, Link, LinkError,
    Strobe, Trigger, Watchdog,
};

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

/// Faults applied to every byte (per mille).
#[derive(Debug, Clone, Copy, Default)]
pub struct Faults {
    /// Device → host bytes dropped.
    pub drop_out: u32,
    /// Device → host bytes corrupted (XOR with a random non-zero value).
    pub corrupt_out: u32,
    /// Host → device bytes dropped.
    pub drop_in: u32,
    /// Host → device bytes corrupted.
    pub corrupt_in: u32,
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
    reboot: bool,
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
        let link = PtyLink {
            pty: Some(open_pty(&path)),
            path: path.clone(),
            control: control.clone(),
            down_until: None,
            rng: 0x2545_F491,
            version: setup.protocol_version,
            incoming: Vec::new(),
            pending: Vec::new(),
        };
        let calibration = setup
            .calibrated
            .then(|| WireCalibration::from(&Calibration::reference_design()));
        let c = control.clone();
        let thread = std::thread::spawn(move || {
            let mut link = link;
            let mut store = RamStore(calibration);
            while let Some((l, s)) = boot(link, store, &c) {
                (link, store) = (l, s);
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

    /// Reboots the device (the firmware starts afresh: sequence numbers restart, history
    /// emptied; the stored calibration stays).
    pub fn reboot(&self) {
        self.control.lock().unwrap().reboot = true;
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

/// Runs the firmware from a (re)boot until the test stops it (`None`) or reboots it (the
/// link and store survive a reboot, as the USB cable and the flash do).
fn boot(link: PtyLink, store: RamStore, control: &Shared) -> Option<(PtyLink, RamStore)> {
    control.lock().unwrap().issued = 0;
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
        watchdog: NoWatchdog,
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
    let Devices { link, store, .. } = app.dev;
    Some((link, store))
}

/// Polls `future` to completion, sleeping briefly between polls: the test board's devices
/// (a non-blocking pty, `Instant` deadlines) are polled, not interrupt-driven, as on the
/// emulated board (whose `embassy_futures::block_on` spins; here that would take a core).
pub fn block_on<F: Future>(future: F) -> F::Output {
    let mut future = pin!(future);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(v) = future.as_mut().poll(&mut cx) {
            return v;
        }
        std::thread::sleep(Duration::from_micros(200));
    }
}

/// Completes at `deadline`.
async fn until(deadline: Instant) {
    poll_fn(|_| {
        if Instant::now() >= deadline {
            Poll::Ready(())
        } else {
            Poll::Pending
        }
    })
    .await
}

struct TestBoard;

impl Board for TestBoard {
    type Camera = TestCamera;
    type Laser = RecordingLaser;
    type Trigger = TestTrigger;
    type Link = PtyLink;
    type Clock = TestClock;
    type Store = RamStore;
    type Watchdog = NoWatchdog;
    const KIND: protocol::Board = protocol::Board::Emulated;
    /// The firmware's log, on stderr when `TANGENT_TEST_DEVICE_LOG` is set (the tests
    /// check what goes over the link).
    fn log(args: std::fmt::Arguments<'_>) {
        if std::env::var_os("TANGENT_TEST_DEVICE_LOG").is_some() {
            eprintln!("device: {args}");
        }
    }
}

struct TestClock(Instant);

impl Clock for TestClock {
    fn now_us(&self) -> u64 {
        self.0.elapsed().as_micros() as u64
    }
    async fn delay_us(&self, us: u32) {
        until(Instant::now() + Duration::from_micros(us as u64)).await
    }
}

struct TestCamera {
    /// Laser-on frames delivered (the firmware's capture number after a pair).
    captures: u32,
}

impl Camera for TestCamera {
    fn geometry(&self) -> Geometry {
        FRAME
    }

    async fn capture<L: Laser, C: Clock>(
        &mut self,
        _exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        buf: &mut [u8],
    ) -> Result<(), CameraError> {
        strobe.on();
        let lit = strobe.is_lit();
        until(Instant::now() + FRAME_TIME).await;
        strobe.off();
        let frame = if lit {
            self.captures += 1;
            test_frame(self.captures, FrameSel::On)
        } else {
            test_frame(self.captures + 1, FrameSel::Off)
        };
        buf.get_mut(..frame.len())
            .ok_or(CameraError::BufferSize)?
            .copy_from_slice(&frame);
        Ok(())
    }
}

struct RecordingLaser(Shared);

impl Laser for RecordingLaser {
    fn count(&self) -> u8 {
        2
    }
    fn set(&mut self, mask: u8) {
        self.0.lock().unwrap().laser_switches.push(mask);
    }
}

struct TestTrigger(Shared);

impl Trigger for TestTrigger {
    /// Presses are short: released before the measurement ends.
    fn is_pressed(&mut self) -> bool {
        false
    }

    async fn wait_pressed(&mut self) {
        poll_fn(|_| {
            let mut c = self.0.lock().unwrap();
            let now = Instant::now();
            if c.presses == 0 || c.next_press.is_some_and(|t| now < t) {
                return Poll::Pending;
            }
            c.presses -= 1;
            c.next_press = Some(now + c.press_interval);
            Poll::Ready(())
        })
        .await
    }
}

struct RamStore(Option<WireCalibration>);

impl CalibrationStore for RamStore {
    fn load(&mut self) -> Option<WireCalibration> {
        self.0.clone()
    }
    fn save(&mut self, calibration: &WireCalibration) -> Result<(), u32> {
        self.0 = Some(calibration.clone());
        Ok(())
    }
}

struct NoWatchdog;

impl Watchdog for NoWatchdog {
    fn feed(&mut self) {}
}

/// Reading `n` after a boot has diameter [`diameter_of`]`(n)`; the firmware numbers its
/// readings the same way (every measurement here succeeds).
struct TestMeasurer {
    control: Shared,
    made: u32,
}

impl Measurer for TestMeasurer {
    fn measure(&mut self, pair: &FramePair<'_>, _: &Calibration) -> Result<Outcome, u32> {
        assert_eq!(
            (pair.width, pair.height, pair.row_offset),
            (
                FRAME.width as usize,
                FRAME.height as usize,
                FRAME.row_offset as usize
            )
        );
        self.made += 1;
        self.control.lock().unwrap().issued = self.made;
        Ok(Outcome {
            method: Method::CircleFit,
            diameter_m: diameter_of(self.made),
            uncertainty_m: 0.0015,
            distance_m: 1.2,
            tilt_rad: 0.05,
            flags: 0x0004,
        })
    }
}

/// The pty as the firmware's host link: a USB CDC-ACM port seen from the device.
struct PtyLink {
    pty: Option<Pty>,
    path: PathBuf,
    control: Shared,
    /// Cable out until then.
    down_until: Option<Instant>,
    rng: u32,
    /// Protocol version on the wire.
    version: u8,
    /// Host bytes of a partial frame (another version only).
    incoming: Vec<u8>,
    /// Bytes for the firmware not yet read (host frames re-encoded in the firmware's
    /// version can be longer than the firmware's read).
    pending: Vec<u8>,
}

impl PtyLink {
    fn rand(&mut self) -> u32 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 17;
        self.rng ^= self.rng << 5;
        self.rng
    }

    fn hit(&mut self, per_mille: u32) -> bool {
        per_mille > 0 && self.rand() % 1000 < per_mille
    }

    /// Drops and corrupts bytes at the given rates.
    fn damage(&mut self, bytes: &[u8], drop: u32, corrupt: u32) -> Vec<u8> {
        let mut out = Vec::with_capacity(bytes.len());
        for &b in bytes {
            if self.hit(drop) {
                continue;
            }
            out.push(if self.hit(corrupt) {
                b ^ (1 + (self.rand() % 255) as u8)
            } else {
                b
            });
        }
        out
    }

    /// Queues host bytes for the firmware. Another version's frames are re-encoded in the
    /// firmware's version (frames that do not decode pass as they are, for the firmware to
    /// reject).
    fn from_host(&mut self, bytes: &[u8]) {
        if self.version == protocol::PROTOCOL_VERSION {
            self.pending.extend_from_slice(bytes);
            return;
        }
        for &b in bytes {
            self.incoming.push(b);
            if b == protocol::DELIMITER {
                let mut frame = std::mem::take(&mut self.incoming);
                let copy = frame.clone();
                let out = match protocol::decode::<ToDevice>(&mut frame) {
                    Ok(msg) => reframe(&msg, self.version),
                    Err(_) => copy,
                };
                self.pending.extend_from_slice(&out);
            }
        }
    }
}

/// `message` as a frame of protocol `version`.
fn reframe<T: serde::Serialize>(message: &T, version: u8) -> Vec<u8> {
    let mut scratch = [0u8; MAX_RAW_LEN];
    let raw = protocol::encode_raw(message, version, &mut scratch).unwrap();
    let mut out = [0u8; MAX_FRAME_LEN];
    let n = protocol::cobs_frame(raw, &mut out).unwrap();
    out[..n].to_vec()
}

impl Link for PtyLink {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, LinkError> {
        poll_fn(|_| {
            if let Some(until) = self.control.lock().unwrap().cut_until.take() {
                // Cable out: the host's port hangs up and the path disappears; the firmware
                // sees the disconnect once, then waits for the cable, measuring meanwhile.
                self.pty = None;
                let _ = std::fs::remove_file(&self.path);
                self.down_until = Some(until);
                self.incoming.clear();
                self.pending.clear();
                return Poll::Ready(Err(LinkError::Disconnected));
            }
            if let Some(until) = self.down_until {
                if Instant::now() < until {
                    return Poll::Pending;
                }
                self.down_until = None;
                self.pty = Some(open_pty(&self.path));
            }
            let Some(pty) = self.pty.as_mut() else {
                return Poll::Pending;
            };
            let mut raw = [0u8; 256];
            // Nothing there, or nobody has the port open (EIO): nothing new.
            if let Ok(n) = pty.master.read(&mut raw) {
                let f = self.control.lock().unwrap().faults;
                let damaged = self.damage(&raw[..n], f.drop_in, f.corrupt_in);
                self.from_host(&damaged);
            }
            if self.pending.is_empty() {
                return Poll::Pending;
            }
            let n = self.pending.len().min(buf.len());
            for (d, s) in buf.iter_mut().zip(self.pending.drain(..n)) {
                *d = s;
            }
            Poll::Ready(Ok(n))
        })
        .await
    }

    async fn write_all(&mut self, data: &[u8]) -> Result<(), LinkError> {
        if self.pty.is_none() {
            return Err(LinkError::Disconnected);
        }
        let frame = if self.version == protocol::PROTOCOL_VERSION {
            data.to_vec()
        } else {
            let mut copy = data.to_vec();
            let msg = protocol::decode::<FromDevice>(&mut copy).unwrap();
            reframe(&msg, self.version)
        };
        let f = self.control.lock().unwrap().faults;
        let out = self.damage(&frame, f.drop_out, f.corrupt_out);
        let mut rest = &out[..];
        let deadline = Instant::now() + Duration::from_millis(500);
        poll_fn(|_| {
            let Some(pty) = self.pty.as_mut() else {
                return Poll::Ready(Err(LinkError::Disconnected));
            };
            while !rest.is_empty() {
                match pty.master.write(rest) {
                    Ok(n) => rest = &rest[n..],
                    Err(e) if e.kind() == ErrorKind::WouldBlock && Instant::now() < deadline => {
                        return Poll::Pending
                    }
                    // Nobody on the other side: the bytes are lost, as on a real wire.
                    Err(_) => return Poll::Ready(Err(LinkError::Disconnected)),
                }
            }
            Poll::Ready(Ok(()))
        })
        .await
    }
}

/// A port that is not a Tangent: a GPS-like device sending NMEA text.
pub struct NotATangent {
    path: PathBuf,
    stop: Arc<Mutex<bool>>,
    thread: Option<JoinHandle<()>>,
    _dir: tempfile::TempDir,
}

impl NotATangent {
    /// Starts it; [`NotATangent::path`] is where the host opens it.
    pub fn start() -> NotATangent {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ttyGPS");
        let mut pty = open_pty(&path);
        let stop = Arc::new(Mutex::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 256];
            while !*s.lock().unwrap() {
                // What the host sends is ignored.
                let _ = pty.master.read(&mut buf);
                let _ = pty.master.write_all(
                    b"$GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,*76\r\n",
                );
                std::thread::sleep(Duration::from_millis(50));
            }
        });
        NotATangent {
            path,
            stop,
            thread: Some(thread),
            _dir: dir,
        }
    }

    /// The path to open.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for NotATangent {
    fn drop(&mut self) {
        *self.stop.lock().unwrap() = true;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

pub struct Pty {
    master: File,
}

pub fn open_pty(link: &Path) -> Pty {
    let pty = nix::pty::openpty(None, None).expect("openpty");
    // openpty(3) does not set close-on-exec: without it a child process (the `tangent`
    // binary under test) would inherit the master, and closing ours would not hang up.
    for fd in [pty.master, pty.slave] {
        nix::fcntl::fcntl(
            fd,
            nix::fcntl::FcntlArg::F_SETFD(nix::fcntl::FdFlag::FD_CLOEXEC),
        )
        .expect("close-on-exec");
    }
    let mut t = nix::sys::termios::tcgetattr(pty.slave).expect("tcgetattr");
    nix::sys::termios::cfmakeraw(&mut t);
    nix::sys::termios::tcsetattr(pty.slave, nix::sys::termios::SetArg::TCSANOW, &t)
        .expect("tcsetattr");
    let name = std::fs::read_link(format!("/proc/self/fd/{}", pty.slave)).expect("pty name");
    nix::fcntl::fcntl(
        pty.master,
        nix::fcntl::FcntlArg::F_SETFL(nix::fcntl::OFlag::O_NONBLOCK),
    )
    .expect("non-blocking master");
    // Our copy of the slave is not needed: the host opens it by name.
    let _ = nix::unistd::close(pty.slave);
    // Replace the link atomically (new link, then rename over the old one).
    let tmp = link.with_extension("new");
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(&name, &tmp).expect("symlink");
    std::fs::rename(&tmp, link).expect("rename symlink");
    Pty {
        // SAFETY: `openpty` returned a fresh descriptor that nothing else owns.
        master: unsafe { File::from_raw_fd(pty.master) },
    }
}

/// What the test controls of a [`Relay`].
#[derive(Default)]
struct RelayControl {
    faults: Faults,
    cut_until: Option<Instant>,
    stop: bool,
}

/// A man in the middle between the host and a real serial peer (the emulated firmware's
/// pty): the host opens [`Relay::path`]; bytes are copied both ways with [`Faults`], and
/// [`Relay::cut`] unplugs the host side for a while, as [`TestDevice::cut`] does.
pub struct Relay {
    path: PathBuf,
    control: Arc<Mutex<RelayControl>>,
    thread: Option<JoinHandle<()>>,
    _dir: tempfile::TempDir,
}

impl Relay {
    /// Relays to the tty at `peer`.
    pub fn start(peer: &Path) -> Relay {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ttyRELAY");
        let control = Arc::new(Mutex::new(RelayControl::default()));
        let fd = nix::fcntl::open(
            peer,
            nix::fcntl::OFlag::O_RDWR
                | nix::fcntl::OFlag::O_NOCTTY
                | nix::fcntl::OFlag::O_NONBLOCK
                | nix::fcntl::OFlag::O_CLOEXEC,
            nix::sys::stat::Mode::empty(),
        )
        .expect("open the peer tty");
        let mut t = nix::sys::termios::tcgetattr(fd).expect("tcgetattr");
        nix::sys::termios::cfmakeraw(&mut t);
        nix::sys::termios::tcsetattr(fd, nix::sys::termios::SetArg::TCSANOW, &t).expect("raw");
        // SAFETY: a fresh descriptor owned by nothing else.
        let mut peer_file = unsafe { File::from_raw_fd(fd) };
        let mut pty = open_pty(&path);
        let c = control.clone();
        let p = path.clone();
        let thread = std::thread::spawn(move || {
            let mut rng = 0x9E37_79B9u32;
            let mut hit = |per_mille: u32| {
                rng ^= rng << 13;
                rng ^= rng >> 17;
                rng ^= rng << 5;
                per_mille > 0 && rng % 1000 < per_mille
            };
            let mut buf = [0u8; 1024];
            loop {
                let (stop, cut_until, f) = {
                    let mut c = c.lock().unwrap();
                    (c.stop, c.cut_until.take(), c.faults)
                };
                if stop {
                    return;
                }
                if let Some(until) = cut_until {
                    drop(pty);
                    let _ = std::fs::remove_file(&p);
                    while Instant::now() < until {
                        // The device keeps talking into the void.
                        let _ = peer_file.read(&mut buf);
                        std::thread::sleep(Duration::from_millis(1));
                    }
                    pty = open_pty(&p);
                }
                let mut idle = true;
                // Host → device.
                if let Ok(n) = pty.master.read(&mut buf) {
                    idle = n == 0;
                    let mut out = Vec::with_capacity(n);
                    for &b in &buf[..n] {
                        if hit(f.drop_in) {
                            continue;
                        }
                        out.push(if hit(f.corrupt_in) { b ^ 0x5A } else { b });
                    }
                    write_all_nb(&mut peer_file, &out);
                }
                // Device → host.
                if let Ok(n) = peer_file.read(&mut buf) {
                    idle &= n == 0;
                    let mut out = Vec::with_capacity(n);
                    for &b in &buf[..n] {
                        if hit(f.drop_out) {
                            continue;
                        }
                        out.push(if hit(f.corrupt_out) { b ^ 0x5A } else { b });
                    }
                    write_all_nb(&mut pty.master, &out);
                }
                if idle {
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        });
        Relay {
            path,
            control,
            thread: Some(thread),
            _dir: dir,
        }
    }

    /// The path the host opens.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Sets the faults.
    pub fn faults(&self, f: Faults) {
        self.control.lock().unwrap().faults = f;
    }

    /// Unplugs the host side for `d`.
    pub fn cut(&self, d: Duration) {
        self.control.lock().unwrap().cut_until = Some(Instant::now() + d);
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.control.lock().unwrap().stop = true;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Writes everything to a non-blocking descriptor (gives up after 500 ms or on a hang-up:
/// the bytes are lost as on a wire).
fn write_all_nb(f: &mut File, bytes: &[u8]) {
    let mut rest = bytes;
    let deadline = Instant::now() + Duration::from_millis(500);
    while !rest.is_empty() && Instant::now() < deadline {
        match f.write(rest) {
            Ok(n) => rest = &rest[n..],
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(1))
            }
            Err(_) => return,
        }
    }
}
