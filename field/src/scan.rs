//! Reading a field log that may be damaged: every record that can be recovered, and an
//! account of every byte that could not (`docs/reliability.md`).
//!
//! A line that is not exactly one record is searched for records inside it: a record is
//! 8 hex digits, a space and a JSON object whose CRC-32 matches, so a lost newline (two
//! records on one line), bytes inserted before or after a record, or a record glued to the
//! magic line are all recovered. Whatever is left of a line is a [`DamagedSpan`], named by
//! its line number and byte range. The CRC makes a false recovery a 2⁻³² event per
//! candidate.

use std::collections::HashMap;
use std::fmt;

use crc::{Crc, Digest};

use crate::record::{decode_line, Record, MAGIC_LINE};

/// The UTF-8 byte-order mark some editors put at the start of a text file.
const BOM: &[u8] = b"\xEF\xBB\xBF";

/// A first line within this many byte edits of the magic line is the magic line, damaged:
/// a few flipped, lost or extra bytes, not another kind of file.
const MAGIC_MAX_EDITS: usize = 3;

/// Records are searched inside a damaged line only up to this length (the longest record
/// `listen` writes is well under 1 KiB; an intact line of any length still reads). The
/// bound keeps the search linear in the size of the damage (a 1 MB line made of nothing
/// but record starts takes about a second).
const MAX_RECOVERED_RECORD: usize = 4 * 1024;

static CRC: Crc<u32> = tangent_core::protocol::calibration_record::CRC32;

/// A record read from the log and where it is.
#[derive(Debug, Clone, PartialEq)]
pub struct Located {
    /// Line number (1-based; the magic line is line 1).
    pub line: usize,
    /// Byte offset of the record's first byte in the file.
    pub offset: usize,
    /// The record.
    pub record: Record,
}

/// Why some bytes are not a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DamageKind {
    /// Only NUL bytes (a zeroed disk sector).
    Zeroed,
    /// Looks like a record, but its CRC does not match: bytes were changed, lost or added.
    CrcMismatch,
    /// A CRC-valid line that is not a plot or tree record (written by a newer tangent?).
    UnknownRecord,
    /// Neither a record nor part of one.
    NotARecord,
}

impl fmt::Display for DamageKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DamageKind::Zeroed => "zeroed (NUL bytes)",
            DamageKind::CrcMismatch => "a record whose CRC does not match (bytes changed)",
            DamageKind::UnknownRecord => "a CRC-valid record of an unknown kind",
            DamageKind::NotARecord => "not a record",
        })
    }
}

/// Bytes of the log that could not be read as records.
#[derive(Debug, Clone, PartialEq)]
pub struct DamagedSpan {
    /// Line number (1-based).
    pub line: usize,
    /// First byte (offset in the file).
    pub start: usize,
    /// One past the last byte.
    pub end: usize,
    /// What the bytes look like.
    pub kind: DamageKind,
}

/// A reading found a second time: same device, sequence number and device time.
#[derive(Debug, Clone, PartialEq)]
pub struct Duplicate {
    /// Line of the copy (not exported).
    pub line: usize,
    /// Line of the first occurrence (exported).
    pub first_line: usize,
    /// Device id.
    pub device_id: String,
    /// Device sequence number.
    pub seq: u32,
}

/// A plot whose trees are in the log but whose header is not.
#[derive(Debug, Clone, PartialEq)]
pub struct HeaderlessPlot {
    /// The plot id its trees carry.
    pub plot_id: String,
    /// How many trees.
    pub trees: usize,
    /// Line of its first tree.
    pub first_line: usize,
}

/// Departures from the written format that lose nothing.
#[derive(Debug, Clone, PartialEq)]
pub enum Tolerated {
    /// The file starts with a UTF-8 byte-order mark.
    Bom,
    /// Lines end in CR LF (a log converted on Windows or by mail).
    Crlf {
        /// How many lines.
        lines: usize,
    },
    /// The first line is not exactly the magic line.
    MagicDamaged {
        /// What it is (lossy UTF-8, at most 40 characters).
        found: String,
    },
    /// Several records on one line (a newline was lost).
    JoinedRecords {
        /// Line number.
        line: usize,
        /// How many records the line holds.
        records: usize,
    },
    /// The first line is a record, not the magic line (the records are read).
    MagicMissing,
    /// Empty lines.
    BlankLines {
        /// How many.
        count: usize,
    },
    /// The last record has no newline (it is kept; the next append starts a new line).
    NoFinalNewline,
}

impl fmt::Display for Tolerated {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Tolerated::Bom => write!(f, "the file starts with a byte-order mark (ignored)"),
            Tolerated::Crlf { lines } => write!(
                f,
                "{lines} line(s) end in CR LF (converted on Windows or by mail; read as usual)"
            ),
            Tolerated::MagicDamaged { found } => write!(
                f,
                "line 1 is `{found}`, not `{}` (damaged; the records are read)",
                MAGIC_LINE.trim_end()
            ),
            Tolerated::JoinedRecords { line, records } => write!(
                f,
                "line {line} holds {records} records (a newline was lost; each is read)"
            ),
            Tolerated::MagicMissing => write!(
                f,
                "line 1 is not `{}` (missing; the records are read)",
                MAGIC_LINE.trim_end()
            ),
            Tolerated::BlankLines { count } => write!(f, "{count} empty line(s) (ignored)"),
            Tolerated::NoFinalNewline => write!(f, "the last record has no newline"),
        }
    }
}

/// Everything a log holds: the records that can be read and an account of the rest.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scan {
    /// Recovered records in file order, each reading once.
    pub records: Vec<Located>,
    /// Bytes that are not records, in file order.
    pub damaged: Vec<DamagedSpan>,
    /// Readings found more than once (exported once).
    pub duplicates: Vec<Duplicate>,
    /// Plots whose header was lost (their trees are kept).
    pub headerless: Vec<HeaderlessPlot>,
    /// What was tolerated.
    pub tolerated: Vec<Tolerated>,
    /// True when line 1 is the magic line, intact or damaged.
    pub magic_line: bool,
    /// End of the last recovered record, line end included (the magic line's end if there
    /// is none): the damage after it is the torn tail.
    pub good_len: usize,
}

impl Scan {
    /// The recovered records.
    pub fn records(&self) -> Vec<Record> {
        self.records.iter().map(|l| l.record.clone()).collect()
    }

    /// Damage after the last record: a record cut short by a crash (or a garbled tail).
    pub fn torn_tail(&self) -> &[DamagedSpan] {
        let first = self.damaged.partition_point(|d| d.start < self.good_len);
        &self.damaged[first..]
    }

    /// Damage followed by records (storage damage, not a crash).
    pub fn damaged_inside(&self) -> &[DamagedSpan] {
        let first = self.damaged.partition_point(|d| d.start < self.good_len);
        &self.damaged[..first]
    }

    /// True when every byte was read as a record and nothing needed tolerance.
    pub fn is_clean(&self) -> bool {
        self.damaged.is_empty()
            && self.duplicates.is_empty()
            && self.headerless.is_empty()
            && self.tolerated.is_empty()
    }

    /// One line per finding, for people (empty when the log is clean).
    pub fn findings(&self) -> Vec<String> {
        let mut out = Vec::new();
        for d in &self.damaged {
            let tail = if d.start >= self.good_len {
                " (torn tail)"
            } else {
                ""
            };
            out.push(format!(
                "line {}: {} byte(s) at {}..{} unreadable{tail}: {}",
                d.line,
                d.end - d.start,
                d.start,
                d.end,
                d.kind
            ));
        }
        for p in &self.headerless {
            out.push(format!(
                "plot {}: header lost; its {} tree(s) from line {} are kept",
                p.plot_id, p.trees, p.first_line
            ));
        }
        for d in &self.duplicates {
            out.push(format!(
                "line {}: reading {}#{} repeats line {} (exported once)",
                d.line, d.device_id, d.seq, d.first_line
            ));
        }
        out.extend(self.tolerated.iter().map(|t| t.to_string()));
        out
    }
}

/// True when `bytes` is not a field log: its first line is not (nearly) the magic line and
/// no line has the shape of a record.
pub fn is_foreign(bytes: &[u8], scan: &Scan) -> bool {
    !scan.magic_line
        && scan.records.is_empty()
        && !bytes
            .split(|&b| b == b'\n')
            .any(|line| (0..line.len()).any(|i| record_shape(line, i)))
}

fn bom_len(bytes: &[u8]) -> usize {
    if bytes.starts_with(BOM) {
        BOM.len()
    } else {
        0
    }
}

/// Reads every record of a field log's bytes and accounts for the rest.
pub fn scan(bytes: &[u8]) -> Scan {
    let mut s = Scan::default();
    let mut pos = bom_len(bytes);
    if pos > 0 {
        s.tolerated.push(Tolerated::Bom);
    }
    let magic = MAGIC_LINE.trim_end().as_bytes();
    let (mut crlf, mut blank, mut line_no) = (0, 0, 0);
    let mut joined = Vec::new();
    s.good_len = pos;
    while pos < bytes.len() {
        line_no += 1;
        let (content_end, next) = match bytes[pos..].iter().position(|&b| b == b'\n') {
            Some(nl) => (pos + nl, pos + nl + 1),
            None => (bytes.len(), bytes.len()),
        };
        let has_newline = next > content_end;
        let mut end = content_end;
        if end > pos && bytes[end - 1] == b'\r' {
            end -= 1;
            crlf += usize::from(has_newline);
        }
        let line = &bytes[pos..end];
        if line_no == 1 && line == magic {
            s.magic_line = true;
            s.good_len = next;
        } else if line.is_empty() {
            blank += usize::from(has_newline);
        } else if let Some(record) = decode_line(line) {
            s.records.push(Located {
                line: line_no,
                offset: pos,
                record,
            });
            s.good_len = next;
            if !has_newline {
                s.tolerated.push(Tolerated::NoFinalNewline);
            }
        } else {
            let (found, unknown) = recover(line);
            if found.len() > 1 {
                joined.push(Tolerated::JoinedRecords {
                    line: line_no,
                    records: found.len(),
                });
            }
            let mut covered = 0;
            for (i, (start, stop, record)) in found.into_iter().enumerate() {
                let gap = &line[covered..start];
                let near_magic = line_no == 1 && i == 0 && near_magic_line(gap);
                if near_magic {
                    s.magic_line = true;
                    s.tolerated.push(magic_damaged(gap));
                } else {
                    damage(&mut s, line_no, pos, covered..start, line, &unknown);
                }
                s.records.push(Located {
                    line: line_no,
                    offset: pos + start,
                    record,
                });
                covered = stop;
                s.good_len = if stop == line.len() { next } else { pos + stop };
            }
            let rest = &line[covered..];
            if line_no == 1 && covered == 0 && near_magic_line(rest) {
                s.magic_line = true;
                s.tolerated.push(magic_damaged(rest));
                s.good_len = next;
            } else {
                damage(&mut s, line_no, pos, covered..line.len(), line, &unknown);
            }
        }
        pos = next;
    }
    if !s.magic_line && !bytes.is_empty() {
        s.tolerated.push(Tolerated::MagicMissing);
    }
    if crlf > 0 {
        s.tolerated.push(Tolerated::Crlf { lines: crlf });
    }
    if blank > 0 {
        s.tolerated.push(Tolerated::BlankLines { count: blank });
    }
    s.tolerated.extend(joined);
    remove_duplicates(&mut s);
    s.headerless = headerless(&s.records);
    s
}

/// Within [`MAGIC_MAX_EDITS`] byte edits of the magic line?
fn near_magic_line(line: &[u8]) -> bool {
    let magic = MAGIC_LINE.trim_end().as_bytes();
    line.len() <= magic.len() + MAGIC_MAX_EDITS
        && strsim::generic_levenshtein(&line.to_vec(), &magic.to_vec()) <= MAGIC_MAX_EDITS
}

fn magic_damaged(found: &[u8]) -> Tolerated {
    Tolerated::MagicDamaged {
        found: String::from_utf8_lossy(found).chars().take(40).collect(),
    }
}

/// Records `range` of `line` (which starts at file offset `offset`) as damaged unless
/// empty; `unknown` are the starts of CRC-valid records of an unknown kind in the line.
fn damage(
    s: &mut Scan,
    line_no: usize,
    offset: usize,
    range: std::ops::Range<usize>,
    line: &[u8],
    unknown: &[usize],
) {
    let bytes = &line[range.clone()];
    if bytes.is_empty() {
        return;
    }
    let kind = if bytes.iter().all(|&b| b == 0) {
        DamageKind::Zeroed
    } else if unknown.iter().any(|u| range.contains(u)) {
        DamageKind::UnknownRecord
    } else if (0..bytes.len()).any(|i| record_shape(bytes, i)) {
        DamageKind::CrcMismatch
    } else {
        DamageKind::NotARecord
    };
    s.damaged.push(DamagedSpan {
        line: line_no,
        start: offset + range.start,
        end: offset + range.end,
        kind,
    });
}

/// Does a record start at `line[i]`: 8 hex digits, a space, `{`?
fn record_shape(line: &[u8], i: usize) -> bool {
    line.len() >= i + 10
        && line[i..i + 8].iter().all(u8::is_ascii_hexdigit)
        && line[i + 8] == b' '
        && line[i + 9] == b'{'
}

/// Every end (one past a `}`) at which the JSON starting at `line[i + 9]` has the CRC
/// that `line[i..i + 8]` names, nearest first; the CRC is updated byte by byte so the
/// search is linear.
fn crc_valid_ends(line: &[u8], i: usize) -> impl Iterator<Item = usize> + '_ {
    let want = record_shape(line, i)
        .then(|| std::str::from_utf8(&line[i..i + 8]).ok())
        .flatten()
        .and_then(|hex| u32::from_str_radix(hex, 16).ok());
    let json_start = i + 9;
    let limit = match want {
        Some(_) => line.len().min(i + MAX_RECOVERED_RECORD),
        None => json_start,
    };
    let mut digest: Option<Digest<'static, u32>> = want.map(|_| CRC.digest());
    (json_start..limit).filter_map(move |e| {
        let d = digest.as_mut()?;
        d.update(&line[e..e + 1]);
        (line[e] == b'}' && d.clone().finalize() == want?).then_some(e + 1)
    })
}

/// The records inside a damaged line: `(start, end, record)` in order, not overlapping;
/// and the starts of CRC-valid JSON that is not a record (of an unknown kind).
type Recovered = (Vec<(usize, usize, Record)>, Vec<usize>);

fn recover(line: &[u8]) -> Recovered {
    let mut found = Vec::new();
    let mut unknown = Vec::new();
    let mut i = 0;
    while i < line.len() {
        let mut record = None;
        for end in crc_valid_ends(line, i) {
            let parsed = std::str::from_utf8(&line[i + 9..end])
                .ok()
                .and_then(|json| serde_json::from_str::<Record>(json).ok());
            match parsed {
                Some(r) => {
                    record = Some((end, r));
                    break;
                }
                None => unknown.push(i),
            }
        }
        match record {
            Some((end, r)) => {
                found.push((i, end, r));
                i = end;
            }
            None => i += 1,
        }
    }
    (found, unknown)
}

/// Keeps the first of every reading found twice: same device, sequence number and device
/// time. The device time tells a copy from a reading after a device restart (which starts
/// the sequence numbers again).
fn remove_duplicates(s: &mut Scan) {
    let mut seen: HashMap<(String, u32, u64), usize> = HashMap::new();
    let mut kept = Vec::with_capacity(s.records.len());
    for located in std::mem::take(&mut s.records) {
        if let Record::Tree(t) = &located.record {
            let key = (t.device_id.clone(), t.seq, t.device_time_ms);
            if let Some(&first_line) = seen.get(&key) {
                s.duplicates.push(Duplicate {
                    line: located.line,
                    first_line,
                    device_id: t.device_id.clone(),
                    seq: t.seq,
                });
                continue;
            }
            seen.insert(key, located.line);
        }
        kept.push(located);
    }
    s.records = kept;
}

/// Plots that have trees but no header.
fn headerless(records: &[Located]) -> Vec<HeaderlessPlot> {
    let mut out: Vec<HeaderlessPlot> = Vec::new();
    let headed: Vec<&str> = records
        .iter()
        .filter_map(|l| match &l.record {
            Record::Plot(p) => Some(p.plot_id.as_str()),
            Record::Tree(_) => None,
        })
        .collect();
    for l in records {
        if let Record::Tree(t) = &l.record {
            if headed.contains(&t.plot_id.as_str()) {
                continue;
            }
            match out.iter_mut().find(|p| p.plot_id == t.plot_id) {
                Some(p) => p.trees += 1,
                None => out.push(HeaderlessPlot {
                    plot_id: t.plot_id.clone(),
                    trees: 1,
                    first_line: l.line,
                }),
            }
        }
    }
    out
}
