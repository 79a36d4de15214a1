//! The application's two safety promises on virtual time (`crate::fakes`): the lasers never
//! stay lit beyond [`MAX_LASER_ON_US`] (+ one guard poll) whatever the camera does, and the
//! watchdog is fed by the main loop only — while idle and between measurements — so a hang
//! stops the feeding and the hardware watchdog resets the device.

use std::cell::RefCell;
use std::rc::Rc;

use tangent_core::accelerometer;
use tangent_core::protocol::{
    AccelReading, ErrorCode, Request, WirePlanesUncertainty, MAX_FRAME_LEN,
};

use super::*;
use crate::adxl355::model::Adxl355Model;
use crate::adxl355::{Adxl355, SAMPLE_SIGMA_M_S2};
use crate::fakes::{
    longest_lit_us, poll_bounded, CameraBehaviour, FailingMeasurer, FakeBoard, FakeCamera,
    FakeClock, FakeLaser, FakeWatchdog, NoTrigger, QuietLink, RamSector, RefStore, Time, GEOMETRY,
};
use crate::fakes::{VerticalMeasurer, Verticals};
use crate::i2c_target::TargetBus;
use crate::measure::{FramePair, Measurer};
use crate::mode_log::ModeLog;
use tangent_core::measurement::Measurement;
use tangent_core::real::Real;

/// Polls enough for any bounded capture here (each poll advances the time by ≥ one guard
/// poll while a capture hangs, and CAPTURE_TIMEOUT_US / GUARD_POLL_US = 500).
const POLLS: usize = 100_000;

/// The longest a capture may keep a laser lit: the limit plus the guard's polling period.
const LIT_BOUND_US: u64 = MAX_LASER_ON_US + GUARD_POLL_US as u64;

/// The longest one exposure may take: the capture timeout plus the guard's polling period.
const EXPOSE_BOUND_US: u64 = CAPTURE_TIMEOUT_US + GUARD_POLL_US as u64;

struct Rig {
    time: Time,
    switches: Rc<RefCell<Vec<(u64, u8)>>>,
    feeds: Rc<RefCell<Vec<u64>>>,
    writes: Rc<core::cell::Cell<usize>>,
    off: Vec<u8>,
    on: Vec<u8>,
    rx: Vec<u8>,
    /// The mode store's flash: kept across [`Rig::app`] calls, as across power cycles.
    sector: RamSector,
    /// The accelerometer on the board's bus (`None`: not fitted).
    accelerometer: Option<Adxl355Model>,
}

impl Rig {
    fn new() -> Self {
        Rig {
            time: Time::default(),
            switches: Rc::default(),
            feeds: Rc::default(),
            writes: Rc::default(),
            off: vec![0; GEOMETRY.frame_len()],
            on: vec![0; GEOMETRY.frame_len()],
            rx: vec![0; MAX_FRAME_LEN],
            sector: RamSector::new(16),
            accelerometer: None,
        }
    }

    fn app(
        &mut self,
        camera: CameraBehaviour,
        writes_hang: bool,
    ) -> App<'_, FakeBoard, FailingMeasurer> {
        self.app_with(camera, writes_hang, FailingMeasurer)
    }

    fn app_with<M: Measurer>(
        &mut self,
        camera: CameraBehaviour,
        writes_hang: bool,
        measurer: M,
    ) -> App<'_, FakeBoard, M> {
        let clock = FakeClock(self.time.clone());
        let devices = Devices::<FakeBoard> {
            camera: FakeCamera {
                clock: clock.clone(),
                behaviour: camera,
            },
            laser: FakeLaser {
                time: self.time.clone(),
                switches: self.switches.clone(),
            },
            trigger: NoTrigger,
            link: QuietLink {
                writes: self.writes.clone(),
                writes_hang,
            },
            clock,
            store: RefStore,
            modes: ModeLog::new(self.sector.clone()),
            watchdog: FakeWatchdog {
                time: self.time.clone(),
                feeds: self.feeds.clone(),
            },
            accelerometer: Adxl355::new(TargetBus::new(self.accelerometer.clone())),
        };
        let buffers = Buffers {
            off: &mut self.off,
            on: &mut self.on,
            rx: &mut self.rx,
        };
        App::new(devices, measurer, buffers)
    }
}

/// Captures a pair with the camera doing `behaviour`; the result, the longest laser
/// on-time and the laser mask at the end.
fn capture_with(behaviour: CameraBehaviour) -> (Result<FrameSetInfo, DeviceError>, u64, u8) {
    let mut rig = Rig::new();
    let switches = rig.switches.clone();
    let result = {
        let mut app = rig.app(behaviour, false);
        assert!(
            app.calibration().is_some(),
            "the fake store's calibration loads"
        );
        poll_bounded(app.capture_pair(), POLLS).expect("a capture is bounded by its guard")
    };
    let (lit, last) = longest_lit_us(&switches.borrow());
    (result, lit, last)
}

#[test]
fn a_working_camera_lights_the_lasers_for_the_exposure_only() {
    let (result, lit, last) = capture_with(CameraBehaviour::Works);
    let info = result.expect("capture");
    assert_eq!(info.laser_mask, 0b11);
    assert_eq!(lit, info.exposure_us as u64);
    assert_eq!(last, 0);
}

#[test]
fn a_camera_that_hangs_with_the_lasers_lit_is_cut_off_at_the_limit() {
    let (result, lit, last) = capture_with(CameraBehaviour::HangsLit);
    assert_eq!(result.map_err(|e| e.code), Err(ErrorCode::LaserTimeout));
    assert!(
        lit > MAX_LASER_ON_US,
        "lit {lit} µs: tripped before the limit"
    );
    assert!(lit <= LIT_BOUND_US, "lit {lit} µs > {LIT_BOUND_US} µs");
    assert_eq!(last, 0, "a laser is still on");
}

#[test]
fn a_measurement_with_a_hung_lit_camera_reports_laser_timeout() {
    let mut rig = Rig::new();
    let switches = rig.switches.clone();
    let result = {
        let mut app = rig.app(CameraBehaviour::HangsLit, false);
        poll_bounded(app.measure_once(), POLLS).expect("bounded")
    };
    assert_eq!(result.map_err(|e| e.code), Err(ErrorCode::LaserTimeout));
    let (lit, last) = longest_lit_us(&switches.borrow());
    assert!(
        lit <= LIT_BOUND_US && last == 0,
        "lit {lit} µs, last mask {last:#b}"
    );
}

#[test]
fn a_camera_that_fails_mid_exposure_leaves_the_lasers_off() {
    let (result, lit, last) = capture_with(CameraBehaviour::FailsMidExposure);
    let error = result.expect_err("the camera failed");
    assert_eq!(error.code, ErrorCode::CameraFailure);
    assert_eq!(error.detail, CameraError::Transfer.code());
    assert!(lit <= LIT_BOUND_US, "lit {lit} µs");
    assert_eq!(last, 0, "a laser is still on");
}

/// A board without frame buffers (the H743 streams the laser-on frame) answers a raw capture
/// with the specific "no frame store" failure, without lighting a laser, and the host's
/// sentence says why.
#[test]
fn a_board_without_frame_buffers_refuses_raw_captures_clearly() {
    let mut rig = Rig::new();
    rig.off.clear();
    rig.on.clear();
    let switches = rig.switches.clone();
    let result = {
        let mut app = rig.app(CameraBehaviour::Works, false);
        poll_bounded(app.capture_pair(), POLLS).expect("bounded")
    };
    let error = result.expect_err("no memory for a pair");
    assert_eq!(error.code, ErrorCode::CameraFailure);
    assert_eq!(error.detail, CameraError::NoFrameStore.code());
    let sentence = std::format!("{error}");
    assert!(
        sentence.contains("cannot store a raw frame pair"),
        "{sentence}"
    );
    assert!(switches.borrow().iter().all(|&(_, m)| m == 0));
}

#[test]
fn a_dead_camera_times_out_without_lighting_and_without_feeding_the_watchdog() {
    let mut rig = Rig::new();
    let (time, feeds, switches) = (rig.time.clone(), rig.feeds.clone(), rig.switches.clone());
    let result = {
        let mut app = rig.app(CameraBehaviour::HangsDark, false);
        poll_bounded(app.capture_pair(), POLLS).expect("bounded")
    };
    assert_eq!(result.map_err(|e| e.code), Err(ErrorCode::CameraTimeout));
    let took = time.get();
    assert!(
        took > CAPTURE_TIMEOUT_US && took <= EXPOSE_BOUND_US,
        "took {took} µs"
    );
    assert!(
        feeds.borrow().is_empty(),
        "fed from inside a capture: {:?}",
        feeds.borrow()
    );
    assert!(switches.borrow().iter().all(|&(_, m)| m == 0));
}

/// The largest gap between consecutive feeds (from time 0).
fn longest_gap(feeds: &[u64]) -> u64 {
    let mut previous = 0;
    feeds
        .iter()
        .map(|&t| {
            let gap = t - previous;
            previous = t;
            gap
        })
        .max()
        .unwrap_or(0)
}

#[test]
fn the_idle_loop_feeds_the_watchdog_every_tick() {
    let mut rig = Rig::new();
    let (time, feeds) = (rig.time.clone(), rig.feeds.clone());
    {
        let mut app = rig.app(CameraBehaviour::Works, false);
        for _ in 0..50 {
            poll_bounded(app.step(), POLLS).expect("an idle step ends");
        }
    }
    let feeds = feeds.borrow();
    assert_eq!(feeds.len(), 50);
    assert_eq!(
        time.get(),
        50 * IDLE_TICK_US as u64,
        "each idle step is one tick"
    );
    assert!(longest_gap(&feeds) <= IDLE_TICK_US as u64);
}

#[test]
fn a_long_stream_feeds_the_watchdog_between_measurements() {
    // A stream of measurements — with a working camera, and with a dead one (every
    // exposure runs into the capture timeout) — is fed once per measurement and between a
    // stem reading's frame pairs: the longest gap is one pair, bounded by two guarded
    // exposures.
    for camera in [
        CameraBehaviour::Works,
        CameraBehaviour::HangsDark,
        CameraBehaviour::HangsLit,
    ] {
        let mut rig = Rig::new();
        let (feeds, writes, switches) =
            (rig.feeds.clone(), rig.writes.clone(), rig.switches.clone());
        {
            let mut app = rig.app(camera, false);
            poll_bounded(app.handle(1, Request::StartStream), POLLS).expect("ack");
            for _ in 0..200 {
                poll_bounded(app.step(), POLLS).expect("a stream step ends");
            }
        }
        let feeds = feeds.borrow();
        // A dead camera ends the reading at its first pair.
        let per_step = match camera {
            CameraBehaviour::Works => DEFAULT_EXPOSURES as usize,
            _ => 1,
        };
        assert_eq!(feeds.len(), 200 * per_step, "{camera:?}");
        assert_eq!(
            writes.get(),
            1 + 200,
            "{camera:?}: the ack and one report per step"
        );
        let gap = longest_gap(&feeds);
        assert!(
            gap <= 2 * EXPOSE_BOUND_US,
            "{camera:?}: {gap} µs between feeds"
        );
        let (lit, last) = longest_lit_us(&switches.borrow());
        assert!(
            lit <= LIT_BOUND_US && last == 0,
            "{camera:?}: lit {lit} µs, last {last:#b}"
        );
    }
}

#[test]
fn a_hang_in_the_main_loop_stops_the_feeding() {
    // The link's write never completes (a hang the guard does not cover): the step that
    // hangs fed the watchdog when it started and between its reading's frame pairs, and
    // never again, so the hardware watchdog's countdown runs out — nothing else feeds it.
    let mut rig = Rig::new();
    let feeds = rig.feeds.clone();
    {
        let mut app = rig.app(CameraBehaviour::Works, true);
        app.stream = Some((1, crate::stats::Welford::new()));
        assert!(
            poll_bounded(app.step(), POLLS).is_none(),
            "the step should hang"
        );
    }
    assert_eq!(
        feeds.borrow().len(),
        DEFAULT_EXPOSURES as usize,
        "{:?}",
        feeds.borrow()
    );
}

/// The mode from the host: every mode this build measures is taken and remembered, every
/// other refused with the `UnsupportedMode` failure and the mode left as it was; the device
/// starts in the stem's mode.
#[test]
fn set_mode_takes_what_the_build_measures_and_refuses_the_rest() {
    use tangent_core::instrument;
    use tangent_core::measurement::Mode;
    let mut rig = Rig::new();
    let mut app = rig.app(CameraBehaviour::Works, false);
    assert_eq!(app.mode(), Mode::Cylinder);
    let mut refused = 0;
    for mode in Mode::ALL {
        let before = app.mode();
        match app.set_mode(mode) {
            Ok(()) => {
                assert!(
                    instrument::supports(mode),
                    "{mode:?} taken without a solver"
                );
                assert_eq!(app.mode(), mode);
            }
            Err(error) => {
                refused += 1;
                assert!(!instrument::supports(mode), "{mode:?} refused");
                assert_eq!(error, Failure::UnsupportedMode(mode).device_error());
                assert_eq!(error.code, ErrorCode::MeasurementFailed);
                assert_eq!(app.mode(), before, "a refused mode changes nothing");
            }
        }
    }
    assert!(
        refused < Mode::ALL.len(),
        "the stem's mode is always measured"
    );
}

/// The mode survives a power cycle (the application built again on the same flash), a mode
/// set again is not stored again, and a store that fails keeps the mode as it was and says
/// `StorageFailure`.
#[test]
fn the_mode_survives_a_power_cycle_and_a_failed_store_changes_nothing() {
    use tangent_core::measurement::Mode;
    let mut rig = Rig::new();
    {
        let app = rig.app(CameraBehaviour::Works, false);
        assert_eq!(app.mode(), Mode::Cylinder);
        assert_eq!(app.mode_store(), ModeStoreState::Empty);
    }
    {
        let mut app = rig.app(CameraBehaviour::Works, false);
        app.set_mode(Mode::Sphere).unwrap();
        assert_eq!(app.mode_store(), ModeStoreState::Loaded(Mode::Sphere));
        app.set_mode(Mode::Sphere).unwrap();
    }
    assert_eq!(
        rig.sector.0.borrow().programs,
        1,
        "the same mode twice is stored once"
    );
    let sector = rig.sector.clone();
    {
        let mut app = rig.app(CameraBehaviour::Works, false);
        assert_eq!(app.mode(), Mode::Sphere, "kept across the power cycle");
        assert_eq!(app.mode_store(), ModeStoreState::Loaded(Mode::Sphere));
        sector.0.borrow_mut().refuse_programs = true;
        let e = app.set_mode(Mode::Wall).unwrap_err();
        assert_eq!(e.code, ErrorCode::StorageFailure);
        assert_eq!(e.detail, 4, "the board's code");
        assert_eq!(app.mode(), Mode::Sphere, "a mode not stored is not taken");
        sector.0.borrow_mut().refuse_programs = false;
        // A power cut while the next change is programmed: that change is lost, not the
        // one before.
        sector.0.borrow_mut().tear_next_program = Some(13);
        assert_eq!(
            app.set_mode(Mode::Road).unwrap_err().code,
            ErrorCode::StorageFailure
        );
        assert_eq!(app.mode(), Mode::Sphere);
    }
    let app = rig.app(CameraBehaviour::Works, false);
    assert_eq!(app.mode(), Mode::Sphere);
    assert!(!rig.sector.0.borrow().programmed_twice);
}

/// A damaged store gives the default mode and says so; setting the default explicitly then
/// stores it.
#[test]
fn a_damaged_store_gives_the_default_mode_reported() {
    use tangent_core::measurement::Mode;
    let mut rig = Rig::new();
    rig.sector.0.borrow_mut().words[0] = [0x5A; 32];
    {
        let mut app = rig.app(CameraBehaviour::Works, false);
        assert_eq!(app.mode(), Mode::Cylinder);
        assert_eq!(app.mode_store(), ModeStoreState::Corrupt);
        app.set_mode(Mode::Cylinder).unwrap();
        assert_eq!(app.mode_store(), ModeStoreState::Loaded(Mode::Cylinder));
    }
    let app = rig.app(CameraBehaviour::Works, false);
    assert_eq!(app.mode_store(), ModeStoreState::Loaded(Mode::Cylinder));
}

#[test]
fn the_crossing_laser_is_never_lit_with_the_parallel_pair() {
    // The walls' three-line head (docs/building.md, "The crossing line"): plane 2 runs down
    // the image and has a frame of its own; the pair's capture lights lasers 0 and 1 only.
    let mut rig = Rig::new();
    let switches = rig.switches.clone();
    let info = {
        let mut app = rig.app(CameraBehaviour::Works, false);
        let mut cal = tangent_core::calibration::Calibration::reference_design();
        let crossing = tangent_core::calibration::reference_crossing_plane()
            .expect("the reference crossing plane is valid");
        cal.planes.push(crossing).expect("room for a third plane");
        // The fake camera's small frame.
        cal.camera.width = GEOMETRY.width as u32;
        cal.camera.height = GEOMETRY.height as u32;
        cal.camera.cx = 0.5 * (GEOMETRY.width as f64 - 1.0);
        cal.camera.cy = 0.5 * (GEOMETRY.height as f64 - 1.0);
        app.install_calibration(&tangent_core::protocol::WireCalibration::from(&cal))
            .expect("a three-plane calibration installs");
        poll_bounded(app.capture_pair(), POLLS)
            .expect("a capture is bounded by its guard")
            .expect("the camera works")
    };
    assert_eq!(info.laser_mask, 0b011);
    let log = switches.borrow();
    assert!(log.iter().any(|&(_, m)| m == 0b011), "{log:?}");
    assert!(log.iter().all(|&(_, m)| m & 0b100 == 0), "{log:?}");
    assert_eq!(longest_lit_us(&log).1, 0, "the lasers end off");
}

/// The reference calibration with an accelerometer aligned with the camera and no bias.
fn calibration_with_accelerometer() -> WireCalibration {
    let mut wire = WireCalibration::from(&Calibration::reference_design());
    wire.accelerometer = Some(protocol::WireAccelerometer {
        bias_m_s2: [0.0; 3],
        bias_sigma_m_s2: 0.0074,
        camera_from_sensor_rad: [0.0; 3],
        alignment_sigma_rad: 0.00087,
    });
    wire
}

/// One measurement in `mode` on a rig whose accelerometer is `part`, with `wire` installed
/// when given: the reading (or error), the vertical the measurer was given, and whether the
/// accelerometer was set up at all.
fn measure_in(
    mode: Mode,
    part: Option<Adxl355Model>,
    wire: Option<WireCalibration>,
) -> (
    Result<Reading, DeviceError>,
    Vec<crate::fakes::Gravity>,
    bool,
) {
    let mut rig = Rig::new();
    rig.accelerometer = part;
    let verticals = Verticals::default();
    let mut app = rig.app_with(
        CameraBehaviour::Works,
        false,
        VerticalMeasurer(verticals.clone()),
    );
    // The fake camera's frames are not the reference sensor's, which `install_calibration`
    // refuses: the accelerometer's part is put in place as it would install it.
    app.alignment = wire
        .and_then(|w| w.accelerometer)
        .and_then(|a| a.to_alignment());
    app.set_mode(mode).unwrap();
    let reading = poll_bounded(app.measure_once(), POLLS).expect("bounded");
    let set_up = app.dev.accelerometer.is_ready();
    let v = verticals.borrow().clone();
    (reading, v, set_up)
}

/// A level device: the sensor (aligned with the camera) feels 1 g up, along the camera's −y.
fn level_part() -> Adxl355Model {
    let g = crate::adxl355::STANDARD_GRAVITY;
    Adxl355Model::new([0.0, -g, 0.0], SAMPLE_SIGMA_M_S2, 3)
}

#[test]
fn a_wall_reading_carries_the_accelerometer_and_the_plumb_gets_its_gravity() {
    let (reading, verticals, _) = measure_in(
        Mode::Wall,
        Some(level_part()),
        Some(calibration_with_accelerometer()),
    );
    let reading = reading.unwrap();
    let Some(AccelReading::Mean {
        m_s2,
        samples,
        sample_sigma_m_s2,
    }) = reading.accelerometer
    else {
        panic!("{:?}", reading.accelerometer)
    };
    assert_eq!(
        (samples, sample_sigma_m_s2),
        (ACCEL_SAMPLES, SAMPLE_SIGMA_M_S2)
    );
    // The mean of 16 samples: within 4σ/√16 of the sensed force on every axis.
    let g = crate::adxl355::STANDARD_GRAVITY;
    for (got, want) in m_s2.iter().zip([0.0, -g, 0.0]) {
        assert!((got - want).abs() < SAMPLE_SIGMA_M_S2, "{m_s2:?}");
    }
    // The measurer got gravity as the core computes it from the reading: down the image.
    let alignment = calibration_with_accelerometer()
        .accelerometer
        .and_then(|a| a.to_alignment())
        .unwrap();
    let want = accelerometer::vertical(&reading.accelerometer.unwrap().mean().unwrap(), &alignment)
        .unwrap();
    assert_eq!(verticals, [Some((want.down, want.sigma_rad))]);
    assert!(want.down.y > 0.9999, "{want:?}");
}

#[test]
fn without_an_accelerometer_or_its_calibration_a_wall_reading_says_why_and_has_no_plumb() {
    // Not fitted: the reading is made, without the vertical, and says so.
    let (reading, verticals, _) =
        measure_in(Mode::Wall, None, Some(calibration_with_accelerometer()));
    assert_eq!(reading.unwrap().accelerometer, Some(AccelReading::Absent));
    assert_eq!(verticals, [None]);
    // The wrong part: a failure with its code, still a reading.
    let mut part = level_part();
    part.id[2] = 0xE5;
    let (reading, verticals, _) = measure_in(
        Mode::Wall,
        Some(part),
        Some(calibration_with_accelerometer()),
    );
    assert_eq!(
        reading.unwrap().accelerometer,
        Some(AccelReading::Failed(
            tangent_core::protocol::codes::ACCEL_WRONG_PART
        ))
    );
    assert_eq!(verticals, [None]);
    // A part that never leaves standby: a timeout, not a hang.
    let mut part = level_part();
    part.conversion_polls = u32::MAX;
    let (reading, _, _) = measure_in(
        Mode::Wall,
        Some(part),
        Some(calibration_with_accelerometer()),
    );
    assert_eq!(
        reading.unwrap().accelerometer,
        Some(AccelReading::Failed(
            tangent_core::protocol::codes::ACCEL_TIMEOUT
        ))
    );
    // No accelerometer calibration: the mean travels, the plumb does not.
    let (reading, verticals, _) = measure_in(Mode::Wall, Some(level_part()), None);
    assert!(reading.unwrap().accelerometer.unwrap().mean().is_some());
    assert_eq!(verticals, [None]);
}

#[test]
fn instruments_without_a_plumb_do_not_read_the_accelerometer() {
    for mode in [Mode::Cylinder, Mode::Sphere, Mode::Road] {
        let (reading, verticals, set_up) = measure_in(
            mode,
            Some(level_part()),
            Some(calibration_with_accelerometer()),
        );
        assert_eq!(reading.unwrap().accelerometer, None, "{mode:?}");
        assert_eq!(verticals, [None], "{mode:?}");
        assert!(!set_up, "{mode:?}: the accelerometer was not touched");
    }
}

/// A planes' covariance that is no covariance (a correlation above 1) is refused with its
/// own detail, and the calibration before stays active.
#[test]
fn a_planes_uncertainty_that_is_no_covariance_is_refused() {
    let mut rig = Rig::new();
    let mut app = rig.app(CameraBehaviour::Works, false);
    let before = app.calibration.clone();
    let mut wire = calibration_with_accelerometer();
    wire.uncertainty = Some(WirePlanesUncertainty {
        sigma: heapless::Vec::from_slice(&[2e-4, 2e-4, 2e-4, 2e-4]).unwrap(),
        correlation: heapless::Vec::from_slice(&[0.0, 1.2, 0.0, 0.0, 0.9, 0.0]).unwrap(),
    });
    assert_eq!(
        app.install_calibration(&wire),
        Err(DeviceError {
            code: ErrorCode::InvalidCalibration,
            detail: 4
        })
    );
    assert_eq!(app.calibration, before);
}

#[test]
fn an_accelerometer_calibration_that_is_not_finite_is_refused() {
    let mut rig = Rig::new();
    let mut app = rig.app(CameraBehaviour::Works, false);
    let mut wire = calibration_with_accelerometer();
    if let Some(a) = wire.accelerometer.as_mut() {
        a.camera_from_sensor_rad[0] = f64::INFINITY;
    }
    assert_eq!(
        app.install_calibration(&wire),
        Err(DeviceError {
            code: ErrorCode::InvalidCalibration,
            detail: 3
        })
    );
    assert_eq!(app.alignment, None);
}

/// Reads a stem of 300 mm + 10 mm per pair measured and, asked to combine, reports how many
/// pairs the reading took in its `exposures` (how the application drives the exposures is
/// under test here; the combination itself is the core's, tested there and under QEMU).
struct CountingMeasurer {
    measured: Rc<core::cell::Cell<usize>>,
}

impl Measurer for CountingMeasurer {
    fn measure(
        &mut self,
        mode: Mode,
        _: &FramePair<'_>,
        _: &Calibration,
    ) -> Result<Measurement, Failure> {
        let k = self.measured.get();
        self.measured.set(k + 1);
        // The second pair of every reading fails: a pair that cannot be read does not end
        // the reading.
        if k % 4 == 1 {
            return Err(Failure::Frame);
        }
        let diameter = 0.3 + 0.01 * k as Real;
        Ok(match mode {
            Mode::Cylinder => Measurement::Stem(tangent_core::measurement::StemReading {
                diameter,
                uncertainty: 0.001,
                method: tangent_core::protocol::Method::CircleFit,
                distance: 1.0,
                tilt: None,
                axes: None,
                flags: tangent_core::solvers::result::Flags::default(),
                exposures: 1,
            }),
            _ => return Err(Failure::UnsupportedMode(mode)),
        })
    }

    fn begin_exposures(&mut self) {
        self.measured.set(0);
    }

    fn combined(&mut self, _: Mode) -> Option<Result<Measurement, Failure>> {
        let n = self.measured.get();
        Some(
            self.measure(Mode::Cylinder, &PAIR, &Calibration::reference_design())
                .map(|m| match m {
                    Measurement::Stem(s) => {
                        Measurement::Stem(tangent_core::measurement::StemReading {
                            exposures: n as u8,
                            ..s
                        })
                    }
                    other => other,
                }),
        )
    }
}

const PAIR: FramePair<'static> = FramePair {
    off: &[],
    on: &[],
    width: 0,
    height: 0,
    row_offset: 0,
    laser_mask: 0,
};

/// A stem reading measures the set number of frame pairs and reports the measurer's
/// combination of them; one pair is reported as it is; other instruments take one pair;
/// a count of 0 or above 16 is refused and the count stays as it was.
#[test]
fn a_stem_reading_takes_the_set_number_of_pairs() {
    use tangent_core::measurement::Mode;
    let measured = Rc::new(core::cell::Cell::new(0));
    let mut rig = Rig::new();
    let mut app = rig.app_with(
        CameraBehaviour::Works,
        false,
        CountingMeasurer {
            measured: measured.clone(),
        },
    );
    assert_eq!(app.exposures(), DEFAULT_EXPOSURES);
    let stem = |r: Reading| match r.measurement {
        Measurement::Stem(s) => s,
        other => panic!("not a stem: {other:?}"),
    };
    let reading = stem(poll_bounded(app.measure_once(), POLLS).unwrap().unwrap());
    assert_eq!(
        measured.get(),
        DEFAULT_EXPOSURES as usize + 1,
        "pairs, then the combination"
    );
    assert_eq!(reading.exposures, DEFAULT_EXPOSURES);
    for bad in [0, 17, u8::MAX] {
        let error = app.set_exposures(bad).unwrap_err();
        assert_eq!(error.code, ErrorCode::InvalidSetting);
        assert_eq!(error.detail, bad as u32);
        assert_eq!(
            app.exposures(),
            DEFAULT_EXPOSURES,
            "a refused count changes nothing"
        );
    }
    app.set_exposures(1).unwrap();
    let reading = stem(poll_bounded(app.measure_once(), POLLS).unwrap().unwrap());
    assert_eq!(measured.get(), 1, "one pair, not combined");
    assert_eq!((reading.exposures, reading.diameter), (1, 0.3));
    app.set_exposures(16).unwrap();
    poll_bounded(app.measure_once(), POLLS).unwrap().unwrap();
    assert_eq!(measured.get(), 17);
    app.set_mode(Mode::Sphere).unwrap();
    let failed = poll_bounded(app.measure_once(), POLLS)
        .unwrap()
        .unwrap_err();
    assert_eq!(measured.get(), 1, "a sphere takes one pair");
    assert_eq!(failed.code, ErrorCode::MeasurementFailed);
}
