//! The wall instrument on the committed wall captures (`docs/building.md`).

use std::path::Path;

use tangent_core::pipeline::PipelineConfig;
use tangent_core::solvers::stem::CylinderParams;
use tangent_host::measure::{measure_capture, Solved};

fn captures() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/captures"))
}

#[test]
#[ignore]
fn debug_runs() {
    let name = std::env::var("WALL").unwrap();
    let o = measure_capture(
        &captures().join(&name),
        None,
        &PipelineConfig::default(),
        &CylinderParams::default(),
    )
    .unwrap();
    println!("{}", o.reading.summary());
    if let Ok(Solved::Wall(m)) = &o.result {
        for r in &m.solution.runs {
            let pts = m.profile.points(&o.points, r.curve as usize);
            println!("{:?} {:?} .. {:?}", r, pts[r.start as usize], pts[r.end as usize - 1]);
        }
        for w in &m.solution.walls {
            println!("{:?}", w.plane);
        }
    }
    let m = o.result.as_ref().map(|s| s.profile().plane_points);
    println!("{m:?}");
}
