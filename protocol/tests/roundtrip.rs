//! Property tests: every message survives encode -> stream -> decode, and
//! corruption never yields a frame.

mod common;

use common::*;
use dexitac_protocol::*;
use proptest::prelude::*;

fn encode<M: Message>(seq: u16, msg: &M) -> Vec<u8> {
    EncodedFrame::new(seq, msg)
        .expect("MAX_FRAME_LEN fits every message")
        .to_vec()
}

/// The frame's encoded size never exceeds the advertised bound.
fn check_bound(wire: &[u8]) -> Result<(), TestCaseError> {
    prop_assert!(
        wire.len() <= MAX_FRAME_LEN,
        "{} > {}",
        wire.len(),
        MAX_FRAME_LEN
    );
    prop_assert_eq!(wire.last(), Some(&0u8));
    prop_assert!(!wire[..wire.len() - 1].contains(&0));
    Ok(())
}

/// Every single-bit flip of `wire` (delimiter excluded) must not produce a
/// frame; it may produce errors, or nothing (when the flip hid the delimiter).
fn every_bit_flip_rejected<M: Message + std::fmt::Debug>(wire: &[u8]) -> Result<(), TestCaseError> {
    for i in 0..wire.len() - 1 {
        for bit in 0..8 {
            let mut bad = wire.to_vec();
            bad[i] ^= 1 << bit;
            let got = decode_all::<M>(&bad);
            prop_assert!(
                got.iter().all(|r| r.is_err()),
                "flip of byte {} bit {} gave {:?}",
                i,
                bit,
                got
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn host_msg_round_trips(seq: u16, msg in host_msg()) {
        let wire = encode(seq, &msg);
        check_bound(&wire)?;
        prop_assert_eq!(decode_all::<HostMsg>(&wire), vec![Ok(Frame { seq, msg })]);
    }

    #[test]
    fn mcu_msg_round_trips(seq: u16, msg in mcu_msg()) {
        let wire = encode(seq, &msg);
        check_bound(&wire)?;
        prop_assert_eq!(decode_all::<McuMsg>(&wire), vec![Ok(Frame { seq, msg })]);
    }

    #[test]
    fn host_msg_every_bit_flip_is_rejected(seq: u16, msg in host_msg()) {
        every_bit_flip_rejected::<HostMsg>(&encode(seq, &msg))?;
    }

    #[test]
    fn mcu_msg_every_bit_flip_is_rejected(seq: u16, msg in mcu_msg()) {
        every_bit_flip_rejected::<McuMsg>(&encode(seq, &msg))?;
    }

    /// A stream of frames split at arbitrary points decodes to the same frames.
    #[test]
    fn chunked_stream_decodes_every_frame(
        msgs in proptest::collection::vec(host_msg(), 1..20),
        cuts in proptest::collection::vec(any::<prop::sample::Index>(), 0..10),
    ) {
        let mut stream = Vec::new();
        for (seq, msg) in msgs.iter().enumerate() {
            stream.extend(encode(seq as u16, msg));
        }
        let mut points: Vec<usize> = cuts.iter().map(|c| c.index(stream.len())).collect();
        points.sort_unstable();
        let mut decoder = Decoder::<HostMsg>::new();
        let mut got = Vec::new();
        let mut start = 0;
        for end in points.into_iter().chain([stream.len()]) {
            got.extend(decoder.feed(&stream[start..end]));
            start = end;
        }
        let want: Vec<_> = msgs
            .iter()
            .enumerate()
            .map(|(seq, &msg)| Ok(Frame { seq: seq as u16, msg }))
            .collect();
        prop_assert_eq!(got, want);
    }

    /// Garbage before a frame costs at most the garbage: the decoder
    /// resynchronises at the delimiter and the frame after it decodes.
    #[test]
    fn resynchronises_after_garbage(
        garbage in proptest::collection::vec(any::<u8>(), 0..300),
        seq: u16,
        msg in mcu_msg(),
    ) {
        let mut stream = garbage;
        stream.push(0);
        stream.extend(encode(seq, &msg));
        let got = decode_all::<McuMsg>(&stream);
        prop_assert_eq!(got.last(), Some(&Ok(Frame { seq, msg })));
        prop_assert!(got[..got.len() - 1].iter().all(|r| r.is_err()));
    }

    /// Random byte corruption of a command stream never yields a frame that
    /// was not sent: whatever survives decoding is an original frame.
    #[test]
    fn corrupted_stream_yields_only_sent_frames(
        msgs in proptest::collection::vec(host_msg(), 1..30),
        hits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        let sent: Vec<Frame<HostMsg>> = msgs
            .iter()
            .enumerate()
            .map(|(seq, &msg)| Frame { seq: seq as u16, msg })
            .collect();
        let mut stream: Vec<u8> = sent.iter().flat_map(|f| encode(f.seq, &f.msg)).collect();
        for (at, value) in hits {
            let i = at.index(stream.len());
            stream[i] = value;
        }
        for frame in decode_all::<HostMsg>(&stream).into_iter().flatten() {
            prop_assert!(sent.contains(&frame), "{:?} was never sent", frame);
        }
    }

    /// Arbitrary bytes never panic, and any frame they yield carries a valid
    /// CRC: re-encoding it gives back exactly the bytes it came from.
    #[test]
    fn arbitrary_bytes_never_yield_a_frame_failing_its_crc(
        bytes in proptest::collection::vec(any::<u8>(), 0..2048),
    ) {
        for chunk in bytes.split_inclusive(|b| *b == 0) {
            if let Some(Ok(frame)) = decode_all::<HostMsg>(chunk).pop() {
                prop_assert_eq!(encode(frame.seq, &frame.msg), chunk.to_vec());
            }
        }
        let _: Vec<_> = decode_all::<McuMsg>(&bytes);
    }
}
