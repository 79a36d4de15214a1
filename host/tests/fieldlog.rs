//! The field log: round trip, exact export formats, recovery from a torn last record at
//! every possible cut, the real `tangent listen` killed mid-session (SIGKILL) then
//! restarted — every reading it printed is in the log, none twice, none missing — and
//! damage: each kind the field brings (a flipped byte, a lost newline, NULs, CR LF, a BOM,
//! a damaged magic line or plot header, a copied record) read back with nothing lost
//! unnamed, then property tests over random corruptions of k bytes and truncations.

mod test_device;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use tangent_host::fieldlog::{
    self, encode_line, ExportFormat, FieldLog, FieldLogError, PlotHeader, Record, TreeRecord,
    MAGIC_LINE,
};
use test_device::{diameter_of, TestDevice};

fn plot(id: &str) -> Record {
    Record::Plot(PlotHeader {
        plot_id: id.into(),
        started: "2025-06-01T08:00:00Z".into(),
        note: String::new(),
    })
}

fn tree(plot_id: &str, tree_id: u32, species: &str, d: f64, flags: u32, seq: u32) -> Record {
    Record::Tree(TreeRecord {
        plot_id: plot_id.into(),
        tree_id,
        species: species.into(),
        diameter_mm: d,
        uncertainty_mm: 1.24,
        tilt_deg: 2.96,
        flags,
        time: format!("2025-06-01T08:0{tree_id}:00Z"),
        device_id: "H743-0001".into(),
        calib_id: 7,
        seq,
        device_time_ms: 1000 * seq as u64,
        kind: "stem".into(),
        measurement: None,
        label: String::new(),
    })
}

/// `record` with the user's `label`.
fn labelled(mut record: Record, label: &str) -> Record {
    if let Record::Tree(t) = &mut record {
        t.label = label.into();
    }
    record
}

fn sample() -> Vec<Record> {
    vec![
        plot("P-017"),
        tree("P-017", 1, "PIAB", 314.06, 0, 1),
        labelled(
            tree("P-017", 2, "PISY", 201.96, 0x0006, 2),
            "by the \"old\" gate, north",
        ),
        plot("P 18, \"north\""),
        tree("P 18, \"north\"", 1, "50", 88.0, 0x8400, 3),
    ]
}

#[test]
fn round_trip_and_reopen() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("field.log");
    {
        let mut log = FieldLog::open(&path).unwrap();
        for r in sample() {
            log.append(r).unwrap();
        }
        assert_eq!(log.records(), &sample()[..]);
    }
    let log = FieldLog::open(&path).unwrap();
    assert_eq!(log.records(), &sample()[..]);
    assert_eq!((log.torn_bytes(), log.skipped()), (0, 0));
    assert_eq!(log.current_plot().unwrap().plot_id, "P 18, \"north\"");
    assert_eq!(log.last_tree_in("P-017").unwrap().tree_id, 2);
    // The journal is the documented text: magic line, then `crc json` lines.
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with(MAGIC_LINE));
    assert_eq!(text.lines().count(), 1 + sample().len());
    assert_eq!(FieldLog::read(&path).unwrap(), sample());
}

#[test]
fn a_tree_needs_a_plot_and_a_log_is_locked() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("field.log");
    let mut log = FieldLog::open(&path).unwrap();
    assert!(matches!(
        log.append(tree("P", 1, "X", 1.0, 0, 1)),
        Err(FieldLogError::NoPlot)
    ));
    assert!(matches!(
        FieldLog::open(&path),
        Err(FieldLogError::Locked(_))
    ));
    std::fs::write(dir.path().join("other.txt"), "hello\n").unwrap();
    assert!(matches!(
        FieldLog::open(&dir.path().join("other.txt")),
        Err(FieldLogError::NotAFieldLog(_))
    ));
}

#[test]
fn csv_export_is_exactly_the_documented_layout() {
    let want = "\
plot_id,P-017
started,2025-06-01T08:00:00Z
note,
trees,2

tree_id,species,dbh_mm,uncertainty_mm,tilt_deg,flags,time,device_id,calib_id,seq,plot_id,kind,label
1,PIAB,314.1,1.2,3.0,,2025-06-01T08:01:00Z,H743-0001,7,1,P-017,stem,
2,PISY,202.0,1.2,3.0,POOR_FIT+TILT_IGNORED,2025-06-01T08:02:00Z,H743-0001,7,2,P-017,stem,\"by the \"\"old\"\" gate, north\"

plot_id,\"P 18, \"\"north\"\"\"
started,2025-06-01T08:00:00Z
note,
trees,1

tree_id,species,dbh_mm,uncertainty_mm,tilt_deg,flags,time,device_id,calib_id,seq,plot_id,kind,label
1,50,88.0,1.2,3.0,NEAR_POLE+NOT_SPHERICAL,2025-06-01T08:01:00Z,H743-0001,7,3,\"P 18, \"\"north\"\"\",stem,
";
    assert_eq!(fieldlog::export(&sample(), ExportFormat::Csv), want);
}

#[test]
fn tsv_export_is_exactly_the_documented_layout() {
    let got = fieldlog::export(&sample()[..3], ExportFormat::Tsv);
    let want = "plot_id\tP-017\nstarted\t2025-06-01T08:00:00Z\nnote\t\ntrees\t2\n\n\
tree_id\tspecies\tdbh_mm\tuncertainty_mm\ttilt_deg\tflags\ttime\tdevice_id\tcalib_id\tseq\tplot_id\tkind\tlabel\n\
1\tPIAB\t314.1\t1.2\t3.0\t\t2025-06-01T08:01:00Z\tH743-0001\t7\t1\tP-017\tstem\t\n\
2\tPISY\t202.0\t1.2\t3.0\tPOOR_FIT+TILT_IGNORED\t2025-06-01T08:02:00Z\tH743-0001\t7\t2\tP-017\tstem\tby the \"old\" gate, north\n";
    assert_eq!(got, want);
    // Field-Map's calliper import skips the header lines and reads tab-separated columns:
    // every tree row has exactly as many fields as the column line.
    let rows: Vec<&str> = got.lines().skip(5).collect();
    assert!(rows.iter().all(|r| r.split('\t').count() == 13));
}

#[test]
fn json_export_nests_trees_in_plots() {
    let got = fieldlog::export(&sample(), ExportFormat::Json);
    let v: serde_json::Value = serde_json::from_str(&got).unwrap();
    assert_eq!(v["format"], "tangent-field-log");
    assert_eq!(v["version"], 1);
    let plots = v["plots"].as_array().unwrap();
    assert_eq!(plots.len(), 2);
    assert_eq!(plots[0]["plot_id"], "P-017");
    let t = &plots[0]["trees"][1];
    assert_eq!(t["tree_id"], 2);
    assert_eq!(t["species"], "PISY");
    assert_eq!(t["diameter_mm"], 201.96);
    assert_eq!(t["flags"], 6);
    assert_eq!(
        t["flag_names"],
        serde_json::json!(["POOR_FIT", "TILT_IGNORED"])
    );
    assert_eq!(t["label"], "by the \"old\" gate, north");
    // No label, no key: the records of unlabelled readings are as they always were.
    assert!(plots[0]["trees"][0].get("label").is_none());
    assert_eq!(plots[1]["trees"].as_array().unwrap().len(), 1);
}

/// Logs written before readings had kinds and labels (and before they carried the whole
/// reading) still read: their readings are unlabelled stems, exported with an empty label,
/// and re-encoding them gives back the very same line.
#[test]
fn logs_from_before_labels_still_read() {
    use tangent_core::protocol::calibration_record::CRC32;
    let old_json = r#"{"type":"tree","plot_id":"P-1","tree_id":4,"species":"PIAB","diameter_mm":250.5,"uncertainty_mm":1.1,"tilt_deg":0.0,"flags":0,"time":"2024-05-01T09:00:00Z","device_id":"H743-0001","calib_id":3,"seq":9,"device_time_ms":9000}"#;
    let header = r#"{"type":"plot","plot_id":"P-1","started":"2024-05-01T08:00:00Z"}"#;
    let line = |json: &str| format!("{:08x} {json}\n", CRC32.checksum(json.as_bytes()));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.log");
    std::fs::write(
        &path,
        format!("{MAGIC_LINE}{}{}", line(header), line(old_json)),
    )
    .unwrap();
    let records = FieldLog::read(&path).unwrap();
    let Record::Tree(t) = &records[1] else {
        panic!("not a reading: {:?}", records[1]);
    };
    assert_eq!((t.kind.as_str(), t.label.as_str()), ("stem", ""));
    assert_eq!((t.tree_id, t.diameter_mm, t.measurement), (4, 250.5, None));
    // Re-encoded, it gains only its kind (no label key, no reading).
    assert_eq!(
        encode_line(&records[1]),
        line(&old_json.replace(
            r#""device_time_ms":9000}"#,
            r#""device_time_ms":9000,"kind":"stem"}"#
        ))
    );
    let csv = fieldlog::export(&records, ExportFormat::Csv);
    assert!(csv.ends_with(",P-1,stem,\n"), "{csv}");
    // A log that has labels appends to it, and both read back.
    {
        let mut log = FieldLog::open(&path).unwrap();
        log.append(labelled(tree("P-1", 5, "PISY", 300.0, 0, 10), "new"))
            .unwrap();
    }
    let records = FieldLog::read(&path).unwrap();
    assert_eq!(records.len(), 3);
    assert!(matches!(&records[2], Record::Tree(t) if t.label == "new"));
}

/// A power cut can leave the last record cut at any byte (or the file extended with
/// garbage). At every cut the log reopens with all earlier records, sets the torn bytes
/// aside, and takes new records.
#[test]
fn torn_last_record_is_recovered_at_every_cut() {
    let dir = tempfile::tempdir().unwrap();
    let records = sample();
    let mut full = MAGIC_LINE.to_string();
    for r in &records[..4] {
        full += &encode_line(r);
    }
    let last = encode_line(&records[4]);
    let path = dir.path().join("field.log");
    for cut in 0..last.len() {
        let mut bytes = full.clone().into_bytes();
        bytes.extend_from_slice(&last.as_bytes()[..cut]);
        std::fs::write(&path, &bytes).unwrap();
        let _ = std::fs::remove_file(dir.path().join("field.log.torn"));
        {
            let mut log = FieldLog::open(&path).unwrap();
            if cut == last.len() - 1 {
                // Whole but for its newline: the record is kept, the newline restored.
                assert_eq!(log.records(), &records[..], "cut at {cut}");
                assert_eq!(log.torn_bytes(), 0);
                drop(log);
                assert_eq!(FieldLog::read(&path).unwrap(), records);
                assert!(std::fs::read(&path).unwrap().ends_with(b"}\n"));
                continue;
            }
            assert_eq!(log.records(), &records[..4], "cut at {cut}");
            assert_eq!(log.torn_bytes(), cut, "cut at {cut}");
            log.append(records[4].clone()).unwrap();
        }
        assert_eq!(FieldLog::read(&path).unwrap(), records, "cut at {cut}");
        if cut > 0 {
            let torn = std::fs::read(dir.path().join("field.log.torn")).unwrap();
            assert_eq!(torn, &last.as_bytes()[..cut]);
        }
    }
    // A complete-looking last line with a flipped byte (garbled sector) is torn as well;
    // a damaged line followed by good ones is skipped, not cut.
    let mut bad = last.clone().into_bytes();
    bad[20] ^= 0x01;
    let mut bytes = full.clone().into_bytes();
    bytes.extend_from_slice(&bad);
    std::fs::write(&path, &bytes).unwrap();
    let log = FieldLog::open(&path).unwrap();
    assert_eq!((log.records().len(), log.torn_bytes()), (4, bad.len()));
    drop(log);
    let mut bytes = MAGIC_LINE.as_bytes().to_vec();
    bytes.extend_from_slice(encode_line(&records[0]).as_bytes());
    bytes.extend_from_slice(&bad);
    bytes.extend_from_slice(encode_line(&records[1]).as_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let log = FieldLog::open(&path).unwrap();
    assert_eq!(log.records(), &records[..2]);
    assert_eq!((log.skipped(), log.torn_bytes()), (1, 0));
    // A file killed while its magic line was being written is simply a new log.
    drop(log);
    std::fs::write(&path, &MAGIC_LINE.as_bytes()[..7]).unwrap();
    assert!(FieldLog::open(&path).unwrap().records().is_empty());
}

fn tangent() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tangent"))
}

fn tree_seqs(path: &Path) -> Vec<u32> {
    FieldLog::read(path)
        .unwrap()
        .into_iter()
        .filter_map(|r| match r {
            Record::Tree(t) => {
                assert!((t.diameter_mm - diameter_of(t.seq) as f64 * 1e3).abs() < 1e-9);
                Some(t.seq)
            }
            Record::Plot(_) => None,
        })
        .collect()
}

/// `tangent listen` is killed with SIGKILL while readings pour in; every reading it printed
/// (printing happens after the fsync) is in the log, the log reopens cleanly, and a
/// restarted listener picks up exactly where the log ends — from the device's history —
/// so the final log holds readings 1..=N once each.
#[test]
fn killed_listener_loses_and_duplicates_nothing() {
    let dev = TestDevice::start();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("field.log");
    let n = 50u32; // within the device's 64-reading history
    let mut child = tangent()
        .args(["listen", "--port"])
        .arg(dev.path())
        .arg("--log")
        .arg(&log)
        .args([
            "--plot-id",
            "K1",
            "--species",
            "FASY",
            "--label",
            "stand 4, edge",
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    dev.press(n, Duration::from_millis(15));
    // Kill it mid-stream, after some readings were printed.
    let mut printed = Vec::new();
    let end = Instant::now() + Duration::from_secs(30);
    while printed.len() < 15 && Instant::now() < end {
        if let Ok(line) = rx.recv_timeout(Duration::from_millis(100)) {
            printed.push(line);
        }
    }
    child.kill().unwrap();
    child.wait().unwrap();
    while let Ok(line) = rx.try_recv() {
        printed.push(line);
    }
    assert!(printed.len() >= 15, "listener printed {printed:?}");
    let printed_seqs: Vec<u32> = printed
        .iter()
        .map(|l| l.rsplit('#').next().unwrap().trim().parse().unwrap())
        .collect();
    let logged = tree_seqs(&log);
    // Every printed reading is in the log (write-ahead), in order, no duplicates.
    assert!(
        logged.starts_with(&printed_seqs),
        "printed {printed_seqs:?}, logged {logged:?}"
    );
    assert_eq!(logged, (1..=logged.len() as u32).collect::<Vec<_>>());
    let k = logged.len() as u32;
    assert!(
        k < n,
        "killed after every reading ({k}); the test needs it mid-stream"
    );

    // Restart: it must fetch k+1..=n (some made while nobody listened) from the history.
    dev.wait_presses(Duration::from_secs(30));
    let out = tangent()
        .args(["listen", "--port"])
        .arg(dev.path())
        .arg("--log")
        .arg(&log)
        .args(["--count", &(n - k).to_string()])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(tree_seqs(&log), (1..=n).collect::<Vec<_>>());
    // Tree ids continue in the plot; the species stays what the first run was given only
    // for the first run (the second gave none).
    let trees: Vec<TreeRecord> = FieldLog::read(&log)
        .unwrap()
        .into_iter()
        .filter_map(|r| match r {
            Record::Tree(t) => Some(t),
            _ => None,
        })
        .collect();
    assert_eq!(
        trees.iter().map(|t| t.tree_id).collect::<Vec<_>>(),
        (1..=n).collect::<Vec<_>>()
    );
    assert!(trees.iter().all(|t| t.plot_id == "K1"));
    assert!(trees[..k as usize].iter().all(|t| t.species == "FASY"));
    // So does the label: on the first run's readings (and printed with them), not after.
    assert!(trees[..k as usize]
        .iter()
        .all(|t| t.label == "stand 4, edge"));
    assert!(trees[k as usize..].iter().all(|t| t.label.is_empty()));
    assert!(printed.iter().all(|l| l.contains("\"stand 4, edge\"")));
}

#[test]
fn log_export_command_writes_the_format() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("field.log");
    {
        let mut log = FieldLog::open(&path).unwrap();
        for r in sample() {
            log.append(r).unwrap();
        }
    }
    for (fmt, kind) in [
        ("csv", ExportFormat::Csv),
        ("tsv", ExportFormat::Tsv),
        ("json", ExportFormat::Json),
    ] {
        let out = tangent()
            .args(["log", "export", "--format", fmt, "--log"])
            .arg(&path)
            .output()
            .unwrap();
        assert!(out.status.success());
        assert_eq!(
            String::from_utf8(out.stdout).unwrap(),
            fieldlog::export(&sample(), kind)
        );
    }
    let out = tangent()
        .args([
            "log",
            "export",
            "--format",
            "csv",
            "--plot-id",
            "P-017",
            "--log",
        ])
        .arg(&path)
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8(out.stdout).unwrap(),
        fieldlog::export(&sample()[..3], ExportFormat::Csv)
    );
}

/// `tangent log show` lists each reading with its kind and label; `--kind` and `--plot-id`
/// select.
#[test]
fn log_show_lists_readings_with_kind_and_label() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("field.log");
    {
        let mut log = FieldLog::open(&path).unwrap();
        for r in sample() {
            log.append(r).unwrap();
        }
        let mut sphere = tree("P-017", 3, "", 80.0, 0, 4);
        if let Record::Tree(t) = &mut sphere {
            t.kind = "sphere".into();
        }
        log.append(labelled(sphere, "ball B")).unwrap();
    }
    let show = |extra: &[&str]| {
        let out = tangent()
            .args(["log", "show", "--log"])
            .arg(&path)
            .args(extra)
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        String::from_utf8(out.stdout).unwrap()
    };
    let all = show(&[]);
    let lines: Vec<&str> = all.lines().collect();
    assert_eq!(lines.len(), 4, "{all}");
    assert_eq!(
        lines[1],
        "P-017 #2 stem 202.0 mm ± 1.2 PISY [POOR_FIT+TILT_IGNORED] 2025-06-01T08:02:00Z \"by the \"old\" gate, north\""
    );
    assert!(
        lines[0].ends_with("08:01:00Z"),
        "no label, nothing after the time: {}",
        lines[0]
    );
    assert_eq!(
        show(&["--kind", "sphere"]).trim_end(),
        "P-017 #3 sphere 80.0 mm ± 1.2 2025-06-01T08:03:00Z \"ball B\""
    );
    assert_eq!(show(&["--plot-id", "P 18, \"north\""]).lines().count(), 1);
}

/// Damage of every kind and the property tests over random corruptions.
mod fieldlog_damage;
