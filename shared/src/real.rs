//! The scalar type of the measurement core.
//!
//! The core computes in `f64` on the host and in `f32` on the Cortex-M7 (feature `f32`), with
//! the same source. Transcendental functions come from [`num_traits::Float`], which maps to
//! `std` on the host and to `libm` in `no_std` builds, so the same code runs in both places.

/// Scalar used for every geometric quantity (metres, radians, pixels).
#[cfg(not(feature = "f32"))]
pub type Real = f64;
/// Scalar used for every geometric quantity (metres, radians, pixels).
#[cfg(feature = "f32")]
pub type Real = f32;

pub use num_traits::Float;

/// π in the core's precision.
pub const PI: Real = core::f64::consts::PI as Real;

/// Machine epsilon of [`Real`].
pub const EPSILON: Real = Real::EPSILON;

/// A 2-D vector (pixels or in-plane metres) in the core's precision.
pub type Vec2 = nalgebra::Vector2<Real>;
/// A 3-D vector (metres, camera frame unless said otherwise) in the core's precision.
pub type Vec3 = nalgebra::Vector3<Real>;
/// A 3×3 matrix in the core's precision.
pub type Mat3 = nalgebra::Matrix3<Real>;
