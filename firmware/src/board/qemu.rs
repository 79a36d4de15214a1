//! The emulated board: `qemu-system-arm -M mps2-an500` (Cortex-M7), see `qemu/run.sh`.
//!
//! * link: CMSDK APB UART0 at 0x4000_4000 (QEMU's first `-serial`), polled;
//! * clock: SysTick on the 25 MHz core clock, wrapping every 2²⁴ ticks, extended to 64 bits
//!   by counting wraps in the SysTick exception. With `-icount shift=0` QEMU's virtual
//!   clock advances 1 ns per instruction, so one tick is 40 instructions: the benchmark's
//!   instruction counter;
//! * camera: frame pairs from PGM files on the host, read by semihosting, one pair per
//!   capture, cycling through the pairs named on the command line. The laser-on file is
//!   used only when the strobe really lit a laser, the laser-off file otherwise. A streamed
//!   capture (`capture_rows`) reads the file in blocks of [`ports::BLOCK_ROWS`] rows and
//!   hands each over as it is read, as the H743's DCMI line blocks arrive;
//! * lasers: a bitmask in RAM (no hardware), trigger: none, watchdog: none (QEMU's
//!   CMSDK watchdog is not wired to reset on this machine model);
//! * calibration store: RAM, initialised from a calibration record file (`--calib`);
//! * accelerometer: the ADXL355 driver on an emulated I²C bus holding the part's register
//!   model ([`crate::adxl355::model`]) — the same driver path as the H743's — sensing the
//!   fixed specific force of `--accel FX,FY,FZ` (sensor axes, m/s²: a device held still)
//!   with Gaussian noise of `--accel-noise SIGMA` per sample (default: the part's,
//!   [`crate::adxl355::SAMPLE_SIGMA_M_S2`]); without `--accel` no part answers the bus
//!   (an instrument without one);
//! * mode store: the mode log ([`crate::mode_log`]) in a host file that stands for the
//!   H743's flash sector (`--mode-store FILE`, [`MODE_WORDS`] flash words, created when the
//!   first mode is stored), so a restarted emulator keeps the mode; without the option the
//!   mode lives in RAM ([`ModeStoreState::Volatile`]).
//!
//! Command line (semihosting `SYS_GET_CMDLINE`, QEMU's `-append`):
//! `[--calib FILE] [--mode-store FILE] [--bench] [--window ROW] [--accel FX,FY,FZ [--accel-noise SIGMA]] OFF.pgm ON.pgm [OFF.pgm ON.pgm …]`;
//! [`start`] reads it and brings the board up.

use core::future::poll_fn;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use core::task::Poll;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_semihosting::nr;
use tangent_core::measurement::Mode;
use tangent_core::protocol::{self, ModeStoreState, WireCalibration};

use tangent_core::pipeline::{Workspace, WorkspaceSizes};

use crate::adxl355::model::Adxl355Model;
use crate::adxl355::{Adxl355, SAMPLE_SIGMA_M_S2};
use crate::app::Buffers;
use crate::i2c_target::TargetBus;

use crate::mode_log::{FlashWords, ModeLog, VolatileModes, ERASED, WORD};
use crate::ports::{self, CameraError, Devices, Geometry, LinkError, ModeStore, Strobe};

mod semihosting;
pub use semihosting::{command_line, exit, load_calibration, log, read_file};
use semihosting::{read_pgm_header, read_pgm_rows, HostFile};

/// Largest frame the emulated board accepts (752 × 480 8-bit).
pub const MAX_FRAME: usize = 752 * 480;
/// Curve/point entries of the pipeline's workspace: 752 columns, two planes.
pub const POINTS: usize = WorkspaceSizes::new(752, 480, 8, 2).points;
/// Bytes of the semihosting command line the board reads.
const MAX_COMMAND_LINE: usize = 4096;

// Everything in .bss (the emulated RAM has no regions to choose from). The stored frame
// pair serves raw captures (`CaptureFrames`); measurements stream the laser-on frame.
crate::buffers::board_buffers! {
    off_bytes = MAX_FRAME, on_bytes = MAX_FRAME, diff_bytes = MAX_FRAME, points = POINTS;
    off;
    on;
    diff;
    runs;
    small;
    objects;
    readout;
    faint;
}

/// Bytes of the block the emulated camera hands over at a time ([`ports::BLOCK_ROWS`] rows
/// of up to 752 pixels), as the H743's DMA does.
const BLOCK_BYTES: usize = ports::BLOCK_ROWS * 752;

/// SysTick input clock of mps2-an500 (Hz).
pub const SYSCLK_HZ: u64 = 25_000_000;
const RELOAD: u32 = 0x00FF_FFFF;

/// SysTick wraps since boot; incremented by [`on_systick`].
static WRAPS: AtomicU32 = AtomicU32::new(0);

/// Call from the `SysTick` exception handler.
pub fn on_systick() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// Starts SysTick as a free-running 24-bit down-counter with the wrap interrupt.
pub fn start_systick(mut syst: SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(RELOAD);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Core-clock ticks since boot (25 MHz).
pub fn ticks() -> u64 {
    loop {
        let hi = WRAPS.load(Ordering::Relaxed);
        let val = SYST::get_current();
        // A wrap between the two reads of WRAPS shows as a changed count: retry.
        if WRAPS.load(Ordering::Relaxed) == hi {
            return ((hi as u64) << 24) + (RELOAD - val) as u64;
        }
    }
}

/// SysTick-based clock.
pub struct QemuClock;

impl ports::Clock for QemuClock {
    fn now_us(&self) -> u64 {
        ticks() * 1_000_000 / SYSCLK_HZ
    }

    async fn delay_us(&self, us: u32) {
        let end = ticks() + us as u64 * SYSCLK_HZ / 1_000_000;
        poll_fn(|cx| {
            if ticks() >= end {
                Poll::Ready(())
            } else {
                cx.waker().wake_by_ref();
                Poll::Pending
            }
        })
        .await
    }
}

/// CMSDK APB UART (QEMU `cmsdk-apb-uart`): DATA, STATE (bit 0 TX full, bit 1 RX full),
/// CTRL (bit 0 TX enable, bit 1 RX enable), INTSTATUS, BAUDDIV.
pub struct Uart {
    base: usize,
}

impl Uart {
    /// UART0 of mps2-an500.
    pub const UART0: usize = 0x4000_4000;

    /// Enables TX and RX. QEMU ignores the baud rate but wants a divisor ≥ 16.
    ///
    /// # Safety
    /// `base` must be a CMSDK UART owned by the caller alone.
    pub unsafe fn new(base: usize) -> Self {
        let u = Uart { base };
        u.write_reg(0x10, 16);
        u.write_reg(0x08, 0b11);
        u
    }

    fn read_reg(&self, off: usize) -> u32 {
        // SAFETY: a register of the UART this value owns (see `new`).
        unsafe { core::ptr::read_volatile((self.base + off) as *const u32) }
    }

    fn write_reg(&self, off: usize, v: u32) {
        // SAFETY: as in `read_reg`.
        unsafe { core::ptr::write_volatile((self.base + off) as *mut u32, v) }
    }

    fn try_read(&self) -> Option<u8> {
        if self.read_reg(0x04) & 0b10 != 0 {
            Some(self.read_reg(0x00) as u8)
        } else {
            None
        }
    }
}

impl ports::Link for Uart {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, LinkError> {
        poll_fn(|cx| {
            let mut n = 0;
            while n < buf.len() {
                match self.try_read() {
                    Some(b) => {
                        buf[n] = b;
                        n += 1;
                    }
                    None => break,
                }
            }
            if n > 0 {
                Poll::Ready(Ok(n))
            } else {
                cx.waker().wake_by_ref();
                Poll::Pending
            }
        })
        .await
    }

    async fn write_all(&mut self, data: &[u8]) -> Result<(), LinkError> {
        for &b in data {
            while self.read_reg(0x04) & 0b01 != 0 {}
            self.write_reg(0x00, b as u32);
        }
        Ok(())
    }
}

/// Lasers as a bitmask (the emulated camera asks the strobe whether they are lit).
pub struct QemuLaser {
    mask: u8,
}

impl QemuLaser {
    /// Three lasers (the parallel pair and the walls' crossing line), off.
    pub const fn new() -> Self {
        QemuLaser { mask: 0 }
    }
}

impl Default for QemuLaser {
    fn default() -> Self {
        Self::new()
    }
}

impl ports::Laser for QemuLaser {
    fn count(&self) -> u8 {
        3
    }
    fn set(&mut self, mask: u8) {
        self.mask = mask & 0b111;
    }
}

/// No trigger on the emulated board: measurements come from the link.
pub struct NoTrigger;

impl ports::Trigger for NoTrigger {
    fn is_pressed(&mut self) -> bool {
        false
    }
    async fn wait_pressed(&mut self) {
        core::future::pending::<()>().await
    }
}

/// No watchdog on the emulated board.
pub struct NoWatchdog;

impl ports::Watchdog for NoWatchdog {
    fn feed(&mut self) {}
}

/// Calibration kept in RAM (initialised from `--calib`).
pub struct RamStore {
    cal: Option<WireCalibration>,
}

impl RamStore {
    /// A store holding `cal`.
    pub fn new(cal: Option<WireCalibration>) -> Self {
        RamStore { cal }
    }
}

impl ports::CalibrationStore for RamStore {
    fn load(&mut self) -> Option<WireCalibration> {
        self.cal.clone()
    }
    fn save(&mut self, calibration: &WireCalibration) -> Result<(), u32> {
        self.cal = Some(calibration.clone());
        Ok(())
    }
}

/// Flash words of the emulated mode sector: 2 KiB, small so a test reaches the log's erase
/// (the H743's sector has 4 096).
pub const MODE_WORDS: usize = 64;

/// The emulated board's mode sector: a host file of [`MODE_WORDS`] flash words (missing or
/// short: the rest erased), mirrored in RAM and written back whole after every program and
/// erase. Board codes: 1 the file cannot be created, 2 it was written short, 3 a word
/// programmed twice, 4 a word outside the sector.
pub struct FileSector<'c> {
    path: &'c str,
    image: [[u8; WORD]; MODE_WORDS],
}

impl<'c> FileSector<'c> {
    /// The sector in `path` (read now; a missing file is an erased sector).
    pub fn open(path: &'c str) -> Self {
        let mut image = [[ERASED; WORD]; MODE_WORDS];
        if let Some(f) = HostFile::open(path, nr::open::R_BINARY) {
            for word in image.iter_mut() {
                if f.read_exact(word).is_none() {
                    // A short file: the rest is erased (a partial word too).
                    *word = [ERASED; WORD];
                    break;
                }
            }
        }
        FileSector { path, image }
    }

    fn persist(&self) -> Result<(), u32> {
        let f = HostFile::open(self.path, nr::open::W_TRUNC_BINARY).ok_or(1u32)?;
        for word in &self.image {
            f.write_all(word).ok_or(2u32)?;
        }
        Ok(())
    }
}

impl FlashWords for FileSector<'_> {
    fn words(&self) -> usize {
        MODE_WORDS
    }
    fn read(&mut self, index: usize, word: &mut [u8; WORD]) -> Result<(), u32> {
        *word = *self.image.get(index).ok_or(4u32)?;
        Ok(())
    }
    fn program(&mut self, index: usize, word: &[u8; WORD]) -> Result<(), u32> {
        let slot = self.image.get_mut(index).ok_or(4u32)?;
        if slot.iter().any(|&b| b != ERASED) {
            return Err(3);
        }
        *slot = *word;
        self.persist()
    }
    fn erase(&mut self) -> Result<(), u32> {
        self.image = [[ERASED; WORD]; MODE_WORDS];
        self.persist()
    }
}

/// The emulated board's mode store: the log in a file (`--mode-store`), or none (the mode
/// in RAM only, [`ModeStoreState::Volatile`]).
pub struct QemuModes<'c>(Option<ModeLog<FileSector<'c>>>);

impl ModeStore for QemuModes<'_> {
    fn load(&mut self) -> ModeStoreState {
        match &mut self.0 {
            Some(log) => log.load(),
            None => VolatileModes.load(),
        }
    }
    fn save(&mut self, mode: Mode) -> Result<(), u32> {
        match &mut self.0 {
            Some(log) => log.save(mode),
            None => VolatileModes.save(mode),
        }
    }
}

/// Most frame pairs on the command line.
pub const MAX_SCENES: usize = 32;

/// The emulated camera: frame pairs from PGM files.
pub struct FileCamera<'c> {
    scenes: heapless::Vec<(&'c str, &'c str), MAX_SCENES>,
    next: usize,
    geometry: Geometry,
    /// The block of rows a streamed capture hands over.
    block: &'static mut [u8; BLOCK_BYTES],
}

impl<'c> FileCamera<'c> {
    /// A camera over `(off, on)` file pairs, all of the size of the first one.
    pub fn new(scenes: heapless::Vec<(&'c str, &'c str), MAX_SCENES>) -> Result<Self, CameraError> {
        let (off, _) = scenes.first().ok_or(CameraError::Source)?;
        static TAKEN: AtomicBool = AtomicBool::new(false);
        static mut BLOCK: [u8; BLOCK_BYTES] = [0; BLOCK_BYTES];
        let h = read_pgm_header(off)?;
        let geometry = Geometry {
            width: u16::try_from(h.width).map_err(|_| CameraError::Source)?,
            height: u16::try_from(h.height).map_err(|_| CameraError::Source)?,
            row_offset: 0,
        };
        if geometry.width as usize > 752 || TAKEN.swap(true, Ordering::AcqRel) {
            return Err(CameraError::BufferSize);
        }
        // SAFETY: `TAKEN` lets this point be reached once: the only reference.
        let block = unsafe { &mut *addr_of_mut!(BLOCK) };
        Ok(FileCamera {
            scenes,
            next: 0,
            geometry,
            block,
        })
    }

    /// Exposes like `capture` and returns the file to read: the laser-on file only when the
    /// strobe really lit a laser.
    fn expose<L: ports::Laser, C: ports::Clock>(
        &mut self,
        strobe: &Strobe<'_, L, C>,
    ) -> Result<&'c str, CameraError> {
        let (off, on) = *self.scenes.get(self.next).ok_or(CameraError::Source)?;
        strobe.on();
        let lit = strobe.is_lit();
        strobe.off();
        // A pair is (dark, lit): the lit frame completes it and the next pair begins.
        if strobe.mask() != 0 {
            self.next = (self.next + 1) % self.scenes.len().max(1);
        }
        Ok(if lit { on } else { off })
    }

    /// The files are a window of the sensor starting at row `row_offset` (the H743 board's
    /// read-out window, for benchmarks of its frame size).
    pub fn with_row_offset(mut self, row_offset: u16) -> Self {
        self.geometry.row_offset = row_offset;
        self
    }

    /// Number of frame pairs.
    pub fn scene_count(&self) -> usize {
        self.scenes.len()
    }
}

impl ports::Camera for FileCamera<'_> {
    fn geometry(&self) -> Geometry {
        self.geometry
    }

    async fn capture<L: ports::Laser, C: ports::Clock>(
        &mut self,
        _exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        buf: &mut [u8],
    ) -> Result<(), CameraError> {
        let path = self.expose(strobe)?;
        let len = self.geometry.frame_len();
        let dst = buf.get_mut(..len).ok_or(CameraError::BufferSize)?;
        let mut at = 0;
        read_pgm_rows(path, self.geometry, self.block, |rows| {
            if let Some(d) = dst.get_mut(at..at + rows.len()) {
                d.copy_from_slice(rows);
            }
            at += rows.len();
        })
    }

    async fn capture_rows<L: ports::Laser, C: ports::Clock, S: ports::RowSink + ?Sized>(
        &mut self,
        _exposure_us: u32,
        strobe: &Strobe<'_, L, C>,
        _buf: &mut [u8],
        sink: &mut S,
    ) -> Result<(), CameraError> {
        let path = self.expose(strobe)?;
        read_pgm_rows(path, self.geometry, self.block, |rows| sink.rows(rows))
    }
}

/// Three finite numbers separated by commas (`--accel`).
fn parse_vector(s: &str) -> Option<[f32; 3]> {
    let mut v = [0.0f32; 3];
    let mut parts = s.split(',');
    for x in v.iter_mut() {
        *x = parts.next()?.parse().ok().filter(|x: &f32| x.is_finite())?;
    }
    parts.next().is_none().then_some(v)
}

/// The emulated board.
pub struct Qemu<'c>(core::marker::PhantomData<&'c ()>);

impl<'c> ports::Board for Qemu<'c> {
    type Camera = FileCamera<'c>;
    type Laser = QemuLaser;
    type Trigger = NoTrigger;
    type Link = Uart;
    type Clock = QemuClock;
    type Store = RamStore;
    type ModeStore = QemuModes<'c>;
    type Watchdog = NoWatchdog;
    type Accelerometer = Adxl355<TargetBus<Adxl355Model>>;
    const KIND: protocol::Board = protocol::Board::Emulated;
    fn log(args: core::fmt::Arguments<'_>) {
        log(args)
    }
}

/// The started board.
pub struct Started {
    /// The devices.
    pub devices: Devices<Qemu<'static>>,
    /// The application's buffers.
    pub buffers: Buffers<'static>,
    /// The pipeline's working memory, for the camera's frame size.
    pub workspace: Workspace<'static, u8>,
    /// `--bench`: measure every frame pair once, print the instruction counts and exit.
    pub bench: bool,
}

/// Brings the board up from its command line: SysTick, the camera over the frame files, the
/// calibration file, the UART, the buffers. A bad command line is logged and ends QEMU with
/// a failure, as does a second call.
pub fn start(syst: SYST) -> Started {
    static STARTED: AtomicBool = AtomicBool::new(false);
    static mut COMMAND_LINE: [u8; MAX_COMMAND_LINE] = [0; MAX_COMMAND_LINE];
    if STARTED.swap(true, Ordering::AcqRel) {
        log(format_args!("the emulated board is started once"));
        exit(false)
    }
    start_systick(syst);
    // SAFETY: `STARTED` lets this point be reached once: the only reference, for the
    // program's life.
    let buf = unsafe { &mut *addr_of_mut!(COMMAND_LINE) };
    let Some(cmdline) = command_line(buf) else {
        log(format_args!("no semihosting command line"));
        exit(false)
    };

    let mut calib_path = None;
    let mut mode_path = None;
    let mut bench = false;
    let mut row_offset = 0u16;
    let mut accel_force: Option<[f32; 3]> = None;
    let mut accel_noise = SAMPLE_SIGMA_M_S2;
    let mut files: heapless::Vec<&str, { 2 * MAX_SCENES }> = heapless::Vec::new();
    let mut args = cmdline.split_ascii_whitespace();
    // The first word is the program (the -kernel file name).
    let _ = args.next();
    while let Some(a) = args.next() {
        match a {
            "--calib" => calib_path = args.next(),
            "--mode-store" => match args.next() {
                Some(p) => mode_path = Some(p),
                None => {
                    log(format_args!("--mode-store needs a file"));
                    exit(false)
                }
            },
            "--bench" => bench = true,
            "--accel" => match args.next().and_then(parse_vector) {
                Some(f) => accel_force = Some(f),
                None => {
                    log(format_args!(
                        "--accel needs the specific force FX,FY,FZ (sensor axes, m/s²)"
                    ));
                    exit(false)
                }
            },
            "--accel-noise" => match args.next().and_then(|s| s.parse::<f32>().ok()) {
                Some(s) if s >= 0.0 && s.is_finite() => accel_noise = s,
                _ => {
                    log(format_args!(
                        "--accel-noise needs the 1σ of a sample (m/s², ≥ 0)"
                    ));
                    exit(false)
                }
            },
            "--window" => match args.next().and_then(|r| r.parse().ok()) {
                Some(r) => row_offset = r,
                None => {
                    log(format_args!(
                        "--window needs the sensor row of the files' first row"
                    ));
                    exit(false)
                }
            },
            f => {
                if files.push(f).is_err() {
                    log(format_args!(
                        "too many frame files (max {})",
                        2 * MAX_SCENES
                    ));
                    exit(false)
                }
            }
        }
    }
    let mut scenes = heapless::Vec::new();
    for pair in files.chunks_exact(2) {
        let _ = scenes.push((pair[0], pair[1]));
    }
    if scenes.is_empty() || !files.len().is_multiple_of(2) {
        log(format_args!(
            "usage: tangent-qemu [--calib FILE] [--mode-store FILE] [--bench] [--window ROW] [--accel FX,FY,FZ [--accel-noise SIGMA]] OFF.pgm ON.pgm [OFF.pgm ON.pgm ...]"
        ));
        exit(false)
    }
    let camera = match FileCamera::new(scenes) {
        Ok(c) => c.with_row_offset(row_offset),
        Err(e) => {
            log(format_args!("cannot read the first frame: {:?}", e));
            exit(false)
        }
    };
    // The workspace covers the camera's frame size (at most MAX_FRAME pixels).
    let pixels = ports::Camera::geometry(&camera).frame_len();
    let calibration = match calib_path {
        Some(p) => match load_calibration(p) {
            Some(c) => Some(c),
            None => {
                log(format_args!("{}: not a valid calibration record", p));
                exit(false)
            }
        },
        None => None,
    };
    let Some((buffers, workspace)) = take_buffers(pixels) else {
        log(format_args!("the buffers are taken once"));
        exit(false)
    };

    // SAFETY: UART0 is used by nothing else.
    let link = unsafe { Uart::new(Uart::UART0) };
    let devices = Devices {
        camera,
        laser: QemuLaser::new(),
        trigger: NoTrigger,
        link,
        clock: QemuClock,
        store: RamStore::new(calibration),
        modes: QemuModes(mode_path.map(|p| ModeLog::new(FileSector::open(p)))),
        watchdog: NoWatchdog,
        // The noise's seed is fixed: a run repeats.
        accelerometer: Adxl355::new(TargetBus::new(
            accel_force.map(|f| Adxl355Model::new(f, accel_noise, 1)),
        )),
    };
    Started {
        devices,
        buffers,
        workspace,
        bench,
    }
}
