//! The field log's records and lines: the journal format every companion writes and reads
//! (`docs/field-guide.md`).
//!
//! ```text
//! TANGENT-FIELDLOG 1\n                         first line: magic and format version
//! <crc32 as 8 hex digits> <JSON record>\n       one line per record
//! ```
//!
//! The CRC-32 (ISO-HDLC, the zlib CRC) covers the JSON bytes. A record is a plot header
//! (`{"type":"plot",...}`, starts a plot) or a tree reading (`{"type":"tree",...}`).

use serde::{Deserialize, Serialize};
use tangent_core::measurement::Measurement;
use tangent_core::protocol::calibration_record::CRC32;
use tangent_core::protocol::{codes, Board, Reading};
use tangent_core::solvers::result::Flags;

/// First line of every field log.
pub const MAGIC_LINE: &str = "TANGENT-FIELDLOG 1\n";

/// A plot header: the trees recorded after it belong to this plot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlotHeader {
    /// Plot id as the inventory names it (e.g. `"P-017"`).
    pub plot_id: String,
    /// When the plot was started (RFC 3339, UTC).
    pub started: String,
    /// Free-text note.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
}

/// One reading (a tree's, or of any other instrument: [`TreeRecord::kind`]). The record keeps
/// its historical name and `"type":"tree"` so that every log ever written still reads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TreeRecord {
    /// Plot the tree belongs to.
    pub plot_id: String,
    /// Tree number within the plot.
    pub tree_id: u32,
    /// Species code (the inventory's code list, e.g. `PIAB` or `50`).
    pub species: String,
    /// Diameter (millimetres): [`Measurement::value`] of the reading — a stem's or a sphere's
    /// diameter.
    pub diameter_mm: f64,
    /// Standard uncertainty of the diameter (millimetres).
    pub uncertainty_mm: f64,
    /// Stem tilt from the laser-plane normal (degrees; 0 when not measured).
    pub tilt_deg: f64,
    /// Quality flags (bits of `solvers::result::Flags`).
    pub flags: u32,
    /// Host time of the reading (RFC 3339, UTC).
    pub time: String,
    /// Device id (USB serial number, or the board name).
    pub device_id: String,
    /// Calibration id the reading was computed with.
    pub calib_id: u32,
    /// Device sequence number of the reading.
    pub seq: u32,
    /// Device time of the reading (ms since its boot).
    pub device_time_ms: u64,
    /// What the reading is of ([`Measurement::kind`]: `stem`, `sphere`, …), so that one log
    /// mixes instruments; logs written before readings had kinds hold stems only.
    #[serde(default = "stem_kind")]
    pub kind: String,
    /// The whole reading as the device sent it (any instrument's fields, SI units); absent
    /// from logs written before readings had kinds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measurement: Option<Measurement>,
    /// The user's free-text label of the reading (`"kitchen NE corner"`, `"door 2 width"`);
    /// empty when none was given, and in logs written before readings had labels.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub label: String,
}

/// The kind of the readings of logs written before readings had kinds.
fn stem_kind() -> String {
    "stem".to_string()
}

/// Where a reading is filed: the plot, tree and species the forester chose, the user's label,
/// the device it came from, and the host's time it arrived (RFC 3339 UTC with seconds,
/// `2025-06-01T10:00:00Z`).
#[derive(Debug, Clone, Copy)]
pub struct Filing<'a> {
    /// Plot id.
    pub plot_id: &'a str,
    /// Tree number.
    pub tree_id: u32,
    /// Species code.
    pub species: &'a str,
    /// Free-text label (empty: none).
    pub label: &'a str,
    /// Device id.
    pub device_id: &'a str,
    /// Host time.
    pub time: &'a str,
}

impl TreeRecord {
    /// The record of a reading from the device, filed as `filing` says.
    pub fn from_reading(r: &Reading, filing: Filing<'_>) -> TreeRecord {
        let m = &r.measurement;
        let tilt = match m {
            Measurement::Stem(stem) => stem.tilt.map(|t| t.total),
            #[allow(unreachable_patterns)] // the instruments without a tilt
            _ => None,
        };
        TreeRecord {
            plot_id: filing.plot_id.to_string(),
            tree_id: filing.tree_id,
            species: filing.species.to_string(),
            // Via f32, the precision of the wire, so a reading logs the same digits whatever
            // precision the host computes in.
            diameter_mm: m.value() as f32 as f64 * 1e3,
            uncertainty_mm: m.uncertainty() as f32 as f64 * 1e3,
            tilt_deg: tilt.map_or(0.0, |t| (t as f32 as f64).to_degrees()),
            flags: m.flags().0,
            time: filing.time.to_string(),
            device_id: filing.device_id.to_string(),
            calib_id: r.calib_id,
            seq: r.seq,
            device_time_ms: r.timestamp_ms,
            kind: m.kind().to_string(),
            measurement: Some(*m),
            label: filing.label.to_string(),
        }
    }
}

/// One journal record.
// Most records are trees; boxing them to shrink the rare plot header would only add an
// allocation per reading.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Record {
    /// A plot header.
    Plot(PlotHeader),
    /// A tree reading.
    Tree(TreeRecord),
}

impl Record {
    /// The plot the record belongs to.
    pub fn plot_id(&self) -> &str {
        match self {
            Record::Plot(p) => &p.plot_id,
            Record::Tree(t) => &t.plot_id,
        }
    }
}

/// The records of plot `plot_id` only (what `tangent log export --plot-id` exports).
pub fn select_plot(records: &[Record], plot_id: &str) -> Vec<Record> {
    records
        .iter()
        .filter(|r| r.plot_id() == plot_id)
        .cloned()
        .collect()
}

/// Flag names in capitals (how exports have always spelt [`codes::FLAG_NAMES`]) joined by
/// `+`, unknown bits as hex; empty when no flag is set.
pub fn flag_names(flags: u32) -> String {
    let mut names: Vec<String> = codes::flag_names(Flags(flags))
        .map(str::to_ascii_uppercase)
        .collect();
    let rest = flags & !codes::known_flags().0;
    if rest != 0 {
        names.push(format!("0x{rest:04X}"));
    }
    names.join("+")
}

/// One reading as `tangent log show` prints it: plot, number, kind, value (mm) ± σ (a
/// wall's corner angle, plumb, parallel distance and segment too, when it has them),
/// species, flags, time and the label in quotes (fields that are empty are left out).
pub fn reading_line(t: &TreeRecord) -> String {
    let mut s = format!(
        "{} #{} {} {:.1} mm ± {:.1}",
        t.plot_id, t.tree_id, t.kind, t.diameter_mm, t.uncertainty_mm
    );
    if let Some(Measurement::Wall(w)) = &t.measurement {
        // `Real` is f32 in the device build: the casts are not no-ops there.
        #[allow(clippy::unnecessary_cast)]
        let degrees = |v: tangent_core::real::Real| (v as f64).to_degrees();
        #[allow(clippy::unnecessary_cast)]
        let mm = |v: tangent_core::real::Real| v as f64 * 1e3;
        if let Some(c) = w.corner {
            s += &format!(
                ", corner {:.2}° ± {:.2}",
                degrees(c.value),
                degrees(c.sigma)
            );
        }
        if let Some(p) = w.plumb {
            s += &format!(", plumb {:.2}° ± {:.2}", degrees(p.value), degrees(p.sigma));
        }
        if let Some(p) = w.parallel {
            s += &format!(", parallel {:.1} mm ± {:.1}", mm(p.value), mm(p.sigma));
        }
        if let Some((l, whole)) = w.segment {
            let bound = if whole { "" } else { " (at least)" };
            s += &format!(
                ", segment {:.1} mm ± {:.1}{bound}",
                mm(l.value),
                mm(l.sigma)
            );
        }
    }
    if !t.species.is_empty() {
        s += &format!(" {}", t.species);
    }
    let flags = flag_names(t.flags);
    if !flags.is_empty() {
        s += &format!(" [{flags}]");
    }
    s += &format!(" {}", t.time);
    if !t.label.is_empty() {
        s += &format!(" \"{}\"", t.label);
    }
    s
}

/// Encodes one record as its journal line.
pub fn encode_line(record: &Record) -> String {
    // Serialising plain structs of strings and numbers cannot fail.
    let json = serde_json::to_string(record).unwrap_or_default();
    format!("{:08x} {json}\n", CRC32.checksum(json.as_bytes()))
}

/// Decodes one journal line (without its newline); `None` if it is damaged.
pub fn decode_line(line: &[u8]) -> Option<Record> {
    let text = std::str::from_utf8(line).ok()?;
    let (crc, json) = text.split_once(' ')?;
    if crc.len() != 8 || u32::from_str_radix(crc, 16).ok()? != CRC32.checksum(json.as_bytes()) {
        return None;
    }
    serde_json::from_str(json).ok()
}

/// The device id of a caliper whose USB serial number is not known: its board's name.
pub fn board_device_id(board: Board) -> &'static str {
    match board {
        Board::H743 => "H743",
        Board::Emulated => "emulated",
    }
}
