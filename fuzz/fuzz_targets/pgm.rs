//! The PGM reader on arbitrary bytes: every malformation is a `PgmError`, never a panic or
//! an allocation beyond what the bytes hold; a decoded greymap re-encodes to the same bytes
//! when its header is the writer's canonical one.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_host::pgm::Pgm;

fuzz_target!(|data: &[u8]| {
    if let Ok(pgm) = Pgm::decode(data) {
        let encoded = pgm.encode().expect("a decoded greymap encodes");
        assert_eq!(Pgm::decode(&encoded).expect("its encoding decodes"), pgm);
        let canonical = format!("P5\n{} {}\n{}\n", pgm.width, pgm.height, pgm.maxval);
        if data.starts_with(canonical.as_bytes()) {
            assert_eq!(encoded, data, "a canonical file re-encodes to itself");
        }
    }
});
