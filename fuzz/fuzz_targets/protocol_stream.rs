//! The receive side of a link on arbitrary bytes: `Decoder::feed` must never panic or grow,
//! and every message it decodes must re-encode to a frame that decodes to the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tangent_core::protocol::{
    encode, Decoder, Feed, FromDevice, ToDevice, MAX_FRAME_LEN, MAX_RAW_LEN,
};

/// Encodes `message`, decodes the frame, re-encodes: both encodings must be identical.
fn round_trip<T>(message: &T)
where
    T: serde::Serialize + for<'a> serde::Deserialize<'a>,
{
    let (mut scratch, mut frame) = ([0u8; MAX_RAW_LEN], [0u8; MAX_FRAME_LEN]);
    let n = encode(message, &mut scratch, &mut frame).expect("a decoded message re-encodes");
    let first = frame[..n].to_vec();
    let again: T = tangent_core::protocol::decode(&mut frame[..n]).expect("its frame decodes");
    let n2 = encode(&again, &mut scratch, &mut frame).expect("re-encodes");
    assert_eq!(first, frame[..n2], "re-encoding changed the frame");
}

fuzz_target!(|data: &[u8]| {
    // The first byte chooses the direction (host side or device side), the rest is the stream.
    let Some((&side, stream)) = data.split_first() else {
        return;
    };
    let mut decoder = Decoder::new([0u8; MAX_FRAME_LEN]);
    let mut rest = stream;
    if side & 1 == 0 {
        loop {
            match decoder.feed::<ToDevice>(rest) {
                Feed::Consumed => break,
                Feed::Frame { message, remaining } => {
                    round_trip(&message);
                    rest = remaining;
                }
                Feed::Rejected { remaining, .. } => rest = remaining,
            }
        }
    } else {
        loop {
            // `FromDevice` borrows from the decoder's buffer: copy what is needed before
            // feeding on.
            let (frame, remaining) = match decoder.feed::<FromDevice>(rest) {
                Feed::Consumed => break,
                Feed::Frame { message, remaining } => {
                    let (mut scratch, mut frame) = ([0u8; MAX_RAW_LEN], [0u8; MAX_FRAME_LEN]);
                    let n = encode(&message, &mut scratch, &mut frame)
                        .expect("a decoded message re-encodes");
                    (Some(frame[..n].to_vec()), remaining)
                }
                Feed::Rejected { remaining, .. } => (None, remaining),
            };
            if let Some(mut frame) = frame {
                let first = frame.clone();
                let again: FromDevice =
                    tangent_core::protocol::decode(&mut frame).expect("decodes");
                let (mut scratch, mut out) = ([0u8; MAX_RAW_LEN], [0u8; MAX_FRAME_LEN]);
                let n = encode(&again, &mut scratch, &mut out).expect("re-encodes");
                assert_eq!(first, out[..n], "re-encoding changed the frame");
            }
            rest = remaining;
        }
    }
    let stats = decoder.stats();
    assert!(stats.frames_ok as usize <= stream.len());
});
