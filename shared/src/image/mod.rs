//! Frames and the image-processing chain (thesis chapter 5).
//!
//! A [`Frame`] is 8-bit or 16-bit pixels in any storage (a borrowed slice, a mutable slice, a
//! `Vec`, an array) with a width, a height and a row stride (in pixels), so that a DMA buffer, a
//! window of a larger image or a host `Vec` can all be viewed without copying. Pixel `(x, y)` is at `data[y * stride + x]`; `x` is the column
//! (right), `y` the row (down). The centre of pixel `(x, y)` has image coordinates `(x, y)`.

use core::fmt;
use core::marker::PhantomData;

// The speckle filter is kept for tests only: on the device it would cost ≈ 20 M instructions per
// 752×480 frame (docs/image-processing.md, "Cost"), 4–7 times the whole measurement, while
// `curve::smooth` already averages the speckle jitter along the curve at almost no cost
// (docs/subpixel.md §8); the full-frame chain test (`select`) still exercises it.
#[cfg(test)]
pub(crate) mod filter;
mod lanes;
pub mod segment;
pub mod select;
pub mod subtract;
pub mod threshold;

/// A pixel type the pipeline accepts: `u8` (8-bit sensors) or `u16` (10/12/16-bit sensors).
pub trait Pixel: Copy + Default + Ord + Into<u32> + fmt::Debug + 'static {
    /// Bits of the storage type (8 or 16).
    const STORAGE_BITS: u8;
    /// The value 0 (usable in `const` buffer initialisers).
    const ZERO: Self;
    /// Converts from `u32`, saturating at the storage type's maximum.
    fn saturate_from(v: u32) -> Self;
}

impl Pixel for u8 {
    const STORAGE_BITS: u8 = 8;
    const ZERO: Self = 0;
    #[inline]
    fn saturate_from(v: u32) -> Self {
        if v > u8::MAX as u32 {
            u8::MAX
        } else {
            v as u8
        }
    }
}

impl Pixel for u16 {
    const STORAGE_BITS: u8 = 16;
    const ZERO: Self = 0;
    #[inline]
    fn saturate_from(v: u32) -> Self {
        if v > u16::MAX as u32 {
            u16::MAX
        } else {
            v as u16
        }
    }
}

/// Why a buffer cannot be viewed as a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// Width or height is zero.
    Empty,
    /// The stride is smaller than the width.
    StrideTooSmall {
        /// Frame width in pixels.
        width: usize,
        /// Row stride in pixels.
        stride: usize,
    },
    /// The buffer holds fewer pixels than `(height - 1) * stride + width`.
    BufferTooSmall {
        /// Pixels needed.
        needed: usize,
        /// Pixels in the buffer.
        actual: usize,
    },
    /// The bit depth is zero or larger than the storage type.
    BadBitDepth(u8),
    /// Two frames that must have the same size do not.
    SizeMismatch {
        /// `(width, height)` of the first frame.
        expected: (usize, usize),
        /// `(width, height)` of the second frame.
        actual: (usize, usize),
    },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::Empty => write!(f, "frame has zero width or height"),
            FrameError::StrideTooSmall { width, stride } => {
                write!(f, "row stride {stride} is smaller than the width {width}")
            }
            FrameError::BufferTooSmall { needed, actual } => {
                write!(f, "frame buffer holds {actual} pixels, {needed} needed")
            }
            FrameError::BadBitDepth(b) => {
                write!(f, "bit depth {b} is not supported by the pixel type")
            }
            FrameError::SizeMismatch { expected, actual } => write!(
                f,
                "frame is {}x{}, expected {}x{}",
                actual.0, actual.1, expected.0, expected.1
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for FrameError {}

fn check_layout(len: usize, width: usize, height: usize, stride: usize) -> Result<(), FrameError> {
    if width == 0 || height == 0 {
        return Err(FrameError::Empty);
    }
    if stride < width {
        return Err(FrameError::StrideTooSmall { width, stride });
    }
    let needed = (height - 1)
        .checked_mul(stride)
        .and_then(|n| n.checked_add(width))
        .ok_or(FrameError::BufferTooSmall {
            needed: usize::MAX,
            actual: len,
        })?;
    if len < needed {
        return Err(FrameError::BufferTooSmall {
            needed,
            actual: len,
        });
    }
    Ok(())
}

fn check_bit_depth<P: Pixel>(bits: u8) -> Result<(), FrameError> {
    if bits == 0 || bits > P::STORAGE_BITS {
        Err(FrameError::BadBitDepth(bits))
    } else {
        Ok(())
    }
}

/// A frame: pixels in any storage `S` that can be viewed as a slice of `P` (a borrowed
/// `&[P]`, a `&mut [P]` written in place, a `Vec<P>`, an array), with a width, a height, a row
/// stride and a bit depth — smoltcp's `Packet<T: AsRef<[u8]>>` pattern. The read methods need
/// `S: AsRef<[P]>`, the write methods `S: AsMut<[P]>`.
///
/// ```
/// use tangent_core::image::Frame;
///
/// // A 3 × 2 frame of a 10-bit sensor stored in `u16`, rows 4 pixels apart.
/// let pixels: [u16; 8] = [1, 2, 3, 0, 4, 5, 1023, 0];
/// let frame = Frame::new(&pixels[..], 3, 2, 4)?.with_bit_depth(10)?;
/// assert_eq!(frame.row(1), &[4, 5, 1023]);
/// assert_eq!(frame.max_value(), 1023);
///
/// // Owned, mutable storage: written row by row.
/// let mut out = Frame::new([0u8; 6], 3, 2, 3)?;
/// out.row_mut(0).copy_from_slice(&[7, 8, 9]);
/// assert_eq!(out.get(2, 0), Some(9));
/// # Ok::<(), tangent_core::image::FrameError>(())
/// ```
#[derive(Debug, Clone, Copy)]
pub struct Frame<P: Pixel, S> {
    data: S,
    width: usize,
    height: usize,
    stride: usize,
    bit_depth: u8,
    pixel: PhantomData<P>,
}

impl<P: Pixel, S> Frame<P, S> {
    /// Declares the sensor's bit depth (e.g. 10 for a 10-bit sensor stored in `u16`), which sets
    /// the saturation level [`Frame::max_value`].
    pub fn with_bit_depth(mut self, bits: u8) -> Result<Self, FrameError> {
        check_bit_depth::<P>(bits)?;
        self.bit_depth = bits;
        Ok(self)
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Row stride in pixels.
    pub fn stride(&self) -> usize {
        self.stride
    }
    /// Sensor bit depth.
    pub fn bit_depth(&self) -> u8 {
        self.bit_depth
    }
    /// Largest value a pixel can take: `2^bit_depth - 1` (the saturation level).
    pub fn max_value(&self) -> u32 {
        (1u32 << self.bit_depth) - 1
    }
    /// Checks that `other` has the same width and height.
    pub fn check_same_size<Q: Pixel, T>(&self, other: &Frame<Q, T>) -> Result<(), FrameError> {
        if self.width == other.width && self.height == other.height {
            Ok(())
        } else {
            Err(FrameError::SizeMismatch {
                expected: (self.width, self.height),
                actual: (other.width, other.height),
            })
        }
    }
}

impl<P: Pixel, S: AsRef<[P]>> Frame<P, S> {
    /// Views `data` as a `width × height` frame whose rows start every `stride` pixels.
    /// The bit depth is that of the storage type; see [`Frame::with_bit_depth`].
    pub fn new(data: S, width: usize, height: usize, stride: usize) -> Result<Self, FrameError> {
        check_layout(data.as_ref().len(), width, height, stride)?;
        Ok(Frame {
            data,
            width,
            height,
            stride,
            bit_depth: P::STORAGE_BITS,
            pixel: PhantomData,
        })
    }

    /// Row `y` (`width` pixels). Panics if `y >= height` (a programming error, not bad data).
    pub fn row(&self, y: usize) -> &[P] {
        let start = y * self.stride;
        &self.data.as_ref()[start..start + self.width]
    }
    /// Pixel `(x, y)`, or `None` outside the frame.
    pub fn get(&self, x: usize, y: usize) -> Option<P> {
        if x < self.width && y < self.height {
            Some(self.data.as_ref()[y * self.stride + x])
        } else {
            None
        }
    }
    /// A borrowed, read-only view of the same pixels.
    pub fn view(&self) -> Frame<P, &[P]> {
        Frame {
            data: self.data.as_ref(),
            width: self.width,
            height: self.height,
            stride: self.stride,
            bit_depth: self.bit_depth,
            pixel: PhantomData,
        }
    }
}

impl<P: Pixel, S: AsMut<[P]>> Frame<P, S> {
    /// Row `y`, mutable. Panics if `y >= height`.
    pub fn row_mut(&mut self, y: usize) -> &mut [P] {
        let start = y * self.stride;
        &mut self.data.as_mut()[start..start + self.width]
    }
    /// Row `y - 1` (read-only) together with row `y` (mutable), for one-pass neighbourhood
    /// algorithms that write a row while reading the previous one (segmentation). `None` if
    /// `y == 0` or `y >= height`.
    pub fn previous_and_row_mut(&mut self, y: usize) -> Option<(&[P], &mut [P])> {
        if y == 0 || y >= self.height {
            return None;
        }
        let (head, tail) = self.data.as_mut().split_at_mut(y * self.stride);
        let prev_start = (y - 1) * self.stride;
        let prev = head.get(prev_start..prev_start + self.width)?;
        let cur = tail.get_mut(..self.width)?;
        Some((prev, cur))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_layouts() {
        let buf = [0u8; 10];
        assert_eq!(Frame::new(&buf, 0, 1, 1).unwrap_err(), FrameError::Empty);
        assert_eq!(
            Frame::new(&buf, 4, 2, 3).unwrap_err(),
            FrameError::StrideTooSmall {
                width: 4,
                stride: 3
            }
        );
        assert_eq!(
            Frame::new(&buf, 4, 3, 4).unwrap_err(),
            FrameError::BufferTooSmall {
                needed: 12,
                actual: 10
            }
        );
        // The last row need not be padded to the stride.
        assert!(Frame::new(&buf, 4, 2, 6).is_ok());
        assert_eq!(
            Frame::new(&buf, 2, 2, 2)
                .unwrap()
                .with_bit_depth(9)
                .unwrap_err(),
            FrameError::BadBitDepth(9)
        );
    }

    #[test]
    fn strided_rows_and_saturation_level() {
        let buf: [u16; 8] = [1, 2, 9, 9, 3, 4, 9, 9];
        let f = Frame::new(&buf, 2, 2, 4)
            .unwrap()
            .with_bit_depth(10)
            .unwrap();
        assert_eq!(f.row(1), &[3, 4]);
        assert_eq!(f.get(1, 1), Some(4));
        assert_eq!(f.get(2, 0), None);
        assert_eq!(f.max_value(), 1023);
    }
}
