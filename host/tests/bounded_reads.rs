//! Reads are bounded by what the header promises: a PGM whose file is longer than its header
//! says is refused from its size (not read whole), a FIFO is refused before it is opened (a
//! read never hangs), and a capture declaring frames above the format's maximum is refused
//! before any frame is read. Each read runs in a thread with a timeout, so a regression
//! fails instead of hanging or filling memory.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use tangent_host::capture::{Capture, CaptureError, MAX_FRAME_SIDE};
use tangent_host::pgm::{Pgm, PgmError};

/// Runs `f` in a thread; fails the test if it takes longer than 20 s.
fn within_timeout<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(20))
        .expect("the read did not finish within 20 s")
}

fn small_pgm(path: &Path) -> u64 {
    let pgm = Pgm::from_u16(4, 3, 1023, vec![7; 12]).unwrap();
    pgm.write(path).unwrap();
    std::fs::metadata(path).unwrap().len()
}

#[test]
fn a_pgm_extended_to_1_5_gb_is_refused_without_being_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("on.pgm");
    let len = small_pgm(&path);
    // Sparse: costs no disk and no time to make; reading it whole would take 1.5 GB.
    const EXTENDED: u64 = 1_500_000_000;
    std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(EXTENDED)
        .unwrap();
    let started = std::time::Instant::now();
    let result = within_timeout(move || Pgm::read(&path));
    match result {
        Err(PgmError::TrailingData(n)) => assert_eq!(n as u64, EXTENDED - len),
        other => panic!("expected TrailingData, got {other:?}"),
    }
    // Reading 1.5 GB takes seconds; refusing from the size takes microseconds.
    assert!(
        started.elapsed() < Duration::from_secs(1),
        "{:?}",
        started.elapsed()
    );
}

#[test]
fn a_truncated_pgm_is_refused_with_its_byte_counts() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("on.pgm");
    let len = small_pgm(&path);
    std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(len - 5)
        .unwrap();
    match Pgm::read(&path) {
        Err(PgmError::Truncated { expected, actual }) => assert_eq!((expected, actual), (24, 19)),
        other => panic!("expected Truncated, got {other:?}"),
    }
}

#[test]
fn a_fifo_named_on_pgm_is_refused_not_waited_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("on.pgm");
    nix::unistd::mkfifo(&path, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let shown = path.display().to_string();
    let result = within_timeout(move || Pgm::read(&path));
    match result {
        Err(e @ PgmError::NotAFile { .. }) => {
            assert_eq!(e.to_string(), format!("{shown}: not a regular file"))
        }
        other => panic!("expected NotAFile, got {other:?}"),
    }
}

#[test]
fn a_directory_named_on_pgm_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    assert!(matches!(
        Pgm::read(dir.path()),
        Err(PgmError::NotAFile { .. })
    ));
}

fn corpus_capture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/captures/cyl-d300-z150-shade")
}

/// A copy of a corpus capture, edited.
fn edited_capture(edit: impl FnOnce(&Path)) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for entry in std::fs::read_dir(corpus_capture()).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.path().join(entry.file_name())).unwrap();
    }
    edit(dir.path());
    dir
}

fn first_frame(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(dir.join("capture.toml")).unwrap();
    let meta = tangent_host::capture::CaptureMeta::parse(&text).unwrap();
    dir.join(&meta.frames[0].file)
}

#[test]
fn a_capture_frame_that_is_a_fifo_is_refused() {
    let dir = edited_capture(|d| {
        let frame = first_frame(d);
        std::fs::remove_file(&frame).unwrap();
        nix::unistd::mkfifo(&frame, nix::sys::stat::Mode::S_IRWXU).unwrap();
    });
    let path = dir.path().to_path_buf();
    let result = within_timeout(move || Capture::read(&path).map(|_| ()));
    assert!(
        matches!(
            result,
            Err(CaptureError::Pgm {
                source: PgmError::NotAFile { .. },
                ..
            })
        ),
        "{result:?}"
    );
}

#[test]
fn a_frame_whose_header_declares_8000x8000_is_refused_before_its_raster_is_read() {
    let dir = edited_capture(|d| {
        // A real 8000 × 8000 16-bit raster (128 MB), sparse on disk.
        let frame = first_frame(d);
        let header = b"P5\n8000 8000\n1023\n";
        std::fs::write(&frame, header).unwrap();
        std::fs::OpenOptions::new()
            .write(true)
            .open(&frame)
            .unwrap()
            .set_len(header.len() as u64 + 8000 * 8000 * 2)
            .unwrap();
    });
    let path = dir.path().to_path_buf();
    let started = std::time::Instant::now();
    let result = within_timeout(move || Capture::read(&path).map(|_| ()));
    assert!(
        matches!(
            result,
            Err(CaptureError::FrameSizeMismatch {
                actual: (8000, 8000),
                ..
            })
        ),
        "{result:?}"
    );
    assert!(
        started.elapsed() < Duration::from_secs(1),
        "{:?}",
        started.elapsed()
    );
}

#[test]
fn a_capture_declaring_frames_above_the_maximum_is_refused() {
    let text = std::fs::read_to_string(corpus_capture().join("capture.toml")).unwrap();
    let big = text.replacen("width = 752", "width = 8000", 1).replacen(
        "height = 480",
        "height = 8000",
        1,
    );
    assert_ne!(big, text);
    let err = tangent_host::capture::CaptureMeta::parse(&big).unwrap_err();
    assert!(
        err.to_string()
            .contains("8000x8000 exceeds the format's maximum"),
        "{err}"
    );
    let side = MAX_FRAME_SIDE;
    let at_limit = text
        .replacen("width = 752", &format!("width = {side}"), 1)
        .replacen("height = 480", "height = 1", 1);
    tangent_host::capture::CaptureMeta::parse(&at_limit).unwrap();
}

#[test]
fn inspect_refuses_an_8000x8000_capture_with_a_clear_message() {
    let dir = edited_capture(|d| {
        let meta = d.join("capture.toml");
        let text = std::fs::read_to_string(&meta).unwrap();
        let big = text.replacen("width = 752", "width = 8000", 1).replacen(
            "height = 480",
            "height = 8000",
            1,
        );
        std::fs::write(&meta, big).unwrap();
    });
    let out_png = dir.path().join("inspect.png");
    let out = within_timeout({
        let capture = dir.path().to_path_buf();
        move || {
            std::process::Command::new(env!("CARGO_BIN_EXE_tangent"))
                .arg("inspect")
                .arg(&capture)
                .arg("--out")
                .arg(&out_png)
                .output()
                .unwrap()
        }
    });
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("frame size 8000x8000 exceeds the format's maximum"),
        "{stderr}"
    );
    assert!(!dir.path().join("inspect.png").exists());
}

#[test]
fn a_capture_toml_that_is_a_fifo_is_refused_not_waited_on() {
    let dir = edited_capture(|d| {
        let meta = d.join("capture.toml");
        std::fs::remove_file(&meta).unwrap();
        nix::unistd::mkfifo(&meta, nix::sys::stat::Mode::S_IRWXU).unwrap();
    });
    let path = dir.path().to_path_buf();
    let result = within_timeout(move || Capture::read(&path).map(|_| ()));
    match result {
        Err(e @ CaptureError::Io { .. }) => {
            let text = e.to_string();
            assert!(text.starts_with("capture.toml: "), "{text}");
            assert!(text.contains("not a regular file"), "{text}");
        }
        other => panic!("expected an I/O error naming capture.toml, got {other:?}"),
    }
}

#[test]
fn a_broken_optional_truth_curve_does_not_block_the_measurement() {
    // One broken row; and, separately, a truth curve that is a FIFO.
    let broken = edited_capture(|d| {
        let path = d.join("truth-curve.csv");
        let mut text = std::fs::read_to_string(&path).unwrap();
        text.push_str("0,12,not-a-number,0,0,0,0\n");
        std::fs::write(&path, text).unwrap();
    });
    let fifo = edited_capture(|d| {
        let path = d.join("truth-curve.csv");
        std::fs::remove_file(&path).unwrap();
        nix::unistd::mkfifo(&path, nix::sys::stat::Mode::S_IRWXU).unwrap();
    });
    for dir in [broken, fifo] {
        let path = dir.path().to_path_buf();
        let capture = within_timeout(move || Capture::read(&path)).expect("still a capture");
        assert!(capture.truth_curve.is_none());
        let why = capture
            .truth_curve_unreadable
            .clone()
            .expect("the problem is named");
        assert!(why.contains("truth-curve.csv"), "{why}");
        let outcome = tangent_host::measure::measure_loaded(
            &capture,
            "edited",
            None,
            &Default::default(),
            &Default::default(),
        )
        .expect("measured");
        assert!(
            outcome.reading.diameter_m.is_some(),
            "{:?}",
            outcome.reading
        );
        let summary = outcome.reading.summary();
        assert!(summary.contains("(truth curve ignored: "), "{summary}");
        assert!(summary.contains("truth-curve.csv"), "{summary}");
    }
}
