//! The streaming front end: the laser-on frame goes through the pipeline as the camera
//! delivers it, in blocks of rows, so that only the work after the last pixel is left when
//! the frame is in (`docs/pipeline.md`, "Streaming"; memory map in `docs/hardware.md`).
//!
//! ```text
//! laser-off frame ──► Workspace::diff (stored whole)
//! laser-on rows ──► push_rows: diff = max(on − off, 0) in place, histogram,
//!                   candidate runs above the provisional threshold, the curve points of
//!                   the columns whose rows are in (`readout_fits`)
//! last row ──► finish: threshold, runs above it (from the candidates), union–find over
//!              runs, selection, subpixel curve (the points located during the read-out
//!              looked up, the rest located), smoothing, triangulation
//! ```
//!
//! The provisional threshold is the floor every threshold the pipeline can choose is raised
//! to ([`Floors::min_threshold`](crate::image::threshold::Floors)), so the runs above the
//! final threshold lie inside the candidate runs and are found by rescanning only the
//! candidates' pixels. When the candidate table fills (a cluttered or noisy scene) the
//! difference frame, which is kept whole, is rescanned instead: the result is the same,
//! only slower.
//!
//! The host's replay ([`super::extract_profile`]) feeds a stored frame pair through the same
//! stream, so host and device compute the same.

use crate::calibration::Calibration;
use crate::image::segment::{self, Connectivity, SegmentError};
use crate::image::subtract::{DifferenceHistogram, SubtractStats};
use crate::image::threshold::{self, ThresholdError};
use crate::image::{Frame, FrameError, Pixel};
use crate::real::Real;

use super::faint;
use super::faint_sums::{self, FaintReadout, IntKernel};
use super::profile::{self, Profile, Stage};
use super::readout_fits::ReadoutFits;
use super::workspace::need;
use super::{PipelineConfig, PipelineError, Workspace};

/// Rows per block in which the host's replay feeds the laser-on frame, and the device's DMA
/// delivers it (`docs/hardware.md`): 16 rows of 752 pixels = 12,032 bytes per block.
pub const BLOCK_ROWS: usize = 16;

/// A frame pair on its way through the pipeline: the laser-off frame stored in the
/// workspace, the laser-on frame arriving in rows ([`ProfileStream::push_rows`]), the
/// profile when the last row is in ([`ProfileStream::finish`]). The stream is the state
/// between the calls; the workspace is lent to each (so a device's measurer can own both).
///
/// ```
/// use tangent_core::pipeline::{Buffers, PipelineConfig, ProfileStream, WorkspaceSizes};
/// # use tangent_core::calibration::Calibration;
/// # fn run(cal: &Calibration, off: &[u8], on: &[u8]) {
/// const SIZES: WorkspaceSizes = WorkspaceSizes::new(752, 480, 8, 2);
/// let mut buffers = Box::new(Buffers::<u8, { SIZES.pixels }, { SIZES.points }>::new());
/// let mut ws = buffers.workspace();
/// let (w, h) = (cal.camera.width as usize, cal.camera.height as usize);
/// ws.diff[..w * h].copy_from_slice(off); // the laser-off frame (on a device: its DMA)
/// let config = PipelineConfig::default();
/// let mut stream = ProfileStream::begin(&mut ws, cal, &config, 8).unwrap();
/// for block in on.chunks(16 * w) {
///     stream.push_rows(&mut ws, block).unwrap(); // as the camera delivers them
/// }
/// let profile = stream.finish(&mut ws, cal, &config);
/// # }
/// ```
#[derive(Debug, Clone)]
pub struct ProfileStream {
    width: usize,
    height: usize,
    bit_depth: u8,
    next_row: usize,
    difference: DifferenceHistogram,
    provisional: u32,
    candidates: usize,
    /// The candidate table filled up: `finish` rescans the difference frame.
    overflow: bool,
    /// The curve points located as their rows arrive (`pipeline::readout_fits`).
    readout: ReadoutFits,
    /// Block width of the faint search's block sums gathered as the rows arrive
    /// (`pipeline::faint_sums`), 0 when they are not.
    sums_block: usize,
    /// The faint search's noise pass during the read-out, when it runs
    /// (`pipeline::faint_sums`).
    faint: Option<FaintReadout>,
}

impl ProfileStream {
    /// Starts a frame pair of the calibrated camera's size and `bit_depth` bits:
    /// `ws.diff[..width × height]` holds the laser-off frame (row-major, `width` pixels per
    /// row) by the first [`ProfileStream::push_rows`]. Checks the calibration and the
    /// workspace; clears the histogram.
    pub fn begin<P: Pixel>(
        ws: &mut Workspace<'_, P>,
        calibration: &Calibration,
        config: &PipelineConfig,
        bit_depth: u8,
    ) -> Result<Self, PipelineError> {
        calibration
            .validate()
            .map_err(|_| PipelineError::Calibration)?;
        let (width, height) = (
            calibration.camera.width as usize,
            calibration.camera.height as usize,
        );
        if width == 0 || height == 0 {
            return Err(PipelineError::Frame(FrameError::Empty));
        }
        if width > 1 << 16 || height > 1 << 16 {
            return Err(PipelineError::Segment(SegmentError::FrameTooLarge {
                width,
                height,
            }));
        }
        if bit_depth == 0 || bit_depth > P::STORAGE_BITS {
            return Err(PipelineError::Frame(FrameError::BadBitDepth(bit_depth)));
        }
        need("diff", width * height, ws.diff.len())?;
        let max_value = ((1u64 << bit_depth) - 1) as u32;
        let difference =
            DifferenceHistogram::new::<P>(max_value, ws.histogram).map_err(|e| match e {
                ThresholdError::Frame(e) => PipelineError::Frame(e),
                e => PipelineError::Threshold(e),
            })?;
        let readout = ReadoutFits::begin(
            ws.column_tracks,
            ws.readout_fits,
            (width, height),
            config.extract,
            config.floors,
        );
        let sums_block = faint_sums::table_block(
            config.faint,
            (width, height),
            bit_depth,
            ws.block_sums.len(),
        );
        let faint = match config.faint {
            Some(params) if sums_block != 0 => {
                let (taps, len) = faint::kernel(params.profile_sigma_px);
                IntKernel::new(&taps[..len]).and_then(|kernel| {
                    FaintReadout::begin(
                        kernel,
                        width.div_ceil(sums_block),
                        height,
                        ws.faint_columns,
                        |blk| {
                            let x0 = blk * sums_block;
                            faint::band_rows(calibration, &params, x0, (x0 + sums_block).min(width))
                        },
                    )
                })
            }
            _ => None,
        };
        Ok(ProfileStream {
            width,
            height,
            bit_depth,
            next_row: 0,
            difference,
            provisional: config.floors.min_threshold,
            candidates: 0,
            overflow: false,
            readout,
            sums_block,
            faint,
        })
    }

    /// Rows received so far.
    pub fn rows_received(&self) -> usize {
        self.next_row
    }

    /// Rows of every block's band whose faint-search responses the read-out has taken so far
    /// (`pipeline::faint_sums`).
    #[cfg(test)]
    pub(super) fn faint_rows_done(&self) -> usize {
        self.faint.map_or(0, |f| f.rows_done())
    }

    /// The next rows of the laser-on frame (a whole number of rows of `width` pixels): each
    /// is subtracted from the stored laser-off row in place, counted in the histogram, and
    /// its runs above the provisional threshold are noted. Errors: a partial row, or more
    /// rows than the frame has.
    pub fn push_rows<P: Pixel>(
        &mut self,
        ws: &mut Workspace<'_, P>,
        rows: &[P],
    ) -> Result<(), PipelineError> {
        let w = self.width;
        if !rows.len().is_multiple_of(w) || self.next_row + rows.len() / w > self.height {
            return Err(PipelineError::Frame(FrameError::SizeMismatch {
                expected: (w, self.height),
                actual: (rows.len() % w, self.next_row + rows.len().div_ceil(w)),
            }));
        }
        for on in rows.chunks_exact(w) {
            let y = self.next_row;
            let Some(off_diff) = ws.diff.get_mut(y * w..(y + 1) * w) else {
                return Err(PipelineError::WorkspaceTooSmall {
                    buffer: "diff",
                    needed: (y + 1) * w,
                    actual: ws.diff.len(),
                });
            };
            // The faint search's block sums, in the subtraction's pass for blocks of 8.
            match self.sums_block {
                0 => self.difference.row(on, off_diff, ws.histogram),
                8 => self.difference.row_with_block_sums(
                    on,
                    off_diff,
                    ws.histogram,
                    ws.block_sums,
                    (y, self.height),
                ),
                b => {
                    self.difference.row(on, off_diff, ws.histogram);
                    faint_sums::gather_row(off_diff, b, y, self.height, ws.block_sums);
                }
            }
            if !self.overflow {
                let first = self.candidates;
                let found = segment::row_runs(
                    off_diff,
                    y as u16,
                    0,
                    self.provisional,
                    ws.candidate_runs,
                    &mut self.candidates,
                );
                // A full table leaves this row's runs incomplete: `finish` rescans (and the
                // read-out extraction stops: the points are then located after the frame).
                self.overflow = found.is_err();
                if !self.overflow {
                    let diff = self.diff_frame(ws.diff)?;
                    let runs = ws.candidate_runs.get(first..self.candidates).unwrap_or(&[]);
                    self.readout.row(
                        (ws.column_tracks, ws.readout_fits),
                        &diff,
                        y,
                        runs.iter().map(|r| (r.start as usize, r.end as usize)),
                    );
                }
            }
            self.next_row += 1;
            if self.next_row.is_multiple_of(BLOCK_ROWS) && self.next_row < self.height {
                let diff = self.diff_frame(ws.diff)?;
                let left = self
                    .readout
                    .block_done((ws.column_tracks, ws.readout_fits), &diff, y);
                // The faint search's noise pass in the work the curve points left.
                if let Some(faint) = self.faint.as_mut() {
                    faint.step(ws.block_sums, ws.faint_columns, y, left);
                }
            }
        }
        Ok(())
    }

    /// The difference frame as far as it is: rows `..next_row` subtracted, the rest still the
    /// laser-off frame.
    fn diff_frame<'d, P: Pixel>(&self, diff: &'d [P]) -> Result<Frame<P, &'d [P]>, PipelineError> {
        let pixels = self.width * self.height;
        let data = diff.get(..pixels).ok_or(PipelineError::WorkspaceTooSmall {
            buffer: "diff",
            needed: pixels,
            actual: diff.len(),
        })?;
        Ok(
            Frame::new(data, self.width, self.height, self.width)?
                .with_bit_depth(self.bit_depth)?,
        )
    }

    /// The profile of the pair, once every row is in: [`ProfileStream::finish_probed`] without
    /// a probe.
    pub fn finish<P: Pixel>(
        self,
        ws: &mut Workspace<'_, P>,
        calibration: &Calibration,
        config: &PipelineConfig,
    ) -> Result<Profile, PipelineError> {
        self.finish_probed(ws, calibration, config, |_| {})
    }

    /// The work after the last pixel: the darkness tests, the threshold, the runs above it
    /// and their labelling, then the rest of the chain (selection, subpixel curve, smoothing,
    /// triangulation), with the calibration and configuration the stream began with. Calls
    /// `probe` as each [`Stage`] completes.
    pub fn finish_probed<P: Pixel>(
        self,
        ws: &mut Workspace<'_, P>,
        calibration: &Calibration,
        config: &PipelineConfig,
        mut probe: impl FnMut(Stage),
    ) -> Result<Profile, PipelineError> {
        let ProfileStream {
            width,
            height,
            bit_depth,
            next_row,
            mut difference,
            provisional,
            candidates,
            overflow,
            readout,
            sums_block,
            faint: faint_readout,
        } = self;
        let cam = &calibration.camera;
        if (cam.width as usize, cam.height as usize) != (width, height) {
            return Err(PipelineError::FrameSizeMismatch {
                calibrated: (cam.width, cam.height),
                actual: (width, height),
            });
        }
        need("diff", width * height, ws.diff.len())?;
        if next_row != height {
            return Err(PipelineError::Frame(FrameError::SizeMismatch {
                expected: (width, height),
                actual: (width, next_row),
            }));
        }
        let pixels = width * height;
        let stats = difference.finish(ws.histogram);
        let full_scale = ((1u64 << bit_depth) - 1) as u32;
        let histogram_len = (full_scale as usize + 1).min(ws.histogram.len());
        let histogram = &ws.histogram[..histogram_len];
        let noise = threshold::difference_noise(histogram);
        let pair = profile::Subtracted {
            width,
            height,
            bit_depth,
            stats,
            noise,
            block_sums: sums_block,
            faint_rows: faint_readout.map_or(0, |f| f.rows_done()),
        };
        // The thresholded chain; where it finds no stripe, the faint search may
        // (`faint::or_search`).
        let read = (|| {
            let histogram = &ws.histogram[..histogram_len];
            darkness_tests(&stats, noise, full_scale, config)?;
            probe(Stage::Subtracted);

            let automatic = config.threshold.threshold(histogram)?;
            let t = config.floors.apply(automatic, stats.max_difference, noise);
            probe(Stage::Thresholded);

            // Runs above `t`: inside the candidates (t ≥ the provisional threshold), or, when the
            // candidate table overflowed, from the whole difference frame.
            let diff =
                Frame::new(&ws.diff[..pixels], width, height, width)?.with_bit_depth(bit_depth)?;
            let mut n = 0usize;
            if overflow || t < provisional {
                for y in 0..height {
                    segment::row_runs(diff.row(y), y as u16, 0, t, ws.runs, &mut n)?;
                }
            } else {
                for c in ws.candidate_runs.iter().take(candidates) {
                    let (x0, x1) = (c.start as usize, c.end as usize);
                    let values =
                        diff.row(c.row as usize)
                            .get(x0..x1)
                            .ok_or(PipelineError::Frame(FrameError::BufferTooSmall {
                                needed: x1,
                                actual: width,
                            }))?;
                    segment::row_runs(values, c.row, x0, t, ws.runs, &mut n)?;
                }
            }
            let runs = &mut ws.runs[..n];
            let segmentation = segment::label_runs(&diff, runs, ws.objects, Connectivity::Eight)?;
            probe(Stage::Segmented);

            profile::after_segmentation(
                ws,
                profile::Segmented {
                    pair,
                    threshold: t,
                    objects: segmentation.objects,
                    runs: n,
                    readout,
                },
                calibration,
                config,
                &mut probe,
            )
        })();
        let searched = matches!(&read, Err(e) if faint::takes_over(e, config));
        let result = faint::or_search(read, ws, pair, calibration, config);
        if searched {
            probe(Stage::FaintSearched);
        }
        result
    }
}

/// Runs the image part of the chain and triangulates the curves: `off` and `on` are the
/// laser-off and laser-on frames (all of the calibration's planes lit in `on`).
///
/// On success the workspace holds the difference frame, the labels, the curve points and the
/// 3-D points; the returned [`Profile`] says where each plane's points are.
pub fn extract_profile<P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    config: &PipelineConfig,
    ws: &mut Workspace<'_, P>,
) -> Result<Profile, PipelineError> {
    extract_profile_probed(off, on, calibration, config, ws, |_| {})
}

/// [`extract_profile`] that calls `probe` as each [`Stage`] completes (the firmware's
/// instruction-count benchmark time-stamps them; `docs/performance.md`). With an empty
/// closure it compiles to [`extract_profile`].
///
/// The pair goes through the device's streaming front end ([`ProfileStream`]): `off` is
/// copied into the workspace (where the device's DMA puts it) and `on` is fed in blocks of
/// [`BLOCK_ROWS`] rows, as the camera delivers it.
pub fn extract_profile_probed<P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    config: &PipelineConfig,
    ws: &mut Workspace<'_, P>,
    probe: impl FnMut(Stage),
) -> Result<Profile, PipelineError> {
    let (width, height) = check_inputs(off, on, calibration, ws)?;
    for (y, stored) in ws.diff[..width * height]
        .chunks_exact_mut(width)
        .enumerate()
    {
        stored.copy_from_slice(off.row(y));
    }
    let mut stream = ProfileStream::begin(ws, calibration, config, on.bit_depth())?;
    for block in (0..height).step_by(BLOCK_ROWS) {
        for y in block..(block + BLOCK_ROWS).min(height) {
            stream.push_rows(ws, on.row(y))?;
        }
    }
    stream.finish_probed(ws, calibration, config, probe)
}

/// A valid calibration whose camera has the frames' size, and room for them in the
/// workspace. Returns `(width, height)`.
fn check_inputs<P: Pixel>(
    off: &Frame<P, impl AsRef<[P]>>,
    on: &Frame<P, impl AsRef<[P]>>,
    calibration: &Calibration,
    ws: &Workspace<'_, P>,
) -> Result<(usize, usize), PipelineError> {
    calibration
        .validate()
        .map_err(|_| PipelineError::Calibration)?;
    let cam = &calibration.camera;
    let (width, height) = (on.width(), on.height());
    if (cam.width as usize, cam.height as usize) != (width, height) {
        return Err(PipelineError::FrameSizeMismatch {
            calibrated: (cam.width, cam.height),
            actual: (width, height),
        });
    }
    on.check_same_size(off)?;
    need("diff", width * height, ws.diff.len())?;
    Ok((width, height))
}

/// The two "is there anything to see?" tests: enough laser light above the noise, and an
/// ambient that does not blind the sensor (`full_scale`: the frames' full scale).
fn darkness_tests(
    stats: &SubtractStats,
    noise: Real,
    full_scale: u32,
    config: &PipelineConfig,
) -> Result<(), PipelineError> {
    if !config.floors.is_lit(stats.max_difference, noise) {
        return Err(PipelineError::NoLaserLight {
            max_difference: stats.max_difference,
        });
    }
    // The off frame's mean at full scale means most of it is clipped: nothing can be seen.
    if stats.off_mean >= 0.9 * full_scale as Real {
        return Err(PipelineError::AmbientSaturated {
            fraction: stats.off_mean / full_scale as Real,
        });
    }
    Ok(())
}
