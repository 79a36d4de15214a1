//! Segmentation into connected objects, by runs, and object features (thesis §5.4–5.5;
//! derivation and connectivity discussion in `docs/image-processing.md`, sections
//! "Segmentation" and "Object features").
//!
//! Run-length labelling with union–find over runs, so that the memory grows with the lit
//! runs, not with the pixels (no label frame):
//!
//! 1. **Runs.** [`row_runs`] turns each row into its maximal runs of pixels above the
//!    threshold (a [`Run`]: row, first column, end column), in raster order. The streaming
//!    front end (`pipeline::stream`) does this as the rows arrive.
//! 2. **Union–find over runs.** [`label_runs`] joins each run to the runs of the row above
//!    that it touches (a two-pointer sweep of the two rows' runs), in a union–find table kept
//!    in the runs themselves (`label` = parent run, always `<=` the run's own index, so the
//!    root of a class is its first run in raster order).
//! 3. **Resolve and features.** One ascending sweep gives each root the next compact label
//!    `1..=n` (objects numbered in raster order of their first pixel, as a pixel-by-pixel
//!    labelling numbers them) and every run its object's label, while each object's
//!    [`ObjectFeatures`] are accumulated from the intensity frame over its runs' pixels.
//!
//! [`Connectivity::Eight`] (the default) joins every pair of foreground pixels that share a 2×2
//! window — that is full 8-connectivity. [`Connectivity::ThesisSix`] is the literal reading of
//! the thesis's mask (the current pixel joins its left, upper and upper-left neighbours only),
//! which never joins a pixel to its upper-right neighbour: a 6-connectivity that splits thin
//! curves rising to the right ("/") into fragments. See docs/image-processing.md.

use core::fmt;

use super::lanes::{pack4, ByteGreater};
use super::{Frame, FrameError, Pixel};
use crate::real::Real;

/// Which pixel pairs the segmentation considers connected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Connectivity {
    /// 8-connectivity: horizontal, vertical and both diagonal neighbours (every pair of pixels
    /// in a common 2×2 window). Symmetric under mirroring; the default.
    #[default]
    Eight,
    /// The thesis's mask read literally: a pixel joins its left, upper and upper-left
    /// neighbours. Horizontal, vertical and "\" diagonal neighbours are connected, "/" diagonal
    /// ones are not (6-connectivity on a sheared hexagonal grid).
    ThesisSix,
}

/// Why a frame cannot be segmented.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SegmentError {
    /// The intensity and label frames differ in size (or are malformed).
    Frame(FrameError),
    /// Object coordinates are stored as `u16` and counts as `u32`: the frame must be at most
    /// 65 536 pixels wide and high and have fewer than 2^32 pixels.
    FrameTooLarge {
        /// Frame width in pixels.
        width: usize,
        /// Frame height in pixels.
        height: usize,
    },
    /// The frame has more runs of foreground pixels than the run table holds (at most
    /// 65 535: a run's union–find parent is a `u16`).
    TooManyLabels {
        /// Runs the table can hold.
        capacity: usize,
    },
    /// The frame has more objects than the feature table holds.
    TooManyObjects {
        /// Objects the feature table can hold.
        capacity: usize,
    },
}

impl From<FrameError> for SegmentError {
    fn from(e: FrameError) -> Self {
        SegmentError::Frame(e)
    }
}

impl fmt::Display for SegmentError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SegmentError::Frame(e) => write!(f, "{e}"),
            SegmentError::FrameTooLarge { width, height } => {
                write!(f, "frame {width}x{height} too large to segment")
            }
            SegmentError::TooManyLabels { capacity } => write!(
                f,
                "segmentation needs more than {capacity} runs (image too cluttered)"
            ),
            SegmentError::TooManyObjects { capacity } => {
                write!(
                    f,
                    "image has more than {capacity} objects (image too cluttered)"
                )
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for SegmentError {}

/// Features of one object (thesis §5.5), accumulated exactly in integers during the
/// relabelling scan. Coordinates are pixel indices (`x` column, `y` row).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectFeatures {
    /// Compact label of the object in the label frame (`1..=n`).
    pub label: u16,
    /// Number of pixels.
    pub pixel_count: u32,
    /// Leftmost column.
    pub min_x: u16,
    /// Rightmost column.
    pub max_x: u16,
    /// Top row.
    pub min_y: u16,
    /// Bottom row.
    pub max_y: u16,
    /// `Σ I` over the object's pixels (`I` = intensity-frame value).
    pub intensity_sum: u64,
    /// `Σ I·x`.
    pub intensity_x_sum: u64,
    /// `Σ I·y`.
    pub intensity_y_sum: u64,
    /// `Σ x` (for the geometric centroid).
    pub x_sum: u64,
    /// `Σ y`.
    pub y_sum: u64,
    /// Largest intensity in the object.
    pub peak_intensity: u32,
}

impl ObjectFeatures {
    /// All fields zero, for initialising caller-owned buffers (a static of it lands in
    /// `.bss`); [`segment`] initialises every entry it uses.
    pub const ZERO: ObjectFeatures = ObjectFeatures {
        label: 0,
        pixel_count: 0,
        min_x: 0,
        max_x: 0,
        min_y: 0,
        max_y: 0,
        intensity_sum: 0,
        intensity_x_sum: 0,
        intensity_y_sum: 0,
        x_sum: 0,
        y_sum: 0,
        peak_intensity: 0,
    };

    /// Features of an object with no pixel yet (identity element of the accumulation).
    pub const fn empty(label: u16) -> Self {
        ObjectFeatures {
            label,
            pixel_count: 0,
            min_x: u16::MAX,
            max_x: 0,
            min_y: u16::MAX,
            max_y: 0,
            intensity_sum: 0,
            intensity_x_sum: 0,
            intensity_y_sum: 0,
            x_sum: 0,
            y_sum: 0,
            peak_intensity: 0,
        }
    }

    /// Adds the pixels of run `run`, whose intensities are `values` (`run.len()` of them).
    #[inline]
    fn add_run<P: Pixel>(&mut self, run: &Run, values: &[P]) {
        let (x0, x1, y) = (run.start as u64, run.end as u64, run.row as u64);
        let n = x1.saturating_sub(x0);
        if n == 0 {
            return;
        }
        self.pixel_count += n as u32;
        self.min_x = self.min_x.min(run.start);
        self.max_x = self.max_x.max(run.end - 1);
        self.min_y = self.min_y.min(run.row);
        self.max_y = self.max_y.max(run.row);
        // Σx over x0..x1 in closed form.
        self.x_sum += (x0 + x1 - 1) * n / 2;
        self.y_sum += y * n;
        let (mut s, mut sx, mut peak) = (0u64, 0u64, self.peak_intensity);
        for (x, &p) in (x0..).zip(values) {
            let i: u32 = p.into();
            s += i as u64;
            sx += i as u64 * x;
            peak = peak.max(i);
        }
        self.intensity_sum += s;
        self.intensity_x_sum += sx;
        self.intensity_y_sum += s * y;
        self.peak_intensity = peak;
    }

    /// Bounding-box width in pixels, `max_x - min_x + 1` (0 for an empty object).
    pub fn width(&self) -> u32 {
        if self.pixel_count == 0 {
            0
        } else {
            self.max_x as u32 - self.min_x as u32 + 1
        }
    }

    /// Bounding-box height in pixels, `max_y - min_y + 1` (0 for an empty object).
    pub fn height(&self) -> u32 {
        if self.pixel_count == 0 {
            0
        } else {
            self.max_y as u32 - self.min_y as u32 + 1
        }
    }

    /// Height-to-width ratio of the bounding box (thesis §5.6.2). A laser curve across a
    /// trunk in Tangent's images is wide and short (ratio well below 1). `0` for an empty
    /// object.
    pub fn height_to_width_ratio(&self) -> Real {
        let w = self.width();
        if w == 0 {
            0.0
        } else {
            self.height() as Real / w as Real
        }
    }

    /// Geometric centroid `(Σx/n, Σy/n)` in pixel coordinates, `None` for an empty object.
    pub fn geometric_centroid(&self) -> Option<(Real, Real)> {
        if self.pixel_count == 0 {
            return None;
        }
        let n = self.pixel_count as f64;
        Some((
            (self.x_sum as f64 / n) as Real,
            (self.y_sum as f64 / n) as Real,
        ))
    }

    /// Intensity-weighted centroid `(ΣIx/ΣI, ΣIy/ΣI)` in pixel coordinates; the geometric
    /// centroid if every intensity is zero; `None` for an empty object. The sums are exact
    /// integers; the division is done in `f64` so that sums beyond 2^24 keep their precision
    /// before the result is rounded to [`Real`].
    pub fn centroid(&self) -> Option<(Real, Real)> {
        if self.intensity_sum == 0 {
            return self.geometric_centroid();
        }
        let s = self.intensity_sum as f64;
        Some((
            (self.intensity_x_sum as f64 / s) as Real,
            (self.intensity_y_sum as f64 / s) as Real,
        ))
    }
}

/// A maximal horizontal run of foreground pixels: row `row`, columns `start..end`. `label`
/// is the run's object (`1..=n`) after [`label_runs`] (during it, its union–find parent).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Run {
    /// Image row.
    pub row: u16,
    /// First column.
    pub start: u16,
    /// One past the last column.
    pub end: u16,
    /// Object label (`1..=n`) once labelled; 0 before.
    pub label: u16,
}

impl Run {
    /// An all-zero run, for initialising caller-owned buffers (usable in `const`/`static`).
    pub const ZERO: Run = Run {
        row: 0,
        start: 0,
        end: 0,
        label: 0,
    };

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.end.saturating_sub(self.start) as usize
    }

    /// True for a run without pixels.
    pub fn is_empty(&self) -> bool {
        self.end <= self.start
    }
}

/// Result of a segmentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Segmentation {
    /// Number of objects `n`: the runs are labelled `1..=n`, `features[..n]` hold their
    /// features (`features[i].label == i + 1`).
    pub objects: usize,
    /// Runs of foreground pixels (what the run table must hold; useful to size it).
    pub runs: usize,
}

/// Appends to `runs[*count..]` the maximal runs of `values` above `threshold`, as runs of row
/// `row` whose columns start at `x0` (`values` is `row[x0..x0 + values.len()]` of an image),
/// and advances `*count`. A frame wider than 65 536 columns cannot be described
/// ([`SegmentError::FrameTooLarge`]); a full table is [`SegmentError::TooManyLabels`] (the runs
/// written so far stay valid).
///
/// Cost: background dominates a laser image, so 8-bit values are tested four to a `u32`
/// word, four words per iteration ([`ByteGreater`]: one saturating subtraction per word on
/// the Cortex-M7); only words holding foreground are looked at pixel by pixel.
pub fn row_runs<P: Pixel>(
    values: &[P],
    row: u16,
    x0: usize,
    threshold: u32,
    runs: &mut [Run],
    count: &mut usize,
) -> Result<(), SegmentError> {
    if x0 + values.len() > 1 << 16 {
        return Err(SegmentError::FrameTooLarge {
            width: x0 + values.len(),
            height: row as usize + 1,
        });
    }
    let capacity = runs.len().min(u16::MAX as usize);
    let mut push = |start: usize, end: usize| -> Result<(), SegmentError> {
        let slot = runs
            .get_mut(*count)
            .filter(|_| *count < capacity)
            .ok_or(SegmentError::TooManyLabels { capacity })?;
        *slot = Run {
            row,
            start: (x0 + start) as u16,
            end: (x0 + end) as u16,
            label: 0,
        };
        *count += 1;
        Ok(())
    };
    // Start of the open run, if any.
    let mut open: Option<usize> = None;
    let mut x = 0usize;
    let n = values.len();
    if P::STORAGE_BITS == 8 && threshold < 255 {
        let greater = ByteGreater::new(threshold);
        let words = n / 4;
        while x < 4 * words {
            if open.is_none() {
                // Skip background four words at a time, then word by word.
                while x + 16 <= 4 * words {
                    let Some(chunk) = values.get(x..x + 16) else {
                        break;
                    };
                    let (w01, w23) = chunk.split_at(8);
                    let (w0, w1) = w01.split_at(4);
                    let (w2, w3) = w23.split_at(4);
                    let hit = greater.test(pack4(w0))
                        | greater.test(pack4(w1))
                        | greater.test(pack4(w2))
                        | greater.test(pack4(w3));
                    if hit != 0 {
                        break;
                    }
                    x += 16;
                }
                while x < 4 * words && greater.test(pack4(&values[x..x + 4])) == 0 {
                    x += 4;
                }
                if x >= 4 * words {
                    break;
                }
            }
            // A word with foreground, or inside an open run: pixel by pixel.
            for (i, &p) in values[x..x + 4].iter().enumerate() {
                let v: u32 = p.into();
                match (v > threshold, open) {
                    (true, None) => open = Some(x + i),
                    (false, Some(s)) => {
                        push(s, x + i)?;
                        open = None;
                    }
                    _ => {}
                }
            }
            x += 4;
        }
        x = 4 * words;
    } else if P::STORAGE_BITS == 8 {
        // No 8-bit value exceeds 255.
        return Ok(());
    }
    for (i, &p) in values.iter().enumerate().skip(x) {
        let v: u32 = p.into();
        match (v > threshold, open) {
            (true, None) => open = Some(i),
            (false, Some(s)) => {
                push(s, i)?;
                open = None;
            }
            _ => {}
        }
    }
    if let Some(s) = open {
        push(s, n)?;
    }
    Ok(())
}

/// Root of run `x` in the union–find table kept in the runs' `label` fields, with path
/// halving. The invariant `parent <= index` makes the walk strictly decreasing, so it
/// terminates on any content.
#[inline]
fn find(runs: &mut [Run], mut x: usize) -> usize {
    loop {
        let p = match runs.get(x) {
            Some(r) if (r.label as usize) < x => r.label as usize,
            _ => return x,
        };
        let gp = match runs.get(p) {
            Some(r) if (r.label as usize) < p => r.label as usize,
            _ => return p,
        };
        if let Some(r) = runs.get_mut(x) {
            r.label = gp as u16;
        }
        x = gp;
    }
}

/// Records that runs `a` and `b` are the same object (the larger root points to the
/// smaller).
#[inline]
fn union(runs: &mut [Run], a: usize, b: usize) {
    let (ra, rb) = (find(runs, a), find(runs, b));
    let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
    if lo != hi {
        if let Some(r) = runs.get_mut(hi) {
            r.label = lo as u16;
        }
    }
}

/// Labels `runs` (maximal runs of one image in raster order, as [`row_runs`] writes them)
/// into connected objects: each run's `label` becomes its object's compact label `1..=n`, and
/// `features[..n]` the objects' features, with intensities read from `image` (the frame the
/// runs were found in). Objects are numbered in raster order of their first pixel.
///
/// Errors: [`SegmentError::TooManyObjects`] when `features` is too short,
/// [`SegmentError::TooManyLabels`] for more than 65 535 runs (their parents are `u16`),
/// [`SegmentError::Frame`] for a run outside `image`.
pub fn label_runs<P: Pixel>(
    image: &Frame<P, impl AsRef<[P]>>,
    runs: &mut [Run],
    features: &mut [ObjectFeatures],
    connectivity: Connectivity,
) -> Result<Segmentation, SegmentError> {
    if runs.len() > u16::MAX as usize {
        return Err(SegmentError::TooManyLabels {
            capacity: u16::MAX as usize,
        });
    }
    // ---- Union–find: each run against the runs of the row above that it touches. ----
    // `prev` = the previous row's runs, `cur` = this row's; both ordered by column.
    let (mut prev_start, mut prev_end) = (0usize, 0usize);
    let mut i = 0usize;
    while i < runs.len() {
        let row = runs[i].row;
        let mut row_end = i;
        while row_end < runs.len() && runs[row_end].row == row {
            row_end += 1;
        }
        let touching_row = prev_end > prev_start && runs[prev_start].row.wrapping_add(1) == row;
        let mut j = prev_start;
        for k in i..row_end {
            runs[k].label = k as u16;
            if !touching_row {
                continue;
            }
            let (start, end) = (runs[k].start, runs[k].end);
            // Runs above that end before this one's reach: they cannot touch later ones.
            while j < prev_end && runs[j].end < start {
                j += 1;
            }
            let mut m = j;
            while m < prev_end {
                let above = runs[m];
                let touches = match connectivity {
                    Connectivity::Eight => above.start <= end,
                    Connectivity::ThesisSix => above.start < end,
                };
                if !touches {
                    break;
                }
                union(runs, m, k);
                m += 1;
            }
        }
        prev_start = i;
        prev_end = row_end;
        i = row_end;
    }

    // ---- Resolve: root → compact label, in place (ascending: parents come first). ----
    let mut objects = 0usize;
    for k in 0..runs.len() {
        let p = runs[k].label as usize;
        let compact = if p == k {
            if objects >= features.len() {
                return Err(SegmentError::TooManyObjects {
                    capacity: features.len(),
                });
            }
            objects += 1;
            features[objects - 1] = ObjectFeatures::empty(objects as u16);
            objects as u16
        } else {
            // The parent (p < k) already holds its compact label, which is this run's.
            runs.get(p).map_or(0, |r| r.label)
        };
        runs[k].label = compact;
    }

    // ---- Features over each run's pixels. ----
    for run in runs.iter() {
        let row = run.row as usize;
        if row >= image.height() {
            return Err(SegmentError::Frame(FrameError::SizeMismatch {
                expected: (image.width(), image.height()),
                actual: (run.end as usize, row + 1),
            }));
        }
        let values = image
            .row(row)
            .get(run.start as usize..run.end as usize)
            .ok_or(SegmentError::Frame(FrameError::SizeMismatch {
                expected: (image.width(), image.height()),
                actual: (run.end as usize, row + 1),
            }))?;
        if let Some(f) = features.get_mut((run.label as usize).wrapping_sub(1)) {
            f.add_run(run, values);
        }
    }
    Ok(Segmentation {
        objects,
        runs: runs.len(),
    })
}

/// Segments `image` into connected objects of pixels with `value > threshold`: its runs
/// ([`row_runs`], every row) into `runs`, labelled by [`label_runs`], and the objects'
/// features into `features[..n]`. Returns the segmentation; `runs[..result.runs]` are the
/// labelled runs.
///
/// `image` is the difference image (the threshold is applied on the fly) or a binary mask
/// from [`threshold_mask`](super::threshold::threshold_mask) with `threshold = 0`; its values
/// are also the intensities `I` of the features.
///
/// Errors: [`SegmentError::TooManyLabels`] / [`SegmentError::TooManyObjects`] when a table is
/// full. These are errors rather than a silent truncation because truncation would drop the
/// objects scanned last (the bottom of the image) whatever they are — possibly the laser
/// curve — and return a plausible but wrong measurement; an error lets the pipeline tell the
/// user the scene is too cluttered or the threshold too low.
pub fn segment<P: Pixel>(
    image: &Frame<P, impl AsRef<[P]>>,
    threshold: u32,
    runs: &mut [Run],
    features: &mut [ObjectFeatures],
    connectivity: Connectivity,
) -> Result<Segmentation, SegmentError> {
    let (width, height) = (image.width(), image.height());
    if width > 1 << 16 || height > 1 << 16 || width.saturating_mul(height) > u32::MAX as usize {
        return Err(SegmentError::FrameTooLarge { width, height });
    }
    let mut count = 0usize;
    for y in 0..height {
        row_runs(image.row(y), y as u16, 0, threshold, runs, &mut count)?;
    }
    let runs = runs.get_mut(..count).unwrap_or(&mut []);
    label_runs(image, runs, features, connectivity)
}

/// Writes the label of every pixel (0 = background) into `labels` from labelled `runs`
/// (for plots and tests: the pipeline itself never needs a label frame).
pub fn paint_labels(runs: &[Run], labels: &mut Frame<u16, impl AsMut<[u16]>>) {
    for y in 0..labels.height() {
        labels.row_mut(y).fill(0);
    }
    for run in runs {
        if (run.row as usize) < labels.height() {
            if let Some(cells) = labels
                .row_mut(run.row as usize)
                .get_mut(run.start as usize..run.end as usize)
            {
                cells.fill(run.label);
            }
        }
    }
}

#[cfg(test)]
mod tests;
