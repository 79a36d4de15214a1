//! The application: trigger → exposures → measurement → report, and the host's commands.
//!
//! ```text
//!            trigger press / Measure / stream tick
//!   Idle ─────────────────────────────────────────► Expose(off) ──► Expose(on) ──► Measure ──► Report
//!    ▲   (link bytes → commands, watchdog fed)          laser off     laser on only     pipeline    Reading /
//!    └────────────────────────────────────────────────────────────────  during integration ───────  Error ─┘
//!                     held trigger or stream: loop with running mean and spread
//! ```
//!
//! Safety of the lasers: every exposure goes through [`expose`], which hands the camera a
//! [`Strobe`] (lit only between the driver's `on()`/`off()` at integration start/end),
//! races the capture against a guard that trips the strobe after [`MAX_LASER_ON_US`] and
//! gives up after [`CAPTURE_TIMEOUT_US`], and switches every laser off when it returns —
//! on success, error, timeout and cancellation alike (the strobe's `Drop`). Boards switch
//! the lasers off at reset before anything else runs.

use embassy_futures::select::{select, select3, Either, Either3};
use heapless::Deque;
use tangent_core::accelerometer::Alignment;
use tangent_core::calibration::{Calibration, CalibrationError};
use tangent_core::instrument;
use tangent_core::measurement::Mode;
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::codes::HISTORY_LEN;
use tangent_core::protocol::{
    self, DeviceError, DeviceInfo, ErrorCode, Feed, FrameEncoder, FrameSel, FrameSetInfo,
    FromDevice, LinkStats, ModeStoreState, Reading, Request, Response, SelfTestReport, ToDevice,
    WireCalibration, FRAME_CHUNK_MAX, PROTOCOL_VERSION, UNSOLICITED,
};
use tangent_core::solvers::stem::MAX_EXPOSURES;

use crate::exposure::{self, Exposure};
use crate::measure::{Measurer, StreamMeasurer};
use crate::ports::{
    Board, CalibrationStore, Camera, CameraError, Clock, Devices, Laser, Link, ModeStore, RowSink,
    Strobe, Trigger, Watchdog,
};
use crate::stats::Welford;

/// Hard limit of the laser on-time of one exposure (µs): the longest exposure plus
/// margin for the driver's start/stop latency. Eye safety does not depend on it (Class 2
/// lasers), but a stuck-on laser wastes the battery and blinds the next dark frame.
pub const MAX_LASER_ON_US: u64 = exposure::MAX_EXPOSURE_US as u64 + 2_000;
/// A capture that has not completed after this long failed (µs): exposure, read-out of a
/// full frame (≈ 17 ms at 26.6 MHz) and generous slack.
pub const CAPTURE_TIMEOUT_US: u64 = 250_000;
/// How often the guard checks the laser (µs).
const GUARD_POLL_US: u32 = 500;
/// Idle wake-up period: feeds the watchdog while nothing happens (µs).
const IDLE_TICK_US: u32 = 100_000;
/// Every `PEAK_ROW_STEP`-th row is sampled for auto-exposure.
const PEAK_ROW_STEP: usize = 4;
/// Accelerometer samples averaged for a reading that uses the vertical: 16 at 62.5 Hz,
/// 0.26 s (the simulator's reference, `docs/building.md` §6).
pub const ACCEL_SAMPLES: u16 = 16;

/// Frame pairs a stem reading combines until the host sets another count
/// ([`Request::SetExposures`]): four halve the held-out error of one pair's reading at a
/// sixth of a second per trigger press (`docs/error-model.md` §6, `docs/firmware.md`).
pub const DEFAULT_EXPOSURES: u8 = 4;

/// True for the instruments whose reading uses the vertical (the wall's plumb): only they
/// read the accelerometer, so the others measure as fast as before.
pub fn uses_vertical(mode: Mode) -> bool {
    mode == Mode::Wall
}

/// The firmware's buffers, allocated by the board (frames in DMA-reachable RAM).
pub struct Buffers<'b> {
    /// Laser-off frame (`geometry().frame_len()` bytes).
    pub off: &'b mut [u8],
    /// Laser-on frame (same size).
    pub on: &'b mut [u8],
    /// Receive buffer of the protocol decoder (≥ [`protocol::MAX_FRAME_LEN`]).
    pub rx: &'b mut [u8],
}

/// The application state.
pub struct App<'b, B: Board, M: Measurer> {
    /// The board's devices.
    pub dev: Devices<B>,
    measurer: M,
    off: &'b mut [u8],
    on: &'b mut [u8],
    rx: protocol::Decoder<&'b mut [u8]>,
    enc: FrameEncoder,
    calibration: Option<Calibration>,
    /// The calibration as received (f64), returned unchanged by `ReadCalibration`.
    calibration_wire: Option<WireCalibration>,
    /// The accelerometer's part of the calibration, when it has one: turns the
    /// accelerometer's mean into gravity in the camera frame.
    alignment: Option<Alignment>,
    seq: u32,
    capture_no: u32,
    frames: Option<FrameSetInfo>,
    exposure: Exposure,
    history: Deque<Reading, HISTORY_LEN>,
    stream: Option<(u16, Welford)>,
    /// The instrument every reading is measured with ([`Request::SetMode`]), remembered by
    /// the board's [`ModeStore`]; [`Mode::Cylinder`] when the store has none.
    mode: Mode,
    /// Where `mode` came from (reported in [`DeviceInfo::mode_store`]).
    mode_store: ModeStoreState,
    /// Frame pairs one stem reading combines ([`Request::SetExposures`]; RAM only).
    exposures: u8,
    /// Duration of the last pipeline run (µs of the board clock), for benchmarks.
    pub last_pipeline_us: u64,
}

enum Event {
    Bytes(usize),
    LinkDown,
    Trigger,
    StreamTick,
    Idle,
}

impl<'b, B: Board, M: Measurer> App<'b, B, M> {
    /// Builds the application; switches the lasers off and loads the stored calibration,
    /// then the stored mode (the default, [`Mode::Cylinder`], when the store has none: why is
    /// logged and reported in [`DeviceInfo::mode_store`]).
    pub fn new(mut dev: Devices<B>, measurer: M, buffers: Buffers<'b>) -> Self {
        dev.laser.set(0);
        let (calibration, calibration_wire) = match dev.store.load() {
            Some(w) => match w.to_calibration() {
                Ok(c) => (Some(c), Some(w)),
                Err(_) => (None, None),
            },
            None => (None, None),
        };
        let alignment = calibration_wire
            .as_ref()
            .and_then(|w| w.accelerometer)
            .and_then(|a| a.to_alignment());
        let mode_store = dev.modes.load();
        let mode = match mode_store {
            ModeStoreState::Loaded(mode) => mode,
            other => {
                B::log(format_args!("mode: {}", other));
                Mode::Cylinder
            }
        };
        App {
            dev,
            measurer,
            off: buffers.off,
            on: buffers.on,
            rx: protocol::Decoder::new(buffers.rx),
            enc: FrameEncoder::new(),
            calibration,
            calibration_wire,
            alignment,
            seq: 0,
            capture_no: 0,
            frames: None,
            exposure: Exposure::new(),
            history: Deque::new(),
            stream: None,
            mode,
            mode_store,
            exposures: DEFAULT_EXPOSURES,
            last_pipeline_us: 0,
        }
    }

    /// The measurer (for its benchmark timings).
    pub fn measurer(&self) -> &M {
        &self.measurer
    }

    /// The active calibration.
    pub fn calibration(&self) -> Option<&Calibration> {
        self.calibration.as_ref()
    }

    /// The instrument the device measures with.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Where the mode came from: the store, or why the default.
    pub fn mode_store(&self) -> ModeStoreState {
        self.mode_store
    }

    /// Frame pairs one stem reading combines.
    pub fn exposures(&self) -> u8 {
        self.exposures
    }

    /// Link counters.
    pub fn link_stats(&self) -> LinkStats {
        self.rx.stats()
    }

    /// Runs forever: announces the device, then serves the trigger and the link.
    pub async fn run(&mut self) -> ! {
        self.announce().await;
        loop {
            self.step().await;
        }
    }

    /// Logs the start and sends the unsolicited `Info` banner (what a boot looks like to
    /// the host). [`App::run`] calls it once; a test board that runs [`App::step`] itself
    /// calls it after each (simulated) boot.
    pub async fn announce(&mut self) {
        B::log(format_args!(
            "tangent firmware {} up, calibration {:?}",
            crate::VERSION,
            self.calibration.as_ref().map(|c| c.id)
        ));
        self.send_info(UNSOLICITED).await;
    }

    /// One turn of the main loop: waits for an event (or does one stream measurement) and
    /// handles it.
    pub async fn step(&mut self) {
        self.dev.watchdog.feed();
        let mut chunk = [0u8; 64];
        let event = if self.stream.is_some() {
            // Streaming: take bytes if some are waiting, otherwise measure again.
            match select(self.dev.link.read(&mut chunk), core::future::ready(())).await {
                Either::First(Ok(n)) => Event::Bytes(n),
                Either::First(Err(_)) => Event::LinkDown,
                Either::Second(()) => Event::StreamTick,
            }
        } else {
            match select3(
                self.dev.link.read(&mut chunk),
                self.dev.trigger.wait_pressed(),
                self.dev.clock.delay_us(IDLE_TICK_US),
            )
            .await
            {
                Either3::First(Ok(n)) => Event::Bytes(n),
                Either3::First(Err(_)) => Event::LinkDown,
                Either3::Second(()) => Event::Trigger,
                Either3::Third(()) => Event::Idle,
            }
        };
        match event {
            Event::Bytes(n) => self.on_bytes(chunk.get(..n).unwrap_or(&[])).await,
            Event::LinkDown => {
                // A half-received frame is meaningless after a disconnect; streams end
                // (the host restarts them; readings stay in the history).
                self.rx.reset();
                self.stream = None;
                self.dev.clock.delay_us(IDLE_TICK_US).await;
            }
            Event::Trigger => self.on_trigger().await,
            Event::StreamTick => {
                if let Some((tag, mut stats)) = self.stream.take() {
                    self.measure_and_report(tag, Some(&mut stats)).await;
                    // A StopStream handled meanwhile is impossible (single task), so the
                    // stream continues.
                    self.stream = Some((tag, stats));
                }
            }
            Event::Idle => {}
        }
    }

    async fn on_bytes(&mut self, bytes: &[u8]) {
        let mut input = bytes;
        loop {
            match self.rx.feed::<ToDevice>(input) {
                Feed::Consumed => break,
                Feed::Frame { message, remaining } => {
                    input = remaining;
                    self.handle(message.tag, message.request).await;
                }
                Feed::Rejected { error, remaining } => {
                    input = remaining;
                    if let protocol::ProtocolError::VersionMismatch { received } = error {
                        let e = DeviceError {
                            code: ErrorCode::UnsupportedVersion,
                            detail: received as u32,
                        };
                        self.send(UNSOLICITED, &Response::Error(e)).await;
                    }
                    B::log(format_args!("rejected frame: {}", error));
                }
            }
        }
    }

    /// Trigger pressed: measure until it is released, with running statistics.
    async fn on_trigger(&mut self) {
        let mut stats = Welford::new();
        loop {
            self.dev.watchdog.feed();
            self.measure_and_report(UNSOLICITED, Some(&mut stats)).await;
            if !self.dev.trigger.is_pressed() {
                break;
            }
        }
    }

    /// Handles one request.
    pub async fn handle(&mut self, tag: u16, request: Request) {
        match request {
            Request::DeviceInfo => self.send_info(tag).await,
            Request::Measure => self.measure_and_report(tag, None).await,
            Request::StartStream => {
                self.stream = Some((tag, Welford::new()));
                self.send(tag, &Response::Ack).await;
            }
            Request::StopStream => {
                self.stream = None;
                self.send(tag, &Response::Ack).await;
            }
            Request::History { after_seq } => {
                let mut i = 0;
                while let Some(r) = self.history.iter().nth(i).copied() {
                    if r.seq > after_seq {
                        self.send(tag, &Response::Reading(r)).await;
                    }
                    i += 1;
                }
                let last_seq = self.seq;
                self.send(tag, &Response::HistoryEnd { last_seq }).await;
            }
            Request::CaptureFrames => match self.capture_pair().await {
                Ok(info) => self.send(tag, &Response::FramesReady(info)).await,
                Err(e) => self.send(tag, &Response::Error(e)).await,
            },
            Request::ReadFrameChunk {
                capture,
                frame,
                offset,
                max_len,
            } => self.send_chunk(tag, capture, frame, offset, max_len).await,
            Request::ReadCalibration => {
                let response = match &self.calibration_wire {
                    Some(c) => Response::Calibration(c.clone()),
                    None => Response::Error(DeviceError {
                        code: ErrorCode::NoCalibration,
                        detail: 0,
                    }),
                };
                self.send(tag, &response).await;
            }
            Request::WriteCalibration(wire) => {
                let response = match self.install_calibration(&wire) {
                    Ok(()) => Response::Ack,
                    Err(e) => Response::Error(e),
                };
                self.send(tag, &response).await;
            }
            Request::SetExposure(us) => {
                self.exposure.set_fixed(us);
                self.send(tag, &Response::Ack).await;
            }
            Request::SelfTest => {
                let report = self.self_test().await;
                self.send(tag, &Response::SelfTest(report)).await;
            }
            Request::SetMode(mode) => {
                let response = match self.set_mode(mode) {
                    Ok(()) => Response::Ack,
                    Err(e) => Response::Error(e),
                };
                self.send(tag, &response).await;
            }
            Request::SetExposures(count) => {
                let response = match self.set_exposures(count) {
                    Ok(()) => Response::Ack,
                    Err(e) => Response::Error(e),
                };
                self.send(tag, &response).await;
            }
        }
    }

    /// Sets the frame pairs one stem reading combines: 1 to [`MAX_EXPOSURES`], else
    /// [`ErrorCode::InvalidSetting`] (detail: the count) and the count stays as it was.
    pub fn set_exposures(&mut self, count: u8) -> Result<(), DeviceError> {
        if count == 0 || count as usize > MAX_EXPOSURES {
            return Err(DeviceError {
                code: ErrorCode::InvalidSetting,
                detail: count as u32,
            });
        }
        self.exposures = count;
        Ok(())
    }

    /// Selects the instrument of later readings and stores it, so a reset or power cycle
    /// keeps it. A mode this build cannot measure is refused
    /// ([`Failure::UnsupportedMode`]), and a mode the store fails to keep is refused with
    /// [`ErrorCode::StorageFailure`] (detail: the board's code); either way the mode stays as
    /// it was. A running stream carries on in the new mode with fresh statistics (a mean of
    /// stems and spheres means nothing).
    pub fn set_mode(&mut self, mode: Mode) -> Result<(), DeviceError> {
        if !instrument::supports(mode) {
            return Err(Failure::UnsupportedMode(mode).device_error());
        }
        // Storing the mode already stored would only wear the flash; a default mode that
        // the user now sets explicitly is stored.
        if self.mode_store != ModeStoreState::Loaded(mode) {
            self.dev.modes.save(mode).map_err(|detail| {
                B::log(format_args!(
                    "mode {} not stored: code {}",
                    mode.name(),
                    detail
                ));
                DeviceError {
                    code: ErrorCode::StorageFailure,
                    detail,
                }
            })?;
            if self.mode_store != ModeStoreState::Volatile {
                self.mode_store = ModeStoreState::Loaded(mode);
            }
        }
        if mode != self.mode {
            if let Some((_, stats)) = self.stream.as_mut() {
                *stats = Welford::new();
            }
        }
        self.mode = mode;
        Ok(())
    }

    fn install_calibration(&mut self, wire: &WireCalibration) -> Result<(), DeviceError> {
        let invalid = |detail| DeviceError {
            code: ErrorCode::InvalidCalibration,
            detail,
        };
        let cal = wire.to_calibration().map_err(|e| match e {
            // The planes' covariance, apart: the planes themselves are fine.
            CalibrationError::Uncertainty(_) => invalid(4),
            _ => invalid(1),
        })?;
        let alignment = match &wire.accelerometer {
            Some(a) => Some(a.to_alignment().ok_or(invalid(3))?),
            None => None,
        };
        let g = self.dev.camera.geometry();
        // The calibration describes the full sensor; the frames must lie inside it.
        if cal.camera.width != g.width as u32
            || (cal.camera.height as u64) < g.row_offset as u64 + g.height as u64
        {
            return Err(invalid(2));
        }
        self.dev.store.save(wire).map_err(|detail| DeviceError {
            code: ErrorCode::StorageFailure,
            detail,
        })?;
        self.calibration = Some(cal);
        self.calibration_wire = Some(wire.clone());
        self.alignment = alignment;
        Ok(())
    }

    async fn send_chunk(
        &mut self,
        tag: u16,
        capture: u32,
        frame: FrameSel,
        offset: u32,
        max_len: u16,
    ) {
        let err = |code| Response::Error(DeviceError { code, detail: 0 });
        let Some(info) = self.frames else {
            return self.send(tag, &err(ErrorCode::NoFrames)).await;
        };
        if info.capture != capture {
            return self.send(tag, &err(ErrorCode::StaleCapture)).await;
        }
        let total = info.width as usize * info.height as usize;
        let buf: &[u8] = match frame {
            FrameSel::Off => self.off,
            FrameSel::On => self.on,
        };
        let start = offset as usize;
        let len = (max_len as usize).min(FRAME_CHUNK_MAX);
        let end = start.saturating_add(len).min(total);
        let Some(data) = buf.get(start..end).filter(|_| start < total) else {
            return self.send(tag, &err(ErrorCode::OutOfRange)).await;
        };
        let msg = FromDevice {
            tag,
            response: Response::FrameChunk {
                capture,
                frame,
                offset,
                total: total as u32,
                data,
            },
        };
        // Encode here (not via `send`) because the chunk borrows the frame buffer.
        if let Ok(bytes) = self.enc.encode(&msg) {
            let _ = self.dev.link.write_all(bytes).await;
        }
    }

    async fn send_info(&mut self, tag: u16) {
        let g = self.dev.camera.geometry();
        let info = DeviceInfo {
            protocol_version: PROTOCOL_VERSION,
            fw_version: crate::VERSION,
            board: B::KIND,
            calib_id: self.calibration.as_ref().map(|c| c.id),
            frame_width: g.width,
            frame_height: g.height,
            uptime_ms: self.dev.clock.now_ms(),
            last_seq: self.seq,
            link: self.rx.stats(),
            mode: self.mode,
            mode_store: self.mode_store,
            exposures: self.exposures,
        };
        self.send(tag, &Response::Info(info)).await;
    }

    /// Sends one message; a link that is down drops it (readings stay in the history).
    async fn send(&mut self, tag: u16, response: &Response<'_>) {
        let msg = FromDevice {
            tag,
            response: response.clone(),
        };
        match self.enc.encode(&msg) {
            Ok(bytes) => {
                let _ = self.dev.link.write_all(bytes).await;
            }
            Err(e) => B::log(format_args!("cannot encode a response: {}", e)),
        }
    }

    /// Self-test: a capture, the calibration, laser contrast and the dark level.
    pub async fn self_test(&mut self) -> SelfTestReport {
        use protocol::self_test::*;
        let mut failed = 0;
        let ran = CAMERA | CALIBRATION | LASER_CONTRAST | DARK_LEVEL;
        if self.calibration.is_none() {
            failed |= CALIBRATION;
        }
        match self.capture_pair().await {
            Ok(info) => {
                let w = info.width as usize;
                let dark = exposure::peak(self.off, w, 1);
                if dark >= exposure::SATURATED {
                    failed |= DARK_LEVEL;
                }
                // The lasers must add light somewhere: the brightest on-pixel must exceed
                // the brightest off-pixel by more than sensor noise (a few grey levels).
                let lit = exposure::peak(self.on, w, 1);
                if lit <= dark.saturating_add(8) {
                    failed |= LASER_CONTRAST;
                }
            }
            Err(_) => failed |= CAMERA | LASER_CONTRAST | DARK_LEVEL,
        }
        SelfTestReport { failed, ran }
    }
}

/// Forwards the laser-on rows to the measurer and keeps the brightest pixel of every
/// [`PEAK_ROW_STEP`]-th row, for the auto-exposure.
struct PeakSink<'m> {
    measurer: &'m mut dyn StreamMeasurer,
    width: usize,
    row: usize,
    peak: u8,
}

impl RowSink for PeakSink<'_> {
    fn rows(&mut self, rows: &[u8]) {
        for row in rows.chunks_exact(self.width.max(1)) {
            if self.row.is_multiple_of(PEAK_ROW_STEP) {
                self.peak = self.peak.max(exposure::peak(row, self.width, 1));
            }
            self.row += 1;
        }
        self.measurer.rows(rows);
    }
}

/// One exposure with the lasers of `mask`, guarded (see the module documentation), read
/// into `buf`.
pub async fn expose<C: Camera, L: Laser, K: Clock>(
    camera: &mut C,
    laser: &mut L,
    clock: &K,
    mask: u8,
    exposure_us: u32,
    buf: &mut [u8],
) -> Result<(), DeviceError> {
    guarded::<C, L, K, dyn RowSink>(camera, laser, clock, mask, exposure_us, buf, None).await
}

/// One exposure like [`expose`] whose rows go to `sink` as they are read out
/// ([`Camera::capture_rows`]; `buf` is the frame buffer of a camera that does not stream).
pub async fn expose_rows<C: Camera, L: Laser, K: Clock, S: RowSink + ?Sized>(
    camera: &mut C,
    laser: &mut L,
    clock: &K,
    mask: u8,
    exposure_us: u32,
    buf: &mut [u8],
    sink: &mut S,
) -> Result<(), DeviceError> {
    guarded(camera, laser, clock, mask, exposure_us, buf, Some(sink)).await
}

async fn guarded<C: Camera, L: Laser, K: Clock, S: RowSink + ?Sized>(
    camera: &mut C,
    laser: &mut L,
    clock: &K,
    mask: u8,
    exposure_us: u32,
    buf: &mut [u8],
    sink: Option<&mut S>,
) -> Result<(), DeviceError> {
    enum Guard {
        Laser,
        Timeout,
    }
    let start = clock.now_us();
    let result = {
        let strobe = Strobe::new(laser, clock, mask);
        let guard = async {
            loop {
                clock.delay_us(GUARD_POLL_US).await;
                if strobe.lit_for_us() > MAX_LASER_ON_US {
                    strobe.trip();
                    return Guard::Laser;
                }
                if clock.now_us().saturating_sub(start) > CAPTURE_TIMEOUT_US {
                    return Guard::Timeout;
                }
            }
        };
        let capture = async {
            match sink {
                Some(sink) => camera.capture_rows(exposure_us, &strobe, buf, sink).await,
                None => camera.capture(exposure_us, &strobe, buf).await,
            }
        };
        let r = select(capture, guard).await;
        let tripped = strobe.tripped();
        let err = |code, detail| Err(DeviceError { code, detail });
        match r {
            Either::First(Ok(())) if tripped => err(ErrorCode::LaserTimeout, 0),
            Either::First(Ok(())) => Ok(()),
            Either::First(Err(CameraError::Timeout)) => {
                err(ErrorCode::CameraTimeout, CameraError::Timeout.code())
            }
            Either::First(Err(e)) => err(ErrorCode::CameraFailure, e.code()),
            Either::Second(Guard::Laser) => err(ErrorCode::LaserTimeout, 0),
            Either::Second(Guard::Timeout) => err(ErrorCode::CameraTimeout, 0),
        }
        // `strobe` drops here: every laser off.
    };
    laser.set(0);
    result
}

mod reading;
#[cfg(test)]
mod tests;
