//! What a solver reports besides its number: which method produced it, quality flags, and the
//! stem's tilt. Shared by every solver mode, the pipeline, the wire protocol (the types are
//! serialised as they are) and the host.

#[allow(unused_imports)]
use crate::real::Float;
use crate::real::{norm, Real, Vec3};
use serde::{Deserialize, Serialize};

use crate::laser_plane::LaserPlane;

/// Which computation the reported diameter comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// Three-tangent method in one plane (transversal stem assumed).
    ThreeTangent,
    /// Robust geometric circle fit in one plane (transversal stem assumed).
    CircleFit,
    /// Cylinder fit to two or more planes' curves (tilt measured).
    CylinderFit,
    /// Three-tangent method on the curves projected along the fitted axis (tilt measured).
    GeneralisedThreeTangent,
    /// Sphere fitted to every point of every plane at once, σ-weighted (`docs/sphere.md`).
    JointFit,
    /// Sphere from the circle fits of its sections, `R² = rᵢ² + hᵢ²` (`docs/sphere.md`).
    SphereSections,
    /// Sphere from the three-tangent circles of its sections (`docs/sphere.md`).
    SphereThreeTangent,
    /// ISO 13473-1 mean profile depth of a road profile (`docs/road.md`).
    MeanProfileDepth,
    /// Walls by weighted principal components of the lines' points (`docs/building.md`).
    PlanePca,
}

/// Quality flags of a solution (a bit set; `Flags::ARC_TOO_SHORT.0 | …`). 32 bits: on the
/// wire (postcard's variable-length integers) a set whose bits all lie below 16 encodes as
/// it did when the set had 16 bits, so older messages and logs still read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Flags(pub u32);

impl Flags {
    /// The lit and visible arc spans less than `min_arc_angle` seen from the centre: the fit
    /// is poorly conditioned (the three-tangent result may still be good).
    pub const ARC_TOO_SHORT: Flags = Flags(1 << 0);
    /// The fit's residuals are well above the predicted point noise, or many points were
    /// rejected as outliers (bark, branches, a second object).
    pub const POOR_FIT: Flags = Flags(1 << 1);
    /// Only one plane: the stem is assumed transversal; a sideways lean `φ` inflates the
    /// diameter by `1/cos φ` (`docs/cylinder.md`, "Error when the tilt is ignored").
    pub const TILT_IGNORED: Flags = Flags(1 << 2);
    /// The methods disagree. Stem: the three-tangent and fit radii differ by more than 3σ
    /// combined (an edge is probably occluded or lost in the dark); the fit was reported.
    /// Sphere: the joint fit and the sections' sphere differ by more than 3σ combined (the
    /// reading's σ already carries any excess beyond 1σ, `docs/sphere.md`, "Methods that
    /// disagree"), or the sections' centres missed the sphere's axis and one sphere fitted
    /// to every line's points overruled them ("Sections that miss the axis").
    pub const INCONSISTENT: Flags = Flags(1 << 3);
    /// The three-tangent method failed (edges missing, too few points near the nearest
    /// point).
    pub const THREE_TANGENT_FAILED: Flags = Flags(1 << 4);
    /// The circle / cylinder fit failed.
    pub const FIT_FAILED: Flags = Flags(1 << 5);
    /// The stem is nearer or farther than the working range in the parameters.
    pub const RANGE_LIMIT: Flags = Flags(1 << 6);
    /// Two planes were given but the cylinder fit failed; the result is the one-plane
    /// solution of plane 0.
    pub const TILT_FIT_FAILED: Flags = Flags(1 << 7);
    /// The tilt exceeds `max_tilt`: the section is strongly elliptic and the result less
    /// reliable.
    pub const LARGE_TILT: Flags = Flags(1 << 8);
    /// Several objects: more than `max_outlier_fraction` of the points were rejected.
    pub const SEVERAL_OBJECTS: Flags = Flags(1 << 9);
    /// Image: more than 10 % of the curve's samples clipped at full scale; the subpixel
    /// estimator compensates, but exposure should come down (set by `pipeline`).
    pub const STRIPE_SATURATED: Flags = Flags(1 << 11);
    /// Image: the laser-off frame is brighter than half of full scale (sunlit bark): shot noise
    /// and a shallow stripe; readings are noisier (set by `pipeline`).
    pub const AMBIENT_BRIGHT: Flags = Flags(1 << 12);
    /// Image: another object of comparable size was seen beside the aimed one (a second
    /// trunk, a branch); the one nearest the central column was measured (set by `pipeline`).
    pub const OTHER_OBJECTS: Flags = Flags(1 << 13);
    /// The section is not round: a circle fit leaves a systematic residual pattern that an
    /// ellipse explains ([`super::ellipse::fit_ellipse`], `docs/cylinder.md`, "Elliptic stems"). The
    /// diameter is the mean of the fitted axes (as cross-calipering), its σ covers the unseen
    /// back, and [`super::stem::CylinderSolution::axes`] gives the two diameters.
    pub const ELLIPTIC: Flags = Flags(1 << 14);
    /// Sphere: a section lies near a pole (its radius below `pole_ratio·R`), where the
    /// sphere's radius rests on the section's distance from the centre alone
    /// (`docs/sphere.md`, "Near a pole").
    pub const NEAR_POLE: Flags = Flags(1 << 10);
    /// Sphere: the object fails the sphere test — its sections are not round, or do not lie
    /// on one sphere within their noise (`docs/sphere.md`, "Is it a sphere?").
    pub const NOT_SPHERICAL: Flags = Flags(1 << 15);
    /// Image: no threshold separated the stripe from the noise; the faint-stripe search
    /// (matched filter across the stripe, a track along it) found it
    /// (`docs/image-processing.md`, "Faint stripes"). Its points are weak and the reading is
    /// noisier and more often wrong than a thresholded one; its σ says by how much (set by
    /// `pipeline`).
    pub const FAINT_STRIPE: Flags = Flags(1 << 16);

    /// Whether every flag of `other` is set.
    pub fn contains(self, other: Flags) -> bool {
        self.0 & other.0 == other.0
    }
    /// Sets the flags of `other`.
    pub fn insert(&mut self, other: Flags) {
        self.0 |= other.0;
    }
    /// Whether no flag is set.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
}

/// Tilt of the stem axis relative to plane 0 (`docs/cylinder.md`, "Tilt angles").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tilt {
    /// Unit axis direction in the camera frame, oriented along the plane normal (`u·n > 0`).
    pub axis: Vec3,
    /// Lean in the `(b, n)` plane (towards/away from the instrument): `atan2(u·b, u·n)`.
    pub theta: Real,
    /// Sideways lean in the `(a, n)` plane: `atan2(u·a, u·n)`.
    pub phi: Real,
    /// Total angle between axis and plane normal: `acos(u·n)`.
    pub total: Real,
    /// Direction of the lean in the plane: `atan2(u·b, u·a)`.
    pub azimuth: Real,
    /// 1σ of the axis direction (radians).
    pub sigma: Real,
}

impl Tilt {
    /// Tilt angles of `axis` (any length, either sign) relative to `plane`.
    pub fn of(axis: Vec3, plane: &LaserPlane, sigma: Real) -> Tilt {
        let (a, b) = plane.plane_axes();
        let n = plane.normal;
        let mut u = axis / norm(&axis);
        if u.dot(&n) < 0.0 {
            u = -u;
        }
        let (ua, ub, un) = (u.dot(&a), u.dot(&b), u.dot(&n));
        Tilt {
            axis: u,
            theta: ub.atan2(un),
            phi: ua.atan2(un),
            total: un.clamp(-1.0, 1.0).acos(),
            azimuth: ub.atan2(ua),
            sigma,
        }
    }
}
