//! Calibration of a unit: the camera by Zhang's method on a chessboard, then the laser
//! planes from captures of the laser on the board (thesis chapter 6, appendix A).
//!
//! The chain (derivations in `docs/calibration.md`):
//!
//! 1. [`corners`]: chessboard inner corners per image, labelled on the board grid and refined
//!    to subpixel accuracy;
//! 2. [`zhang`]: per-view homographies (normalised DLT), the closed-form intrinsics from the
//!    constraints on `B = K^-T K^-1`, per-view extrinsics, and a linear first guess of the
//!    radial distortion;
//! 3. [`refine`]: Levenberg–Marquardt over all intrinsics, the five Brown–Conrady coefficients
//!    and every pose, with per-view reprojection errors and parameter standard deviations;
//! 4. [`laser`]: board pose per capture, stripe points back-projected onto the board plane,
//!    robust plane fit, repeatability (leave-one-pose-out spread of baseline, tilt, roll);
//! 5. [`report`]: the text report and the PNG figures;
//! 6. [`reference`] (optional, two planes or more): the planes' `e` and `δ` refined against
//!    each other on captures of a ball, which both sections must fit, or of a flat wall,
//!    which every line must lie in;
//! 7. [`sanity`]: what is refused — views that cannot determine the calibration,
//!    parameters whose σ is beyond a sane bound, loaded values outside physical ranges.
//!
//! The camera model is the core's ([`tangent_core::camera::Camera`]): whatever is
//! calibrated here is exactly what the instrument evaluates.

pub mod corners;
pub mod laser;
pub mod reference;
pub mod refine;
pub mod report;
pub mod sanity;
pub mod zhang;

use nalgebra::{Rotation3, Vector3};
use tangent_core::real::{Vec2, Vec3};

/// A planar chessboard target: its count of *inner* corners and its square size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Board {
    /// Inner corners along the board's long side (the `9` of "9x6").
    pub cols: usize,
    /// Inner corners along the other side (the `6` of "9x6").
    pub rows: usize,
    /// Side of one square (metres).
    pub square: f64,
}

impl Board {
    /// The board point of grid corner `(i, j)` (column `i`, row `j`), in the board frame
    /// (metres, `z = 0`).
    pub fn point(&self, i: usize, j: usize) -> Vec3 {
        Vec3::new(i as f64 * self.square, j as f64 * self.square, 0.0)
    }

    /// Number of inner corners.
    pub fn len(&self) -> usize {
        self.cols * self.rows
    }

    /// True for a board without inner corners (never valid; see [`Board::parse`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Parses `"9x6"` (inner corners) and a square size such as `"25mm"`, `"2.5cm"`,
    /// `"0.025m"` or `"0.025"` (metres).
    pub fn parse(size: &str, square: &str) -> Result<Self, String> {
        let (c, r) = size
            .split_once(['x', 'X'])
            .ok_or_else(|| format!("board size `{size}`: expected COLSxROWS, e.g. 9x6"))?;
        let cols: usize = c
            .trim()
            .parse()
            .map_err(|_| format!("board size `{size}`: bad column count"))?;
        let rows: usize = r
            .trim()
            .parse()
            .map_err(|_| format!("board size `{size}`: bad row count"))?;
        if cols < 3 || rows < 3 {
            return Err(format!(
                "board size `{size}`: need at least 3x3 inner corners"
            ));
        }
        let s = square.trim();
        let (num, scale) = if let Some(v) = s.strip_suffix("mm") {
            (v, 1e-3)
        } else if let Some(v) = s.strip_suffix("cm") {
            (v, 1e-2)
        } else if let Some(v) = s.strip_suffix('m') {
            (v, 1.0)
        } else {
            (s, 1.0)
        };
        let value: f64 = num
            .trim()
            .parse()
            .map_err(|_| format!("square size `{square}`: not a number"))?;
        let square = value * scale;
        if !(square.is_finite() && square > 0.0) {
            return Err(format!("square size `{square}`: must be positive"));
        }
        // The long side is `cols` by convention; a "6x9" board is the same board.
        let (cols, rows) = if cols >= rows {
            (cols, rows)
        } else {
            (rows, cols)
        };
        Ok(Board { cols, rows, square })
    }
}

/// One labelled corner: its board grid index and its measured pixel position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Column on the board grid, `0..board.cols`.
    pub i: usize,
    /// Row on the board grid, `0..board.rows`.
    pub j: usize,
    /// Subpixel position in the image (pixels, OpenCV convention).
    pub pixel: Vec2,
}

/// The corners found in one image.
///
/// The grid labels are defined up to an isometry of the board (a rotation by 180°, a
/// mirror, or, for a partial board, a shift): every such relabelling is the same set of
/// board points seen from a different pose, so it does not change the intrinsics
/// (`docs/calibration.md`, "Labelling").
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Where the view came from (file name), for the report.
    pub name: String,
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// The labelled corners.
    pub corners: Vec<Corner>,
}

/// A rigid transform board → camera: `X_cam = R·X_board + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation board → camera.
    pub rotation: Rotation3<f64>,
    /// Translation (metres): the board origin in the camera frame.
    pub translation: Vector3<f64>,
}

impl Pose {
    /// Maps a board point into the camera frame.
    pub fn apply(&self, p: &Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// The board plane in the camera frame as `(n, d)` with `n·X = d`, `n` the board's
    /// `z` axis expressed in the camera frame.
    pub fn plane(&self) -> (Vec3, f64) {
        let n = self.rotation * Vec3::z();
        (n, n.dot(&self.translation))
    }
}

/// Why a calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// Fewer usable views than the method needs.
    #[error("{found} usable view(s), at least {needed} needed")]
    TooFewViews {
        /// Usable views.
        found: usize,
        /// Views needed.
        needed: usize,
    },
    /// The closed-form solution is degenerate (e.g. every view parallel to the image).
    #[error("degenerate geometry: {0}")]
    Degenerate(String),
    /// The refinement did not produce a valid camera.
    #[error("refinement failed: {0}")]
    Refinement(String),
    /// The views cannot determine the calibration (repeated views, too little tilt between
    /// them, a laser plane seen at a single depth); see [`sanity`].
    #[error("the views cannot determine the calibration: {0}")]
    Undetermined(String),
    /// A parameter's standard deviation exceeds its bound ([`sanity`]).
    #[error(
        "{name} is not determined by these views: σ = {sigma:.4e} {unit}, the bound is \
         {bound:.4e} {unit}; add views with the board tilted differently"
    )]
    TooUncertain {
        /// The parameter.
        name: &'static str,
        /// Its standard deviation.
        sigma: f64,
        /// The bound it exceeds.
        bound: f64,
        /// Unit of both.
        unit: &'static str,
    },
    /// A capture given as a reference view that is not in the reference's mode
    /// ([`reference`]): a ball's views are taken in sphere mode, a wall's in wall mode.
    #[error("{0}: not a {1}-mode capture; the reference's views are taken in {1} mode")]
    NotAReferenceCapture(String, &'static str),
    /// Too few stripe points to fit a laser plane.
    #[error("{found} laser-stripe point(s) on the board, at least {needed} needed")]
    TooFewStripePoints {
        /// Points found.
        found: usize,
        /// Points needed.
        needed: usize,
    },
}
