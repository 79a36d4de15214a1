//! `tangent calibrate accelerometer`: poses of a simulated sensor (known bias, scale and
//! misalignment, the reference noise) in, the `[accelerometer]` table of the calibration file
//! out, within its σ of the truth; poses that cannot determine it are refused naming the file.

use std::path::Path;
use std::process::Command;

use nalgebra::{Rotation3, Vector3};
use tangent_core::calibration::Calibration;
use tangent_host::calibration_file;

const G: f64 = 9.806_65;

fn tangent(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tangent"))
        .args(args)
        .output()
        .unwrap()
}

/// The poses file of a sensor with `bias`, `scale`, `camera_from_sensor`, at gravity
/// directions `dirs`, with deterministic small reading errors (±0.03 mg) and none on gravity.
fn write_poses(
    path: &Path,
    bias: Vector3<f64>,
    scale: f64,
    camera_from_sensor: Rotation3<f64>,
    dirs: &[Vector3<f64>],
) {
    let mut text = String::new();
    for (i, g) in dirs.iter().enumerate() {
        let wiggle = 0.03e-3 * G * ((i as f64 * 1.7).sin());
        let a = camera_from_sensor.inverse() * (-g * G) * scale
            + bias
            + Vector3::new(wiggle, -wiggle, 0.5 * wiggle);
        text += &format!(
            "[[pose]]\nmean_m_s2 = [{}, {}, {}]\nsigma_m_s2 = {}\ngravity_camera = [{}, {}, {}]\ndirection_sigma_rad = {}\n\n",
            a.x, a.y, a.z, 0.0275e-3 * G, g.x, g.y, g.z, 3.5e-4
        );
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn six_tilted_faces_give_the_table_within_its_sigma() {
    let dir = tempfile::tempdir().unwrap();
    let calib = dir.path().join("cal.toml");
    calibration_file::write(&calib, &Calibration::reference_design()).unwrap();
    let bias = Vector3::new(0.21, -0.13, 0.05);
    let scale = 1.002;
    let r = Rotation3::new(Vector3::new(0.012, -0.004, 0.017));
    let tilt = Rotation3::from_euler_angles(0.35, 0.35, 0.0);
    let dirs: Vec<_> = [
        Vector3::x(),
        -Vector3::x(),
        Vector3::y(),
        -Vector3::y(),
        Vector3::z(),
        -Vector3::z(),
    ]
    .iter()
    .map(|v| tilt * v)
    .collect();
    let poses = dir.path().join("poses.toml");
    write_poses(&poses, bias, scale, r, &dirs);
    let out = tangent(&[
        "calibrate",
        "accelerometer",
        poses.to_str().unwrap(),
        "--calib",
        calib.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("bias") && stdout.contains("χ²/dof"),
        "{stdout}"
    );
    let table = calibration_file::read_accelerometer(&calib)
        .unwrap()
        .expect("[accelerometer] written");
    for i in 0..3 {
        let e = table.bias_m_s2[i] - bias[i];
        assert!(
            e.abs() < 4.0 * table.bias_sigma_m_s2[i],
            "bias axis {i}: {e} vs σ {}",
            table.bias_sigma_m_s2[i]
        );
    }
    let got = Rotation3::new(Vector3::from(table.camera_from_sensor_rad));
    assert!((got * r.inverse()).angle() < 0.01f64.to_radians());
    assert!((table.scale - scale).abs() < 1e-4);
    assert_eq!(table.poses, 6);
    // The rest of the file is kept: it still reads as the same calibration.
    assert_eq!(
        calibration_file::read(&calib).unwrap(),
        Calibration::reference_design()
    );
}

#[test]
fn poses_along_one_line_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let calib = dir.path().join("cal.toml");
    calibration_file::write(&calib, &Calibration::reference_design()).unwrap();
    let poses = dir.path().join("poses.toml");
    let dirs = [Vector3::y(), -Vector3::y(), Vector3::y(), -Vector3::y()];
    write_poses(&poses, Vector3::zeros(), 1.0, Rotation3::identity(), &dirs);
    let out = tangent(&[
        "calibrate",
        "accelerometer",
        poses.to_str().unwrap(),
        "--calib",
        calib.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("poses.toml") && err.contains("two independent directions"),
        "{err}"
    );
    assert!(calibration_file::read_accelerometer(&calib)
        .unwrap()
        .is_none());
}
