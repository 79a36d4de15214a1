//! The objects the pipeline sees in random wall rooms and the planes it gives them
//! (`docs/building.md`, "Niches: fragments assigned by depth agreement"): for each seed, every
//! object of at least `min_pixels` (columns, mean row, pixels) with the depth its centroid
//! triangulates to on each laser plane, which plane's curve its columns ended up in, and the
//! walls and readings of the room.
//!
//! Usage: `niche_fragments SEED [SEED …]` (the two-line head; `evaluate --walls` rooms).
use tangent_core::image::Frame;
use tangent_core::instrument::pipeline_config;
use tangent_core::laser_plane::triangulate;
use tangent_core::measurement::Mode;
use tangent_core::pipeline::{extract_profile, OwnedBuffers, PipelineConfig};
use tangent_core::real::Vec2;
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::evaluate_walls::RANGE_M;
use tangent_host::measure::measure_loaded;
use tangent_host::pgm::PgmSamples;
use tangent_host::simulate::simulate;
use tangent_host::simulate::wall_corpus::{random_room, RoomKind};

fn main() -> anyhow::Result<()> {
    let base = PipelineConfig::default();
    let config = pipeline_config(Mode::Wall, &base);
    for seed in std::env::args()
        .skip(1)
        .filter_map(|a| a.parse::<u64>().ok())
    {
        let (spec, draw) = random_room(seed, RoomKind::of_seed(seed), RANGE_M, false);
        let (capture, _) = simulate(&spec)?;
        println!(
            "seed {seed}: {} at {:.3} m ({})",
            draw.kind.name(),
            draw.distance_m,
            draw.description
        );
        let cal = &capture.calibration;
        let off = capture.off_frame();
        let (_, on) = capture
            .on_frames()
            .find(|(lit, _)| lit.len() == cal.planes.len())
            .ok_or_else(|| anyhow::anyhow!("no frame lights every plane"))?;
        let (PgmSamples::U8(a), PgmSamples::U8(b)) = (&off.samples, &on.samples) else {
            anyhow::bail!("8-bit frames only");
        };
        let (w, h) = (off.width, off.height);
        let mut hw = OwnedBuffers::<u8>::for_frame(w, h, off.bit_depth(), cal.planes.len());
        let offf = Frame::new(&a[..], w, h, w)?.with_bit_depth(off.bit_depth())?;
        let onf = Frame::new(&b[..], w, h, w)?.with_bit_depth(on.bit_depth())?;
        let profile = {
            let mut ws = hw.workspace();
            extract_profile(&offf, &onf, cal, &config, &mut ws)
        };
        let ws = hw.workspace();
        let Ok(profile) = profile else {
            println!("  pipeline: {:?}", profile.err());
            continue;
        };
        let curve = &ws.curve[..];
        for f in ws.objects[..profile.objects]
            .iter()
            .filter(|f| f.pixel_count >= config.selection.min_pixels)
        {
            let (cx, cy) = f.geometric_centroid().unwrap_or_default();
            let depths: Vec<String> = cal
                .planes
                .iter()
                .map(|p| {
                    triangulate(&cal.camera, p, Vec2::new(cx, cy))
                        .map_or("-".into(), |x| format!("{:.3}", x.z))
                })
                .collect();
            // Which plane's curve holds points in this object's columns near its rows.
            let mut planes: Vec<usize> = Vec::new();
            for (k, &(s, e)) in profile
                .plane_points
                .iter()
                .enumerate()
                .take(cal.planes.len())
            {
                if curve[s..e].iter().any(|c| {
                    c.column >= f.min_x
                        && c.column <= f.max_x
                        && c.row >= f.min_y as f64 - 1.0
                        && c.row <= f.max_y as f64 + 1.0
                }) {
                    planes.push(k);
                }
            }
            println!(
                "  object {:3}: cols {:3}–{:3} rows {:3}–{:3} mean row {:6.1} px {:5}  z on planes [{}]  in curve of {:?}",
                f.label,
                f.min_x,
                f.max_x,
                f.min_y,
                f.max_y,
                cy,
                f.pixel_count,
                depths.join(", "),
                planes
            );
        }
        let out = measure_loaded(
            &capture,
            &format!("seed {seed}"),
            None,
            &base,
            &CylinderParams::default(),
        )?;
        match (&out.reading.wall, &out.reading.error) {
            (Some(wr), _) => println!("  {}", serde_json::to_string(wr)?),
            (None, e) => println!("  no reading: {e:?}"),
        }
    }
    Ok(())
}
