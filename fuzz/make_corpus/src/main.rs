//! Writes a handful of valid inputs per fuzz target into `fuzz/corpus/<target>/`: real
//! encodings of protocol messages and calibration records, crops of the corpus frames, the
//! corpus's capture and calibration TOML, field-log lines. Each input is named by its content
//! hash, so a re-run adds nothing when nothing changed.

use std::path::{Path, PathBuf};

use tangent_core::protocol::{
    calibration_record, encode, encode_raw, DeviceError, ErrorCode, FrameSel, FromDevice, Request,
    Response, ToDevice, WireCalibration, MAX_FRAME_LEN, MAX_RAW_LEN, PROTOCOL_VERSION, UNSOLICITED,
};
use tangent_host::capture::Capture;
use tangent_host::fieldlog::{encode_line, PlotHeader, Record, TreeRecord};
use tangent_host::pgm::Pgm;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn write(target: &str, bytes: &[u8]) {
    let dir = root().join("fuzz/corpus").join(target);
    std::fs::create_dir_all(&dir).unwrap();
    // FNV-1a: a stable name from the content.
    let hash = bytes.iter().fold(0xcbf29ce484222325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x100000001b3)
    });
    std::fs::write(dir.join(format!("{hash:016x}")), bytes).unwrap();
}

fn requests(cal: &WireCalibration) -> Vec<ToDevice> {
    [
        Request::DeviceInfo,
        Request::Measure,
        Request::History { after_seq: 41 },
        Request::ReadFrameChunk {
            capture: 3,
            frame: FrameSel::On,
            offset: 4096,
            max_len: 512,
        },
        Request::WriteCalibration(cal.clone()),
        Request::SetExposure(Some(2000)),
        Request::SetExposures(4),
    ]
    .into_iter()
    .enumerate()
    .map(|(i, request)| ToDevice {
        tag: i as u16 + 1,
        request,
    })
    .collect()
}

fn responses(cal: &WireCalibration) -> Vec<FromDevice<'static>> {
    const CHUNK: &[u8] = &[0, 1, 2, 3, 0, 0, 255, 3];
    vec![
        FromDevice {
            tag: 1,
            response: Response::Ack,
        },
        FromDevice {
            tag: 2,
            response: Response::HistoryEnd { last_seq: 57 },
        },
        FromDevice {
            tag: 3,
            response: Response::Error(DeviceError {
                code: ErrorCode::NoCalibration,
                detail: 0,
            }),
        },
        FromDevice {
            tag: 4,
            response: Response::FrameChunk {
                capture: 3,
                frame: FrameSel::Off,
                offset: 0,
                total: 721_920,
                data: CHUNK,
            },
        },
        FromDevice {
            tag: UNSOLICITED,
            response: Response::Calibration(cal.clone()),
        },
    ]
}

fn main() {
    let capture_dir = root().join("tests/captures/cyl-d300-z150-shade");
    let capture = Capture::read(&capture_dir).unwrap();
    let wire = WireCalibration::from(&capture.calibration);

    // Protocol: framed messages (the stream target takes a direction byte first) and raw
    // bodies (version ‖ postcard, without the CRC the body target appends).
    let mut stream_to = vec![0u8];
    let mut stream_from = vec![1u8];
    let (mut scratch, mut frame) = ([0u8; MAX_RAW_LEN], [0u8; MAX_FRAME_LEN]);
    for m in requests(&wire) {
        let n = encode(&m, &mut scratch, &mut frame).unwrap();
        stream_to.extend_from_slice(&frame[..n]);
        write("protocol_stream", &[&[0u8][..], &frame[..n]].concat());
        let raw = encode_raw(&m, PROTOCOL_VERSION, &mut scratch).unwrap();
        write(
            "protocol_body",
            &[&[0u8][..], &raw[1..raw.len() - 2]].concat(),
        );
    }
    for m in responses(&wire) {
        let n = encode(&m, &mut scratch, &mut frame).unwrap();
        stream_from.extend_from_slice(&frame[..n]);
        write("protocol_stream", &[&[1u8][..], &frame[..n]].concat());
        let raw = encode_raw(&m, PROTOCOL_VERSION, &mut scratch).unwrap();
        write(
            "protocol_body",
            &[&[1u8][..], &raw[1..raw.len() - 2]].concat(),
        );
    }
    write("protocol_stream", &stream_to);
    write("protocol_stream", &stream_from);

    // Calibration records: whole records (mode 0) and bare payloads (mode 1, the target
    // wraps them).
    let mut record = [0u8; calibration_record::MAX_RECORD];
    let n = calibration_record::encode(&wire, &mut record).unwrap();
    write("calibration_record", &[&[0u8][..], &record[..n]].concat());
    write(
        "calibration_record",
        &[&[1u8][..], &record[8..n - 4]].concat(),
    );

    // PGM: small crops of the corpus frames around the laser stripe, 16-bit and 8-bit.
    let on = Pgm::read(&capture_dir.join("on.pgm")).unwrap();
    for (x0, y0, w, h) in [(360, 230, 8, 6), (0, 0, 3, 2), (370, 200, 16, 16)] {
        let crop: Vec<u16> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| on.get(x0 + x, y0 + y).unwrap())
            .collect();
        // Scaled to 8 and 10 bits whatever the frame's depth.
        let scale = |bits: u32| {
            let from = u32::from(on.maxval);
            let to = (1u32 << bits) - 1;
            crop.iter().map(move |&v| (u32::from(v) * to / from) as u16)
        };
        let wide = Pgm::from_u16(w, h, 1023, scale(10).collect()).unwrap();
        write("pgm", &wide.encode().unwrap());
        let narrow = scale(8).map(|v| v as u8).collect();
        write(
            "pgm",
            &Pgm::from_u8(w, h, 255, narrow).unwrap().encode().unwrap(),
        );
    }
    write("pgm", b"P5\n# a comment\n2 1\n65535\n\xff\xff\x00\x01");

    // Capture and calibration TOML from the corpus.
    for name in ["cyl-d300-z150-shade", "board-pose-01"] {
        let text = std::fs::read(
            root()
                .join("tests/captures")
                .join(name)
                .join("capture.toml"),
        );
        write("capture_toml", &text.unwrap());
    }
    write(
        "calibration_toml",
        tangent_host::calibration_file::to_string(&capture.calibration).as_bytes(),
    );

    // Field-log lines: a plot header, trees, and a log of them.
    let plot = Record::Plot(PlotHeader {
        plot_id: "P-017".into(),
        started: "2025-06-01T08:00:00Z".into(),
        note: "north slope, \"wet\"".into(),
    });
    let tree = |tree_id: u32, species: &str, d: f64, flags: u32| {
        Record::Tree(TreeRecord {
            plot_id: "P-017".into(),
            tree_id,
            species: species.into(),
            diameter_mm: d,
            uncertainty_mm: 1.24,
            tilt_deg: 2.96,
            flags,
            time: "2025-06-01T08:01:00Z".into(),
            device_id: "H743-0001".into(),
            calib_id: 7,
            seq: tree_id,
            device_time_ms: 1000 * tree_id as u64,
            kind: "stem".into(),
            measurement: None,
            label: String::new(),
        })
    };
    let records = [
        plot,
        tree(1, "PIAB", 314.06, 0),
        tree(2, "50", 88.0, 0x8006),
    ];
    let mut log = String::new();
    for r in &records {
        let line = encode_line(r);
        write("fieldlog", line.as_bytes());
        log += &line;
    }
    write("fieldlog", log.as_bytes());
}
