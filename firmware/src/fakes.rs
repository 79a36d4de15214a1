//! Test doubles of the ports on virtual time, for the firmware's unit tests: a clock whose
//! delays advance the time instead of waiting, lasers and a watchdog that log every switch
//! and feed with the time, a camera whose behaviour each test chooses, and a bounded poller
//! (a hung future must not hang the test).

use std::cell::{Cell, RefCell};
use std::future::Future;
use std::pin::pin;
use std::rc::Rc;
use std::task::{Context, Poll, Waker};

use tangent_core::calibration::Calibration;
use tangent_core::measurement::{Measurement, Mode, StemReading};
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::Method;
use tangent_core::protocol::{self, WireCalibration};
use tangent_core::real::{Real, Vec3};
use tangent_core::solvers::result::Flags;

use embedded_hal_async::i2c::{ErrorKind, ErrorType, I2c, Operation};

use crate::adxl355::model::Adxl355Model;
use crate::adxl355::Adxl355;
use crate::i2c_target::{Target, TargetBus};
use crate::measure::{FramePair, Measurer};
use crate::mode_log::{FlashWords, ModeLog, ERASED, WORD};
use crate::ports::{
    Board, CalibrationStore, Camera, CameraError, Clock, Geometry, Laser, Link, LinkError, Strobe,
    Trigger, Watchdog,
};

/// Virtual time (µs), shared by every fake of one test.
pub type Time = Rc<Cell<u64>>;

/// Polls `future` with a no-op waker until it is ready, at most `max_polls` times; `None`
/// when it is still pending (hung).
pub fn poll_bounded<F: Future>(future: F, max_polls: usize) -> Option<F::Output> {
    let mut future = pin!(future);
    let mut cx = Context::from_waker(Waker::noop());
    (0..max_polls).find_map(|_| match future.as_mut().poll(&mut cx) {
        Poll::Ready(v) => Some(v),
        Poll::Pending => None,
    })
}

/// Yields once (lets the other branch of a `select` run).
async fn yield_once() {
    let mut yielded = false;
    core::future::poll_fn(|cx| {
        if yielded {
            Poll::Ready(())
        } else {
            yielded = true;
            cx.waker().wake_by_ref();
            Poll::Pending
        }
    })
    .await
}

/// A clock on virtual time: a delay moves the time to its deadline (if it is not there yet)
/// and yields once.
#[derive(Clone, Default)]
pub struct FakeClock(pub Time);

impl Clock for FakeClock {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
    async fn delay_us(&self, us: u32) {
        let deadline = self.0.get() + us as u64;
        yield_once().await;
        self.0.set(self.0.get().max(deadline));
    }
}

/// Lasers that log every switch as (time, mask).
pub struct FakeLaser {
    pub time: Time,
    pub switches: Rc<RefCell<Vec<(u64, u8)>>>,
}

impl FakeLaser {
    pub fn new(time: &Time) -> Self {
        FakeLaser {
            time: time.clone(),
            switches: Rc::default(),
        }
    }
}

impl Laser for FakeLaser {
    /// The three-laser head: the parallel pair and the walls' crossing line.
    fn count(&self) -> u8 {
        3
    }
    fn set(&mut self, mask: u8) {
        self.switches.borrow_mut().push((self.time.get(), mask));
    }
}

/// The longest time any laser stayed lit in a switch log (µs), and the mask last set.
pub fn longest_lit_us(switches: &[(u64, u8)]) -> (u64, u8) {
    let mut longest = 0;
    let mut lit_since = None;
    for &(t, mask) in switches {
        match (lit_since, mask) {
            (None, m) if m != 0 => lit_since = Some(t),
            (Some(t0), 0) => {
                longest = u64::max(longest, t - t0);
                lit_since = None;
            }
            _ => {}
        }
    }
    (longest, switches.last().map_or(0, |s| s.1))
}

/// What the fake camera does in `capture`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraBehaviour {
    /// Lights the strobe for the exposure, switches it off and delivers the frame.
    Works,
    /// Works for a dark exposure; lights the strobe of a lit one and never finishes it.
    HangsLit,
    /// Never delivers a frame and lights nothing (a dead sensor).
    HangsDark,
    /// Works for a dark exposure; lights the strobe of a lit one, then fails half-way
    /// through it (without `off()`).
    FailsMidExposure,
}

pub struct FakeCamera {
    pub clock: FakeClock,
    pub behaviour: CameraBehaviour,
}

/// The fake camera's frames (small: the tests are about time, not pixels).
pub const GEOMETRY: Geometry = Geometry {
    width: 8,
    height: 4,
    row_offset: 0,
};

impl Camera for FakeCamera {
    fn geometry(&self) -> Geometry {
        GEOMETRY
    }
    async fn capture<L: Laser, C: Clock>(
        &mut self,
        exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        buf: &mut [u8],
    ) -> Result<(), CameraError> {
        let dark = strobe.mask() == 0;
        match self.behaviour {
            CameraBehaviour::HangsLit if !dark => {
                strobe.on();
                core::future::pending().await
            }
            CameraBehaviour::FailsMidExposure if !dark => {
                strobe.on();
                self.clock.delay_us(exposure_us / 2).await;
                Err(CameraError::Transfer)
            }
            CameraBehaviour::HangsDark => core::future::pending().await,
            _ => {
                strobe.on();
                self.clock.delay_us(exposure_us).await;
                strobe.off();
                buf.fill(if dark { 10 } else { 200 });
                Ok(())
            }
        }
    }
}

/// No trigger press ever.
pub struct NoTrigger;

impl Trigger for NoTrigger {
    fn is_pressed(&mut self) -> bool {
        false
    }
    async fn wait_pressed(&mut self) {
        core::future::pending().await
    }
}

/// A link on which the host sends nothing; counts the frames written, and hangs in
/// `write_all` when `writes_hang`.
#[derive(Default)]
pub struct QuietLink {
    pub writes: Rc<Cell<usize>>,
    pub writes_hang: bool,
}

impl Link for QuietLink {
    async fn read(&mut self, _buf: &mut [u8]) -> Result<usize, LinkError> {
        core::future::pending().await
    }
    async fn write_all(&mut self, _data: &[u8]) -> Result<(), LinkError> {
        if self.writes_hang {
            core::future::pending::<()>().await;
        }
        self.writes.set(self.writes.get() + 1);
        Ok(())
    }
}

/// A store holding the reference design's calibration (so measurements capture frames).
pub struct RefStore;

impl CalibrationStore for RefStore {
    fn load(&mut self) -> Option<WireCalibration> {
        Some(WireCalibration::from(&Calibration::reference_design()))
    }
    fn save(&mut self, _calibration: &WireCalibration) -> Result<(), u32> {
        Ok(())
    }
}

/// A watchdog that logs the time of every feed.
pub struct FakeWatchdog {
    pub time: Time,
    pub feeds: Rc<RefCell<Vec<u64>>>,
}

impl Watchdog for FakeWatchdog {
    fn feed(&mut self) {
        self.feeds.borrow_mut().push(self.time.get());
    }
}

/// A measurer that always fails (the reading is not what these tests are about).
pub struct FailingMeasurer;

impl Measurer for FailingMeasurer {
    fn measure(
        &mut self,
        _: Mode,
        _: &FramePair<'_>,
        _: &Calibration,
    ) -> Result<Measurement, Failure> {
        Err(Failure::Frame)
    }
}

/// Gravity (down, 1σ) a measurer is given for one measurement ([`Measurer::set_vertical`]).
pub type Gravity = Option<(Vec3, Real)>;

/// The gravity a measurer was given for each measurement.
pub type Verticals = Rc<RefCell<Vec<Gravity>>>;

/// A measurer that records the vertical it is given and reads a fixed stem (the app's
/// handling of the accelerometer is what these tests are about, not the pipeline).
pub struct VerticalMeasurer(pub Verticals);

impl Measurer for VerticalMeasurer {
    fn measure(
        &mut self,
        _: Mode,
        _: &FramePair<'_>,
        _: &Calibration,
    ) -> Result<Measurement, Failure> {
        Ok(Measurement::Stem(StemReading {
            diameter: 0.3,
            uncertainty: 0.001,
            method: Method::CircleFit,
            distance: 1.0,
            tilt: None,
            axes: None,
            flags: Flags::default(),
            exposures: 1,
        }))
    }
    fn set_vertical(&mut self, gravity: Option<(Vec3, Real)>) {
        self.0.borrow_mut().push(gravity);
    }
}

/// A flash sector in RAM, shared (`Rc`) so a test can build the application again on the
/// same contents — a power cycle — and with the faults of real flash on demand.
#[derive(Clone)]
pub struct RamSector(pub Rc<RefCell<SectorState>>);

/// The contents of a [`RamSector`] and the faults it will inject.
pub struct SectorState {
    /// The words.
    pub words: Vec<[u8; WORD]>,
    /// Erases done.
    pub erases: usize,
    /// Programs done (whole or torn).
    pub programs: usize,
    /// The next program writes only this many bytes and fails: a power cut mid-program.
    pub tear_next_program: Option<usize>,
    /// Every program fails before touching the word (a locked or worn-out sector).
    pub refuse_programs: bool,
    /// Reading this word fails (an ECC error the hardware reports).
    pub unreadable: Option<usize>,
    /// Programming a word that is not erased (a bug the log must never have).
    pub programmed_twice: bool,
}

impl RamSector {
    /// An erased sector of `words` words.
    pub fn new(words: usize) -> Self {
        RamSector(Rc::new(RefCell::new(SectorState {
            words: vec![[ERASED; WORD]; words],
            erases: 0,
            programs: 0,
            tear_next_program: None,
            refuse_programs: false,
            unreadable: None,
            programmed_twice: false,
        })))
    }
}

impl FlashWords for RamSector {
    fn words(&self) -> usize {
        self.0.borrow().words.len()
    }
    fn read(&mut self, index: usize, word: &mut [u8; WORD]) -> Result<(), u32> {
        let s = self.0.borrow();
        if s.unreadable == Some(index) {
            return Err(7);
        }
        *word = *s.words.get(index).ok_or(1u32)?;
        Ok(())
    }
    fn program(&mut self, index: usize, word: &[u8; WORD]) -> Result<(), u32> {
        let mut s = self.0.borrow_mut();
        if s.refuse_programs {
            return Err(4);
        }
        let tear = s.tear_next_program.take();
        s.programs += 1;
        let was_erased = s.words.get(index).ok_or(1u32)?.iter().all(|&b| b == ERASED);
        s.programmed_twice |= !was_erased;
        let n = tear.unwrap_or(WORD).min(WORD);
        let dst = s.words.get_mut(index).ok_or(1u32)?;
        dst[..n].copy_from_slice(&word[..n]);
        if tear.is_some() {
            return Err(9);
        }
        Ok(())
    }
    fn erase(&mut self) -> Result<(), u32> {
        let mut s = self.0.borrow_mut();
        s.erases += 1;
        for w in s.words.iter_mut() {
            *w = [ERASED; WORD];
        }
        Ok(())
    }
}

pub struct FakeBoard;

impl Board for FakeBoard {
    type Camera = FakeCamera;
    type Laser = FakeLaser;
    type Trigger = NoTrigger;
    type Link = QuietLink;
    type Clock = FakeClock;
    type Store = RefStore;
    type ModeStore = ModeLog<RamSector>;
    type Watchdog = FakeWatchdog;
    type Accelerometer = Adxl355<TargetBus<Adxl355Model>>;
    const KIND: protocol::Board = protocol::Board::Emulated;
    fn log(_args: core::fmt::Arguments<'_>) {}
}

/// One I²C transaction as the target saw it: the bytes written (register pointer first) and
/// how many were read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Transfer {
    /// Bytes written.
    pub write: Vec<u8>,
    /// Bytes read.
    pub read: usize,
}

/// An I²C bus of one emulated target ([`Target`]) that records every transaction and fails
/// every one after the first `fail_after` (a bus error): the drivers' set-up tests.
pub struct RecordingBus<T> {
    /// The bus and its target.
    pub bus: TargetBus<T>,
    /// The transactions so far.
    pub transfers: Vec<Transfer>,
    /// Transactions that succeed before the bus fails.
    pub fail_after: usize,
}

impl<T> RecordingBus<T> {
    /// A working bus with `target` on it.
    pub fn new(target: T) -> Self {
        RecordingBus {
            bus: TargetBus::new(Some(target)),
            transfers: Vec::new(),
            fail_after: usize::MAX,
        }
    }

    /// The target.
    pub fn target(&mut self) -> &mut T {
        self.bus.target.as_mut().expect("the bus has its target")
    }
}

impl<T> ErrorType for RecordingBus<T> {
    type Error = ErrorKind;
}

impl<T: Target> I2c for RecordingBus<T> {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), ErrorKind> {
        if self.transfers.len() >= self.fail_after {
            return Err(ErrorKind::Bus);
        }
        let mut transfer = Transfer {
            write: Vec::new(),
            read: 0,
        };
        for op in operations.iter() {
            match op {
                Operation::Write(bytes) => transfer.write.extend_from_slice(bytes),
                Operation::Read(buf) => transfer.read += buf.len(),
            }
        }
        self.transfers.push(transfer);
        self.bus.transaction(address, operations).await
    }
}
