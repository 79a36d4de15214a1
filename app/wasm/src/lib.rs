//! The field app's WebAssembly module: the page's only source of the wire protocol, the
//! reading types, the failure texts and the field-log format — `tangent-core` and
//! `tangent-field` compiled to `wasm32-unknown-unknown`, behind a small C ABI over byte
//! buffers (why not wasm-bindgen: `docs/field-app.md`). The page's loader is
//! `app/web/core.js`.
//!
//! **Calling convention.** The page writes its arguments into input slots
//! ([`tg_input`]: slot 0 and 1), calls a function, and reads the result from the output
//! buffer ([`tg_output_ptr`], [`tg_output_len`]): UTF-8 JSON, a journal line, an export or
//! frame bytes. Functions return 0 on success; 1 means the output holds an error sentence.
//! One page, one thread: the buffers and the link state are single globals.
//!
//! **The link.** [`Link`] is the browser's half of what `tangent listen` does with the
//! port: the core's [`Decoder`] and [`FrameEncoder`] and `tangent-field`'s [`SeqTracker`]
//! (readings in order, once each, gaps recovered from the device's history). The page only
//! moves bytes and waits.

use std::cell::RefCell;

use serde::Deserialize;
use serde_json::{json, Value};
use tangent_core::protocol::{
    codes, Decoder, Feed, FrameEncoder, FromDevice, ProtocolError, Reading, Request, Response,
    ToDevice, MAX_FRAME_LEN, PROTOCOL_VERSION,
};
use tangent_field::advice::warnings;
use tangent_field::seq::{HistoryOutcome, SeqTracker};
use tangent_field::{
    board_device_id, encode_line, export_records, is_foreign, scan, tally, ExportFormat, Filing,
    Record, TreeRecord, MAGIC_LINE,
};

/// The browser side of the link to one caliper.
pub struct Link {
    rx: Decoder<Vec<u8>>,
    enc: FrameEncoder,
    seq: SeqTracker,
    /// The reading popped last, waiting to be filed.
    current: Option<Reading>,
}

impl Default for Link {
    fn default() -> Self {
        Link {
            rx: Decoder::new(vec![0; MAX_FRAME_LEN]),
            enc: FrameEncoder::new(),
            seq: SeqTracker::default(),
            current: None,
        }
    }
}

impl Link {
    /// Encodes `request` (JSON of [`Request`], e.g. `"Measure"` or
    /// `{"History":{"after_seq":4}}`) with `tag` as a frame.
    pub fn encode(&mut self, tag: u16, request_json: &str) -> Result<Vec<u8>, String> {
        let request: Request = serde_json::from_str(request_json)
            .map_err(|e| format!("not a request: {request_json}: {e}"))?;
        self.enc
            .encode(&ToDevice { tag, request })
            .map(<[u8]>::to_vec)
            .map_err(|e| e.to_string())
    }

    /// Feeds bytes from the device; returns what they held, in order, as JSON: `{"tag",
    /// "response"}` per message (readings also go to the tracker; a device error carries its
    /// sentence as `"text"`), `{"rejected": why}` per bad frame.
    pub fn feed(&mut self, mut bytes: &[u8]) -> Value {
        let mut out = Vec::new();
        loop {
            match self.rx.feed::<FromDevice>(bytes) {
                Feed::Consumed => break,
                Feed::Frame { message, remaining } => {
                    let mut event = json!({ "tag": message.tag, "response": message.response });
                    match message.response {
                        Response::Reading(r) => {
                            event["duplicate"] = self.seq.accept(r).into();
                        }
                        Response::Error(e) => event["text"] = e.to_string().into(),
                        Response::Info(i) => {
                            event["device_id"] = board_device_id(i.board).into();
                        }
                        _ => {}
                    }
                    out.push(event);
                    bytes = remaining;
                }
                Feed::Rejected { error, remaining } => {
                    let why = match error {
                        ProtocolError::VersionMismatch { received } => format!(
                            "the device speaks protocol version {received}, this app speaks version {PROTOCOL_VERSION}: {}",
                            if received > PROTOCOL_VERSION { "update the app" } else { "update the firmware (`tangent flash`)" }
                        ),
                        other => other.to_string(),
                    };
                    out.push(json!({ "rejected": why }));
                    bytes = remaining;
                }
            }
        }
        Value::Array(out)
    }

    /// The next reading in order (JSON: the reading, its method's name and its warnings in
    /// words), kept to be filed; `null` when none is ready.
    pub fn pop_reading(&mut self) -> Value {
        let Some(r) = self.seq.pop_ready() else {
            return Value::Null;
        };
        self.current = Some(r);
        json!({
            "reading": r,
            "kind": r.measurement.kind(),
            "method": codes::method_name(r.measurement.method()),
            "warnings": warnings(r.measurement.flags().0),
        })
    }

    /// Files the last popped reading: its record and journal line.
    pub fn file(&mut self, filing: &FilingJson) -> Result<Value, String> {
        let r = self.current.take().ok_or("no reading to file")?;
        let record = TreeRecord::from_reading(
            &r,
            Filing {
                plot_id: &filing.plot_id,
                tree_id: filing.tree_id,
                species: &filing.species,
                label: &filing.label,
                device_id: &filing.device_id,
                time: &filing.time,
            },
        );
        let line = encode_line(&Record::Tree(record.clone()));
        Ok(json!({ "record": record, "line": line }))
    }
}

/// Where the page files a reading (JSON of [`Filing`]).
#[derive(Debug, Deserialize)]
pub struct FilingJson {
    plot_id: String,
    tree_id: u32,
    species: String,
    /// Optional: the page files without a label unless it sends one.
    #[serde(default)]
    label: String,
    device_id: String,
    time: String,
}

/// Everything a field log's bytes hold, for the page: the records (with their journal
/// lines, re-encoded), what could not be read, and whether it is a field log at all.
pub fn import(bytes: &[u8]) -> Value {
    let found = scan(bytes);
    if is_foreign(bytes, &found) {
        return json!({ "error": "this file is not a Tangent field log (its first line is not `TANGENT-FIELDLOG 1`)" });
    }
    let records = found.records();
    let lines: Vec<String> = records.iter().map(encode_line).collect();
    json!({ "records": records, "lines": lines, "findings": found.findings() })
}

/// `tangent log export` of a log's bytes: every readable record, or plot `plot_id`'s only.
pub fn export_log(bytes: &[u8], plot_id: Option<&str>, format: &str) -> Result<String, String> {
    let format = match format {
        "csv" => ExportFormat::Csv,
        "tsv" => ExportFormat::Tsv,
        "json" => ExportFormat::Json,
        other => return Err(format!("unknown export format {other}")),
    };
    let found = scan(bytes);
    if is_foreign(bytes, &found) {
        return Err("not a Tangent field log".into());
    }
    export_records(&found.records(), plot_id, format).map_err(|e| e.to_string())
}

// ---- the C ABI ---------------------------------------------------------------------------

#[derive(Default)]
struct State {
    input: [Vec<u8>; 2],
    output: Vec<u8>,
    link: Link,
}

thread_local! {
    static STATE: RefCell<State> = RefCell::new(State::default());
}

fn with<R>(f: impl FnOnce(&mut State) -> R) -> R {
    STATE.with(|s| f(&mut s.borrow_mut()))
}

/// Sets the output to `result` (its text, or its error sentence) and returns 0 or 1.
fn finish(s: &mut State, result: Result<Vec<u8>, String>) -> u32 {
    match result {
        Ok(bytes) => {
            s.output = bytes;
            0
        }
        Err(e) => {
            s.output = e.into_bytes();
            1
        }
    }
}

fn input_text(s: &State, slot: usize) -> Result<String, String> {
    String::from_utf8(s.input[slot].clone()).map_err(|_| format!("input {slot} is not UTF-8"))
}

/// Makes input `slot` (0 or 1) `len` bytes long and returns where the page writes them.
#[no_mangle]
pub extern "C" fn tg_input(slot: u32, len: u32) -> *mut u8 {
    with(|s| {
        let buf = &mut s.input[(slot as usize).min(1)];
        buf.clear();
        buf.resize(len as usize, 0);
        buf.as_mut_ptr()
    })
}

/// Where the last result is.
#[no_mangle]
pub extern "C" fn tg_output_ptr() -> *const u8 {
    with(|s| s.output.as_ptr())
}

/// How long the last result is.
#[no_mangle]
pub extern "C" fn tg_output_len() -> u32 {
    with(|s| s.output.len() as u32)
}

/// The constants the page needs (JSON): protocol version, history length, the field log's
/// magic line, flag names.
#[no_mangle]
pub extern "C" fn tg_constants() -> u32 {
    with(|s| {
        let flags: Vec<&str> = codes::FLAG_NAMES.iter().map(|(_, n)| *n).collect();
        let v = json!({
            "protocol_version": PROTOCOL_VERSION,
            "history_len": codes::HISTORY_LEN,
            "magic_line": MAGIC_LINE,
            "flag_names": flags,
            "usb_vendor_id": codes::USB_VID,
            "usb_product_id": codes::USB_PID,
        });
        finish(s, Ok(v.to_string().into_bytes()))
    })
}

/// Input 0: a request as JSON; output: its frame with `tag`.
#[no_mangle]
pub extern "C" fn tg_encode(tag: u32) -> u32 {
    with(|s| {
        let r = input_text(s, 0).and_then(|json| s.link.encode(tag as u16, &json));
        finish(s, r)
    })
}

/// Input 0: bytes from the device; output: JSON array of what they held ([`Link::feed`]).
#[no_mangle]
pub extern "C" fn tg_feed() -> u32 {
    with(|s| {
        let bytes = std::mem::take(&mut s.input[0]);
        let v = s.link.feed(&bytes);
        finish(s, Ok(v.to_string().into_bytes()))
    })
}

/// Output: the next reading in order ([`Link::pop_reading`]), or `null`.
#[no_mangle]
pub extern "C" fn tg_pop_reading() -> u32 {
    with(|s| {
        let v = s.link.pop_reading();
        finish(s, Ok(v.to_string().into_bytes()))
    })
}

/// Input 0: JSON [`FilingJson`]; output: `{record, line}` of the last popped reading.
#[no_mangle]
pub extern "C" fn tg_file_reading() -> u32 {
    with(|s| {
        let r = input_text(s, 0)
            .and_then(|j| serde_json::from_str::<FilingJson>(&j).map_err(|e| e.to_string()))
            .and_then(|f| s.link.file(&f))
            .map(|v| v.to_string().into_bytes());
        finish(s, r)
    })
}

/// Highest sequence number delivered (or given up on).
#[no_mangle]
pub extern "C" fn tg_last_seq() -> u32 {
    with(|s| s.link.seq.last())
}

/// Highest device time seen (ms; a device reporting less restarted), as f64 for JS.
#[no_mangle]
pub extern "C" fn tg_newest_ms() -> f64 {
    with(|s| s.link.seq.newest_ms() as f64)
}

/// Delivers readings after `seq` from now on (the last one already stored).
#[no_mangle]
pub extern "C" fn tg_resume_after(seq: u32) {
    with(|s| s.link.seq.resume_after(seq))
}

/// The device restarted: its numbers start again at 1.
#[no_mangle]
pub extern "C" fn tg_restart() {
    with(|s| s.link.seq.restart())
}

/// Whether readings are missing (ask `History`).
#[no_mangle]
pub extern "C" fn tg_has_gap() -> u32 {
    with(|s| s.link.seq.has_gap() as u32)
}

/// Starts a `History` request: its `after_seq`.
#[no_mangle]
pub extern "C" fn tg_history_requested() -> u32 {
    with(|s| s.link.seq.history_requested())
}

/// The `HistoryEnd`: output `{"rebooted":true}` or `{"lost":[[from,to],…]}`.
#[no_mangle]
pub extern "C" fn tg_history_ended(after_seq: u32, device_last: u32) -> u32 {
    with(|s| {
        let v = match s.link.seq.history_ended(after_seq, device_last) {
            HistoryOutcome::Rebooted => json!({ "rebooted": true }),
            HistoryOutcome::Done { lost } => json!({ "lost": lost }),
        };
        finish(s, Ok(v.to_string().into_bytes()))
    })
}

/// Forgets any partial frame (the port was re-opened).
#[no_mangle]
pub extern "C" fn tg_reset_decoder() {
    with(|s| s.link.rx.reset())
}

/// Input 0: a record as JSON (`{"type":"plot",…}`); output: its journal line.
#[no_mangle]
pub extern "C" fn tg_encode_record() -> u32 {
    with(|s| {
        let r = input_text(s, 0)
            .and_then(|j| serde_json::from_str::<Record>(&j).map_err(|e| e.to_string()))
            .map(|rec| encode_line(&rec).into_bytes());
        finish(s, r)
    })
}

/// Input 0: a field log's bytes; output: [`import`]'s JSON.
#[no_mangle]
pub extern "C" fn tg_import() -> u32 {
    with(|s| {
        let v = import(&s.input[0]);
        finish(s, Ok(v.to_string().into_bytes()))
    })
}

/// Input 0: a field log's bytes, input 1: the plot id (empty: all plots); `format` 0 CSV,
/// 1 TSV, 2 JSON; output: the export, byte for byte what `tangent log export` writes.
#[no_mangle]
pub extern "C" fn tg_export(format: u32) -> u32 {
    with(|s| {
        let r = input_text(s, 1).and_then(|plot| {
            let plot = (!plot.is_empty()).then_some(plot.as_str());
            let name = ["csv", "tsv", "json"].get(format as usize).copied();
            export_log(&s.input[0], plot, name.unwrap_or("")).map(String::into_bytes)
        });
        finish(s, r)
    })
}

/// Input 0: a field log's bytes, input 1: the plot id; output: the plot's tally (JSON) and
/// the trees that count, by number.
#[no_mangle]
pub extern "C" fn tg_tally() -> u32 {
    with(|s| {
        let r = input_text(s, 1).map(|plot| {
            let records = scan(&s.input[0]).records();
            let trees = tally::trees_of(&records, &plot);
            json!({ "tally": tally::tally(&records, &plot), "trees": trees })
                .to_string()
                .into_bytes()
        });
        finish(s, r)
    })
}

#[cfg(test)]
mod tests;
