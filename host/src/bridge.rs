//! The field app's server (`tangent app`): the page's files over HTTP on localhost (a
//! secure context, so the browser allows Web Serial and IndexedDB persistence), and a
//! **WebSocket bridge** to the caliper — the app's second transport, for browsers or
//! sessions where Web Serial cannot reach the port (a pty, the emulated caliper under QEMU,
//! headless tests).
//!
//! The bridge moves bytes and nothing else: every WebSocket binary message from the page is
//! written to the device whole, every byte from the device goes to the page; framing, CRC
//! and the protocol stay in the page's WebAssembly core. One page at a time: a new
//! connection replaces the previous one. While no page is connected the device's bytes are
//! dropped, as on a pulled cable.
//!
//! With `--emulator`, `/control/…` lets a test do to the emulated caliper what a forester
//! does to a real one, and answers only once the caliper has done it (so a test waits for
//! events, never for time): `trigger?n=` (trigger presses: `Measure`s with tag 0, whose
//! readings reach the page unsolicited, as the hardware trigger's do; answered with their
//! sequence numbers), `hold` and `release` (the trigger held: `StartStream`, then
//! `StopStream`, answered once the stream has ended, with the streamed readings' numbers), `cut` (the
//! cable pulled: the page's connection is closed and refused until `plug`, or for `ms=`,
//! while the device keeps running; with `measuring=1` a trigger press goes just before it,
//! and the answer waits for that reading), `plug`, and `idle` (waits until the device has
//! finished all it was asked, ends any stream, and answers its last sequence number). The
//! controls see the device's answers by decoding a copy of its byte stream; what reaches
//! the page is untouched.

use std::collections::VecDeque;
use std::io::{Cursor, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use tangent_core::protocol::{
    Decoder, ErrorCode, Feed, FrameEncoder, FromDevice, Request, Response, ToDevice, MAX_FRAME_LEN,
    UNSOLICITED,
};

/// Longest HTTP request head read.
const MAX_HEAD: usize = 16 * 1024;

/// How long the bridge's WebSocket loop waits for the page before looking at the device's
/// bytes again.
const POLL: Duration = Duration::from_millis(10);

/// Longest a control waits for one answer of the device (a measurement takes well under a
/// second under QEMU; this only ends a control whose device has died).
const ANSWER_TIMEOUT: Duration = Duration::from_secs(60);

/// Where the device's bytes go and where the page's come from.
pub struct Bridge {
    /// Writes to the device.
    device: Mutex<Box<dyn Write + Send>>,
    /// The connected page's outbox.
    page: Mutex<Option<Sender<Vec<u8>>>>,
    /// Bumped to close the current page's connection.
    generation: AtomicU64,
    /// Whether connections are refused (a pulled cable).
    cut: Mutex<Cut>,
    /// Whether `/control/` is served (the emulated caliper only).
    controls: bool,
    /// The device's answers to the controls, decoded from a copy of its bytes.
    answers: Mutex<Answers>,
    /// Signalled when an answer arrives.
    answered: Condvar,
    /// One control at a time owns the answers.
    control_turn: Mutex<()>,
}

/// Whether a control starts from an empty answer queue (all but `release`, which collects
/// what its `hold` streamed).
#[derive(Clone, Copy, PartialEq, Debug)]
enum Fresh {
    Yes,
    No,
}

/// The state of the bridge's "cable".
#[derive(Clone, Copy, PartialEq, Debug)]
enum Cut {
    /// Plugged in.
    No,
    /// Pulled until `/control/plug`.
    UntilPlugged,
    /// Pulled until then.
    Until(Instant),
}

/// What the device answered with tag [`UNSOLICITED`] (the controls' requests), in order.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Answer {
    /// A reading with this sequence number.
    Reading(u32),
    /// A measurement that failed.
    Failed,
    /// An acknowledgement (`StartStream`, `StopStream`).
    Ack,
}

/// The controls' view of the device's byte stream.
struct Answers {
    decoder: Decoder<Vec<u8>>,
    queue: VecDeque<Answer>,
    /// Highest sequence number seen in any reading (whatever its tag).
    last_seq: u32,
    /// Whether the device's boot banner has been seen (bytes sent before it may be lost).
    booted: bool,
}

impl Answers {
    /// Decodes `bytes`, queueing the answers with tag [`UNSOLICITED`].
    fn feed(&mut self, bytes: &[u8]) {
        let mut input = bytes;
        loop {
            let (answer, seq, remaining) = match self.decoder.feed::<FromDevice>(input) {
                Feed::Consumed => break,
                Feed::Rejected { remaining, .. } => (None, None, remaining),
                Feed::Frame { message, remaining } => {
                    let seq = match &message.response {
                        Response::Reading(r) => Some(r.seq),
                        Response::Info(_) if message.tag == UNSOLICITED => {
                            self.booted = true;
                            None
                        }
                        _ => None,
                    };
                    let answer = match message.response {
                        _ if message.tag != UNSOLICITED => None,
                        Response::Reading(r) => Some(Answer::Reading(r.seq)),
                        Response::Error(e) if e.code == ErrorCode::MeasurementFailed => {
                            Some(Answer::Failed)
                        }
                        Response::Ack => Some(Answer::Ack),
                        // The boot banner and the like answer no control.
                        _ => None,
                    };
                    (answer, seq, remaining)
                }
            };
            if let Some(seq) = seq {
                self.last_seq = self.last_seq.max(seq);
            }
            if let Some(answer) = answer {
                self.queue.push_back(answer);
            }
            input = remaining;
        }
    }
}

impl Bridge {
    /// A bridge writing to `device`; `controls` enables `/control/`.
    pub fn new(device: Box<dyn Write + Send>, controls: bool) -> Arc<Bridge> {
        Arc::new(Bridge {
            device: Mutex::new(device),
            page: Mutex::new(None),
            generation: AtomicU64::new(0),
            cut: Mutex::new(Cut::No),
            controls,
            answers: Mutex::new(Answers {
                decoder: Decoder::new(vec![0; MAX_FRAME_LEN]),
                queue: VecDeque::new(),
                last_seq: 0,
                booted: false,
            }),
            answered: Condvar::new(),
            control_turn: Mutex::new(()),
        })
    }

    /// Bytes from the device: to the page, if one is connected (and, with controls, to
    /// their decoder).
    pub fn from_device(&self, bytes: &[u8]) {
        if self.controls {
            if let Ok(mut answers) = self.answers.lock() {
                answers.feed(bytes);
                self.answered.notify_all();
            }
        }
        if let Ok(page) = self.page.lock() {
            if let Some(tx) = page.as_ref() {
                let _ = tx.send(bytes.to_vec());
            }
        }
    }

    /// Writes one whole message to the device (never interleaved with another).
    fn to_device(&self, bytes: &[u8]) -> std::io::Result<()> {
        let mut device = self
            .device
            .lock()
            .map_err(|_| std::io::Error::other("device writer poisoned"))?;
        device.write_all(bytes)?;
        device.flush()
    }

    /// Writes to `device` from now on (the port was re-opened).
    pub fn replace_device(&self, device: Box<dyn Write + Send>) {
        if let Ok(mut d) = self.device.lock() {
            *d = device;
        }
    }

    /// Closes the page's connection (the device's bytes are dropped until it comes back).
    pub fn drop_page(&self) {
        self.generation.fetch_add(1, Ordering::SeqCst);
        if let Ok(mut page) = self.page.lock() {
            *page = None;
        }
    }

    fn send_request(&self, request: Request) -> std::io::Result<()> {
        let frame = FrameEncoder::new()
            .encode(&ToDevice {
                tag: UNSOLICITED,
                request,
            })
            .map(<[u8]>::to_vec)
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        self.to_device(&frame)
    }

    /// The controls' turn; with [`Fresh::Yes`] answers still queued from before are stale.
    fn control_turn(&self, fresh: Fresh) -> std::io::Result<MutexGuard<'_, ()>> {
        let turn = self
            .control_turn
            .lock()
            .map_err(|_| std::io::Error::other("controls poisoned"))?;
        let mut answers = self.wait_answers(|a| a.booted)?;
        if fresh == Fresh::Yes {
            answers.queue.clear();
        }
        Ok(turn)
    }

    /// Waits (at most [`ANSWER_TIMEOUT`]) until `ready` holds of the answers.
    fn wait_answers(
        &self,
        ready: impl Fn(&Answers) -> bool,
    ) -> std::io::Result<MutexGuard<'_, Answers>> {
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        let mut answers = self.lock_answers()?;
        while !ready(&answers) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::TimedOut,
                    format!("the emulated caliper did not answer within {ANSWER_TIMEOUT:?}"),
                ));
            }
            answers = self
                .answered
                .wait_timeout(answers, left)
                .map_err(|_| std::io::Error::other("answers poisoned"))?
                .0;
        }
        Ok(answers)
    }

    fn lock_answers(&self) -> std::io::Result<MutexGuard<'_, Answers>> {
        self.answers
            .lock()
            .map_err(|_| std::io::Error::other("answers poisoned"))
    }

    /// The device's next answer to a control.
    fn next_answer(&self) -> std::io::Result<Answer> {
        let mut answers = self.wait_answers(|a| !a.queue.is_empty())?;
        answers
            .queue
            .pop_front()
            .ok_or_else(|| std::io::Error::other("an answer vanished"))
    }

    /// Waits for `n` measurements' answers: their readings' sequence numbers (`None` for a
    /// failed one).
    fn measurements(&self, n: u64) -> std::io::Result<Vec<Option<u32>>> {
        (0..n)
            .map(|_| match self.next_answer()? {
                Answer::Reading(seq) => Ok(Some(seq)),
                Answer::Failed => Ok(None),
                Answer::Ack => Err(std::io::Error::other(
                    "an acknowledgement where a measurement was expected",
                )),
            })
            .collect()
    }

    /// Waits for the acknowledgement of a stream request; returns the readings streamed
    /// before it.
    fn until_ack(&self) -> std::io::Result<Vec<Option<u32>>> {
        let mut streamed = Vec::new();
        loop {
            match self.next_answer()? {
                Answer::Ack => return Ok(streamed),
                Answer::Reading(seq) => streamed.push(Some(seq)),
                Answer::Failed => streamed.push(None),
            }
        }
    }

    fn pull_cable(&self, cut: Cut) {
        if let Ok(mut c) = self.cut.lock() {
            *c = cut;
        }
        if cut != Cut::No {
            self.drop_page();
        }
    }

    fn is_cut(&self) -> bool {
        match self.cut.lock().map(|c| *c) {
            Ok(Cut::No) => false,
            Ok(Cut::Until(t)) => Instant::now() < t,
            Ok(Cut::UntilPlugged) | Err(_) => true,
        }
    }
}

/// A control's answer: the sequence numbers of the readings it made (`null` for a failed
/// measurement), and the device's last one.
fn made(seqs: &[Option<u32>], last_seq: u32) -> String {
    serde_json::json!({ "seqs": seqs, "last_seq": last_seq }).to_string()
}

/// Serves `dir` and the bridge on `listener` until the process ends.
pub fn serve(listener: TcpListener, dir: PathBuf, bridge: Arc<Bridge>) {
    for stream in listener.incoming().flatten() {
        let dir = dir.clone();
        let bridge = bridge.clone();
        std::thread::spawn(move || {
            if let Err(e) = handle(stream, &dir, &bridge) {
                eprintln!("app server: {e}");
            }
        });
    }
}

/// A stream that first replays the request head already read.
struct Replay {
    head: Cursor<Vec<u8>>,
    stream: TcpStream,
}

impl Read for Replay {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if (self.head.position() as usize) < self.head.get_ref().len() {
            return self.head.read(buf);
        }
        self.stream.read(buf)
    }
}

impl Write for Replay {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.stream.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.stream.flush()
    }
}

fn read_head(stream: &mut TcpStream) -> std::io::Result<Vec<u8>> {
    let mut head = Vec::new();
    let mut buf = [0u8; 2048];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        if head.len() > MAX_HEAD {
            return Err(std::io::Error::other("request head too long"));
        }
        let n = stream.read(&mut buf)?;
        if n == 0 {
            // A connection the browser opened ahead of need and closed unused is no error.
            return Ok(head);
        }
        head.extend_from_slice(&buf[..n]);
    }
    Ok(head)
}

fn handle(mut stream: TcpStream, dir: &Path, bridge: &Arc<Bridge>) -> std::io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    let head = read_head(&mut stream)?;
    if !head.windows(4).any(|w| w == b"\r\n\r\n") {
        return Ok(());
    }
    let text = String::from_utf8_lossy(&head).into_owned();
    let mut words = text.split_whitespace();
    let (method, target) = (words.next().unwrap_or(""), words.next().unwrap_or("/"));
    let (path, query) = target.split_once('?').unwrap_or((target, ""));
    if path == "/bridge" {
        return websocket(stream, head, bridge);
    }
    if let Some(action) = path.strip_prefix("/control/") {
        let (status, body) = if bridge.controls {
            control(bridge, action, query)
        } else {
            (
                "404 Not Found",
                "controls are offered with --emulator only".to_string(),
            )
        };
        return respond(&mut stream, status, "text/plain", body.as_bytes());
    }
    if method != "GET" && method != "HEAD" {
        return respond(
            &mut stream,
            "405 Method Not Allowed",
            "text/plain",
            b"GET only",
        );
    }
    static_file(&mut stream, dir, path)
}

fn respond(stream: &mut TcpStream, status: &str, kind: &str, body: &[u8]) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-cache\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body)?;
    stream.flush()
}

fn content_type(path: &Path) -> &'static str {
    match path.extension().and_then(|e| e.to_str()).unwrap_or("") {
        "html" => "text/html; charset=utf-8",
        "js" => "text/javascript; charset=utf-8",
        "css" => "text/css; charset=utf-8",
        "wasm" => "application/wasm",
        "json" | "webmanifest" => "application/manifest+json",
        "svg" => "image/svg+xml",
        "png" => "image/png",
        _ => "application/octet-stream",
    }
}

fn static_file(stream: &mut TcpStream, dir: &Path, path: &str) -> std::io::Result<()> {
    let name = if path == "/" {
        "index.html"
    } else {
        path.trim_start_matches('/')
    };
    // Plain names inside the directory only: no `..`, no absolute paths.
    if name
        .split('/')
        .any(|part| part.is_empty() || part == ".." || part.starts_with('.'))
    {
        return respond(stream, "404 Not Found", "text/plain", b"not found");
    }
    let file = dir.join(name);
    match std::fs::read(&file) {
        Ok(body) => respond(stream, "200 OK", content_type(&file), &body),
        Err(_) => respond(stream, "404 Not Found", "text/plain", b"not found"),
    }
}

fn query_number(query: &str, key: &str, default: u64) -> u64 {
    query
        .split('&')
        .filter_map(|kv| kv.split_once('='))
        .find(|(k, _)| *k == key)
        .and_then(|(_, v)| v.parse().ok())
        .unwrap_or(default)
}

/// `/control/…`: what a forester does to the caliper, done to the emulated one; answered
/// (JSON, see [`made`]) once the device has done it.
fn control(bridge: &Arc<Bridge>, action: &str, query: &str) -> (&'static str, String) {
    let result = (|| -> std::io::Result<Vec<Option<u32>>> {
        match action {
            "trigger" => {
                let n = query_number(query, "n", 1);
                let _turn = bridge.control_turn(Fresh::Yes)?;
                (0..n).try_for_each(|_| bridge.send_request(Request::Measure))?;
                bridge.measurements(n)
            }
            "hold" => {
                let _turn = bridge.control_turn(Fresh::Yes)?;
                bridge.send_request(Request::StartStream)?;
                bridge.until_ack()
            }
            "release" => {
                // The readings streamed since `hold` are still queued.
                let _turn = bridge.control_turn(Fresh::No)?;
                bridge.send_request(Request::StopStream)?;
                // The device is one task: once StopStream is acknowledged, nothing more streams.
                bridge.until_ack()
            }
            "cut" => {
                let cut = match query_number(query, "ms", 0) {
                    0 => Cut::UntilPlugged,
                    ms => Cut::Until(Instant::now() + Duration::from_millis(ms)),
                };
                if query_number(query, "measuring", 0) == 0 {
                    bridge.pull_cable(cut);
                    return Ok(Vec::new());
                }
                let _turn = bridge.control_turn(Fresh::Yes)?;
                bridge.send_request(Request::Measure)?;
                bridge.pull_cable(cut);
                bridge.measurements(1)
            }
            "plug" => {
                bridge.pull_cable(Cut::No);
                Ok(Vec::new())
            }
            "idle" => {
                // Requests are handled in order by one task: the acknowledgement of this
                // StopStream comes after everything asked before it (and ends any stream).
                let _turn = bridge.control_turn(Fresh::Yes)?;
                bridge.send_request(Request::StopStream)?;
                bridge.until_ack()
            }
            _ => Err(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no control {action}"),
            )),
        }
    })();
    match result {
        Ok(seqs) => {
            let last_seq = bridge.lock_answers().map(|a| a.last_seq).unwrap_or(0);
            ("200 OK", made(&seqs, last_seq))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => ("404 Not Found", e.to_string()),
        Err(e) => ("500 Internal Server Error", e.to_string()),
    }
}

fn websocket(stream: TcpStream, head: Vec<u8>, bridge: &Arc<Bridge>) -> std::io::Result<()> {
    if bridge.is_cut() {
        let mut stream = stream;
        return respond(
            &mut stream,
            "503 Service Unavailable",
            "text/plain",
            b"the caliper is disconnected",
        );
    }
    let tcp = stream.try_clone()?;
    let replay = Replay {
        head: Cursor::new(head),
        stream,
    };
    let mut ws = tungstenite::accept(replay).map_err(|e| std::io::Error::other(e.to_string()))?;
    tcp.set_read_timeout(Some(POLL))?;
    tcp.set_nodelay(true)?;
    let (tx, rx): (Sender<Vec<u8>>, Receiver<Vec<u8>>) = mpsc::channel();
    // This page replaces any other.
    let generation = bridge.generation.fetch_add(1, Ordering::SeqCst) + 1;
    if let Ok(mut page) = bridge.page.lock() {
        *page = Some(tx);
    }
    let result = pump(&mut ws, &rx, bridge, generation);
    let _ = ws.close(None);
    let _ = ws.flush();
    if bridge.generation.load(Ordering::SeqCst) == generation {
        bridge.drop_page();
    }
    result
}

/// Moves bytes both ways until the page goes or is replaced (or the cable is "cut").
fn pump(
    ws: &mut tungstenite::WebSocket<Replay>,
    rx: &Receiver<Vec<u8>>,
    bridge: &Arc<Bridge>,
    generation: u64,
) -> std::io::Result<()> {
    use tungstenite::{Error, Message};
    loop {
        if bridge.generation.load(Ordering::SeqCst) != generation {
            return Ok(());
        }
        // Everything the device sent since the last look, as one message.
        let mut bytes = Vec::new();
        while let Ok(chunk) = rx.try_recv() {
            bytes.extend_from_slice(&chunk);
        }
        if !bytes.is_empty() {
            if let Err(e) = ws.send(Message::binary(bytes)) {
                return Err(std::io::Error::other(e.to_string()));
            }
        }
        match ws.read() {
            Ok(Message::Binary(bytes)) => bridge.to_device(&bytes)?,
            Ok(Message::Close(_)) => return Ok(()),
            Ok(_) => {}
            Err(Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                // Nothing from the page: flush what is queued for it.
                let _ = ws.flush();
            }
            Err(Error::ConnectionClosed | Error::AlreadyClosed) => return Ok(()),
            Err(e) => return Err(std::io::Error::other(e.to_string())),
        }
    }
}
