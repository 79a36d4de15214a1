//! `tangent listen` opens the port before it touches the field log: a listen that cannot
//! reach the device creates no log, appends no plot header and sets no torn tail aside.

use std::path::Path;
use std::process::{Command, Output};

use tangent_host::fieldlog::{FieldLog, PlotHeader, Record};

fn listen(log: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args([
            "listen",
            "--port",
            "/nonexistent/tangent-tty",
            "--plot-id",
            "new-plot",
        ])
        .arg("--log")
        .arg(log)
        .output()
        .unwrap()
}

fn assert_port_error(out: &Output) {
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("/nonexistent/tangent-tty"), "{stderr}");
    assert!(!stderr.contains("started plot"), "{stderr}");
}

#[test]
fn a_missing_port_creates_no_log() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("field.log");
    assert_port_error(&listen(&log));
    assert!(
        !log.exists(),
        "listen created the log before opening the port"
    );
}

#[test]
fn a_missing_port_leaves_an_existing_log_and_its_torn_tail_alone() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("field.log");
    {
        let mut field_log = FieldLog::open(&log).unwrap();
        field_log
            .append(Record::Plot(PlotHeader {
                plot_id: "P-1".into(),
                started: "2025-06-01T08:00:00Z".into(),
                note: String::new(),
            }))
            .unwrap();
    }
    // A torn last record, as a crash mid-write leaves it.
    let mut bytes = std::fs::read(&log).unwrap();
    bytes.extend_from_slice(b"T\t{\"plot_id\":\"P-1\",\"tree_");
    std::fs::write(&log, &bytes).unwrap();

    assert_port_error(&listen(&log));
    assert_eq!(std::fs::read(&log).unwrap(), bytes, "the log was changed");
    let entries: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(entries, vec![std::ffi::OsString::from("field.log")]);
}
