//! The CI check of the firmware: on the emulated firmware (QEMU mps2-an500, the shared
//! pipeline in `f32` on the Cortex-M7), every instrument measures what the host measures
//! on the same frames — stems, several exposures, spheres, road profiles, walls, the plumb.
//!
//! Needs `qemu-system-arm` (CI installs it; without it each test prints why it is skipped)
//! and builds the emulated firmware (`cargo firmware-qemu`) on first use.

mod emulated;

use tangent_core::calibration::PlanesUncertainty;
use tangent_core::measurement::{Measurement, Mode};
use tangent_core::protocol::{DeviceError, ErrorCode, Request, Response, WireCalibration};

use emulated::*;

#[test]
fn on_device_spheres_equal_the_hosts() {
    let wanted = [
        "sphere-d100-z080-matt-2p",
        "sphere-d150-z100-offcentre-2p",
        "sphere-d250-z150-shiny-offcentre-2p",
        "sphere-d400-z200-matt-2p",
        "sphere-d080-z090-floor-offcentre-2p",
        "sphere-d055-z120-nearpole-2p",
        "notsphere-wall-z120-2p",
    ];
    // Three balls are measured with planes refined on a reference: the calibration carries
    // their covariance (`[planes_uncertainty]`, protocol v6), which sets the stated σ; the
    // device receives it with the calibration and must state the host's σ.
    let refined = PlanesUncertainty::new(
        &[2e-4, 1.9e-4, 2e-4, 1.9e-4],
        &[
            1.0, 0.0, 0.9, 0.0, //
            0.0, 1.0, 0.0, 0.94, //
            0.9, 0.0, 1.0, 0.0, //
            0.0, 0.94, 0.0, 1.0,
        ],
    )
    .unwrap();
    let with_covariance = [
        "sphere-d150-z100-offcentre-2p",
        "sphere-d400-z200-matt-2p",
        "sphere-d055-z120-nearpole-2p",
    ];
    let entries = tangent_host::simulate::sphere_corpus::entries()
        .into_iter()
        .map(|mut e| {
            if with_covariance.contains(&e.name.as_str()) {
                e.spec.calibration = e.spec.calibration.with_uncertainty(refined).unwrap();
            }
            e
        })
        .collect();
    let same = |name: &str, h: &Measurement, d: &Measurement| {
        let (Measurement::Sphere(h), Measurement::Sphere(d)) = (h, d) else {
            panic!("{name}: sphere readings, got host {h:?}, device {d:?}")
        };
        let rel = (d.diameter - h.diameter).abs() / h.diameter;
        eprintln!(
            "{name}: host {:.4} mm {:?}, device {:.4} mm {:?}, relative difference {rel:.2e}",
            h.diameter * 1e3,
            h.method,
            d.diameter * 1e3,
            d.method
        );
        assert_eq!(d.method, h.method, "{name}: method");
        assert!(
            rel <= 1e-4,
            "{name}: device {} m vs host {} m",
            d.diameter,
            h.diameter
        );
        assert_eq!(d.flags, h.flags, "{name}: flags");
        // The stated σ too: its covariance inverts a normal matrix whose determinant can be
        // beyond f32's range (`solvers::lm::spd_inverse`: a closed-form inverse gave a zero
        // covariance in f32 for the core's near-pole unit test ball).
        let rel_sigma = (d.uncertainty - h.uncertainty).abs() / h.uncertainty;
        eprintln!(
            "{name}: σ host {:.4} mm, device {:.4} mm",
            h.uncertainty * 1e3,
            d.uncertainty * 1e3
        );
        assert!(
            d.uncertainty > 0.0 && rel_sigma <= 1e-2,
            "{name}: σ device {} m vs host {} m",
            d.uncertainty,
            h.uncertainty
        );
    };
    let Some(compared) = device_equals_host(entries, &wanted, Mode::Sphere, SetMode::Yes, same)
    else {
        return;
    };
    assert!(
        compared >= 3,
        "only {compared} balls measured on both sides"
    );
}

/// The firmware issue's CI check: the emulated firmware, running the shared pipeline in
/// `f32` on the Cortex-M7, gives the host's results (pipeline in `f64`) on the same frames:
/// same method, diameters within 1e-4 relative, or a failure where the host fails.
///
/// Why 1e-4 holds: the device's only difference is `f32` arithmetic (ε = 6e-8). The
/// subpixel rows carry ≈ 1e-4 px of rounding after the ~10 operations of the estimator
/// (row ≈ 400 × 6e-8 × a few), and the diameter of a fit to N ≈ 100–700 points moves by
/// about (rounding / noise) of its statistical error — below 1e-5 relative — unless a
/// decision (outlier rejection, method choice) flips, which the method comparison catches.
#[test]
fn on_device_measurements_equal_the_hosts() {
    let wanted = [
        "cyl-d050-z050-shade",
        "cyl-d300-z150-shade",
        "cyl-d600-z150-shade",
        "cyl-d300-z150-sun",
        "cyl-d300-z150-10bit",
        "cyl-d300-z150-vertical-2p",
        "cyl-d300-z150-tilt10-right-2p",
        "cyl-d500-z200-tilt15-diagonal-2p",
        "nothing-in-range",
    ];
    let same = |name: &str, h: &Measurement, d: &Measurement| {
        let rel = (d.value() - h.value()).abs() / h.value();
        eprintln!(
            "{name}: host {:.4} mm {:?}, device {:.4} mm {:?}, relative difference {rel:.2e}",
            h.value() * 1e3,
            h.method(),
            d.value() * 1e3,
            d.method()
        );
        assert_eq!(d.kind(), "stem", "{name}: kind");
        assert_eq!(d.method(), h.method(), "{name}: method");
        assert!(
            rel <= 1e-4,
            "{name}: device {} m vs host {} m",
            d.value(),
            h.value()
        );
        assert_eq!(d.flags(), h.flags(), "{name}: flags");
    };
    // The stem is the caliper's instrument at boot: no mode is set.
    let Some(compared) = device_equals_host(
        tangent_host::simulate::corpus::entries(),
        &wanted,
        Mode::Cylinder,
        SetMode::AtBoot,
        same,
    ) else {
        return;
    };
    assert!(
        compared >= 5,
        "only {compared} captures measured on both sides"
    );
}

/// Several exposures on the device (`Request::SetExposures`, `docs/error-model.md` §6,
/// (E7)): the emulated firmware measures four frame pairs per `Measure` and combines them;
/// the host measures the same pairs one by one and combines them with the same core
/// function. The readings agree as one pair's do (each pair within the f32 rounding, the
/// mean of four no further), name four exposures, and a count the device cannot take is
/// refused by name with the count unchanged.
#[test]
fn on_device_exposures_combine_as_the_hosts() {
    use tangent_core::instrument::stem::Stem;
    use tangent_core::instrument::{measure_with, InstrumentParams};
    use tangent_core::pipeline::{OwnedBuffers, PipelineConfig};
    use tangent_core::solvers::stem::combine_exposures;
    use tangent_host::simulate::simulate;

    let Some(elf) = firmware_elf() else {
        return;
    };
    const PAIRS: usize = 4;
    let wanted = ["cyl-d300-z150-shade", "cyl-d300-z150-tilt10-right-2p"];
    let dir = tempfile::tempdir().unwrap();
    let (mut files, mut cases) = (Vec::new(), Vec::new());
    for entry in tangent_host::simulate::corpus::entries()
        .into_iter()
        .filter(|e| wanted.contains(&e.name.as_str()))
    {
        let name = entry.name;
        let mut spec = entry.spec;
        spec.params.exposure_pairs = PAIRS;
        let (capture, _) = simulate(&spec).expect("simulate the capture");
        assert_eq!(capture.pairs(), PAIRS, "{name}");
        let mut solutions = Vec::new();
        for k in 0..PAIRS {
            let pair = capture.exposure_pair(k).expect("a pair");
            let (paths, (off, on), (w, h)) = write_pair(dir.path(), &format!("{name}-p{k}"), &pair);
            files.push(paths);
            let off_f = tangent_core::image::Frame::new(&off, w, h, w).unwrap();
            let on_f = tangent_core::image::Frame::new(&on, w, h, w).unwrap();
            let planes = capture.calibration.planes.len();
            let mut ws = OwnedBuffers::<u8>::for_frame(w, h, 8, planes);
            let measured = measure_with::<Stem, u8>(
                &off_f,
                &on_f,
                &capture.calibration,
                &PipelineConfig::default(),
                &InstrumentParams::default().cylinder,
                &mut ws.workspace(),
            )
            .unwrap_or_else(|e| panic!("{name}: pair {k} reads on the host: {e}"));
            solutions.push(measured.solution);
        }
        let host = Measurement::from(&combine_exposures(&solutions).expect("combines"));
        cases.push((name, capture.calibration.clone(), host));
    }
    assert_eq!(cases.len(), wanted.len(), "corpus entries missing");

    let mut dev = Device::boot(&elf, &files, None);
    for bad in [0u8, 17] {
        dev.request(Request::SetExposures(bad), |r| {
            assert_eq!(
                r,
                Response::Error(DeviceError {
                    code: ErrorCode::InvalidSetting,
                    detail: bad as u32
                })
            )
        });
    }
    let info = dev.request(Request::DeviceInfo, |r| match r {
        Response::Info(i) => i.exposures,
        other => panic!("{other:?}"),
    });
    assert_eq!(info, 4, "the default count, unchanged by the refused ones");
    dev.request(Request::SetExposures(PAIRS as u8), |r| {
        assert_eq!(r, Response::Ack)
    });
    for (name, cal, host) in &cases {
        dev.request(Request::WriteCalibration(WireCalibration::from(cal)), |r| {
            assert_eq!(r, Response::Ack, "{name}")
        });
        dev.request(Request::Measure, |r| {
            let Response::Reading(reading) = r else {
                panic!("{name}: device {r:?}");
            };
            let (Measurement::Stem(d), Measurement::Stem(h)) = (&reading.measurement, host) else {
                panic!("{name}: not stems: {:?}, {host:?}", reading.measurement);
            };
            let rel = (d.diameter - h.diameter).abs() / h.diameter;
            eprintln!(
                "{name}: host {:.4} ± {:.4} mm, device {:.4} ± {:.4} mm ({} exposures), \
                 relative difference {rel:.2e}",
                h.diameter * 1e3,
                h.uncertainty * 1e3,
                d.diameter * 1e3,
                d.uncertainty * 1e3,
                d.exposures
            );
            assert_eq!(
                (d.exposures, h.exposures),
                (PAIRS as u8, PAIRS as u8),
                "{name}"
            );
            assert_eq!(d.method, h.method, "{name}: method");
            assert_eq!(d.flags, h.flags, "{name}: flags");
            assert!(rel <= 1e-4, "{name}: diameter");
            // σ: rounding moves each pair by ≈ 1e-5 of d, against a scatter of ≈ 1e-3 of d.
            let rel_sigma = (d.uncertainty - h.uncertainty).abs() / h.uncertainty;
            assert!(rel_sigma <= 1e-2, "{name}: σ differs by {rel_sigma:.2e}");
        });
    }
}

/// The road instrument on the emulated device (mode set from the host) gives the host's
/// reading on the same frames: MPD within 1 µm (f32 against f64: heights are differences of
/// depths ≈ 0.3 m, rounded at ≈ 4e-8 m, far below), the same segments; a refusal reads the
/// same sentence.
#[test]
fn road_profiles_on_the_device_equal_the_hosts() {
    let wanted = ["road-head-stone-mastic", "road-head-tilted-10deg"];
    let same = |name: &str, h: &Measurement, d: &Measurement| {
        let (Measurement::Road(h), Measurement::Road(d)) = (h, d) else {
            panic!("{name}: road readings, got host {h:?}, device {d:?}")
        };
        eprintln!(
            "{name}: host MPD {:.4} mm, device {:.4} mm",
            h.mpd * 1e3,
            d.mpd * 1e3
        );
        assert!((d.mpd - h.mpd).abs() <= 1e-6, "{name}: {d:?} vs {h:?}");
        assert_eq!(d.segments, h.segments, "{name}");
    };
    device_equals_host(
        tangent_host::simulate::corpus::entries(),
        &wanted,
        Mode::Road,
        SetMode::Yes,
        same,
    );
}

/// The wall instrument on the device: set to `Mode::Wall` from the host, the emulated
/// firmware (f32) reads the corpus's walls as the host (f64) does — same number of walls,
/// axis distance within 1e-4 relative, angles within 0.01° — or fails with the same sentence
/// (`docs/building.md`).
#[test]
fn on_device_wall_readings_equal_the_hosts() {
    let wanted = [
        "wall-z150-frontal",
        "wall-corner-z200",
        "wall-corner-z150-a100-brick",
        "wall-z200-one-line",
    ];
    let same = |name: &str, h: &Measurement, d: &Measurement| {
        let (Measurement::Wall(h), Measurement::Wall(d)) = (h, d) else {
            panic!("{name}: wall readings, got host {h:?}, device {d:?}")
        };
        eprintln!("{name}: host {h:?}\n{name}: device {d:?}");
        assert_eq!(d.walls, h.walls, "{name}: walls");
        assert!(
            (d.distance - h.distance).abs() <= 1e-4 * h.distance,
            "{name}"
        );
        let deg = 0.01f64.to_radians() as tangent_core::real::Real;
        assert!((d.yaw.value - h.yaw.value).abs() <= deg, "{name}: yaw");
        match (d.corner, h.corner) {
            (Some(a), Some(b)) => assert!((a.value - b.value).abs() <= deg, "{name}"),
            (None, None) => {}
            other => panic!("{name}: corners {other:?}"),
        }
    };
    let Some(compared) = device_equals_host(
        tangent_host::simulate::corpus::entries(),
        &wanted,
        Mode::Wall,
        SetMode::Yes,
        same,
    ) else {
        return;
    };
    assert!(
        compared >= 3,
        "only {compared} wall captures measured on both sides"
    );
}

/// The vertical on the device (issue 15): the emulated board's ADXL355 (its register model,
/// through the same driver as the H743's) senses each wall capture's recorded specific force
/// with the part's noise; the device averages 16 samples, sends the mean with the wall
/// reading and computes the plumb with the accelerometer calibration pushed with the
/// camera's. The host, given the device's mean and the same calibration, computes the same
/// plumb (`tangent_core::accelerometer::vertical` on both sides; f32 against f64: within
/// 0.01°, σ within 1 %). Without a part the reading says so and has no plumb.
#[test]
fn on_device_plumb_equals_the_hosts() {
    use tangent_core::instrument::{measure, InstrumentParams};
    use tangent_core::pipeline::{OwnedBuffers, PipelineConfig};
    use tangent_core::protocol::{AccelReading, WireAccelerometer};
    use tangent_host::simulate::simulate;

    let Some(elf) = firmware_elf() else {
        return;
    };
    let wanted = [
        "wall-z150-frontal",
        "wall-corner-z200",
        "wall-z300-yaw25-concrete",
    ];
    let dir = tempfile::tempdir().unwrap();
    let mut compared = 0;
    for entry in tangent_host::simulate::corpus::entries()
        .into_iter()
        .filter(|e| wanted.contains(&e.name.as_str()))
    {
        let name = entry.name;
        let (capture, _) = simulate(&entry.spec).expect("simulate the corpus capture");
        let record = capture
            .meta
            .accelerometer
            .clone()
            .expect("a wall capture records its accelerometer");
        let (_, alignment) = record.to_core();
        let mut wire = WireCalibration::from(&capture.calibration);
        wire.accelerometer = Some(WireAccelerometer::from(&alignment));
        let off_pgm = capture.off_frame();
        let (_, on_pgm) = capture.on_frames().next().expect("an on frame");
        let (w, h) = (off_pgm.width, off_pgm.height);
        let (off, on) = (to_u8(off_pgm), to_u8(on_pgm));
        let pair = (
            dir.path().join(format!("{name}-off.pgm")),
            dir.path().join(format!("{name}-on.pgm")),
        );
        write_pgm(&pair.0, w, h, &off);
        write_pgm(&pair.1, w, h, &on);
        let force = record.mean_m_s2.map(|x| x as f32);
        let device_reading = |options: &str| {
            let mut dev = Device::boot_with(&elf, std::slice::from_ref(&pair), None, options);
            dev.request(Request::SetMode(Mode::Wall), |r| {
                assert_eq!(r, Response::Ack)
            });
            dev.request(Request::WriteCalibration(wire.clone()), |r| {
                assert_eq!(r, Response::Ack, "{name}")
            });
            dev.request(Request::Measure, |r| match r {
                Response::Reading(reading) => reading,
                other => panic!("{name}: {other:?}"),
            })
        };
        let host = |gravity| {
            let mut params = InstrumentParams::default();
            params.wall.walls.gravity = gravity;
            let off_f = tangent_core::image::Frame::new(&off, w, h, w).unwrap();
            let on_f = tangent_core::image::Frame::new(&on, w, h, w).unwrap();
            let mut ws = OwnedBuffers::<u8>::for_frame(w, h, 8, capture.calibration.planes.len());
            let m = measure(
                Mode::Wall,
                &off_f,
                &on_f,
                &capture.calibration,
                &PipelineConfig::default(),
                &params,
                &mut ws.workspace(),
            )
            .expect("the host reads the wall");
            let Measurement::Wall(m) = m else {
                panic!("{name}: {m:?}")
            };
            m
        };

        let reading = device_reading(&format!("--accel {},{},{}", force[0], force[1], force[2]));
        let Some(accel @ AccelReading::Mean { m_s2, samples, .. }) = reading.accelerometer else {
            panic!("{name}: {:?}", reading.accelerometer)
        };
        // The emulated part's noise, averaged: within 5σ/√16 of the sensed force.
        let sigma = tangent_firmware::adxl355::SAMPLE_SIGMA_M_S2 / (samples as f32).sqrt();
        for (got, want) in m_s2.iter().zip(force) {
            assert!(
                (got - want).abs() < 5.0 * sigma,
                "{name}: {m_s2:?} vs {force:?}"
            );
        }
        let v = tangent_core::accelerometer::vertical(&accel.mean().unwrap(), &alignment)
            .expect("the device was at rest");
        let h = host(Some((v.down, v.sigma_rad)));
        let Measurement::Wall(d) = reading.measurement else {
            panic!("{name}: {:?}", reading.measurement)
        };
        let (Some(dp), Some(hp)) = (d.plumb, h.plumb) else {
            panic!("{name}: plumb device {:?}, host {:?}", d.plumb, h.plumb)
        };
        eprintln!(
            "{name}: plumb host {:+.4}° ± {:.4}°, device {:+.4}° ± {:.4}°",
            hp.value.to_degrees(),
            hp.sigma.to_degrees(),
            dp.value.to_degrees(),
            dp.sigma.to_degrees()
        );
        assert!(
            (dp.value - hp.value).abs() <= 0.01f64.to_radians(),
            "{name}: plumb"
        );
        assert!(
            (dp.sigma - hp.sigma).abs() <= 0.01 * hp.sigma,
            "{name}: plumb σ"
        );
        compared += 1;

        if compared == 1 {
            // No part fitted: the reading is made, says why it has no plumb, and the host
            // without a vertical agrees.
            let reading = device_reading("");
            assert_eq!(reading.accelerometer, Some(AccelReading::Absent), "{name}");
            let Measurement::Wall(d) = reading.measurement else {
                panic!("{name}: {:?}", reading.measurement)
            };
            assert_eq!((d.plumb, host(None).plumb), (None, None), "{name}");
        }
    }
    assert_eq!(compared, wanted.len(), "corpus entries missing");
}
