//! Instruction-count benchmark of the on-device pipeline under QEMU (not a test).
//!
//! Renders a few corpus captures with the simulator, writes them as 8-bit PGMs, runs the
//! emulated firmware (`cargo firmware-qemu` first) with `-icount shift=0` in `--bench`
//! mode, and prints the pipeline's instructions per frame pair and per pixel. Under
//! `-icount shift=0` QEMU advances its virtual clock 1 ns per guest instruction, and the
//! firmware times the pipeline with SysTick (25 MHz: one tick per 40 instructions), so the
//! microseconds it reports are thousands of instructions. The firmware first times a loop
//! of known length to check that scale. Method and results: `docs/performance.md`.
//!
//! `cargo run --release -p tangent-host --example firmware_bench`

use std::path::Path;

use tangent_core::protocol::{calibration_record, WireCalibration};
use tangent_host::simulate::{corpus, simulate};

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let elf = root.join("firmware/target/thumbv7em-none-eabihf/release/tangent-qemu");
    if !elf.exists() {
        eprintln!("{} missing: run `cargo firmware-qemu` first", elf.display());
        std::process::exit(2);
    }
    let names = [
        "cyl-d300-z150-shade",
        "cyl-d050-z050-shade",
        "cyl-d1000-z100-shade",
        "cyl-d300-z150-sun",
    ];
    // `FIRMWARE_BENCH_DIR=dir` keeps the frames and calibration there (to rerun QEMU by hand,
    // e.g. with `-d exec` to profile); otherwise a temporary directory.
    let temp = tempfile::tempdir().expect("temp dir");
    let kept = std::env::var_os("FIRMWARE_BENCH_DIR").map(std::path::PathBuf::from);
    if let Some(d) = &kept {
        std::fs::create_dir_all(d).expect("create FIRMWARE_BENCH_DIR");
    }
    let dir_path = kept.unwrap_or_else(|| temp.path().to_path_buf());
    let mut args = String::from("--bench");
    let mut calibration = None;
    let mut sizes = Vec::new();
    for e in corpus::entries()
        .into_iter()
        .filter(|e| names.contains(&e.name.as_str()))
    {
        let (capture, _) = simulate(&e.spec).expect("simulate");
        let cal = capture.calibration.clone();
        // One calibration for all (every chosen capture uses the one-plane reference).
        calibration.get_or_insert(cal);
        let (_, on) = capture.on_frames().next().expect("on frame");
        for (tag, pgm) in [("off", capture.off_frame()), ("on", on)] {
            let bits = pgm.bit_depth() as u32;
            let data: Vec<u8> = pgm
                .to_u16()
                .into_iter()
                .map(|v| (v >> bits.saturating_sub(8)) as u8)
                .collect();
            let path = dir_path.join(format!("{}-{tag}.pgm", e.name));
            let mut bytes = format!("P5\n{} {}\n255\n", pgm.width, pgm.height).into_bytes();
            bytes.extend_from_slice(&data);
            std::fs::write(&path, bytes).expect("write pgm");
            args += &format!(" {}", path.display());
        }
        sizes.push((e.name.clone(), on.width * on.height));
    }
    let cal = calibration.expect("captures rendered");
    let mut rec = [0u8; calibration_record::MAX_RECORD];
    let n = calibration_record::encode(&WireCalibration::from(&cal), &mut rec).expect("record");
    let cal_path = dir_path.join("calib.bin");
    std::fs::write(&cal_path, &rec[..n]).expect("write calibration");
    args = format!("--calib {} {args}", cal_path.display());

    // The firmware writes its log to QEMU's stderr (semihosting `:tt` in append mode).
    let out = tangent_host::emulator::qemu_command(&elf, "null", true, &args)
        .output()
        .expect("run qemu-system-arm");
    let status = out.status;
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    println!("{text}");
    println!("| capture | pixels | instructions (pipeline) | per pixel | at 480 MHz, 1 IPC |");
    println!("|---|---|---|---|---|");
    for line in text.lines().filter(|l| l.starts_with("bench scene=")) {
        let field = |k: &str| {
            line.split_whitespace()
                .find_map(|w| w.strip_prefix(k))
                .unwrap_or("")
        };
        let i: usize = field("scene=").parse().unwrap_or(0);
        let us: f64 = field("pipeline_us=").parse().unwrap_or(0.0);
        let (name, pixels) = &sizes[i.min(sizes.len() - 1)];
        let instr = us * 1000.0;
        println!(
            "| {name} | {pixels} | {:.2} M | {:.2} | {:.1} ms |",
            instr / 1e6,
            instr / *pixels as f64,
            instr / 480e6 * 1e3
        );
    }
    if !status.success() {
        eprintln!("the firmware reported a failed measurement (see the log above)");
    }
}
