//! Tests of `segment`.

extern crate std;
use super::*;
use std::vec;
use std::vec::Vec;

/// Parses a drawing ('#' foreground, '.' background) into a row-major u8 mask.
fn parse(rows: &[&str]) -> (Vec<u8>, usize, usize) {
    let w = rows[0].len();
    let data = rows
        .iter()
        .flat_map(|r| r.bytes().map(|b| (b == b'#') as u8))
        .collect();
    (data, w, rows.len())
}

struct Out {
    labels: Vec<u16>,
    features: Vec<ObjectFeatures>,
    seg: Segmentation,
}

fn run(mask: &[u8], w: usize, h: usize, conn: Connectivity) -> Out {
    let img = Frame::new(mask, w, h, w).unwrap();
    let mut labels = vec![0xFFFFu16; w * h];
    let mut runs = vec![Run::ZERO; w.div_ceil(2) * h];
    let mut features = vec![ObjectFeatures::empty(0); w * h];
    let seg = segment(&img, 0, &mut runs, &mut features, conn).unwrap();
    let mut lf = Frame::new(&mut labels, w, h, w).unwrap();
    paint_labels(&runs[..seg.runs], &mut lf);
    features.truncate(seg.objects);
    Out {
        labels,
        features,
        seg,
    }
}

/// Independent ground truth: breadth-first flood fill from each unlabelled foreground pixel
/// in raster order, so components are numbered by their first pixel like `segment`.
fn flood(mask: &[u8], w: usize, h: usize, conn: Connectivity) -> Vec<u16> {
    let mut nb: Vec<(isize, isize)> = vec![(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, 1)];
    if conn == Connectivity::Eight {
        nb.extend([(1, -1), (-1, 1)]);
    }
    let mut out = vec![0u16; w * h];
    let mut n = 0u16;
    for start in 0..w * h {
        if mask[start] == 0 || out[start] != 0 {
            continue;
        }
        n += 1;
        out[start] = n;
        let mut queue = std::collections::VecDeque::from([start]);
        while let Some(i) = queue.pop_front() {
            let (x, y) = ((i % w) as isize, (i / w) as isize);
            for (dx, dy) in &nb {
                let (u, v) = (x + dx, y + dy);
                if u < 0 || v < 0 || u >= w as isize || v >= h as isize {
                    continue;
                }
                let j = v as usize * w + u as usize;
                if mask[j] != 0 && out[j] == 0 {
                    out[j] = n;
                    queue.push_back(j);
                }
            }
        }
    }
    out
}

#[test]
fn l_shape_is_one_object_with_known_features() {
    let (m, w, h) = parse(&["#....", "#....", "#....", "####."]);
    let o = run(&m, w, h, Connectivity::Eight);
    assert_eq!(o.seg.objects, 1);
    let f = o.features[0];
    assert_eq!((f.label, f.pixel_count), (1, 7));
    assert_eq!((f.min_x, f.max_x, f.min_y, f.max_y), (0, 3, 0, 3));
    assert_eq!((f.width(), f.height()), (4, 4));
    // Mask values are 1: geometric = weighted centroid = ((0+0+0+0+1+2+3)/7, (0+1+2+3*4)/7).
    // Tolerance: one f64 -> Real rounding of values < 4 (f32: 2.4e-7).
    let (cx, cy) = f.centroid().unwrap();
    assert!((cx - 6.0 / 7.0).abs() < 1e-6 && (cy - 15.0 / 7.0).abs() < 1e-6);
    assert_eq!(o.labels, flood(&m, w, h, Connectivity::Eight));
}

#[test]
fn u_shape_merges_late_and_labels_are_compact() {
    // Two arms (runs 0 and 1 of row 0, run 2 the lone pixel at the top right); the
    // bottom bar merges them in the last row. Compact labels: U = 1, dot = 2.
    let (m, w, h) = parse(&["#..#..#", "#..#...", "#..#...", "####..."]);
    let o = run(&m, w, h, Connectivity::Eight);
    assert_eq!(o.seg.runs, 8);
    assert_eq!(o.seg.objects, 2);
    assert_eq!(o.labels, flood(&m, w, h, Connectivity::Eight));
    assert_eq!(o.labels[0], 1);
    assert_eq!(o.labels[3], 1);
    assert_eq!(o.labels[6], 2);
    assert_eq!(o.features[0].pixel_count, 10);
    assert_eq!(o.features[1].pixel_count, 1);
}

#[test]
fn comb_needs_chained_equivalences() {
    // Five teeth, labelled 1..5 in row 0, joined only by the fourth row: the union-find
    // must resolve 1~2~3~4~5 into a single object (the pixel below the bar belongs to it).
    let (m, w, h) = parse(&[
        "#.#.#.#.#",
        "#.#.#.#.#",
        "#.#.#.#.#",
        "#########",
        "........#",
    ]);
    let o = run(&m, w, h, Connectivity::Eight);
    assert_eq!(o.seg.runs, 5 * 3 + 2);
    assert_eq!(o.seg.objects, 1);
    // Staircase merging from the right ("W" pattern), where the left arm arrives last.
    let (m, w, h) = parse(&["....#.#", "...##.#", "..#..##", ".#.....", "#......"]);
    let o = run(&m, w, h, Connectivity::Eight);
    assert_eq!(o.labels, flood(&m, w, h, Connectivity::Eight));
    assert_eq!(o.seg.objects, 1);
}

#[test]
fn diagonal_touching_and_connectivity() {
    // "\" diagonal: one object in both connectivities.
    let (m, w, h) = parse(&["#...", ".#..", "..#.", "...#"]);
    assert_eq!(run(&m, w, h, Connectivity::Eight).seg.objects, 1);
    assert_eq!(run(&m, w, h, Connectivity::ThesisSix).seg.objects, 1);
    // "/" diagonal: one object with 8-connectivity, four with the literal 2x2 mask.
    let (m, w, h) = parse(&["...#", "..#.", ".#..", "#..."]);
    assert_eq!(run(&m, w, h, Connectivity::Eight).seg.objects, 1);
    let o = run(&m, w, h, Connectivity::ThesisSix);
    assert_eq!(o.seg.objects, 4);
    assert_eq!(o.labels, flood(&m, w, h, Connectivity::ThesisSix));
}

#[test]
fn single_pixel_objects() {
    let (m, w, h) = parse(&["#.#.#", ".....", "#.#.#"]);
    let o = run(&m, w, h, Connectivity::Eight);
    assert_eq!(o.seg.objects, 6);
    for (i, f) in o.features.iter().enumerate() {
        assert_eq!(f.label as usize, i + 1);
        assert_eq!((f.pixel_count, f.width(), f.height()), (1, 1, 1));
        let x = 2 * (i % 3) as u16;
        let y = 2 * (i / 3) as u16;
        assert_eq!((f.min_x, f.min_y), (x, y));
    }
    assert_eq!(o.seg.runs, 6);
}

#[test]
fn matches_flood_fill_on_random_masks() {
    // Pseudo-random masks at several densities (LCG, fixed seed), both connectivities.
    let mut s: u32 = 12345;
    for &density in &[20u32, 45, 60] {
        for conn in [Connectivity::Eight, Connectivity::ThesisSix] {
            let (w, h) = (37, 23);
            let m: Vec<u8> = (0..w * h)
                .map(|_| {
                    s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    ((s >> 24) % 100 < density) as u8
                })
                .collect();
            let o = run(&m, w, h, conn);
            let truth = flood(&m, w, h, conn);
            assert_eq!(o.labels, truth, "density {density} {conn:?}");
            for f in &o.features {
                let n = truth.iter().filter(|&&l| l == f.label).count();
                assert_eq!(f.pixel_count as usize, n);
            }
        }
    }
}

#[test]
fn intensity_features_on_a_known_shape() {
    // 3x2 block at x = 2..=4, y = 1..=2 with intensity 10*x + y (threshold 5 excludes the
    // background value 3). Weighted centroid: Σ I x / Σ I computed by hand.
    let (w, h) = (6, 4);
    let mut img = vec![3u16; w * h];
    let (mut si, mut six, mut siy) = (0u64, 0u64, 0u64);
    for y in 1..=2 {
        for x in 2..=4 {
            let v = 10 * x as u64 + y as u64;
            img[y * w + x] = v as u16;
            si += v;
            six += v * x as u64;
            siy += v * y as u64;
        }
    }
    let fi = Frame::new(&img, w, h, w).unwrap();
    let mut runs = [Run::ZERO; 2];
    let mut feats = [ObjectFeatures::empty(0); 2];
    let seg = segment(&fi, 5, &mut runs, &mut feats, Connectivity::Eight).unwrap();
    assert_eq!(seg.objects, 1);
    let f = feats[0];
    assert_eq!((f.pixel_count, f.peak_intensity), (6, 42));
    assert_eq!(
        (f.intensity_sum, f.intensity_x_sum, f.intensity_y_sum),
        (si, six, siy)
    );
    let ratio = f.height_to_width_ratio();
    assert!((ratio - 2.0 / 3.0).abs() < 1e-6);
    let (cx, cy) = f.centroid().unwrap();
    // Tolerance: one rounding of an f64 quotient to Real (f32: 2^-24 relative of ~3).
    assert!((cx - (six as f64 / si as f64) as Real).abs() < 1e-6);
    assert!((cy - (siy as f64 / si as f64) as Real).abs() < 1e-6);
    let (gx, gy) = f.geometric_centroid().unwrap();
    assert!((gx - 3.0).abs() < 1e-6 && (gy - 1.5).abs() < 1e-6);
}

#[test]
fn full_tables_are_errors() {
    let (m, w, h) = parse(&["#.#.#", ".....", "#.#.#"]);
    let img = Frame::new(&m, w, h, w).unwrap();
    let mut feats = [ObjectFeatures::empty(0); 6];
    // 6 runs needed; a table of 5 holds 5.
    let mut runs = [Run::ZERO; 6];
    assert_eq!(
        segment(&img, 0, &mut runs[..5], &mut feats, Connectivity::Eight).unwrap_err(),
        SegmentError::TooManyLabels { capacity: 5 }
    );
    // Enough runs but room for only 4 objects' features.
    assert_eq!(
        segment(&img, 0, &mut runs, &mut feats[..4], Connectivity::Eight).unwrap_err(),
        SegmentError::TooManyObjects { capacity: 4 }
    );
    // Exactly enough of both succeeds.
    let seg = segment(&img, 0, &mut runs, &mut feats, Connectivity::Eight).unwrap();
    assert_eq!(seg.objects, 6);
    // An empty table cannot hold a run, but an empty image needs none.
    assert_eq!(
        segment(&img, 0, &mut [], &mut feats, Connectivity::Eight).unwrap_err(),
        SegmentError::TooManyLabels { capacity: 0 }
    );
    let dark = [0u8; 15];
    let img = Frame::new(&dark, w, h, w).unwrap();
    let seg = segment(&img, 0, &mut [], &mut [], Connectivity::Eight).unwrap();
    assert_eq!((seg.objects, seg.runs), (0, 0));
}

#[test]
fn word_scan_finds_the_runs_of_a_pixel_scan() {
    // 8-bit rows of every length 0..40 with runs starting and ending at every offset within a
    // word: the word-skipping scan gives the runs of the plain per-pixel definition.
    let mut s: u32 = 99;
    for n in 0..40usize {
        for density in [5u32, 30, 70] {
            let row: Vec<u8> = (0..n)
                .map(|_| {
                    s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    if (s >> 24) % 100 < density {
                        9 + (s >> 8) as u8 % 200
                    } else {
                        (s >> 12) as u8 % 9
                    }
                })
                .collect();
            let mut runs = vec![Run::ZERO; n + 1];
            let mut count = 0;
            row_runs(&row, 3, 5, 8, &mut runs, &mut count).unwrap();
            let mut expect = Vec::new();
            let mut open = None;
            for (x, &v) in row.iter().chain([0u8].iter()).enumerate() {
                match (v > 8, open) {
                    (true, None) => open = Some(x),
                    (false, Some(a)) => {
                        expect.push((a as u16 + 5, x as u16 + 5));
                        open = None;
                    }
                    _ => {}
                }
            }
            let got: Vec<(u16, u16)> = runs[..count].iter().map(|r| (r.start, r.end)).collect();
            assert_eq!(got, expect, "n {n} density {density}");
            assert!(runs[..count].iter().all(|r| r.row == 3));
        }
    }
}
