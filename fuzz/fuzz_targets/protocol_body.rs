//! Message bodies behind a valid CRC: the fuzzer writes `version ‖ postcard body` and the
//! target appends the CRC, so every input reaches the deserialiser (random bytes would
//! almost never pass the CRC). Whatever decodes must re-encode to the same raw bytes
//! (trailing bytes are refused, so nothing is ignored).
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_core::protocol::{
    decode_raw, encode_raw, FromDevice, ToDevice, CRC, MAX_RAW_LEN, PROTOCOL_VERSION,
};

fuzz_target!(|data: &[u8]| {
    let Some((&kind, body)) = data.split_first() else {
        return;
    };
    let mut raw = Vec::with_capacity(body.len() + 3);
    raw.push(PROTOCOL_VERSION);
    raw.extend_from_slice(body);
    raw.extend_from_slice(&CRC.checksum(&raw).to_le_bytes());
    let mut scratch = [0u8; MAX_RAW_LEN];
    if kind & 1 == 0 {
        if let Ok(message) = decode_raw::<ToDevice>(&raw) {
            let again = encode_raw(&message, PROTOCOL_VERSION, &mut scratch).expect("re-encodes");
            let reread: ToDevice = decode_raw(again).expect("its encoding decodes");
            let again = again.to_vec();
            let twice = encode_raw(&reread, PROTOCOL_VERSION, &mut scratch).expect("re-encodes");
            assert_eq!(again, twice, "re-encoding changed the bytes");
        }
    } else if let Ok(message) = decode_raw::<FromDevice>(&raw) {
        let again = encode_raw(&message, PROTOCOL_VERSION, &mut scratch)
            .expect("re-encodes")
            .to_vec();
        let reread: FromDevice = decode_raw(&again).expect("its encoding decodes");
        let mut scratch2 = [0u8; MAX_RAW_LEN];
        let twice = encode_raw(&reread, PROTOCOL_VERSION, &mut scratch2).expect("re-encodes");
        assert_eq!(again, twice, "re-encoding changed the bytes");
    }
});
