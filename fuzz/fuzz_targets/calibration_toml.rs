//! A calibration file from a string (`calibration_file::parse`): any text is a calibration
//! or a `CalibrationFileError`; a parsed calibration writes a file that parses again to the
//! same values. "The same" is to 1e-12 (relative; absolute near zero): loading normalises
//! each plane's normal and projects its source onto the plane, which is not idempotent to the
//! last bit (a few ulps may move per load/save cycle).
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_host::calibration_file;

/// The two texts differ at most in the last digits of their numbers.
fn same_up_to_rounding(a: &str, b: &str) -> bool {
    let tokens = |s: &str| {
        s.split(|c: char| c.is_whitespace() || "[],=".contains(c))
            .filter(|t| !t.is_empty())
            .map(str::to_owned)
            .collect::<Vec<_>>()
    };
    let (ta, tb) = (tokens(a), tokens(b));
    ta.len() == tb.len()
        && ta.iter().zip(&tb).all(|(x, y)| {
            x == y
                || match (x.parse::<f64>(), y.parse::<f64>()) {
                    (Ok(x), Ok(y)) => (x - y).abs() <= 1e-12 * (1.0 + x.abs().max(y.abs())),
                    _ => false,
                }
        })
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(calibration) = calibration_file::parse(text) {
        let written = calibration_file::to_string(&calibration);
        let reread = calibration_file::parse(&written).expect("a written calibration parses");
        let rewritten = calibration_file::to_string(&reread);
        assert!(
            same_up_to_rounding(&written, &rewritten),
            "writing is not stable:\n{written}\n{rewritten}"
        );
    }
});
