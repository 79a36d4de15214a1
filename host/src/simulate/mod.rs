//! The capture simulator: renders laser-off / laser-on frame pairs of known scenes with the
//! exact ground truth (`docs/simulator.md`).
//!
//! Chain: [`scene`] (objects, textures, ray casting) → [`render`] (per-pixel irradiance
//! layers by ray tracing through the camera model, adaptive supersampling, exact true
//! curve) → [`sensor`] (radiometry, PSF, speckle, shot/read noise, gain, quantisation) →
//! [`crate::capture::Capture`]. [`corpus`] lists the committed test captures.
//!
//! Deterministic: every random draw comes from a `Pcg64` seeded from the spec's seed and
//! the (frame, row) it belongs to, so the result does not depend on thread scheduling.

pub mod accelerometer;
pub mod corpus;
pub mod laser;
pub mod physics;
pub mod reflectance;
pub mod render;
pub mod rig;
pub mod road_corpus;
pub mod scene;
pub mod sensor;
pub mod sphere_corpus;
pub mod wall_corpus;

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tangent_core::calibration::{Calibration, MAX_PLANES};

use crate::calibration_file::CalibrationToml;
use crate::capture::{Capture, CaptureMeta, FrameEntry, Mode, Truth, FORMAT_VERSION, MAX_PAIRS};
use crate::pgm::Pgm;
use crate::truth::{Object, PhysicsModel};
use accelerometer::AccelerometerSim;
use laser::LaserParams;
use reflectance::Reflectance;
use render::{HandMotion, Lighting, RenderSetup};
use scene::{splitmix, Scene, SceneError};
use sensor::{OpticsParams, SensorParams};

/// How the exposure time is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Exposure {
    /// Like the sensor's automatic exposure: the brightest pixel of the (noise-free) laser-on
    /// frame reaches `peak_fraction` of full scale, within `[20 µs, max_s]`.
    Auto {
        /// Target fraction of full scale for the brightest pixel.
        peak_fraction: f64,
        /// Longest exposure allowed (hand-held: ≈ 30 ms).
        max_s: f64,
    },
    /// Automatic exposure that judges the stripe by its typical column rather than its
    /// brightest pixel: the median, over the columns the laser lights, of each column's
    /// brightest (noise-free) laser-on pixel reaches `peak_fraction` of full scale, within
    /// `[20 µs, max_s]`. A glint a few columns long then saturates instead of dimming the
    /// whole stripe (`docs/sphere.md`, "Steel balls").
    AutoMedianColumn {
        /// Target fraction of full scale for the median column's peak.
        peak_fraction: f64,
        /// Longest exposure allowed.
        max_s: f64,
    },
    /// A fixed exposure time.
    Fixed {
        /// Seconds.
        seconds: f64,
    },
}

/// Everything the simulator needs besides the calibration and the objects; written to the
/// `[simulation]` table of `capture.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimParams {
    /// Seed of every random draw (noise, speckle, textures). Below 2⁶³ (TOML integers).
    pub seed: u64,
    /// Laser planes lit in the laser-on frame(s).
    pub lit_planes: Vec<usize>,
    /// One laser-on frame per lit plane instead of one frame with all of them.
    pub separate_frames: bool,
    /// Ambient light.
    pub lighting: Lighting,
    /// The lasers.
    pub laser: LaserParams,
    /// Lens and filter.
    pub optics: OpticsParams,
    /// The sensor.
    pub sensor: SensorParams,
    /// Exposure control.
    pub exposure: Exposure,
    /// Analogue gain.
    pub gain: f64,
    /// Multiplicative laser speckle on or off.
    pub speckle: bool,
    /// RMS height roughness of the surfaces for the speckle's spectral decorrelation
    /// (metres; bark ≈ 1 mm).
    pub surface_roughness_m: f64,
    /// Device displacement of the laser-off frame relative to the laser-on frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hand_motion: Option<HandMotion>,
    /// `n` of the `n × n` supersampling of stripe and edge pixels.
    pub supersampling: usize,
    /// Exposure pairs taken while the trigger is held (`docs/simulator.md`, "Several
    /// exposures"): each pair has its own sensor noise and, unless `frozen_speckle`, its own
    /// speckle.
    #[serde(default = "one_pair", skip_serializing_if = "is_one_pair")]
    pub exposure_pairs: usize,
    /// The same speckle in every exposure pair: the hand did not move enough between the
    /// pairs to renew it (the worst case for averaging).
    #[serde(default, skip_serializing_if = "is_false")]
    pub frozen_speckle: bool,
    /// Name of the physics model these parameters were drawn from ([`physics::apply`]);
    /// also recorded in the capture's `[truth]`.
    #[serde(default, skip_serializing_if = "is_reference")]
    pub physics: PhysicsModel,
    /// BRDF of every surface (the objects' albedos scale it).
    #[serde(default, skip_serializing_if = "Reflectance::is_lambertian")]
    pub reflectance: Reflectance,
    /// Feature size of the procedural textures relative to the nominal one
    /// ([`scene::Scene::with_texture_scale`]).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub texture_scale: f64,
    /// The device's accelerometer, when it has one (`docs/building.md` §6): its record is
    /// written to the capture's `[accelerometer]` and the true gravity to `[truth]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accelerometer: Option<AccelerometerSim>,
}

fn is_reference(m: &PhysicsModel) -> bool {
    *m == PhysicsModel::Reference
}

fn one_pair() -> usize {
    1
}

fn is_one_pair(n: &usize) -> bool {
    *n == 1
}

fn is_false(b: &bool) -> bool {
    !*b
}

fn one() -> f64 {
    1.0
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

impl Default for SimParams {
    /// Plane 0 lit, forest shade, the reference laser/lens/sensor, auto exposure to 70 %
    /// (max 30 ms), unity gain, speckle on, no hand motion, 8 × 8 supersampling.
    fn default() -> Self {
        SimParams {
            seed: 1,
            lit_planes: vec![0],
            separate_frames: false,
            lighting: Lighting::shade(),
            laser: LaserParams::default(),
            optics: OpticsParams::default(),
            sensor: SensorParams::default(),
            exposure: Exposure::Auto {
                peak_fraction: 0.7,
                max_s: 0.03,
            },
            gain: 1.0,
            speckle: true,
            surface_roughness_m: 1e-3,
            hand_motion: None,
            supersampling: 8,
            exposure_pairs: 1,
            frozen_speckle: false,
            physics: PhysicsModel::Reference,
            reflectance: Reflectance::Lambertian,
            texture_scale: 1.0,
            accelerometer: None,
        }
    }
}

/// A complete simulation request.
#[derive(Debug, Clone, PartialEq)]
pub struct SimSpec {
    /// Measurement mode written to the capture.
    pub mode: Mode,
    /// Free-text description.
    pub description: String,
    /// RFC 3339 timestamp written to the capture.
    pub timestamp: String,
    /// Camera and laser planes.
    pub calibration: Calibration,
    /// The scene (camera frame of the laser-on frame).
    pub objects: Vec<Object>,
    /// Everything else.
    pub params: SimParams,
}

/// Why a simulation could not run.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The scene is invalid.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A parameter is out of range.
    #[error("simulation parameter: {0}")]
    Param(String),
    /// The result could not be assembled as a capture.
    #[error("capture: {0}")]
    Capture(String),
}

/// Output of [`simulate`] besides the capture: numbers useful in reports and tests.
#[derive(Debug, Clone)]
pub struct SimReport {
    /// Exposure used (seconds).
    pub exposure_s: f64,
    /// Electron rate per unit `ρ·E` (e⁻/s per W/m²), [`SensorParams::electrons_per_s`].
    pub electrons_per_w_m2_s: f64,
    /// Gamma shape `M` of the per-pixel speckle factor (contrast `1/√M`): pixel
    /// integration ([`sensor::speckle_cells`]) and spectral decorrelation combined.
    pub speckle_cells: f64,
}

/// Speckle correlation σ on the sensor (pixels) from which neighbouring pixels' speckle is
/// rendered correlated ([`sensor::correlated_speckle`]); below it the pixel integrates many
/// grains and neighbours are nearly independent (the reference f/2.4 lens: 0.15 px).
pub const CORRELATED_SPECKLE_GRAIN_PX: f64 = 0.25;

/// Random stream of the PRNU pattern.
const PRNU_STREAM: u64 = 300;
/// First random stream of the row noise (plus the frame's stream).
const ROW_NOISE_STREAM: u64 = 400;
/// Offset of every per-frame stream (frames, their row noise, the speckle) from one exposure
/// pair to the next: pair 0's streams are those of a single-pair capture.
const PAIR_STREAMS: u64 = 1000;

fn rng_for(seed: u64, stream: u64, row: u64) -> Pcg64 {
    Pcg64::seed_from_u64(splitmix(
        seed ^ splitmix(stream.wrapping_mul(0x1_0000_0001) ^ (row << 20)),
    ))
}

impl SimSpec {
    /// The spec that produced a synthetic capture (its `[simulation]` table, objects and
    /// calibration), for re-simulation (e.g. with another seed).
    pub fn from_capture(capture: &Capture) -> Result<Self, SimError> {
        let meta = &capture.meta;
        let table = meta
            .simulation
            .clone()
            .ok_or_else(|| SimError::Param("the capture has no [simulation] table".into()))?;
        let params = SimParams::deserialize(table).map_err(|e| SimError::Param(e.to_string()))?;
        Ok(SimSpec {
            mode: meta.mode,
            description: meta.description.clone(),
            timestamp: meta.timestamp.to_string(),
            calibration: capture.calibration.clone(),
            objects: meta
                .truth
                .as_ref()
                .map(|t| t.objects.clone())
                .unwrap_or_default(),
            params,
        })
    }
}

/// Renders a capture (frames + exact truth) from a spec. Deterministic for a given spec.
pub fn simulate(spec: &SimSpec) -> Result<(Capture, SimReport), SimError> {
    let p = &spec.params;
    let cal = &spec.calibration;
    cal.validate().map_err(|e| SimError::Param(e.to_string()))?;
    let nplanes = cal.planes.len();
    if p.lit_planes.is_empty() || p.lit_planes.iter().any(|&i| i >= nplanes) {
        return Err(SimError::Param(format!(
            "lit_planes {:?} must name planes 0..{nplanes}",
            p.lit_planes
        )));
    }
    if !(1..=MAX_PAIRS).contains(&p.exposure_pairs) {
        return Err(SimError::Param(format!(
            "exposure_pairs {} must be 1 to {MAX_PAIRS}",
            p.exposure_pairs
        )));
    }
    if !(1..=16).contains(&p.sensor.bit_depth)
        || p.gain.is_nan()
        || p.gain <= 0.0
        || p.supersampling == 0
    {
        return Err(SimError::Param(
            "bit_depth 1..=16, gain > 0 and supersampling ≥ 1 required".into(),
        ));
    }
    let scene = Scene::new(&spec.objects, p.seed)?.with_texture_scale(p.texture_scale);
    let setup = RenderSetup {
        calibration: cal,
        scene: &scene,
        lighting: &p.lighting,
        laser: &p.laser,
        reflectance: &p.reflectance,
        vignetting: p.optics.vignetting,
        supersampling: p.supersampling,
    };
    let mut lit = [false; MAX_PLANES];
    p.lit_planes.iter().for_each(|&i| lit[i] = true);
    let (w, h) = (cal.camera.width as usize, cal.camera.height as usize);

    let mut on = setup.render(None, &lit);
    let mut off_ambient = match &p.hand_motion {
        Some(m) => setup.render(Some(m), &[false; MAX_PLANES]).ambient,
        None => on.ambient.clone(),
    };
    let sigma = p.optics.psf_sigma_px;
    let defocus = p.optics.defocus_radius_px;
    for layer in std::iter::once(&mut on.ambient)
        .chain(std::iter::once(&mut off_ambient))
        .chain(
            on.lasers
                .iter_mut()
                .enumerate()
                .filter(|(i, _)| lit[*i])
                .map(|(_, l)| l),
        )
    {
        sensor::gaussian_blur(layer, w, h, sigma);
        sensor::disc_blur(layer, w, h, defocus);
    }

    let k = p.sensor.electrons_per_s(&p.optics, p.laser.wavelength_m);
    let exposure_s = match p.exposure {
        Exposure::Fixed { seconds } if seconds > 0.0 => seconds,
        Exposure::Fixed { .. } => return Err(SimError::Param("exposure must be positive".into())),
        Exposure::Auto {
            peak_fraction,
            max_s,
        } => {
            // A row-wise (crossing) plane has its own frame: it does not add to the others'.
            let row_wise = |i: &&usize| cal.planes.get(**i).is_some_and(|pl| pl.is_row_wise());
            let peak = (0..w * h)
                .map(|j| {
                    let across = p.lit_planes.iter().filter(|i| !row_wise(i));
                    let alone = p.lit_planes.iter().filter(row_wise);
                    let most_alone = alone.map(|&i| on.lasers[i][j]).fold(0.0, f64::max);
                    on.ambient[j]
                        + across
                            .map(|&i| on.lasers[i][j])
                            .sum::<f64>()
                            .max(most_alone)
                })
                .fold(0.0, f64::max)
                * k;
            if peak > 0.0 {
                (peak_fraction * p.sensor.full_well_e / (p.gain * peak)).clamp(20e-6, max_s)
            } else {
                max_s
            }
        }
        Exposure::AutoMedianColumn {
            peak_fraction,
            max_s,
        } => {
            let mut peaks: Vec<f64> = (0..w)
                .filter_map(|col| {
                    let (mut laser, mut total) = (0.0f64, 0.0f64);
                    for row in 0..h {
                        let j = row * w + col;
                        let l: f64 = p.lit_planes.iter().map(|&i| on.lasers[i][j]).sum();
                        laser = laser.max(l);
                        total = total.max(on.ambient[j] + l);
                    }
                    (laser > 0.0).then_some(total)
                })
                .collect();
            peaks.sort_by(f64::total_cmp);
            match peaks.get(peaks.len() / 2) {
                Some(&peak) if peak > 0.0 => {
                    (peak_fraction * p.sensor.full_well_e / (p.gain * peak * k)).clamp(20e-6, max_s)
                }
                _ => max_s,
            }
        }
    };

    // Speckle contrast per pixel: pixel integration (1/√M_pix) times spectral
    // decorrelation (C_λ); the Gamma shape is 1/C².
    let cells_pixel = sensor::speckle_cells(
        p.sensor.pixel_pitch_m,
        sensor::speckle_correlation_m(p.laser.wavelength_m, p.optics.f_number),
    );
    let c_lambda = sensor::spectral_speckle_contrast(
        p.laser.wavelength_m,
        p.laser.spectral_width_m,
        p.surface_roughness_m,
    );
    let contrast = c_lambda / cells_pixel.sqrt();
    let cells = if contrast > 0.0 {
        1.0 / (contrast * contrast)
    } else {
        f64::INFINITY
    };
    // Speckle: one factor per pixel and laser (independent lasers, independent patterns).
    // Grains well below the pixel (the reference lens) are independent from pixel to pixel;
    // larger ones (a stopped-down lens) are rendered as a correlated field.
    let grain_px = sensor::speckle_correlation_m(p.laser.wavelength_m, p.optics.f_number)
        / p.sensor.pixel_pitch_m;
    let speckle_of_pair = |pair: u64| -> Vec<Vec<f64>> {
        let stream = |i: usize| 100 + i as u64 + pair * PAIR_STREAMS;
        (0..nplanes)
            .map(|i| {
                if !(p.speckle && lit[i]) {
                    return Vec::new();
                }
                if grain_px >= CORRELATED_SPECKLE_GRAIN_PX {
                    let white: Vec<f64> = (0..h)
                        .into_par_iter()
                        .flat_map_iter(|row| {
                            let mut rng = rng_for(p.seed, stream(i), row as u64);
                            (0..w)
                                .map(move |_| rng.sample::<f64, _>(rand_distr::StandardNormal))
                                .collect::<Vec<_>>()
                        })
                        .collect();
                    // Pixel-integrated grains: the intensity correlation widened by the pixel's
                    // box (variance 1/12 px²).
                    let width = (grain_px * grain_px + 1.0 / 12.0).sqrt();
                    return sensor::correlated_speckle(&white, w, h, width, cells);
                }
                (0..h)
                    .into_par_iter()
                    .flat_map_iter(|row| {
                        let mut rng = rng_for(p.seed, stream(i), row as u64);
                        (0..w)
                            .map(move |_| sensor::speckle_factor(cells, &mut rng))
                            .collect::<Vec<_>>()
                    })
                    .collect()
            })
            .collect()
    };

    // A row-wise plane (the walls' crossing line) is always fired alone, in a frame of its
    // own after the others' (`docs/building.md`, "The crossing line"), as the device does.
    let row_wise = |i: usize| cal.planes.get(i).is_some_and(|pl| pl.is_row_wise());
    let frame_sets: Vec<Vec<usize>> = if p.separate_frames {
        p.lit_planes.iter().map(|&i| vec![i]).collect()
    } else {
        let across: Vec<usize> = p
            .lit_planes
            .iter()
            .copied()
            .filter(|&i| !row_wise(i))
            .collect();
        std::iter::once(across)
            .filter(|s| !s.is_empty())
            .chain(
                p.lit_planes
                    .iter()
                    .filter(|&&i| row_wise(i))
                    .map(|&i| vec![i]),
            )
            .collect()
    };
    // Photo-response non-uniformity: one fixed gain per pixel, the same in every frame.
    let prnu: Vec<f64> = if p.sensor.prnu > 0.0 {
        (0..h)
            .into_par_iter()
            .flat_map_iter(|row| {
                let mut rng = rng_for(p.seed, PRNU_STREAM, row as u64);
                (0..w)
                    .map(move |_| {
                        (1.0 + p.sensor.prnu * rng.sample::<f64, _>(rand_distr::StandardNormal))
                            .max(0.0)
                    })
                    .collect::<Vec<_>>()
            })
            .collect()
    } else {
        Vec::new()
    };
    let expose =
        |stream: u64, planes: &[usize], ambient: &[f64], speckle: &[Vec<f64>]| -> Vec<u16> {
            (0..h)
                .into_par_iter()
                .flat_map_iter(|row| {
                    let mut rng = rng_for(p.seed, stream, row as u64);
                    // The row's temporal offset comes from its own stream, so the pixels' draws
                    // are those of a sensor without row noise.
                    let row_offset_e = if p.sensor.row_noise_e > 0.0 {
                        let mut row_rng = rng_for(p.seed, ROW_NOISE_STREAM + stream, row as u64);
                        p.sensor.row_noise_e * row_rng.sample::<f64, _>(rand_distr::StandardNormal)
                    } else {
                        0.0
                    };
                    let mut out = Vec::with_capacity(w);
                    for col in 0..w {
                        let j = row * w + col;
                        let mut rate = ambient[j];
                        for &i in planes {
                            let s = speckle
                                .get(i)
                                .and_then(|v| v.get(j))
                                .copied()
                                .unwrap_or(1.0);
                            rate += on.lasers[i][j] * s;
                        }
                        if let Some(g) = prnu.get(j) {
                            rate *= g;
                        }
                        out.push(p.sensor.expose_pixel_with_offset(
                            rate * k * exposure_s,
                            row_offset_e,
                            p.gain,
                            &mut rng,
                        ));
                    }
                    out
                })
                .collect()
        };
    let to_pgm = |data: Vec<u16>| -> Result<Pgm, SimError> {
        let maxval = p.sensor.max_dn();
        let r = if maxval <= 255 {
            Pgm::from_u8(
                w,
                h,
                maxval as u8,
                data.into_iter().map(|v| v as u8).collect(),
            )
        } else {
            Pgm::from_u16(w, h, maxval, data)
        };
        r.map_err(|e| SimError::Capture(e.to_string()))
    };

    let (mut frames, mut entries) = (Vec::new(), Vec::new());
    let mut speckle = speckle_of_pair(0);
    for pair in 0..p.exposure_pairs {
        let streams = pair as u64 * PAIR_STREAMS;
        if pair > 0 && !p.frozen_speckle {
            speckle = speckle_of_pair(pair as u64);
        }
        // Pair 0 keeps the names of a single-pair capture.
        let prefix = if pair == 0 {
            String::new()
        } else {
            format!("p{pair}-")
        };
        frames.push(to_pgm(expose(streams, &[], &off_ambient, &speckle))?);
        entries.push(FrameEntry {
            file: format!("{prefix}off.pgm"),
            lasers_on: vec![],
            pair,
        });
        for (n, set) in frame_sets.iter().enumerate() {
            frames.push(to_pgm(expose(
                streams + 1 + n as u64,
                set,
                &on.ambient,
                &speckle,
            ))?);
            let file = if frame_sets.len() == 1 {
                format!("{prefix}on.pgm")
            } else {
                format!(
                    "{prefix}on-{}.pgm",
                    set.iter()
                        .map(|i| i.to_string())
                        .collect::<Vec<_>>()
                        .join("-")
                )
            };
            entries.push(FrameEntry {
                file,
                lasers_on: set.clone(),
                pair,
            });
        }
    }

    let truth_curve = render::truth_curve(&setup, &p.lit_planes);
    let timestamp = spec
        .timestamp
        .parse::<toml::value::Datetime>()
        .map_err(|e| SimError::Param(format!("timestamp: {e}")))?;
    let calibration = toml::Value::try_from(CalibrationToml::from_calibration(cal))
        .map_err(|e| SimError::Capture(e.to_string()))?;
    let simulation = toml::Value::try_from(p).map_err(|e| SimError::Capture(e.to_string()))?;
    let meta = CaptureMeta {
        format_version: FORMAT_VERSION,
        sensor: p.sensor.name.clone(),
        width: cal.camera.width,
        height: cal.camera.height,
        bit_depth: p.sensor.bit_depth,
        exposure_s,
        gain: p.gain,
        mode: spec.mode,
        timestamp,
        description: spec.description.clone(),
        frames: entries,
        calibration,
        truth: Some(Truth {
            truth_curve: Some("truth-curve.csv".into()),
            objects: spec.objects.clone(),
            // The reference model is left implicit (as in `[simulation]`), so the reference
            // captures' `capture.toml` is what it was before the models existed.
            physics_model: (p.physics != PhysicsModel::Reference).then_some(p.physics),
            gravity: p.accelerometer.as_ref().map(|a| a.gravity_camera),
        }),
        simulation: Some(simulation),
        accelerometer: p.accelerometer.as_ref().map(|a| a.record(p.seed)),
    };
    let capture = Capture {
        meta,
        calibration: cal.clone(),
        frames,
        truth_curve: Some(truth_curve),
        truth_curve_unreadable: None,
    };
    Ok((
        capture,
        SimReport {
            exposure_s,
            electrons_per_w_m2_s: k,
            speckle_cells: cells,
        },
    ))
}
