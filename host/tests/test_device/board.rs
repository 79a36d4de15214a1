//! The test board: the firmware's ports over a pty, `Instant`s and shared test state.

use std::future::{poll_fn, Future};
use std::io::{ErrorKind, Read, Write};
use std::path::PathBuf;
use std::pin::pin;
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

use tangent_core::calibration::Calibration;
use tangent_core::measurement::{Measurement, Mode, StemReading, TiltAngles};
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::{
    self, FrameSel, FromDevice, Method, ToDevice, WireCalibration, MAX_FRAME_LEN, MAX_RAW_LEN,
};
use tangent_core::solvers::result::Flags;
use tangent_firmware::adxl355::model::Adxl355Model;
use tangent_firmware::adxl355::Adxl355;
use tangent_firmware::i2c_target::TargetBus;
use tangent_firmware::measure::{FramePair, Measurer};
use tangent_firmware::mode_log::{FlashWords, ModeLog, ERASED, WORD};
use tangent_firmware::ports::{
    Board, CalibrationStore, Camera, CameraError, Clock, Geometry, Laser, Link, LinkError, Strobe,
    Trigger, Watchdog,
};

use super::pty::{open_pty, Pty};
use super::{diameter_of, test_frame, Shared, FRAME, FRAME_TIME};

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

pub(super) struct TestBoard;

impl Board for TestBoard {
    type Camera = TestCamera;
    type Laser = RecordingLaser;
    type Trigger = TestTrigger;
    type Link = PtyLink;
    type Clock = TestClock;
    type Store = RamStore;
    type ModeStore = ModeLog<RamWords>;
    type Watchdog = NoWatchdog;
    /// No accelerometer fitted (the stem tests' device): the ADXL355 driver on an empty bus.
    type Accelerometer = Adxl355<TargetBus<Adxl355Model>>;
    const KIND: protocol::Board = protocol::Board::Emulated;
    /// The firmware's log, on stderr when `TANGENT_TEST_DEVICE_LOG` is set (the tests
    /// check what goes over the link).
    fn log(args: std::fmt::Arguments<'_>) {
        if std::env::var_os("TANGENT_TEST_DEVICE_LOG").is_some() {
            eprintln!("device: {args}");
        }
    }
}

pub(super) struct TestClock(pub(super) Instant);

impl Clock for TestClock {
    fn now_us(&self) -> u64 {
        self.0.elapsed().as_micros() as u64
    }
    async fn delay_us(&self, us: u32) {
        until(Instant::now() + Duration::from_micros(us as u64)).await
    }
}

pub(super) struct TestCamera {
    /// Laser-on frames delivered (the firmware's capture number after a pair).
    pub(super) captures: u32,
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

pub(super) struct RecordingLaser(pub(super) Shared);

impl Laser for RecordingLaser {
    fn count(&self) -> u8 {
        2
    }
    fn set(&mut self, mask: u8) {
        self.0.lock().unwrap().laser_switches.push(mask);
    }
}

pub(super) struct TestTrigger(pub(super) Shared);

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

pub(super) struct RamStore(pub(super) Option<WireCalibration>);

impl CalibrationStore for RamStore {
    fn load(&mut self) -> Option<WireCalibration> {
        self.0.clone()
    }
    fn save(&mut self, calibration: &WireCalibration) -> Result<(), u32> {
        self.0 = Some(calibration.clone());
        Ok(())
    }
}

/// The mode log's sector in RAM (kept across the test device's reboots, as flash is).
pub(super) struct RamWords(Vec<[u8; WORD]>);

impl RamWords {
    /// An erased sector of 64 words (the emulated board's size).
    pub(super) fn new() -> Self {
        RamWords(vec![[ERASED; WORD]; 64])
    }
}

impl FlashWords for RamWords {
    fn words(&self) -> usize {
        self.0.len()
    }
    fn read(&mut self, index: usize, word: &mut [u8; WORD]) -> Result<(), u32> {
        *word = *self.0.get(index).ok_or(1u32)?;
        Ok(())
    }
    fn program(&mut self, index: usize, word: &[u8; WORD]) -> Result<(), u32> {
        *self.0.get_mut(index).ok_or(1u32)? = *word;
        Ok(())
    }
    fn erase(&mut self) -> Result<(), u32> {
        self.0.fill([ERASED; WORD]);
        Ok(())
    }
}

pub(super) struct NoWatchdog;

impl Watchdog for NoWatchdog {
    fn feed(&mut self) {}
}

/// Reading `n` after a boot has diameter [`diameter_of`]`(n)`; the firmware numbers its
/// readings the same way (every measurement here succeeds).
pub(super) struct TestMeasurer {
    pub(super) control: Shared,
    pub(super) made: u32,
}

impl Measurer for TestMeasurer {
    fn measure(
        &mut self,
        _: Mode,
        pair: &FramePair<'_>,
        _: &Calibration,
    ) -> Result<Measurement, Failure> {
        assert_eq!(
            (pair.width, pair.height, pair.row_offset),
            (
                FRAME.width as usize,
                FRAME.height as usize,
                FRAME.row_offset as usize
            )
        );
        Ok(Measurement::Stem(StemReading {
            diameter: diameter_of(self.made).into(),
            uncertainty: 0.0015f32.into(),
            method: Method::CircleFit,
            distance: 1.2f32.into(),
            tilt: Some(TiltAngles {
                total: 0.05f32.into(),
                theta: 0.0,
                phi: 0.05f32.into(),
            }),
            axes: None,
            flags: Flags::TILT_IGNORED,
            exposures: 1,
        }))
    }

    /// A reading begins (the firmware's default several frame pairs follow; it reports
    /// the first, since this measurer does not combine them): the next number.
    fn begin_exposures(&mut self) {
        self.made += 1;
        self.control.lock().unwrap().issued = self.made;
    }
}

/// The pty as the firmware's host link: a USB CDC-ACM port seen from the device.
pub(super) struct PtyLink {
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
    /// A link on a new pty behind `path`, speaking protocol `version`.
    pub(super) fn new(path: PathBuf, control: Shared, version: u8) -> PtyLink {
        PtyLink {
            pty: Some(open_pty(&path)),
            path,
            control,
            down_until: None,
            rng: 0x2545_F491,
            version,
            incoming: Vec::new(),
            pending: Vec::new(),
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
    fn queue_host_bytes(&mut self, bytes: &[u8]) {
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
            let (cut, plugged) = {
                let mut c = self.control.lock().unwrap();
                (c.cut_until.take(), std::mem::take(&mut c.plug))
            };
            if let Some(until) = cut {
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
                if Instant::now() < until && !plugged {
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
                self.queue_host_bytes(&damaged);
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
