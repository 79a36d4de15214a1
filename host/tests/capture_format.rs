//! The capture format (`docs/formats.md`): PGM and calibration/capture TOML round trips,
//! every documented error, fuzzing of the readers, and the committed corpus (readable, and
//! regenerated bit for bit).

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use tangent_core::calibration::Calibration;
use tangent_host::calibration_file::{self, CalibrationFileError};
use tangent_host::capture::{Capture, CaptureError, CaptureMeta};
use tangent_host::pgm::{Pgm, PgmError, PgmSamples};
use tangent_host::simulate::corpus;

// ---------------------------------------------------------------------------------------
// PGM

#[test]
fn pgm_8bit_round_trip() {
    let data: Vec<u8> = (0..12u8).map(|v| v * 20).collect();
    let pgm = Pgm::from_u8(4, 3, 255, data.clone()).unwrap();
    let bytes = pgm.encode().unwrap();
    assert!(bytes.starts_with(b"P5\n4 3\n255\n"));
    assert_eq!(&bytes[bytes.len() - 12..], &data[..]);
    assert_eq!(Pgm::decode(&bytes).unwrap(), pgm);
    assert_eq!(pgm.bit_depth(), 8);
}

#[test]
fn pgm_16bit_is_big_endian() {
    let pgm = Pgm::from_u16(2, 1, 1023, vec![0x0102, 0x03FF]).unwrap();
    let bytes = pgm.encode().unwrap();
    assert_eq!(&bytes[bytes.len() - 4..], &[0x01, 0x02, 0x03, 0xFF]);
    let back = Pgm::decode(&bytes).unwrap();
    assert_eq!(back.samples, PgmSamples::U16(vec![0x0102, 0x03FF]));
    assert_eq!(back.bit_depth(), 10);
}

#[test]
fn pgm_header_comments_and_whitespace() {
    let mut bytes = b"P5 # made by hand\n# another comment\n2\t2\r\n# maxval next\n255\n".to_vec();
    bytes.extend_from_slice(&[1, 2, 3, 4]);
    let pgm = Pgm::decode(&bytes).unwrap();
    assert_eq!((pgm.width, pgm.height, pgm.maxval), (2, 2, 255));
    assert_eq!(pgm.get(1, 1), Some(4));
}

#[test]
fn pgm_errors() {
    let ok = Pgm::from_u8(3, 2, 255, vec![9; 6])
        .unwrap()
        .encode()
        .unwrap();
    assert!(
        matches!(Pgm::decode(b"P2\n3 2\n255\n"), Err(PgmError::BadMagic { found }) if found == "P2")
    );
    assert!(matches!(Pgm::decode(b""), Err(PgmError::BadMagic { .. })));
    match Pgm::decode(&ok[..ok.len() - 2]) {
        Err(PgmError::Truncated {
            expected: 6,
            actual: 4,
        }) => {}
        other => panic!("expected Truncated {{6, 4}}, got {other:?}"),
    }
    let mut long = ok.clone();
    long.push(0);
    assert!(matches!(Pgm::decode(&long), Err(PgmError::TrailingData(1))));
    assert!(matches!(
        Pgm::decode(b"P5\n3 2\n70000\n"),
        Err(PgmError::BadMaxval(70000))
    ));
    assert!(matches!(
        Pgm::decode(b"P5\n3 2\n0\n"),
        Err(PgmError::BadMaxval(0))
    ));
    assert!(matches!(
        Pgm::decode(b"P5\n3 x\n255\n"),
        Err(PgmError::BadHeader { field: "height" })
    ));
    assert!(matches!(
        Pgm::decode(b"P5\n0 2\n255\n"),
        Err(PgmError::BadHeader { field: "width" })
    ));
    assert!(matches!(
        Pgm::decode(b"P5\n3 2\n255"),
        Err(PgmError::BadHeader { field: "maxval" })
    ));
    let mut above = b"P5\n2 1\n100\n".to_vec();
    above.extend_from_slice(&[50, 101]);
    assert!(matches!(
        Pgm::decode(&above),
        Err(PgmError::SampleAboveMaxval {
            x: 1,
            y: 0,
            value: 101,
            maxval: 100
        })
    ));
    assert!(matches!(
        Pgm::decode(b"P5\n99999999999 99999999999\n255\n"),
        Err(PgmError::TooLarge { .. })
    ));
    assert!(matches!(
        Pgm::from_u8(3, 2, 255, vec![0; 5]),
        Err(PgmError::InvalidImage(_))
    ));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    /// Arbitrary bytes never panic the PGM reader.
    #[test]
    fn pgm_decode_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
        let _ = Pgm::decode(&bytes);
    }

    /// A valid header with mutated bytes never panics, and an unmutated raster decodes.
    #[test]
    fn pgm_mutated_never_panics(w in 1usize..6, h in 1usize..6, wide in any::<bool>(),
                                flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..4)) {
        let pgm = if wide {
            Pgm::from_u16(w, h, 4095, vec![4095; w * h]).unwrap()
        } else {
            Pgm::from_u8(w, h, 255, vec![7; w * h]).unwrap()
        };
        let mut bytes = pgm.encode().unwrap();
        prop_assert_eq!(Pgm::decode(&bytes).unwrap(), pgm);
        let n = bytes.len();
        for (i, v) in flips {
            bytes[i % n] = v;
        }
        let _ = Pgm::decode(&bytes);
    }
}

// ---------------------------------------------------------------------------------------
// Calibration TOML

fn reference_text() -> String {
    calibration_file::to_string(&corpus::two_plane_calibration())
}

#[test]
fn calibration_round_trip_is_exact() {
    // TOML floats are written with Rust's shortest round-trip representation, so the
    // parsed calibration equals the original bit for bit (no tolerance needed).
    let c = corpus::distorted_calibration();
    let back = calibration_file::parse(&calibration_file::to_string(&c)).unwrap();
    assert_eq!(back, c);
    let c2 = corpus::two_plane_calibration();
    assert_eq!(calibration_file::parse(&reference_text()).unwrap(), c2);
}

/// A refined calibration's `[planes_uncertainty]` round-trips; one that is no covariance, or
/// covers other planes than the file has, is refused naming the table.
#[test]
fn calibration_planes_uncertainty_round_trips_and_is_checked() {
    use tangent_core::calibration::PlanesUncertainty;
    let u = PlanesUncertainty::new(
        &[2e-4, 1.9e-4, 2e-4, 1.8e-4],
        &[
            1.0, 0.0, 0.9, 0.0, //
            0.0, 1.0, 0.0, 0.96, //
            0.9, 0.0, 1.0, 0.0, //
            0.0, 0.96, 0.0, 1.0,
        ],
    )
    .unwrap();
    let c = corpus::two_plane_calibration().with_uncertainty(u).unwrap();
    let text = calibration_file::to_string(&c);
    assert!(text.contains("[planes_uncertainty]"), "{text}");
    assert_eq!(calibration_file::parse(&text).unwrap(), c);
    let refused = |text: &str| match calibration_file::parse(text) {
        Err(e @ CalibrationFileError::Uncertainty(_)) => e.to_string(),
        other => panic!("expected [planes_uncertainty] refused, got {other:?}"),
    };
    let above_one = refused(&text.replacen("0.96", "1.5", 1));
    assert!(above_one.starts_with("[planes_uncertainty]"), "{above_one}");
    let one_plane = text.replace(
        "sigma = [0.0002, 0.00019, 0.0002, 0.00018]",
        "sigma = [0.0002, 0.00019]",
    );
    assert_ne!(one_plane, text);
    assert!(refused(&one_plane).contains("correlation"), "{one_plane}");
}

#[test]
fn calibration_units_are_in_the_keys() {
    let text = reference_text();
    for key in [
        "fx_px",
        "cy_px",
        "width_px",
        "offset_m",
        "source_m",
        "[[planes]]",
        "[camera.distortion]",
    ] {
        assert!(text.contains(key), "{key} missing in\n{text}");
    }
}

#[test]
fn calibration_unknown_key_names_key_and_line() {
    let text = reference_text().replace("fx_px", "fx_pixels");
    let line = text
        .lines()
        .position(|l| l.starts_with("fx_pixels"))
        .unwrap()
        + 1;
    match calibration_file::parse(&text) {
        Err(CalibrationFileError::UnknownKey { key, line: Some(l) }) => {
            assert_eq!(key, "fx_pixels");
            assert_eq!(l, line);
        }
        other => panic!("expected UnknownKey, got {other:?}"),
    }
    let misspelt = reference_text().replace("k1 =", "kl =");
    assert!(
        matches!(calibration_file::parse(&misspelt), Err(CalibrationFileError::UnknownKey { key, .. }) if key == "kl")
    );
}

#[test]
fn calibration_missing_planes_and_keys() {
    let text = reference_text();
    let no_planes: String = text.split("[[planes]]").next().unwrap().to_string();
    assert!(matches!(
        calibration_file::parse(&no_planes),
        Err(CalibrationFileError::MissingPlanes)
    ));
    let no_fx: String = text
        .lines()
        .filter(|l| !l.starts_with("fx_px"))
        .collect::<Vec<_>>()
        .join("\n");
    assert!(
        matches!(calibration_file::parse(&no_fx), Err(CalibrationFileError::MissingKey { key, .. }) if key == "fx_px")
    );
    let five = format!(
        "{text}{}",
        &text[text.find("[[planes]]").unwrap()..].repeat(2)
    );
    assert!(matches!(
        calibration_file::parse(&five),
        Err(CalibrationFileError::TooManyPlanes(6))
    ));
}

#[test]
fn calibration_invalid_values_and_syntax() {
    let zero_normal = reference_text().replacen("normal = [", "normal = [0.0, 0.0, 0.0, ", 1);
    // Four components: a type error (array of 3 expected) is a syntax-level error.
    let r = calibration_file::parse(&zero_normal);
    assert!(
        matches!(r, Err(CalibrationFileError::Syntax { .. })),
        "{r:?}"
    );
    let c = corpus::one_plane_calibration();
    let mut file = calibration_file::CalibrationToml::from_calibration(&c);
    file.planes[0].normal = [0.0, 0.0, 0.0];
    let text = toml::to_string(&file).unwrap();
    assert!(matches!(
        calibration_file::parse(&text),
        Err(CalibrationFileError::Invalid(_))
    ));
    assert!(matches!(
        calibration_file::parse("id = ["),
        Err(CalibrationFileError::Syntax { line: Some(1), .. })
    ));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, ..ProptestConfig::default() })]

    /// Arbitrary text never panics the calibration or capture readers.
    #[test]
    fn toml_readers_never_panic(text in "\\PC{0,200}") {
        let _ = calibration_file::parse(&text);
        let _ = CaptureMeta::parse(&text);
    }

    /// A valid calibration with one character replaced never panics the reader.
    #[test]
    fn calibration_mutated_never_panics(pos in any::<usize>(), c in any::<char>()) {
        let text = reference_text();
        let mut chars: Vec<char> = text.chars().collect();
        let n = chars.len();
        chars[pos % n] = c;
        let _ = calibration_file::parse(&chars.into_iter().collect::<String>());
    }
}

// ---------------------------------------------------------------------------------------
// Capture directories

const FRAME: (usize, usize) = (752, 480);

/// Writes a hand-made capture as a third party would (docs/formats.md example).
fn hand_made(dir: &Path, extra_meta: &str, calibration: &str) {
    std::fs::create_dir_all(dir).unwrap();
    let (w, h) = FRAME;
    Pgm::from_u8(w, h, 255, vec![10; w * h])
        .unwrap()
        .write(&dir.join("off.pgm"))
        .unwrap();
    let mut on = vec![10u8; w * h];
    on[240 * w..241 * w].fill(200);
    Pgm::from_u8(w, h, 255, on)
        .unwrap()
        .write(&dir.join("on.pgm"))
        .unwrap();
    let text = format!(
        r#"format_version = 1
sensor = "MT9V034"
width = 752
height = 480
bit_depth = 8
exposure_s = 0.01
gain = 1.0
mode = "cylinder"
timestamp = 2025-06-01T10:00:00Z
{extra_meta}
frames = [
  {{ file = "off.pgm", lasers_on = [] }},
  {{ file = "on.pgm", lasers_on = [0] }},
]
{calibration}
"#
    );
    std::fs::write(dir.join("capture.toml"), text).unwrap();
}

fn inline_calibration(c: &Calibration) -> String {
    // The calibration file's tables, re-rooted under [calibration].
    let text = calibration_file::to_string(c);
    let mut out = String::from("[calibration]\n");
    for line in text.lines() {
        if let Some(rest) = line.strip_prefix("[[") {
            out.push_str(&format!("[[calibration.{rest}\n"));
        } else if let Some(rest) = line.strip_prefix('[') {
            out.push_str(&format!("[calibration.{rest}\n"));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

#[test]
fn hand_made_capture_reads_with_inline_or_file_calibration() {
    let tmp = tempfile::tempdir().unwrap();
    let c = corpus::one_plane_calibration();
    hand_made(&tmp.path().join("a"), "", &inline_calibration(&c));
    let cap = Capture::read(&tmp.path().join("a")).unwrap();
    assert_eq!(cap.calibration, c);
    assert_eq!(cap.off_frame().get(0, 0), Some(10));
    let (lit, on) = cap.on_frames().next().unwrap();
    assert_eq!((lit, on.get(5, 240)), (&[0usize][..], Some(200)));

    calibration_file::write(&tmp.path().join("unit.toml"), &c).unwrap();
    hand_made(&tmp.path().join("b"), "", "calibration = \"../unit.toml\"");
    assert_eq!(Capture::read(&tmp.path().join("b")).unwrap().calibration, c);
}

fn read_err(extra_meta: &str, calibration: &str, edit: impl FnOnce(&Path)) -> CaptureError {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("c");
    hand_made(&dir, extra_meta, calibration);
    edit(&dir);
    Capture::read(&dir).expect_err("capture should be rejected")
}

fn edit_meta(dir: &Path, from: &str, to: &str) {
    let p = dir.join("capture.toml");
    let t = std::fs::read_to_string(&p).unwrap();
    assert!(t.contains(from), "{from} not in capture.toml");
    std::fs::write(p, t.replacen(from, to, 1)).unwrap();
}

#[test]
fn capture_errors() {
    let cal = inline_calibration(&corpus::one_plane_calibration());
    let e = read_err("", &cal, |d| edit_meta(d, "exposure_s", "exposure_ms"));
    assert!(
        matches!(e, CaptureError::UnknownKey { ref key, line: Some(6) } if key == "exposure_ms"),
        "{e}"
    );
    let e = read_err("", &cal, |d| edit_meta(d, "fx_px", "fx"));
    assert!(
        matches!(e, CaptureError::Calibration(CalibrationFileError::UnknownKey { ref key, .. }) if key == "fx"),
        "{e}"
    );
    let e = read_err("", &cal, |d| edit_meta(d, "gain = 1.0\n", ""));
    assert!(
        matches!(e, CaptureError::MissingKey { ref key, .. } if key == "gain"),
        "{e}"
    );
    let e = read_err("", &cal, |d| {
        edit_meta(d, "format_version = 1", "format_version = 2")
    });
    assert!(matches!(e, CaptureError::UnsupportedVersion(2)), "{e}");
    let e = read_err("", &cal, |d| {
        edit_meta(
            d,
            "timestamp = 2025-06-01T10:00:00Z",
            "timestamp = 2025-06-01",
        )
    });
    assert!(matches!(e, CaptureError::InvalidField(_)), "{e}");

    // Size mismatch with the calibration.
    let mut small = corpus::one_plane_calibration();
    small.camera.width = 640;
    let e = read_err("", &inline_calibration(&small), |_| {});
    assert!(
        matches!(
            e,
            CaptureError::CalibrationSizeMismatch {
                frames: (752, 480),
                calibration: (640, 480)
            }
        ),
        "{e}"
    );
    // A frame of the wrong size.
    let e = read_err("", &cal, |d| {
        Pgm::from_u8(10, 10, 255, vec![0; 100])
            .unwrap()
            .write(&d.join("on.pgm"))
            .unwrap()
    });
    assert!(
        matches!(
            e,
            CaptureError::FrameSizeMismatch {
                actual: (10, 10),
                ..
            }
        ),
        "{e}"
    );
    // A 10-bit frame in an 8-bit capture.
    let e = read_err("", &cal, |d| {
        Pgm::from_u16(752, 480, 1023, vec![0; 752 * 480])
            .unwrap()
            .write(&d.join("on.pgm"))
            .unwrap()
    });
    assert!(
        matches!(
            e,
            CaptureError::WrongMaxval {
                expected: 255,
                actual: 1023,
                ..
            }
        ),
        "{e}"
    );
    // A truncated frame.
    let e = read_err("", &cal, |d| {
        let p = d.join("off.pgm");
        let b = std::fs::read(&p).unwrap();
        std::fs::write(&p, &b[..b.len() - 100]).unwrap();
    });
    assert!(
        matches!(
            e,
            CaptureError::Pgm {
                source: PgmError::Truncated {
                    expected: 360960,
                    actual: 360860
                },
                ..
            }
        ),
        "{e}"
    );
    // Frame bookkeeping.
    let e = read_err("", &cal, |d| {
        edit_meta(d, "lasers_on = []", "lasers_on = [0]")
    });
    assert!(matches!(e, CaptureError::OffFrameCount(0)), "{e}");
    let e = read_err("", &cal, |d| {
        edit_meta(d, "lasers_on = [0]", "lasers_on = [1]")
    });
    assert!(
        matches!(
            e,
            CaptureError::NoSuchPlane {
                plane: 1,
                count: 1,
                ..
            }
        ),
        "{e}"
    );
    let e = read_err("", &cal, |d| {
        edit_meta(d, "file = \"on.pgm\"", "file = \"../on.pgm\"")
    });
    assert!(matches!(e, CaptureError::BadFileName(_)), "{e}");
    // Missing planes in the inline calibration.
    let no_planes = cal
        .split("[[calibration.planes]]")
        .next()
        .unwrap()
        .to_string();
    let e = read_err("", &no_planes, |_| {});
    assert!(
        matches!(
            e,
            CaptureError::Calibration(CalibrationFileError::MissingPlanes)
        ),
        "{e}"
    );
    // A malformed truth curve is optional ground truth: the capture still reads, without it,
    // and the problem is named (file and line).
    let truth = "[truth]\ntruth_curve = \"t.csv\"\n";
    let tail = format!("{cal}{truth}");
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("c");
    hand_made(&dir, "", &tail);
    std::fs::write(
        dir.join("t.csv"),
        "plane,column,row_px,x_m,y_m,z_m,object\n0,1,nan,0,0,1,0\n",
    )
    .unwrap();
    let capture = Capture::read(&dir)
        .map_err(|e| e.to_string())
        .expect("still readable");
    assert!(capture.truth_curve.is_none());
    let why = capture.truth_curve_unreadable.expect("named");
    assert!(why.contains("t.csv line 2"), "{why}");
}

// ---------------------------------------------------------------------------------------
// The committed corpus

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/captures")
}

#[test]
fn corpus_matches_the_entry_list_and_reads() {
    let entries = corpus::entries();
    assert!(entries.len() >= 40, "the corpus needs at least 40 captures");
    for e in &entries {
        let dir = corpus_dir().join(&e.name);
        let cap = Capture::read(&dir).unwrap_or_else(|err| panic!("{}: {err}", e.name));
        assert_eq!(cap.calibration, e.spec.calibration, "{}", e.name);
        assert!(cap.truth_curve.is_some(), "{}", e.name);
    }
}

#[test]
fn corpus_regenerates_bit_for_bit() {
    // One capture of each kind of feature that touches the byte stream: a plain stem, the
    // 10-bit one, a distorted lens with two-plane hand motion… rendering all 45 takes ~30 s
    // in release; three suffice to catch any change of the simulator's output.
    let names = [
        "cyl-d300-z150-shade",
        "cyl-d300-z150-10bit",
        "cyl-d300-z150-tilt20-away-2p",
        // The chessboard target (anti-aliased square edges) and three frames.
        "board-pose-03",
    ];
    let entries: Vec<_> = corpus::entries()
        .into_iter()
        .filter(|e| names.contains(&e.name.as_str()))
        .collect();
    assert_eq!(entries.len(), names.len());
    let tmp = tempfile::tempdir().unwrap();
    corpus::write_entries(&entries, tmp.path()).unwrap();
    for name in names {
        for file in std::fs::read_dir(corpus_dir().join(name)).unwrap() {
            let file = file.unwrap().file_name();
            let committed = std::fs::read(corpus_dir().join(name).join(&file)).unwrap();
            let fresh = std::fs::read(tmp.path().join(name).join(&file))
                .unwrap_or_else(|_| panic!("{name}/{file:?} not regenerated"));
            assert!(
                committed == fresh,
                "{name}/{file:?} differs from its regeneration"
            );
        }
    }
}

/// A capture taken while the trigger was held: two exposure pairs, each with its own
/// laser-off frame (`docs/formats.md` §3), read as two captures of one pair each; a pair
/// without its laser-off frame is named.
#[test]
fn exposure_pairs_read_and_a_broken_pair_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("pairs");
    let c = corpus::one_plane_calibration();
    hand_made(&dir, "", &inline_calibration(&c));
    for name in ["off.pgm", "on.pgm"] {
        std::fs::copy(dir.join(name), dir.join(format!("p1-{name}"))).unwrap();
    }
    let two_pairs = r#"  { file = "on.pgm", lasers_on = [0] },
  { file = "p1-off.pgm", lasers_on = [], pair = 1 },
  { file = "p1-on.pgm", lasers_on = [0], pair = 1 },"#;
    edit_meta(
        &dir,
        r#"  { file = "on.pgm", lasers_on = [0] },"#,
        two_pairs,
    );
    let cap = Capture::read(&dir).unwrap();
    assert_eq!(cap.pairs(), 2);
    let second = cap.exposure_pair(1).unwrap();
    assert_eq!((second.pairs(), second.frames.len()), (1, 2));
    assert_eq!(second.meta.frames[0].file, "p1-off.pgm");
    assert!(cap.exposure_pair(2).is_none());
    // The first pair is what single-pair readers (sphere, wall, road, plots) see.
    assert_eq!(cap.on_frames().count(), 1);

    edit_meta(
        &dir,
        r#"file = "p1-off.pgm", lasers_on = []"#,
        r#"file = "p1-off.pgm", lasers_on = [0]"#,
    );
    let e = Capture::read(&dir).expect_err("pair 1 has no laser-off frame");
    assert!(
        matches!(
            e,
            CaptureError::PairFrames {
                pair: 1,
                off: 0,
                on: 2
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("exposure pair 1"), "{e}");
    edit_meta(
        &dir,
        "pair = 1 },\n  { file = \"p1-on.pgm\", lasers_on = [0], pair = 1",
        "pair = 16 },\n  { file = \"p1-on.pgm\", lasers_on = [0], pair = 16",
    );
    let e = Capture::read(&dir).expect_err("pair 16 is beyond the format");
    assert!(e.to_string().contains("frame pair 16"), "{e}");
}
