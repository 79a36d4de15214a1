// Temporary diagnostic (not committed).
use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::measure::{measure_loaded, Solved};
use tangent_host::simulate::simulate;
use tangent_host::simulate::wall_corpus::{random_room, RoomKind};

fn main() -> anyhow::Result<()> {
    let seed: u64 = std::env::args().nth(1).unwrap().parse()?;
    let crossing = std::env::args().nth(2).is_some();
    let (spec, _draw) = random_room(seed, RoomKind::of_seed(seed), (0.5, 5.0), crossing);
    let (capture, _) = simulate(&spec)?;
    let outcome = measure_loaded(
        &capture,
        "dbg",
        None,
        &PipelineConfig::default(),
        &CylinderParams::default(),
    )?;
    let Ok(Solved::Wall(m)) = &outcome.result else {
        anyhow::bail!("no wall")
    };
    let s = &m.solution;
    let f = 1000.0; // printed columns approximate
    let _ = f;
    println!("aimed {} walls {}", s.aimed, s.walls.len());
    for (i, w) in s.walls.iter().enumerate() {
        println!(
            "wall {i}: n {:?} off {:.4}",
            w.plane.normal.as_slice(),
            w.plane.offset
        );
    }
    for r in s.runs.iter() {
        println!(
            "run curve {} {}..{} wall {:?}",
            r.curve, r.start, r.end, r.wall
        );
    }
    if std::env::var("RUNS").is_ok() {
        for r in s.runs.iter().filter(|r| r.wall.is_none()) {
            let pts = m.profile.points(&outcome.points, r.curve as usize);
            let cps = m.profile.points(&outcome.curve, r.curve as usize);
            for i in r.start as usize..r.end as usize {
                let w = &s.walls[s.aimed].plane;
                println!(
                    "  free {} {i} col {} amp {:.1} d_aimed {:+.2} mm",
                    r.curve,
                    cps[i].column,
                    cps[i].amplitude,
                    (w.normal.dot(&pts[i]) - w.offset) * 1e3
                );
            }
        }
    }
    if let Some(g) = &s.segment {
        println!(
            "segment curve {} kinds {:?} len {:.2} mm ± {:.2}",
            g.curve,
            g.kinds,
            g.length.value * 1e3,
            g.length.sigma * 1e3
        );
        for e in g.ends {
            println!("  end {:?}", e.as_slice());
        }
        let pts = m.profile.points(&outcome.points, g.curve);
        let cps = m.profile.points(&outcome.curve, g.curve);
        for (i, (p, c)) in pts.iter().zip(cps).enumerate() {
            if std::env::var("ALLPTS").is_ok()
                || i < 2
                || (i >= 140 && i <= 156)
                || (i >= 545 && i <= 560)
            {
                println!(
                    "  pt {i} col {} row {:.2} amp {:.1} w {:.2} xyz {:?}",
                    c.column,
                    c.row,
                    c.amplitude,
                    c.width,
                    p.as_slice()
                );
            }
        }
    }
    if let Some(tc) = &capture.truth_curve {
        let g = s.segment.as_ref().unwrap();
        let mut last = None;
        for p in tc.iter().filter(|p| p.plane == g.curve) {
            if last != Some(p.object) {
                println!(
                    "truth col {} obj {} row {:.2} xyz {:?}",
                    p.column, p.object, p.row_px, p.point_m
                );
                last = Some(p.object);
            }
        }
    }
    println!("{}", serde_json::to_string(&outcome.reading)?);
    Ok(())
}
