//! `tangent calibrate ball`: rendered views of the reference ball and a calibration file whose
//! planes are off by a draw of the board calibration's σ in; the `[[planes]]` rewritten with
//! the relative tilt restored within its stated σ, every other key kept; bad input refused
//! naming the capture.

use std::path::{Path, PathBuf};
use std::process::Command;

use tangent_core::noise::NoiseModel;
use tangent_host::calibration_draw::drawn;
use tangent_host::calibration_file;
use tangent_host::simulate::rig::two_plane_calibration;
use tangent_host::simulate::simulate;
use tangent_host::simulate::sphere_corpus::reference_ball_spec;

fn tangent(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args(args)
        .output()
        .unwrap()
}

fn relative_tilt(c: &tangent_core::calibration::Calibration) -> f64 {
    c.planes[1].baseline_tilt().1 - c.planes[0].baseline_tilt().1
}

/// Six views rendered into `dir`, their paths.
fn write_views(dir: &Path) -> Vec<PathBuf> {
    (0..6)
        .map(|i| {
            let (capture, _) = simulate(&reference_ball_spec(i, 11)).unwrap();
            let d = dir.join(format!("ball-{i}"));
            capture.write(&d).unwrap();
            d
        })
        .collect()
}

#[test]
fn the_ball_command_restores_the_planes_relative_tilt_and_keeps_the_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let views = write_views(tmp.path());
    let truth = two_plane_calibration();
    let noise = NoiseModel {
        focal_px: 0.0,
        ..NoiseModel::reference()
    };
    let off = drawn(&truth, &noise, 3).unwrap();
    let calib = tmp.path().join("unit.toml");
    calibration_file::write(&calib, &off).unwrap();
    std::fs::write(
        &calib,
        std::fs::read_to_string(&calib).unwrap() + "\n[road]\nheight_scale = 1.01\n",
    )
    .unwrap();
    let mut args: Vec<String> = vec!["calibrate".into(), "ball".into()];
    args.extend(views.iter().map(|v| v.display().to_string()));
    args.extend(["--calib".into(), calib.display().to_string()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = tangent(&args);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The printed σ of the relative tilt, e.g. "laser 1 against laser 0: δ ± 0.0660 mrad".
    let sigma_mrad: f64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("laser 1 against laser 0: δ ± "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    eprintln!("{stdout}");
    let refined = calibration_file::read(&calib).unwrap();
    let before = (relative_tilt(&off) - relative_tilt(&truth)) * 1e3;
    let after = (relative_tilt(&refined) - relative_tilt(&truth)) * 1e3;
    assert!(
        after.abs() < 3.5 * sigma_mrad && sigma_mrad < 0.14,
        "{before} → {after} ± {sigma_mrad} mrad\n{stdout}"
    );
    assert!(after.abs() < 0.5 * before.abs(), "{before} → {after}");
    assert_eq!(refined.camera, off.camera);
    let road = calibration_file::read_road(&calib).unwrap().unwrap();
    assert_eq!(road.height_scale, 1.01);

    // Two views, or a stem capture among them, are refused by name; the file is untouched.
    let kept = std::fs::read_to_string(&calib).unwrap();
    let two = [
        "calibrate",
        "ball",
        args[2],
        args[3],
        "--calib",
        calib.to_str().unwrap(),
    ];
    let out = tangent(&two);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("2 usable view(s), at least 3 needed"), "{err}");
    let stem = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/captures/cyl-d300-z150-shade");
    let with_stem = [
        "calibrate",
        "ball",
        args[2],
        args[3],
        stem.to_str().unwrap(),
        "--calib",
        calib.to_str().unwrap(),
    ];
    let out = tangent(&with_stem);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("cyl-d300-z150-shade") && err.contains("sphere mode"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&calib).unwrap(), kept);
}
