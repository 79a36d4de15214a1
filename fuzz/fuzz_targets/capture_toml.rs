//! `capture.toml` from a string (`CaptureMeta::parse`), then its inline calibration (a file
//! name is not followed: no file system round trip per input), then the metadata's own
//! serialisation parsed back.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_host::capture::CaptureMeta;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(meta) = CaptureMeta::parse(text) else {
        return;
    };
    if meta.calibration.is_table() {
        let _ = meta.resolve_calibration(std::path::Path::new("/nonexistent"));
    }
    let written = toml::to_string(&meta).expect("parsed metadata serialises");
    let reread = CaptureMeta::parse(&written).expect("its serialisation parses");
    assert_eq!(
        toml::to_string(&reread).expect("serialises"),
        written,
        "serialisation is not stable"
    );
});
