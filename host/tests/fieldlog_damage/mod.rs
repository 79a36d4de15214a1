//! The field log under damage: each kind the field brings, read back with nothing lost
//! unnamed; the `log check` / `log export` commands on damaged logs; and property tests over
//! random corruptions of k bytes and truncations (`docs/reliability.md`).

use std::path::Path;

use proptest::prelude::*;
use tangent_host::fieldlog::{DamageKind, Scan, Tolerated};

use super::*;

/// The journal bytes of `records` and each record's byte range (newline included).
fn journal(records: &[Record]) -> (Vec<u8>, Vec<std::ops::Range<usize>>) {
    let mut bytes = MAGIC_LINE.as_bytes().to_vec();
    let mut ranges = Vec::new();
    for r in records {
        let start = bytes.len();
        bytes.extend_from_slice(encode_line(r).as_bytes());
        ranges.push(start..bytes.len());
    }
    (bytes, ranges)
}

fn crc32(bytes: &[u8]) -> u32 {
    tangent_core::protocol::calibration_record::CRC32.checksum(bytes)
}

fn lines_of(scan: &Scan) -> Vec<usize> {
    scan.damaged.iter().map(|d| d.line).collect()
}

/// The kinds of damage named in issue 13, one at a time: what is read, what is named.
#[test]
fn each_kind_of_damage_keeps_the_intact_records_and_names_the_rest() {
    let records = sample();
    let (good, ranges) = journal(&records);
    let lines: Vec<&[u8]> = good.split_inclusive(|&b| b == b'\n').collect();
    let join = |ls: &[&[u8]]| ls.concat();

    // One flipped byte in a tree line: that tree is named (line 3), the rest is read.
    let mut bytes = good.clone();
    bytes[ranges[1].start + 30] ^= 0x20;
    let scan = fieldlog::scan(&bytes);
    let mut want = records.clone();
    want.remove(1);
    assert_eq!(scan.records(), want);
    assert_eq!(lines_of(&scan), [3]);
    assert_eq!(scan.damaged[0].kind, DamageKind::CrcMismatch);

    // A flipped byte in a plot header costs only the header: its trees are exported under
    // their plot id, marked header_lost.
    let mut bytes = good.clone();
    bytes[ranges[0].start + 25] ^= 0x01;
    let scan = fieldlog::scan(&bytes);
    assert_eq!(scan.records(), records[1..]);
    assert_eq!(lines_of(&scan), [2]);
    assert_eq!(scan.headerless.len(), 1);
    assert_eq!(
        (
            scan.headerless[0].plot_id.as_str(),
            scan.headerless[0].trees
        ),
        ("P-017", 2)
    );
    let json: serde_json::Value =
        serde_json::from_str(&fieldlog::export(&scan.records(), ExportFormat::Json)).unwrap();
    assert_eq!(json["plots"][0]["plot_id"], "P-017");
    assert_eq!(json["plots"][0]["header_lost"], true);
    assert_eq!(json["plots"][0]["trees"].as_array().unwrap().len(), 2);
    assert!(json["plots"][1].get("header_lost").is_none());

    // A lost newline between two records: both read.
    let mut bytes = good.clone();
    bytes.remove(ranges[1].end - 1);
    let scan = fieldlog::scan(&bytes);
    assert_eq!(scan.records(), records);
    assert!(scan.damaged.is_empty());
    assert!(scan.tolerated.contains(&Tolerated::JoinedRecords {
        line: 3,
        records: 2
    }));
    // ... and a newline replaced by another byte: both read, the byte named.
    let mut bytes = good.clone();
    bytes[ranges[1].end - 1] = b'#';
    let scan = fieldlog::scan(&bytes);
    assert_eq!(scan.records(), records);
    assert_eq!(lines_of(&scan), [3]);
    assert_eq!(scan.damaged[0].end - scan.damaged[0].start, 1);

    // A NUL-filled line among good ones.
    let bytes = join(&[
        lines[0],
        lines[1],
        b"\0\0\0\0\0\0\0\0\n",
        &join(&lines[2..]),
    ]);
    let scan = fieldlog::scan(&bytes);
    assert_eq!(scan.records(), records);
    assert_eq!(lines_of(&scan), [3]);
    assert_eq!(scan.damaged[0].kind, DamageKind::Zeroed);

    // A CRC-valid record of a kind this reader does not know (a newer tangent): named.
    let json = r#"{"type":"photo","file":"p.jpg"}"#;
    let newer = format!("{:08x} {json}\n", crc32(json.as_bytes()));
    let bytes = join(&[&good, newer.as_bytes()]);
    let scan = fieldlog::scan(&bytes);
    assert_eq!(scan.records(), records);
    assert_eq!(lines_of(&scan), [7]);
    assert_eq!(scan.damaged[0].kind, DamageKind::UnknownRecord);

    // CR LF conversion, a BOM, one changed byte in the magic line: every record read.
    let crlf: Vec<u8> = String::from_utf8(good.clone())
        .unwrap()
        .replace('\n', "\r\n")
        .into_bytes();
    let mut bom = b"\xEF\xBB\xBF".to_vec();
    bom.extend_from_slice(&good);
    let mut magic = good.clone();
    magic[3] = b'X';
    for (name, bytes, tolerated) in [
        ("crlf", &crlf, Tolerated::Crlf { lines: 6 }),
        ("bom", &bom, Tolerated::Bom),
        (
            "magic",
            &magic,
            Tolerated::MagicDamaged {
                found: "TANXENT-FIELDLOG 1".into(),
            },
        ),
    ] {
        let scan = fieldlog::scan(bytes);
        assert_eq!(scan.records(), records, "{name}");
        assert!(scan.damaged.is_empty(), "{name}");
        assert_eq!(scan.tolerated, [tolerated], "{name}");
    }

    // A record copied twice: exported once, the copy named.
    let bytes = join(&[&good, lines[2]]);
    let scan = fieldlog::scan(&bytes);
    assert_eq!(scan.records(), records);
    assert_eq!(scan.duplicates.len(), 1);
    assert_eq!(
        (scan.duplicates[0].line, scan.duplicates[0].first_line),
        (7, 3)
    );
    // The same sequence number at another device time is a reading after a device
    // restart, not a copy: both kept.
    let Record::Tree(mut restarted) = records[1].clone() else {
        unreachable!()
    };
    restarted.device_time_ms += 1;
    let bytes = join(&[&good, encode_line(&Record::Tree(restarted)).as_bytes()]);
    let scan = fieldlog::scan(&bytes);
    assert_eq!((scan.records().len(), scan.duplicates.len()), (6, 0));
}

/// `log check` reports without changing anything; `log export` exports every readable
/// record, names the rest, appends the raw bytes to `<log>.damaged` (once per span, never
/// overwriting) and exits 3; a log that only needed care exits 4; an intact one 0.
#[test]
fn log_check_and_export_report_damage_and_exit_accordingly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("field.log");
    let side = dir.path().join("field.log.damaged");
    let records = sample();
    let (good, ranges) = journal(&records);
    let run = |args: &[&str]| {
        tangent()
            .args(args)
            .arg("--log")
            .arg(&path)
            .output()
            .unwrap()
    };

    std::fs::write(&path, &good).unwrap();
    let out = run(&["log", "check"]);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("2 plot(s), 3 tree(s)"), "{text}");
    assert!(text.contains("the log is intact"), "{text}");

    let mut bytes = good.clone();
    bytes[ranges[0].start + 25] ^= 0x01; // the first plot header
    bytes.extend_from_slice(&encode_line(&records[2]).as_bytes()[..40]); // torn tail
    std::fs::write(&path, &bytes).unwrap();
    let out = run(&["log", "check"]);
    assert_eq!(out.status.code(), Some(3));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("plot P-017: 2 tree(s), header lost"),
        "{text}"
    );
    assert!(text.contains("damaged lines: 1;"), "{text}");
    assert!(text.contains("torn tail: 40 byte(s)"), "{text}");
    assert!(text.contains("line 2: "), "{text}");
    assert!(text.contains("line 7: 40 byte(s)"), "{text}");
    assert_eq!(
        std::fs::read(&path).unwrap(),
        bytes,
        "check changed the log"
    );
    assert!(!side.exists(), "check wrote a side file");

    let out = run(&["log", "export", "--format", "csv", "--plot-id", "P-017"]);
    assert_eq!(out.status.code(), Some(3));
    let intact = fieldlog::export(&records[..3], ExportFormat::Csv);
    let (_, rows) = intact.split_once("\n\n").unwrap();
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        format!("plot_id,P-017\nstarted,\nnote,\ntrees,2\n\n{rows}")
    );
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("line 2: "), "{stderr}");
    assert!(stderr.contains("(torn tail)"), "{stderr}");
    let saved = std::fs::read(&side).unwrap();
    let header = &bytes[ranges[0].start..ranges[0].end - 1];
    assert!(saved.windows(header.len()).any(|w| w == header));
    // Exporting again saves nothing new; new damage is appended after the old.
    run(&["log", "export", "--format", "json"]);
    assert_eq!(std::fs::read(&side).unwrap(), saved);
    bytes[ranges[3].start + 30] ^= 0x04;
    std::fs::write(&path, &bytes).unwrap();
    let out = run(&["log", "export", "--format", "tsv"]);
    assert_eq!(out.status.code(), Some(3));
    let more = std::fs::read(&side).unwrap();
    assert!(more.starts_with(&saved) && more.len() > saved.len());

    let mut copied = good.clone();
    copied.extend_from_slice(encode_line(&records[1]).as_bytes());
    std::fs::write(&path, &copied).unwrap();
    let out = run(&["log", "export", "--format", "csv"]);
    assert_eq!(out.status.code(), Some(4));
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        fieldlog::export(&records, ExportFormat::Csv)
    );
}

/// `listen` opens (`FieldLog::open`) a damaged log: intact records are kept, damage inside
/// is saved to `.damaged` and the log stays appendable after a lost final newline.
#[test]
fn open_keeps_records_around_damage_and_stays_appendable() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("field.log");
    let records = sample();
    let (good, ranges) = journal(&records);
    let mut bytes = String::from_utf8(good.clone())
        .unwrap()
        .replace('\n', "\r\n")
        .into_bytes();
    bytes[ranges[2].start + 40] ^= 0x10; // tree 2 of P-017 (its line, shifted by 3 CRs)
    bytes.pop(); // the last line's LF
    std::fs::write(&path, &bytes).unwrap();
    let mut log = FieldLog::open(&path).unwrap();
    let mut want = records.clone();
    want.remove(2);
    assert_eq!(log.records(), want);
    assert_eq!((log.skipped(), log.torn_bytes()), (1, 0));
    assert!(dir.path().join("field.log.damaged").exists());
    log.append(records[2].clone()).unwrap();
    drop(log);
    want.push(records[2].clone());
    assert_eq!(FieldLog::read(&path).unwrap(), want);
}

fn arb_text() -> impl Strategy<Value = String> {
    // Printable ASCII (braces, quotes, digits and spaces make record look-alikes), a tab
    // and some non-ASCII.
    "[ -~\tæøé]{0,14}"
}

fn arb_record(seq: u32) -> impl Strategy<Value = Record> {
    let plot = (arb_text(), arb_text(), arb_text()).prop_map(|(plot_id, started, note)| {
        Record::Plot(PlotHeader {
            plot_id,
            started,
            note,
        })
    });
    let tree = (
        arb_text(),
        any::<u32>(),
        arb_text(),
        (0.0f64..3000.0, 0.0f64..50.0, -90.0f64..90.0),
        any::<u32>(),
        arb_text(),
        arb_text(),
        any::<u32>(),
        any::<u64>(),
    )
        .prop_map(
            move |(
                plot_id,
                tree_id,
                species,
                (d, u, tilt),
                flags,
                time,
                device_id,
                calib_id,
                ms,
            )| {
                Record::Tree(TreeRecord {
                    plot_id,
                    tree_id,
                    species,
                    diameter_mm: d,
                    uncertainty_mm: u,
                    tilt_deg: tilt,
                    flags,
                    time,
                    device_id,
                    calib_id,
                    seq,
                    device_time_ms: ms,
                    kind: "stem".into(),
                    measurement: None,
                    label: String::new(),
                })
            },
        );
    prop_oneof![1 => plot, 4 => tree]
}

/// 5–12 records with distinct sequence numbers (so none is a duplicate of another), as
/// they read back (serde_json's float parsing may differ from the written value in the
/// last bit; the property is about records, not float formatting).
fn arb_log() -> impl Strategy<Value = Vec<Record>> {
    (5usize..=12)
        .prop_flat_map(|n| (0..n as u32).map(arb_record).collect::<Vec<_>>())
        .prop_map(|records| {
            records
                .iter()
                .map(|r| fieldlog::decode_line(encode_line(r).trim_end().as_bytes()).unwrap())
                .collect()
        })
}

#[derive(Debug, Clone)]
enum Edit {
    /// XOR the byte with a non-zero mask.
    Flip(prop::sample::Index, u8),
    Delete(prop::sample::Index),
    Insert(prop::sample::Index, u8),
}

fn arb_edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<prop::sample::Index>(), 1u8..=255).prop_map(|(i, m)| Edit::Flip(i, m)),
        any::<prop::sample::Index>().prop_map(Edit::Delete),
        (any::<prop::sample::Index>(), any::<u8>()).prop_map(|(i, b)| Edit::Insert(i, b)),
    ]
}

/// The record (index into the original records) that original byte `b` belongs to.
fn record_of(ranges: &[std::ops::Range<usize>], b: usize) -> Option<usize> {
    ranges.iter().position(|r| r.contains(&b))
}

/// Checks a scan of corrupted bytes against the originals: nothing invented, order kept,
/// every untouched record read, every lost record named by a damaged span over one of its
/// surviving bytes, and every span's line number right.
fn assert_nothing_lost_unnamed(
    records: &[Record],
    ranges: &[std::ops::Range<usize>],
    bytes: &[u8],
    origin: &[Option<usize>],
    touched: &std::collections::BTreeSet<usize>,
) -> Result<(), TestCaseError> {
    let scan = FieldLog::scan_bytes(Path::new("log"), bytes)
        .map_err(|e| TestCaseError::fail(format!("refused: {e}")))?;
    let got = scan.records();
    // Each record read is the original whose bytes it was read from (found through the
    // byte map, so identical records cannot stand in for each other), in order.
    let mut recovered = vec![false; records.len()];
    let mut last = None;
    for l in &scan.records {
        // An inserted byte equal to its neighbour makes the two indistinguishable: a record
        // may then begin on the inserted copy, so it is mapped by its first original byte.
        let first_original = origin[l.offset..].iter().flatten().next();
        let i = first_original.and_then(|&b| record_of(ranges, b));
        let Some(i) = i.filter(|&i| records[i] == l.record) else {
            return Err(TestCaseError::fail(format!("invented: {l:?}")));
        };
        prop_assert!(last < Some(i), "out of order: {l:?}");
        last = Some(i);
        recovered[i] = true;
    }
    for (i, range) in ranges.iter().enumerate() {
        if recovered[i] {
            continue;
        }
        prop_assert!(touched.contains(&i), "untouched record {i} lost: {scan:?}");
        let surviving: Vec<usize> = (0..bytes.len())
            .filter(|&p| origin[p].is_some_and(|b| range.contains(&b) && b + 1 < range.end))
            .collect();
        if surviving.is_empty() {
            continue; // nothing of it is left in the file to name
        }
        prop_assert!(
            scan.damaged
                .iter()
                .any(|d| surviving.iter().any(|p| (d.start..d.end).contains(p))),
            "record {i} lost without being named: {:?}",
            scan.findings()
        );
    }
    for d in &scan.damaged {
        let line = 1 + bytes[..d.start].iter().filter(|&&b| b == b'\n').count();
        prop_assert_eq!(d.line, line);
    }
    // Every recovered tree is exported, under its plot.
    let exported: usize = fieldlog::plots(&got).iter().map(|p| p.trees.len()).sum();
    let trees = got.iter().filter(|r| matches!(r, Record::Tree(_))).count();
    prop_assert_eq!(exported, trees);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    /// Any k ≤ 4 byte flips, deletions and insertions anywhere in the log (magic line
    /// included): at most the records those bytes touch are lost, and each lost one is
    /// named.
    #[test]
    fn corrupting_k_bytes_loses_only_the_touched_records_and_names_them(
        records in arb_log(),
        edits in prop::collection::vec(arb_edit(), 1..=4),
    ) {
        let (mut bytes, ranges) = journal(&records);
        let mut origin: Vec<Option<usize>> = (0..bytes.len()).map(Some).collect();
        let mut touched = std::collections::BTreeSet::new();
        for edit in edits {
            let mut touch = |p: usize, origin: &[Option<usize>]| {
                // The byte's record, or (for an inserted byte or a gap) its neighbours'.
                for q in [p.checked_sub(1), Some(p), Some(p + 1)].into_iter().flatten() {
                    if let Some(Some(b)) = origin.get(q) {
                        if q == p || origin.get(p).is_none_or(|o| o.is_none()) {
                            touched.extend(record_of(&ranges, *b));
                        }
                    }
                }
            };
            match edit {
                Edit::Flip(i, mask) if !bytes.is_empty() => {
                    let p = i.index(bytes.len());
                    touch(p, &origin);
                    bytes[p] ^= mask;
                }
                Edit::Delete(i) if !bytes.is_empty() => {
                    let p = i.index(bytes.len());
                    touch(p, &origin);
                    bytes.remove(p);
                    origin.remove(p);
                }
                Edit::Insert(i, b) => {
                    let p = i.index(bytes.len() + 1);
                    // Between two bytes: both neighbours' records are touched.
                    for q in [p.checked_sub(1), Some(p)].into_iter().flatten() {
                        if let Some(Some(o)) = origin.get(q) {
                            touched.extend(record_of(&ranges, *o));
                        }
                    }
                    bytes.insert(p, b);
                    origin.insert(p, None);
                }
                _ => {}
            }
        }
        assert_nothing_lost_unnamed(&records, &ranges, &bytes, &origin, &touched)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// A log cut anywhere after its magic line (a power cut) loses only the record the cut
    /// goes through, which is named as the torn tail; `FieldLog::open` keeps the same
    /// records, sets the tail aside in `.torn` and takes new records.
    #[test]
    fn a_truncated_log_loses_only_the_cut_record(
        records in arb_log(),
        cut in any::<prop::sample::Index>(),
    ) {
        let (mut bytes, ranges) = journal(&records);
        let at = MAGIC_LINE.len() + cut.index(bytes.len() - MAGIC_LINE.len() + 1);
        bytes.truncate(at);
        let origin: Vec<Option<usize>> = (0..bytes.len()).map(Some).collect();
        let touched = (0..records.len()).filter(|&i| ranges[i].end > at).collect();
        assert_nothing_lost_unnamed(&records, &ranges, &bytes, &origin, &touched)?;
        let scan = fieldlog::scan(&bytes);
        prop_assert!(scan.damaged_inside().is_empty());

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("field.log");
        std::fs::write(&path, &bytes).unwrap();
        let mut log = FieldLog::open(&path).unwrap();
        prop_assert_eq!(log.records(), &scan.records()[..]);
        let plot = plot("after");
        log.append(plot.clone()).unwrap();
        drop(log);
        let mut want = scan.records();
        want.push(plot);
        prop_assert_eq!(FieldLog::read(&path).unwrap(), want);
    }
}
