//! Feeds arbitrary bytes to both directions' streaming decoders, in chunks
//! whose sizes the input chooses. Fails on a panic, or on a decoded frame
//! that does not re-encode to a frame decoding to the same value.
#![no_main]

use dexitac_protocol::{Decoder, EncodedFrame, Frame, HostMsg, McuMsg, Message};
use libfuzzer_sys::fuzz_target;

fn check<M: Message + PartialEq + core::fmt::Debug + Copy>(data: &[u8]) {
    let (chunking, stream) = data.split_first().map_or((1, data), |(c, s)| (*c, s));
    let chunk = usize::from(chunking).max(1);
    let mut decoder = Decoder::<M>::new();
    for piece in stream.chunks(chunk) {
        for frame in decoder.feed(piece).flatten() {
            let wire = EncodedFrame::new(frame.seq, &frame.msg).expect("a decoded message re-encodes");
            let again: Vec<Result<Frame<M>, _>> = Decoder::<M>::new().feed(&wire).collect();
            assert_eq!(again, [Ok(frame)]);
        }
    }
}

fuzz_target!(|data: &[u8]| {
    check::<HostMsg>(data);
    check::<McuMsg>(data);
});
