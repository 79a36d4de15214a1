//! Selection of the laser-curve object(s) among the segmented objects (thesis §5.6; criteria
//! and default values derived in `docs/image-processing.md`, section "Object selection").
//!
//! Three criteria, applied in the thesis's order:
//!
//! 1. **Amount of pixels** (§5.6.1): objects of fewer than `min_pixels` pixels are speckle,
//!    noise or tiny ambient changes.
//! 2. **Height-to-width ratio** (§5.6.2): the ratio of the bounding box must lie in
//!    `[min_height_to_width, max_height_to_width]`. In Tangent's images the laser plane is
//!    horizontal and crosses a vertical trunk, so the curve is *wide and short* (ratio ≪ 1),
//!    while clutter that changed between the two exposures (a swaying twig, a leaf edge) is
//!    tall or compact. The defaults therefore eliminate objects with a **high** ratio. The
//!    thesis's Fig. 5.10 eliminates objects with a **low** ratio: its camera sees the laser
//!    curve running along the columns (rotated 90° with respect to Tangent). Both are
//!    expressible with the two bounds.
//! 3. **Distance from the central column** (§5.6.3): the user aims the instrument at the trunk,
//!    so the object nearest the image's central column is kept. The distance is measured from
//!    the central column to the object's bounding box (zero when the object straddles it), so
//!    that a long curve crossing the centre is never beaten by a short blob whose centroid
//!    happens to be nearer. Ties go to the larger object, then to the lower label.

use super::segment::ObjectFeatures;
use crate::real::Real;

/// Parameters of [`select`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectionParams {
    /// Minimum pixel count of a candidate (thesis's `N_pix`).
    pub min_pixels: u32,
    /// Minimum bounding-box height-to-width ratio (0 disables the lower bound).
    pub min_height_to_width: Real,
    /// Maximum bounding-box height-to-width ratio (`Real::INFINITY` disables the upper bound).
    pub max_height_to_width: Real,
    /// How many objects to keep, nearest to the central column first (1 in the thesis; 2 for
    /// a two-plane instrument, or more to keep the pieces of a curve broken by bark texture).
    pub max_objects: usize,
}

impl Default for SelectionParams {
    /// Defaults for the reference hardware (MT9V034, 752×480, 6 µm pixels, 6 mm lens, so
    /// f ≈ 1000 px; trunks 5–100 cm at 0.5–3 m), derived in docs/image-processing.md:
    /// - `min_pixels = 16`: the smallest curve (5 cm trunk at 3 m) is ≈ 17 px wide and ≥ 2 px
    ///   thick, ≈ 34 px; half of it leaves margin for a curve broken in two.
    /// - `max_height_to_width = 1.0`: curves across trunks have ratios ≈ 0.1–0.4 (the largest
    ///   for a 1 m trunk at 0.5 m); a ratio above 1 is a vertical object, not the curve.
    /// - `min_height_to_width = 0.0` (disabled), `max_objects = 1` (thesis: one object kept).
    fn default() -> Self {
        SelectionParams {
            min_pixels: 16,
            min_height_to_width: 0.0,
            max_height_to_width: 1.0,
            max_objects: 1,
        }
    }
}

/// What [`select`] did, for diagnostics and for the pipeline's "reading not trustworthy"
/// decisions (e.g. many rejected objects = cluttered scene).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SelectionReport {
    /// Objects examined.
    pub examined: usize,
    /// Objects eliminated by the pixel-count criterion.
    pub too_small: usize,
    /// Objects eliminated by the height-to-width criterion.
    pub bad_ratio: usize,
    /// Objects that passed both criteria (candidates for the distance criterion).
    pub candidates: usize,
    /// Labels written to the output (`min(candidates, max_objects, out.len())`).
    pub selected: usize,
}

/// Whether `f` passes the pixel-count criterion (thesis §5.6.1).
pub fn passes_pixel_count(f: &ObjectFeatures, min_pixels: u32) -> bool {
    f.pixel_count >= min_pixels
}

/// Whether `f` passes the height-to-width criterion (thesis §5.6.2):
/// `min <= height / width <= max`. A NaN bound rejects every object.
pub fn passes_height_to_width(f: &ObjectFeatures, min: Real, max: Real) -> bool {
    let r = f.height_to_width_ratio();
    r >= min && r <= max
}

/// Distance in **half pixels** from the central column `(width - 1) / 2` to the object's
/// bounding box `[min_x, max_x]` (0 if the box straddles the central column). Integers keep
/// the comparison exact: twice the central column is the integer `width - 1`.
pub fn central_column_distance_half_px(f: &ObjectFeatures, frame_width: usize) -> u64 {
    let c2 = frame_width.saturating_sub(1) as u64;
    let lo2 = 2 * f.min_x as u64;
    let hi2 = 2 * f.max_x as u64;
    if lo2 > c2 {
        lo2 - c2
    } else {
        // 0 when the box straddles the central column (hi2 >= c2).
        c2.saturating_sub(hi2)
    }
}

/// Distance in pixels from the central column to the object's bounding box (see
/// [`central_column_distance_half_px`]).
pub fn central_column_distance(f: &ObjectFeatures, frame_width: usize) -> Real {
    central_column_distance_half_px(f, frame_width) as Real * 0.5
}

/// Sort key of the distance criterion: nearer first, then larger, then lower label.
fn rank(f: &ObjectFeatures, frame_width: usize) -> (u64, core::cmp::Reverse<u32>, u16) {
    (
        central_column_distance_half_px(f, frame_width),
        core::cmp::Reverse(f.pixel_count),
        f.label,
    )
}

/// The feature entry of `label`: `features[label - 1]` when the table is compact (as written
/// by [`segment`](super::segment::segment)), otherwise a linear search.
fn feature_of(features: &[ObjectFeatures], label: u16) -> Option<&ObjectFeatures> {
    match features.get((label as usize).wrapping_sub(1)) {
        Some(f) if f.label == label => Some(f),
        _ => features.iter().find(|f| f.label == label),
    }
}

/// Applies the three criteria of thesis §5.6 to `features` (objects of a frame
/// `frame_width` pixels wide) and writes the labels of the kept objects into `out`, nearest to
/// the central column first. At most `min(params.max_objects, out.len())` labels are written;
/// the report says how many and why the others were eliminated.
///
/// Cost: `O(n·k)` for `n` objects and `k` kept (an insertion into the short sorted output).
pub fn select(
    features: &[ObjectFeatures],
    frame_width: usize,
    params: &SelectionParams,
    out: &mut [u16],
) -> SelectionReport {
    let keep = params.max_objects.min(out.len());
    let mut report = SelectionReport {
        examined: features.len(),
        ..Default::default()
    };
    for f in features {
        if !passes_pixel_count(f, params.min_pixels) {
            report.too_small += 1;
            continue;
        }
        if !passes_height_to_width(f, params.min_height_to_width, params.max_height_to_width) {
            report.bad_ratio += 1;
            continue;
        }
        report.candidates += 1;
        if keep == 0 {
            continue;
        }
        // Insertion into out[..selected], kept sorted by rank; the worst falls off the end.
        let key = rank(f, frame_width);
        let n = report.selected;
        let pos = out
            .iter()
            .take(n)
            .position(|&l| feature_of(features, l).is_none_or(|g| key < rank(g, frame_width)))
            .unwrap_or(n);
        if pos >= keep {
            continue;
        }
        let end = if n < keep { n + 1 } else { keep };
        if let Some(window) = out.get_mut(pos..end) {
            window.rotate_right(1);
            if let Some(first) = window.first_mut() {
                *first = f.label;
            }
        }
        report.selected = end;
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obj(label: u16, x: (u16, u16), y: (u16, u16), pixels: u32) -> ObjectFeatures {
        let mut f = ObjectFeatures::empty(label);
        f.min_x = x.0;
        f.max_x = x.1;
        f.min_y = y.0;
        f.max_y = y.1;
        f.pixel_count = pixels;
        f
    }

    #[test]
    fn pixel_count_criterion() {
        let feats = [
            obj(1, (370, 374), (10, 10), 5),
            obj(2, (300, 315), (10, 10), 16),
            obj(3, (10, 50), (10, 11), 60),
        ];
        let params = SelectionParams {
            max_objects: 3,
            ..Default::default()
        };
        let mut out = [0u16; 3];
        let r = select(&feats, 752, &params, &mut out);
        assert_eq!((r.too_small, r.candidates, r.selected), (1, 2, 2));
        // 2 is nearer the central column (375.5) than 3.
        assert_eq!(&out[..2], &[2, 3]);
    }

    #[test]
    fn ratio_criterion_both_orientations() {
        // A wide, short curve (ratio 8/300) and a tall twig (ratio 60/4), both straddling.
        let curve = obj(1, (220, 519), (200, 207), 900);
        let twig = obj(2, (374, 377), (100, 159), 200);
        let feats = [curve, twig];
        let mut out = [0u16; 2];
        let r = select(&feats, 752, &SelectionParams::default(), &mut out);
        assert_eq!((r.bad_ratio, r.selected, out[0]), (1, 1, 1));
        // The thesis's orientation (curve along the columns): eliminate low ratios instead.
        let thesis = SelectionParams {
            min_height_to_width: 1.0,
            max_height_to_width: Real::INFINITY,
            ..Default::default()
        };
        let r = select(&feats, 752, &thesis, &mut out);
        assert_eq!((r.bad_ratio, r.selected, out[0]), (1, 1, 2));
        // Boundary: ratio exactly 1 is kept by max = 1.
        let square = [obj(7, (0, 9), (0, 9), 100)];
        assert_eq!(
            select(&square, 752, &SelectionParams::default(), &mut out).selected,
            1
        );
    }

    #[test]
    fn nearest_to_central_column() {
        // Width 752: central column 375.5 (half-px 751).
        let left = obj(1, (100, 300), (50, 52), 400); // 75.5 px away
        let right = obj(2, (420, 700), (60, 62), 500); // 44.5 px away
        let far_right = obj(3, (380, 390), (70, 71), 30); // 4.5 px away
        assert_eq!(central_column_distance(&left, 752), 75.5);
        assert_eq!(central_column_distance(&right, 752), 44.5);
        let feats = [left, right, far_right];
        let mut out = [0u16; 3];
        let p = SelectionParams {
            max_objects: 3,
            ..Default::default()
        };
        assert_eq!(select(&feats, 752, &p, &mut out).selected, 3);
        assert_eq!(out, [3, 2, 1]);
        // Only one kept by default, and only out.len() written.
        let mut one = [0u16; 1];
        assert_eq!(
            select(&feats, 752, &SelectionParams::default(), &mut one).selected,
            1
        );
        assert_eq!(one, [3]);
        let r = select(&feats, 752, &p, &mut one);
        assert_eq!((r.candidates, r.selected, one), (3, 1, [3]));
        // Two objects straddling the centre (two laser planes): the larger one first.
        let a = obj(1, (300, 450), (100, 104), 600);
        let b = obj(2, (200, 500), (300, 306), 1500);
        let mut two = [0u16; 2];
        select(&[a, b], 752, &p, &mut two);
        assert_eq!(two, [2, 1]);
        // Odd width: central column 2 of 5 is exactly a pixel centre.
        assert_eq!(central_column_distance(&obj(1, (2, 2), (0, 0), 1), 5), 0.0);
        assert_eq!(central_column_distance(&obj(1, (0, 1), (0, 0), 1), 5), 1.0);
    }

    /// The whole chain of this module family on a synthetic reference-size frame pair
    /// (752×480, 8-bit): ambient texture with sensor noise in both frames, a laser arc (Gaussian
    /// profile, σ = 1.5 px, amplitude 150) across columns 126..=625 in the ON frame only, a tall
    /// ambient change (a swaying twig) and isolated speckle-like dots. Ground truth: the
    /// selected object is the arc, whose columns are known. Performance sanity only (timings
    /// are printed with `--nocapture`, not asserted).
    #[test]
    fn full_frame_chain_752x480() {
        extern crate std;
        use crate::image::filter::{gaussian_filter, scratch_len, GaussianKernel};
        use crate::image::segment::{segment, Connectivity, Run};
        use crate::image::subtract::subtract;
        use crate::image::threshold::{histogram, otsu_threshold};
        use crate::image::Frame;
        use std::vec;

        let (w, h) = (752usize, 480usize);
        let mut seed: u32 = 7;
        let mut noise = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 29) as i32 - 4 // uniform in -4..=3
        };
        let mut off = vec![0u8; w * h];
        let mut on = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let ambient = 40 + ((x * 7 + y * 3) % 80) as i32; // bark-like texture
                off[y * w + x] = (ambient + noise()).clamp(0, 255) as u8;
                let mut lit = ambient as f64;
                if (126..=625).contains(&x) {
                    let u = (x as f64 - 375.5) / 250.0;
                    let centre = 240.0 + 40.0 * (1.0 - u * u).max(0.0).sqrt();
                    let d = (y as f64 - centre) / 1.5;
                    lit += 150.0 * (-0.5 * d * d).exp();
                }
                if (98..=101).contains(&x) && (100..160).contains(&y) {
                    lit += 90.0; // twig: 4 px wide, 60 px tall
                }
                if x % 97 == 13 && y % 53 == 11 {
                    lit += 80.0; // isolated dots
                }
                on[y * w + x] = (lit.round() as i32 + noise()).clamp(0, 255) as u8;
            }
        }

        let t0 = std::time::Instant::now();
        let fon = Frame::new(&on, w, h, w).unwrap();
        let foff = Frame::new(&off, w, h, w).unwrap();
        let mut diff = vec![0u8; w * h];
        let mut fd = Frame::new(&mut diff, w, h, w).unwrap();
        let stats = subtract(&fon, &foff, &mut fd).unwrap();
        let t_sub = t0.elapsed();
        assert!(stats.max_difference >= 140);

        let fd = Frame::new(&diff, w, h, w).unwrap();
        let mut bins = [0u32; 256];
        histogram(&fd, &mut bins).unwrap();
        let t = otsu_threshold(&bins).unwrap();
        // Noise differences reach 7; the laser peak is ~150: the threshold lies between.
        assert!(t > 7 && t < 140, "t = {t}");
        let t_thr = t0.elapsed();

        let mut runs = vec![Run::ZERO; 4096];
        let mut feats = [ObjectFeatures::empty(0); 256];
        let seg = segment(&fd, t, &mut runs, &mut feats, Connectivity::Eight).unwrap();
        let t_seg = t0.elapsed();

        let mut out = [0u16; 1];
        let r = select(
            &feats[..seg.objects],
            w,
            &SelectionParams::default(),
            &mut out,
        );
        assert_eq!(r.selected, 1);
        let arc = feats[out[0] as usize - 1];
        assert_eq!((arc.min_x, arc.max_x), (126, 625));
        // The arc's crest (v = 280 at the centre) and ends (v = 240) with ±2σ of thickness.
        assert!(arc.min_y >= 236 && arc.max_y <= 284, "{arc:?}");
        assert!(r.too_small >= 1 && r.bad_ratio >= 1, "{r:?}");

        let mut smooth = vec![0u8; w * h];
        let mut fs = Frame::new(&mut smooth, w, h, w).unwrap();
        let mut scratch = vec![0u32; scratch_len(w)];
        gaussian_filter(
            &fd,
            &GaussianKernel::new(1.0).unwrap(),
            &mut scratch,
            &mut fs,
        )
        .unwrap();
        let t_filt = t0.elapsed();
        std::println!(
            "752x480 u8: subtract {:?}, histogram+otsu {:?}, segment {:?}, gaussian σ=1 {:?}; \
             threshold {t}, {} objects, {} runs",
            t_sub,
            t_thr - t_sub,
            t_seg - t_thr,
            t_filt - t_seg,
            seg.objects,
            seg.runs
        );
    }

    #[test]
    fn nothing_to_select() {
        let mut out = [0u16; 1];
        assert_eq!(
            select(&[], 752, &SelectionParams::default(), &mut out).selected,
            0
        );
        let nan = SelectionParams {
            max_height_to_width: Real::NAN,
            ..Default::default()
        };
        let feats = [obj(1, (0, 99), (0, 1), 200)];
        let r = select(&feats, 752, &nan, &mut out);
        assert_eq!((r.bad_ratio, r.selected), (1, 0));
    }
}
