//! The crossing laser line (`docs/building.md`, "The crossing line: extraction"): a laser
//! plane whose line runs down the image (nearly vertical where lines 0 and 1 run across it)
//! is fired alone in its own exposure and extracted **row by row** — by the column-wise
//! pipeline itself, run on the transposed frame pair with the transposed calibration.
//!
//! Transposing the image swaps `u ↔ v`; the pinhole and distortion model is the same with
//! `fx ↔ fy`, `cx ↔ cy`, `p1 ↔ p2`, and a camera-frame point `(x, y, z)` becomes `(y, x, z)`,
//! so a plane `n·X = d` becomes `(n_y, n_x, n_z)·X' = d`. The transposed plane of a
//! vertical fan is a horizontal fan's: every step of the pipeline (peaks per column, curve,
//! triangulation, each point's σ) applies unchanged, and the stem pipeline is not touched.

use crate::calibration::Calibration;
use crate::camera::Camera;
use crate::laser_plane::LaserPlane;
use crate::real::Vec3;

use super::PipelineError;

/// A laser plane whose line runs down the image (the crossing line), extracted row by row:
/// [`LaserPlane::is_row_wise`].
pub fn is_row_wise(plane: &LaserPlane) -> bool {
    plane.is_row_wise()
}

/// `(x, y, z) → (y, x, z)`: a camera-frame vector in the transposed image's frame and back.
pub fn swap_xy(v: Vec3) -> Vec3 {
    Vec3::new(v.y, v.x, v.z)
}

/// `plane` seen from the transposed camera.
pub fn transposed_plane(plane: &LaserPlane) -> LaserPlane {
    LaserPlane {
        normal: swap_xy(plane.normal),
        offset: plane.offset,
        source: swap_xy(plane.source),
    }
}

/// The camera of the transposed image.
pub fn transposed_camera(camera: &Camera) -> Camera {
    let mut t = *camera;
    t.width = camera.height;
    t.height = camera.width;
    t.fx = camera.fy;
    t.fy = camera.fx;
    t.cx = camera.cy;
    t.cy = camera.cx;
    t.distortion.p1 = camera.distortion.p2;
    t.distortion.p2 = camera.distortion.p1;
    t
}

/// The calibration for extracting plane `plane` of `calibration` from the transposed frame
/// pair: the transposed camera and that plane alone (as plane 0). `Calibration` when there is
/// no such plane.
pub fn transposed_calibration(
    calibration: &Calibration,
    plane: usize,
) -> Result<Calibration, PipelineError> {
    let p = calibration
        .plane(plane)
        .map_err(|_| PipelineError::Calibration)?;
    let mut planes = heapless::Vec::new();
    planes
        .push(transposed_plane(p))
        .map_err(|_| PipelineError::Calibration)?;
    Ok(Calibration {
        id: calibration.id,
        camera: transposed_camera(&calibration.camera),
        planes,
        // The transposed plane is one plane out of several: its own share of the covariance
        // is not kept, and the board budget (the larger) stands.
        uncertainty: None,
    })
}

/// Writes the transpose of the `width` × `height` image `src` (row-major) into `dst`
/// (`height` × `width`, row-major): `dst[u·height + v] = src[v·width + u]`.
/// `FrameSizeMismatch` (`(width, height)` against the two slices' lengths) when either slice
/// is not `width·height` long.
pub fn transpose_frame<P: Copy>(
    src: &[P],
    width: usize,
    height: usize,
    dst: &mut [P],
) -> Result<(), PipelineError> {
    let n = width.saturating_mul(height);
    if src.len() != n || dst.len() != n {
        return Err(PipelineError::FrameSizeMismatch {
            calibrated: (width as u32, height as u32),
            actual: (src.len(), dst.len()),
        });
    }
    // Blocks of 16 × 16 keep both sides in cache.
    const B: usize = 16;
    for v0 in (0..height).step_by(B) {
        for u0 in (0..width).step_by(B) {
            for v in v0..(v0 + B).min(height) {
                for u in u0..(u0 + B).min(width) {
                    dst[u * height + v] = src[v * width + u];
                }
            }
        }
    }
    Ok(())
}

/// Brings the crossing line's points back from the transposed frame: swaps `x ↔ y` of each.
pub fn untranspose_points(points: &mut [Vec3]) {
    for p in points {
        *p = swap_xy(*p);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::reference_crossing_plane;

    #[test]
    fn the_crossing_plane_is_row_wise_and_the_parallel_ones_are_not() {
        let c = Calibration::reference_design();
        assert!(c.planes.iter().all(|p| !is_row_wise(p)));
        let x = reference_crossing_plane().unwrap();
        assert!(is_row_wise(&x));
        // Transposed, it is a horizontal fan: column-wise, like plane 0 (same baseline and
        // tilt).
        let t = transposed_plane(&x);
        assert!(!is_row_wise(&t));
        assert!((t.normal - c.planes[0].normal).norm() < 1e-6);
        assert!((t.offset - c.planes[0].offset).abs() < 1e-6);
    }

    #[test]
    fn a_point_projects_to_the_swapped_pixel_in_the_transposed_camera() {
        let mut cam = Calibration::reference_design().camera;
        cam.distortion.k1 = -0.1;
        cam.distortion.p1 = 1e-3;
        cam.distortion.p2 = -2e-3;
        cam.fx = 1010.0;
        let t = transposed_camera(&cam);
        let p = Vec3::new(0.21, -0.13, 1.7);
        let a = cam.project(p).unwrap();
        let b = t.project(swap_xy(p)).unwrap();
        let (u, v, ut, vt) = (a.x, a.y, b.x, b.y);
        assert!(
            (u - vt).abs() < 1e-6 && (v - ut).abs() < 1e-6,
            "{u} {v} / {ut} {vt}"
        );
    }

    #[test]
    fn transposing_twice_gives_the_frame_back() {
        let (w, h) = (37usize, 21usize);
        let src: heapless::Vec<u16, 777> = (0..(w * h) as u16).collect();
        let mut t = [0u16; 777];
        let mut back = [0u16; 777];
        transpose_frame(&src, w, h, &mut t).unwrap();
        assert_eq!(t[5 * h + 3], src[3 * w + 5]);
        transpose_frame(&t, h, w, &mut back).unwrap();
        assert_eq!(&back[..], &src[..]);
        assert!(transpose_frame(&src, w, h + 1, &mut t).is_err());
    }
}
