//! One frame on the wire, and how it is encoded and checked.
//!
//! ```text
//! raw   = version:u8 | seq:u16 LE | postcard(message) | crc:u32 LE
//! crc   = CRC-32C(direction:u8 | version | seq | postcard(message))
//! wire  = COBS(raw) | 0x00
//! ```
//!
//! The CRC is CRC-32C (Castagnoli, `crc::CRC_32_ISCSI`): it catches every
//! single-bit and every burst error up to 32 bits in a frame this short.
//! The direction byte ([`Message::DIRECTION`]) is covered by the CRC but not
//! sent: a frame travelling the other way (a looped-back or echoed line)
//! fails its CRC instead of being read as the other side's message.
//! COBS removes every 0x00 from the frame so that 0x00 can delimit frames;
//! a receiver that joins mid-stream resynchronises at the next 0x00.
//! [`MAX_FRAME_LEN`] bounds every frame on the wire, delimiter included.

use core::fmt;

use crc::{Crc, CRC_32_ISCSI};
use postcard::experimental::max_size::MaxSize;

use crate::message::{HostMsg, McuMsg, Message, Telemetry};
use crate::PROTOCOL_VERSION;

const CRC32C: Crc<u32> = Crc::<u32>::new(&CRC_32_ISCSI);

/// Bytes before the message: version (1) and sequence number (2).
pub const HEADER_LEN: usize = 3;
/// Bytes of the CRC after the message.
pub const CRC_LEN: usize = 4;

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// Largest postcard encoding of any message, either direction.
pub const MAX_MESSAGE_LEN: usize = max(HostMsg::POSTCARD_MAX_SIZE, McuMsg::POSTCARD_MAX_SIZE);
/// Largest frame before COBS: header, message, CRC.
pub const MAX_RAW_LEN: usize = HEADER_LEN + MAX_MESSAGE_LEN + CRC_LEN;
/// Largest COBS-encoded frame, without its 0x00 delimiter.
pub const MAX_ENCODED_LEN: usize = cobs::max_encoding_length(MAX_RAW_LEN);
/// Largest frame on the wire, 0x00 delimiter included.
pub const MAX_FRAME_LEN: usize = MAX_ENCODED_LEN + 1;

/// Largest wire frame (COBS and 0x00 delimiter included) of a message whose
/// postcard encoding takes at most `message_len` bytes.
pub const fn max_frame_len_for(message_len: usize) -> usize {
    cobs::max_encoding_length(HEADER_LEN + message_len + CRC_LEN) + 1
}

/// Largest telemetry frame on the wire: [`McuMsg::Telemetry`]'s tag byte and
/// body. Telemetry is the only periodic frame, so the line time of this
/// frame sets the shortest telemetry interval the firmware accepts.
pub const MAX_TELEMETRY_FRAME_LEN: usize = max_frame_len_for(1 + Telemetry::POSTCARD_MAX_SIZE);

/// A decoded frame: its sequence number and message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame<M> {
    /// The sender's sequence number (wrapping); acks and nacks echo it.
    pub seq: u16,
    /// The message.
    pub msg: M,
}

/// Why received bytes are not a frame. Frames that fail their CRC are never
/// interpreted further.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// More bytes than [`MAX_ENCODED_LEN`] arrived without a delimiter; the
    /// rest up to the next 0x00 is dropped.
    TooLong,
    /// The bytes are not valid COBS.
    Cobs,
    /// The decoded frame is shorter than a header, a one-byte message and a CRC.
    TooShort,
    /// The CRC does not match: corrupted on the line.
    Crc,
    /// Intact frame of another protocol version.
    WrongVersion {
        /// The version byte received.
        version: u8,
    },
    /// Intact frame whose message tag this build does not know.
    UnknownMessage {
        /// The frame's sequence number.
        seq: u16,
        /// The unknown tag.
        tag: u8,
    },
    /// Intact frame whose message does not decode (bad field value, tank
    /// targets out of limits, missing or trailing bytes).
    Malformed {
        /// The frame's sequence number.
        seq: u16,
    },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::TooLong => write!(f, "frame longer than {MAX_ENCODED_LEN} bytes"),
            FrameError::Cobs => f.write_str("invalid COBS encoding"),
            FrameError::TooShort => f.write_str("frame too short"),
            FrameError::Crc => f.write_str("CRC mismatch"),
            FrameError::WrongVersion { version } => {
                write!(f, "protocol version {version}, expected {PROTOCOL_VERSION}")
            }
            FrameError::UnknownMessage { seq, tag } => {
                write!(f, "unknown message tag {tag} (seq {seq})")
            }
            FrameError::Malformed { seq } => write!(f, "malformed message (seq {seq})"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for FrameError {}

/// Encoding failed: the output buffer is too small. A buffer of
/// [`MAX_FRAME_LEN`] bytes always suffices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BufferTooSmall;

impl fmt::Display for BufferTooSmall {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "output buffer smaller than the frame")
    }
}

#[cfg(feature = "std")]
impl std::error::Error for BufferTooSmall {}

/// Encodes `msg` with sequence number `seq` into `out` as a complete wire
/// frame (COBS and trailing 0x00 included); returns the frame's length.
///
/// ```
/// use dexitac_protocol::{encode_into, HostMsg, MAX_FRAME_LEN};
/// let mut buf = [0u8; MAX_FRAME_LEN];
/// let n = encode_into(7, &HostMsg::Heartbeat, &mut buf).unwrap();
/// assert_eq!(buf[n - 1], 0x00);
/// assert!(!buf[..n - 1].contains(&0x00));
/// ```
pub fn encode_into<M: Message>(seq: u16, msg: &M, out: &mut [u8]) -> Result<usize, BufferTooSmall> {
    let mut raw = [0u8; MAX_RAW_LEN];
    let [version, seq_lo, seq_hi, body @ ..] = &mut raw;
    *version = PROTOCOL_VERSION;
    [*seq_lo, *seq_hi] = seq.to_le_bytes();
    // `body` holds MAX_MESSAGE_LEN + CRC_LEN bytes, more than any message needs.
    let body_len = postcard::to_slice(msg, body)
        .map_err(|_| BufferTooSmall)?
        .len();
    let crc_at = HEADER_LEN + body_len;
    let crc = checksum::<M>(raw.get(..crc_at).ok_or(BufferTooSmall)?);
    raw.get_mut(crc_at..crc_at + CRC_LEN)
        .ok_or(BufferTooSmall)?
        .copy_from_slice(&crc.to_le_bytes());
    let raw = raw.get(..crc_at + CRC_LEN).ok_or(BufferTooSmall)?;
    let n = cobs::try_encode(raw, out).map_err(|_| BufferTooSmall)?;
    *out.get_mut(n).ok_or(BufferTooSmall)? = 0;
    Ok(n + 1)
}

/// A frame encoded into its own fixed buffer (no allocation).
#[derive(Clone, Copy)]
pub struct EncodedFrame {
    buf: [u8; MAX_FRAME_LEN],
    len: usize,
}

impl EncodedFrame {
    /// Encodes `msg` with sequence number `seq`. Every [`Message`] fits
    /// ([`MAX_FRAME_LEN`] is derived from the largest), so this only fails if
    /// that derivation were wrong; the error is kept rather than a panic.
    pub fn new<M: Message>(seq: u16, msg: &M) -> Result<Self, BufferTooSmall> {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let len = encode_into(seq, msg, &mut buf)?;
        Ok(EncodedFrame { buf, len })
    }

    /// The wire bytes, trailing 0x00 included.
    pub fn as_bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }
}

impl core::ops::Deref for EncodedFrame {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        self.as_bytes()
    }
}

impl fmt::Debug for EncodedFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_tuple("EncodedFrame")
            .field(&self.as_bytes())
            .finish()
    }
}

/// Decodes one COBS-encoded frame (without its 0x00 delimiter), in place.
/// `encoded` is overwritten by the decoded bytes.
pub fn decode_in_place<M: Message>(encoded: &mut [u8]) -> Result<Frame<M>, FrameError> {
    if encoded.len() > MAX_ENCODED_LEN {
        return Err(FrameError::TooLong);
    }
    let n = cobs::decode_in_place(encoded).map_err(|_| FrameError::Cobs)?;
    let raw = encoded.get(..n).ok_or(FrameError::Cobs)?;
    check_raw(raw)
}

/// The CRC of a frame of `M`: CRC-32C over the direction byte and `checked`.
fn checksum<M: Message>(checked: &[u8]) -> u32 {
    let mut digest = CRC32C.digest();
    digest.update(&[M::DIRECTION]);
    digest.update(checked);
    digest.finalize()
}

/// Checks and decodes a raw (un-COBSed) frame: CRC, version, then message.
fn check_raw<M: Message>(raw: &[u8]) -> Result<Frame<M>, FrameError> {
    if raw.len() < HEADER_LEN + 1 + CRC_LEN {
        return Err(FrameError::TooShort);
    }
    let (checked, crc) = raw.split_at(raw.len() - CRC_LEN);
    let crc_bytes: [u8; CRC_LEN] = crc.try_into().map_err(|_| FrameError::TooShort)?;
    if checksum::<M>(checked) != u32::from_le_bytes(crc_bytes) {
        return Err(FrameError::Crc);
    }
    let [version, seq_lo, seq_hi, body @ ..] = checked else {
        return Err(FrameError::TooShort);
    };
    if *version != PROTOCOL_VERSION {
        return Err(FrameError::WrongVersion { version: *version });
    }
    let seq = u16::from_le_bytes([*seq_lo, *seq_hi]);
    let tag = body.first().copied().ok_or(FrameError::TooShort)?;
    if tag >= M::VARIANT_COUNT {
        // Tags are postcard varints; a byte >= 0x80 is a multi-byte varint,
        // which no message of ours needs, so it is unknown too.
        return Err(FrameError::UnknownMessage { seq, tag });
    }
    match postcard::take_from_bytes::<M>(body) {
        Ok((msg, [])) => Ok(Frame { seq, msg }),
        Ok(_) | Err(_) => Err(FrameError::Malformed { seq }),
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::{Decoder, TankTargets, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA};

    /// A host-to-MCU wire frame around arbitrary raw bytes, with a correct CRC.
    fn wire_with_valid_crc(header_and_body: &[u8]) -> Vec<u8> {
        let mut raw = header_and_body.to_vec();
        raw.extend_from_slice(&checksum::<HostMsg>(header_and_body).to_le_bytes());
        let mut wire = std::vec![0u8; cobs::max_encoding_length(raw.len()) + 1];
        let n = cobs::encode(&raw, &mut wire);
        wire.truncate(n);
        wire.push(0);
        wire
    }

    fn decode_host(wire: &[u8]) -> Vec<Result<Frame<HostMsg>, FrameError>> {
        Decoder::<HostMsg>::new().feed(wire).collect()
    }

    #[test]
    fn valid_frame_decodes() {
        let wire = wire_with_valid_crc(&[PROTOCOL_VERSION, 5, 0, 10]);
        let want = Frame {
            seq: 5,
            msg: HostMsg::Heartbeat,
        };
        assert_eq!(decode_host(&wire), [Ok(want)]);
    }

    #[test]
    fn other_protocol_version_is_rejected() {
        let wire = wire_with_valid_crc(&[PROTOCOL_VERSION + 1, 5, 0, 10]);
        let want = FrameError::WrongVersion {
            version: PROTOCOL_VERSION + 1,
        };
        assert_eq!(decode_host(&wire), [Err(want)]);
    }

    #[test]
    fn unknown_tag_is_an_unknown_message() {
        let wire = wire_with_valid_crc(&[PROTOCOL_VERSION, 9, 0, HostMsg::VARIANT_COUNT]);
        let want = FrameError::UnknownMessage {
            seq: 9,
            tag: HostMsg::VARIANT_COUNT,
        };
        assert_eq!(decode_host(&wire), [Err(want)]);
    }

    #[test]
    fn trailing_bytes_are_malformed() {
        let wire = wire_with_valid_crc(&[PROTOCOL_VERSION, 1, 0, 10, 0]);
        assert_eq!(decode_host(&wire), [Err(FrameError::Malformed { seq: 1 })]);
    }

    #[test]
    fn truncated_body_is_malformed() {
        // SetChambers with 3 of its 8 valve states.
        let wire = wire_with_valid_crc(&[PROTOCOL_VERSION, 1, 0, 2, 0, 1, 2]);
        assert_eq!(decode_host(&wire), [Err(FrameError::Malformed { seq: 1 })]);
    }

    #[test]
    fn invalid_valve_state_is_malformed() {
        let wire = wire_with_valid_crc(&[PROTOCOL_VERSION, 1, 0, 2, 0, 0, 0, 0, 0, 0, 0, 3]);
        assert_eq!(decode_host(&wire), [Err(FrameError::Malformed { seq: 1 })]);
    }

    #[test]
    fn tank_targets_outside_the_hard_limits_do_not_decode() {
        for (positive_pa, negative_pa) in [
            (POSITIVE_TANK_MAX_PA + 1, 0),
            (-1, 0),
            (0, NEGATIVE_TANK_MIN_PA - 1),
            (0, 1),
            (i32::MAX, i32::MIN),
        ] {
            assert!(TankTargets::new(positive_pa, negative_pa).is_err());
            let mut raw = std::vec![PROTOCOL_VERSION, 4, 0];
            // Same layout as TankTargets, but unchecked: two zigzag varints.
            let body = postcard::to_allocvec(&(6u8, positive_pa, negative_pa)).expect("encodes");
            raw.extend_from_slice(&body);
            let got = decode_host(&wire_with_valid_crc(&raw));
            assert_eq!(
                got,
                [Err(FrameError::Malformed { seq: 4 })],
                "{positive_pa} {negative_pa}"
            );
        }
    }

    #[test]
    fn tank_targets_at_the_hard_limits_decode() {
        let targets = TankTargets::new(POSITIVE_TANK_MAX_PA, NEGATIVE_TANK_MIN_PA).expect("limits");
        let msg = HostMsg::SetTankTargets(targets);
        let wire = EncodedFrame::new(3, &msg).expect("fits");
        assert_eq!(decode_host(&wire), [Ok(Frame { seq: 3, msg })]);
    }

    #[test]
    fn frames_without_a_message_are_too_short() {
        // Header and valid CRC, but no message byte.
        let header_only = wire_with_valid_crc(&[PROTOCOL_VERSION, 0, 0]);
        assert_eq!(decode_host(&header_only), [Err(FrameError::TooShort)]);
        // COBS [1, 1] decodes to the single byte 0x00.
        assert_eq!(decode_host(&[1, 1, 0]), [Err(FrameError::TooShort)]);
    }

    #[test]
    fn bad_crc_is_rejected() {
        let mut wire = EncodedFrame::new(1, &HostMsg::Arm).expect("fits").to_vec();
        let crc_byte = wire.len() - 2;
        wire[crc_byte] ^= 0x10;
        assert_eq!(decode_host(&wire), [Err(FrameError::Crc)]);
    }

    #[test]
    fn invalid_cobs_is_rejected() {
        // The code byte 0x09 promises 8 more bytes before the delimiter.
        assert_eq!(decode_host(&[0x09, 1, 2, 0]), [Err(FrameError::Cobs)]);
    }

    #[test]
    fn overlong_input_is_reported_once_then_resynchronised() {
        let mut stream = std::vec![0x55u8; 3 * MAX_ENCODED_LEN];
        stream.push(0);
        stream.extend_from_slice(&EncodedFrame::new(2, &HostMsg::Ping { nonce: 1 }).expect("fits"));
        let want = Frame {
            seq: 2,
            msg: HostMsg::Ping { nonce: 1 },
        };
        assert_eq!(decode_host(&stream), [Err(FrameError::TooLong), Ok(want)]);
    }

    #[test]
    fn empty_frames_are_skipped() {
        let mut stream = std::vec![0u8, 0, 0];
        stream.extend_from_slice(&EncodedFrame::new(0, &HostMsg::SealAll).expect("fits"));
        stream.extend_from_slice(&[0, 0]);
        let want = Frame {
            seq: 0,
            msg: HostMsg::SealAll,
        };
        assert_eq!(decode_host(&stream), [Ok(want)]);
    }

    #[test]
    fn a_frame_is_only_read_in_its_own_direction() {
        // `Ping { nonce: 5 }` and `Ack { seq: 5 }` have the same body bytes
        // (tag 1, varint 5): only the direction byte in the CRC tells them apart.
        let ping = EncodedFrame::new(0, &HostMsg::Ping { nonce: 5 }).expect("fits");
        let ack = EncodedFrame::new(0, &McuMsg::Ack { seq: 5 }).expect("fits");
        assert_eq!(ping[..4], ack[..4]);
        let got: Vec<_> = Decoder::<McuMsg>::new().feed(&ping).collect();
        assert_eq!(got, [Err(FrameError::Crc)]);
        let got: Vec<_> = Decoder::<HostMsg>::new().feed(&ack).collect();
        assert_eq!(got, [Err(FrameError::Crc)]);
    }

    #[test]
    fn max_frame_len_bounds_every_message() {
        assert_eq!(MAX_FRAME_LEN, MAX_ENCODED_LEN + 1);
        assert_eq!(max_frame_len_for(MAX_MESSAGE_LEN), MAX_FRAME_LEN);
        // The hello reply is the longest message: 66 bytes of postcard at most
        // (37 of them the calibration report).
        assert_eq!(
            McuMsg::POSTCARD_MAX_SIZE,
            1 + crate::HelloReply::POSTCARD_MAX_SIZE
        );
        assert_eq!(crate::CalibrationReport::POSTCARD_MAX_SIZE, 37);
        assert_eq!(MAX_MESSAGE_LEN, 66);
        assert_eq!(MAX_FRAME_LEN, 75, "stated in the crate docs");
        // Telemetry: 35 bytes of postcard at most, 44 on the wire.
        assert_eq!(MAX_TELEMETRY_FRAME_LEN, 44, "stated in the crate docs");
    }

    #[test]
    fn small_output_buffer_is_an_error_not_a_panic() {
        let mut out = [0u8; 8];
        assert_eq!(
            encode_into(0, &HostMsg::Ping { nonce: u32::MAX }, &mut out),
            Err(BufferTooSmall)
        );
    }
}
