//! Every file error of the `tangent` command names its path and its cause, once, and
//! `tangent measure` reports a bad argument without giving up on the others (exit status as
//! its `--help` documents: 0 all read and measured, 1 some without a reading, 2 something
//! unreadable).
//!
//! These run the built binary, as a user would, on broken copies of a corpus capture.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use tangent_host::capture::Capture;

/// The capture the README's main command measures.
fn good_capture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/captures/cyl-d300-z150-shade")
}

fn tangent(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("the tangent binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// `out` failed with `code`, and its standard error names `path` and contains `cause`, with
/// no OS error and no path printed twice.
#[track_caller]
fn fails_naming(out: &Output, code: i32, path: &str, cause: &str) {
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "stderr: {err}");
    assert!(err.contains(path), "{path:?} not named in: {err}");
    assert!(err.contains(cause), "{cause:?} not in: {err}");
    assert!(
        err.matches("(os error").count() <= 1,
        "an OS error printed twice: {err}"
    );
    assert_eq!(
        err.matches(path).count(),
        1,
        "{path:?} named more than once: {err}"
    );
}

/// A copy of the good capture in a temporary directory, changed by `edit`.
fn broken_capture(edit: impl FnOnce(&Path)) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("broken");
    Capture::read(&good_capture()).unwrap().write(&dir).unwrap();
    edit(&dir);
    (tmp, dir)
}

#[test]
fn measure_names_a_missing_path_and_a_plain_file() {
    let out = tangent(&["measure", "no/such/capture"]);
    fails_naming(&out, 2, "no/such/capture", "no such capture directory");

    let file = good_capture().join("capture.toml");
    let out = tangent(&["measure", file.to_str().unwrap()]);
    fails_naming(&out, 2, file.to_str().unwrap(), "not a directory");

    let empty = tempfile::tempdir().unwrap();
    let out = tangent(&["measure", empty.path().to_str().unwrap()]);
    fails_naming(
        &out,
        2,
        empty.path().to_str().unwrap(),
        "nor a directory of captures",
    );
}

#[test]
fn one_bad_argument_does_not_stop_the_batch() {
    let good = good_capture();
    let good = good.to_str().unwrap();
    let out = tangent(&["measure", "no/such/capture", good]);
    fails_naming(&out, 2, "no/such/capture", "no such capture directory");
    let stdout = text(&out.stdout);
    assert!(stdout.contains(good) && stdout.contains("d = "), "{stdout}");

    // With --json every capture has its line, the unreadable one an error object.
    let out = tangent(&["measure", "--json", good, "no/such/capture"]);
    assert_eq!(out.status.code(), Some(2));
    let lines: Vec<serde_json::Value> = text(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
        .collect();
    assert_eq!(lines.len(), 2, "{lines:?}");
    assert!(lines[0]["diameter_m"].is_number(), "{}", lines[0]);
    assert_eq!(
        lines[1]["error"],
        "no/such/capture: no such capture directory"
    );
}

#[test]
fn measure_names_the_broken_file_inside_a_capture() {
    let (_tmp, dir) = broken_capture(|d| std::fs::remove_file(d.join("on.pgm")).unwrap());
    let out = tangent(&["measure", dir.to_str().unwrap()]);
    fails_naming(&out, 2, dir.to_str().unwrap(), "on.pgm: No such file");

    let (_tmp, dir) = broken_capture(|d| {
        let p = d.join("off.pgm");
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 10]).unwrap();
    });
    let out = tangent(&["measure", dir.to_str().unwrap()]);
    fails_naming(&out, 2, dir.to_str().unwrap(), "frame off.pgm: truncated");

    // A calibration kept in a file beside the capture, with a typo.
    let (_tmp, dir) = broken_capture(|d| {
        let mut c = Capture::read(d).unwrap();
        c.meta.calibration = toml::Value::String("../unit.toml".into());
        c.write(d).unwrap();
        let text = tangent_host::calibration_file::to_string(&c.calibration);
        std::fs::write(d.join("../unit.toml"), text.replace("fx_px", "fx")).unwrap();
    });
    let out = tangent(&["measure", dir.to_str().unwrap()]);
    fails_naming(
        &out,
        2,
        dir.to_str().unwrap(),
        "calibration file ../unit.toml: unknown key `fx`",
    );
}

#[test]
fn a_calibration_file_error_names_the_file() {
    let good = good_capture();
    let out = tangent(&["measure", good.to_str().unwrap(), "--calib", "no-such.toml"]);
    fails_naming(&out, 2, "no-such.toml", "No such file");
    let out = tangent(&[
        "measure",
        "--json",
        good.to_str().unwrap(),
        "--calib",
        "no-such.toml",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let line: serde_json::Value = serde_json::from_str(text(&out.stdout).trim()).unwrap();
    assert!(
        line["error"]
            .as_str()
            .unwrap()
            .starts_with("no-such.toml: "),
        "{line}"
    );

    for args in [
        &["accuracy", "--calib", "no-such.toml"][..],
        &["device-calibration", "push", "no-such.toml"],
        &[
            "calibrate",
            "laser",
            good.to_str().unwrap(),
            "--camera",
            "no-such.toml",
        ],
    ] {
        fails_naming(&tangent(args), 1, "no-such.toml", "No such file");
    }
    // A file that is not a calibration: the file and the line.
    let not_toml = good.join("truth-curve.csv");
    fails_naming(
        &tangent(&["accuracy", "--calib", not_toml.to_str().unwrap()]),
        1,
        not_toml.to_str().unwrap(),
        "(line 1)",
    );
}

#[test]
fn other_commands_name_their_paths() {
    fails_naming(
        &tangent(&["inspect", "no/such/capture"]),
        1,
        "no/such/capture",
        "no such capture directory",
    );
    fails_naming(
        &tangent(&[
            "simulate",
            "again",
            "no/such/capture",
            "--seed",
            "2",
            "--out",
            "x",
        ]),
        1,
        "no/such/capture",
        "no such capture directory",
    );
    fails_naming(
        &tangent(&["log", "export", "--format", "csv", "--log", "no-such.log"]),
        1,
        "no-such.log",
        "No such file",
    );
    // Writing into a path under a regular file.
    let (_tmp, dir) = broken_capture(|_| {});
    let under_file = dir.join("capture.toml").join("out");
    let under_file = under_file.to_str().unwrap();
    fails_naming(
        &tangent(&[
            "inspect",
            dir.to_str().unwrap(),
            "--out",
            &format!("{under_file}.png"),
        ]),
        1,
        under_file,
        "Not a directory",
    );
    fails_naming(
        &tangent(&[
            "measure",
            good_capture().to_str().unwrap(),
            "--plot",
            under_file,
        ]),
        2,
        under_file,
        "Not a directory",
    );
    fails_naming(
        &tangent(&["simulate", "stem", "--out", under_file]),
        1,
        under_file,
        "Not a directory",
    );
}

#[test]
fn measure_exits_as_its_help_says() {
    let help = text(&tangent(&["measure", "--help"]).stdout);
    for promise in [
        "0 when every capture gave a reading",
        "1 when some gave none",
        "2 when a capture",
    ] {
        assert!(help.contains(promise), "{promise:?} not in --help:\n{help}");
    }
    let good = good_capture();
    assert_eq!(
        tangent(&["measure", good.to_str().unwrap()]).status.code(),
        Some(0)
    );
    let refused = good.with_file_name("cyl-d1000-z050-partly-outside");
    let out = tangent(&["measure", good.to_str().unwrap(), refused.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stdout));
}
