//! Tests of the device contract's codes and sentences.

extern crate std;
use std::string::{String, ToString};
use std::vec::Vec;

use super::*;
use crate::image::FrameError;
use crate::laser_plane::{LaserPlaneError, TriangulationError};
use crate::protocol::{decode, encode, FromDevice, Response, MAX_FRAME_LEN, MAX_RAW_LEN};

/// One error of every kind the pipeline can report (every variant, and every nested variant
/// that maps to its own failure).
fn every_pipeline_error() -> Vec<PipelineError> {
    let frame = FrameError::SizeMismatch {
        expected: (752, 480),
        actual: (752, 479),
    };
    let mut all = std::vec![
        PipelineError::Frame(FrameError::Empty),
        PipelineError::FrameSizeMismatch {
            calibrated: (752, 480),
            actual: (640, 480),
        },
        PipelineError::WorkspaceTooSmall {
            buffer: "labels",
            needed: 360_960,
            actual: 1000,
        },
        PipelineError::NoLaserLight { max_difference: 10 },
        PipelineError::AmbientSaturated { fraction: 0.93 },
        PipelineError::Threshold(ThresholdError::Frame(frame)),
        PipelineError::Threshold(ThresholdError::NotEnoughLevels {
            present: 1,
            needed: 2,
        }),
        PipelineError::Threshold(ThresholdError::TooManyPixels),
        PipelineError::Segment(SegmentError::Frame(frame)),
        PipelineError::Segment(SegmentError::FrameTooLarge {
            width: 70_000,
            height: 2,
        }),
        PipelineError::Segment(SegmentError::TooManyLabels { capacity: 4095 }),
        PipelineError::Segment(SegmentError::TooManyObjects { capacity: 1024 }),
        PipelineError::NoCurve,
        PipelineError::CurveTooShort {
            plane: 1,
            points: 17,
        },
        PipelineError::Curve(CurveError::Frame(frame)),
        PipelineError::Curve(CurveError::TooManyCurves { selected: 9 }),
        PipelineError::Curve(CurveError::OutputFull { capacity: 3008 }),
        PipelineError::Curve(CurveError::NoCurve),
        PipelineError::Calibration,
        PipelineError::Triangulation(TriangulationError::Plane(LaserPlaneError::CameraInPlane)),
        PipelineError::OutsideFrame,
    ];
    for n in 0.. {
        match solve_error_of_number(n) {
            Some(e) => all.push(PipelineError::Solve(e)),
            None => break,
        }
    }
    all.push(PipelineError::UnsupportedMode(
        crate::measurement::Mode::Road,
    ));
    all
}

/// What the device sends for `e` and the host reads from the wire: a whole frame, encoded
/// and decoded.
fn over_the_wire(e: &PipelineError) -> DeviceError {
    let msg = FromDevice {
        tag: 0,
        response: Response::Error(Failure::of(e).device_error()),
    };
    let mut scratch = [0u8; MAX_RAW_LEN];
    let mut frame = [0u8; MAX_FRAME_LEN];
    let n = encode(&msg, &mut scratch, &mut frame).unwrap();
    match decode::<FromDevice>(&mut frame[..n]).unwrap().response {
        Response::Error(error) => error,
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_failure_reads_the_same_from_a_file_and_from_the_caliper() {
    for e in every_pipeline_error() {
        // What `tangent measure` prints for a capture the host measured itself …
        let direct = Failure::of(&e).to_string();
        // … and what `tangent listen` prints for the caliper's report of the same failure.
        let error = over_the_wire(&e);
        assert_eq!(error.code, ErrorCode::MeasurementFailed);
        let received = Failure::from_detail(error.detail);
        assert_eq!(received, Failure::of(&e), "{e:?}");
        assert_eq!(received.to_string(), direct, "{e:?}");
        assert_eq!(
            error.to_string(),
            std::format!("no stem was measured: {direct}")
        );
        assert!(!matches!(received, Failure::Unknown { .. }), "{e:?}");
    }
}

#[test]
fn failures_of_the_corpus_keep_the_pipelines_words() {
    // The sentences the corpus readings print (tests/captures) are the pipeline's own.
    for e in [
        PipelineError::NoLaserLight { max_difference: 16 },
        PipelineError::Segment(SegmentError::TooManyObjects { capacity: 1024 }),
        PipelineError::OutsideFrame,
        PipelineError::NoCurve,
        PipelineError::Calibration,
        PipelineError::Solve(SolveError::NotRound),
    ] {
        assert_eq!(Failure::of(&e).to_string(), e.to_string());
    }
}

#[test]
fn failure_codes_are_the_documented_ones() {
    // docs/protocol.md, "Measurement failures": changing a number breaks older hosts.
    let got: Vec<u8> = every_pipeline_error()
        .iter()
        .map(|e| Failure::of(e).code())
        .collect();
    assert_eq!(
        got,
        [
            1, 2, 3, 4, 5, 1, 6, 6, 1, 1, 15, 7, 8, 9, 1, 10, 10, 8, 11, 12, 13, 14, 14, 14, 14,
            14, 14, 14, 14, 14, 14, 14, 14, 14, 14, 16
        ]
    );
    assert_eq!(
        Failure::of(&PipelineError::Solve(SolveError::NotRound)).detail(),
        14 | 9 << 8
    );
    assert_eq!(
        Failure::of(&PipelineError::NoLaserLight { max_difference: 7 }).detail(),
        4 | 7 << 8
    );
}

#[test]
fn unknown_and_oversized_details_are_named_not_misread() {
    let newer = Failure::from_detail(200 | 5 << 8);
    assert_eq!(
        newer,
        Failure::Unknown {
            code: 200,
            argument: 5
        }
    );
    assert!(newer.to_string().contains("code 200"));
    assert!(matches!(
        Failure::from_detail(14 | 99 << 8),
        Failure::Unknown { code: 14, .. }
    ));
    // A number too large for 24 bits saturates instead of spilling into the code.
    let big = Failure::of(&PipelineError::CurveTooShort {
        plane: 0,
        points: usize::MAX,
    });
    assert_eq!(big.detail() & 0xFF, 9);
    assert_eq!(
        Failure::from_detail(big.detail()),
        Failure::CurveTooShort {
            points: (1 << 24) - 1
        }
    );
}

#[test]
fn every_flag_has_one_name_and_known_flags_are_all_of_them() {
    let mut names: Vec<&str> = FLAG_NAMES.iter().map(|(_, n)| *n).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), FLAG_NAMES.len());
    let mut bits = 0u32;
    for (f, _) in FLAG_NAMES {
        assert_eq!(f.0.count_ones(), 1);
        assert_eq!(bits & f.0, 0);
        bits |= f.0;
    }
    assert_eq!(known_flags(), Flags(bits));
    let set = Flags(Flags::TILT_IGNORED.0 | Flags::ELLIPTIC.0 | Flags::NOT_SPHERICAL.0);
    let got: Vec<&str> = flag_names(set).collect();
    assert_eq!(got, ["tilt_ignored", "elliptic", "not_spherical"]);
}

#[test]
fn every_method_has_a_distinct_name() {
    let names: Vec<String> = [
        Method::ThreeTangent,
        Method::CircleFit,
        Method::CylinderFit,
        Method::GeneralisedThreeTangent,
        Method::JointFit,
        Method::SphereSections,
        Method::SphereThreeTangent,
        Method::MeanProfileDepth,
    ]
    .iter()
    .map(|m| method_name(*m).to_string())
    .collect();
    assert_eq!(
        names,
        [
            "three_tangent",
            "circle_fit",
            "cylinder_fit",
            "generalised_three_tangent",
            "joint_fit",
            "sections",
            "sphere_three_tangent",
            "mean_profile_depth"
        ]
    );
}
