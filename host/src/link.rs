//! The serial link to a Tangent: open a port by path, speak the wire protocol
//! (`tangent_core::protocol`, `docs/protocol.md`), survive the field.
//!
//! What "survive" means, and how:
//!
//! * **Garbage, dropped or corrupted bytes, partial frames.** Frames end at 0x00 (COBS), so
//!   the receiver throws away at most the frame in progress; the CRC rejects corrupted ones.
//!   The host sends a lone 0x00 after opening so the device drops any half-received frame.
//! * **Lost frames.** Requests wait for the reply carrying their tag and are re-sent (with a
//!   fresh tag) after [`LinkConfig::reply_timeout`]; only idempotent requests are re-sent.
//!   Readings carry a sequence number: a gap (or an idle link, which could hide a lost
//!   *last* reading) makes the link ask `History { after_seq }` and the device re-sends what
//!   it kept (its last [`protocol::codes::HISTORY_LEN`] readings). Duplicates (a reading seen twice) are dropped. So the
//!   caller of [`Link::next_reading`] sees every reading once, in sequence order.
//! * **Cable yanked / port gone.** A read or write error closes the port; the link re-opens
//!   the same path until [`LinkConfig::reconnect_timeout`], repeats the handshake (protocol
//!   version, reboot detection), restarts a running stream and recovers the readings made
//!   meanwhile from the history.
//! * **Device rebooted.** Sequence numbers restart at 1 after a reboot; the link notices
//!   (boot banner, `last_seq` or uptime going backwards) and starts counting afresh.
//! * **Another protocol version / not a Tangent.** A CRC-valid frame of another version is
//!   a [`LinkError::VersionMismatch`] naming both versions; a port that answers nothing
//!   valid is a [`LinkError::NotATangent`].
//!
//! The receive side is the core's [`Decoder`], the one the firmware runs, here owning its
//! buffer (a `Vec<u8>` of [`MAX_FRAME_LEN`]).

use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use tangent_core::measurement::Mode;
use tangent_core::protocol::{
    self, Board, Decoder, DeviceError, ErrorCode, Feed, FrameEncoder, FromDevice, LinkStats,
    ModeStoreState, ProtocolError, Reading, Request, ToDevice, MAX_FRAME_LEN, PROTOCOL_VERSION,
    UNSOLICITED,
};
use tangent_field::seq::{HistoryOutcome, SeqTracker};

mod commands;
mod ports;
mod reply;

pub use ports::{device_id, list_ports, usb_serial_number, PortCandidate};
pub use reply::{DeviceIdentity, Reply};

/// Line rate set on the port. USB CDC-ACM and ptys ignore it; a USB–UART adapter wired to
/// the board's UART would need it.
pub const BAUD: u32 = 115_200;

/// How long one `read` on the port may block: bounds the latency of deadlines.
const POLL: Duration = Duration::from_millis(20);

/// Most bytes taken from the port per `read`.
const READ_CHUNK: usize = 1024;

/// Timing of the link.
#[derive(Debug, Clone)]
pub struct LinkConfig {
    /// How long to wait for the reply to one attempt of a request.
    pub reply_timeout: Duration,
    /// Attempts of an idempotent request before giving up.
    pub attempts: u32,
    /// How long to keep trying to re-open a port that went away (`None`: forever).
    pub reconnect_timeout: Option<Duration>,
    /// After this long without any frame, ask the device for readings we may have missed
    /// (a lost last reading has no successor to reveal the gap).
    pub idle_check: Duration,
}

impl Default for LinkConfig {
    fn default() -> Self {
        LinkConfig {
            reply_timeout: Duration::from_millis(1500),
            attempts: 4,
            reconnect_timeout: Some(Duration::from_secs(30)),
            idle_check: Duration::from_millis(1000),
        }
    }
}

/// Why the link failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The port could not be opened.
    #[error("cannot open {path}: {source} (is the Tangent plugged in? `tangent devices` lists the ports that look like one)")]
    Open {
        /// The port.
        path: String,
        /// Why.
        source: serialport::Error,
    },
    /// Nothing on the port speaks the Tangent protocol.
    #[error("{path} does not look like a Tangent: no valid answer within {waited:?} ({bytes} bytes received, {malformed} malformed frames). Check the port with `tangent devices`")]
    NotATangent {
        /// The port.
        path: String,
        /// How long we waited.
        waited: Duration,
        /// Bytes received meanwhile.
        bytes: usize,
        /// Frames that failed COBS/CRC.
        malformed: u32,
    },
    /// The device speaks another version of the protocol.
    #[error("the device on {path} speaks protocol version {device}, this tangent speaks version {host}: {}", if *device > *host { "update the host software" } else { "update the firmware (`tangent flash`)" })]
    VersionMismatch {
        /// The port.
        path: String,
        /// The device's version.
        device: u8,
        /// Ours ([`PROTOCOL_VERSION`]).
        host: u8,
    },
    /// A request got no reply.
    #[error("no answer to {what} from {path} after {attempts} attempt(s) of {each:?}")]
    Timeout {
        /// The port.
        path: String,
        /// The request.
        what: &'static str,
        /// Attempts made.
        attempts: u32,
        /// Wait per attempt.
        each: Duration,
    },
    /// The port went away and did not come back.
    #[error("lost the device on {path} and it did not come back within {waited:?}")]
    Disconnected {
        /// The port.
        path: String,
        /// How long we tried to re-open it.
        waited: Duration,
    },
    /// The device answered with an error.
    #[error("the device refused {what}: {error}")]
    Device {
        /// The request.
        what: &'static str,
        /// The device's error.
        error: DeviceError,
    },
    /// The device answered something that does not fit the request.
    #[error("unexpected answer to {what}: {got}")]
    Unexpected {
        /// The request.
        what: &'static str,
        /// What came back (debug form).
        got: String,
    },
}

/// Something the user may want to hear about while the link copes on its own.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkEvent {
    /// The port failed; re-opening it.
    Lost(String),
    /// The port is back (after this many attempts).
    Reconnected {
        /// Open attempts.
        attempts: u32,
    },
    /// The device rebooted: its sequence numbers restart.
    Rebooted,
    /// A trigger press or a stream reading could not be measured (the error's `Display` is
    /// the sentence for the forester, `protocol::codes`).
    MeasurementFailed(DeviceError),
    /// Readings could not be recovered (they fell out of the device's history).
    Unrecoverable {
        /// First missing sequence number.
        from: u32,
        /// Last missing sequence number.
        to: u32,
    },
}

/// Host-side counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkCounters {
    /// Frames received and decoded.
    pub frames_ok: u64,
    /// Frames rejected (COBS, CRC, too short, undecodable).
    pub malformed: u64,
    /// Frames longer than [`MAX_FRAME_LEN`].
    pub oversize: u64,
    /// Frames of another protocol version.
    pub version_mismatch: u64,
    /// Readings received more than once and dropped.
    pub duplicates: u64,
    /// Readings obtained through `History` after a gap or a reconnect.
    pub history_requests: u64,
    /// Readings lost for good (out of the device's history).
    pub lost: u64,
    /// Times the port was re-opened.
    pub reconnects: u64,
    /// Reboots of the device noticed.
    pub reboots: u64,
    /// Request attempts that timed out and were re-sent.
    pub retries: u64,
}

/// Receiver of [`LinkEvent`]s.
type EventSink = Box<dyn FnMut(&LinkEvent) + Send>;

/// A link to one Tangent on one serial port.
pub struct Link {
    path: String,
    cfg: LinkConfig,
    port: Option<Box<dyn serialport::SerialPort>>,
    /// Frames in progress.
    rx: Decoder<Vec<u8>>,
    /// Bytes read from the port and not yet fed to `rx`: `inbox[inbox_at..]`.
    inbox: Vec<u8>,
    inbox_at: usize,
    enc: FrameEncoder,
    next_tag: u16,
    identity: DeviceIdentity,
    seq: SeqTracker,
    streaming: bool,
    last_frame_at: Instant,
    last_check_at: Instant,
    counters: LinkCounters,
    bytes_in: usize,
    peer_version: Option<u8>,
    on_event: Option<EventSink>,
    /// The mode asked for with [`Link::set_mode`], set again after a device restart.
    mode: Option<Mode>,
    /// The count asked for with [`Link::set_exposures`], set again after a device restart.
    exposures: Option<u8>,
}

/// What one frame turned out to be.
#[allow(clippy::large_enum_variant)]
enum Incoming {
    Message(u16, Reply),
    Rejected,
}

impl Link {
    /// Opens `path`, checks that a Tangent of our protocol version answers, and starts
    /// taking readings after the device's current last sequence number.
    pub fn open(path: &str, cfg: LinkConfig) -> Result<Link, LinkError> {
        let port = open_port(path)?;
        let now = Instant::now();
        let mut link = Link {
            path: path.to_string(),
            cfg,
            port: Some(port),
            rx: Decoder::new(vec![0; MAX_FRAME_LEN]),
            inbox: Vec::with_capacity(READ_CHUNK),
            inbox_at: 0,
            enc: FrameEncoder::new(),
            next_tag: 1,
            identity: DeviceIdentity {
                protocol_version: PROTOCOL_VERSION,
                fw_version: String::new(),
                board: Board::Emulated,
                calib_id: None,
                frame_width: 0,
                frame_height: 0,
                uptime_ms: 0,
                last_seq: 0,
                link: LinkStats::default(),
                mode: Mode::Cylinder,
                mode_store: ModeStoreState::Empty,
                // Replaced by the handshake's identity.
                exposures: 1,
            },
            seq: SeqTracker::default(),
            streaming: false,
            last_frame_at: now,
            last_check_at: now,
            counters: LinkCounters::default(),
            bytes_in: 0,
            peer_version: None,
            on_event: None,
            mode: None,
            exposures: None,
        };
        link.handshake()?;
        link.seq.resume_after(link.identity.last_seq);
        Ok(link)
    }

    /// Calls `f` for every [`LinkEvent`] (e.g. to tell the user the cable came loose).
    pub fn on_event(&mut self, f: impl FnMut(&LinkEvent) + Send + 'static) {
        self.on_event = Some(Box::new(f));
    }

    /// The port path.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The device, as of the last handshake or `DeviceInfo`.
    pub fn identity(&self) -> &DeviceIdentity {
        &self.identity
    }

    /// Host-side counters.
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    /// Highest sequence number delivered (or given up on).
    pub fn last_seq(&self) -> u32 {
        self.seq.last()
    }

    /// Delivers readings after `seq` from now on (e.g. the last one already in the field
    /// log, so readings taken while the host was away are recovered from the device's
    /// history). Values above the device's `last_seq` are ignored.
    pub fn resume_after(&mut self, seq: u32) {
        if seq <= self.identity.last_seq {
            self.seq.resume_after(seq);
        }
    }

    fn emit(&mut self, e: LinkEvent) {
        if let Some(f) = self.on_event.as_mut() {
            f(&e);
        }
    }

    /// `DeviceInfo` with a version check and reboot detection; what opening and re-opening
    /// do.
    fn handshake(&mut self) -> Result<(), LinkError> {
        let started = Instant::now();
        // A lone delimiter ends whatever partial frame the device holds.
        self.write_bytes(&[protocol::DELIMITER])?;
        let was = self.identity.clone();
        let info = match self.request_inner(Request::DeviceInfo, "DeviceInfo", true) {
            Ok(Reply::Info(i)) => i,
            Ok(other) => {
                return Err(LinkError::Unexpected {
                    what: "DeviceInfo",
                    got: format!("{other:?}"),
                })
            }
            Err(LinkError::Timeout { .. }) => {
                if let Some(v) = self.peer_version {
                    return Err(self.version_error(v));
                }
                return Err(LinkError::NotATangent {
                    path: self.path.clone(),
                    waited: started.elapsed(),
                    bytes: self.bytes_in,
                    malformed: self.counters.malformed as u32,
                });
            }
            Err(e) => return Err(e),
        };
        if info.protocol_version != PROTOCOL_VERSION {
            return Err(self.version_error(info.protocol_version));
        }
        let rebooted = !was.fw_version.is_empty()
            && (info.last_seq < self.seq.last() || info.uptime_ms < self.seq.newest_ms());
        self.identity = info;
        if rebooted {
            self.device_rebooted();
        }
        Ok(())
    }

    fn version_error(&self, device: u8) -> LinkError {
        LinkError::VersionMismatch {
            path: self.path.clone(),
            device,
            host: PROTOCOL_VERSION,
        }
    }

    fn device_rebooted(&mut self) {
        self.counters.reboots += 1;
        self.seq.restart();
        self.streaming = false;
        self.emit(LinkEvent::Rebooted);
    }

    fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        loop {
            let r = match self.port.as_mut() {
                Some(p) => p.write_all(bytes).and_then(|()| p.flush()),
                None => Err(std::io::Error::new(ErrorKind::NotConnected, "port closed")),
            };
            match r {
                Ok(()) => return Ok(()),
                Err(e) => self.reconnect(&e.to_string())?,
            }
        }
    }

    fn send(&mut self, request: Request) -> Result<u16, LinkError> {
        let tag = self.next_tag;
        self.next_tag = self.next_tag.checked_add(1).unwrap_or(1);
        let frame = self
            .enc
            .encode(&ToDevice { tag, request })
            .map(|b| b.to_vec())
            .map_err(|e| LinkError::Unexpected {
                what: "encode",
                got: e.to_string(),
            })?;
        self.write_bytes(&frame)?;
        Ok(tag)
    }

    /// Re-opens the port (until the reconnect timeout), then re-does the handshake,
    /// restarts a running stream and asks for the readings missed meanwhile.
    fn reconnect(&mut self, why: &str) -> Result<(), LinkError> {
        self.port = None;
        self.rx.reset();
        self.inbox.clear();
        self.inbox_at = 0;
        self.emit(LinkEvent::Lost(why.to_string()));
        let started = Instant::now();
        let mut attempts = 0;
        loop {
            attempts += 1;
            std::thread::sleep(Duration::from_millis(100));
            if let Ok(p) = open_port(&self.path) {
                self.port = Some(p);
                break;
            }
            if let Some(limit) = self.cfg.reconnect_timeout {
                if started.elapsed() > limit {
                    return Err(LinkError::Disconnected {
                        path: self.path.clone(),
                        waited: started.elapsed(),
                    });
                }
            }
        }
        self.counters.reconnects += 1;
        self.emit(LinkEvent::Reconnected { attempts });
        // The handshake itself may hit another disconnect: it then recurses through
        // `write_bytes`, bounded by the reconnect timeout.
        self.handshake()?;
        // A device that restarted keeps its mode in its mode store, but one whose store
        // failed, or a board without one, comes back in the default: the readings must stay
        // of the asked kind.
        if let Some(mode) = self.mode.filter(|m| *m != self.identity.mode) {
            self.expect_ack(Request::SetMode(mode), "SetMode")?;
            self.note_mode_set(mode);
        }
        // The count of exposures lives in the device's RAM: a restart forgot it.
        if let Some(count) = self.exposures.filter(|n| *n != self.identity.exposures) {
            self.set_exposures(count)?;
        }
        if self.streaming {
            self.request_inner(Request::StartStream, "StartStream", true)?;
        }
        self.recover()?;
        Ok(())
    }

    /// Reads until one frame ends or `deadline` passes.
    fn pump(&mut self, deadline: Instant) -> Result<Option<Incoming>, LinkError> {
        loop {
            if let Some(incoming) = self.next_frame() {
                return Ok(Some(incoming));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            self.inbox.resize(READ_CHUNK, 0);
            self.inbox_at = 0;
            let timeout = (deadline - now).min(POLL);
            let r = match self.port.as_mut() {
                Some(p) => p
                    .set_timeout(timeout)
                    .map_err(std::io::Error::from)
                    .and_then(|()| p.read(&mut self.inbox)),
                None => Err(std::io::Error::new(ErrorKind::NotConnected, "port closed")),
            };
            let n = *r.as_ref().unwrap_or(&0);
            self.inbox.truncate(n);
            match r {
                Ok(0) => self.reconnect("end of file")?,
                Ok(n) => self.bytes_in += n,
                Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::Interrupted => {
                }
                Err(e) => self.reconnect(&e.to_string())?,
            }
        }
    }

    /// Feeds the unread bytes to the decoder until one frame ends (`None` when they run out).
    fn next_frame(&mut self) -> Option<Incoming> {
        let input = self.inbox.get(self.inbox_at..).unwrap_or_default();
        let (incoming, remaining) = match self.rx.feed::<FromDevice>(input) {
            Feed::Consumed => (None, 0),
            Feed::Frame { message, remaining } => {
                self.counters.frames_ok += 1;
                self.last_frame_at = Instant::now();
                let reply = Reply::from(message.response);
                (Some(Incoming::Message(message.tag, reply)), remaining.len())
            }
            Feed::Rejected { error, remaining } => {
                match error {
                    ProtocolError::VersionMismatch { received } => {
                        self.counters.version_mismatch += 1;
                        self.peer_version = Some(received);
                    }
                    ProtocolError::Oversize => self.counters.oversize += 1,
                    _ => self.counters.malformed += 1,
                }
                (Some(Incoming::Rejected), remaining.len())
            }
        };
        self.inbox_at = self.inbox.len() - remaining;
        incoming
    }

    /// Handles a message that is not the awaited reply: readings go to the tracker, a
    /// boot banner means a reboot.
    fn side_message(&mut self, tag: u16, reply: Reply) {
        match reply {
            Reply::Reading(r) => {
                let duplicate = self.seq.accept(r);
                self.counters.duplicates += duplicate as u64;
            }
            Reply::Error(e) if e.code == ErrorCode::MeasurementFailed => {
                self.emit(LinkEvent::MeasurementFailed(e));
            }
            Reply::Info(i) if tag == UNSOLICITED => {
                // The boot banner.
                let had_any = self.seq.last() > 0 || self.seq.has_gap();
                self.identity = i;
                if had_any {
                    self.device_rebooted();
                }
            }
            _ => {}
        }
    }

    /// Sends `request` and returns the reply with its tag; re-sends idempotent requests.
    fn request_inner(
        &mut self,
        request: Request,
        what: &'static str,
        idempotent: bool,
    ) -> Result<Reply, LinkError> {
        let attempts = if idempotent {
            self.cfg.attempts.max(1)
        } else {
            1
        };
        for attempt in 0..attempts {
            if attempt > 0 {
                self.counters.retries += 1;
            }
            let tag = self.send(request.clone())?;
            let deadline = Instant::now() + self.cfg.reply_timeout;
            while let Some(incoming) = self.pump(deadline)? {
                match incoming {
                    Incoming::Message(t, reply) if t == tag => {
                        if let Reply::Reading(r) = &reply {
                            if self.seq.accept(*r) {
                                self.counters.duplicates += 1;
                            }
                            if !matches!(request, Request::Measure) {
                                // A History replay (or a stream): more follows.
                                continue;
                            }
                        }
                        return Ok(reply);
                    }
                    Incoming::Message(t, Reply::Error(e))
                        if t == UNSOLICITED && e.code == ErrorCode::UnsupportedVersion =>
                    {
                        // The device could not read our frame: it speaks another version.
                        return Err(self.version_error(self.peer_version.unwrap_or(0)));
                    }
                    Incoming::Message(t, reply) => self.side_message(t, reply),
                    Incoming::Rejected => {
                        if let (Some(v), true) =
                            (self.peer_version, self.identity.fw_version.is_empty())
                        {
                            return Err(self.version_error(v));
                        }
                    }
                }
            }
        }
        Err(LinkError::Timeout {
            path: self.path.clone(),
            what,
            attempts,
            each: self.cfg.reply_timeout,
        })
    }

    /// Asks the device for the readings after our last one; gives up (and reports) those
    /// that fell out of its history.
    fn recover(&mut self) -> Result<(), LinkError> {
        self.counters.history_requests += 1;
        self.last_check_at = Instant::now();
        let after_seq = self.seq.history_requested();
        let reply = self.request_inner(Request::History { after_seq }, "History", true)?;
        let Reply::HistoryEnd { last_seq } = reply else {
            return Err(LinkError::Unexpected {
                what: "History",
                got: format!("{reply:?}"),
            });
        };
        match self.seq.history_ended(after_seq, last_seq) {
            HistoryOutcome::Rebooted => {
                // Sequence numbers went backwards: a reboot we had not noticed.
                self.device_rebooted();
                self.recover()
            }
            HistoryOutcome::Done { lost } => {
                for (from, to) in lost {
                    self.counters.lost += (to - from + 1) as u64;
                    self.emit(LinkEvent::Unrecoverable { from, to });
                }
                Ok(())
            }
        }
    }

    /// The next reading, in sequence order, each exactly once; `None` when `timeout`
    /// passes without one. Recovers gaps and checks for lost trailing readings when idle.
    pub fn next_reading(&mut self, timeout: Duration) -> Result<Option<Reading>, LinkError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(r) = self.seq.pop_ready() {
                return Ok(Some(r));
            }
            let now = Instant::now();
            if self.seq.has_gap()
                || (now.duration_since(self.last_frame_at) >= self.cfg.idle_check
                    && now.duration_since(self.last_check_at) >= self.cfg.idle_check)
            {
                self.recover()?;
                continue;
            }
            if now >= deadline {
                return Ok(None);
            }
            let wake =
                deadline.min(self.last_check_at.max(self.last_frame_at) + self.cfg.idle_check);
            if let Some(Incoming::Message(tag, reply)) = self.pump(wake.max(now))? {
                self.side_message(tag, reply);
            }
        }
    }

    /// Refreshes [`Link::identity`].
    pub fn device_info(&mut self) -> Result<DeviceIdentity, LinkError> {
        match self.request_inner(Request::DeviceInfo, "DeviceInfo", true)? {
            Reply::Info(i) => {
                self.identity = i.clone();
                Ok(i)
            }
            other => Err(unexpected("DeviceInfo", other)),
        }
    }

    /// One measurement (as a trigger press). The reading itself is delivered by
    /// [`Link::next_reading`], so a reply lost on the wire is recovered from the history
    /// rather than measured twice; a device error is returned.
    pub fn measure(&mut self) -> Result<(), LinkError> {
        match self.request_inner(Request::Measure, "Measure", false) {
            Ok(Reply::Reading(_)) => Ok(()),
            Ok(Reply::Error(error)) => Err(LinkError::Device {
                what: "Measure",
                error,
            }),
            Ok(other) => Err(unexpected("Measure", other)),
            // Not re-sent (it would measure twice): if the device did measure, the
            // reading comes through the history.
            Err(LinkError::Timeout { .. }) => self.recover(),
            Err(e) => Err(e),
        }
    }

    /// Starts continuous measurement (as a held trigger); restarted after reconnects.
    pub fn start_stream(&mut self) -> Result<(), LinkError> {
        self.expect_ack(Request::StartStream, "StartStream")?;
        self.streaming = true;
        Ok(())
    }

    /// Selects the instrument the device measures with from now on (and again after it
    /// restarts). A mode the firmware cannot measure is [`LinkError::Device`] with the
    /// sentence of [`Failure::UnsupportedMode`](tangent_core::protocol::codes::Failure).
    /// The device acknowledges a mode once its mode store holds it (a store that fails
    /// is [`LinkError::Device`] with `StorageFailure`, the mode unchanged).
    pub fn set_mode(&mut self, mode: Mode) -> Result<(), LinkError> {
        self.expect_ack(Request::SetMode(mode), "SetMode")?;
        self.note_mode_set(mode);
        self.mode = Some(mode);
        Ok(())
    }

    /// The identity after an acknowledged `SetMode`: the mode, now stored (unless the board
    /// keeps none).
    fn note_mode_set(&mut self, mode: Mode) {
        self.identity.mode = mode;
        if self.identity.mode_store != ModeStoreState::Volatile {
            self.identity.mode_store = ModeStoreState::Loaded(mode);
        }
    }

    /// Stops continuous measurement.
    pub fn stop_stream(&mut self) -> Result<(), LinkError> {
        self.streaming = false;
        self.expect_ack(Request::StopStream, "StopStream")
    }

    fn expect_ack(&mut self, request: Request, what: &'static str) -> Result<(), LinkError> {
        match self.request_inner(request, what, true)? {
            Reply::Ack => Ok(()),
            Reply::Error(error) => Err(LinkError::Device { what, error }),
            other => Err(unexpected(what, other)),
        }
    }
}

fn unexpected(what: &'static str, got: Reply) -> LinkError {
    LinkError::Unexpected {
        what,
        got: format!("{got:?}"),
    }
}

fn open_port(path: &str) -> Result<Box<dyn serialport::SerialPort>, LinkError> {
    serialport::new(path, BAUD)
        .timeout(POLL)
        .open()
        .map_err(|source| LinkError::Open {
            path: path.to_string(),
            source,
        })
}
