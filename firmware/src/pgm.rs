//! Header of a binary PGM (Netpbm `P5`) file, for the emulated camera.
//!
//! `P5`, whitespace, width, whitespace, height, whitespace, maxval, exactly one whitespace
//! byte, then the raster (`docs/formats.md`; one byte per sample when maxval < 256, else
//! two, big-endian). `#` comments run to the end of the line. Hand-written because the
//! firmware is `no_std` and only needs the header: the raster is read straight into the
//! frame buffer.

/// A parsed PGM header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PgmHeader {
    /// Width (pixels).
    pub width: usize,
    /// Height (pixels).
    pub height: usize,
    /// Largest sample value (1..=65535).
    pub maxval: u16,
    /// Byte offset of the raster.
    pub data_offset: usize,
}

impl PgmHeader {
    /// Bytes per sample (1 or 2).
    pub fn bytes_per_sample(&self) -> usize {
        if self.maxval < 256 {
            1
        } else {
            2
        }
    }
}

/// Parses the header at the start of `bytes` (which must hold the whole header).
pub fn parse_header(bytes: &[u8]) -> Option<PgmHeader> {
    if bytes.get(..2)? != b"P5" {
        return None;
    }
    let mut pos = 2;
    let mut fields = [0u32; 3];
    for field in fields.iter_mut() {
        // Skip whitespace and comments.
        loop {
            match *bytes.get(pos)? {
                b' ' | b'\t' | b'\r' | b'\n' => pos += 1,
                b'#' => {
                    while *bytes.get(pos)? != b'\n' {
                        pos += 1;
                    }
                }
                _ => break,
            }
        }
        let start = pos;
        let mut value: u32 = 0;
        while let Some(d @ b'0'..=b'9') = bytes.get(pos).copied() {
            value = value.checked_mul(10)?.checked_add((d - b'0') as u32)?;
            pos += 1;
        }
        if pos == start || value == 0 {
            return None;
        }
        *field = value;
    }
    // Exactly one whitespace byte ends the header.
    if !matches!(bytes.get(pos)?, b' ' | b'\t' | b'\r' | b'\n') {
        return None;
    }
    let [width, height, maxval] = fields;
    Some(PgmHeader {
        width: width as usize,
        height: height as usize,
        maxval: u16::try_from(maxval).ok()?,
        data_offset: pos + 1,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_headers_with_comments() -> Result<(), &'static str> {
        let h =
            parse_header(b"P5\n# made by tangent\n752 480\n255\n\x00\x01").ok_or("8-bit header")?;
        assert_eq!((h.width, h.height, h.maxval), (752, 480, 255));
        assert_eq!(h.data_offset, 33); // 3 + 18 + 8 + 4 header bytes
        assert_eq!(h.bytes_per_sample(), 1);
        let h = parse_header(b"P5 4 2 1023 ").ok_or("16-bit header")?;
        assert_eq!(
            (h.width, h.height, h.maxval, h.data_offset),
            (4, 2, 1023, 12)
        );
        assert_eq!(h.bytes_per_sample(), 2);
        Ok(())
    }

    #[test]
    fn rejects_malformed_headers() {
        for bad in [
            &b"P6\n4 2\n255\n"[..],
            b"P5\n4 0\n255\n",
            b"P5\n4 2\n70000\n",
            b"P5\n4 2\n255",
            b"P5\n4",
            b"P5\n99999999999 2\n255\n",
            b"P5\n4 2\n255x",
        ] {
            assert_eq!(parse_header(bad), None, "{:?}", core::str::from_utf8(bad));
        }
    }
}
