//! Laser planes and triangulation (thesis chapter 3).
//!
//! A line laser spreads its beam into a fan: a plane in the camera frame, which we write
//! `n·X = d` with `n` a unit normal and, canonically, `d > 0` (the camera centre is on the
//! negative side, `n` points away from the camera). The fan's apex, the laser's emission
//! point `S`, lies in the plane; the three-tangent method needs it because the rays that
//! graze a trunk start there.
//!
//! The thesis parametrises the plane by the baseline `e` (camera-to-laser distance) and the
//! tilt `δ` of the fan towards the optical axis ([`LaserPlane::from_baseline_tilt`]):
//!
//! ```text
//!   side view, x axis out of the page (y down, z forward)
//!
//!   C o--------------------------------------------o------> z   (optical axis, y = 0)
//!     |                                  ______.--'  z0 = e / tan(delta)
//!     | e                    ______.----'
//!     |          ______.----'   laser plane, seen edge-on (contains the x axis)
//!   S o____.----'  ) delta
//!     |  - - - - - - - - - - -   (through S, parallel to z)
//!     v y
//! ```
//!
//! Every pixel of the laser curve then maps to one 3-D point: the pixel's ray meets the
//! plane once ([`LaserPlane::intersect_ray`], [`triangulate`]). For undistorted image
//! coordinates the map image ↔ plane is a homography
//! ([`LaserPlane::plane_to_normalised_homography`]). Derivations: `docs/laser-plane.md`.

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::camera::{Camera, CameraError};
// `Float` supplies sqrt/atan2/… in `no_std`; with `std` the inherent methods win.
#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, sqrt, Mat3, Real, Vec2, Vec3, PI};

/// Largest distance (metres) between the given source point and the plane that
/// [`LaserPlane::new`] silently corrects by projecting the source onto the plane.
///
/// 10 µm: two orders of magnitude below any mechanical knowledge of where a laser diode
/// emits (≈ 1 mm), so a larger gap is a real inconsistency, and two orders of magnitude above
/// the `f32` rounding of coordinates of ~1 m (ε·1 m ≈ 1.2e-7 m) or of a plane fitted in `f32`.
pub const SOURCE_IN_PLANE_TOLERANCE: Real = 1e-5;

/// Smallest plane offset `|d|` (metres), i.e. distance from the camera centre to the plane.
///
/// When the camera centre lies in the laser plane, the whole plane images onto one line and
/// triangulation is impossible (the homography of `docs/laser-plane.md` has determinant
/// `−d`). 0.1 mm is far below any useful baseline (centimetres), far above rounding.
pub const MIN_PLANE_OFFSET: Real = 1e-4;

/// Why a laser-plane operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaserPlaneError {
    /// The normal is zero, too short to normalise, or not finite.
    DegenerateNormal,
    /// The source point is farther than [`SOURCE_IN_PLANE_TOLERANCE`] from the plane, or is
    /// not finite.
    SourceNotInPlane,
    /// The offset is not finite, or `|d| <` [`MIN_PLANE_OFFSET`]: the camera centre is in the
    /// plane, which then images onto a line.
    CameraInPlane,
    /// The baseline `e` is not finite or not larger than [`MIN_PLANE_OFFSET`].
    InvalidBaseline,
    /// The tilt `δ` (or roll) is not finite, or `|δ| ≥ π/2`.
    InvalidTilt,
    /// The ray is (numerically) parallel to the plane, zero, or not finite.
    RayParallel,
    /// The ray meets the plane behind the camera.
    BehindCamera,
}

impl fmt::Display for LaserPlaneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LaserPlaneError::DegenerateNormal => {
                write!(f, "laser-plane normal is zero or not finite")
            }
            LaserPlaneError::SourceNotInPlane => {
                write!(f, "laser source point is not in the laser plane")
            }
            LaserPlaneError::CameraInPlane => write!(
                f,
                "laser plane passes through the camera centre (or offset not finite)"
            ),
            LaserPlaneError::InvalidBaseline => {
                write!(f, "laser baseline must be finite and positive")
            }
            LaserPlaneError::InvalidTilt => {
                write!(f, "laser tilt must be finite with |tilt| < 90 degrees")
            }
            LaserPlaneError::RayParallel => write!(f, "ray is parallel to the laser plane"),
            LaserPlaneError::BehindCamera => {
                write!(f, "ray meets the laser plane behind the camera")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for LaserPlaneError {}

/// A laser plane in the camera frame: the points `X` with `normal·X = offset`, plus the
/// laser's emission point `source` (the fan apex), which lies in the plane.
///
/// Invariants established by [`LaserPlane::new`] (and checked by
/// [`LaserPlane::validate`]): `normal` has unit length, `offset ≥` [`MIN_PLANE_OFFSET`]
/// (the sign of the normal is chosen so that the offset is positive), `source` is in the
/// plane. All in metres, camera frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LaserPlane {
    /// Unit normal, pointing away from the camera centre.
    pub normal: Vec3,
    /// Distance from the camera centre to the plane (metres, positive).
    pub offset: Real,
    /// The laser's emission point (fan apex), in the plane (metres, camera frame).
    pub source: Vec3,
}

impl LaserPlane {
    /// The plane's line runs down the image (a vertical fan beside the camera: the crossing
    /// line of `docs/building.md`): its normal leans more towards the camera's x axis than its
    /// y axis, so depth moves its stripe along the rows and it is extracted row by row
    /// (`pipeline::crossing`); every other plane's stripe moves along the columns.
    pub fn is_row_wise(&self) -> bool {
        self.normal.x.abs() > self.normal.y.abs()
    }

    /// Builds a plane `normal·X = offset` with emission point `source`.
    ///
    /// Normalises `normal` (dividing `offset` by its length), flips both so that the
    /// offset is positive, and projects `source` onto the plane if it is at most
    /// [`SOURCE_IN_PLANE_TOLERANCE`] away (rejecting it otherwise).
    pub fn new(normal: Vec3, offset: Real, source: Vec3) -> Result<Self, LaserPlaneError> {
        let len = norm(&normal);
        if !(len.is_finite() && len > sqrt(Real::MIN_POSITIVE)) {
            return Err(LaserPlaneError::DegenerateNormal);
        }
        let mut n = normal / len;
        let mut d = offset / len;
        if !d.is_finite() || d.abs() < MIN_PLANE_OFFSET {
            return Err(LaserPlaneError::CameraInPlane);
        }
        if d < 0.0 {
            n = -n;
            d = -d;
        }
        if !(source.x.is_finite() && source.y.is_finite() && source.z.is_finite()) {
            return Err(LaserPlaneError::SourceNotInPlane);
        }
        let gap = n.dot(&source) - d;
        if gap.is_nan() || gap.abs() > SOURCE_IN_PLANE_TOLERANCE {
            return Err(LaserPlaneError::SourceNotInPlane);
        }
        Ok(LaserPlane {
            normal: n,
            offset: d,
            source: source - n * gap,
        })
    }

    /// The plane through three points, with `source` as emission point.
    ///
    /// The normal is `(p1 − p0) × (p2 − p0)`; [`LaserPlaneError::DegenerateNormal`] if the
    /// points are (nearly) collinear — relative to the size of the triangle, so that the
    /// test does not depend on units.
    pub fn from_points(
        p0: Vec3,
        p1: Vec3,
        p2: Vec3,
        source: Vec3,
    ) -> Result<Self, LaserPlaneError> {
        let (a, b) = (p1 - p0, p2 - p0);
        let n = a.cross(&b);
        // |a × b| = |a||b| sin θ; reject sin θ below √ε (the normal's direction would then
        // carry less than half the significant digits).
        let scale = norm(&a) * norm(&b);
        if !(scale.is_finite() && norm(&n) > sqrt(Real::EPSILON) * scale) {
            return Err(LaserPlaneError::DegenerateNormal);
        }
        Self::new(n, n.dot(&p0), source)
    }

    /// The thesis's parametrisation: baseline `e` (metres) and tilt `δ` (radians).
    ///
    /// The source is at `S = (0, e, 0)` (a distance `e` below the camera, `y` down); the
    /// fan contains the `x` direction and rises towards the optical axis at angle `δ`,
    /// crossing it at `z = e / tan δ`:
    ///
    /// ```text
    /// n = (0, cos δ, sin δ),   d = e·cos δ,   in-plane depth direction b = (0, −sin δ, cos δ)
    /// ```
    ///
    /// `e > 0` is required (a laser above the camera is the same plane rolled by π, see
    /// [`LaserPlane::from_baseline_tilt_roll`]); `|δ| < π/2`. `δ = 0` gives a fan parallel to
    /// the axis, `δ < 0` one falling away from it. `docs/laser-plane.md`, "Baseline and tilt".
    pub fn from_baseline_tilt(baseline: Real, tilt: Real) -> Result<Self, LaserPlaneError> {
        Self::from_baseline_tilt_roll(baseline, tilt, 0.0)
    }

    /// [`LaserPlane::from_baseline_tilt`] rotated by the roll angle `ρ` about the optical
    /// axis (a laser mounted with its fan not parallel to the sensor rows):
    /// `S = R_z(ρ)·(0, e, 0)`, `n = R_z(ρ)·(0, cos δ, sin δ)`, with
    /// `R_z(ρ) = [[cos ρ, −sin ρ, 0], [sin ρ, cos ρ, 0], [0, 0, 1]]`.
    pub fn from_baseline_tilt_roll(
        baseline: Real,
        tilt: Real,
        roll: Real,
    ) -> Result<Self, LaserPlaneError> {
        if !(baseline.is_finite() && baseline > MIN_PLANE_OFFSET) {
            return Err(LaserPlaneError::InvalidBaseline);
        }
        if !(tilt.is_finite() && tilt.abs() < 0.5 * PI && roll.is_finite()) {
            return Err(LaserPlaneError::InvalidTilt);
        }
        let (sd, cd) = tilt.sin_cos();
        let (sr, cr) = roll.sin_cos();
        let rot = |v: Vec3| Vec3::new(cr * v.x - sr * v.y, sr * v.x + cr * v.y, v.z);
        let normal = rot(Vec3::new(0.0, cd, sd));
        let source = rot(Vec3::new(0.0, baseline, 0.0));
        // n·S = e·cos δ exactly in exact arithmetic; `new` re-projects the rounding.
        Self::new(normal, baseline * cd, source)
    }

    /// The thesis's `(e, δ)` of this plane: `δ = asin(n_z)` and `e = d / cos δ`.
    ///
    /// This is the inverse of [`LaserPlane::from_baseline_tilt_roll`] for `e > 0`,
    /// `|δ| < π/2` (the roll is [`LaserPlane::roll`]). Geometrically `e` is where the plane
    /// meets the line through the camera centre along the rolled `y` axis, and the plane
    /// crosses the optical axis at `z = d / n_z = e / tan δ`. For a plane perpendicular to
    /// the optical axis (`n_z = ±1`) `e` is infinite. Uses only the plane, not `source`.
    pub fn baseline_tilt(&self) -> (Real, Real) {
        let nz = self.normal.z.clamp(-1.0, 1.0);
        let tilt = nz.asin();
        let cos_tilt = sqrt(self.normal.x * self.normal.x + self.normal.y * self.normal.y);
        let baseline = if cos_tilt > 0.0 {
            self.offset / cos_tilt
        } else {
            Real::INFINITY
        };
        (baseline, tilt)
    }

    /// Roll `ρ` of the fan about the optical axis: `ρ = atan2(−n_x, n_y)` (0 for the thesis's
    /// planes, see [`LaserPlane::from_baseline_tilt_roll`]).
    pub fn roll(&self) -> Real {
        (-self.normal.x).atan2(self.normal.y)
    }

    /// Where the plane crosses the optical axis: `z = d / n_z`, or `None` if it is parallel
    /// to the axis (`n_z = 0`) or crosses behind the camera.
    pub fn axis_crossing(&self) -> Option<Real> {
        let z = self.offset / self.normal.z;
        if z.is_finite() && z > 0.0 {
            Some(z)
        } else {
            None
        }
    }

    /// Checks the invariants (unit finite normal, offset ≥ [`MIN_PLANE_OFFSET`], source in the
    /// plane), e.g. after deserialising.
    ///
    /// "Unit" is checked to `1e-4` relative: enough to catch an unnormalised or corrupted
    /// normal, loose enough for a normal stored in `f32` text (7 digits).
    pub fn validate(&self) -> Result<(), LaserPlaneError> {
        let len = norm(&self.normal);
        if !(len.is_finite() && (len - 1.0).abs() <= 1e-4) {
            return Err(LaserPlaneError::DegenerateNormal);
        }
        if !(self.offset.is_finite() && self.offset >= MIN_PLANE_OFFSET) {
            return Err(LaserPlaneError::CameraInPlane);
        }
        let gap = self.signed_distance(self.source);
        if gap.is_nan() || gap.abs() > SOURCE_IN_PLANE_TOLERANCE {
            return Err(LaserPlaneError::SourceNotInPlane);
        }
        Ok(())
    }

    /// Intersection of the ray `t·ray` (`t > 0`) from the camera centre with the plane:
    /// `t = d / (n·ray)` (`docs/laser-plane.md`, "Ray–plane intersection").
    ///
    /// [`LaserPlaneError::RayParallel`] if `|n·ray| ≤ 16·ε·|ray|` (the angle between ray and
    /// plane is at the rounding level) or the ray is zero / not finite;
    /// [`LaserPlaneError::BehindCamera`] if `t ≤ 0`.
    #[inline]
    pub fn intersect_ray(&self, ray: Vec3) -> Result<Vec3, LaserPlaneError> {
        let len = norm(&ray);
        if !(len.is_finite() && len > 0.0) {
            return Err(LaserPlaneError::RayParallel);
        }
        let denom = self.normal.dot(&ray);
        if denom.is_nan() || denom.abs() <= 16.0 * Real::EPSILON * len {
            return Err(LaserPlaneError::RayParallel);
        }
        let t = self.offset / denom;
        if !t.is_finite() {
            return Err(LaserPlaneError::RayParallel);
        }
        if t <= 0.0 {
            return Err(LaserPlaneError::BehindCamera);
        }
        Ok(ray * t)
    }

    /// Signed distance of `p` from the plane, `n·p − d` (negative on the camera's side).
    pub fn signed_distance(&self, p: Vec3) -> Real {
        self.normal.dot(&p) - self.offset
    }

    /// The in-plane orthonormal axes `(a, b)` used by [`LaserPlane::to_plane_coords`].
    ///
    /// `b` = the optical axis `ẑ` projected on the plane and normalised: the in-plane
    /// direction pointing away from the source towards larger depth. `a = n × b`: in the
    /// plane, perpendicular to `b`; for a plane of zero roll it is exactly the camera's `x`
    /// axis, for roll `ρ` it is `x̂` rotated by `ρ` about `ẑ`. `(a, b, −n)` is right-handed.
    ///
    /// For a plane perpendicular to the optical axis (`|n_z| > 1 − 1e-6`, where `ẑ`'s
    /// projection vanishes) `b` is instead the projection of `−ŷ` (up), so the axes are
    /// always defined.
    pub fn plane_axes(&self) -> (Vec3, Vec3) {
        let n = self.normal;
        let project = |v: Vec3| v - n * n.dot(&v);
        let bz = project(Vec3::new(0.0, 0.0, 1.0));
        let b_raw = if bz.norm_squared() > 2e-6 {
            bz
        } else {
            project(Vec3::new(0.0, -1.0, 0.0))
        };
        let b = b_raw / norm(&b_raw);
        let a = n.cross(&b);
        (a, b)
    }

    /// 2-D coordinates in the plane: `q = ((p − S)·a, (p − S)·b)` with origin at the source
    /// `S` and the axes of [`LaserPlane::plane_axes`]. A point off the plane is first
    /// projected orthogonally onto it.
    pub fn to_plane_coords(&self, p: Vec3) -> Vec2 {
        let (a, b) = self.plane_axes();
        let rel = p - self.source;
        Vec2::new(rel.dot(&a), rel.dot(&b))
    }

    /// The 3-D point (camera frame) with in-plane coordinates `q`: `S + q_a·a + q_b·b`.
    pub fn from_plane_coords(&self, q: Vec2) -> Vec3 {
        let (a, b) = self.plane_axes();
        self.source + a * q.x + b * q.y
    }

    /// The camera centre's orthogonal projection onto the plane (the point `d·n`), in plane
    /// coordinates. Its distance from the plane is [`LaserPlane::offset`].
    ///
    /// For the thesis's planes it is `(0, e·sin δ)`: on the `b` axis, `e·sin δ` in front of
    /// the source.
    pub fn camera_centre_in_plane(&self) -> Vec2 {
        self.to_plane_coords(self.normal * self.offset)
    }

    /// The homography `G = [a | b | S]` (columns) from in-plane coordinates to ideal
    /// normalised image coordinates: `λ·(x, y, 1)ᵀ = G·(q_a, q_b, 1)ᵀ`.
    ///
    /// Multiply by [`Camera::intrinsic_matrix`] on the left for (undistorted) pixels:
    /// `H = K·[a | b | S]`, the classical `K·(r1 r2 t)` of a plane (`docs/laser-plane.md`,
    /// "Image ↔ plane homography"). `det G = −d ≠ 0`: the map is one-to-one.
    pub fn plane_to_normalised_homography(&self) -> Mat3 {
        let (a, b) = self.plane_axes();
        Mat3::from_columns(&[a, b, self.source])
    }

    /// The inverse homography, ideal normalised image coordinates → in-plane coordinates:
    /// `G⁻¹ = (1/det G)·[b × S ; S × a ; a × b]` (rows), with `det G = (a × b)·S = −d`.
    pub fn normalised_to_plane_homography(&self) -> Mat3 {
        let (a, b) = self.plane_axes();
        let s = self.source;
        let det = a.cross(&b).dot(&s);
        let (r0, r1, r2) = (b.cross(&s) / det, s.cross(&a) / det, a.cross(&b) / det);
        Mat3::new(r0.x, r0.y, r0.z, r1.x, r1.y, r1.z, r2.x, r2.y, r2.z)
    }
}

/// Why a pixel could not be triangulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriangulationError {
    /// The pixel has no valid ray (see [`CameraError`]).
    Camera(CameraError),
    /// The ray does not meet the plane in front of the camera (see [`LaserPlaneError`]).
    Plane(LaserPlaneError),
}

impl From<CameraError> for TriangulationError {
    fn from(e: CameraError) -> Self {
        TriangulationError::Camera(e)
    }
}

impl From<LaserPlaneError> for TriangulationError {
    fn from(e: LaserPlaneError) -> Self {
        TriangulationError::Plane(e)
    }
}

impl fmt::Display for TriangulationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TriangulationError::Camera(e) => write!(f, "triangulation: {e}"),
            TriangulationError::Plane(e) => write!(f, "triangulation: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for TriangulationError {}

/// Triangulates one (distorted) pixel of the laser curve: undistort → ray → intersection
/// with the laser plane. Returns the 3-D point in the camera frame (metres).
#[inline(always)]
pub fn triangulate(
    camera: &Camera,
    plane: &LaserPlane,
    pixel: Vec2,
) -> Result<Vec3, TriangulationError> {
    let ray = camera.pixel_to_ray(pixel)?;
    Ok(plane.intersect_ray(ray)?)
}

#[cfg(test)]
// The casts to f64 are no-ops in f64 builds but needed with `--features f32`.
#[allow(clippy::unnecessary_cast)]
mod tests {
    use super::*;
    use crate::camera::Distortion;

    /// Machine epsilon of the precision under test, as `f64`.
    const EPS: f64 = Real::EPSILON as f64;

    /// Thesis plane of the reference design: e = 0.10 m, axis crossing at 1.5 m.
    fn thesis_plane() -> (LaserPlane, f64, f64) {
        let e = 0.10;
        let tilt = (0.10f64 / 1.5).atan();
        (
            LaserPlane::from_baseline_tilt(e as Real, tilt as Real).unwrap(),
            e,
            tilt,
        )
    }

    fn close(a: Vec3, b: [f64; 3], tol: f64) -> bool {
        (a.x as f64 - b[0]).abs() <= tol
            && (a.y as f64 - b[1]).abs() <= tol
            && (a.z as f64 - b[2]).abs() <= tol
    }

    #[test]
    fn baseline_tilt_geometry() {
        let (p, e, tilt) = thesis_plane();
        // n = (0, cos δ, sin δ), d = e cos δ, S = (0, e, 0).
        assert!(close(p.normal, [0.0, tilt.cos(), tilt.sin()], 4.0 * EPS));
        assert!((p.offset as f64 - e * tilt.cos()).abs() <= 4.0 * EPS * e);
        assert!(close(p.source, [0.0, e, 0.0], 4.0 * EPS));
        // Contains its source, the axis crossing (0, 0, e/tan δ) = (0, 0, 1.5), and the
        // x direction from there. Distances of O(1 m) points carry ~4 ε·1.5 m of rounding.
        let tol = 8.0 * EPS * 1.5;
        assert!((p.signed_distance(p.source) as f64).abs() <= tol);
        assert!((p.signed_distance(Vec3::new(0.0, 0.0, 1.5)) as f64).abs() <= tol);
        assert!((p.signed_distance(Vec3::new(0.7, 0.0, 1.5)) as f64).abs() <= tol);
        assert!((p.axis_crossing().unwrap() as f64 - 1.5).abs() <= tol);
        // The camera is on the negative side, a point below the plane line on the positive.
        assert!(p.signed_distance(Vec3::zeros()) < 0.0);
        // Inverse.
        let (e2, t2) = p.baseline_tilt();
        assert!((e2 as f64 - e).abs() <= 8.0 * EPS * e);
        assert!((t2 as f64 - tilt).abs() <= 8.0 * EPS);
        assert_eq!(p.roll(), 0.0);
    }

    #[test]
    fn baseline_tilt_roll_round_trip() {
        for &(e, t, r) in &[(0.1, 0.2, 0.3), (0.05, -0.4, -1.0), (0.3, 1.2, 2.5)] {
            let p = LaserPlane::from_baseline_tilt_roll(e, t, r).unwrap();
            let (e2, t2) = p.baseline_tilt();
            // asin near |δ| = 1.2 amplifies the rounding of n_z by 1/cos δ ≈ 2.8.
            assert!(((e2 - e) / e).abs() as f64 <= 16.0 * EPS, "{e} {e2}");
            assert!((t2 - t).abs() as f64 <= 16.0 * EPS, "{t} {t2}");
            assert!((p.roll() - r).abs() as f64 <= 16.0 * EPS, "{r}");
            // The source is at distance e from the camera, in the plane.
            assert!((p.source.norm() - e).abs() as f64 <= 4.0 * EPS);
        }
    }

    #[test]
    fn plane_through_three_known_points() {
        // x + 2y + 3z = 6 through its axis intercepts: n = (1,2,3)/√14, d = 6/√14.
        let p = LaserPlane::from_points(
            Vec3::new(6.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0),
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(0.0, 0.0, 2.0),
        )
        .unwrap();
        let s = 14f64.sqrt();
        assert!(close(p.normal, [1.0 / s, 2.0 / s, 3.0 / s], 8.0 * EPS));
        assert!((p.offset as f64 - 6.0 / s).abs() <= 16.0 * EPS * 6.0);
        // Collinear points: no plane.
        let c = LaserPlane::from_points(
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(0.0, 0.0, 3.0),
            Vec3::new(0.0, 0.0, 1.0),
        );
        assert_eq!(c, Err(LaserPlaneError::DegenerateNormal));
    }

    #[test]
    fn ray_plane_intersection_at_known_poses() {
        // Plane z = 2 given with a non-unit, inward normal: normalised and flipped.
        let p = LaserPlane::new(Vec3::new(0.0, 0.0, -3.0), -6.0, Vec3::new(0.5, 0.0, 2.0)).unwrap();
        assert_eq!(p.normal, Vec3::new(0.0, 0.0, 1.0));
        assert_eq!(p.offset, 2.0);
        let x = p.intersect_ray(Vec3::new(0.1, -0.2, 1.0)).unwrap();
        assert!(close(x, [0.2, -0.4, 2.0], 4.0 * EPS));
        // Thesis plane: the ray (0, y, 1) meets it at t = e / (y + tan δ).
        let (p, e, tilt) = thesis_plane();
        for &y in &[0.0, 0.05, 0.2] {
            let x = p.intersect_ray(Vec3::new(0.0, y as Real, 1.0)).unwrap();
            let t = e / (y + tilt.tan());
            // Relative rounding of a few ε, amplified by t ≤ 1.5 m.
            assert!(
                close(x, [0.0, y * t, t], 16.0 * EPS * 1.5),
                "{y}: {x:?} vs t = {t}"
            );
        }
    }

    #[test]
    fn intersection_error_cases() {
        let (p, _, tilt) = thesis_plane();
        // Along x: in a direction of the plane, parallel.
        assert_eq!(
            p.intersect_ray(Vec3::new(1.0, 0.0, 0.0)),
            Err(LaserPlaneError::RayParallel)
        );
        assert_eq!(
            p.intersect_ray(Vec3::zeros()),
            Err(LaserPlaneError::RayParallel)
        );
        assert_eq!(
            p.intersect_ray(Vec3::new(Real::NAN, 0.0, 1.0)),
            Err(LaserPlaneError::RayParallel)
        );
        // Above the plane's horizon (y < −tan δ) the ray meets the plane behind the camera.
        assert_eq!(
            p.intersect_ray(Vec3::new(0.0, -(2.0 * tilt.tan()) as Real, 1.0)),
            Err(LaserPlaneError::BehindCamera)
        );
        let z2 = LaserPlane::new(Vec3::new(0.0, 0.0, 1.0), 2.0, Vec3::new(0.0, 0.0, 2.0)).unwrap();
        assert_eq!(
            z2.intersect_ray(Vec3::new(0.0, 0.0, -1.0)),
            Err(LaserPlaneError::BehindCamera)
        );
    }

    #[test]
    fn construction_error_cases() {
        let s = Vec3::new(0.0, 0.0, 2.0);
        let z = Vec3::new(0.0, 0.0, 1.0);
        assert_eq!(
            LaserPlane::new(Vec3::zeros(), 2.0, s),
            Err(LaserPlaneError::DegenerateNormal)
        );
        assert_eq!(
            LaserPlane::new(Vec3::new(Real::NAN, 0.0, 1.0), 2.0, s),
            Err(LaserPlaneError::DegenerateNormal)
        );
        assert_eq!(
            LaserPlane::new(z, 0.0, Vec3::zeros()),
            Err(LaserPlaneError::CameraInPlane)
        );
        assert_eq!(
            LaserPlane::new(z, 2.0, Vec3::new(0.0, 0.0, 2.01)),
            Err(LaserPlaneError::SourceNotInPlane)
        );
        // A source 1 µm off the plane is projected onto it.
        let p = LaserPlane::new(z, 2.0, Vec3::new(0.3, 0.0, 2.000001)).unwrap();
        assert!((p.signed_distance(p.source) as f64).abs() <= 4.0 * EPS * 2.0);
        assert_eq!(
            LaserPlane::from_baseline_tilt(0.0, 0.1),
            Err(LaserPlaneError::InvalidBaseline)
        );
        assert_eq!(
            LaserPlane::from_baseline_tilt(-0.1, 0.1),
            Err(LaserPlaneError::InvalidBaseline)
        );
        assert_eq!(
            LaserPlane::from_baseline_tilt(0.1, 1.6),
            Err(LaserPlaneError::InvalidTilt)
        );
        assert_eq!(
            LaserPlane::from_baseline_tilt(0.1, Real::NAN),
            Err(LaserPlaneError::InvalidTilt)
        );
        let mut bad = thesis_plane().0;
        bad.normal *= 2.0;
        assert_eq!(bad.validate(), Err(LaserPlaneError::DegenerateNormal));
        assert_eq!(thesis_plane().0.validate(), Ok(()));
    }

    #[test]
    fn plane_coordinates() {
        let (p, e, tilt) = thesis_plane();
        let (a, b) = p.plane_axes();
        // Zero roll: a = x̂, b = (0, −sin δ, cos δ).
        assert!(close(a, [1.0, 0.0, 0.0], 4.0 * EPS));
        assert!(close(b, [0.0, -tilt.sin(), tilt.cos()], 4.0 * EPS));
        // The axis crossing is straight ahead of the source along b at √(e² + z0²).
        let q = p.to_plane_coords(Vec3::new(0.0, 0.0, 1.5));
        assert!(
            (q.x as f64).abs() <= 8.0 * EPS
                && (q.y as f64 - (e * e + 2.25).sqrt()).abs() <= 8.0 * EPS * 1.5
        );
        // Camera centre's foot: (0, e sin δ).
        let c = p.camera_centre_in_plane();
        assert!(
            (c.x as f64).abs() <= 4.0 * EPS && (c.y as f64 - e * tilt.sin()).abs() <= 8.0 * EPS
        );
        // Round trip and orthonormality for a rolled, generic plane.
        let p = LaserPlane::from_baseline_tilt_roll(0.12, 0.3, 0.4).unwrap();
        let (a, b) = p.plane_axes();
        assert!(
            (a.norm() - 1.0).abs() as f64 <= 4.0 * EPS
                && (b.norm() - 1.0).abs() as f64 <= 4.0 * EPS
        );
        assert!((a.dot(&b) as f64).abs() <= 4.0 * EPS);
        assert!(
            (a.dot(&p.normal) as f64).abs() <= 4.0 * EPS
                && (b.dot(&p.normal) as f64).abs() <= 4.0 * EPS
        );
        assert!(b.z > 0.0 && a.x > 0.0);
        let q = Vec2::new(-0.3, 1.7);
        let x = p.from_plane_coords(q);
        assert!((p.signed_distance(x) as f64).abs() <= 8.0 * EPS * 2.0);
        let q2 = p.to_plane_coords(x);
        assert!(((q2 - q).norm() as f64) <= 8.0 * EPS * 2.0);
        // Plane perpendicular to the optical axis: fallback axes still orthonormal.
        let f = LaserPlane::new(Vec3::new(0.0, 0.0, 1.0), 1.0, Vec3::new(0.0, 0.1, 1.0)).unwrap();
        let (a, b) = f.plane_axes();
        assert!(
            close(b, [0.0, -1.0, 0.0], 4.0 * EPS) && (a.norm() - 1.0).abs() as f64 <= 4.0 * EPS
        );
    }

    #[test]
    fn homography_is_the_ray_plane_map() {
        let p = LaserPlane::from_baseline_tilt_roll(0.1, 0.07, 0.2).unwrap();
        let g = p.plane_to_normalised_homography();
        let gi = p.normalised_to_plane_homography();
        let id = g * gi;
        for i in 0..3 {
            for j in 0..3 {
                let expect = if i == j { 1.0 } else { 0.0 };
                // det G = −d = −0.1: inversion loses up to ~|G|·|G⁻¹| ≈ 20/0.1 ulps.
                assert!((id[(i, j)] as f64 - expect).abs() <= 400.0 * EPS, "{id}");
            }
        }
        assert!((g.determinant() as f64 + p.offset as f64).abs() <= 16.0 * EPS);
        for &q in &[
            Vec2::new(0.2, 1.0),
            Vec2::new(-0.4, 2.5),
            Vec2::new(0.0, 0.5),
        ] {
            // Forward: plane point → its normalised image.
            let x = p.from_plane_coords(q);
            let h = g * Vec3::new(q.x, q.y, 1.0);
            assert!(((h / h.z - x / x.z).norm() as f64) <= 32.0 * EPS);
            // Backward: image → plane through the inverse equals the ray–plane intersection.
            let ray = x / x.z;
            let back = gi * ray;
            let q_h = Vec2::new(back.x / back.z, back.y / back.z);
            let q_i = p.to_plane_coords(p.intersect_ray(ray).unwrap());
            // In-plane metres at ≤ 2.5 m: ~ε·2.5·(condition ≈ 20).
            assert!(
                ((q_h - q).norm() as f64) <= 64.0 * EPS * 2.5,
                "{q_h:?} {q:?}"
            );
            assert!(
                ((q_i - q).norm() as f64) <= 64.0 * EPS * 2.5,
                "{q_i:?} {q:?}"
            );
        }
    }

    #[test]
    fn triangulate_recovers_points_of_the_plane() {
        let cam = Camera {
            distortion: Distortion {
                k1: -0.3,
                k2: 0.1,
                k3: -0.01,
                p1: 1e-3,
                p2: -1e-3,
            },
            cx: 371.2,
            cy: 244.8,
            ..Camera::reference_design()
        };
        let (p, _, _) = thesis_plane();
        for &q in &[
            Vec2::new(0.0, 1.0),
            Vec2::new(0.15, 0.6),
            Vec2::new(-0.3, 2.5),
            Vec2::new(0.05, 1.5),
        ] {
            let x = p.from_plane_coords(q);
            let px = cam.project(x).unwrap();
            let t = triangulate(&cam, &p, px).unwrap();
            // Error model: the ray carries ~1e-3 px-equivalent in f32 (≈ 8 ε (1 + |d|)
            // normalised incl. pixel rounding), i.e. an angle α ≈ 8 ε·1.5 rad; along the
            // plane the depth error is z²/(e cos δ)·α-ish → z²/e · α with z ≤ 2.5, e = 0.1.
            let z = x.z as f64;
            let tol = z * z / 0.1 * 16.0 * EPS * 1.5 + 8.0 * EPS * z;
            assert!(
                ((t - x).norm() as f64) <= tol,
                "{q:?}: {t:?} vs {x:?} (tol {tol})"
            );
        }
        // Above the plane's horizon: behind the camera. NaN pixel: camera error.
        assert_eq!(
            triangulate(&cam, &p, Vec2::new(375.0, 100.0)),
            Err(TriangulationError::Plane(LaserPlaneError::BehindCamera))
        );
        assert_eq!(
            triangulate(&cam, &p, Vec2::new(Real::NAN, 100.0)),
            Err(TriangulationError::Camera(CameraError::NonFinite))
        );
    }
}
