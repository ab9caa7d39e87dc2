//! The fuzz target's seed inputs (`protocol/fuzz/seeds/frame*`) are frames
//! of this protocol version, one seed per message variant of both
//! directions, so the fuzzer starts from frames that get past the CRC and
//! version checks. A seed is one chunk-size byte (the fuzz target's first
//! input byte) and the same frame twice.
//!
//! After a protocol change, rewrite them from the examples the wire
//! snapshots use:
//!
//! ```sh
//! DEXITAC_WRITE_FUZZ_SEEDS=1 cargo test -p dexitac-protocol --test fuzz_seeds
//! ```

mod common;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use common::{host_examples, mcu_examples};
use dexitac_protocol::*;

/// The chunk size the seeds ask the fuzz target to feed the decoders with.
const CHUNK: u8 = 7;

fn seed_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz")
        .join("seeds")
}

fn seed<M: Message>(msg: &M) -> Vec<u8> {
    let frame = EncodedFrame::new(0x0102, msg).expect("every message fits a frame");
    let mut bytes = vec![CHUNK];
    bytes.extend_from_slice(&frame);
    bytes.extend_from_slice(&frame);
    bytes
}

fn write_seeds(dir: &Path) {
    for entry in std::fs::read_dir(dir).expect("seed directory") {
        let path = entry.expect("directory entry").path();
        let is_frame_seed = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("frame"));
        if is_frame_seed {
            std::fs::remove_file(&path).expect("removing an old seed");
        }
    }
    let (host, mcu) = (host_examples(), mcu_examples());
    let seeds = host.iter().map(seed).chain(mcu.iter().map(seed));
    for (i, bytes) in seeds.enumerate() {
        std::fs::write(dir.join(format!("frame{i:02}")), bytes).expect("writing a seed");
    }
}

/// The message tags of the frames in `stream`, if every frame in it decodes
/// as an `M` and there is at least one.
fn tags_if_all_decode<M: Message>(stream: &[u8]) -> Option<Vec<u8>> {
    let frames: Vec<_> = Decoder::<M>::new().feed(stream).collect();
    if frames.is_empty() {
        return None;
    }
    frames
        .into_iter()
        .map(|r| {
            r.ok()
                .map(|f| postcard::to_allocvec(&f.msg).expect("encodes")[0])
        })
        .collect()
}

#[test]
fn fuzz_seeds_are_frames_of_this_protocol_version() {
    let dir = seed_dir();
    if std::env::var("DEXITAC_WRITE_FUZZ_SEEDS").is_ok_and(|v| v == "1") {
        write_seeds(&dir);
    }
    let mut names: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("protocol/fuzz/seeds")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("frame"))
        })
        .collect();
    names.sort();
    let mut host_tags = BTreeSet::new();
    let mut mcu_tags = BTreeSet::new();
    let mut stale = Vec::new();
    for path in &names {
        let bytes = std::fs::read(path).expect("reading a seed");
        let stream = bytes.get(1..).unwrap_or(&[]);
        match (
            tags_if_all_decode::<HostMsg>(stream),
            tags_if_all_decode::<McuMsg>(stream),
        ) {
            (Some(tags), None) => host_tags.extend(tags),
            (None, Some(tags)) => mcu_tags.extend(tags),
            _ => stale.push(path.display().to_string()),
        }
    }
    assert!(
        stale.is_empty(),
        "seeds that are not valid frames of protocol v{PROTOCOL_VERSION} in one direction: {stale:?}; \
         rewrite them with DEXITAC_WRITE_FUZZ_SEEDS=1 cargo test -p dexitac-protocol --test fuzz_seeds"
    );
    assert_eq!(
        host_tags,
        (0..HostMsg::VARIANT_COUNT).collect(),
        "a seed per host message"
    );
    assert_eq!(
        mcu_tags,
        (0..McuMsg::VARIANT_COUNT).collect(),
        "a seed per MCU message"
    );
}

#[test]
fn a_seed_of_another_protocol_version_is_caught() {
    // Version 1 Hello, as the seeds carried before: chunk byte, frame.
    let old = [
        7u8, 0x04, 0x01, 0x02, 0x01, 0x05, 0xc8, 0x77, 0xcc, 0x36, 0x00,
    ];
    let stream = &old[1..];
    assert_eq!(
        Decoder::<HostMsg>::new().feed(stream).collect::<Vec<_>>(),
        [Err(FrameError::WrongVersion { version: 1 })]
    );
    assert_eq!(tags_if_all_decode::<HostMsg>(stream), None);
    assert_eq!(tags_if_all_decode::<McuMsg>(stream), None);
}
