//! `tangent accuracy`: the error model's predicted diameter uncertainty against distance,
//! one line per stem diameter and method, as a PNG (thesis chapter 7; `docs/error-model.md`).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::anyhow;
use plotters::prelude::*;
use tangent_core::calibration::Calibration;
use tangent_core::error_model::{predict_diameter_sigma, StemGeometry};
use tangent_core::noise::NoiseModel;
use tangent_core::real::Vec2;
use tangent_host::{calibration_file, plot};

/// The long help of `tangent accuracy` (`main.rs` gives it to clap on the subcommand, where
/// the short doc comment would otherwise replace it).
pub const LONG_ABOUT: &str = "Plots the error model's predicted 1-sigma diameter error (mm) of a \
transversal stem against its distance (m), for several diameters, for the three-tangent method \
(solid) and the circle fit (dashed), with the reference noise model (subpixel noise, speckle, \
calibration errors). Also prints the table of the plotted values.";

/// Arguments of `tangent accuracy`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Calibration file (default: the reference design, one plane).
    #[arg(long, value_name = "FILE")]
    calib: Option<PathBuf>,
    /// Output PNG.
    #[arg(long, default_value = "accuracy.png")]
    out: PathBuf,
    /// Diameters to plot (millimetres).
    #[arg(
        long,
        value_delimiter = ',',
        value_parser = parse_diameter_mm,
        default_values_t = vec![50.0, 100.0, 200.0, 400.0, 800.0]
    )]
    diameters_mm: Vec<f64>,
}

/// Predicted σ (metres) of both methods for a stem of `d` at in-plane distance `z`.
fn predict(cal: &Calibration, d: f64, z: f64, scratch: &mut [Vec2]) -> (Option<f64>, Option<f64>) {
    let Some(plane) = cal.planes.first() else {
        return (None, None);
    };
    match predict_diameter_sigma(
        plane,
        &cal.camera,
        &StemGeometry {
            distance: z,
            diameter: d,
        },
        &NoiseModel::reference(),
        scratch,
    ) {
        Ok(p) => (
            p.three_tangent.map(|m| m.total),
            p.circle_fit.map(|m| m.total),
        ),
        Err(_) => (None, None),
    }
}

/// Diameters a stem can have (mm): the error model is meaningful from a sapling to the
/// largest trees measured with a caliper.
const DIAMETER_RANGE_MM: (f64, f64) = (1.0, 10_000.0);

/// A diameter in millimetres, finite and within [`DIAMETER_RANGE_MM`] (`NaN`, `0` or
/// `1e300` would plot nothing meaningful, or nothing at all).
fn parse_diameter_mm(text: &str) -> Result<f64, String> {
    let (lo, hi) = DIAMETER_RANGE_MM;
    let value: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number"))?;
    if !(lo..=hi).contains(&value) {
        return Err(format!("{value} mm is outside {lo}..{hi} mm"));
    }
    Ok(value)
}

/// Runs `tangent accuracy`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let cal = match &args.calib {
        // The error names the file.
        Some(p) => calibration_file::read(p)?,
        None => Calibration::reference_design(),
    };
    let mut scratch = vec![Vec2::zeros(); 2 * cal.camera.width as usize];
    let distances: Vec<f64> = (0..=50).map(|i| 0.5 + 2.5 * i as f64 / 50.0).collect();
    let mut series = Vec::new();
    let mut y_max: f64 = 1.0;
    for &d_mm in &args.diameters_mm {
        let mut tt = Vec::new();
        let mut fit = Vec::new();
        for &z in &distances {
            let (a, b) = predict(&cal, d_mm * 1e-3, z, &mut scratch);
            if let Some(a) = a {
                tt.push((z, a * 1e3));
            }
            if let Some(b) = b {
                fit.push((z, b * 1e3));
            }
        }
        y_max = y_max.max(tt.iter().chain(&fit).map(|p| p.1).fold(0.0, f64::max));
        series.push((d_mm, tt, fit));
    }
    let y_max = y_max.min(20.0);

    plot::init_fonts();
    // Plotters reports the file's failure without its name.
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", args.out.display());
    let root = BitMapBackend::new(&args.out, (1000, 650)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .margin(15)
        .caption(
            "Predicted 1σ diameter error (error model, reference noise)",
            ("sans-serif", 22),
        )
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.5f64..3.0f64, 0f64..y_max)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("distance from the laser to the stem (m)")
        .y_desc("1σ of the diameter (mm)")
        .draw()
        .map_err(|e| err(&e))?;
    for (i, (d_mm, tt, fit)) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                tt.iter().map(|&(z, s)| (z, s.min(y_max))),
                colour.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(format!("{d_mm:.0} mm, three-tangent"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(DashedLineSeries::new(
                fit.iter().map(|&(z, s)| (z, s.min(y_max))),
                6,
                4,
                colour.stroke_width(1),
            ))
            .map_err(|e| err(&e))?
            .label(format!("{d_mm:.0} mm, circle fit"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(1))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;

    println!("predicted 1σ of the diameter (mm): three-tangent / circle fit");
    print!("{:>8}", "z (m)");
    for d in &args.diameters_mm {
        print!("{:>16}", format!("{d:.0} mm"));
    }
    println!();
    for &z in &[0.5, 1.0, 1.5, 2.0, 2.5, 3.0] {
        print!("{z:>8.1}");
        for &d_mm in &args.diameters_mm {
            let (a, b) = predict(&cal, d_mm * 1e-3, z, &mut scratch);
            let f = |v: Option<f64>| {
                v.map(|v| format!("{:.2}", v * 1e3))
                    .unwrap_or_else(|| "–".into())
            };
            print!("{:>16}", format!("{} / {}", f(a), f(b)));
        }
        println!();
    }
    eprintln!("wrote {}", args.out.display());
    Ok(ExitCode::SUCCESS)
}
