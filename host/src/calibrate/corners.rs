//! Chessboard corners: detection, grid labelling, validation and subpixel refinement
//! (`docs/calibration.md`, section 1).
//!
//! Detection and grid labelling use the `calib-targets` crate (ChESS X-corner detector from
//! `chess-corners`, then a grid grown from local neighbour structure). We chose it over
//! writing our own after trying it on OpenCV's sample set: it is maintained (2026
//! releases), MIT/Apache, pure Rust, labels partial boards, and is built to refuse rather
//! than guess a labelling. It is not trusted blindly, though; on top of it this module:
//!
//! 1. removes corners inconsistent with their grid neighbours (a spurious X-junction in the
//!    background attached to the grid: on OpenCV's `left12.jpg` the crate returns two such
//!    corners), by predicting every corner from its neighbours along both grid axes;
//! 2. refines each corner with the gradient-orthogonality method of OpenCV's
//!    `cornerSubPix` (every image gradient near a saddle point is orthogonal to the vector
//!    from the saddle point), in a window sized from the local grid spacing so that it
//!    never reaches the next corner; the refined corners are checked again;
//! 3. maps the crate's grid indices onto the physical board, rejecting a grid larger than
//!    the board unless a unique board-sized window contains it.

use std::collections::HashMap;

use calib_targets::chessboard::ChessboardParams;
use calib_targets::detect;
use image::GrayImage;
use tangent_core::real::Vec2;

use super::{Board, Corner, View};

/// Fewest corners a view must keep to be used: a homography has 8 degrees of freedom, and
/// a view barely determining it would only add noise to the intrinsics.
pub const MIN_CORNERS: usize = 12;

/// Largest half-width of the subpixel window (pixels), OpenCV's calibration sample default
/// (`winSize = 11`). The window is also limited to 0.4 × the distance to the nearest grid
/// neighbour, so that it never contains a second corner.
pub const MAX_HALF_WINDOW: usize = 11;

/// Largest error of a midpoint prediction `(p₋ + p₊)/2`, relative to the local spacing.
///
/// Under perspective the spacing changes by a ratio `ρ` from one square to the next; the
/// midpoint is then off by `|ρ − 1|/2` of the spacing. 0.2 allows `ρ` up to 1.4 (a board at
/// a grazing angle) while a spurious or mislabelled corner is off by half a square or more.
pub const MIDPOINT_TOLERANCE: f64 = 0.2;

/// Largest error of a linear extrapolation `2p₁ − p₂`, relative to the local spacing: twice
/// the midpoint tolerance, since the extrapolation error is the full second difference.
pub const EXTRAPOLATION_TOLERANCE: f64 = 0.4;

/// Why no usable corners came out of an image.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CornerError {
    /// The detector found no chessboard.
    #[error("no chessboard found")]
    NotFound,
    /// Too few corners survived validation.
    #[error("only {0} valid corner(s) (at least {MIN_CORNERS} needed)")]
    TooFewCorners(usize),
    /// The detected grid is larger than the board and cannot be placed on it uniquely.
    #[error("detected grid {0}x{1} does not fit the {2}x{3} board unambiguously")]
    Ambiguous(usize, usize, usize, usize),
}

/// Detects, validates, refines and labels the corners of `board` in a grey image.
///
/// `name` identifies the view in reports. Errors when the board is not found or too little
/// of it is unambiguously labelled; a partial board is returned with the corners found.
pub fn detect(img: &GrayImage, board: &Board, name: &str) -> Result<View, CornerError> {
    detect_with(img, board, name, &DetectOptions::default())
}

/// Options of [`detect_with`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectOptions {
    /// Largest half-width of the subpixel window (pixels); see [`MAX_HALF_WINDOW`].
    pub max_half_window: usize,
    /// Fraction of the nearest-neighbour spacing the half-window may reach.
    pub window_fraction: f64,
    /// Refine with [`corner_subpix`] (true) or keep the detector's own subpixel positions.
    pub refine: bool,
}

impl Default for DetectOptions {
    fn default() -> Self {
        DetectOptions {
            max_half_window: MAX_HALF_WINDOW,
            window_fraction: 0.4,
            refine: true,
        }
    }
}

/// [`detect`] with explicit options.
pub fn detect_with(
    img: &GrayImage,
    board: &Board,
    name: &str,
    opts: &DetectOptions,
) -> Result<View, CornerError> {
    let found = detect::detect_chessboard_best(
        img,
        &detect::default_chess_config(),
        &ChessboardParams::sweep_default(),
    )
    .map_err(|_| CornerError::NotFound)?;
    let mut grid: HashMap<(i32, i32), Vec2> = found
        .corners
        .iter()
        .map(|c| {
            (
                (c.grid.u, c.grid.v),
                Vec2::new(c.position[0] as f64, c.position[1] as f64),
            )
        })
        .collect();
    remove_inconsistent(&mut grid);

    let gray = GrayF::from_image(img);
    let mut refined = HashMap::with_capacity(grid.len());
    for (&key, &p) in &grid {
        let spacing =
            nearest_neighbour_distance(&grid, key).unwrap_or(2.0 * MAX_HALF_WINDOW as f64 + 2.0);
        let half = ((opts.window_fraction * spacing).floor() as usize)
            .clamp(2, opts.max_half_window.max(2));
        let q = if opts.refine {
            corner_subpix(&gray, p, half)
        } else {
            Some(p)
        };
        if let Some(q) = q {
            // A refinement that walks more than a quarter of a square away has locked on
            // something else.
            if (q - p).norm() <= 0.25 * spacing {
                refined.insert(key, q);
            }
        }
    }
    remove_inconsistent(&mut refined);
    let corners = label(&refined, board)?;
    if corners.len() < MIN_CORNERS {
        return Err(CornerError::TooFewCorners(corners.len()));
    }
    Ok(View {
        name: name.to_string(),
        width: img.width(),
        height: img.height(),
        corners,
    })
}

/// Distance from a grid corner to its nearest 4-neighbour present in the grid.
fn nearest_neighbour_distance(grid: &HashMap<(i32, i32), Vec2>, (u, v): (i32, i32)) -> Option<f64> {
    let p = grid.get(&(u, v))?;
    [(1, 0), (-1, 0), (0, 1), (0, -1)]
        .iter()
        .filter_map(|(du, dv)| grid.get(&(u + du, v + dv)).map(|q| (q - p).norm()))
        .min_by(|a, b| a.total_cmp(b))
}

/// Counts `(agreeing, disagreeing)` neighbour predictions of the corner at `key`.
fn support(grid: &HashMap<(i32, i32), Vec2>, key: (i32, i32)) -> (usize, usize) {
    let Some(&p) = grid.get(&key) else {
        return (0, 0);
    };
    let (u, v) = key;
    let (mut agree, mut disagree) = (0, 0);
    let mut judge = |pred: Vec2, spacing: f64, tol: f64| {
        if spacing > 0.0 && (pred - p).norm() <= tol * spacing {
            agree += 1;
        } else {
            disagree += 1;
        }
    };
    for (du, dv) in [(1, 0), (0, 1)] {
        let at = |k: i32| grid.get(&(u + k * du, v + k * dv)).copied();
        if let (Some(a), Some(b)) = (at(-1), at(1)) {
            judge((a + b) / 2.0, (b - a).norm() / 2.0, MIDPOINT_TOLERANCE);
        }
        for s in [1, -1] {
            if let (Some(a), Some(b)) = (at(s), at(2 * s)) {
                judge(2.0 * a - b, (a - b).norm(), EXTRAPOLATION_TOLERANCE);
            }
        }
    }
    (agree, disagree)
}

/// Removes, one at a time, the corner with no agreeing neighbour prediction and the most
/// disagreeing ones (a corner with no prediction at all, i.e. without two aligned
/// neighbours, is also removed), until every corner is supported by its neighbours.
fn remove_inconsistent(grid: &mut HashMap<(i32, i32), Vec2>) {
    loop {
        let worst = grid
            .keys()
            .map(|&k| (k, support(grid, k)))
            .filter(|(_, (a, _))| *a == 0)
            .max_by_key(|&(k, (_, d))| (d, std::cmp::Reverse(k)));
        match worst {
            Some((k, _)) => {
                grid.remove(&k);
            }
            None => return,
        }
    }
}

/// Maps crate grid indices onto the board (see the module documentation, step 3).
fn label(grid: &HashMap<(i32, i32), Vec2>, board: &Board) -> Result<Vec<Corner>, CornerError> {
    if grid.is_empty() {
        return Err(CornerError::TooFewCorners(0));
    }
    let umin = grid.keys().map(|k| k.0).min().unwrap_or(0);
    let umax = grid.keys().map(|k| k.0).max().unwrap_or(0);
    let vmin = grid.keys().map(|k| k.1).min().unwrap_or(0);
    let vmax = grid.keys().map(|k| k.1).max().unwrap_or(0);
    let (w, h) = ((umax - umin + 1) as usize, (vmax - vmin + 1) as usize);
    let (c, r) = (board.cols, board.rows);

    // Candidate placements: (transpose?, u offset, v offset) of a board-sized window.
    let mut best: Vec<(bool, i32, i32)> = Vec::new();
    let mut best_count = 0;
    for transpose in [false, true] {
        let (ww, wh) = if transpose { (r, c) } else { (c, r) };
        // Offsets such that the window [u0, u0+ww) × [v0, v0+wh) overlaps the grid.
        for u0 in (umin - ww as i32 + 1)..=umax {
            for v0 in (vmin - wh as i32 + 1)..=vmax {
                let count = grid
                    .keys()
                    .filter(|&&(u, v)| {
                        u >= u0 && u < u0 + ww as i32 && v >= v0 && v < v0 + wh as i32
                    })
                    .count();
                if count > best_count {
                    best_count = count;
                    best.clear();
                }
                if count == best_count {
                    best.push((transpose, u0, v0));
                }
            }
        }
    }
    let inside = |&(t, u0, v0): &(bool, i32, i32), u: i32, v: i32| {
        let (ww, wh) = if t {
            (r as i32, c as i32)
        } else {
            (c as i32, r as i32)
        };
        u >= u0 && u < u0 + ww && v >= v0 && v < v0 + wh
    };
    let Some(&first) = best.first() else {
        return Err(CornerError::TooFewCorners(0));
    };
    // Every best window must select the same corners; otherwise the placement is ambiguous.
    if best_count < grid.len() {
        for cand in &best[1..] {
            if grid
                .keys()
                .any(|&(u, v)| inside(cand, u, v) != inside(&first, u, v))
            {
                return Err(CornerError::Ambiguous(w, h, c, r));
            }
        }
    }
    let (t, _, _) = first;
    let mut corners: Vec<Corner> = grid
        .iter()
        .filter(|(&(u, v), _)| inside(&first, u, v))
        .map(|(&(u, v), &p)| {
            let (a, b) = ((u - first.1) as usize, (v - first.2) as usize);
            let (i, j) = if t { (b, a) } else { (a, b) };
            Corner { i, j, pixel: p }
        })
        .collect();
    corners.sort_by_key(|c| (c.j, c.i));
    Ok(corners)
}

/// A grey image as `f32` samples for subpixel work.
pub struct GrayF {
    width: usize,
    height: usize,
    data: Vec<f32>,
}

impl GrayF {
    /// Converts an 8-bit grey image.
    pub fn from_image(img: &GrayImage) -> Self {
        GrayF {
            width: img.width() as usize,
            height: img.height() as usize,
            data: img.as_raw().iter().map(|&b| b as f32).collect(),
        }
    }

    /// Bilinear sample at `(x, y)` (pixel centres at integers); `None` outside the image.
    pub fn sample(&self, x: f64, y: f64) -> Option<f64> {
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        if x0 + 1 >= self.width || y0 + 1 >= self.height {
            return None;
        }
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let at = |xx: usize, yy: usize| self.data[yy * self.width + xx] as f64;
        let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
        let bot = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
        Some(top * (1.0 - fy) + bot * fy)
    }
}

/// Subpixel saddle point by gradient orthogonality (OpenCV's `cornerSubPix`).
///
/// At the true corner `q`, every gradient `g_p` at a nearby pixel `p` is either zero (flat
/// square) or orthogonal to `p − q` (on an edge through `q`), so `q` minimises
/// `Σ w_p (g_pᵀ(p − q))²`, whose normal equations give
/// `q = (Σ w g gᵀ)⁻¹ Σ w g gᵀ p` (`docs/calibration.md`, "Subpixel corners"). The window is
/// re-centred on the new estimate (bilinear resampling) until it moves less than 0.001 px.
/// Weights are OpenCV's Gaussian `exp(−|p − q|²/half²)`. `None` if the window leaves the
/// image or the system is singular.
pub fn corner_subpix(img: &GrayF, start: Vec2, half: usize) -> Option<Vec2> {
    let h = half as i64;
    let size = (2 * h + 3) as usize;
    let mut q = start;
    let mut patch = vec![0.0f64; size * size];
    for _ in 0..40 {
        // Sample the window (with a 1-pixel border for the gradients) centred on q.
        for (k, val) in patch.iter_mut().enumerate() {
            let dx = (k % size) as i64 - h - 1;
            let dy = (k / size) as i64 - h - 1;
            *val = img.sample(q.x + dx as f64, q.y + dy as f64)?;
        }
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for dy in -h..=h {
            for dx in -h..=h {
                let (cx, cy) = ((dx + h + 1) as usize, (dy + h + 1) as usize);
                let gx = 0.5 * (patch[cy * size + cx + 1] - patch[cy * size + cx - 1]);
                let gy = 0.5 * (patch[(cy + 1) * size + cx] - patch[(cy - 1) * size + cx]);
                let w = (-((dx * dx + dy * dy) as f64) / (h * h) as f64).exp();
                let (gxx, gxy, gyy) = (w * gx * gx, w * gx * gy, w * gy * gy);
                let (px, py) = (q.x + dx as f64, q.y + dy as f64);
                a11 += gxx;
                a12 += gxy;
                a22 += gyy;
                b1 += gxx * px + gxy * py;
                b2 += gxy * px + gyy * py;
            }
        }
        let det = a11 * a22 - a12 * a12;
        if !(det.is_finite() && det > 1e-9 * (a11 + a22) * (a11 + a22)) {
            return None;
        }
        let next = Vec2::new((a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det);
        let moved = (next - q).norm();
        q = next;
        if (q - start).norm() > half as f64 {
            return None;
        }
        if moved < 1e-3 {
            break;
        }
    }
    Some(q)
}
