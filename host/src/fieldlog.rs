//! The field log: an append-only, crash-safe journal of plots and tree readings, and its
//! export to what inventory software imports.
//!
//! ## Journal format (`docs/field-guide.md`)
//!
//! ```text
//! TANGENT-FIELDLOG 1\n                         first line: magic and format version
//! <crc32 as 8 hex digits> <JSON record>\n       one line per record
//! ```
//!
//! The CRC-32 (ISO-HDLC, the zlib CRC) covers the JSON bytes. A record is a plot header
//! (`{"type":"plot",...}`, starts a plot) or a tree reading (`{"type":"tree",...}`).
//!
//! **Crash safety.** Each record is written with one `write` on a file opened for appending
//! and then `fsync`ed (`File::sync_data`) before [`FieldLog::append`] returns — the record
//! is on disk before the reading is shown to the forester (write-ahead). A process killed
//! at any point leaves whole records plus at most one incomplete last line; a power cut can
//! leave a torn or garbled last record (the file grew but its data did not all reach the
//! disk). On [`FieldLog::open`], trailing lines that are incomplete or fail their CRC are
//! cut off (the cut bytes are saved next to the log as `<log>.torn`, never destroyed),
//! so every record that `append` confirmed is kept and the log stays appendable. A bad line
//! *followed by good ones* cannot come from an append that was cut short; it is storage
//! damage: counted in [`FieldLog::skipped`], its raw bytes appended to `<log>.damaged`,
//! and the rest is read.
//!
//! **Damage.** [`scan`] reads whatever can be read — records on lines that lost their
//! newline, after a byte-order mark, in CR LF lines, after a damaged magic line — and names
//! every byte it cannot read as a record by line number and byte range ([`Scan`]);
//! `tangent log check` prints that account, `tangent log export` exports every recovered
//! record once and saves the unreadable bytes to `<log>.damaged` (`docs/reliability.md`).
//!
//! Why hand-written rather than a database crate: the format must be readable with a text
//! editor in the field and by any language, a single append + fsync is all the durability
//! machinery needed, and SQLite would be a C dependency for one table.

use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

// The format itself (records, lines, damage scan, exports) lives in `tangent-field`, shared
// with the browser field app; this module adds the file: locking, appending with fsync,
// recovery of a torn tail.
use tangent_core::protocol::calibration_record::CRC32;
pub use tangent_field::export::{
    export, export_records, plots, ExportFormat, ExportPlot, NoSuchPlot, TREE_COLUMNS,
};
pub use tangent_field::record::{
    decode_line, encode_line, flag_names, reading_line, select_plot, Filing, PlotHeader, Record,
    TreeRecord, MAGIC_LINE,
};
pub use tangent_field::scan::{
    scan, DamageKind, DamagedSpan, Duplicate, HeaderlessPlot, Located, Scan, Tolerated,
};

/// Why the field log could not be used.
#[derive(Debug, thiserror::Error)]
pub enum FieldLogError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a field log.
    #[error("{0} is not a Tangent field log (its first line is not `TANGENT-FIELDLOG 1`)")]
    NotAFieldLog(PathBuf),
    /// Another process has the log open for writing.
    #[error("{0} is in use by another tangent process")]
    Locked(PathBuf),
    /// A tree was appended before any plot header.
    #[error("no plot started: give a plot id (--plot-id)")]
    NoPlot,
}

/// An open field log.
pub struct FieldLog {
    path: PathBuf,
    file: File,
    records: Vec<Record>,
    scan: Scan,
    torn_bytes: usize,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> FieldLogError + '_ {
    move |source| FieldLogError::Io {
        path: path.to_path_buf(),
        source,
    }
}

impl FieldLog {
    /// Opens (creating if needed) the log at `path` for appending, recovering from a
    /// crash: a torn last record is cut off and saved to `<path>.torn`. Takes an exclusive
    /// lock so two processes never interleave records.
    pub fn open(path: &Path) -> Result<FieldLog, FieldLogError> {
        let created = !path.exists();
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(path)
            .map_err(io(path))?;
        // A lock can outlive its holder briefly (a process exiting, or a fork of this
        // process that has not exec'd yet still shares the descriptor): wait up to 2 s.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(2);
        loop {
            match file.try_lock() {
                Ok(()) => break,
                Err(std::fs::TryLockError::WouldBlock) if std::time::Instant::now() < deadline => {
                    std::thread::sleep(std::time::Duration::from_millis(20))
                }
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(FieldLogError::Locked(path.to_path_buf()))
                }
                Err(std::fs::TryLockError::Error(e)) => return Err(io(path)(e)),
            }
        }
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io(path))?;
        let magic = MAGIC_LINE.as_bytes();
        if bytes.len() < magic.len() && magic.starts_with(&bytes) {
            // New, or killed while writing the magic line.
            file.set_len(0).map_err(io(path))?;
            file.write_all(magic).map_err(io(path))?;
            file.sync_all().map_err(io(path))?;
            if created {
                sync_parent(path)?;
            }
            bytes = magic.to_vec();
        }
        let scan = scan_bytes(path, &bytes)?;
        save_damaged(path, &bytes, scan.damaged_inside())?;
        let good_len = scan.good_len;
        let torn_bytes = bytes.len() - good_len;
        if torn_bytes > 0 {
            let torn_path = side_path(path, "torn");
            let mut saved = OpenOptions::new()
                .append(true)
                .create(true)
                .open(&torn_path)
                .map_err(io(&torn_path))?;
            saved
                .write_all(&bytes[good_len..])
                .and_then(|()| saved.sync_all())
                .map_err(io(&torn_path))?;
            file.set_len(good_len as u64).map_err(io(path))?;
        }
        if good_len > 0 && bytes[good_len - 1] != b'\n' {
            // The last record lost its newline (or a record was recovered from the middle
            // of a line): the next record must start a line of its own.
            file.write_all(b"\n").map_err(io(path))?;
        }
        if torn_bytes > 0 || bytes[..good_len].last() != Some(&b'\n') {
            file.sync_all().map_err(io(path))?;
        }
        Ok(FieldLog {
            path: path.to_path_buf(),
            file,
            records: scan.records(),
            scan,
            torn_bytes,
        })
    }

    /// Reads a log without modifying or locking it (for export): every recoverable
    /// record, each reading once; damage is ignored (see [`FieldLog::scan_file`]).
    pub fn read(path: &Path) -> Result<Vec<Record>, FieldLogError> {
        Ok(FieldLog::scan_file(path)?.records())
    }

    /// Reads a log without modifying or locking it and accounts for every byte: the
    /// records and where they are, damaged lines, duplicates, a torn tail.
    pub fn scan_file(path: &Path) -> Result<Scan, FieldLogError> {
        let bytes = std::fs::read(path).map_err(io(path))?;
        scan_bytes(path, &bytes)
    }

    /// [`FieldLog::scan_file`] on bytes already read from `path` (named in errors).
    pub fn scan_bytes(path: &Path, bytes: &[u8]) -> Result<Scan, FieldLogError> {
        scan_bytes(path, bytes)
    }

    /// The log's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every record, in order.
    pub fn records(&self) -> &[Record] {
        &self.records
    }

    /// Bytes of a torn last record cut off when opening (0 after a clean shutdown).
    pub fn torn_bytes(&self) -> usize {
        self.torn_bytes
    }

    /// Damaged lines in the middle of the log that were skipped (their bytes are in
    /// `<log>.damaged`).
    pub fn skipped(&self) -> usize {
        let mut lines: Vec<usize> = self.scan.damaged_inside().iter().map(|d| d.line).collect();
        lines.dedup();
        lines.len()
    }

    /// What opening found in the log (damage, duplicates, tolerated format changes).
    pub fn scan(&self) -> &Scan {
        &self.scan
    }

    /// The current plot (the last header), if any.
    pub fn current_plot(&self) -> Option<&PlotHeader> {
        self.records.iter().rev().find_map(|r| match r {
            Record::Plot(p) => Some(p),
            Record::Tree(_) => None,
        })
    }

    /// The last tree of plot `plot_id`.
    pub fn last_tree_in(&self, plot_id: &str) -> Option<&TreeRecord> {
        self.records.iter().rev().find_map(|r| match r {
            Record::Tree(t) if t.plot_id == plot_id => Some(t),
            _ => None,
        })
    }

    /// The last tree recorded from `device_id` (any plot).
    pub fn last_tree_from(&self, device_id: &str) -> Option<&TreeRecord> {
        self.records.iter().rev().find_map(|r| match r {
            Record::Tree(t) if t.device_id == device_id => Some(t),
            _ => None,
        })
    }

    /// Appends a record durably: one write, then fsync. When this returns `Ok`, the record
    /// survives a crash or power cut.
    pub fn append(&mut self, record: Record) -> Result<(), FieldLogError> {
        if let Record::Tree(t) = &record {
            if self.current_plot().is_none() {
                return Err(FieldLogError::NoPlot);
            }
            debug_assert!(!t.plot_id.is_empty());
        }
        let line = encode_line(&record);
        self.file
            .write_all(line.as_bytes())
            .and_then(|()| self.file.sync_data())
            .map_err(io(&self.path))?;
        self.records.push(record);
        Ok(())
    }
}

/// Scans `bytes` read from `path`, refusing a file that is not a field log.
fn scan_bytes(path: &Path, bytes: &[u8]) -> Result<Scan, FieldLogError> {
    let found = scan(bytes);
    if tangent_field::scan::is_foreign(bytes, &found) {
        return Err(FieldLogError::NotAFieldLog(path.to_path_buf()));
    }
    Ok(found)
}

/// `<log>.<suffix>`, next to the log.
pub fn side_path(log: &Path, suffix: &str) -> PathBuf {
    let mut p = log.as_os_str().to_owned();
    p.push(".");
    p.push(suffix);
    PathBuf::from(p)
}

/// Appends the raw bytes of `spans` of the log `path` (whose content is `bytes`) to
/// `<log>.damaged`, each after a line naming where it came from; a span already saved
/// (same line, range and CRC) is not saved again, so the file only grows with new damage
/// and is never overwritten. Returns how many spans were newly saved.
pub fn save_damaged(
    path: &Path,
    bytes: &[u8],
    spans: &[DamagedSpan],
) -> Result<usize, FieldLogError> {
    if spans.is_empty() {
        return Ok(0);
    }
    let side = side_path(path, "damaged");
    let existing = match std::fs::read(&side) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(io(&side)(e)),
    };
    let mut out = Vec::new();
    let mut saved = 0;
    for d in spans {
        let raw = &bytes[d.start..d.end];
        let key = format!(
            "line {}, bytes {}..{}, crc32 {:08x}",
            d.line,
            d.start,
            d.end,
            CRC32.checksum(raw)
        );
        if existing.windows(key.len()).any(|w| w == key.as_bytes()) {
            continue;
        }
        let name = path
            .file_name()
            .unwrap_or(path.as_os_str())
            .to_string_lossy();
        out.extend_from_slice(
            format!("--- {name} {key}: {}; saved {}\n", d.kind, now_rfc3339()).as_bytes(),
        );
        out.extend_from_slice(raw);
        out.push(b'\n');
        saved += 1;
    }
    if saved > 0 {
        let mut file = OpenOptions::new()
            .append(true)
            .create(true)
            .open(&side)
            .map_err(io(&side))?;
        file.write_all(&out)
            .and_then(|()| file.sync_all())
            .map_err(io(&side))?;
    }
    Ok(saved)
}

fn sync_parent(path: &Path) -> Result<(), FieldLogError> {
    // The new directory entry must reach the disk too, or a crash could lose the file.
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    File::open(parent)
        .and_then(|d| d.sync_all())
        .map_err(io(parent))
}

/// Now, as RFC 3339 UTC with seconds (`2025-06-01T10:00:00Z`).
pub fn now_rfc3339() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}
