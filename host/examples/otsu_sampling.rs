//! Does a sample of the pixels serve Otsu's threshold as well as all of them? (not a test)
//!
//! For every capture of the recorded corpus (`tests/captures`), the threshold the pipeline
//! applies (`Floors::apply` of Otsu's threshold, the brightest difference and the noise σ̂)
//! from the histogram of every pixel of the difference frame, and from the histograms of every
//! 2nd, 4th and 8th row. Prints a table and how many thresholds differ. Results:
//! `docs/performance.md`, "Sampled statistics".
//!
//! `cargo run --release -p tangent-host --example otsu_sampling [DIR]`

use std::path::Path;

use tangent_core::image::threshold::{difference_noise, Floors, ThresholdMethod};
use tangent_host::capture::{find_captures, Capture};

const STEPS: [usize; 4] = [1, 2, 4, 8];

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = std::env::args()
        .nth(1)
        .map(Into::into)
        .unwrap_or_else(|| root.join("tests/captures"));
    let floors = Floors::default();
    println!(
        "| capture | max difference | threshold, all rows | every 2nd | every 4th | every 8th |"
    );
    println!("|---|---|---|---|---|---|");
    let (mut pairs, mut differ) = (0usize, [0usize; 4]);
    for path in find_captures(&dir).expect("captures") {
        let Ok(capture) = Capture::read(&path) else {
            continue;
        };
        let off = capture.off_frame();
        let bits = off.bit_depth();
        let off_v = off.to_u16();
        for (_, on) in capture.on_frames() {
            let on_v = on.to_u16();
            let w = on.width;
            let diff: Vec<u32> = on_v
                .iter()
                .zip(&off_v)
                .map(|(&a, &b)| a.saturating_sub(b) as u32)
                .collect();
            let max_difference = diff.iter().copied().max().unwrap_or(0);
            let mut cells = Vec::new();
            let mut full = None;
            for (k, step) in STEPS.iter().enumerate() {
                let mut hist = vec![0u32; 1 << bits];
                let top = hist.len() - 1;
                for row in diff.chunks_exact(w).step_by(*step) {
                    for &d in row {
                        hist[(d as usize).min(top)] += 1;
                    }
                }
                let t = ThresholdMethod::Otsu
                    .threshold(&hist)
                    .map(|auto| floors.apply(auto, max_difference, difference_noise(&hist)));
                let cell = match t {
                    Ok(t) => t.to_string(),
                    Err(_) => "—".to_string(),
                };
                if k == 0 {
                    full = Some(cell.clone());
                } else if Some(&cell) != full.as_ref() {
                    differ[k] += 1;
                }
                cells.push(cell);
            }
            pairs += 1;
            println!(
                "| {} | {max_difference} | {} |",
                path.file_name().unwrap_or_default().to_string_lossy(),
                cells.join(" | ")
            );
        }
    }
    println!(
        "\n{pairs} frame pairs; thresholds that differ from all rows': every 2nd row {}, every 4th {}, every 8th {}",
        differ[1], differ[2], differ[3]
    );
}
