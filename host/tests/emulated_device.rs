//! The emulated firmware (QEMU mps2-an500) as a real serial peer: protocol round trips,
//! frame dumps, calibration storage, link fault tolerance, the mode. The on-device
//! measurements against the host's are `emulated_measurements.rs`.
//!
//! Needs `qemu-system-arm` (CI installs it; without it each test prints why it is skipped)
//! and builds the emulated firmware (`cargo firmware-qemu`) on first use.

mod emulated;

use tangent_core::calibration::Calibration;
use tangent_core::measurement::Mode;
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::{
    self, DeviceError, ErrorCode, FrameSel, Request, Response, ToDevice, WireCalibration,
    FRAME_CHUNK_MAX, PROTOCOL_VERSION,
};

use emulated::*;

#[test]
fn boot_banner_info_and_calibration_round_trip() {
    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off, on, _, _) = synthetic_pair(dir.path(), "a");
    let cal = Calibration::reference_design();
    let mut dev = Device::boot(&elf, &[(off, on)], Some(&cal));

    // The unsolicited banner names the protocol and the stored calibration.
    dev.expect(protocol::UNSOLICITED, |r| match r {
        Response::Info(i) => {
            assert_eq!(i.protocol_version, PROTOCOL_VERSION);
            assert_eq!(i.board, protocol::Board::Emulated);
            assert_eq!(i.calib_id, Some(cal.id));
            assert_eq!((i.frame_width, i.frame_height), (752, 480));
        }
        other => panic!("expected the boot banner, got {other:?}"),
    });

    let wire = dev.request(Request::ReadCalibration, |r| match r {
        Response::Calibration(c) => c,
        other => panic!("{other:?}"),
    });
    assert_eq!(wire, WireCalibration::from(&cal));
    // The device computes in f32: what it returns is the f32 rounding of what it got.
    assert_eq!(wire.to_calibration().unwrap().id, cal.id);

    let mut new = cal.clone();
    new.id = 4242;
    new.camera.cx = 371.25;
    dev.request(
        Request::WriteCalibration(WireCalibration::from(&new)),
        |r| assert_eq!(r, Response::Ack),
    );
    let back = dev.request(Request::ReadCalibration, |r| match r {
        Response::Calibration(c) => c,
        other => panic!("{other:?}"),
    });
    assert_eq!(back.id, 4242);
    assert_eq!(back.intrinsics[2], 371.25);

    // An invalid calibration is refused and the previous one stays active.
    let mut bad = WireCalibration::from(&new);
    bad.intrinsics[0] = f64::NAN;
    dev.request(Request::WriteCalibration(bad), |r| match r {
        Response::Error(DeviceError { code, .. }) => {
            assert_eq!(code, ErrorCode::InvalidCalibration)
        }
        other => panic!("{other:?}"),
    });
    dev.request(Request::DeviceInfo, |r| match r {
        Response::Info(i) => assert_eq!(i.calib_id, Some(4242)),
        other => panic!("{other:?}"),
    });
}

#[test]
fn frame_dump_equals_the_source_frames() {
    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off_path, on_path, off, on) = synthetic_pair(dir.path(), "dump");
    let mut dev = Device::boot(&elf, &[(off_path, on_path)], None);
    let info = dev.request(Request::CaptureFrames, |r| match r {
        Response::FramesReady(i) => i,
        other => panic!("{other:?}"),
    });
    assert_eq!((info.width, info.height, info.bit_depth), (752, 480, 8));
    assert_ne!(info.laser_mask, 0);
    for (sel, want) in [(FrameSel::Off, &off), (FrameSel::On, &on)] {
        let mut got = Vec::new();
        while got.len() < want.len() {
            let request = Request::ReadFrameChunk {
                capture: info.capture,
                frame: sel,
                offset: got.len() as u32,
                max_len: FRAME_CHUNK_MAX as u16,
            };
            dev.request(request, |r| match r {
                Response::FrameChunk {
                    offset,
                    total,
                    data,
                    ..
                } => {
                    assert_eq!(offset as usize, got.len());
                    assert_eq!(total as usize, want.len());
                    assert!(!data.is_empty() && data.len() <= FRAME_CHUNK_MAX);
                    got.extend_from_slice(data);
                }
                other => panic!("{other:?}"),
            });
        }
        assert!(got == *want, "{sel:?} frame differs from its source");
    }
    // Past the end, and a capture that no longer exists.
    let request = Request::ReadFrameChunk {
        capture: info.capture,
        frame: FrameSel::On,
        offset: off.len() as u32,
        max_len: 16,
    };
    dev.request(request, |r| {
        assert!(matches!(
            r,
            Response::Error(DeviceError {
                code: ErrorCode::OutOfRange,
                ..
            })
        ))
    });
    let request = Request::ReadFrameChunk {
        capture: info.capture + 1,
        frame: FrameSel::On,
        offset: 0,
        max_len: 16,
    };
    dev.request(request, |r| {
        assert!(matches!(
            r,
            Response::Error(DeviceError {
                code: ErrorCode::StaleCapture,
                ..
            })
        ))
    });
}

#[test]
fn garbage_corruption_oversize_and_other_versions_are_counted_not_fatal() {
    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off, on, _, _) = synthetic_pair(dir.path(), "g");
    let mut dev = Device::boot(&elf, &[(off, on)], None);
    dev.expect(protocol::UNSOLICITED, |_| ());

    // 1. Line noise then a delimiter: one malformed frame.
    dev.send_raw(&[0x13, 0x37, 0xFF, 0x42, 0x00]);
    // 2. A valid frame with one corrupted byte: malformed (CRC).
    let mut enc = protocol::FrameEncoder::new();
    let mut frame = enc
        .encode(&ToDevice {
            tag: 99,
            request: Request::DeviceInfo,
        })
        .unwrap()
        .to_vec();
    frame[3] ^= 0x10;
    if frame[3] == 0 {
        frame[3] = 0x77;
    }
    dev.send_raw(&frame);
    // 3. An oversize frame (no delimiter for 5000 bytes).
    dev.send_raw(&vec![0x5Au8; 5000]);
    dev.send_raw(&[0x00]);
    // 4. A frame of another protocol version: answered with UnsupportedVersion.
    let mut scratch = [0u8; protocol::MAX_RAW_LEN];
    let raw = protocol::encode_raw(
        &ToDevice {
            tag: 7,
            request: Request::DeviceInfo,
        },
        PROTOCOL_VERSION + 1,
        &mut scratch,
    )
    .unwrap();
    let mut out = [0u8; protocol::MAX_FRAME_LEN];
    let n = protocol::cobs_frame(raw, &mut out).unwrap();
    dev.send_raw(&out[..n]);
    dev.expect(protocol::UNSOLICITED, |r| match r {
        Response::Error(DeviceError { code, detail }) => {
            assert_eq!(code, ErrorCode::UnsupportedVersion);
            assert_eq!(detail, u32::from(PROTOCOL_VERSION + 1));
        }
        other => panic!("{other:?}"),
    });
    // The device still answers, and counted each fault once.
    dev.request(Request::DeviceInfo, |r| match r {
        Response::Info(i) => {
            assert_eq!(i.link.malformed, 2, "{:?}", i.link);
            assert_eq!(i.link.oversize, 1, "{:?}", i.link);
            assert_eq!(i.link.version_mismatch, 1, "{:?}", i.link);
            assert_eq!(i.link.frames_ok, 1, "{:?}", i.link);
        }
        other => panic!("{other:?}"),
    });
}

#[test]
fn measure_without_calibration_is_a_clear_error() {
    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off, on, _, _) = synthetic_pair(dir.path(), "nc");
    let mut dev = Device::boot(&elf, &[(off, on)], None);
    dev.request(Request::Measure, |r| match r {
        Response::Error(DeviceError { code, .. }) => assert_eq!(code, ErrorCode::NoCalibration),
        other => panic!("{other:?}"),
    });
    dev.request(Request::History { after_seq: 0 }, |r| {
        assert_eq!(r, Response::HistoryEnd { last_seq: 0 })
    });
}

/// The mode from the host on the real firmware: the device boots in the stem's mode and says
/// so in `Info`; every mode this build measures is taken and read back; any other is refused
/// with the `UnsupportedMode` sentence and the mode stays; a reading is of the set mode's kind
/// (a nothing-lit pair: the chain's failure, not the refusal of the mode).
#[test]
fn the_mode_is_set_from_the_host_and_read_back() {
    use tangent_core::instrument;

    let Some(elf) = firmware_elf() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (off, on, _, _) = synthetic_pair(dir.path(), "mode");
    let pairs = vec![(off.clone(), on.clone()), (off, on)];
    let mut dev = Device::boot(&elf, &pairs, Some(&Calibration::reference_design()));
    let mode_now = |dev: &mut Device| {
        dev.request(Request::DeviceInfo, |r| match r {
            Response::Info(i) => i.mode,
            other => panic!("{other:?}"),
        })
    };
    assert_eq!(
        mode_now(&mut dev),
        Mode::Cylinder,
        "boots in the stem's mode"
    );
    let mut taken = Vec::new();
    for mode in Mode::ALL {
        let before = mode_now(&mut dev);
        dev.request(Request::SetMode(mode), |r| match r {
            Response::Ack => {
                assert!(
                    instrument::supports(mode),
                    "{mode:?} taken without a solver"
                );
                taken.push(mode);
            }
            Response::Error(DeviceError { code, detail }) => {
                assert!(!instrument::supports(mode), "{mode:?} refused");
                assert_eq!(code, ErrorCode::MeasurementFailed);
                assert_eq!(Failure::from_detail(detail), Failure::UnsupportedMode(mode));
            }
            other => panic!("{other:?}"),
        });
        let after = mode_now(&mut dev);
        let expected = if taken.last() == Some(&mode) {
            mode
        } else {
            before
        };
        assert_eq!(after, expected, "mode after SetMode({mode:?})");
    }
    assert!(taken.contains(&Mode::Cylinder));
    // Measuring in each taken mode runs that mode's chain: this pair has a lit band across
    // the frame, so whatever the outcome, it is not the refusal of the mode.
    for mode in taken.iter().take(pairs.len()) {
        dev.request(Request::SetMode(*mode), |r| assert_eq!(r, Response::Ack));
        dev.request(Request::Measure, |r| match r {
            Response::Reading(reading) => assert_eq!(reading.measurement.mode(), *mode),
            Response::Error(DeviceError { code, detail }) => {
                assert_eq!(code, ErrorCode::MeasurementFailed);
                assert_ne!(
                    Failure::from_detail(detail),
                    Failure::UnsupportedMode(*mode)
                );
            }
            other => panic!("{other:?}"),
        });
    }
}
