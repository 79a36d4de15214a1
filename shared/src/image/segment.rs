//! Segmentation into connected objects with the thesis's 2×2 mask, and object features
//! (thesis §5.4–5.5; derivation and connectivity discussion in `docs/image-processing.md`,
//! sections "Segmentation" and "Object features").
//!
//! Two-pass connected-component labelling:
//!
//! 1. **Scan.** A 2×2 window slides in raster order; its bottom-right pixel is the current one.
//!    A foreground pixel takes the provisional label of a foreground neighbour already scanned,
//!    or a new label; when two differently labelled neighbours meet (the two arms of a "U"),
//!    their labels are recorded as equivalent in a union–find table (`table[l]` = parent of `l`,
//!    always `<= l`, so the root of a class is its smallest label).
//! 2. **Resolve and relabel.** The table is flattened in one ascending sweep into a map from
//!    provisional to compact labels `1..=n` (objects numbered in raster order of their first
//!    pixel), then a second scan rewrites the label frame and accumulates each object's
//!    [`ObjectFeatures`] from the intensity frame.
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
    /// The scan needed more provisional labels than the equivalence table holds
    /// (`table.len() - 1`, at most 65 535).
    TooManyLabels {
        /// Provisional labels the table can hold.
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
                "segmentation needs more than {capacity} provisional labels (image too cluttered)"
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

    #[inline]
    fn add(&mut self, x: u16, y: u16, intensity: u32) {
        self.pixel_count += 1;
        self.min_x = self.min_x.min(x);
        self.max_x = self.max_x.max(x);
        self.min_y = self.min_y.min(y);
        self.max_y = self.max_y.max(y);
        let i = intensity as u64;
        self.intensity_sum += i;
        self.intensity_x_sum += i * x as u64;
        self.intensity_y_sum += i * y as u64;
        self.x_sum += x as u64;
        self.y_sum += y as u64;
        self.peak_intensity = self.peak_intensity.max(intensity);
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

/// Result of a segmentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Segmentation {
    /// Number of objects `n`: the label frame holds `1..=n`, `features[..n]` their features
    /// (`features[i].label == i + 1`).
    pub objects: usize,
    /// Provisional labels the scan used (what the equivalence table must hold; useful to size
    /// it).
    pub provisional_labels: usize,
}

/// Worst-case number of provisional labels for a `width × height` frame, i.e. the table length
/// minus one that can never overflow (capped by the `u16` label range, 65 535):
/// with 8-connectivity a new label needs its four scanned neighbours empty, so new-label pixels
/// are at least 2 apart in both directions: `⌈w/2⌉·⌈h/2⌉`. With [`Connectivity::ThesisSix`]
/// pixels on the anti-diagonals `x + y ≡ 0 (mod 3)` each start a label: `⌈w·h/3⌉` bounds it.
pub fn worst_case_labels(width: usize, height: usize, connectivity: Connectivity) -> usize {
    match connectivity {
        Connectivity::Eight => width.div_ceil(2).saturating_mul(height.div_ceil(2)),
        Connectivity::ThesisSix => width.saturating_mul(height).div_ceil(3),
    }
}

/// Root of label `x` in the equivalence table, with path halving. The table invariant
/// `table[l] <= l` makes the walk strictly decreasing, so it terminates on any table content.
#[inline]
fn find(table: &mut [u16], mut x: u16) -> u16 {
    loop {
        let p = match table.get(x as usize) {
            Some(&p) if p < x => p,
            _ => return x,
        };
        let gp = match table.get(p as usize) {
            Some(&gp) if gp < p => gp,
            _ => return p,
        };
        if let Some(slot) = table.get_mut(x as usize) {
            *slot = gp;
        }
        x = gp;
    }
}

/// Records that labels `a` and `b` are the same object; returns the common root (the smaller).
#[inline]
fn union(table: &mut [u16], a: u16, b: u16) -> u16 {
    let ra = find(table, a);
    let rb = find(table, b);
    let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
    if lo != hi {
        if let Some(slot) = table.get_mut(hi as usize) {
            *slot = lo;
        }
    }
    lo
}

/// Scan state of the first pass: the equivalence table and its fill level.
struct Labeller<'t> {
    table: &'t mut [u16],
    next: u16,
    capacity: usize,
}

impl Labeller<'_> {
    #[inline]
    fn new_label(&mut self) -> Result<u16, SegmentError> {
        if self.next as usize >= self.capacity {
            return Err(SegmentError::TooManyLabels {
                capacity: self.capacity,
            });
        }
        self.next += 1;
        if let Some(slot) = self.table.get_mut(self.next as usize) {
            *slot = self.next;
        }
        Ok(self.next)
    }
}

/// Index of the first 4-pixel word `k` in `from..words` of an 8-bit `row` holding a pixel
/// above the level of `greater`, or `words` if none: the background scan of [`segment`],
/// two words per iteration with the level's branch out of the loop. The labels (`labels`,
/// the row's label row) of the words it passes over are set to 0 on the way — cheaper than
/// clearing the whole row first, which costs as much again as the scan.
#[inline(never)]
fn next_foreground_word<P: Pixel>(
    row: &[P],
    labels: &mut [u16],
    from: usize,
    words: usize,
    greater: ByteGreater,
) -> usize {
    let end = words.min(row.len() / 4).min(labels.len() / 4);
    let from = from.min(end);
    let (Some(words_row), Some(labels)) = (
        row.get(4 * from..4 * end),
        labels.get_mut(4 * from..4 * end),
    ) else {
        return words;
    };
    let mut k = from;
    // Four words (16 pixels) per iteration; the rare chunk holding foreground is resolved
    // word by word below.
    let mut quads = words_row.chunks_exact(16);
    let mut label_quads = labels.chunks_exact_mut(16);
    for (quad, label_quad) in (&mut quads).zip(&mut label_quads) {
        let (w01, w23) = quad.split_at(8);
        let (w0, w1) = w01.split_at(4);
        let (w2, w3) = w23.split_at(4);
        let hit = greater.test(pack4(w0))
            | greater.test(pack4(w1))
            | greater.test(pack4(w2))
            | greater.test(pack4(w3));
        if hit != 0 {
            break;
        }
        label_quad.fill(0);
        k += 4;
    }
    // The chunk with foreground (if any) and the remainder, one word at a time.
    let rest_start = 4 * (k - from);
    for (word, label_word) in words_row[rest_start..]
        .chunks_exact(4)
        .zip(labels[rest_start..].chunks_exact_mut(4))
    {
        if greater.test(pack4(word)) != 0 {
            return k;
        }
        label_word.fill(0);
        k += 1;
    }
    words
}

/// Segments `image` into connected objects of pixels with `value > threshold`, writes compact
/// labels (`0` = background, objects `1..=n`) into `labels` and the objects' features into
/// `features[..n]`.
///
/// - `image`: the difference image (the threshold is applied on the fly, which saves the
///   mask frame and one pass), or a binary mask from
///   [`threshold_mask`](super::threshold::threshold_mask) with `threshold = 0`. The values are
///   also the intensities `I` of the features.
/// - `labels`: same size as `image`; fully overwritten.
/// - `table`: equivalence table, `table.len() - 1` provisional labels (at most 65 535);
///   [`worst_case_labels`] gives a size that never overflows. A few thousand entries are
///   plenty for laser images; clutter beyond that is reported, not truncated.
/// - `features`: one entry per object.
///
/// Cost: background pixels dominate a laser image, so each row is first cleared at memset
/// speed and, for 8-bit images, scanned four pixels per `u32` word for a value above the
/// threshold (two words per loop iteration); only words holding foreground go through the
/// labelling decision tree. Pass 2 visits only the rows between the first and the last
/// foreground row and skips all-background words of four labels.
///
/// Errors: [`SegmentError::TooManyLabels`] / [`SegmentError::TooManyObjects`] when a table is
/// full. These are errors rather than a silent truncation because truncation would drop the
/// objects scanned last (the bottom of the image) whatever they are — possibly the laser
/// curve — and return a plausible but wrong measurement; an error lets the pipeline tell the
/// user the scene is too cluttered or the threshold too low. On error `labels` holds partial
/// provisional labels and must not be used.
pub fn segment<P: Pixel>(
    image: &Frame<P, impl AsRef<[P]>>,
    threshold: u32,
    labels: &mut Frame<u16, impl AsMut<[u16]>>,
    table: &mut [u16],
    features: &mut [ObjectFeatures],
    connectivity: Connectivity,
) -> Result<Segmentation, SegmentError> {
    image.check_same_size(labels)?;
    let (width, height) = (image.width(), image.height());
    if width > 1 << 16 || height > 1 << 16 || width.saturating_mul(height) > u32::MAX as usize {
        return Err(SegmentError::FrameTooLarge { width, height });
    }
    let capacity = table.len().saturating_sub(1).min(u16::MAX as usize);
    if let Some(t0) = table.first_mut() {
        *t0 = 0;
    }
    let mut lab = Labeller {
        table,
        next: 0,
        capacity,
    };
    let mut first_row = usize::MAX;
    let mut last_row = 0usize;

    // ---- Pass 1: provisional labels and equivalences. ----
    // Row 0 has no upper neighbours: a run of foreground pixels shares one label.
    {
        let mut left = 0u16;
        let mut any = false;
        for (c, &p) in labels.row_mut(0).iter_mut().zip(image.row(0)) {
            let v: u32 = p.into();
            left = if v > threshold {
                any = true;
                if left != 0 {
                    left
                } else {
                    lab.new_label()?
                }
            } else {
                0
            };
            *c = left;
        }
        if any {
            first_row = 0;
        }
    }
    for y in 1..height {
        let Some((prev, cur)) = labels.previous_and_row_mut(y) else {
            break; // unreachable: 1 <= y < height
        };
        let row = image.row(y);
        // Equal-length re-slices (n = width for every well-formed frame). Neighbour labels are
        // only read for foreground pixels.
        let n = cur.len().min(row.len()).min(prev.len());
        let (cur, row, prev) = (&mut cur[..n], &row[..n], &prev[..n]);
        // Background is most of a laser image: visit only the 4-pixel words that hold a
        // foreground pixel (8-bit pixels: one word test for 4 pixels; a background pixel's
        // label is 0 whatever its neighbours are), zeroing the others' labels on the way.
        let word_skip = P::STORAGE_BITS == 8 && threshold < 255;
        let greater = ByteGreater::new(threshold);
        if P::STORAGE_BITS == 8 && threshold >= 255 {
            cur.fill(0);
            continue; // no 8-bit value exceeds 255
        }
        let mut any = false;
        // One pixel: writes its label given the label `left` of its left neighbour; returns it.
        let mut pixel = |cur: &mut [u16], x: usize, left: u16| -> Result<u16, SegmentError> {
            let v: u32 = row.get(x).map_or(0, |&p| p.into());
            if v <= threshold {
                if let Some(c) = cur.get_mut(x) {
                    *c = 0;
                }
                return Ok(0);
            }
            let up = prev.get(x).copied().unwrap_or(0);
            let up_left = if x > 0 {
                prev.get(x - 1).copied().unwrap_or(0)
            } else {
                0
            };
            let up_right = prev.get(x + 1).copied().unwrap_or(0);
            any = true;
            let l = match connectivity {
                // Decision tree of Wu, Otoo & Suzuki (2005): the upper neighbour is adjacent
                // to all the others, so when it is set no equivalence can be new.
                Connectivity::Eight => {
                    if up != 0 {
                        up
                    } else if up_left != 0 {
                        if up_right != 0 {
                            union(lab.table, up_left, up_right)
                        } else {
                            up_left
                        }
                    } else if up_right != 0 {
                        if left != 0 {
                            union(lab.table, up_right, left)
                        } else {
                            up_right
                        }
                    } else if left != 0 {
                        left
                    } else {
                        lab.new_label()?
                    }
                }
                // Upper-left is adjacent to both upper and left in this connectivity.
                Connectivity::ThesisSix => {
                    if up_left != 0 {
                        up_left
                    } else if up != 0 {
                        if left != 0 {
                            union(lab.table, up, left)
                        } else {
                            up
                        }
                    } else if left != 0 {
                        left
                    } else {
                        lab.new_label()?
                    }
                }
            };
            if let Some(c) = cur.get_mut(x) {
                *c = l;
            }
            Ok(l)
        };
        let words = if word_skip { n / 4 } else { 0 };
        let mut left = 0u16;
        let mut k = 0;
        loop {
            let next = next_foreground_word(row, cur, k, words, greater);
            if next >= words {
                break;
            }
            if next > k {
                left = 0; // the pixel left of word `next` is background
            }
            for x in 4 * next..4 * next + 4 {
                left = pixel(cur, x, left)?;
            }
            k = next + 1;
        }
        if words > 0 && k < words {
            left = 0;
        }
        for x in 4 * words..n {
            left = pixel(cur, x, left)?;
        }
        if any {
            first_row = first_row.min(y);
            last_row = y;
        }
    }
    let provisional = lab.next as usize;
    let table = lab.table;

    // ---- Resolve: provisional label -> compact label, in place. ----
    // Ascending sweep: a root (table[l] == l) gets the next compact number; any other label's
    // parent p < l has already been replaced by its compact number, which is its own.
    let mut objects = 0usize;
    for l in 1..=provisional {
        let p = table.get(l).copied().unwrap_or(0) as usize;
        let compact = if p == l {
            objects += 1;
            objects as u16
        } else {
            table.get(p).copied().unwrap_or(0)
        };
        if let Some(slot) = table.get_mut(l) {
            *slot = compact;
        }
    }
    if objects > features.len() {
        return Err(SegmentError::TooManyObjects {
            capacity: features.len(),
        });
    }
    for (i, f) in features.iter_mut().take(objects).enumerate() {
        *f = ObjectFeatures::empty(i as u16 + 1);
    }

    // ---- Pass 2: relabel and accumulate features (only rows holding foreground). ----
    if first_row <= last_row {
        for y in first_row..=last_row {
            let row = image.row(y);
            let yy = y as u16; // y < 2^16 checked above
                               // Four labels at a time: most words of a foreground row are background.
            for (k, (c4, p4)) in labels
                .row_mut(y)
                .chunks_mut(4)
                .zip(row.chunks(4))
                .enumerate()
            {
                if c4.iter().fold(0, |acc, &c| acc | c) == 0 {
                    continue;
                }
                for (i, (c, &p)) in c4.iter_mut().zip(p4).enumerate() {
                    if *c == 0 {
                        continue;
                    }
                    let compact = table.get(*c as usize).copied().unwrap_or(0);
                    *c = compact;
                    if let Some(f) = features.get_mut((compact as usize).wrapping_sub(1)) {
                        f.add((4 * k + i) as u16, yy, p.into());
                    }
                }
            }
        }
    }
    Ok(Segmentation {
        objects,
        provisional_labels: provisional,
    })
}

#[cfg(test)]
mod tests;
