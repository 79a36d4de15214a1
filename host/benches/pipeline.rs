//! Host benchmarks of the measurement chain on a 752×480 frame pair: the image part alone
//! (`extract_profile`: subtract, threshold, segment, select, subpixel curve, triangulate) and
//! the whole stem measurement (`instrument::measure_with::<Stem>`). The frames come from the simulator (rendered
//! once, outside the timed loop). And the sphere instrument's image part on the corpus's ball
//! beside the aim on a floor, with and without its arcs-before-lines ranking
//! (`pipeline::arcs`), and the whole sphere measurement on two corpus balls. Results:
//! docs/performance.md.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use tangent_core::image::Frame;
use tangent_core::instrument::{
    measure_with, Instrument, Sphere, Stem, Wall, WallInstrumentParams,
};
use tangent_core::pipeline::{extract_profile, OwnedBuffers, PipelineConfig};
use tangent_core::solvers::sphere::SphereParams;
use tangent_core::solvers::stem::CylinderParams;
use tangent_core::Calibration;
use tangent_host::pgm::PgmSamples;
use tangent_host::simulate::{corpus::random_stem, simulate};

/// One 8-bit frame borrowed from a capture.
type Frame8<'a> = Frame<u8, &'a [u8]>;

/// The capture's laser-off and first laser-on frames (8-bit).
fn frames(capture: &tangent_host::capture::Capture) -> (Frame8<'_>, Frame8<'_>) {
    let (off, on) = (
        capture.off_frame(),
        capture.on_frames().next().expect("an on frame").1,
    );
    let (PgmSamples::U8(off_px), PgmSamples::U8(on_px)) = (&off.samples, &on.samples) else {
        panic!("the benchmark expects 8-bit frames");
    };
    let (w, h) = (on.width, on.height);
    (
        Frame::new(&off_px[..], w, h, w).expect("frame"),
        Frame::new(&on_px[..], w, h, w).expect("frame"),
    )
}

/// A capture of the corpus (`tests/captures/<name>`).
fn corpus_capture(name: &str) -> tangent_host::capture::Capture {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/captures")
        .join(name);
    tangent_host::capture::Capture::read(&dir).expect("corpus capture")
}

/// Workspace buffers for a frame pair and its calibration's planes.
fn buffers(frame: &Frame8, cal: &Calibration) -> OwnedBuffers<u8> {
    OwnedBuffers::<u8>::for_frame(frame.width(), frame.height(), 8, cal.planes.len())
}

/// Times `extract_profile` on one frame pair.
fn bench_extract(
    c: &mut Criterion,
    id: &str,
    (off, on): (&Frame8, &Frame8),
    cal: &Calibration,
    config: &PipelineConfig,
    hw: &mut OwnedBuffers<u8>,
) {
    c.bench_function(id, |b| {
        b.iter(|| black_box(extract_profile(off, on, cal, config, &mut hw.workspace())).is_ok())
    });
}

/// Times the whole measurement of instrument `I` on one frame pair.
fn bench_measure<I: Instrument>(
    c: &mut Criterion,
    id: &str,
    (off, on): (&Frame8, &Frame8),
    cal: &Calibration,
    params: &I::Params,
    hw: &mut OwnedBuffers<u8>,
) {
    let config = PipelineConfig::default();
    c.bench_function(id, |b| {
        b.iter(|| {
            black_box(measure_with::<I, u8>(
                off,
                on,
                cal,
                &config,
                params,
                &mut hw.workspace(),
            ))
            .is_ok()
        })
    });
}

fn bench(c: &mut Criterion) {
    // A 30 cm stem at 1.5 m in forest shade, one plane; and a tilted one with two planes.
    for (name, seed, tilt) in [("one_plane", 7u64, 0.0), ("two_planes", 8u64, 20.0)] {
        let spec = random_stem(seed, tilt);
        let (capture, _) = simulate(&spec).expect("simulated capture");
        let cal = capture.calibration.clone();
        let (off_f, on_f) = frames(&capture);
        let mut hw = buffers(&on_f, &cal);
        let id = format!("extract_profile_752x480_{name}");
        bench_extract(
            c,
            &id,
            (&off_f, &on_f),
            &cal,
            &PipelineConfig::default(),
            &mut hw,
        );
        let id = format!("measure_stem_752x480_{name}");
        bench_measure::<Stem>(
            c,
            &id,
            (&off_f, &on_f),
            &cal,
            &CylinderParams::default(),
            &mut hw,
        );
    }
}

fn bench_sphere(c: &mut Criterion) {
    let capture = corpus_capture("sphere-d080-z090-floor-offcentre-2p");
    let cal = capture.calibration.clone();
    let (off_f, on_f) = frames(&capture);
    let mut hw = buffers(&on_f, &cal);
    let with_arcs = Sphere::pipeline_config(&PipelineConfig::default());
    for (name, config) in [
        ("arcs_first", with_arcs),
        (
            "nearest_only",
            PipelineConfig {
                arcs_first: false,
                ..with_arcs
            },
        ),
    ] {
        let id = format!("extract_profile_sphere_floor_{name}");
        bench_extract(c, &id, (&off_f, &on_f), &cal, &config, &mut hw);
    }
    // The whole sphere measurement: a ball read the usual way, and the small ball whose
    // sections miss the axis, read by the joint fit that decides it (`docs/sphere.md`,
    // "Sections that miss the axis").
    for (name, capture_name) in [
        ("floor_offcentre", "sphere-d080-z090-floor-offcentre-2p"),
        ("nearpole", "sphere-d055-z120-nearpole-2p"),
    ] {
        let capture = corpus_capture(capture_name);
        let cal = capture.calibration.clone();
        let (off_f, on_f) = frames(&capture);
        let mut hw = buffers(&on_f, &cal);
        let id = format!("measure_sphere_{name}");
        bench_measure::<Sphere>(
            c,
            &id,
            (&off_f, &on_f),
            &cal,
            &SphereParams::default(),
            &mut hw,
        );
    }
}

/// The whole wall measurement on two corpus captures (two lines, the board calibration):
/// a room's corner and a niche, each with the readings' calibration σ ((B10),
/// `docs/building.md` §4: seven more passes over the walls' points).
fn bench_walls(c: &mut Criterion) {
    for (name, capture_name) in [
        ("corner", "wall-corner-z200"),
        ("niche", "wall-niche-z200-w600-d150"),
    ] {
        let capture = corpus_capture(capture_name);
        let cal = capture.calibration.clone();
        let (off_f, on_f) = frames(&capture);
        let mut hw = buffers(&on_f, &cal);
        bench_measure::<Wall>(
            c,
            &format!("measure_wall_{name}"),
            (&off_f, &on_f),
            &cal,
            &WallInstrumentParams::default(),
            &mut hw,
        );
    }
}

/// `tangent calibrate ball`'s and `wall`'s refinement on six rendered views of the reference
/// ball and of a flat wall (`docs/calibration.md` §12–13), the views measured once with a
/// drawn calibration: the cost of the variable-projection fit alone.
fn bench_ball_refinement(c: &mut Criterion) {
    use tangent_host::calibrate::reference::{refine_planes, ReferenceView};
    use tangent_host::simulate::{simulate, sphere_corpus::reference_ball_spec};
    let noise = tangent_core::noise::NoiseModel {
        focal_px: 0.0,
        ..tangent_core::noise::NoiseModel::reference()
    };
    let truth = tangent_host::simulate::rig::two_plane_calibration();
    let Ok(off) = tangent_host::calibration_draw::drawn(&truth, &noise, 3) else {
        return;
    };
    let views: Vec<ReferenceView> = (0..6)
        .filter_map(|i| simulate(&reference_ball_spec(i, 7)).ok())
        .filter_map(|(capture, _)| ReferenceView::of_ball(&capture, &off, "view").ok())
        .collect();
    c.bench_function("refine_planes_ball_six_views", |b| {
        b.iter(|| refine_planes(&off, &views, &noise, None).map(|f| f.relative_tilt_sigma))
    });
    // The same on six views of a flat wall, three-line head (§13): six plane parameters.
    let truth = tangent_host::simulate::rig::three_plane_calibration();
    let Ok(off) = tangent_host::calibration_draw::drawn(&truth, &noise, 3) else {
        return;
    };
    let views: Vec<ReferenceView> = (0..6)
        .filter_map(|i| {
            simulate(&tangent_host::simulate::wall_corpus::reference_wall_spec(
                i, 7, true,
            ))
            .ok()
        })
        .filter_map(|(capture, _)| ReferenceView::of_wall(&capture, &off, "view").ok())
        .collect();
    c.bench_function("refine_planes_wall_six_views", |b| {
        b.iter(|| refine_planes(&off, &views, &noise, None).map(|f| f.relative_tilt_sigma))
    });
}

/// The combination of four exposures' stem readings ((E7), `docs/error-model.md` §6): what
/// a several-pair reading adds to its pairs' own work. The four are one corpus stem's
/// reading with its diameter moved by ±½σ and ±σ.
fn bench_exposures(c: &mut Criterion) {
    use tangent_core::solvers::stem::combine_exposures;
    let capture = corpus_capture("cyl-d300-z150-shade");
    let cal = capture.calibration.clone();
    let (off_f, on_f) = frames(&capture);
    let mut hw = buffers(&on_f, &cal);
    let Ok(one) = measure_with::<Stem, u8>(
        &off_f,
        &on_f,
        &cal,
        &PipelineConfig::default(),
        &CylinderParams::default(),
        &mut hw.workspace(),
    ) else {
        return;
    };
    let s = one.solution;
    let four = [-1.0, -0.5, 0.5, 1.0].map(|k| tangent_core::solvers::stem::CylinderSolution {
        diameter: s.diameter + k * s.uncertainty,
        ..s
    });
    c.bench_function("combine_exposures_four", |b| {
        b.iter(|| combine_exposures(black_box(&four)).map(|r| r.diameter))
    });
}

criterion_group! {
    name = benches;
    // Criterion's HTML plots need a system font that plotters (built here with the shipped
    // font only) cannot find; the numbers are what we record.
    config = Criterion::default().without_plots();
    targets = bench, bench_sphere, bench_walls, bench_ball_refinement, bench_exposures
}
criterion_main!(benches);
