//! Field-log lines (`fieldlog::decode_line`, the stable entry point of the log reader).
//! The input is split at newlines like a log; each line is decoded as it is, and its bytes
//! are also decoded behind their correct CRC so the JSON decoder is reached. A decoded
//! record encodes to a line that decodes to the same record.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_host::fieldlog::{decode_line, encode_line};

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

fn check(line: &[u8]) {
    if let Some(record) = decode_line(line) {
        let encoded = encode_line(&record);
        let body = encoded
            .strip_suffix('\n')
            .expect("a line ends in a newline");
        let again = decode_line(body.as_bytes()).expect("an encoded record decodes");
        assert_eq!(encode_line(&again), encoded, "re-encoding changed the line");
    }
}

fuzz_target!(|data: &[u8]| {
    for line in data.split(|&b| b == b'\n') {
        check(line);
        let mut with_crc = format!("{:08x} ", CRC32.checksum(line)).into_bytes();
        with_crc.extend_from_slice(line);
        check(&with_crc);
    }
});
