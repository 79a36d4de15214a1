//! The device's commands beyond measuring: its settings, its calibration, its self-test and
//! its raw frames.

use tangent_core::protocol::{
    DeviceError, ErrorCode, FrameSel, FrameSetInfo, Request, SelfTestReport, WireCalibration,
    FRAME_CHUNK_MAX,
};

use super::{unexpected, Link, LinkError, Reply};

impl Link {
    /// The device's calibration (`None` when it has none).
    pub fn read_calibration(&mut self) -> Result<Option<WireCalibration>, LinkError> {
        match self.request_inner(Request::ReadCalibration, "ReadCalibration", true)? {
            Reply::Calibration(c) => Ok(Some(c)),
            Reply::Error(DeviceError {
                code: ErrorCode::NoCalibration,
                ..
            }) => Ok(None),
            Reply::Error(error) => Err(LinkError::Device {
                what: "ReadCalibration",
                error,
            }),
            other => Err(unexpected("ReadCalibration", other)),
        }
    }

    /// Stores and activates a calibration on the device.
    pub fn write_calibration(&mut self, cal: &WireCalibration) -> Result<(), LinkError> {
        self.expect_ack(Request::WriteCalibration(cal.clone()), "WriteCalibration")?;
        self.identity.calib_id = Some(cal.id);
        Ok(())
    }

    /// Fixes the exposure (µs) or returns to auto-exposure (`None`).
    pub fn set_exposure(&mut self, us: Option<u32>) -> Result<(), LinkError> {
        self.expect_ack(Request::SetExposure(us), "SetExposure")
    }

    /// Sets the frame pairs one stem reading combines (1–16; the device keeps the count
    /// until it restarts, and the link sets it again after a reconnect). A count the device
    /// refuses is [`LinkError::Device`] with `InvalidSetting`, the count unchanged.
    pub fn set_exposures(&mut self, count: u8) -> Result<(), LinkError> {
        self.expect_ack(Request::SetExposures(count), "SetExposures")?;
        self.identity.exposures = count;
        self.exposures = Some(count);
        Ok(())
    }

    /// Runs the device self-test.
    pub fn self_test(&mut self) -> Result<SelfTestReport, LinkError> {
        match self.request_inner(Request::SelfTest, "SelfTest", true)? {
            Reply::SelfTest(s) => Ok(s),
            other => Err(unexpected("SelfTest", other)),
        }
    }

    /// Captures a raw frame pair (laser off, laser on) into the device's buffers.
    pub fn capture_frames(&mut self) -> Result<FrameSetInfo, LinkError> {
        // Not re-sent blindly: a second capture would replace the first. A lost reply just
        // means asking again, which is harmless here since nothing was read yet.
        match self.request_inner(Request::CaptureFrames, "CaptureFrames", true)? {
            Reply::FramesReady(f) => Ok(f),
            Reply::Error(error) => Err(LinkError::Device {
                what: "CaptureFrames",
                error,
            }),
            other => Err(unexpected("CaptureFrames", other)),
        }
    }

    /// Reads one frame of the captured pair `info`, chunk by chunk (a lost chunk is asked
    /// for again); `progress` gets the bytes read so far.
    pub fn read_frame(
        &mut self,
        info: &FrameSetInfo,
        frame: FrameSel,
        mut progress: impl FnMut(usize),
    ) -> Result<Vec<u8>, LinkError> {
        let total = info.width as usize * info.height as usize;
        let mut data = Vec::with_capacity(total);
        // Chunk size adapts to the line: a chunk frame lost to noise halves it (a damaged
        // byte costs a whole frame, so short frames get through a noisy line), a good one
        // doubles it back up to FRAME_CHUNK_MAX.
        let mut chunk_len = FRAME_CHUNK_MAX;
        let mut failures = 0;
        while data.len() < total {
            let request = Request::ReadFrameChunk {
                capture: info.capture,
                frame,
                offset: data.len() as u32,
                max_len: chunk_len as u16,
            };
            match self.request_inner(request, "ReadFrameChunk", false) {
                Ok(Reply::FrameChunk {
                    capture,
                    frame: f,
                    offset,
                    total: t,
                    data: chunk,
                }) if capture == info.capture
                    && f == frame
                    && offset as usize == data.len()
                    && t as usize == total
                    && !chunk.is_empty() =>
                {
                    let take = chunk.len().min(total - data.len());
                    data.extend_from_slice(&chunk[..take]);
                    progress(data.len());
                    failures = 0;
                    chunk_len = (chunk_len * 2).min(FRAME_CHUNK_MAX);
                }
                Ok(Reply::Error(error)) => {
                    return Err(LinkError::Device {
                        what: "ReadFrameChunk",
                        error,
                    })
                }
                Ok(other) => return Err(unexpected("ReadFrameChunk", other)),
                Err(LinkError::Timeout { .. }) if failures < 4 * self.cfg.attempts.max(1) => {
                    failures += 1;
                    self.counters.retries += 1;
                    chunk_len = (chunk_len / 2).max(32);
                }
                Err(e) => return Err(e),
            }
        }
        Ok(data)
    }
}
