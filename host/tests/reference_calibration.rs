//! `tangent calibrate ball` and `wall`: rendered views of the reference (a ball, a flat wall)
//! and a calibration file whose planes are off by a draw of the board calibration's σ in; the
//! `[[planes]]` rewritten with the relative tilt restored within its stated σ, every other
//! key kept; bad input refused naming the capture.

use std::path::{Path, PathBuf};
use std::process::Command;

use tangent_core::noise::NoiseModel;
use tangent_host::calibration_draw::drawn;
use tangent_host::calibration_file;
use tangent_host::simulate::rig::{three_plane_calibration, two_plane_calibration};
use tangent_host::simulate::simulate;
use tangent_host::simulate::sphere_corpus::reference_ball_spec;
use tangent_host::simulate::wall_corpus::reference_wall_spec;

fn tangent(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args(args)
        .output()
        .unwrap()
}

fn relative_tilt(c: &tangent_core::calibration::Calibration) -> f64 {
    c.planes[1].baseline_tilt().1 - c.planes[0].baseline_tilt().1
}

/// Runs `command views… --calib calib`, which must succeed: its arguments, its output and
/// the σ of laser 1's tilt against laser 0's it prints ("laser 1 against laser 0: δ ±
/// 0.0660 mrad").
fn refine(command: &[&str], views: &[PathBuf], calib: &Path) -> (Vec<String>, String, f64) {
    let mut args: Vec<String> = command.iter().map(|a| a.to_string()).collect();
    args.extend(views.iter().map(|v| v.display().to_string()));
    args.extend(["--calib".into(), calib.display().to_string()]);
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = tangent(&refs);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{stdout}");
    let sigma_mrad: f64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("laser 1 against laser 0: δ ± "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    (args, stdout, sigma_mrad)
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
    let (args, stdout, sigma_mrad) = refine(&["calibrate", "ball"], &views, &calib);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let refined = calibration_file::read(&calib).unwrap();
    let before = (relative_tilt(&off) - relative_tilt(&truth)) * 1e3;
    let after = (relative_tilt(&refined) - relative_tilt(&truth)) * 1e3;
    assert!(
        after.abs() < 3.5 * sigma_mrad && sigma_mrad < 0.14,
        "{before} → {after} ± {sigma_mrad} mrad\n{stdout}"
    );
    assert!(after.abs() < 0.5 * before.abs(), "{before} → {after}");
    assert_eq!(refined.camera, off.camera);
    // The refinement's covariance is written beside the planes, and read back.
    let u = refined.uncertainty.expect("[planes_uncertainty] written");
    assert_eq!(u.planes(), 2);
    let (t0, t1) = (u.sigmas()[1], u.sigmas()[3]);
    let relative = (t0 * t0 + t1 * t1 - 2.0 * u.correlation(1, 3) * t0 * t1).sqrt() * 1e3;
    assert!(
        (relative - sigma_mrad).abs() < 0.002,
        "{relative} vs printed {sigma_mrad} mrad"
    );
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

/// The same for a flat wall on the three-line head: `tangent calibrate wall` brings plane 1's
/// tilt relative to plane 0 back within its printed σ and the crossing plane's to a few µrad.
#[test]
fn the_wall_command_restores_the_three_planes_relative_tilts() {
    let tmp = tempfile::tempdir().unwrap();
    let views: Vec<PathBuf> = (0..6)
        .map(|i| {
            let (capture, _) = simulate(&reference_wall_spec(i, 5, true)).unwrap();
            let d = tmp.path().join(format!("wall-{i}"));
            capture.write(&d).unwrap();
            d
        })
        .collect();
    let truth = three_plane_calibration();
    let noise = NoiseModel {
        focal_px: 0.0,
        ..NoiseModel::reference()
    };
    let off = drawn(&truth, &noise, 4).unwrap();
    let calib = tmp.path().join("unit.toml");
    calibration_file::write(&calib, &off).unwrap();
    let (args, stdout, sigma_mrad) = refine(&["calibrate", "wall"], &views, &calib);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let refined = calibration_file::read(&calib).unwrap();
    let relative = |c: &tangent_core::calibration::Calibration, k: usize| {
        (c.planes[k].baseline_tilt().1 - c.planes[0].baseline_tilt().1) * 1e3
    };
    let after1 = relative(&refined, 1) - relative(&truth, 1);
    let after2 = relative(&refined, 2) - relative(&truth, 2);
    assert!(
        after1.abs() < 3.5 * sigma_mrad,
        "{after1} ± {sigma_mrad}\n{stdout}"
    );
    assert!(after2.abs() < 0.01, "{after2} mrad\n{stdout}");
    // A ball's capture among the wall's views is refused by name.
    let ball = tmp.path().join("ball");
    simulate(&reference_ball_spec(0, 1))
        .unwrap()
        .0
        .write(&ball)
        .unwrap();
    let mixed = [
        "calibrate",
        "wall",
        args[2],
        args[3],
        args[4],
        ball.to_str().unwrap(),
        "--calib",
        calib.to_str().unwrap(),
    ];
    let out = tangent(&mixed);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("ball") && err.contains("wall mode"), "{err}");
}
