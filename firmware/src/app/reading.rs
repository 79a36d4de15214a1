//! The measurement path of the application: a reading from one or several frame pairs
//! (trigger press, `Measure`, stream tick), the raw captures, and what both share (the
//! lasers to light, the capture's description).

use tangent_core::accelerometer;
use tangent_core::measurement::{Measurement, Mode};
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::{
    AccelReading, DeviceError, ErrorCode, FrameSetInfo, Reading, Response,
};

use super::{expose, expose_rows, uses_vertical, App, PeakSink, ACCEL_SAMPLES, PEAK_ROW_STEP};
use crate::exposure;
use crate::measure::{FramePair, Measurer};
use crate::ports::{
    AccelError, Accelerometer, Board, Camera, CameraError, Clock, Geometry, Laser, Watchdog,
};
use crate::stats::Welford;

/// The error of a reading asked for before any calibration was pushed.
const NO_CALIBRATION: DeviceError = DeviceError {
    code: ErrorCode::NoCalibration,
    detail: 0,
};

impl<B: Board, M: Measurer> App<'_, B, M> {
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

    /// One reading: the vertical when the mode uses it, then [`App::exposures`] frame pairs
    /// for a stem (combined by the measurer, `docs/error-model.md` §6, (E7)) or one pair for
    /// the other instruments. The reading's time and exposure are those of the first pair
    /// that read; with no pair reading, the first pair's failure is the reading's.
    pub async fn measure_once(&mut self) -> Result<Reading, DeviceError> {
        if self.calibration.is_none() {
            return Err(NO_CALIBRATION);
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
        // The stem combines several frame pairs into one reading ((E7)); a camera or laser
        // fault ends the reading at once, a pair the pipeline cannot read does not.
        let pairs = if self.mode == Mode::Cylinder {
            self.exposures
        } else {
            1
        };
        self.measurer.begin_exposures();
        let mut first: Option<(FrameSetInfo, Result<Measurement, Failure>)> = None;
        for k in 0..pairs {
            // Fed between pairs, so the longest gap stays one pair whatever the count.
            if k > 0 {
                self.dev.watchdog.feed();
            }
            let (info, result) = self.measure_pair().await?;
            // The first pair that read, else the first pair's failure.
            match (&first, &result) {
                (None, _) | (Some((_, Err(_))), Ok(_)) => first = Some((info, result)),
                _ => {}
            }
        }
        let (info, mut result) = first.ok_or(DeviceError {
            code: ErrorCode::InvalidSetting,
            detail: pairs as u32,
        })?;
        if pairs > 1 && result.is_ok() {
            let t0 = self.dev.clock.now_us();
            if let Some(combined) = self.measurer.combined(self.mode) {
                result = combined;
            }
            self.last_pipeline_us += self.dev.clock.now_us().saturating_sub(t0);
        }
        B::log(format_args!(
            "pipeline capture={} time_us={}",
            info.capture, self.last_pipeline_us
        ));
        let measurement = result.map_err(|failure| failure.device_error())?;
        let calib_id = self.calibration.as_ref().ok_or(NO_CALIBRATION)?.id;
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

    /// One frame pair of a reading, captured and measured: streamed when the measurer
    /// streams (the laser-off frame into the measurer's memory, the laser-on frame through
    /// it as it is read out), else stored in the frame buffers and measured afterwards.
    async fn measure_pair(
        &mut self,
    ) -> Result<(FrameSetInfo, Result<Measurement, Failure>), DeviceError> {
        Ok(if self.measurer.streaming().is_some() {
            self.measure_streamed().await?
        } else {
            let info = self.capture_pair().await?;
            let cal = self.calibration.as_ref().ok_or(NO_CALIBRATION)?;
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
}
