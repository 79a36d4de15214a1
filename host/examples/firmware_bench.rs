//! Instruction-count benchmark of the on-device pipeline under QEMU (not a test).
//!
//! Renders a few corpus captures with the simulator, writes them as 8-bit PGMs, runs the
//! emulated firmware (`cargo firmware-qemu` first) with `-icount shift=0` in `--bench`
//! mode, and prints the pipeline's instructions per frame pair — during the read-out (the
//! emulated camera hands the laser-on frame over in line blocks, as the H743's DMA does; per
//! pixel, against the pixel clock's budget) and after the last pixel (per stage) — and the
//! trigger → reading latency from the sensor's timing, on the H743 board's read-out window
//! (`h743::WINDOW`: the whole 752 × 480 frame). Scenes with another calibration (the
//! two-plane tilted stems) run in a second emulator run with their own.
//! Under `-icount shift=0` QEMU advances its virtual clock 1 ns per
//! guest instruction, and the firmware times the pipeline with SysTick (25 MHz: one tick per
//! 40 instructions), so the microseconds it reports are thousands of instructions. The
//! firmware first times a loop of known length to check that scale. Method and results:
//! `docs/performance.md`.
//!
//! `cargo run --release -p tangent-host --example firmware_bench`
//! (`FIRMWARE_BENCH_DIR=dir` keeps the frames and calibration there, to rerun QEMU by hand.)

use std::path::{Path, PathBuf};

use tangent_core::pipeline::BLOCK_ROWS;
use tangent_core::protocol::codes::Failure;
use tangent_core::protocol::{calibration_record, WireCalibration};
use tangent_firmware::board::h743;
use tangent_firmware::exposure::DEFAULT_EXPOSURE_US;
use tangent_firmware::mt9v034::{HBLANK, VBLANK, WIDTH};
use tangent_host::simulate::{corpus, simulate};

/// The H743 board's read-out window: (first sensor row, rows) — the whole frame.
const WINDOW: (usize, usize) = (h743::WINDOW.first_row as usize, h743::WINDOW.rows as usize);

/// Core clock of the H743 (Hz) and pixel clock of the sensor: the read-out's budget per pixel.
const CORE_HZ: f64 = 480e6;
/// Pixel clock of the sensor module (Hz).
const PIXCLK_HZ: f64 = h743::PIXCLK_HZ as f64;

/// Read-out time of a frame of `rows` rows (s): `(rows + VBLANK)` row times of
/// `(WIDTH + HBLANK)` pixel clocks (MT9V034 datasheet, frame timing).
fn readout_s(rows: usize) -> f64 {
    (rows as f64 + VBLANK as f64) * (WIDTH as f64 + HBLANK as f64) / PIXCLK_HZ
}

const STAGES: [&str; 9] = [
    "statistics + darkness tests",
    "threshold",
    "segmentation",
    "selection",
    "curve extraction",
    "growing",
    "smoothing + triangulation",
    "faint search",
    "cylinder solver",
];

/// One scene's frames: name, width, height, laser-off and laser-on pixels (8-bit).
type Frames = (String, usize, usize, Vec<u8>, Vec<u8>);

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let elf = root.join("firmware/target/thumbv7em-none-eabihf/release/tangent-qemu");
    if !elf.exists() {
        eprintln!("{} missing: run `cargo firmware-qemu` first", elf.display());
        std::process::exit(2);
    }
    // Stems up to 1 m across over the working range (the stripe high and low in the frame,
    // short and 559 columns long), and a refusal.
    let names = [
        "cyl-d300-z150-shade",
        "cyl-d050-z050-shade",
        "cyl-d1000-z100-shade",
        "cyl-d300-z150-sun",
        "cyl-d300-z050-shade",
        "cyl-d600-z150-shade",
        "cyl-d1000-z300-shade",
        // Tilted stems, two planes (their own calibration: a second run of the emulator).
        "cyl-d300-z150-tilt20-away-2p",
        "cyl-d300-z100-tilt30-left-2p",
    ];
    let temp = tempfile::tempdir().expect("temp dir");
    let kept = std::env::var_os("FIRMWARE_BENCH_DIR").map(PathBuf::from);
    if let Some(d) = &kept {
        std::fs::create_dir_all(d).expect("create FIRMWARE_BENCH_DIR");
    }
    let dir = kept.unwrap_or_else(|| temp.path().to_path_buf());

    // Scenes grouped by calibration (its wire record), in the order above: one emulator run
    // per group, since the firmware takes one calibration.
    let mut groups: Vec<(Vec<u8>, Vec<Frames>)> = Vec::new();
    for name in names {
        let Some(e) = corpus::entries().into_iter().find(|e| e.name == name) else {
            eprintln!("{name}: not in the simulator's corpus");
            std::process::exit(2);
        };
        let (capture, _) = simulate(&e.spec).expect("simulate");
        let mut rec = [0u8; calibration_record::MAX_RECORD];
        let n = calibration_record::encode(&WireCalibration::from(&capture.calibration), &mut rec)
            .expect("record");
        let (_, on) = capture.on_frames().next().expect("on frame");
        let to8 = |pgm: &tangent_host::pgm::Pgm| -> Vec<u8> {
            let bits = pgm.bit_depth() as u32;
            pgm.to_u16()
                .into_iter()
                .map(|v| (v >> bits.saturating_sub(8)) as u8)
                .collect()
        };
        let frames = (
            e.name.clone(),
            on.width,
            on.height,
            to8(capture.off_frame()),
            to8(on),
        );
        match groups.iter_mut().find(|(r, _)| r[..] == rec[..n]) {
            Some((_, list)) => list.push(frames),
            None => groups.push((rec[..n].to_vec(), vec![frames])),
        }
    }

    let mut failed = false;
    for (group, (record, frames)) in groups.iter().enumerate() {
        let cal_path = dir.join(if group == 0 {
            "calib.bin".to_string()
        } else {
            format!("calib-{group}.bin")
        });
        std::fs::write(&cal_path, record).expect("write calibration");
        let (label, window) = (
            "H743 layout: 752 × 480, streamed in 16-row blocks",
            Some(WINDOW),
        );
        let mut args = format!("--bench --calib {}", cal_path.display());
        if let Some((row, _)) = window.filter(|&(row, _)| row > 0) {
            args += &format!(" --window {row}");
        }
        let mut sizes = Vec::new();
        for (name, width, height, off, on) in frames {
            let (first, rows) = window.unwrap_or((0, *height));
            let tag = if window.is_some() { "-window" } else { "" };
            for (kind, data) in [("off", off), ("on", on)] {
                let path = dir.join(format!("{name}{tag}-{kind}.pgm"));
                let mut bytes = format!("P5\n{width} {rows}\n255\n").into_bytes();
                bytes.extend_from_slice(&data[first * width..(first + rows) * width]);
                std::fs::write(&path, bytes).expect("write pgm");
                args += &format!(" {}", path.display());
            }
            sizes.push((name.clone(), width * rows));
        }
        // The firmware writes its log to QEMU's stderr (semihosting `:tt` in append mode).
        let out = tangent_host::emulator::qemu_command(&elf, "null", true, &args)
            .output()
            .expect("run qemu-system-arm");
        failed |= !out.status.success();
        let text = String::from_utf8_lossy(&out.stderr).into_owned();
        println!(
            "## {label} (calibration {}: {})\n\n{text}",
            group + 1,
            cal_path.display()
        );
        println!(
            "| capture | pixels | during read-out | per pixel | worst block, per pixel | after the last pixel | at 480 MHz, 1 IPC | trigger → reading | result |"
        );
        println!("|---|---|---|---|---|---|---|---|---|");
        let mut stage_rows = Vec::new();
        for line in text.lines().filter(|l| l.starts_with("bench scene=")) {
            let field = |k: &str| {
                line.split_whitespace()
                    .find_map(|w| w.strip_prefix(k))
                    .unwrap_or("")
            };
            let i: usize = field("scene=").parse().unwrap_or(0);
            let us: f64 = field("pipeline_us=").parse().unwrap_or(0.0);
            let readout: f64 = field("readout_us=").parse::<f64>().unwrap_or(0.0) * 1000.0;
            let worst_block: f64 =
                field("readout_block_max_us=").parse::<f64>().unwrap_or(0.0) * 1000.0;
            let (name, pixels) = &sizes[i.min(sizes.len() - 1)];
            let instr = us * 1000.0;
            // Snapshot mode: exposure, read-out, exposure, read-out, then the work after the
            // last pixel (at 1 instruction per cycle).
            let rows = pixels / WIDTH as usize;
            let latency_ms = (2.0 * (DEFAULT_EXPOSURE_US as f64 * 1e-6 + readout_s(rows))
                + instr / CORE_HZ)
                * 1e3;
            let result = match field("diameter_m=").parse::<f64>() {
                Ok(d) => format!("d = {:.1} mm", d * 1e3),
                Err(_) => match field("detail=").parse::<u32>() {
                    Ok(detail) => format!("error {}", Failure::from_detail(detail).code()),
                    Err(_) => "error".to_string(),
                },
            };
            println!(
                "| {name} | {pixels} | {:.2} M | {:.2} (budget {:.1}) | {:.1} | {:.2} M | {:.2} ms | {latency_ms:.1} ms | {result} |",
                readout / 1e6,
                readout / *pixels as f64,
                CORE_HZ / PIXCLK_HZ,
                worst_block / (BLOCK_ROWS * WIDTH as usize) as f64,
                instr / 1e6,
                instr / CORE_HZ * 1e3
            );
            // "stages_us=[a, b, c, d, e, f]" (split by the whitespace after the commas).
            if let Some(start) = line.find("stages_us=[") {
                let rest = &line[start + "stages_us=[".len()..];
                let mut stages: Vec<f64> = rest
                    .split(']')
                    .next()
                    .unwrap_or("")
                    .split(',')
                    .filter_map(|v| v.trim().parse().ok())
                    .collect();
                stages.push(field("solver_us=").parse().unwrap_or(0.0));
                stage_rows.push((name.clone(), stages));
            }
        }
        if !stage_rows.is_empty() {
            println!("\n| stage (M instructions) | {} |", {
                let names: Vec<&str> = stage_rows.iter().map(|(n, _)| n.as_str()).collect();
                names.join(" | ")
            });
            println!("|---|{}", "---|".repeat(stage_rows.len()));
            for (k, stage) in STAGES.iter().enumerate() {
                let cells: Vec<String> = stage_rows
                    .iter()
                    .map(|(_, s)| format!("{:.2}", s.get(k).copied().unwrap_or(0.0) / 1e3))
                    .collect();
                println!("| {stage} | {} |", cells.join(" | "));
            }
        }
        println!();
    }
    if failed {
        eprintln!("some measurement failed (see the logs above; the sun capture fails by design)");
    }
}
