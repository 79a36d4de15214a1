//! A calibration file from a string (`calibration_file::parse`): any text is a calibration
//! or a `CalibrationFileError`; a parsed calibration writes and re-parses to the same text.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_host::calibration_file;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(calibration) = calibration_file::parse(text) {
        let written = calibration_file::to_string(&calibration);
        let reread = calibration_file::parse(&written).expect("a written calibration parses");
        assert_eq!(
            calibration_file::to_string(&reread),
            written,
            "writing is not stable"
        );
    }
});
