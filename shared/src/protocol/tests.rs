//! Tests of the protocol: framing, decoder, messages.

use serde::Serialize;

use super::*;
use crate::calibration::{
    Calibration, CalibrationError, PlanesUncertainty, UncertaintyError, MAX_PLANES, PLANE_PARAMS,
};
use crate::measurement::{Measurement, Mode, StemReading, TiltAngles};
use crate::real::Real;
use crate::solvers::result::Flags;

fn reading(seq: u32) -> Reading {
    Reading {
        seq,
        timestamp_ms: 123_456_789_012,
        calib_id: 7,
        exposure_us: 850,
        measurement: Measurement::Stem(StemReading {
            diameter: 0.3141f32 as Real,
            uncertainty: 0.0012f32 as Real,
            method: Method::CylinderFit,
            distance: 1.75,
            tilt: Some(TiltAngles {
                total: 0.05f32 as Real,
                theta: -0.03f32 as Real,
                phi: 0.04f32 as Real,
            }),
            axes: None,
            flags: Flags(0x1803),
            exposures: 1,
        }),
        stats: Some(RunningStats {
            count: 4,
            mean_m: 0.314,
            spread_m: 0.0004,
        }),
        accelerometer: None,
    }
}

/// A calibrated accelerometer 1° off the camera, with a 25 mg bias.
fn wire_accelerometer() -> WireAccelerometer {
    WireAccelerometer {
        bias_m_s2: [0.245, -0.12, 0.031],
        bias_sigma_m_s2: 0.0074,
        camera_from_sensor_rad: [0.0175, -0.003, 0.009],
        alignment_sigma_rad: 0.00087,
    }
}

fn frame_of<T: Serialize>(msg: &T) -> ([u8; MAX_FRAME_LEN], usize) {
    let mut scratch = [0u8; MAX_RAW_LEN];
    let mut out = [0u8; MAX_FRAME_LEN];
    let n = encode(msg, &mut scratch, &mut out).unwrap();
    (out, n)
}

#[test]
fn frame_has_one_delimiter_at_the_end() {
    let msg = FromDevice {
        tag: 0,
        response: Response::Reading(reading(1)),
    };
    let (out, n) = frame_of(&msg);
    assert_eq!(out[n - 1], 0);
    assert!(out[..n - 1].iter().all(|&b| b != 0));
}

#[test]
fn every_request_round_trips() {
    let cal = WireCalibration::from(&Calibration::reference_design());
    let requests = [
        Request::DeviceInfo,
        Request::Measure,
        Request::StartStream,
        Request::StopStream,
        Request::History { after_seq: 41 },
        Request::CaptureFrames,
        Request::ReadFrameChunk {
            capture: 3,
            frame: FrameSel::On,
            offset: 360_448,
            max_len: 512,
        },
        Request::ReadCalibration,
        Request::WriteCalibration(cal),
        Request::SetExposure(Some(1200)),
        Request::SetExposure(None),
        Request::SelfTest,
        Request::SetMode(Mode::Cylinder),
        Request::SetMode(Mode::Sphere),
        Request::SetMode(Mode::Road),
        Request::SetExposures(4),
    ];
    for (i, request) in requests.into_iter().enumerate() {
        let msg = ToDevice {
            tag: 1000 + i as u16,
            request,
        };
        let (mut out, n) = frame_of(&msg);
        let back: ToDevice = decode(&mut out[..n]).unwrap();
        assert_eq!(back, msg);
    }
}

#[test]
fn largest_messages_fit() {
    // A full chunk of 0xFF bytes (no zeros, worst case for COBS) with maximal varints.
    let data = [0xFFu8; FRAME_CHUNK_MAX];
    let msg = FromDevice {
        tag: u16::MAX,
        response: Response::FrameChunk {
            capture: u32::MAX,
            frame: FrameSel::On,
            offset: u32::MAX,
            total: u32::MAX,
            data: &data,
        },
    };
    let (mut out, n) = frame_of(&msg);
    assert!(n <= MAX_FRAME_LEN);
    let back: FromDevice = decode(&mut out[..n]).unwrap();
    assert_eq!(back, msg);

    // A calibration with MAX_PLANES planes and values whose f64 bytes are all non-zero.
    let mut cal = WireCalibration::from(&Calibration::reference_design());
    while cal.planes.len() < MAX_PLANES {
        cal.planes.push(cal.planes[0]).unwrap();
    }
    cal.id = u32::MAX;
    cal.accelerometer = Some(wire_accelerometer());
    cal.uncertainty = Some(WirePlanesUncertainty::from(&full_uncertainty()));
    let msg = FromDevice {
        tag: u16::MAX,
        response: Response::Calibration(cal),
    };
    let (mut out, n) = frame_of(&msg);
    let back: FromDevice = decode(&mut out[..n]).unwrap();
    assert_eq!(back, msg);
}

/// A covariance of [`MAX_PLANES`] planes, every parameter correlated with every other.
fn full_uncertainty() -> PlanesUncertainty {
    let n = PLANE_PARAMS;
    let sigma: heapless::Vec<Real, PLANE_PARAMS> =
        (0..n).map(|i| 1e-4 + 1e-6 * i as Real).collect();
    let mut rho = [0.0 as Real; PLANE_PARAMS * PLANE_PARAMS];
    for i in 0..n {
        for j in 0..n {
            rho[i * n + j] = if i == j { 1.0 } else { 0.3 };
        }
    }
    PlanesUncertainty::new(&sigma, &rho).unwrap()
}

/// The planes' covariance a refinement leaves crosses the wire (in `f32`) and comes back
/// validated; a correlation the core could not use is refused by name.
#[test]
fn the_planes_uncertainty_crosses_the_wire() {
    let mut planes = Calibration::reference_design();
    let two = PlanesUncertainty::new(
        &[2e-4, 1.5e-4, 2e-4, 1.6e-4],
        &[
            1.0, 0.0, 0.8, 0.0, //
            0.0, 1.0, 0.0, 0.97, //
            0.8, 0.0, 1.0, 0.0, //
            0.0, 0.97, 0.0, 1.0,
        ],
    )
    .unwrap();
    planes = planes.with_uncertainty(two).unwrap();
    let back = WireCalibration::from(&planes).to_calibration().unwrap();
    let u = back.uncertainty.expect("carried");
    for i in 0..4 {
        assert!((u.sigmas()[i] - two.sigmas()[i]).abs() <= 1e-7 * two.sigmas()[i]);
        for j in 0..4 {
            assert!((u.correlation(i, j) - two.correlation(i, j)).abs() <= 1e-6);
        }
    }
    // One plane's covariance for a two-plane calibration.
    let mut wire = WireCalibration::from(&planes);
    let one = PlanesUncertainty::new(&[2e-4, 1e-4], &[1.0, 0.1, 0.1, 1.0]).unwrap();
    wire.uncertainty = Some(WirePlanesUncertainty::from(&one));
    assert_eq!(
        wire.to_calibration(),
        Err(CalibrationError::Uncertainty(
            UncertaintyError::PlaneCount {
                covers: 1,
                planes: 2
            }
        ))
    );
    // A correlation above 1, and a correlation one entry short.
    let mut wire = WireCalibration::from(&planes);
    if let Some(u) = wire.uncertainty.as_mut() {
        u.correlation[0] = 1.5;
    }
    assert_eq!(
        wire.to_calibration(),
        Err(CalibrationError::Uncertainty(
            UncertaintyError::Correlation { row: 0, col: 1 }
        ))
    );
    let mut wire = WireCalibration::from(&planes);
    if let Some(u) = wire.uncertainty.as_mut() {
        u.correlation.pop();
    }
    assert_eq!(
        wire.to_calibration(),
        Err(CalibrationError::Uncertainty(
            UncertaintyError::CorrelationShape {
                expected: 6,
                got: 5
            }
        ))
    );
}

#[test]
fn calibration_survives_the_wire_exactly_in_f64() {
    let cal = Calibration::reference_design();
    let wire = WireCalibration::from(&cal);
    let back = wire.to_calibration().unwrap();
    // f64 → f64 is exact; with the f32 feature Real → f64 → Real is exact as well
    // (every f32 is an f64), so equality holds in both precisions.
    assert_eq!(back, cal);
}

#[test]
fn invalid_calibration_is_rejected() {
    let mut wire = WireCalibration::from(&Calibration::reference_design());
    wire.intrinsics[0] = -1.0;
    assert!(matches!(
        wire.to_calibration(),
        Err(CalibrationError::Camera(_))
    ));
    let mut wire = WireCalibration::from(&Calibration::reference_design());
    wire.planes.clear();
    assert_eq!(wire.to_calibration(), Err(CalibrationError::NoPlanes));
}

#[test]
fn every_single_bit_flip_is_detected() {
    let msg = FromDevice {
        tag: 9,
        response: Response::Reading(reading(77)),
    };
    let mut scratch = [0u8; MAX_RAW_LEN];
    let raw_len = encode_raw(&msg, PROTOCOL_VERSION, &mut scratch)
        .unwrap()
        .len();
    for bit in 0..raw_len * 8 {
        let mut raw = scratch;
        raw[bit / 8] ^= 1 << (bit % 8);
        let r: Result<FromDevice, _> = decode_raw(&raw[..raw_len]);
        assert!(
            matches!(r, Err(ProtocolError::Crc { .. })),
            "bit {bit}: {r:?}"
        );
    }
}

#[test]
fn another_version_is_named_not_called_noise() {
    let mut scratch = [0u8; MAX_RAW_LEN];
    let raw = encode_raw(
        &ToDevice {
            tag: 1,
            request: Request::Measure,
        },
        PROTOCOL_VERSION + 1,
        &mut scratch,
    )
    .unwrap();
    let mut out = [0u8; MAX_FRAME_LEN];
    let n = cobs_frame(raw, &mut out).unwrap();
    let r: Result<ToDevice, _> = decode(&mut out[..n]);
    assert_eq!(
        r,
        Err(ProtocolError::VersionMismatch {
            received: PROTOCOL_VERSION + 1
        })
    );
}

/// Decodes every frame of `stream` with a decoder over a `cap`-byte buffer.
fn decode_stream(stream: &[u8], cap: usize) -> (heapless::Vec<u32, 64>, LinkStats) {
    let mut buf = [0u8; 2048];
    let mut dec = Decoder::new(&mut buf[..cap]);
    let mut seqs = heapless::Vec::new();
    let mut input = stream;
    loop {
        match dec.feed::<FromDevice>(input) {
            Feed::Consumed => break,
            Feed::Frame { message, remaining } => {
                if let Response::Reading(r) = message.response {
                    seqs.push(r.seq).unwrap();
                }
                input = remaining;
            }
            Feed::Rejected { remaining, .. } => input = remaining,
        }
    }
    (seqs, dec.stats())
}

fn stream_of(seqs: core::ops::Range<u32>, out: &mut [u8]) -> usize {
    let mut n = 0;
    for seq in seqs {
        let msg = FromDevice {
            tag: 0,
            response: Response::Reading(reading(seq)),
        };
        let (f, len) = frame_of(&msg);
        out[n..n + len].copy_from_slice(&f[..len]);
        n += len;
    }
    n
}

#[test]
fn decoder_splits_a_stream_fed_in_any_pieces() {
    let mut stream = [0u8; 4096];
    let n = stream_of(1..11, &mut stream);
    for piece in [1, 2, 7, 64, n] {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let mut dec = Decoder::new(&mut buf);
        let mut got = heapless::Vec::<u32, 16>::new();
        for chunk in stream[..n].chunks(piece) {
            let mut input = chunk;
            loop {
                match dec.feed::<FromDevice>(input) {
                    Feed::Consumed => break,
                    Feed::Frame { message, remaining } => {
                        if let Response::Reading(r) = message.response {
                            got.push(r.seq).unwrap();
                        }
                        input = remaining;
                    }
                    Feed::Rejected { error, .. } => panic!("{error}"),
                }
            }
        }
        assert_eq!(
            &got[..],
            &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10][..],
            "piece {piece}"
        );
        assert_eq!(dec.stats().frames_ok, 10);
    }
}

#[test]
fn decoder_resynchronises_after_garbage_and_corruption() {
    let mut stream = [0u8; 4096];
    let mut n = 0;
    // Garbage before the first frame (a receiver that starts mid-stream).
    for b in [0x13u8, 0x37, 0xFF, 0x01] {
        stream[n] = b;
        n += 1;
    }
    n += stream_of(1..4, &mut stream[n..]);
    // Corrupt one byte inside frame 2 (but not a delimiter).
    let second_start = stream[..n].iter().position(|&b| b == 0).unwrap() + 1;
    stream[second_start + 5] ^= 0x40;
    if stream[second_start + 5] == 0 {
        stream[second_start + 5] = 0x55;
    }
    // A truncated frame (cable yanked mid-frame) followed by complete ones.
    let mut tail = [0u8; 1024];
    let t = stream_of(4..6, &mut tail);
    stream[n..n + 10].copy_from_slice(&tail[..10]);
    n += 10;
    // A sender that (re)starts emits a delimiter first, which ends the partial frame.
    stream[n] = DELIMITER;
    n += 1;
    stream[n..n + t].copy_from_slice(&tail[..t]);
    n += t;
    let (seqs, stats) = decode_stream(&stream[..n], MAX_FRAME_LEN);
    // Frame 1 is swallowed with the garbage prefix; frame 2 is corrupted; the
    // truncated frame is malformed; 3, 4, 5 survive.
    assert_eq!(&seqs[..], &[3, 4, 5][..]);
    assert_eq!(stats.frames_ok, 3);
    assert_eq!(stats.malformed, 3);
}

#[test]
fn decoder_rejects_oversize_frames_and_recovers() {
    let mut stream = [0u8; 4096];
    // 1000 non-zero bytes: longer than the 200-byte buffer used below.
    stream[..1000].fill(0xAB);
    stream[1000] = 0;
    let n = 1001 + stream_of(1..3, &mut stream[1001..]);
    let (seqs, stats) = decode_stream(&stream[..n], 200);
    assert_eq!(&seqs[..], &[1, 2][..]);
    assert_eq!(stats.oversize, 1);
    assert_eq!(stats.malformed, 0);
}

#[test]
fn empty_frames_are_ignored() {
    let mut stream = [0u8; 1024];
    let n = 3 + stream_of(1..2, &mut stream[3..]);
    let (seqs, stats) = decode_stream(&stream[..n], MAX_FRAME_LEN);
    assert_eq!(&seqs[..], &[1][..]);
    assert_eq!(stats.malformed, 0);
}

#[test]
fn calibration_record_round_trip_and_corruption() {
    let mut cal = WireCalibration::from(&Calibration::reference_design());
    cal.accelerometer = Some(wire_accelerometer());
    cal.uncertainty = Some(WirePlanesUncertainty::from(&full_uncertainty()));
    let mut buf = [0xFFu8; calibration_record::MAX_RECORD];
    let n = calibration_record::encode(&cal, &mut buf).unwrap();
    assert_eq!(calibration_record::decode(&buf[..n]), Some(cal.clone()));
    // Erased flash.
    assert_eq!(calibration_record::decode(&[0xFF; 64]), None);
    // Every single-byte corruption and every truncation is rejected.
    for i in 0..n {
        let mut b = buf;
        b[i] ^= 0x20;
        assert_eq!(calibration_record::decode(&b[..n]), None, "byte {i}");
        assert_eq!(calibration_record::decode(&buf[..i]), None, "cut at {i}");
    }
}

#[test]
fn crc_matches_the_published_check_value() {
    // CRC-16/IBM-3740 of "123456789" is 0x29B1 (Greg Cook's CRC catalogue).
    assert_eq!(CRC.checksum(b"123456789"), 0x29B1);
}

#[test]
fn random_bytes_never_panic_the_decoder() {
    // xorshift32: a deterministic byte soup with zeros sprinkled in.
    let mut x = 0x1234_5678u32;
    let mut buf = [0u8; 64];
    let mut dec = Decoder::new(&mut buf);
    let mut frames = 0u32;
    for _ in 0..20_000 {
        let mut chunk = [0u8; 16];
        for b in chunk.iter_mut() {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *b = if x.is_multiple_of(23) { 0 } else { x as u8 };
        }
        let mut input = &chunk[..];
        loop {
            match dec.feed::<ToDevice>(input) {
                Feed::Consumed => break,
                Feed::Frame { remaining, .. } => {
                    frames += 1;
                    input = remaining
                }
                Feed::Rejected { remaining, .. } => input = remaining,
            }
        }
    }
    let s = dec.stats();
    // A random frame passes the CRC with probability 2^-16 and must then also be a
    // valid message of version 1; over ~14k random frames essentially none should.
    assert!(frames <= 2, "{frames} random frames accepted");
    assert!(s.malformed + s.oversize > 1000);
}

/// The frame of issue 13 item 7: a CRC-valid version-1 frame whose `Measure` request is
/// followed by four junk bytes. Postcard alone decodes it as `Measure`.
const JUNK_FRAME: [u8; 13] = [
    0x08, 0x01, 0x05, 0x01, 0xde, 0xad, 0xbe, 0xef, 0x04, 0x11, 0x1c, 0xf1, 0x00,
];

#[test]
fn trailing_bytes_after_a_message_are_refused() {
    // Its raw bytes: version 1, tag 5, `Measure`, 0xdeadbeef, CRC.
    let mut frame = JUNK_FRAME;
    let n = cobs::decode_in_place(&mut frame[..12]).unwrap();
    let raw = &frame[..n];
    assert_eq!(
        raw,
        [0x01, 0x05, 0x01, 0xde, 0xad, 0xbe, 0xef, 0x00, 0x11, 0x1c, 0xf1]
    );
    assert_eq!(
        CRC.checksum(&raw[..n - 2]).to_le_bytes(),
        [raw[n - 2], raw[n - 1]]
    );
    // As sent (protocol version 1) it is now refused by its version; the same bytes in this
    // version (version byte replaced, CRC recomputed) are refused for the junk.
    let mut frame = JUNK_FRAME;
    let r: Result<ToDevice, _> = decode(&mut frame);
    assert_eq!(r, Err(ProtocolError::VersionMismatch { received: 1 }));
    let mut same = [0u8; 16];
    same[..n - 2].copy_from_slice(&raw[..n - 2]);
    same[0] = PROTOCOL_VERSION;
    let crc = CRC.checksum(&same[..n - 2]);
    same[n - 2..n].copy_from_slice(&crc.to_le_bytes());
    let r: Result<ToDevice, _> = decode_raw(&same[..n]);
    assert_eq!(r, Err(ProtocolError::TrailingBytes { count: 6 }));
    // Without the junk it is the `Measure` request it pretended to be.
    let mut exact = [PROTOCOL_VERSION, 0x05, 0x01, 0, 0];
    let crc = CRC.checksum(&exact[..3]);
    exact[3..].copy_from_slice(&crc.to_le_bytes());
    let r: Result<ToDevice, _> = decode_raw(&exact);
    assert_eq!(
        r,
        Ok(ToDevice {
            tag: 5,
            request: Request::Measure
        })
    );
}

#[test]
fn the_decoder_counts_trailing_bytes_as_malformed() {
    let mut scratch = [0u8; MAX_RAW_LEN];
    let raw_len = {
        let raw = encode_raw(
            &ToDevice {
                tag: 5,
                request: Request::Measure,
            },
            PROTOCOL_VERSION,
            &mut scratch,
        )
        .unwrap();
        raw.len()
    };
    // Insert one junk byte before the CRC and recompute it.
    let mut forged = [0u8; 16];
    forged[..raw_len - 2].copy_from_slice(&scratch[..raw_len - 2]);
    forged[raw_len - 2] = 0x2a;
    let crc = CRC.checksum(&forged[..raw_len - 1]);
    forged[raw_len - 1..raw_len + 1].copy_from_slice(&crc.to_le_bytes());
    let mut frame = [0u8; 32];
    let len = cobs_frame(&forged[..raw_len + 1], &mut frame).unwrap();
    let mut dec = Decoder::new([0u8; MAX_FRAME_LEN]);
    match dec.feed::<ToDevice>(&frame[..len]) {
        Feed::Rejected { error, .. } => {
            assert_eq!(error, ProtocolError::TrailingBytes { count: 1 })
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(dec.stats().malformed, 1);
}

#[test]
fn a_decoder_owns_or_borrows_its_buffer() {
    let mut stream = [0u8; 1024];
    let n = stream_of(1..3, &mut stream);
    fn seqs<B: AsMut<[u8]>>(dec: &mut Decoder<B>, mut input: &[u8]) -> heapless::Vec<u32, 4> {
        let mut seqs = heapless::Vec::new();
        while let Feed::Frame { message, remaining } = dec.feed::<FromDevice>(input) {
            if let Response::Reading(r) = message.response {
                seqs.push(r.seq).unwrap();
            }
            input = remaining;
        }
        seqs
    }
    let mut owned = Decoder::new([0u8; MAX_FRAME_LEN]);
    let mut lent_buf = [0u8; MAX_FRAME_LEN];
    let mut lent = Decoder::new(&mut lent_buf[..]);
    assert_eq!(&seqs(&mut owned, &stream[..n])[..], &[1, 2][..]);
    assert_eq!(&seqs(&mut lent, &stream[..n])[..], &[1, 2][..]);
    assert_eq!(owned.stats(), lent.stats());
    assert_eq!(owned.into_inner().len(), MAX_FRAME_LEN);
}

#[test]
fn a_reading_carries_the_shared_measurement() {
    let msg = FromDevice {
        tag: 0,
        response: Response::Reading(reading(3)),
    };
    let (mut out, n) = frame_of(&msg);
    let back: FromDevice = decode(&mut out[..n]).unwrap();
    let Response::Reading(r) = back.response else {
        panic!("{back:?}")
    };
    // f32 on the wire: exact in both precisions for values that are f32 already.
    assert_eq!(r, reading(3));
    assert_eq!(r.measurement.method(), Method::CylinderFit);
    assert_eq!(r.measurement.flags(), Flags(0x1803));
}

/// The mode travels as its number (the order of [`Mode::ALL`]), in `SetMode` and in the
/// device's `Info`, so both ends agree on it byte for byte.
#[test]
fn the_mode_travels_as_its_number() {
    for (number, mode) in Mode::ALL.into_iter().enumerate() {
        let mut buf = [0u8; 8];
        let bytes = postcard::to_slice(&Request::SetMode(mode), &mut buf).unwrap();
        // Variant index of SetMode, then the mode's.
        assert_eq!(bytes.len(), 2);
        assert_eq!(bytes[1] as usize, number);
        assert_eq!(Mode::from_name(mode.name()), Some(mode));
    }
    assert_eq!(Mode::from_name("stem"), None);
    let info = Response::Info(DeviceInfo {
        protocol_version: PROTOCOL_VERSION,
        fw_version: "1.2.3",
        board: Board::Emulated,
        calib_id: Some(7),
        frame_width: 752,
        frame_height: 480,
        uptime_ms: 1234,
        last_seq: 9,
        link: LinkStats::default(),
        mode: Mode::Sphere,
        mode_store: ModeStoreState::Loaded(Mode::Sphere),
        exposures: 4,
    });
    let msg = FromDevice {
        tag: 3,
        response: info,
    };
    let (mut out, n) = frame_of(&msg);
    let back: FromDevice = decode(&mut out[..n]).unwrap();
    assert_eq!(back, msg);
}

/// A wall reading carries the accelerometer's mean (or why there is none) beside the
/// measurement, and both ends turn the mean into gravity with the same core function.
#[test]
fn a_reading_carries_the_accelerometer_and_both_ends_read_it_alike() {
    let g = crate::accelerometer::STANDARD_GRAVITY as f32;
    for accelerometer in [
        Some(AccelReading::Mean {
            m_s2: [0.2, g, -0.1],
            samples: 16,
            sample_sigma_m_s2: 0.0011,
        }),
        Some(AccelReading::Absent),
        Some(AccelReading::Failed(codes::ACCEL_TIMEOUT)),
        None,
    ] {
        let msg = FromDevice {
            tag: 9,
            response: Response::Reading(Reading {
                accelerometer,
                ..reading(4)
            }),
        };
        let (mut out, n) = frame_of(&msg);
        let back: FromDevice = decode(&mut out[..n]).unwrap();
        assert_eq!(back, msg);
    }
    let mean = AccelReading::Mean {
        m_s2: [0.2, -g, -0.1],
        samples: 16,
        sample_sigma_m_s2: 0.0011,
    };
    let m = mean.mean().unwrap();
    assert_eq!((m.samples, m.mean_m_s2.y), (16, -g as Real));
    assert_eq!(AccelReading::Absent.mean(), None);
    // The wire alignment and the core's: exact both ways, and checked.
    let a = wire_accelerometer().to_alignment().unwrap();
    assert_eq!(WireAccelerometer::from(&a).to_alignment(), Some(a));
    let v = crate::accelerometer::vertical(&m, &a).unwrap();
    assert!((v.down.norm() - 1.0).abs() < 1e-5, "{v:?}");
    assert!(
        v.down.y > 0.99,
        "the sensor reads up along −y: gravity is +y: {v:?}"
    );
    let mut bad = wire_accelerometer();
    bad.alignment_sigma_rad = -1.0;
    assert_eq!(bad.to_alignment(), None);
    bad = wire_accelerometer();
    bad.bias_m_s2[1] = f64::NAN;
    assert_eq!(bad.to_alignment(), None);
    // What the host prints of a failure names it.
    let mut text: heapless::String<128> = heapless::String::new();
    core::fmt::Write::write_fmt(
        &mut text,
        format_args!("{}", AccelReading::Failed(codes::ACCEL_WRONG_PART)),
    )
    .unwrap();
    assert!(text.contains("ADXL355"), "{text}");
}
