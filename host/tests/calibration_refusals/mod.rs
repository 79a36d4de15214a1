//! The refusals of `docs/calibration.md` ("When calibration refuses"): degenerate inputs
//! fail with the reason named, and no file is written.

use super::*;
use tangent_host::calibrate::CalibrateError;

fn tangent() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_tangent"))
}

/// The same view three times, or two views and a copy: refused as repeated views
/// (OpenCV's corners, so no detector is involved).
#[test]
fn repeated_views_are_refused() {
    let views = opencv_views();
    let same = vec![views[0].clone(), views[0].clone(), views[0].clone()];
    let err = refine::calibrate_camera(&same, &board_9x6()).unwrap_err();
    assert!(
        matches!(&err, CalibrateError::Undetermined(m) if m.contains("1 distinct view")),
        "{err}"
    );
    let copy = vec![views[0].clone(), views[1].clone(), views[0].clone()];
    let err = refine::calibrate_camera(&copy, &board_9x6()).unwrap_err();
    assert!(err.to_string().contains("2 distinct view"), "{err}");
    // Nearly the same: every corner moved by a tenth of a pixel.
    let mut nudged = views[0].clone();
    nudged.corners.iter_mut().for_each(|c| c.pixel.x += 0.1);
    let near = vec![views[0].clone(), nudged, views[1].clone()];
    assert!(matches!(
        refine::calibrate_camera(&near, &board_9x6()),
        Err(CalibrateError::Undetermined(_))
    ));
    // All 13 OpenCV views still calibrate.
    assert!(refine::calibrate_camera(&views, &board_9x6()).is_ok());
}

/// Views that differ only by a translation of the board (same orientation) give Zhang
/// the same constraints: refused for too little tilt between them.
#[test]
fn views_without_tilt_diversity_are_refused() {
    let cam = truth_camera();
    let board = board_9x6();
    let rotation = Rotation3::from_euler_angles(0.3, 0.2, 0.1);
    let poses: Vec<Pose> = (0..4)
        .map(|k| Pose {
            rotation,
            translation: Vector3::new(-0.1 + 0.02 * k as f64, -0.06, 0.5 + 0.1 * k as f64),
        })
        .collect();
    let views = synthetic_views(&cam, &board, &poses, 0.1, 1);
    let err = refine::calibrate_camera(&views, &board).unwrap_err();
    println!("translated only: {err}");
    assert!(
        matches!(&err, CalibrateError::Undetermined(m) if m.contains("orientations")),
        "{err}"
    );
    // With the orientation varied they calibrate.
    let views = synthetic_views(&cam, &board, &truth_poses(&board), 0.0, 1);
    assert!(refine::calibrate_camera(&views, &board).is_ok());
}

/// The laser plane from the same board capture three times is the board itself: refused.
/// Two distinct poses of the corpus still calibrate.
#[test]
fn laser_plane_at_one_depth_is_refused() {
    let (truth, prepared) = committed_board_captures();
    let same = vec![
        prepared[0].clone(),
        prepared[0].clone(),
        prepared[0].clone(),
    ];
    let err = calibrate_lasers(&truth.camera, &board_9x6(), &same).unwrap_err();
    assert!(
        matches!(&err, CalibrateError::Undetermined(m) if m.contains("distinct depths")),
        "{err}"
    );
    let two = vec![prepared[0].clone(), prepared[1].clone()];
    assert!(calibrate_lasers(&truth.camera, &board_9x6(), &two).is_ok());
}

/// A parameter whose σ exceeds its bound is refused by name: three views tilted only
/// 6° apart with 0.3 px corner noise determine the orientation test but not the focal
/// length; and the bound itself names k3 with its σ.
#[test]
fn undetermined_parameters_are_refused_by_name() {
    let cam = truth_camera();
    let board = board_9x6();
    let poses: Vec<Pose> = [(0.0, 0.0), (0.105, 0.0), (0.0, 0.105)]
        .iter()
        .map(|&(a, b)| Pose {
            rotation: Rotation3::from_euler_angles(a, b, 0.0),
            translation: Vector3::new(-0.1, -0.06, 0.6),
        })
        .collect();
    let views = synthetic_views(&cam, &board, &poses, 0.3, 3);
    let err = refine::calibrate_camera(&views, &board).unwrap_err();
    println!("6° apart: {err}");
    assert!(matches!(err, CalibrateError::TooUncertain { .. }), "{err}");
    let mut cal = refine::calibrate_camera(&opencv_views(), &board).unwrap();
    tangent_host::calibrate::sanity::parameters_determined(
        &cal.camera,
        &tangent_host::calibrate::refine::INTRINSIC_NAMES,
        &cal.std_dev,
    )
    .unwrap();
    cal.std_dev[8] = 551_651.0;
    let err = tangent_host::calibrate::sanity::parameters_determined(
        &cal.camera,
        &tangent_host::calibrate::refine::INTRINSIC_NAMES,
        &cal.std_dev,
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .starts_with("k3 is not determined by these views: σ = 5.5165e5"),
        "{err}"
    );
}

/// `calibrate camera` with the same image three times exits non-zero, names the
/// repeated views and writes no file.
#[test]
fn calibrate_camera_command_refuses_repeated_images() {
    let dir = tempfile::tempdir().unwrap();
    let out_file = dir.path().join("calib.toml");
    let image = data_dir().join("left01.jpg");
    let out = tangent()
        .args(["calibrate", "camera"])
        .args([&image, &image, &image])
        .arg("--out")
        .arg(&out_file)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("1 distinct view(s)"), "{stderr}");
    assert!(!out_file.exists());
}

/// `calibrate laser` on the same capture three times exits non-zero, names the reason
/// and writes nothing.
#[test]
fn calibrate_laser_command_refuses_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (truth, _) = committed_board_captures();
    let camera = dir.path().join("camera.toml");
    let text = calibration_file::to_string(&truth);
    let camera_only = &text[..text.find("[[planes]]").unwrap()];
    std::fs::write(&camera, camera_only).unwrap();
    let out_file = dir.path().join("out.toml");
    let pose = captures_dir().join("board-pose-01");
    let out = tangent()
        .args(["calibrate", "laser"])
        .args([&pose, &pose, &pose])
        .arg("--camera")
        .arg(&camera)
        .arg("--out")
        .arg(&out_file)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("cannot determine"), "{stderr}");
    assert!(!out_file.exists());
    assert_eq!(std::fs::read_to_string(&camera).unwrap(), camera_only);
}

/// Loaded calibrations outside physical ranges are refused, naming the key.
#[test]
fn loaded_values_outside_physical_ranges_name_the_key() {
    let (truth, _) = committed_board_captures();
    let text = calibration_file::to_string(&truth);
    assert!(calibration_file::parse(&text).is_ok());
    // Each case is one the core accepts (a plane stays consistent: its source on it).
    let normal = "normal = [0.0, 0.9977851578566089, 0.06651901052377393]";
    let offset = "offset_m = 0.0997785157856609";
    let source = "source_m = [0.0, 0.1, 0.0]";
    let cases: [(&[(&str, &str)], &str); 6] = [
        (
            &[("fx_px = 1000.0", "fx_px = 1e-300")],
            "calibration.camera.fx_px = 1e-300 is outside 100..100000 px",
        ),
        (
            &[("fy_px = 1000.0", "fy_px = 1e300")],
            "calibration.camera.fy_px = 1e300 is outside",
        ),
        (
            &[("cx_px = 375.5", "cx_px = 900.0")],
            "calibration.camera.cx_px = 900 is outside 0..752 px",
        ),
        (
            &[("k3 = 0.0", "k3 = 1360000.0")],
            "calibration.camera.distortion.k3 = 1.36e6 is outside",
        ),
        (
            &[
                (offset, "offset_m = 99.7785157856609"),
                (source, "source_m = [0.0, 100.0, 0.0]"),
            ],
            "calibration.planes[0].offset_m = 99.7785157856609 is outside",
        ),
        (
            &[
                (
                    normal,
                    "normal = [0.0, 1.9955703157132178, 0.13303802104754786]",
                ),
                (offset, "offset_m = 0.1995570315713218"),
            ],
            "calibration.planes[0].normal = 2 is outside length 0.99..1.01",
        ),
    ];
    for (edits, want) in cases {
        let mut bad = text.clone();
        for (from, to) in edits {
            assert!(bad.contains(from), "{from} not in {text}");
            bad = bad.replacen(from, to, 1);
        }
        let err = calibration_file::parse(&bad).unwrap_err().to_string();
        assert!(err.contains(want), "{edits:?}: {err}");
    }
}

/// `accuracy --diameters-mm` refuses NaN, 0 and 1e300.
#[test]
fn accuracy_refuses_meaningless_diameters() {
    for bad in ["NaN", "0", "1e300", "-5", "abc"] {
        let out = tangent()
            .args([
                "accuracy",
                "--out",
                "/nonexistent/never.png",
                "--diameters-mm",
            ])
            .arg(format!("100,{bad}"))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{bad}");
        let stderr = String::from_utf8(out.stderr).unwrap();
        assert!(stderr.contains("--diameters-mm"), "{bad}: {stderr}");
    }
}
