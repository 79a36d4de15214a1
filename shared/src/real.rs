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

/// Square root, correctly rounded: the core's one way to take it.
///
/// `Float::sqrt` (and nalgebra's `norm`) reach `libm`'s software square root in `no_std`
/// builds, about 50 instructions on the Cortex-M7, whose FPU has a correctly rounded
/// `VSQRT.F32` (same result: IEEE 754 requires correct rounding of both). In the `f32` build
/// with the feature `cortex-m7` on ARM it is that instruction (inline assembly: no stable
/// intrinsic reaches it); everywhere else `Float::sqrt`.
#[inline(always)]
pub fn sqrt(x: Real) -> Real {
    #[cfg(all(feature = "f32", feature = "cortex-m7", target_arch = "arm"))]
    {
        let r: f32;
        // SAFETY: VSQRT.F32 reads one FPU register and writes one; no memory or stack.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!(
                "vsqrt.f32 {r}, {x}",
                r = lateout(sreg) r,
                x = in(sreg) x,
                options(pure, nomem, nostack),
            );
        }
        r
    }
    #[cfg(not(all(feature = "f32", feature = "cortex-m7", target_arch = "arm")))]
    {
        Float::sqrt(x)
    }
}

/// The error function (`libm`'s; [`Float`] has none).
#[inline]
pub fn erf(x: Real) -> Real {
    #[cfg(feature = "f32")]
    {
        libm::erff(x)
    }
    #[cfg(not(feature = "f32"))]
    {
        libm::erf(x)
    }
}

/// The standard normal distribution function `Φ(z)`.
#[inline]
pub fn normal_cdf(z: Real) -> Real {
    0.5 * (1.0 + erf(z * core::f64::consts::FRAC_1_SQRT_2 as Real))
}

/// Euclidean norm of a vector through [`sqrt`] (nalgebra's `norm` takes `libm`'s).
#[inline(always)]
pub fn norm<const D: usize>(v: &nalgebra::SVector<Real, D>) -> Real {
    sqrt(v.norm_squared())
}

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
