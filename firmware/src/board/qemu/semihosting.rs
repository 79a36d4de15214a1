//! The emulated board's link to the host machine through semihosting: its files (frames,
//! the calibration record, the mode store's sector), its command line, its console and its
//! exit status.

use core::fmt::Write as _;

use cortex_m_semihosting::{nr, syscall};
use tangent_core::protocol::{calibration_record, WireCalibration};

use crate::pgm;
use crate::ports::{CameraError, Geometry};

/// A semihosting file handle, closed on drop.
pub(super) struct HostFile(usize);

impl HostFile {
    pub(super) fn open(path: &str, mode: usize) -> Option<HostFile> {
        // SYS_OPEN wants a NUL-terminated name and its length without the NUL.
        let mut name = [0u8; 256];
        let bytes = path.as_bytes();
        name.get_mut(..bytes.len())?.copy_from_slice(bytes);
        *name.get_mut(bytes.len())? = 0;
        // SAFETY: semihosting call with a valid, NUL-terminated buffer.
        let fd = unsafe { syscall!(OPEN, name.as_ptr(), mode, bytes.len()) };
        if fd as isize == -1 {
            None
        } else {
            Some(HostFile(fd))
        }
    }

    pub(super) fn len(&self) -> Option<usize> {
        // SAFETY: semihosting call on an open handle.
        let n = unsafe { syscall!(FLEN, self.0) };
        if n as isize == -1 {
            None
        } else {
            Some(n)
        }
    }

    pub(super) fn seek(&self, pos: usize) -> Option<()> {
        // SAFETY: semihosting call on an open handle.
        let r = unsafe { syscall!(SEEK, self.0, pos) };
        (r == 0).then_some(())
    }

    /// Reads up to `buf.len()` bytes; returns how many.
    pub(super) fn read(&self, buf: &mut [u8]) -> usize {
        // SAFETY: semihosting call writing at most buf.len() bytes into buf.
        let not_read = unsafe { syscall!(READ, self.0, buf.as_mut_ptr(), buf.len()) };
        buf.len().saturating_sub(not_read)
    }

    /// Writes every byte of `data`.
    pub(super) fn write_all(&self, data: &[u8]) -> Option<()> {
        // SAFETY: semihosting call reading data.len() bytes from data.
        let not_written = unsafe { syscall!(WRITE, self.0, data.as_ptr(), data.len()) };
        (not_written == 0).then_some(())
    }

    pub(super) fn read_exact(&self, buf: &mut [u8]) -> Option<()> {
        let mut done = 0;
        while done < buf.len() {
            let n = self.read(buf.get_mut(done..)?);
            if n == 0 {
                return None;
            }
            done += n;
        }
        Some(())
    }
}

impl Drop for HostFile {
    fn drop(&mut self) {
        // SAFETY: closes the handle this value owns.
        unsafe {
            syscall!(CLOSE, self.0);
        }
    }
}

pub(super) fn read_pgm_header(path: &str) -> Result<pgm::PgmHeader, CameraError> {
    let f = HostFile::open(path, nr::open::R_BINARY).ok_or(CameraError::Source)?;
    let mut head = [0u8; 128];
    let n = f.read(&mut head);
    pgm::parse_header(head.get(..n).ok_or(CameraError::Source)?).ok_or(CameraError::Source)
}

/// Reads an 8-bit PGM of exactly `geometry`'s size in blocks of up to `block.len()` bytes of
/// whole rows, handing each block to `rows` as it is read. 16-bit files (10-bit sensor data)
/// are reduced to their top 8 bits, as the DCMI's 8-bit bus wired to D9..D2 of the sensor
/// would see them.
pub(super) fn read_pgm_rows(
    path: &str,
    geometry: Geometry,
    block: &mut [u8],
    mut rows: impl FnMut(&[u8]),
) -> Result<(), CameraError> {
    let h = read_pgm_header(path)?;
    if h.width != geometry.width as usize || h.height != geometry.height as usize {
        return Err(CameraError::Source);
    }
    let (w, height) = (geometry.width as usize, geometry.height as usize);
    let len = geometry.frame_len();
    let f = HostFile::open(path, nr::open::R_BINARY).ok_or(CameraError::Source)?;
    if f.len().ok_or(CameraError::Source)? < h.data_offset + len * h.bytes_per_sample() {
        return Err(CameraError::Source);
    }
    if h.bytes_per_sample() == 1 && h.maxval < 255 {
        // Scaling n-bit data to 8 bits is not what a sensor does; such files are not
        // captures of this camera.
        return Err(CameraError::Source);
    }
    f.seek(h.data_offset).ok_or(CameraError::Source)?;
    let block_rows = (block.len() / w.max(1)).max(1);
    // Significant bits of 16-bit samples (10 for maxval 1023); keep the top 8.
    let bits = 32 - (h.maxval as u32).leading_zeros();
    let down = bits.saturating_sub(8);
    let mut row16 = [0u8; 2 * 752];
    let mut y = 0;
    while y < height {
        let n = block_rows.min(height - y);
        let dst = block.get_mut(..n * w).ok_or(CameraError::BufferSize)?;
        if h.bytes_per_sample() == 1 {
            f.read_exact(dst).ok_or(CameraError::Source)?;
        } else {
            let row_bytes = row16.get_mut(..2 * w).ok_or(CameraError::Source)?;
            for dst_row in dst.chunks_exact_mut(w) {
                f.read_exact(row_bytes).ok_or(CameraError::Source)?;
                for (d, s) in dst_row.iter_mut().zip(row_bytes.chunks_exact(2)) {
                    let v = u16::from_be_bytes([s[0], s[1]]);
                    *d = (v >> down).min(255) as u8;
                }
            }
        }
        rows(dst);
        y += n;
    }
    Ok(())
}

/// Reads a whole host file into `buf`; returns its length.
pub fn read_file(path: &str, buf: &mut [u8]) -> Option<usize> {
    let f = HostFile::open(path, nr::open::R_BINARY)?;
    let n = f.len()?;
    f.read_exact(buf.get_mut(..n)?)?;
    Some(n)
}

/// Loads a calibration record file (`protocol::calibration_record`).
pub fn load_calibration(path: &str) -> Option<WireCalibration> {
    let mut buf = [0u8; calibration_record::MAX_RECORD];
    let n = read_file(path, &mut buf)?;
    calibration_record::decode(buf.get(..n)?)
}

/// The command line given to QEMU (`-append`), into `buf`.
pub fn command_line(buf: &mut [u8]) -> Option<&str> {
    let mut block = [buf.as_mut_ptr() as usize, buf.len()];
    // SAFETY: SYS_GET_CMDLINE writes at most block[1] bytes into buf and the length
    // into block[1].
    // (Not `syscall!`, which would wrap the pointer in another parameter block.)
    let r = unsafe { cortex_m_semihosting::syscall1(nr::GET_CMDLINE, block.as_mut_ptr() as usize) };
    if r != 0 {
        return None;
    }
    let n = block[1];
    core::str::from_utf8(buf.get(..n)?).ok()
}

/// Writes a line to the host's console (semihosting), for logs and benchmark output.
pub fn log(args: core::fmt::Arguments<'_>) {
    let mut line: heapless::String<256> = heapless::String::new();
    let _ = line.write_fmt(args);
    let _ = line.push('\n');
    if let Ok(mut out) = cortex_m_semihosting::hio::hstderr() {
        let _ = out.write_all(line.as_bytes());
    }
}

/// Ends the emulation with a status.
pub fn exit(success: bool) -> ! {
    use cortex_m_semihosting::debug;
    debug::exit(if success {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}
