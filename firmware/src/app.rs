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
use tangent_core::accelerometer::{self, Alignment};
use tangent_core::calibration::{Calibration, CalibrationError};
use tangent_core::instrument;
use tangent_core::measurement::{Measurement, Mode};
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::codes::HISTORY_LEN;
use tangent_core::protocol::{
    self, AccelReading, DeviceError, DeviceInfo, ErrorCode, Feed, FrameEncoder, FrameSel,
    FrameSetInfo, FromDevice, LinkStats, ModeStoreState, Reading, Request, Response,
    SelfTestReport, ToDevice, WireCalibration, FRAME_CHUNK_MAX, PROTOCOL_VERSION, UNSOLICITED,
};

use crate::exposure::{self, Exposure};
use crate::measure::{FramePair, Measurer, StreamMeasurer};
use crate::ports::{
    AccelError, Accelerometer, Board, CalibrationStore, Camera, CameraError, Clock, Devices,
    Geometry, Laser, Link, ModeStore, RowSink, Strobe, Trigger, Watchdog,
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
        }
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

    /// Measures once and reports the reading (or the error) with `tag`.
    pub async fn measure_and_report(&mut self, tag: u16, stats: Option<&mut Welford>) {
        match self.measure_once().await {
            Ok(mut reading) => {
                if let Some(s) = stats {
                    s.push(reading.measurement.value() as f64);
                    reading.stats = Some(s.summary());
                }
                if self.history.is_full() {
                    self.history.pop_front();
                }
                let _ = self.history.push_back(reading);
                self.send(tag, &Response::Reading(reading)).await;
            }
            Err(e) => {
                B::log(format_args!(
                    "measurement failed: {:?} {}",
                    e.code, e.detail
                ));
                self.send(tag, &Response::Error(e)).await;
            }
        }
    }

    /// Captures a pair and runs the pipeline on it: streamed when the measurer streams (the
    /// laser-off frame into the measurer's memory, the laser-on frame through it as it is
    /// read out), else stored in the frame buffers and measured afterwards.
    pub async fn measure_once(&mut self) -> Result<Reading, DeviceError> {
        let no_calibration = DeviceError {
            code: ErrorCode::NoCalibration,
            detail: 0,
        };
        if self.calibration.is_none() {
            return Err(no_calibration);
        }
        // The vertical first: the mean of the samples while the user holds the device on
        // the target, and before the frames, so the reading's time stays the laser-on
        // exposure's (`docs/firmware.md`, "The vertical").
        let accelerometer = if uses_vertical(self.mode) {
            Some(self.read_accelerometer().await)
        } else {
            None
        };
        let gravity = accelerometer
            .and_then(|a| a.mean())
            .zip(self.alignment)
            .and_then(|(mean, alignment)| accelerometer::vertical(&mean, &alignment).ok());
        self.measurer
            .set_vertical(gravity.map(|v| (v.down, v.sigma_rad)));
        let (info, result) = if self.measurer.streaming().is_some() {
            self.measure_streamed().await?
        } else {
            let info = self.capture_pair().await?;
            let cal = self.calibration.as_ref().ok_or(no_calibration)?;
            let pair = FramePair {
                off: self.off,
                on: self.on,
                width: info.width as usize,
                height: info.height as usize,
                row_offset: info.row_offset as usize,
                laser_mask: info.laser_mask,
            };
            let t0 = self.dev.clock.now_us();
            let result = self.measurer.measure(self.mode, &pair, cal);
            self.last_pipeline_us = self.dev.clock.now_us().saturating_sub(t0);
            (info, result)
        };
        B::log(format_args!(
            "pipeline capture={} time_us={}",
            info.capture, self.last_pipeline_us
        ));
        let measurement = result.map_err(|failure| failure.device_error())?;
        let calib_id = self.calibration.as_ref().ok_or(no_calibration)?.id;
        self.seq = self.seq.wrapping_add(1).max(1);
        Ok(Reading {
            seq: self.seq,
            timestamp_ms: info.timestamp_ms,
            calib_id,
            exposure_us: info.exposure_us,
            measurement,
            stats: None,
            accelerometer,
        })
    }

    /// The accelerometer's mean over [`ACCEL_SAMPLES`] samples, or why there is none (an
    /// unfitted part is [`AccelReading::Absent`], a failing one its code; never a panic,
    /// and the measurement goes on without the vertical).
    pub async fn read_accelerometer(&mut self) -> AccelReading {
        let sensor = &mut self.dev.accelerometer;
        match sensor.mean(ACCEL_SAMPLES).await {
            Ok(a) => AccelReading::Mean {
                m_s2: a.m_s2,
                samples: ACCEL_SAMPLES,
                sample_sigma_m_s2: sensor.sample_sigma_m_s2(),
            },
            Err(AccelError::Absent) => AccelReading::Absent,
            Err(e) => {
                B::log(format_args!("accelerometer failed: {:?}", e));
                AccelReading::Failed(e.code())
            }
        }
    }

    /// The streamed measurement: the laser-off frame into the measurer, the laser-on frame's
    /// rows through it as they arrive. `last_pipeline_us` is the work after the last pixel.
    /// The frame buffers do not hold this pair (`ReadFrameChunk` answers `NoFrames`).
    async fn measure_streamed(
        &mut self,
    ) -> Result<(FrameSetInfo, Result<Measurement, Failure>), DeviceError> {
        let g = self.dev.camera.geometry();
        let exposure_us = self.exposure.current();
        let mask = self.laser_mask();
        self.frames = None;
        let cal = self.calibration.as_ref().ok_or(DeviceError {
            code: ErrorCode::NoCalibration,
            detail: 0,
        })?;
        let Some(measurer) = self.measurer.streaming() else {
            return Err(DeviceError {
                code: ErrorCode::CameraFailure,
                detail: CameraError::BufferSize.code(),
            });
        };
        let d = &mut self.dev;
        let off = measurer
            .begin(g, cal)
            .map_err(|failure| failure.device_error())?;
        expose(&mut d.camera, &mut d.laser, &d.clock, 0, exposure_us, off).await?;
        let timestamp_ms = d.clock.now_ms();
        let mut sink = PeakSink {
            measurer: &mut *measurer,
            width: g.width as usize,
            row: 0,
            peak: 0,
        };
        expose_rows(
            &mut d.camera,
            &mut d.laser,
            &d.clock,
            mask,
            exposure_us,
            self.on,
            &mut sink,
        )
        .await?;
        let peak = sink.peak;
        self.exposure.update(peak);
        let t0 = d.clock.now_us();
        let result = measurer.finish(self.mode);
        self.last_pipeline_us = d.clock.now_us().saturating_sub(t0);
        let info = self.next_frame_set(g, exposure_us, timestamp_ms, mask);
        Ok((info, result))
    }

    /// The next capture's number and what describes its frame pair.
    fn next_frame_set(
        &mut self,
        g: Geometry,
        exposure_us: u32,
        timestamp_ms: u64,
        laser_mask: u8,
    ) -> FrameSetInfo {
        self.capture_no = self.capture_no.wrapping_add(1);
        FrameSetInfo {
            capture: self.capture_no,
            width: g.width,
            height: g.height,
            row_offset: g.row_offset,
            bit_depth: 8,
            exposure_us,
            timestamp_ms,
            laser_mask,
            calib_id: self.calibration.as_ref().map(|c| c.id),
        }
    }

    /// Lasers to light: one per calibrated plane that the board can drive (all the
    /// board's lasers when there is no calibration, e.g. when recording raw frames) — except
    /// a crossing plane (row-wise, the walls' third line, `docs/building.md`): its line would
    /// merge with the others in one frame, so it is never lit with them.
    fn laser_mask(&self) -> u8 {
        let n = self
            .calibration
            .as_ref()
            .map(|c| c.planes.len() as u8)
            .unwrap_or(u8::MAX)
            .min(self.dev.laser.count())
            .min(8);
        let all = ((1u16 << n) - 1) as u8;
        let crossing = self.calibration.as_ref().map_or(0u8, |c| {
            c.planes
                .iter()
                .take(8)
                .enumerate()
                .filter(|(_, p)| p.is_row_wise())
                .fold(0u8, |m, (i, _)| m | (1 << i))
        });
        all & !crossing
    }

    /// Exposes the laser-off then the laser-on frame into the frame buffers.
    pub async fn capture_pair(&mut self) -> Result<FrameSetInfo, DeviceError> {
        let g = self.dev.camera.geometry();
        let exposure_us = self.exposure.current();
        let mask = self.laser_mask();
        // The buffers are invalid from here until both frames are in.
        self.frames = None;
        let len = g.frame_len();
        // A board that streams the laser-on frame (the H743) has no memory for a stored pair.
        let (Some(off), Some(on)) = (self.off.get_mut(..len), self.on.get_mut(..len)) else {
            return Err(DeviceError {
                code: ErrorCode::CameraFailure,
                detail: CameraError::NoFrameStore.code(),
            });
        };
        let d = &mut self.dev;
        expose(&mut d.camera, &mut d.laser, &d.clock, 0, exposure_us, off).await?;
        let timestamp_ms = d.clock.now_ms();
        expose(&mut d.camera, &mut d.laser, &d.clock, mask, exposure_us, on).await?;
        self.exposure
            .update(exposure::peak(on, g.width as usize, PEAK_ROW_STEP));
        let info = self.next_frame_set(g, exposure_us, timestamp_ms, mask);
        self.frames = Some(info);
        Ok(info)
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

#[cfg(test)]
mod tests;
