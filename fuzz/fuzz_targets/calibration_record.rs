//! The calibration record in flash (`protocol::calibration_record`). Half the inputs get a
//! valid magic, length and CRC around the fuzzer's payload so the deserialiser is reached;
//! the other half are raw (erased flash, torn writes). A decoded record re-encodes to a
//! record that decodes to the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_core::protocol::calibration_record::{decode, encode, CRC32, MAGIC, MAX_RECORD};

fn check(record: &[u8]) {
    if let Some(cal) = decode(record) {
        let mut buf = [0u8; MAX_RECORD];
        let n = encode(&cal, &mut buf).expect("a decoded record re-encodes");
        let first = buf[..n].to_vec();
        let again = decode(&first).expect("its record decodes");
        let n2 = encode(&again, &mut buf).expect("re-encodes");
        assert_eq!(first, buf[..n2], "re-encoding changed the record");
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, payload)) = data.split_first() else {
        return;
    };
    if mode & 1 == 0 {
        check(payload);
    } else {
        let mut record = Vec::with_capacity(payload.len() + 12);
        record.extend_from_slice(&MAGIC);
        record.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        record.extend_from_slice(payload);
        let crc = CRC32.checksum(&record);
        record.extend_from_slice(&crc.to_le_bytes());
        check(&record);
    }
});
