//! Binary PGM (Netpbm `P5`) frames, 8-bit and 16-bit.
//!
//! The format (Netpbm's `pgm(5)`): the magic `P5`, whitespace, the width, whitespace, the
//! height, whitespace, the maximum value `maxval` (1…65535) in ASCII decimal, then **exactly
//! one** whitespace character, then the raster: `height` rows of `width` samples, row-major,
//! top row first. Samples are one byte when `maxval < 256`, otherwise two bytes,
//! **most significant byte first** (big-endian). A `#` starts a comment that runs to the end
//! of the line; comments may appear anywhere in the header before the maxval.
//!
//! Why hand-written: the `image` crate's PNM decoder hides the maxval (it rescales), gives one
//! generic error for every malformation, and we need the exact errors of `docs/formats.md`
//! (bad magic, truncated raster with byte counts, maxval out of range, trailing data) and the
//! raw 10-bit samples untouched. The format is 30 lines of parsing.

use std::io::{Read, Write};
use std::path::Path;

/// The longest header (magic, numbers, comments) [`Pgm::read`] looks at before the raster:
/// a file's size is then known from its header alone, and only that much is read.
pub const MAX_HEADER_BYTES: u64 = 64 * 1024;

/// Why a PGM file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum PgmError {
    /// The file does not start with `P5` (binary greymap).
    #[error("bad magic number {found:?}: a binary PGM starts with \"P5\"")]
    BadMagic {
        /// The first two bytes found (lossily decoded).
        found: String,
    },
    /// A header field (width, height or maxval) is missing, not a decimal number, or zero.
    #[error("bad PGM header: {field} is missing, zero or not a decimal number")]
    BadHeader {
        /// Which field: `"width"`, `"height"` or `"maxval"`.
        field: &'static str,
    },
    /// `maxval` is outside 1…65535.
    #[error("PGM maxval {0} is outside 1..=65535")]
    BadMaxval(u64),
    /// The raster is shorter than `width × height × bytes per sample`.
    #[error("truncated PGM raster: expected {expected} bytes, found {actual}")]
    Truncated {
        /// Raster bytes the header promises.
        expected: usize,
        /// Raster bytes present.
        actual: usize,
    },
    /// Bytes follow the raster (a second image, or a wrong header).
    #[error("{0} unexpected bytes after the PGM raster")]
    TrailingData(usize),
    /// A sample exceeds the declared `maxval`.
    #[error("PGM sample {value} at pixel ({x}, {y}) exceeds maxval {maxval}")]
    SampleAboveMaxval {
        /// Column of the offending sample.
        x: usize,
        /// Row of the offending sample.
        y: usize,
        /// The sample.
        value: u16,
        /// The declared maxval.
        maxval: u16,
    },
    /// The image is too large to address (width × height overflows).
    #[error("PGM size {width}x{height} is too large")]
    TooLarge {
        /// Declared width.
        width: u64,
        /// Declared height.
        height: u64,
    },
    /// The samples given to the writer do not match `width × height`, or a sample exceeds
    /// the maxval, or the maxval is 0.
    #[error("cannot write PGM: {0}")]
    InvalidImage(String),
    /// The header declares another size than the caller expects ([`Pgm::read_expecting`]);
    /// the raster was not read.
    #[error("PGM size {}x{} differs from the expected {}x{}", .actual.0, .actual.1, .expected.0, .expected.1)]
    UnexpectedSize {
        /// `(width, height)` expected.
        expected: (usize, usize),
        /// `(width, height)` in the header.
        actual: (usize, usize),
    },
    /// The path is not a regular file (a FIFO, a device, a directory): reading it could
    /// block forever or never end, so it is refused before it is opened.
    #[error("{path}: not a regular file")]
    NotAFile {
        /// The path.
        path: String,
    },
    /// Reading or writing the file failed. The message names the file and the cause once
    /// (the cause is not also a `source()`, so an error chain does not print it twice).
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        error: std::io::Error,
    },
}

/// The samples of a greymap: one byte per sample (`maxval < 256`) or two.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PgmSamples {
    /// `maxval ≤ 255`.
    U8(Vec<u8>),
    /// `maxval ≥ 256` (big-endian in the file, native here).
    U16(Vec<u16>),
}

/// A greymap: size, maxval, and the samples row-major, top row first.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pgm {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The maximum sample value (`2^bits − 1` for a `bits`-bit sensor).
    pub maxval: u16,
    /// The samples.
    pub samples: PgmSamples,
}

impl Pgm {
    /// An 8-bit greymap (`maxval` ≤ 255).
    pub fn from_u8(
        width: usize,
        height: usize,
        maxval: u8,
        data: Vec<u8>,
    ) -> Result<Self, PgmError> {
        let pgm = Pgm {
            width,
            height,
            maxval: maxval as u16,
            samples: PgmSamples::U8(data),
        };
        pgm.check()?;
        Ok(pgm)
    }

    /// A 16-bit-storage greymap (`maxval` ≥ 256, e.g. 1023 for 10-bit data).
    pub fn from_u16(
        width: usize,
        height: usize,
        maxval: u16,
        data: Vec<u16>,
    ) -> Result<Self, PgmError> {
        let pgm = Pgm {
            width,
            height,
            maxval,
            samples: PgmSamples::U16(data),
        };
        pgm.check()?;
        Ok(pgm)
    }

    /// Bits per sample the maxval implies: the smallest `b` with `2^b − 1 ≥ maxval`.
    pub fn bit_depth(&self) -> u8 {
        (16 - self.maxval.leading_zeros()) as u8
    }

    /// Sample at column `x`, row `y` (as `u16`), or `None` outside the image.
    pub fn get(&self, x: usize, y: usize) -> Option<u16> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = y * self.width + x;
        match &self.samples {
            PgmSamples::U8(d) => d.get(i).map(|&v| v as u16),
            PgmSamples::U16(d) => d.get(i).copied(),
        }
    }

    /// The samples widened to `u16` (a copy).
    pub fn to_u16(&self) -> Vec<u16> {
        match &self.samples {
            PgmSamples::U8(d) => d.iter().map(|&v| v as u16).collect(),
            PgmSamples::U16(d) => d.clone(),
        }
    }

    fn check(&self) -> Result<(), PgmError> {
        if self.maxval == 0 {
            return Err(PgmError::InvalidImage("maxval is 0".into()));
        }
        let n = self
            .width
            .checked_mul(self.height)
            .ok_or(PgmError::TooLarge {
                width: self.width as u64,
                height: self.height as u64,
            })?;
        if self.width == 0 || self.height == 0 {
            return Err(PgmError::InvalidImage("zero width or height".into()));
        }
        let (len, wide) = match &self.samples {
            PgmSamples::U8(d) => (d.len(), false),
            PgmSamples::U16(d) => (d.len(), true),
        };
        if len != n {
            return Err(PgmError::InvalidImage(format!(
                "{len} samples for a {}x{} image",
                self.width, self.height
            )));
        }
        if wide != (self.maxval > 255) {
            return Err(PgmError::InvalidImage(format!(
                "maxval {} needs {}-byte samples",
                self.maxval,
                if self.maxval > 255 { 2 } else { 1 }
            )));
        }
        if let Some((i, v)) = self.first_above_maxval() {
            return Err(PgmError::SampleAboveMaxval {
                x: i % self.width,
                y: i / self.width,
                value: v,
                maxval: self.maxval,
            });
        }
        Ok(())
    }

    fn first_above_maxval(&self) -> Option<(usize, u16)> {
        let m = self.maxval;
        match &self.samples {
            PgmSamples::U8(d) => d
                .iter()
                .position(|&v| v as u16 > m)
                .map(|i| (i, d[i] as u16)),
            PgmSamples::U16(d) => d.iter().position(|&v| v > m).map(|i| (i, d[i])),
        }
    }

    /// Parses a `P5` file's bytes. Never panics; every malformation is a [`PgmError`].
    pub fn decode(bytes: &[u8]) -> Result<Self, PgmError> {
        let header = Header::parse(bytes)?;
        let (pos, expected) = (header.raster_start, header.raster_bytes);
        let raster = &bytes[pos..];
        if raster.len() < expected {
            return Err(PgmError::Truncated {
                expected,
                actual: raster.len(),
            });
        }
        if raster.len() > expected {
            return Err(PgmError::TrailingData(raster.len() - expected));
        }
        let samples = if header.maxval > 255 {
            PgmSamples::U16(
                raster
                    .chunks_exact(2)
                    .map(|c| u16::from_be_bytes([c[0], c[1]]))
                    .collect(),
            )
        } else {
            PgmSamples::U8(raster.to_vec())
        };
        let pgm = Pgm {
            width: header.width,
            height: header.height,
            maxval: header.maxval,
            samples,
        };
        if let Some((i, v)) = pgm.first_above_maxval() {
            return Err(PgmError::SampleAboveMaxval {
                x: i % pgm.width,
                y: i / pgm.width,
                value: v,
                maxval: pgm.maxval,
            });
        }
        Ok(pgm)
    }

    /// Serialises as `P5`: header `"P5\n<w> <h>\n<maxval>\n"`, then the raster
    /// (16-bit samples big-endian).
    pub fn encode(&self) -> Result<Vec<u8>, PgmError> {
        self.check()?;
        let header = format!("P5\n{} {}\n{}\n", self.width, self.height, self.maxval);
        let mut out = Vec::with_capacity(header.len() + self.width * self.height * 2);
        out.extend_from_slice(header.as_bytes());
        match &self.samples {
            PgmSamples::U8(d) => out.extend_from_slice(d),
            PgmSamples::U16(d) => d
                .iter()
                .for_each(|v| out.extend_from_slice(&v.to_be_bytes())),
        }
        Ok(out)
    }

    /// Reads and decodes a file, reading no more than its header promises.
    ///
    /// Only regular files are read (a FIFO or a device is refused before it is opened, so a
    /// read cannot block forever). The header is parsed from the first
    /// [`MAX_HEADER_BYTES`]; a file whose size differs from header + raster is refused from
    /// its size alone, and the raster is read with one byte to spare, so a file that grows
    /// while it is read is refused as [`PgmError::TrailingData`] rather than read whole.
    pub fn read(path: &Path) -> Result<Self, PgmError> {
        Self::read_bounded(path, None)
    }

    /// [`Pgm::read`] of a frame that must be `width × height`: a header declaring another
    /// size is refused as [`PgmError::UnexpectedSize`] before the raster is read, so the
    /// memory a read takes is bounded by what the caller expects, not by the file.
    pub fn read_expecting(path: &Path, width: usize, height: usize) -> Result<Self, PgmError> {
        Self::read_bounded(path, Some((width, height)))
    }

    fn read_bounded(path: &Path, expected: Option<(usize, usize)>) -> Result<Self, PgmError> {
        let io = |error| PgmError::Io {
            path: path.display().to_string(),
            error,
        };
        let meta = std::fs::metadata(path).map_err(io)?;
        if !meta.is_file() {
            return Err(PgmError::NotAFile {
                path: path.display().to_string(),
            });
        }
        let file_len = meta.len();
        let mut file = std::fs::File::open(path).map_err(io)?;
        let mut bytes = Vec::new();
        (&mut file)
            .take(file_len.min(MAX_HEADER_BYTES))
            .read_to_end(&mut bytes)
            .map_err(io)?;
        let header = Header::parse(&bytes)?;
        if let Some(expected) = expected {
            let actual = (header.width, header.height);
            if actual != expected {
                return Err(PgmError::UnexpectedSize { expected, actual });
            }
        }
        let promised = header.raster_start as u64 + header.raster_bytes as u64;
        if file_len < promised {
            return Err(PgmError::Truncated {
                expected: header.raster_bytes,
                actual: (file_len - header.raster_start as u64) as usize,
            });
        }
        if file_len > promised {
            return Err(PgmError::TrailingData(
                usize::try_from(file_len - promised).unwrap_or(usize::MAX),
            ));
        }
        // The size checked out: read the rest, one byte more than promised at most.
        let remaining = (promised + 1).saturating_sub(bytes.len() as u64);
        bytes.reserve(usize::try_from(remaining).unwrap_or(0));
        file.take(remaining).read_to_end(&mut bytes).map_err(io)?;
        Self::decode(&bytes)
    }

    /// Encodes and writes a file.
    pub fn write(&self, path: &Path) -> Result<(), PgmError> {
        let bytes = self.encode()?;
        let io = |error| PgmError::Io {
            path: path.display().to_string(),
            error,
        };
        let mut f = std::fs::File::create(path).map_err(io)?;
        f.write_all(&bytes).map_err(io)
    }
}

/// What a `P5` header says: the size, the maxval, where the raster starts and how long it is.
struct Header {
    width: usize,
    height: usize,
    maxval: u16,
    /// Offset of the first raster byte.
    raster_start: usize,
    /// `width × height × bytes per sample`.
    raster_bytes: usize,
}

impl Header {
    /// Parses the header at the start of `bytes` (the raster need not follow).
    fn parse(bytes: &[u8]) -> Result<Self, PgmError> {
        if bytes.len() < 2 || &bytes[..2] != b"P5" {
            let found = String::from_utf8_lossy(&bytes[..bytes.len().min(2)]).into_owned();
            return Err(PgmError::BadMagic { found });
        }
        let mut pos = 2;
        let width = header_number(bytes, &mut pos, "width")?;
        let height = header_number(bytes, &mut pos, "height")?;
        let maxval = header_number(bytes, &mut pos, "maxval")?;
        if maxval > 65535 {
            return Err(PgmError::BadMaxval(maxval));
        }
        // Exactly one whitespace byte separates maxval from the raster (pgm(5)).
        match bytes.get(pos) {
            Some(c) if c.is_ascii_whitespace() => pos += 1,
            _ => return Err(PgmError::BadHeader { field: "maxval" }),
        }
        let too_large = || PgmError::TooLarge { width, height };
        let (w, h) = usize::try_from(width)
            .ok()
            .zip(usize::try_from(height).ok())
            .ok_or_else(too_large)?;
        let bytes_per_sample = if maxval > 255 { 2 } else { 1 };
        let raster_bytes = w
            .checked_mul(h)
            .and_then(|n| n.checked_mul(bytes_per_sample))
            .ok_or_else(too_large)?;
        Ok(Header {
            width: w,
            height: h,
            maxval: maxval as u16,
            raster_start: pos,
            raster_bytes,
        })
    }
}

/// Skips whitespace and `#` comments, then reads a positive decimal number.
fn header_number(bytes: &[u8], pos: &mut usize, field: &'static str) -> Result<u64, PgmError> {
    loop {
        match bytes.get(*pos) {
            Some(c) if c.is_ascii_whitespace() => *pos += 1,
            Some(b'#') => {
                while let Some(&c) = bytes.get(*pos) {
                    *pos += 1;
                    if c == b'\n' || c == b'\r' {
                        break;
                    }
                }
            }
            _ => break,
        }
    }
    let start = *pos;
    let mut value: u64 = 0;
    while let Some(&c) = bytes.get(*pos) {
        if !c.is_ascii_digit() {
            break;
        }
        value = value
            .checked_mul(10)
            .and_then(|v| v.checked_add((c - b'0') as u64))
            .ok_or(PgmError::BadHeader { field })?;
        *pos += 1;
    }
    if *pos == start || value == 0 {
        // A maxval of 0 is also a header error: pgm(5) requires 0 < maxval.
        return Err(match (field, *pos == start) {
            ("maxval", false) => PgmError::BadMaxval(0),
            _ => PgmError::BadHeader { field },
        });
    }
    // The number must end at whitespace (or a comment), not run into other characters.
    match bytes.get(*pos) {
        Some(c) if c.is_ascii_whitespace() || *c == b'#' => Ok(value),
        _ => Err(PgmError::BadHeader { field }),
    }
}
