//! The field log: the whole-file scanner (`fieldlog::scan`, what `log export|check` and
//! `listen` read a damaged log with) and its lines (`fieldlog::decode_line`).
//!
//! The scan must account for the input: every damaged span lies inside it and the spans are
//! in file order without overlap, every recovered record starts inside it and after the
//! previous one, and the torn tail starts at the end of the last good record. Each line is
//! also decoded as it is and behind its correct CRC (so the JSON decoder is reached); a
//! decoded record encodes to a line that decodes to the same record.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_host::fieldlog::{decode_line, encode_line, scan};

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

fn check_scan(data: &[u8]) {
    let s = scan(data);
    let mut end = 0;
    for d in &s.damaged {
        assert!(d.start >= end && d.start < d.end && d.end <= data.len(), "span {d:?}");
        end = d.end;
    }
    let mut last = None;
    for r in &s.records {
        assert!(r.offset < data.len(), "record offset {}", r.offset);
        assert!(last.is_none_or(|l| r.offset > l), "records out of order");
        last = Some(r.offset);
    }
    assert!(s.good_len <= data.len());
}

fuzz_target!(|data: &[u8]| {
    check_scan(data);
    for line in data.split(|&b| b == b'\n') {
        check(line);
        let mut with_crc = format!("{:08x} ", CRC32.checksum(line)).into_bytes();
        with_crc.extend_from_slice(line);
        check(&with_crc);
    }
});
