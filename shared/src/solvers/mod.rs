//! Solvers: from the 3-D points of one capture to a dimension (thesis chapter 9 onwards).
//!
//! Methods, lowest first (each module uses only those above it in this list):
//!
//! * [`lm`]: the one Levenberg–Marquardt minimiser every geometric fit states its problem to
//!   (a [`lm::LeastSquares`] trait with a const-generic parameter count).
//! * [`circle`]: algebraic (Hyper, and Kåsa as the naive baseline) and geometric (plain,
//!   robust) circle fits on 2-D points, and their radius σ (`docs/cylinder.md`, "Circle fits").
//! * [`ellipse`]: the ellipse fit and score test for non-round sections (`docs/cylinder.md`,
//!   "Elliptic stems").
//! * [`cylinder_fit`]: cylinder (axis and radius) fit to the curves of two or more planes, and
//!   the projection along its axis (`docs/cylinder.md`, "Randomly tilted stem").
//! * [`three_tangent`]: the three-tangent method, plain and generalised (`docs/cylinder.md`,
//!   "Three-tangent method").
//! * [`result`]: what every solver reports besides its number — [`result::Method`],
//!   [`result::Flags`], [`result::Tilt`].
//! * [`sphere_sections`], [`sphere_three_tangent`], [`sphere_fit`]: a sphere from its planar
//!   sections (circle fits or the three-tangent construction) and the joint fit to every point
//!   (`docs/sphere.md`); [`sphere`]: the sphere of one capture — the methods' σ, the choice,
//!   the flags and refusals.
//! * [`stem`]: the stem diameter of one capture — the methods' σ, the choice of the reported
//!   diameter, the flags (`docs/cylinder.md`, "Choosing the method").
//!
//! Solvers read each point's 1σ beside the point (written by the pipeline from
//! [`crate::noise`]); nothing here calls back up into the pipeline or the error model.
//!
//! Every solver works on caller-owned slices, never allocates and returns a [`SolveError`]
//! instead of a made-up number when the data cannot support an answer.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN, which `x <= 0.0` would let
// through (no panics or made-up numbers on bad data).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::fmt;

pub mod circle;
pub mod correlation;
pub mod cylinder_fit;
pub mod ellipse;
pub mod lm;
pub mod mpd;
pub mod plane_pca;
pub mod result;
pub mod road_profile;
pub mod sphere;
pub mod sphere_fit;
pub mod sphere_sections;
pub mod sphere_three_tangent;
pub mod stem;
pub mod three_tangent;
pub mod walls;

/// Why a solver could not produce a trustworthy answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveError {
    /// Fewer points than the model needs (3 for a circle, 5 for an ellipse or a cylinder,
    /// more for the local fits of the three-tangent method).
    TooFewPoints,
    /// An input point or parameter is NaN or infinite.
    NonFinite,
    /// The points do not determine the model: collinear or coincident points, a singular
    /// normal matrix, a source inside the section.
    Degenerate,
    /// An iterative fit did not converge within its iteration budget.
    NotConverged,
    /// A caller-provided scratch buffer is shorter than the number of points.
    ScratchTooSmall,
    /// The lit and visible arc is too short (in angle seen from its centre) for the radius
    /// to be trusted (see `docs/cylinder.md`, "Choosing the method").
    ArcTooShort,
    /// The reading's 1σ is above a third of its size: its 3σ interval reaches zero, so it
    /// does not bound the object (`docs/cylinder.md` §6, rule 3, for any arc).
    Unbounded,
    /// The solved radius is outside the plausible range given in the parameters.
    RadiusOutOfRange,
    /// A parameter is out of its documented domain (negative tolerance, zero iterations, …).
    InvalidParameter,
    /// The input has no or too many laser planes for the requested solution.
    PlaneCount,
    /// The section is detectably not round and one view cannot resolve its axes: measure
    /// across two directions (`docs/cylinder.md`, "Elliptic stems").
    NotRound,
    /// Only one laser plane's curve crosses the object: a sphere's radius is not observable
    /// from one section (`docs/sphere.md`, "One section").
    OneSection,
    /// The sections cannot belong to one sphere: straight, not round, or shapeless (a flat or
    /// elongated object; `docs/sphere.md`, "Is it a sphere?").
    NotSpherical,
    /// Each laser line lies on a round arc, but the arcs do not share one centre: the lines
    /// fall on different objects (`docs/sphere.md`, "Two balls in view").
    TwoObjects,
    /// Every straight run of the lit points lies on one laser line: a plane needs points
    /// off that line (`docs/building.md`, "One line is not a plane").
    SingleLine,
    /// No plane fits: the lit surface is curved, or the lines fall on different objects.
    NotPlanar,
}

impl fmt::Display for SolveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            SolveError::TooFewPoints => "too few points for the model",
            SolveError::NonFinite => "non-finite point or parameter",
            SolveError::Degenerate => "points do not determine the model (collinear or singular)",
            SolveError::NotConverged => "iterative fit did not converge",
            SolveError::ScratchTooSmall => "scratch buffer shorter than the point count",
            SolveError::ArcTooShort => {
                "visible arc too short: the circle fit's σ exceeds a third of its radius"
            }
            SolveError::Unbounded => {
                "the reading does not bound the size: its σ exceeds a third of the diameter (a \
                 faint, short or broken stripe); aim again, nearer"
            }
            SolveError::RadiusOutOfRange => "radius outside the plausible range",
            SolveError::InvalidParameter => "solver parameter out of range",
            SolveError::PlaneCount => "wrong number of laser planes for this solution",
            SolveError::NotRound => "section not round: measure across two directions",
            SolveError::OneSection => {
                "fewer than two laser lines cross the object: a sphere's size needs both lines on \
                 it (centre the ball between the two lines, 0.6–1.5 m away)"
            }
            SolveError::NotSpherical => {
                "not a ball: the laser lines are not arcs of one sphere (straight, elliptic or \
                 shapeless sections: a flat or elongated object)"
            }
            SolveError::TwoObjects => {
                "two objects in view: the laser lines fall on different objects (round sections \
                 that do not share a centre); aim at one ball with nothing else across the lines"
            }
            SolveError::SingleLine => {
                "only one laser line lies on the surface: a plane needs two (aim so that both lines cross the wall)"
            }
            SolveError::NotPlanar => {
                "the lit surface is not flat (curved, or the lines fall on different objects): no wall plane fits"
            }
        };
        f.write_str(s)
    }
}

#[cfg(feature = "std")]
impl std::error::Error for SolveError {}
