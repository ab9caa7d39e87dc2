//! One frame on the wire, and how it is encoded and checked.
//!
//! ```text
//! raw   = version:u8 | seq:u16 LE | postcard(message) | crc32c(version..message):u32 LE
//! wire  = COBS(raw) | 0x00
//! ```
//!
//! The CRC is CRC-32C (Castagnoli, `crc::CRC_32_ISCSI`): it catches every
//! single-bit and every burst error up to 32 bits in a frame this short.
//! COBS removes every 0x00 from the frame so that 0x00 can delimit frames;
//! a receiver that joins mid-stream resynchronises at the next 0x00.
//! [`MAX_FRAME_LEN`] bounds every frame on the wire, delimiter included.

use core::fmt;

use crc::{Crc, CRC_32_ISCSI};
use postcard::experimental::max_size::MaxSize;

use crate::message::{HostMsg, McuMsg, Message};
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
            FrameError::WrongVersion { version } => write!(
                f,
                "protocol version {version}, expected {PROTOCOL_VERSION}"
            ),
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
    let crc = CRC32C.checksum(raw.get(..crc_at).ok_or(BufferTooSmall)?);
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
        f.debug_tuple("EncodedFrame").field(&self.as_bytes()).finish()
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

/// Checks and decodes a raw (un-COBSed) frame: CRC, version, then message.
fn check_raw<M: Message>(raw: &[u8]) -> Result<Frame<M>, FrameError> {
    if raw.len() < HEADER_LEN + 1 + CRC_LEN {
        return Err(FrameError::TooShort);
    }
    let (checked, crc) = raw.split_at(raw.len() - CRC_LEN);
    let crc_bytes: [u8; CRC_LEN] = crc.try_into().map_err(|_| FrameError::TooShort)?;
    if CRC32C.checksum(checked) != u32::from_le_bytes(crc_bytes) {
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
