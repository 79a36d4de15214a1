//! `tangent simulate`: render synthetic captures (`docs/simulator.md`).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::{Subcommand, ValueEnum};
use rayon::prelude::*;
use tangent_host::capture::{Capture, Mode};
use tangent_host::simulate::corpus::{self, dark, ground, stem, sun, tilted_axis};
use tangent_host::simulate::physics::{self, model_for_seed};
use tangent_host::simulate::render::Lighting;
use tangent_host::simulate::{simulate, SimParams, SimSpec};
use tangent_host::truth::PhysicsModel;

/// Arguments of `tangent simulate`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Subcommand, Debug)]
enum What {
    /// Regenerate the committed corpus (bit for bit): `tangent simulate corpus --out tests/captures`.
    Corpus {
        /// Output directory (one sub-directory per capture).
        #[arg(long)]
        out: PathBuf,
        /// Only these captures (by name); default all.
        #[arg(long)]
        only: Vec<String>,
        /// List the corpus names and descriptions instead of rendering.
        #[arg(long)]
        list: bool,
    },
    /// One stem (cylinder) capture.
    Stem {
        /// Stem diameter (millimetres).
        #[arg(long, default_value_t = 300.0)]
        diameter_mm: f64,
        /// Distance to the stem's front surface on the optical axis (metres).
        #[arg(long, default_value_t = 1.5)]
        distance_m: f64,
        /// Lean from vertical (degrees).
        #[arg(long, default_value_t = 0.0)]
        tilt_deg: f64,
        /// Direction of the lean: 0 right, 90 away, 180 left, 270 towards the camera.
        #[arg(long, default_value_t = 0.0)]
        azimuth_deg: f64,
        /// Use the two-plane device.
        #[arg(long)]
        two_planes: bool,
        /// Ambient light.
        #[arg(long, value_enum, default_value_t = Light::Shade)]
        light: Light,
        /// Random seed (below 2^63).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Physics model (docs/simulator.md §10): a name (`reference`, `oren_nayar_bark`,
        /// `specular_sheen`, `flat_top_sheet`, `defocus`, `coarse_speckle`, `noisy_sensor`,
        /// `mixed`) or `by-seed` (the model `tangent evaluate` gives the seed).
        #[arg(long, default_value = "reference")]
        physics: String,
        /// Output capture directory.
        #[arg(long)]
        out: PathBuf,
    },
    /// Random stems across the envelope (Monte-Carlo / accuracy runs): `<out>/random-<seed>/`.
    Random {
        /// Number of captures.
        #[arg(long, default_value_t = 10)]
        count: u64,
        /// First seed; capture k uses seed + k.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Largest lean (degrees); > 0 uses the two-plane device.
        #[arg(long, default_value_t = 0.0)]
        tilt_max_deg: f64,
        /// Physics model, as for `simulate stem` (`by-seed`: as `tangent evaluate` does).
        #[arg(long, default_value = "reference")]
        physics: String,
        /// Exposure pairs per capture (frame pairs while the trigger is held; `tangent
        /// measure` combines them, `docs/error-model.md` section 6, (E7)).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=16))]
        exposure_pairs: u64,
        /// With --exposure-pairs: the same speckle in every pair.
        #[arg(long)]
        frozen_speckle: bool,
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
    },
    /// Re-render a synthetic capture from its `[simulation]` table, with a new seed.
    Again {
        /// The synthetic capture.
        capture: PathBuf,
        /// New seed.
        #[arg(long)]
        seed: u64,
        /// Output capture directory.
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Light {
    /// Dusk under canopy.
    Dusk,
    /// Forest shade.
    Shade,
    /// Sun through the canopy (30 %).
    Sunfleck,
    /// Full sun.
    Sun,
}

fn write(spec: &SimSpec, out: &std::path::Path) -> anyhow::Result<()> {
    let start = std::time::Instant::now();
    let (capture, report) = simulate(spec)?;
    capture
        .write(out)
        .with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{}: exposure {:.3} ms, {} truth points, {:.2} s",
        out.display(),
        report.exposure_s * 1e3,
        capture.truth_curve.as_ref().map_or(0, Vec::len),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The physics model named by `--physics` for a capture of `seed`.
fn physics_model(name: &str, seed: u64) -> anyhow::Result<PhysicsModel> {
    if name == "by-seed" {
        return Ok(model_for_seed(seed));
    }
    PhysicsModel::from_name(name).with_context(|| {
        format!(
            "--physics {name:?}: not a physics model (by-seed, {})",
            PhysicsModel::ALL.map(|m| m.name()).join(", ")
        )
    })
}

/// Runs `tangent simulate`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    match args.what {
        What::Corpus { out, only, list } => {
            let mut entries = corpus::entries();
            if !only.is_empty() {
                for name in &only {
                    if !entries.iter().any(|e| &e.name == name) {
                        bail!("no corpus capture named {name:?} (see --list)");
                    }
                }
                entries.retain(|e| only.contains(&e.name));
            }
            if list {
                for e in &entries {
                    println!("{}\t{}", e.name, e.spec.description);
                }
                return Ok(ExitCode::SUCCESS);
            }
            for e in &entries {
                write(&e.spec, &out.join(&e.name))?;
            }
            println!("{} captures written to {}", entries.len(), out.display());
        }
        What::Stem {
            diameter_mm,
            distance_m,
            tilt_deg,
            azimuth_deg,
            two_planes,
            light,
            seed,
            physics,
            out,
        } => {
            let calibration = if two_planes {
                corpus::two_plane_calibration()
            } else {
                corpus::one_plane_calibration()
            };
            let lighting = match light {
                Light::Dusk => dark(),
                Light::Shade => Lighting::shade(),
                Light::Sunfleck => sun(0.3),
                Light::Sun => sun(1.0),
            };
            let mut params = SimParams {
                seed,
                lighting,
                ..SimParams::default()
            };
            params.lit_planes = (0..calibration.planes.len()).collect();
            let spec = SimSpec {
                mode: Mode::Cylinder,
                description: format!(
                    "stem {diameter_mm} mm at {distance_m} m, tilt {tilt_deg}° azimuth {azimuth_deg}°"
                ),
                timestamp: "2025-06-03T12:00:00Z".into(),
                calibration,
                objects: vec![
                    stem(diameter_mm, distance_m, 0.0, tilted_axis(tilt_deg, azimuth_deg)),
                    ground(),
                ],
                params,
            };
            let mut spec = spec;
            physics::apply(physics_model(&physics, seed)?, seed, &mut spec);
            write(&spec, &out)?;
        }
        What::Random {
            count,
            seed,
            tilt_max_deg,
            physics,
            exposure_pairs,
            frozen_speckle,
            out,
        } => {
            physics_model(&physics, seed)?;
            (0..count).into_par_iter().try_for_each(|k| {
                let s = seed + k;
                let mut spec = corpus::random_stem(s, tilt_max_deg);
                physics::apply(physics_model(&physics, s)?, s, &mut spec);
                spec.params.exposure_pairs = exposure_pairs as usize;
                spec.params.frozen_speckle = frozen_speckle;
                write(&spec, &out.join(format!("random-{s}")))
            })?;
        }
        What::Again { capture, seed, out } => {
            // A capture's errors name its files relative to it; put the directory in front.
            let c = Capture::read(&capture).with_context(|| capture.display().to_string())?;
            let mut spec = SimSpec::from_capture(&c)?;
            spec.params.seed = seed;
            write(&spec, &out)?;
        }
    }
    Ok(ExitCode::SUCCESS)
}
