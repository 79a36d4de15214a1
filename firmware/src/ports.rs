//! The application's ports: one small trait per device the application uses (camera,
//! lasers, trigger, host link, clock, calibration store, mode store, watchdog, accelerometer) and [`Board`] that
//! bundles them. Not a HAL: they say what the application needs, not what the chip offers.
//!
//! Each board (`board::h743`, `board::qemu`, and the host tests' test board) implements
//! them; the application ([`crate::app`]) knows nothing else about the hardware. Async methods run on whatever
//! executor the board uses (embassy on the H743, a busy-polling `block_on` on QEMU), so the
//! futures need not be `Send`.
#![allow(async_fn_in_trait)]

use core::cell::{Cell, RefCell};

use tangent_core::measurement::Mode;
use tangent_core::protocol::{self, ModeStoreState, WireCalibration};

/// Monotonic time since boot.
pub trait Clock {
    /// Microseconds since boot.
    fn now_us(&self) -> u64;
    /// Milliseconds since boot.
    fn now_ms(&self) -> u64 {
        self.now_us() / 1000
    }
    /// Waits at least `us` microseconds.
    async fn delay_us(&self, us: u32);
}

/// The line lasers. Bit `i` of a mask is laser (and calibration plane) `i`.
pub trait Laser {
    /// How many lasers the board drives.
    fn count(&self) -> u8;
    /// Switches the lasers of `mask` on and every other laser off (`0` = all off). Must
    /// take effect before it returns.
    fn set(&mut self, mask: u8);
}

/// The trigger push-button (debounced by the board).
pub trait Trigger {
    /// True while the trigger is held.
    fn is_pressed(&mut self) -> bool;
    /// Completes on the next (debounced) press. Boards without a trigger never complete.
    async fn wait_pressed(&mut self);
}

/// Why a link operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkError {
    /// The host is not connected (USB cable out, port closed).
    Disconnected,
}

/// The byte stream to the host (USB CDC-ACM or a UART).
pub trait Link {
    /// Waits for at least one byte and returns how many were written into `buf`.
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, LinkError>;
    /// Writes every byte of `data`.
    async fn write_all(&mut self, data: &[u8]) -> Result<(), LinkError>;
}

/// Position of the camera's frames on the sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Geometry {
    /// Frame width (pixels).
    pub width: u16,
    /// Frame height (pixels).
    pub height: u16,
    /// Sensor row of the frame's first row (windowed read-out; 0 for a full frame).
    pub row_offset: u16,
}

impl Geometry {
    /// Bytes of one 8-bit frame.
    pub fn frame_len(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// Why a capture failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraError {
    /// The sensor did not deliver the frame in time.
    Timeout,
    /// The frame arrived corrupted (DMA overrun, DCMI error).
    Transfer,
    /// Sensor configuration over I²C failed.
    Bus,
    /// The frame source is unusable (emulated board: missing or malformed capture file).
    Source,
    /// The buffer does not match the frame size.
    BufferSize,
    /// The board has no memory for a stored frame pair (it streams the laser-on frame through
    /// the measurement): raw captures cannot be served.
    NoFrameStore,
}

impl CameraError {
    /// Detail code sent with [`protocol::ErrorCode::CameraFailure`].
    pub fn code(self) -> u32 {
        match self {
            CameraError::Timeout => 1,
            CameraError::Transfer => 2,
            CameraError::Bus => 3,
            CameraError::Source => 4,
            CameraError::BufferSize => 5,
            CameraError::NoFrameStore => tangent_core::protocol::codes::CAMERA_NO_FRAME_STORE,
        }
    }
}

/// Rows per block in which a camera hands a frame over ([`Camera::capture_rows`]): the
/// pipeline's ([`tangent_core::pipeline::BLOCK_ROWS`]).
pub const BLOCK_ROWS: usize = tangent_core::pipeline::BLOCK_ROWS;

/// Receives a frame's rows as the camera reads them out: whole rows of the geometry's
/// width, in order, in blocks ([`BLOCK_ROWS`] rows but the last).
pub trait RowSink {
    /// The next rows.
    fn rows(&mut self, rows: &[u8]);
}

/// The camera: exposes and reads 8-bit frames of a fixed [`Geometry`].
pub trait Camera {
    /// Size and position of the frames.
    fn geometry(&self) -> Geometry;
    /// Exposes one frame for `exposure_us` and reads it into `buf`
    /// (`geometry().frame_len()` bytes). The driver calls [`Strobe::on`] when integration
    /// starts and [`Strobe::off`] when it ends, so the lasers light only the exposure.
    async fn capture<L: Laser, C: Clock>(
        &mut self,
        exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        buf: &mut [u8],
    ) -> Result<(), CameraError>;

    /// Exposes one frame like [`Camera::capture`] and hands its rows to `sink` in blocks of
    /// [`BLOCK_ROWS`] rows as they are read out, so the pipeline works during the read-out.
    /// This default reads the whole frame into `buf` first and hands it over afterwards;
    /// a camera that streams (the H743's DCMI line blocks, the emulated board) overrides it
    /// and needs no `buf`.
    async fn capture_rows<L: Laser, C: Clock, S: RowSink + ?Sized>(
        &mut self,
        exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        buf: &mut [u8],
        sink: &mut S,
    ) -> Result<(), CameraError> {
        self.capture(exposure_us, strobe, buf).await?;
        let g = self.geometry();
        let frame = buf.get(..g.frame_len()).ok_or(CameraError::BufferSize)?;
        for block in frame.chunks(BLOCK_ROWS * (g.width as usize).max(1)) {
            sink.rows(block);
        }
        Ok(())
    }
}

/// Why an accelerometer read failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AccelError {
    /// Nothing acknowledges the part's address: none is fitted, or it is disconnected. The
    /// device measures on without a vertical ([`protocol::AccelReading::Absent`]).
    Absent,
    /// An I²C transaction failed (bus error, a lost acknowledge after the address).
    Bus,
    /// The identity registers do not name the expected part.
    WrongPart,
    /// No new sample came within the sensor's polling budget.
    Timeout,
}

impl AccelError {
    /// Detail code of the failure ([`protocol::AccelReading::Failed`]; the numbers are the
    /// protocol's, `tangent_core::protocol::codes::ACCEL_*`). `Absent` is no failure code:
    /// it travels as [`protocol::AccelReading::Absent`].
    pub fn code(self) -> u32 {
        use tangent_core::protocol::codes;
        match self {
            AccelError::Absent => 0,
            AccelError::Bus => codes::ACCEL_BUS,
            AccelError::WrongPart => codes::ACCEL_WRONG_PART,
            AccelError::Timeout => codes::ACCEL_TIMEOUT,
        }
    }
}

/// One accelerometer sample: the specific force along the sensor's own axes (m/s²; at rest
/// it points up, opposite gravity, with magnitude g). The sensor-to-camera rotation and the
/// bias are the calibration's (`docs/building.md` §6), not the port's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Acceleration {
    /// x, y, z (m/s²).
    pub m_s2: [f32; 3],
}

/// The 3-axis accelerometer: the vertical reference of the wall instrument.
pub trait Accelerometer {
    /// The next sample.
    async fn sample(&mut self) -> Result<Acceleration, AccelError>;

    /// 1σ of one sample's noise on each axis (m/s²) at the sensor's set-up: what the
    /// reading's σ of gravity is computed with.
    fn sample_sigma_m_s2(&self) -> f32;

    /// The mean of `n` (≥ 1) consecutive samples: at rest the noise falls as `1/√n`.
    async fn mean(&mut self, n: u16) -> Result<Acceleration, AccelError> {
        let n = n.max(1);
        let mut sum = [0.0f32; 3];
        for _ in 0..n {
            let s = self.sample().await?;
            for (acc, v) in sum.iter_mut().zip(s.m_s2) {
                *acc += v;
            }
        }
        Ok(Acceleration {
            m_s2: sum.map(|v| v / n as f32),
        })
    }
}

/// Where the calibration lives between power cycles.
pub trait CalibrationStore {
    /// The stored calibration, if a valid one is stored.
    fn load(&mut self) -> Option<WireCalibration>;
    /// Stores `calibration` (replacing the previous one); the error is a board code.
    fn save(&mut self, calibration: &WireCalibration) -> Result<(), u32>;
}

/// Where the instrument mode lives between power cycles (beside the calibration, in a
/// store of its own: a mode change must never put the calibration at risk). Both boards use
/// [`crate::mode_log::ModeLog`] over their own flash words.
pub trait ModeStore {
    /// The stored mode ([`ModeStoreState::Loaded`]), or why there is none.
    fn load(&mut self) -> ModeStoreState;
    /// Stores `mode` so the next [`ModeStore::load`] returns it; the error is a board code.
    fn save(&mut self, mode: Mode) -> Result<(), u32>;
}

/// The hardware watchdog that resets a hung firmware.
pub trait Watchdog {
    /// Restarts the watchdog countdown.
    fn feed(&mut self);
}

/// Everything a board provides.
pub trait Board {
    /// The camera.
    type Camera: Camera;
    /// The lasers.
    type Laser: Laser;
    /// The trigger.
    type Trigger: Trigger;
    /// The host link.
    type Link: Link;
    /// The clock.
    type Clock: Clock;
    /// Calibration storage.
    type Store: CalibrationStore;
    /// Mode storage.
    type ModeStore: ModeStore;
    /// The watchdog.
    type Watchdog: Watchdog;
    /// The accelerometer (the wall instrument's vertical; a board without one fitted
    /// reports [`AccelError::Absent`]).
    type Accelerometer: Accelerometer;
    /// What the board reports in [`protocol::DeviceInfo::board`].
    const KIND: protocol::Board;
    /// Writes a diagnostic line (defmt on the H743, semihosting on QEMU).
    fn log(args: core::fmt::Arguments<'_>);
}

/// The board's devices, as separate fields so the application can borrow them
/// independently (e.g. the camera while the clock guards the laser).
pub struct Devices<B: Board> {
    /// The camera.
    pub camera: B::Camera,
    /// The lasers.
    pub laser: B::Laser,
    /// The trigger.
    pub trigger: B::Trigger,
    /// The host link.
    pub link: B::Link,
    /// The clock.
    pub clock: B::Clock,
    /// Calibration storage.
    pub store: B::Store,
    /// Mode storage.
    pub modes: B::ModeStore,
    /// The watchdog.
    pub watchdog: B::Watchdog,
    /// The accelerometer.
    pub accelerometer: B::Accelerometer,
}

/// Lights the lasers of one exposure, for the camera driver, and keeps account of how
/// long they have been on so a guard can force them off.
///
/// Dropping a `Strobe` switches every laser off: whichever way a capture ends
/// (success, error, timeout, cancelled future), the lasers are off afterwards.
pub struct Strobe<'a, L: Laser, C: Clock> {
    laser: RefCell<&'a mut L>,
    clock: &'a C,
    mask: u8,
    lit_since_us: Cell<Option<u64>>,
    tripped: Cell<bool>,
}

impl<'a, L: Laser, C: Clock> Strobe<'a, L, C> {
    /// A strobe for the lasers of `mask` (0 = a dark exposure: [`Strobe::on`] lights
    /// nothing). Switches every laser off first.
    pub fn new(laser: &'a mut L, clock: &'a C, mask: u8) -> Self {
        laser.set(0);
        Strobe {
            laser: RefCell::new(laser),
            clock,
            mask,
            lit_since_us: Cell::new(None),
            tripped: Cell::new(false),
        }
    }

    /// The lasers this exposure lights.
    pub fn mask(&self) -> u8 {
        self.mask
    }

    /// Lights the lasers (integration is starting). Does nothing once tripped.
    pub fn on(&self) {
        if self.tripped.get() || self.mask == 0 {
            return;
        }
        if let Ok(mut laser) = self.laser.try_borrow_mut() {
            laser.set(self.mask);
            if self.lit_since_us.get().is_none() {
                self.lit_since_us.set(Some(self.clock.now_us()));
            }
        }
    }

    /// Switches the lasers off (integration has ended).
    pub fn off(&self) {
        if let Ok(mut laser) = self.laser.try_borrow_mut() {
            laser.set(0);
        }
        self.lit_since_us.set(None);
    }

    /// True while the lasers are lit.
    pub fn is_lit(&self) -> bool {
        self.lit_since_us.get().is_some()
    }

    /// How long the lasers have been lit (0 when off).
    pub fn lit_for_us(&self) -> u64 {
        match self.lit_since_us.get() {
            Some(t) => self.clock.now_us().saturating_sub(t),
            None => 0,
        }
    }

    /// Forces the lasers off for the rest of this exposure (the guard's hard limit).
    pub fn trip(&self) {
        self.tripped.set(true);
        self.off();
    }

    /// True when the guard forced the lasers off.
    pub fn tripped(&self) -> bool {
        self.tripped.get()
    }
}

impl<L: Laser, C: Clock> Drop for Strobe<'_, L, C> {
    fn drop(&mut self) {
        self.laser.get_mut().set(0);
    }
}

#[cfg(test)]
mod tests;
