//! A recorded frame pair measured with the core alone, as a library user would: two 8-bit
//! frames and a calibration in, one reading out.
//!
//! `cargo run -p tangent-core --example measure_pair [capture directory]` (default: the
//! corpus's 300 mm stem at 1.5 m, `tests/captures/cyl-d300-z150-shade`, which lit plane 0 of
//! the reference design).

use std::path::{Path, PathBuf};

use tangent_core::pipeline::WorkspaceSizes;
use tangent_core::protocol::codes::{method_name, Failure};
use tangent_core::PipelineConfig;
use tangent_core::{measure, Buffers, Calibration, Frame, InstrumentParams, Measurement, Mode};

const WIDTH: usize = 752;
const HEIGHT: usize = 480;
const SIZES: WorkspaceSizes = WorkspaceSizes::new(WIDTH, HEIGHT, 8, 1);

fn main() -> Result<(), String> {
    let dir = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/captures/cyl-d300-z150-shade")
        });
    let (off, on) = (
        read_pgm(&dir.join("off.pgm"))?,
        read_pgm(&dir.join("on.pgm"))?,
    );
    let frame = |pixels| Frame::new(pixels, WIDTH, HEIGHT, WIDTH).map_err(|e| e.to_string());
    let (off, on) = (frame(&off[..])?, frame(&on[..])?);

    let reference = Calibration::reference_design();
    let calibration =
        Calibration::new(1, reference.camera, &reference.planes[..1]).map_err(|e| e.to_string())?;
    // The whole working memory, const-constructed (a device puts it in a `static`).
    let mut buffers = Box::new(Buffers::<u8, { SIZES.pixels }, { SIZES.points }>::new());

    let (config, params) = (PipelineConfig::default(), InstrumentParams::default());
    let reading = measure(
        Mode::Cylinder,
        &off,
        &on,
        &calibration,
        &config,
        &params,
        &mut buffers.workspace(),
    );
    match reading {
        Ok(Measurement::Stem(stem)) => println!(
            "{}: d = {:.1} mm ± {:.1} mm ({}) at {:.2} m",
            dir.display(),
            stem.diameter * 1e3,
            stem.uncertainty * 1e3,
            method_name(stem.method),
            stem.distance
        ),
        // The example measures a stem; another instrument's reading by its headline number.
        Ok(other) => println!(
            "{}: {} {:.1} mm ± {:.1} mm ({})",
            dir.display(),
            other.kind(),
            other.value() * 1e3,
            other.uncertainty() * 1e3,
            method_name(other.method())
        ),
        // The sentence the CLI and the caliper's companion print for the same failure.
        Err(e) => println!("{}: no reading: {}", dir.display(), Failure::of(&e)),
    }
    Ok(())
}

/// The pixels of an 8-bit binary PGM (`P5 width height 255`, then the bytes), checked to be
/// `WIDTH × HEIGHT`.
fn read_pgm(path: &Path) -> Result<Vec<u8>, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let header: Vec<&[u8]> = bytes.splitn(5, |b| b.is_ascii_whitespace()).collect();
    let expected = format!("P5 {WIDTH} {HEIGHT} 255");
    let expected: Vec<&[u8]> = expected.as_bytes().split(|&b| b == b' ').collect();
    match header.split_last() {
        Some((pixels, fields)) if fields == expected && pixels.len() == WIDTH * HEIGHT => {
            Ok(pixels.to_vec())
        }
        _ => Err(format!(
            "{}: not an 8-bit {WIDTH}×{HEIGHT} PGM without comments",
            path.display()
        )),
    }
}
