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
//!        side view (x axis out of the page; y down, z forward)
//!
//!   y=0  C ●━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━━▶ z
//!          ┃  ▲                                        ___----   ● (0, 0, e/tan δ)
//!          ┃  │ e                            ___----‾‾‾           (axis crossing)
//!          ┃  ▼                   ___----‾‾‾
//!   y=e  S ●           ___----‾‾‾   laser plane, rising at angle δ
//!          ┃ ___----‾‾‾ δ           (contains the x direction)
//!          ▼ y    ‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾‾ (parallel to z)
//! ```
//!
//! Every pixel of the laser curve then maps to one 3-D point: the pixel's ray meets the
//! plane once ([`LaserPlane::intersect_ray`], [`triangulate`]). For undistorted image
//! coordinates the map image ↔ plane is a homography
//! ([`LaserPlane::plane_to_normalised_homography`]). Derivations: `docs/laser-plane.md`.

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::camera::{Camera, CameraError};
use crate::real::{Float, Mat3, Real, Vec2, Vec3, PI};

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
            LaserPlaneError::DegenerateNormal => write!(f, "laser-plane normal is zero or not finite"),
            LaserPlaneError::SourceNotInPlane => {
                write!(f, "laser source point is not in the laser plane")
            }
            LaserPlaneError::CameraInPlane => write!(
                f,
                "laser plane passes through the camera centre (or offset not finite)"
            ),
            LaserPlaneError::InvalidBaseline => write!(f, "laser baseline must be finite and positive"),
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
    /// Builds a plane `normal·X = offset` with emission point `source`.
    ///
    /// Normalises `normal` (dividing `offset` by its length), flips both so that the
    /// offset is positive, and projects `source` onto the plane if it is at most
    /// [`SOURCE_IN_PLANE_TOLERANCE`] away (rejecting it otherwise).
    pub fn new(normal: Vec3, offset: Real, source: Vec3) -> Result<Self, LaserPlaneError> {
        let len = normal.norm();
        if !(len.is_finite() && len > Real::MIN_POSITIVE.sqrt()) {
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
        if !(gap.abs() <= SOURCE_IN_PLANE_TOLERANCE) {
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
        let scale = a.norm() * b.norm();
        if !(scale.is_finite() && n.norm() > Real::EPSILON.sqrt() * scale) {
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
        let cos_tilt = (self.normal.x * self.normal.x + self.normal.y * self.normal.y).sqrt();
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
        let len = self.normal.norm();
        if !(len.is_finite() && (len - 1.0).abs() <= 1e-4) {
            return Err(LaserPlaneError::DegenerateNormal);
        }
        if !(self.offset.is_finite() && self.offset >= MIN_PLANE_OFFSET) {
            return Err(LaserPlaneError::CameraInPlane);
        }
        let gap = self.signed_distance(self.source);
        if !(gap.abs() <= SOURCE_IN_PLANE_TOLERANCE) {
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
    pub fn intersect_ray(&self, ray: Vec3) -> Result<Vec3, LaserPlaneError> {
        let len = ray.norm();
        if !(len.is_finite() && len > 0.0) {
            return Err(LaserPlaneError::RayParallel);
        }
        let denom = self.normal.dot(&ray);
        if !(denom.abs() > 16.0 * Real::EPSILON * len) {
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
        let b = b_raw / b_raw.norm();
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
pub fn triangulate(
    camera: &Camera,
    plane: &LaserPlane,
    pixel: Vec2,
) -> Result<Vec3, TriangulationError> {
    let ray = camera.pixel_to_ray(pixel)?;
    Ok(plane.intersect_ray(ray)?)
}
