//! The module's functions, natively: what the page gets for bytes a device sends.

use super::*;
use tangent_core::measurement::{Measurement, StemReading};
use tangent_core::protocol::{FromDevice, Method, Response};
use tangent_core::solvers::result::Flags;

fn reading(seq: u32, flags: u32) -> Reading {
    Reading {
        seq,
        timestamp_ms: 1000 * seq as u64,
        calib_id: 7,
        exposure_us: 800,
        measurement: Measurement::Stem(StemReading {
            diameter: 0.3 + seq as f64 * 0.01,
            uncertainty: 0.0012,
            method: Method::CircleFit,
            distance: 1.2,
            tilt: None,
            axes: None,
            flags: Flags(flags),
            exposures: 1,
        }),
        stats: None,
        accelerometer: None,
    }
}

fn frame(tag: u16, response: Response<'_>) -> Vec<u8> {
    FrameEncoder::new()
        .encode(&FromDevice { tag, response })
        .unwrap()
        .to_vec()
}

#[test]
fn readings_arrive_in_order_once_and_are_filed_as_the_cli_files_them() {
    let mut link = Link::default();
    let mut bytes = frame(0, Response::Reading(reading(1, 0)));
    bytes.extend(frame(
        0,
        Response::Reading(reading(3, Flags::ARC_TOO_SHORT.0)),
    ));
    bytes.extend(frame(0, Response::Reading(reading(1, 0))));
    // Split mid-frame: the decoder keeps the partial frame.
    let (a, b) = bytes.split_at(17);
    let mut events = link.feed(a).as_array().unwrap().clone();
    events.extend(link.feed(b).as_array().unwrap().clone());
    assert_eq!(events.len(), 3);
    assert_eq!(events[2]["duplicate"], true);
    assert!(link.seq.has_gap());
    let first = link.pop_reading();
    assert_eq!(first["reading"]["seq"], 1);
    assert_eq!(first["method"], codes::method_name(Method::CircleFit));
    assert_eq!(link.pop_reading(), Value::Null);
    let filing: FilingJson = serde_json::from_str(
        r#"{"plot_id":"P1","tree_id":1,"species":"PIAB","device_id":"emulated","time":"2026-12-01T10:00:00Z"}"#,
    )
    .unwrap();
    let filed = link.file(&filing).unwrap();
    let want = TreeRecord::from_reading(
        &reading(1, 0),
        Filing {
            plot_id: "P1",
            tree_id: 1,
            species: "PIAB",
            label: "",
            device_id: "emulated",
            time: "2026-12-01T10:00:00Z",
        },
    );
    assert_eq!(filed["line"], encode_line(&Record::Tree(want)));
    assert!(link.file(&filing).is_err(), "a reading is filed once");
    // The gap: History after 1 brings 2; HistoryEnd at 3.
    let after = link.seq.history_requested();
    assert_eq!(after, 1);
    link.feed(&frame(5, Response::Reading(reading(2, 0))));
    link.feed(&frame(5, Response::HistoryEnd { last_seq: 3 }));
    assert_eq!(
        link.seq.history_ended(after, 3),
        HistoryOutcome::Done { lost: vec![] }
    );
    assert_eq!(link.pop_reading()["reading"]["seq"], 2);
    let third = link.pop_reading();
    assert_eq!(third["reading"]["seq"], 3);
    assert!(third["warnings"][0]
        .as_str()
        .unwrap()
        .contains("step back or aim at its centre"));
}

#[test]
fn device_errors_carry_the_cores_sentence_and_bad_frames_are_named() {
    let mut link = Link::default();
    let failure = codes::Failure::from_detail(4 | (12 << 8));
    let err = failure.device_error();
    let mut bytes = frame(3, Response::Error(err));
    bytes.extend([0x11, 0x22, 0x00]);
    let events = link.feed(&bytes);
    assert_eq!(events[0]["text"], err.to_string());
    assert!(events[1]["rejected"].is_string());
}

#[test]
fn requests_encode_as_the_core_encodes_them() {
    let mut link = Link::default();
    let got = link.encode(9, r#"{"History":{"after_seq":4}}"#).unwrap();
    let want = FrameEncoder::new()
        .encode(&ToDevice {
            tag: 9,
            request: Request::History { after_seq: 4 },
        })
        .unwrap()
        .to_vec();
    assert_eq!(got, want);
    assert!(link.encode(1, "\"Fly\"").is_err());
}

#[test]
fn export_and_import_of_a_log() {
    let plot = Record::Plot(tangent_field::PlotHeader {
        plot_id: "P1".into(),
        started: "2026-12-01T10:00:00Z".into(),
        note: String::new(),
    });
    let tree = Record::Tree(TreeRecord::from_reading(
        &reading(1, 0),
        Filing {
            plot_id: "P1",
            tree_id: 1,
            species: "PIAB",
            label: "",
            device_id: "emulated",
            time: "2026-12-01T10:01:00Z",
        },
    ));
    let log = format!("{MAGIC_LINE}{}{}", encode_line(&plot), encode_line(&tree));
    let records = vec![plot, tree];
    assert_eq!(
        export_log(log.as_bytes(), None, "csv").unwrap(),
        tangent_field::export(&records, ExportFormat::Csv)
    );
    assert!(export_log(log.as_bytes(), Some("P2"), "tsv").is_err());
    let imported = import(log.as_bytes());
    assert_eq!(imported["lines"].as_array().unwrap().len(), 2);
    assert!(import(b"hello\nworld\n")["error"].is_string());
}
