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
//! does to a real one: `trigger` (a trigger press: a `Measure` with tag 0, whose reading
//! reaches the page unsolicited, as the hardware trigger's do), `hold?ms=` (the trigger
//! held: `StartStream` … `StopStream`), `cut?ms=` (the cable pulled: the page's connection
//! is closed and refused for that long while the device keeps running).

use std::io::{Cursor, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tangent_core::protocol::{FrameEncoder, Request, ToDevice, UNSOLICITED};

/// Longest HTTP request head read.
const MAX_HEAD: usize = 16 * 1024;

/// How long the bridge's WebSocket loop waits for the page before looking at the device's
/// bytes again.
const POLL: Duration = Duration::from_millis(10);

/// Where the device's bytes go and where the page's come from.
pub struct Bridge {
    /// Writes to the device.
    device: Mutex<Box<dyn Write + Send>>,
    /// The connected page's outbox.
    page: Mutex<Option<Sender<Vec<u8>>>>,
    /// Bumped to close the current page's connection.
    generation: AtomicU64,
    /// Connections are refused until then (a pulled cable).
    cut_until: Mutex<Option<Instant>>,
    /// Whether `/control/` is served (the emulated caliper only).
    controls: bool,
}

impl Bridge {
    /// A bridge writing to `device`; `controls` enables `/control/`.
    pub fn new(device: Box<dyn Write + Send>, controls: bool) -> Arc<Bridge> {
        Arc::new(Bridge {
            device: Mutex::new(device),
            page: Mutex::new(None),
            generation: AtomicU64::new(0),
            cut_until: Mutex::new(None),
            controls,
        })
    }

    /// Bytes from the device: to the page, if one is connected.
    pub fn from_device(&self, bytes: &[u8]) {
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

/// `/control/…`: what a forester does to the caliper, done to the emulated one.
fn control(bridge: &Arc<Bridge>, action: &str, query: &str) -> (&'static str, String) {
    let result = match action {
        "trigger" => {
            let n = query_number(query, "n", 1);
            (0..n).try_for_each(|_| bridge.send_request(Request::Measure))
        }
        "hold" => {
            let ms = query_number(query, "ms", 2000);
            let b = bridge.clone();
            bridge.send_request(Request::StartStream).map(|()| {
                std::thread::spawn(move || {
                    std::thread::sleep(Duration::from_millis(ms));
                    let _ = b.send_request(Request::StopStream);
                });
            })
        }
        "cut" => {
            let ms = query_number(query, "ms", 3000);
            if let Ok(mut until) = bridge.cut_until.lock() {
                *until = Some(Instant::now() + Duration::from_millis(ms));
            }
            bridge.drop_page();
            Ok(())
        }
        _ => return ("404 Not Found", format!("no control {action}")),
    };
    match result {
        Ok(()) => ("200 OK", "ok".into()),
        Err(e) => ("500 Internal Server Error", e.to_string()),
    }
}

fn websocket(stream: TcpStream, head: Vec<u8>, bridge: &Arc<Bridge>) -> std::io::Result<()> {
    let cut = bridge
        .cut_until
        .lock()
        .map(|u| u.is_some_and(|t| Instant::now() < t))
        .unwrap_or(false);
    if cut {
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
