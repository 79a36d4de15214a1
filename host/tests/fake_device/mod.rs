//! An in-process fake Tangent on a pseudo-terminal, with fault injection.
//!
//! The host opens it by path (a symlink to the pty's slave side, like udev's
//! `/dev/serial/by-id/...` links), exactly as it opens a real device. The fake speaks the
//! real protocol (`tangent_core::protocol`) and answers `DeviceInfo`, `Measure`, streams,
//! `History`, calibration, `CaptureFrames`/`ReadFrameChunk`; it "presses the trigger" on
//! command, keeps the last 64 readings like the firmware, and can:
//!
//! * drop and corrupt bytes in both directions (deterministic xorshift, per-mille rates);
//! * cut the link: close the pty (the host sees a hang-up) and remove the path, then,
//!   after a while, come back on a new pty behind the same path — readings made meanwhile
//!   are lost on the wire but stay in the history;
//! * speak another protocol version, or only line noise (not a Tangent at all);
//! * reboot (sequence numbers restart at 1).
//!
//! Reading `seq` has diameter `0.1 m + seq · 1 mm` so a test can check each reading's content.

#![allow(dead_code)]

use std::collections::VecDeque;
use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::FromRawFd;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tangent_core::measurement::{Measurement, StemReading, TiltAngles};
use tangent_core::protocol::{
    self, codes, Board, DeviceInfo, FrameEncoder, FrameSel, FrameSetInfo, FromDevice, LinkStats,
    Method, Reading, Request, Response, RunningStats, ToDevice, WireCalibration, FRAME_CHUNK_MAX,
    UNSOLICITED,
};

/// Readings kept for `History` (as the firmware).
pub const HISTORY: usize = codes::HISTORY_LEN;

/// The diameter the fake reports for reading `seq` (metres, as sent in `f32`).
pub fn diameter_of(seq: u32) -> f32 {
    0.1 + seq as f32 * 0.001
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

/// How the fake behaves on the wire.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Persona {
    /// A Tangent of this protocol version.
    Tangent,
    /// A Tangent whose frames carry another version byte (and which answers ours with
    /// `UnsupportedVersion`, as the firmware does).
    OtherVersion(u8),
    /// Not a Tangent: a GPS-like device sending NMEA text.
    Noise,
}

#[derive(Default)]
struct Control {
    presses: u32,
    press_interval: Duration,
    faults: Faults,
    cut_until: Option<Instant>,
    reboot: bool,
    stop: bool,
    issued: u32,
    frames_ok: u32,
    malformed: u32,
}

/// A running fake device.
pub struct FakeDevice {
    path: PathBuf,
    control: Arc<Mutex<Control>>,
    thread: Option<JoinHandle<()>>,
    _dir: tempfile::TempDir,
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

impl FakeDevice {
    /// Starts a fake device; `path()` is where the host opens it.
    pub fn start(persona: Persona) -> FakeDevice {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ttyTANGENT");
        let control = Arc::new(Mutex::new(Control {
            press_interval: Duration::from_millis(20),
            ..Control::default()
        }));
        let pty = open_pty(&path);
        let c = control.clone();
        let p = path.clone();
        let thread = std::thread::spawn(move || Device::new(persona, p, c).run(pty));
        FakeDevice {
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

    /// Reboots the device (sequence numbers restart, history emptied).
    pub fn reboot(&self) {
        self.control.lock().unwrap().reboot = true;
    }

    /// Readings issued so far (the last sequence number).
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
                "the fake device did not finish its presses"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// (frames accepted, frames rejected) by the device.
    pub fn rx_stats(&self) -> (u32, u32) {
        let c = self.control.lock().unwrap();
        (c.frames_ok, c.malformed)
    }
}

impl Drop for FakeDevice {
    fn drop(&mut self) {
        self.control.lock().unwrap().stop = true;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Device {
    persona: Persona,
    path: PathBuf,
    control: Arc<Mutex<Control>>,
    rng: u32,
    rx: Vec<u8>,
    enc: FrameEncoder,
    seq: u32,
    history: VecDeque<Reading>,
    stream: Option<(u16, u32)>,
    calibration: Option<WireCalibration>,
    boot: Instant,
    next_press: Instant,
    capture: u32,
    frames: Option<(Vec<u8>, Vec<u8>)>,
    stats: LinkStats,
}

/// The frames the fake "captures": a deterministic pattern per capture number.
pub fn fake_frame(capture: u32, sel: FrameSel, w: usize, h: usize) -> Vec<u8> {
    let mut x = 0x1234_5678u32 ^ capture.wrapping_mul(0x9E37_79B9) ^ (sel == FrameSel::On) as u32;
    (0..w * h)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u8
        })
        .collect()
}

/// Frame size of the fake camera (small, so dumps are quick).
pub const FAKE_W: u16 = 64;
/// Frame height of the fake camera.
pub const FAKE_H: u16 = 24;

impl Device {
    fn new(persona: Persona, path: PathBuf, control: Arc<Mutex<Control>>) -> Device {
        Device {
            persona,
            path,
            control,
            rng: 0x2545_F491,
            rx: Vec::new(),
            enc: FrameEncoder::new(),
            seq: 0,
            history: VecDeque::new(),
            stream: None,
            calibration: None,
            boot: Instant::now(),
            next_press: Instant::now(),
            capture: 0,
            frames: None,
            stats: LinkStats::default(),
        }
    }

    fn rand(&mut self) -> u32 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 17;
        self.rng ^= self.rng << 5;
        self.rng
    }

    fn hit(&mut self, per_mille: u32) -> bool {
        per_mille > 0 && self.rand() % 1000 < per_mille
    }

    fn run(mut self, mut pty: Pty) {
        let mut noise_at = Instant::now();
        loop {
            let (stop, cut_until, reboot) = {
                let mut c = self.control.lock().unwrap();
                (c.stop, c.cut_until.take(), std::mem::take(&mut c.reboot))
            };
            if stop {
                return;
            }
            if reboot {
                self.seq = 0;
                self.history.clear();
                self.stream = None;
                self.boot = Instant::now();
                self.control.lock().unwrap().issued = 0;
                let banner = self.info_response();
                self.send_msg(&mut pty, UNSOLICITED, &banner);
            }
            if let Some(until) = cut_until {
                // Cable out: the host's port hangs up, the path disappears; the device
                // keeps measuring (into its history).
                drop(pty);
                let _ = std::fs::remove_file(&self.path);
                while Instant::now() < until {
                    self.trigger(None);
                    std::thread::sleep(Duration::from_millis(1));
                }
                pty = open_pty(&self.path);
                self.rx.clear();
                self.stream = None;
                continue;
            }
            if self.persona == Persona::Noise && noise_at.elapsed() > Duration::from_millis(50) {
                noise_at = Instant::now();
                let _ = pty.master.write_all(
                    b"$GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,*76\r\n",
                );
            }
            let mut buf = [0u8; 256];
            match pty.master.read(&mut buf) {
                Ok(n) if n > 0 => {
                    let mut bytes = Vec::with_capacity(n);
                    let f = self.control.lock().unwrap().faults;
                    for &b in &buf[..n] {
                        if self.hit(f.drop_in) {
                            continue;
                        }
                        let b = if self.hit(f.corrupt_in) {
                            b ^ (1 + (self.rand() % 255) as u8)
                        } else {
                            b
                        };
                        bytes.push(b);
                    }
                    self.on_bytes(&mut pty, &bytes);
                }
                _ => std::thread::sleep(Duration::from_millis(1)),
            }
            self.trigger(Some(&mut pty));
        }
    }

    /// Makes a trigger press (or a stream reading) when one is due.
    fn trigger(&mut self, pty: Option<&mut Pty>) {
        if let Some((tag, count)) = self.stream {
            if pty.is_some() && Instant::now() >= self.next_press {
                let interval = self.control.lock().unwrap().press_interval;
                self.next_press = Instant::now() + interval;
                let stats = RunningStats {
                    count: count + 1,
                    mean_m: 0.2,
                    spread_m: 0.0,
                };
                self.stream = Some((tag, count + 1));
                let r = self.new_reading(Some(stats));
                if let Some(p) = pty {
                    self.send_msg(p, tag, &Response::Reading(r));
                }
                return;
            }
        }
        let due = {
            let c = self.control.lock().unwrap();
            c.presses > 0 && Instant::now() >= self.next_press
        };
        if due {
            let interval = {
                let mut c = self.control.lock().unwrap();
                c.presses -= 1;
                c.press_interval
            };
            self.next_press = Instant::now() + interval;
            let r = self.new_reading(None);
            if let Some(p) = pty {
                self.send_msg(p, UNSOLICITED, &Response::Reading(r));
            }
        }
    }

    fn new_reading(&mut self, stats: Option<RunningStats>) -> Reading {
        self.seq += 1;
        let r = Reading {
            seq: self.seq,
            timestamp_ms: self.boot.elapsed().as_millis() as u64,
            calib_id: self.calibration.as_ref().map(|c| c.id).unwrap_or(77),
            exposure_us: 900,
            measurement: Measurement::Stem(StemReading {
                diameter: diameter_of(self.seq).into(),
                uncertainty: 0.0015f32.into(),
                method: Method::CircleFit,
                distance: 1.2f32.into(),
                tilt: Some(TiltAngles {
                    total: 0.05f32.into(),
                    theta: 0.0,
                    phi: 0.05f32.into(),
                }),
                axes: None,
                flags: tangent_core::solvers::result::Flags::TILT_IGNORED,
            }),
            stats,
        };
        if self.history.len() == HISTORY {
            self.history.pop_front();
        }
        self.history.push_back(r);
        self.control.lock().unwrap().issued = self.seq;
        r
    }

    fn send_msg(&mut self, pty: &mut Pty, tag: u16, response: &Response<'_>) {
        let msg = FromDevice {
            tag,
            response: response.clone(),
        };
        let mut frame = self.enc.encode(&msg).unwrap().to_vec();
        if let Persona::OtherVersion(v) = self.persona {
            let mut scratch = [0u8; protocol::MAX_RAW_LEN];
            let raw = protocol::encode_raw(&msg, v, &mut scratch).unwrap();
            let mut out = [0u8; protocol::MAX_FRAME_LEN];
            let n = protocol::cobs_frame(raw, &mut out).unwrap();
            frame = out[..n].to_vec();
        }
        self.write_faulty(pty, &frame);
    }

    fn write_faulty(&mut self, pty: &mut Pty, frame: &[u8]) {
        let f = self.control.lock().unwrap().faults;
        let mut out = Vec::with_capacity(frame.len());
        for &b in frame {
            if self.hit(f.drop_out) {
                continue;
            }
            out.push(if self.hit(f.corrupt_out) {
                b ^ (1 + (self.rand() % 255) as u8)
            } else {
                b
            });
        }
        let mut rest = &out[..];
        let deadline = Instant::now() + Duration::from_millis(500);
        while !rest.is_empty() && Instant::now() < deadline {
            match pty.master.write(rest) {
                Ok(n) => rest = &rest[n..],
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    std::thread::sleep(Duration::from_millis(1))
                }
                // Nobody on the other side: the bytes are lost, as on a real wire.
                Err(_) => return,
            }
        }
    }

    fn on_bytes(&mut self, pty: &mut Pty, bytes: &[u8]) {
        for &b in bytes {
            if b != 0 {
                if self.rx.len() < 4096 {
                    self.rx.push(b);
                }
                continue;
            }
            let mut frame = std::mem::take(&mut self.rx);
            if frame.is_empty() {
                continue;
            }
            match protocol::decode::<ToDevice>(&mut frame) {
                Ok(msg) => {
                    self.stats.frames_ok += 1;
                    self.control.lock().unwrap().frames_ok += 1;
                    if matches!(self.persona, Persona::OtherVersion(_)) {
                        // It could not have read our frame: answer as the firmware does.
                        let e = protocol::DeviceError {
                            code: protocol::ErrorCode::UnsupportedVersion,
                            detail: protocol::PROTOCOL_VERSION as u32,
                        };
                        self.send_msg(pty, UNSOLICITED, &Response::Error(e));
                        continue;
                    }
                    if self.persona == Persona::Tangent {
                        self.handle(pty, msg.tag, msg.request);
                    }
                }
                Err(_) => {
                    self.stats.malformed += 1;
                    self.control.lock().unwrap().malformed += 1;
                }
            }
        }
    }

    fn info_response(&self) -> Response<'static> {
        Response::Info(DeviceInfo {
            protocol_version: protocol::PROTOCOL_VERSION,
            fw_version: "fake-1.0",
            board: Board::Emulated,
            calib_id: self.calibration.as_ref().map(|c| c.id),
            frame_width: FAKE_W,
            frame_height: FAKE_H,
            uptime_ms: self.boot.elapsed().as_millis() as u64,
            last_seq: self.seq,
            link: self.stats,
        })
    }

    fn handle(&mut self, pty: &mut Pty, tag: u16, request: Request) {
        match request {
            Request::DeviceInfo => {
                let r = self.info_response();
                self.send_msg(pty, tag, &r)
            }
            Request::Measure => {
                let r = self.new_reading(None);
                self.send_msg(pty, tag, &Response::Reading(r));
            }
            Request::StartStream => {
                self.stream = Some((tag, 0));
                self.send_msg(pty, tag, &Response::Ack);
            }
            Request::StopStream => {
                self.stream = None;
                self.send_msg(pty, tag, &Response::Ack);
            }
            Request::History { after_seq } => {
                let replay: Vec<Reading> = self
                    .history
                    .iter()
                    .filter(|r| r.seq > after_seq)
                    .copied()
                    .collect();
                for r in replay {
                    self.send_msg(pty, tag, &Response::Reading(r));
                }
                let last_seq = self.seq;
                self.send_msg(pty, tag, &Response::HistoryEnd { last_seq });
            }
            Request::ReadCalibration => {
                let r = match &self.calibration {
                    Some(c) => Response::Calibration(c.clone()),
                    None => Response::Error(protocol::DeviceError {
                        code: protocol::ErrorCode::NoCalibration,
                        detail: 0,
                    }),
                };
                self.send_msg(pty, tag, &r);
            }
            Request::WriteCalibration(c) => {
                self.calibration = Some(c);
                self.send_msg(pty, tag, &Response::Ack);
            }
            Request::CaptureFrames => {
                self.capture += 1;
                let (w, h) = (FAKE_W as usize, FAKE_H as usize);
                self.frames = Some((
                    fake_frame(self.capture, FrameSel::Off, w, h),
                    fake_frame(self.capture, FrameSel::On, w, h),
                ));
                let info = FrameSetInfo {
                    capture: self.capture,
                    width: FAKE_W,
                    height: FAKE_H,
                    row_offset: 0,
                    bit_depth: 8,
                    exposure_us: 900,
                    timestamp_ms: self.boot.elapsed().as_millis() as u64,
                    laser_mask: 1,
                    calib_id: self.calibration.as_ref().map(|c| c.id),
                };
                self.send_msg(pty, tag, &Response::FramesReady(info));
            }
            Request::ReadFrameChunk {
                capture,
                frame,
                offset,
                max_len,
            } => {
                let Some((off, on)) = &self.frames else {
                    return;
                };
                let data = if frame == FrameSel::Off { off } else { on };
                let start = (offset as usize).min(data.len());
                let end = (start + (max_len as usize).min(FRAME_CHUNK_MAX)).min(data.len());
                let chunk = data[start..end].to_vec();
                let total = data.len() as u32;
                let r = Response::FrameChunk {
                    capture,
                    frame,
                    offset,
                    total,
                    data: &chunk,
                };
                self.send_msg(pty, tag, &r);
            }
            Request::SetExposure(_) => self.send_msg(pty, tag, &Response::Ack),
            Request::SelfTest => self.send_msg(
                pty,
                tag,
                &Response::SelfTest(protocol::SelfTestReport {
                    failed: 0,
                    ran: 0xF,
                }),
            ),
        }
    }
}

/// A man in the middle between the host and a real serial peer (the emulated firmware's
/// pty): the host opens [`Relay::path`]; bytes are copied both ways with [`Faults`], and
/// [`Relay::cut`] unplugs the host side for a while, as [`FakeDevice::cut`] does.
pub struct Relay {
    path: PathBuf,
    control: Arc<Mutex<Control>>,
    thread: Option<JoinHandle<()>>,
    _dir: tempfile::TempDir,
}

impl Relay {
    /// Relays to the tty at `peer`.
    pub fn start(peer: &Path) -> Relay {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ttyRELAY");
        let control = Arc::new(Mutex::new(Control::default()));
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
