//! Sphere mode's aim: arcs before lines (`docs/pipeline.md`, "Arcs before lines"; derivation
//! `docs/sphere.md`, "A floor under the ball").
//!
//! A laser plane draws a straight line on a flat surface in the undistorted image (a plane
//! cut by a plane is a line, and a pinhole maps lines to lines), while its section of a ball
//! is a circle off the camera's centre, seen as an ellipse's arc whose sagitta is the
//! ellipse's semi-minor axis `≈ r·e·f/z²` (`e` the camera's distance from the laser plane):
//! 2.5 px for a 50 mm ball at 1 m. The object nearest the central column is the aimed one
//! ([`crate::image::select`]); on a floor, a ball beside the central column loses that rank
//! to the floor's line and the solver is handed straight sections. In sphere mode the
//! candidates whose pixels bend significantly are therefore ranked before the straight ones.

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{sqrt, Mat3, Real, Vec2, Vec3};

use crate::calibration::Calibration;
use crate::image::segment::Run;

use super::candidate::{Candidate, MAX_CANDIDATES};

/// Columns per sample of a run: a run is cut into pieces this long, each undistorted at its
/// centre (the lens's distortion bends a line by a few pixels over the frame, not within 16
/// columns).
const CHUNK: u16 = 16;

/// Smallest sagitta (pixels) that makes an object an arc: below half a pixel a section is
/// too flat to tell from a line, whatever its significance (a 50 mm ball's sections at 1.5 m
/// bend by ≈ 1 px).
pub const MIN_SAGITTA_PX: Real = 0.75;

/// How many standard errors the sagitta must exceed: the straight line's fitted sagitta is
/// noise of that spread.
const SIGNIFICANCE: Real = 2.0;

/// Weighted sums of one candidate's quadratic fit `v = a + b·t + c·t²` (`t` its column,
/// normalised to `[−1, 1]` over its span; `v` the undistorted normalised row).
#[derive(Clone, Copy)]
struct Sums {
    /// `Σ w φφᵀ`, `φ = (1, t, t²)`.
    m: Mat3,
    /// `Σ w φ v`.
    b: Vec3,
    /// `Σ w v²`.
    vv: Real,
    /// Samples.
    n: u32,
}

impl Sums {
    const ZERO: Sums = Sums {
        m: Mat3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        b: Vec3::new(0.0, 0.0, 0.0),
        vv: 0.0,
        n: 0,
    };
}

/// Sagitta of a candidate's pixels (pixels), and its standard error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Bend {
    /// `|c|·f_y`: how far the fitted parabola's middle lies off the chord of its ends.
    pub sagitta_px: Real,
    /// Its standard error from the fit's residuals.
    pub sigma_px: Real,
}

impl Bend {
    /// Whether the object is an arc rather than a line ([`MIN_SAGITTA_PX`], [`SIGNIFICANCE`]).
    pub fn is_arc(&self) -> bool {
        self.sagitta_px >= MIN_SAGITTA_PX && self.sagitta_px >= SIGNIFICANCE * self.sigma_px
    }
}

/// The [`Bend`] of each of `cands` (`None` where its pixels do not determine one: fewer than
/// four samples, or a degenerate fit), from the labelled `runs`, written to `out`.
pub(super) fn bends(
    cands: &[Candidate],
    runs: &[Run],
    calibration: &Calibration,
    out: &mut [Option<Bend>],
) {
    let n = cands.len().min(out.len()).min(MAX_CANDIDATES);
    let camera = &calibration.camera;
    let mut sums = [Sums::ZERO; MAX_CANDIDATES];
    for run in runs {
        let Some(k) = cands[..n].iter().position(|c| c.label == run.label) else {
            continue;
        };
        let c = &cands[k];
        let mid = 0.5 * (c.min_x as Real + c.max_x as Real);
        let half = (0.5 * (c.max_x as Real - c.min_x as Real)).max(1.0);
        let mut start = run.start;
        while start < run.end {
            let end = run.end.min(start.saturating_add(CHUNK));
            let x = 0.5 * (start as Real + end as Real - 1.0);
            let w = (end - start) as Real;
            start = end;
            let Ok(p) = camera.pixel_to_normalised(Vec2::new(x, run.row as Real)) else {
                continue;
            };
            let t = (x - mid) / half;
            let phi = Vec3::new(1.0, t, t * t);
            let s = &mut sums[k];
            s.m += phi * phi.transpose() * w;
            s.b += phi * (w * p.y);
            s.vv += w * p.y * p.y;
            s.n += 1;
        }
    }
    for (o, s) in out.iter_mut().zip(sums.iter()).take(n) {
        *o = bend_of(s, camera.fy);
    }
}

/// The fit of one candidate's sums.
fn bend_of(s: &Sums, fy: Real) -> Option<Bend> {
    if s.n < 4 {
        return None;
    }
    let inv = s.m.try_inverse()?;
    let theta = inv * s.b;
    // Σ w (v − φθ)² = Σ w v² − θ·b at the least-squares solution.
    let rss = (s.vv - theta.dot(&s.b)).max(0.0);
    let unit = rss / (s.n - 3) as Real;
    let sagitta_px = theta.z.abs() * fy;
    let sigma_px = sqrt(unit * inv[(2, 2)].max(0.0)) * fy;
    (sagitta_px.is_finite() && sigma_px.is_finite()).then_some(Bend {
        sagitta_px,
        sigma_px,
    })
}

/// Ranks the arcs among `cands` (sorted nearest to the central column first) before the
/// lines, each group keeping its order. Nothing moves when none is an arc: the solver then
/// sees what the aim gave it and names it.
pub(super) fn arcs_first(cands: &mut [Candidate], runs: &[Run], calibration: &Calibration) {
    let n = cands.len().min(MAX_CANDIDATES);
    let mut bend = [None; MAX_CANDIDATES];
    bends(&cands[..n], runs, calibration, &mut bend[..n]);
    let arc = |b: &Option<Bend>| b.is_some_and(|b| b.is_arc());
    if !bend[..n].iter().any(arc) {
        return;
    }
    let mut sorted = [Candidate::NONE; MAX_CANDIDATES];
    let mut k = 0;
    for want_arc in [true, false] {
        for (c, b) in cands[..n].iter().zip(bend.iter()) {
            if arc(b) == want_arc {
                sorted[k] = *c;
                k += 1;
            }
        }
    }
    cands[..n].copy_from_slice(&sorted[..n]);
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// The reference calibration with a strong barrel distortion, so that a straight line in
    /// the scene bends by several pixels in the image.
    fn distorted() -> Calibration {
        let mut cal = Calibration::reference_design();
        cal.camera.distortion.k1 = -0.3;
        cal
    }

    /// The runs (label `label`) of the pixels within 1.5 rows of the image of the ideal
    /// normalised curve `curve(s)`, `s ∈ [0, 1]`, and the candidate they form.
    fn rasterise(
        cal: &Calibration,
        label: u16,
        curve: impl Fn(Real) -> Vec2,
    ) -> (Vec<Run>, Candidate) {
        let (w, h) = (752usize, 480usize);
        let mut lit = std::vec![false; w * h];
        for i in 0..=20_000 {
            let p = cal.camera.normalised_to_pixel(curve(i as Real / 20_000.0));
            let (x, y) = (p.x.round() as i64, p.y);
            for row in (y - 1.5).ceil() as i64..=(y + 1.5).floor() as i64 {
                if (0..w as i64).contains(&x) && (0..h as i64).contains(&row) {
                    lit[row as usize * w + x as usize] = true;
                }
            }
        }
        let mut runs = Vec::new();
        let (mut min_x, mut max_x, mut pixels) = (u16::MAX, 0u16, 0u32);
        for row in 0..h {
            let mut x = 0;
            while x < w {
                if !lit[row * w + x] {
                    x += 1;
                    continue;
                }
                let start = x;
                while x < w && lit[row * w + x] {
                    x += 1;
                }
                runs.push(Run {
                    row: row as u16,
                    start: start as u16,
                    end: x as u16,
                    label,
                });
                min_x = min_x.min(start as u16);
                max_x = max_x.max(x as u16 - 1);
                pixels += (x - start) as u32;
            }
        }
        let cand = Candidate {
            label,
            min_x,
            max_x,
            mean_row: 0.0,
            pixels,
            plane: None,
        };
        (runs, cand)
    }

    /// A floor's line (straight in the scene, bent ≈ 5 px by the lens) from `u0` to `u1`.
    fn line(cal: &Calibration, label: u16, u0: Real, u1: Real) -> (Vec<Run>, Candidate) {
        rasterise(cal, label, |s| {
            let u = u0 + (u1 - u0) * s;
            Vec2::new(u, 0.12 + 0.05 * u)
        })
    }

    /// The front half of an ellipse (a ball's section) centred at `u0` whose middle lies
    /// `sagitta_px` below its ends.
    fn arc(cal: &Calibration, label: u16, u0: Real, sagitta_px: Real) -> (Vec<Run>, Candidate) {
        let b = sagitta_px / cal.camera.fy;
        rasterise(cal, label, |s| {
            let phi = crate::real::PI * s;
            Vec2::new(u0 - 0.05 * phi.cos(), 0.15 + b * phi.sin())
        })
    }

    fn bend_of_one(cal: &Calibration, (runs, cand): &(Vec<Run>, Candidate)) -> Bend {
        let mut out = [None];
        bends(core::slice::from_ref(cand), runs, cal, &mut out);
        out[0].expect("the fit is determined")
    }

    #[test]
    fn a_floor_line_bent_by_the_lens_is_straight() {
        let cal = distorted();
        let b = bend_of_one(&cal, &line(&cal, 1, -0.35, 0.35));
        // The rows' quantisation is the fit's only noise: the sagitta is within it.
        assert!(b.sagitta_px <= 2.5 * b.sigma_px, "{b:?}");
        assert!(!b.is_arc(), "{b:?}");
        // Without undistortion the same pixels bend by several pixels: the test exercises
        // the lens model.
        let mut ideal = cal.clone();
        ideal.camera.distortion.k1 = 0.0;
        let raw = bend_of_one(&ideal, &line(&cal, 1, -0.35, 0.35));
        assert!(raw.sagitta_px > 3.0 && raw.is_arc(), "{raw:?}");
    }

    #[test]
    fn a_section_bending_by_three_pixels_is_an_arc() {
        let cal = distorted();
        let b = bend_of_one(&cal, &arc(&cal, 1, 0.1, 3.0));
        // A parabola fitted to a half ellipse of semi-minor axis `b` bends by 0.736·b
        // (`docs/sphere.md`, (S-arc)).
        assert!(
            (b.sagitta_px - 0.736 * 3.0).abs() <= 2.5 * b.sigma_px,
            "{b:?}"
        );
        assert!(b.is_arc(), "{b:?}");
        let flat = bend_of_one(&cal, &arc(&cal, 1, 0.1, 0.0));
        assert!(!flat.is_arc(), "{flat:?}");
    }

    #[test]
    fn arcs_are_ranked_before_lines_and_lines_alone_keep_their_order() {
        let cal = distorted();
        let (mut runs, floor) = line(&cal, 1, -0.35, 0.05);
        let (arc_runs, ball) = arc(&cal, 2, 0.2, 3.0);
        runs.extend_from_slice(&arc_runs);
        let mut cands = [floor, ball];
        arcs_first(&mut cands, &runs, &cal);
        assert_eq!([cands[0].label, cands[1].label], [2, 1]);

        let (mut runs, left) = line(&cal, 1, -0.35, -0.05);
        let (right_runs, right) = line(&cal, 2, 0.0, 0.35);
        runs.extend_from_slice(&right_runs);
        let mut cands = [right, left];
        arcs_first(&mut cands, &runs, &cal);
        assert_eq!([cands[0].label, cands[1].label], [2, 1]);
    }
}
