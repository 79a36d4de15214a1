//! Tests of the image half of the pipeline on rendered frame pairs.
#![allow(clippy::unnecessary_cast)]

extern crate std;
use super::*;
use crate::calibration::Calibration;
use crate::camera::Camera;
use crate::image::Frame;
use crate::laser_plane::LaserPlane;
use std::vec;
use std::vec::Vec;

/// A borrowed 8-bit frame.
pub(crate) type View<'a> = Frame<u8, &'a [u8]>;

pub(crate) const W: usize = 752;
pub(crate) const H: usize = 480;

pub(crate) fn buffers(planes: usize) -> OwnedBuffers<u8> {
    OwnedBuffers::for_frame(W, H, 8, planes)
}

pub(crate) fn calibration(planes: usize) -> Calibration {
    let full = Calibration::reference_design();
    let list: Vec<LaserPlane> = full.planes.iter().copied().take(planes).collect();
    Calibration::new(1, Camera::reference_design(), &list).unwrap()
}

/// The row where `plane` crosses column `u` on a fronto-parallel wall at depth `z`
/// (undistorted reference camera): the ray through (u, v) hits the wall at
/// (x, y) = (u − cx, v − cy)·z/f, and the plane n·X = d gives y analytically.
pub(crate) fn wall_row(cal: &Calibration, plane: usize, u: Real, z: Real) -> Real {
    let cam = &cal.camera;
    let p = cal.planes[plane];
    let x = (u - cam.cx) * z / cam.fx;
    let y = (p.offset - p.normal.x * x - p.normal.z * z) / p.normal.y;
    cam.cy + cam.fy * y / z
}

/// Renders the stripes of the given planes on a wall at depth `z` over columns
/// `cols`: a Gaussian profile integrated over each pixel (erf-free: 8 sub-samples per
/// pixel), amplitude `amp` over an ambient `ambient`.
pub(crate) fn render(
    cal: &Calibration,
    planes: &[usize],
    z: Real,
    cols: core::ops::Range<usize>,
    amp: Real,
    ambient: u8,
) -> (Vec<u8>, Vec<u8>) {
    let off = vec![ambient; W * H];
    let mut on = off.clone();
    let sigma = 1.3;
    for &k in planes {
        for u in cols.clone() {
            let v0 = wall_row(cal, k, u as Real, z);
            for r in 0..H {
                let mut acc = 0.0;
                for s in 0..8 {
                    let y = r as Real - 0.5 + (s as Real + 0.5) / 8.0;
                    acc += (-(y - v0) * (y - v0) / (2.0 * sigma * sigma)).exp();
                }
                let val = on[r * W + u] as Real + amp * acc / 8.0;
                on[r * W + u] = val.round().min(255.0) as u8;
            }
        }
    }
    (off, on)
}

pub(crate) fn frames<'a>(off: &'a [u8], on: &'a [u8]) -> (View<'a>, View<'a>) {
    (
        Frame::new(off, W, H, W).unwrap(),
        Frame::new(on, W, H, W).unwrap(),
    )
}

#[test]
fn wall_points_lie_on_the_wall() {
    let cal = calibration(1);
    let z = 1.2;
    let (off, on) = render(&cal, &[0], z, 150..600, 150.0, 12);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let mut ws = b.workspace();
    let prof = extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap();
    // A stripe the threshold separates is not flagged as faint.
    assert!(!prof.faint);
    let pts = prof.points(ws.points, 0);
    // Every column of the stripe gives a point (the estimator needs the window inside the
    // frame, which holds here).
    assert_eq!(pts.len(), 450);
    // Depth error: the estimator's bias (≤ 0.02 px) plus 8-bit rounding of a 150-level
    // stripe (≈ 0.3/150·σ ≈ 0.003 px) times ∂z/∂v = z²/(e·f) = 14.4 mm/px gives ≤ 0.35 mm.
    let tol = 0.35e-3;
    for p in pts {
        assert!((p.z - z).abs() < tol, "z = {} at x = {}", p.z, p.x);
    }
    // Lateral extent: columns 150 and 599 at depth z.
    let cam = &cal.camera;
    assert!((pts[0].x - (150.0 - cam.cx) * z / cam.fx).abs() < 1e-4);
    assert!(!prof.touches_edge);
    assert_eq!(prof.saturated_points, 0);
}

#[test]
fn two_planes_are_assigned_in_image_order() {
    let cal = calibration(2);
    let z = 0.9;
    let (off, on) = render(&cal, &[0, 1], z, 200..500, 120.0, 5);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(2);
    let mut ws = b.workspace();
    let prof = extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap();
    for k in 0..2 {
        let pts = prof.points(ws.points, k);
        assert_eq!(pts.len(), 300, "plane {k}");
        for p in pts {
            // Points of the right plane triangulate onto the wall; with the planes
            // swapped they would land centimetres away (the planes are 5 cm apart).
            assert!((p.z - z).abs() < 0.5e-3, "plane {k}: z = {}", p.z);
        }
    }
}

#[test]
fn dark_pair_is_no_laser_light() {
    let cal = calibration(1);
    let (off, on) = render(&cal, &[0], 1.0, 100..101, 0.0, 30);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let err = extract_profile(
        &off_f,
        &on_f,
        &cal,
        &PipelineConfig::default(),
        &mut b.workspace(),
    )
    .unwrap_err();
    assert_eq!(err, PipelineError::NoLaserLight { max_difference: 0 });
}

#[test]
fn saturated_ambient_is_reported() {
    let cal = calibration(1);
    let off = vec![255u8; W * H];
    let on = off.clone();
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let cfg = PipelineConfig {
        floors: Floors {
            min_contrast: 0,
            ..Floors::default()
        },
        ..PipelineConfig::default()
    };
    let err = extract_profile(&off_f, &on_f, &cal, &cfg, &mut b.workspace()).unwrap_err();
    assert!(
        matches!(err, PipelineError::AmbientSaturated { .. }),
        "{err:?}"
    );
}

#[test]
fn a_vertical_blob_is_not_a_curve() {
    let cal = calibration(1);
    let off = vec![10u8; W * H];
    let mut on = off.clone();
    for r in 100..300 {
        for c in 370..376 {
            on[r * W + c] = 200;
        }
    }
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let err = extract_profile(
        &off_f,
        &on_f,
        &cal,
        &PipelineConfig::default(),
        &mut b.workspace(),
    )
    .unwrap_err();
    assert_eq!(err, PipelineError::NoCurve);
}

#[test]
fn curve_cut_by_the_frame_edge_is_flagged() {
    let cal = calibration(1);
    let (off, on) = render(&cal, &[0], 1.0, 0..300, 100.0, 10);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let mut ws = b.workspace();
    let prof = extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap();
    assert!(prof.touches_edge);
}

#[test]
fn wrong_sizes_and_small_workspaces_are_errors() {
    let cal = calibration(1);
    let small = vec![0u8; 100 * 100];
    let f = Frame::new(&small, 100, 100, 100).unwrap();
    let mut b = buffers(1);
    let err =
        extract_profile(&f, &f, &cal, &PipelineConfig::default(), &mut b.workspace()).unwrap_err();
    assert_eq!(
        err,
        PipelineError::FrameSizeMismatch {
            calibrated: (752, 480),
            actual: (100, 100)
        }
    );

    let (off, on) = render(&cal, &[0], 1.0, 100..400, 100.0, 10);
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let mut ws = b.workspace();
    ws.points = &mut core::mem::take(&mut ws.points)[..10];
    let err =
        extract_profile(&off_f, &on_f, &cal, &PipelineConfig::default(), &mut ws).unwrap_err();
    assert!(
        matches!(
            err,
            PipelineError::WorkspaceTooSmall {
                buffer: "points",
                ..
            }
        ),
        "{err:?}"
    );
}

/// A dim stripe (12 DN) over noise σ ≈ 0.8 DN passes the noise-relative darkness test
/// (`threshold::Floors::is_lit`); the same noise alone does not.
#[test]
fn contrast_test_is_relative_to_the_noise() {
    let cal = calibration(1);
    let (off, mut on) = render(&cal, &[0], 2.5, 300..450, 12.0, 4);
    // ±1 DN noise on the laser-on frame (σ ≈ 0.8 DN).
    for (i, v) in on.iter_mut().enumerate() {
        let n = ((i * 2_654_435_761usize) >> 7) % 3;
        *v = (*v as i32 + n as i32 - 1).clamp(0, 255) as u8;
    }
    let (off_f, on_f) = frames(&off, &on);
    let mut b = buffers(1);
    let mut ws = b.workspace();
    // With the absolute floor lowered (the default keeps 20 DN, see PipelineConfig), the
    // noise-relative test alone decides: 13 DN over σ̂ < 1 DN is light.
    let cfg = PipelineConfig {
        floors: Floors {
            min_contrast: 8,
            ..Floors::default()
        },
        ..PipelineConfig::default()
    };
    let prof = extract_profile(&off_f, &on_f, &cal, &cfg, &mut ws).unwrap();
    assert!(
        prof.points(ws.points, 0).len() >= 140,
        "{:?}",
        prof.plane_points
    );
    // Pure noise of the same level is dark.
    let (off_f, _) = frames(&off, &on);
    let noisy: Vec<u8> = off
        .iter()
        .enumerate()
        .map(|(i, &v)| (v as i32 + (((i * 2_654_435_761usize) >> 7) % 3) as i32 - 1) as u8)
        .collect();
    let noisy_f = Frame::new(&noisy, W, H, W).unwrap();
    let err = extract_profile(&off_f, &noisy_f, &cal, &cfg, &mut ws).unwrap_err();
    assert!(matches!(err, PipelineError::NoLaserLight { .. }), "{err:?}");
}

/// The streamed front end gives the stored pair's profile whichever way the rows arrive and
/// whether the runs above the threshold come from the candidate runs or, when the candidate
/// table is full, from a rescan of the difference frame; and the labelled runs are those of
/// segmenting the difference frame directly.
#[test]
fn streaming_matches_the_stored_pair() {
    use crate::image::segment::{segment, Connectivity, ObjectFeatures, Run};

    let cal = calibration(2);
    let (off, mut on) = render(&cal, &[0, 1], 0.9, 180..560, 130.0, 9);
    // Specks of noise above the provisional threshold, to give the candidates work.
    for k in 0..400 {
        let i = (k * 7919 + 13) % (W * H);
        on[i] = on[i].saturating_add(9 + (k % 5) as u8);
    }
    let (off_f, on_f) = frames(&off, &on);
    let config = PipelineConfig::default();
    let mut b = buffers(2);
    let mut ws = b.workspace();
    let stored = extract_profile(&off_f, &on_f, &cal, &config, &mut ws).unwrap();
    let points: Vec<_> = ws.points.to_vec();

    // By hand, in blocks of 7 rows (not the replay's 16), with a one-run candidate table:
    // the table overflows on the first specks and `finish` rescans the frame.
    let mut b2 = buffers(2);
    let mut ws2 = b2.workspace();
    let candidates = core::mem::take(&mut ws2.candidate_runs);
    ws2.candidate_runs = &mut candidates[..1];
    ws2.diff[..W * H].copy_from_slice(&off);
    let mut stream = ProfileStream::begin(&mut ws2, &cal, &config, 8).unwrap();
    for block in on.chunks(7 * W) {
        stream.push_rows(&mut ws2, block).unwrap();
    }
    assert_eq!(stream.rows_received(), H);
    let streamed = stream.finish(&mut ws2, &cal, &config).unwrap();
    assert_eq!(streamed, stored);
    assert_eq!(&ws2.points[..points.len()], &points[..]);

    // The labelled runs equal those of the difference frame segmented directly.
    let diff = Frame::new(&ws.diff[..W * H], W, H, W).unwrap();
    let mut runs = vec![Run::ZERO; 8192];
    let mut feats = vec![ObjectFeatures::ZERO; 1024];
    let seg = segment(
        &diff,
        stored.threshold,
        &mut runs,
        &mut feats,
        Connectivity::Eight,
    )
    .unwrap();
    assert_eq!(seg.objects, stored.objects);
    assert_eq!(&feats[..seg.objects], &ws.objects[..seg.objects]);
    assert_eq!(&runs[..seg.runs], &ws.runs[..seg.runs]);

    // A partial row and rows beyond the frame are refused.
    let mut b3 = buffers(2);
    let mut ws3 = b3.workspace();
    let mut stream = ProfileStream::begin(&mut ws3, &cal, &config, 8).unwrap();
    assert!(stream.push_rows(&mut ws3, &on[..W + 1]).is_err());
    stream.push_rows(&mut ws3, &on).unwrap();
    assert!(stream.push_rows(&mut ws3, &on[..W]).is_err());
    // An unfinished frame is refused too.
    let mut b4 = buffers(2);
    let mut ws4 = b4.workspace();
    let mut stream = ProfileStream::begin(&mut ws4, &cal, &config, 8).unwrap();
    stream.push_rows(&mut ws4, &on[..W * 10]).unwrap();
    assert!(matches!(
        stream.finish(&mut ws4, &cal, &config),
        Err(PipelineError::Frame(_))
    ));
}
