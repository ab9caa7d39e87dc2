//! Streaming frame decoder: feed it any bytes, get frames or typed errors.
//!
//! It keeps one fixed buffer of [`MAX_ENCODED_LEN`] bytes (no allocation),
//! never panics, and after garbage, a corrupted frame or an overlong run of
//! bytes it resynchronises at the next 0x00 delimiter. Empty frames (two
//! delimiters in a row) are skipped silently, so a sender on a noisy line
//! should start each frame with a 0x00 too: noise before the frame then ends
//! as an error of its own instead of spoiling the frame.
//!
//! ```
//! use dexitac_protocol::{Decoder, EncodedFrame, Frame, HostMsg};
//! let frame = EncodedFrame::new(3, &HostMsg::Ping { nonce: 42 }).unwrap();
//! let mut stream = b"\x13\x37garbage\x00".to_vec(); // noise first
//! stream.extend_from_slice(&frame);
//!
//! let mut decoder = Decoder::<HostMsg>::new();
//! let results: Vec<_> = decoder.feed(&stream).collect();
//! assert!(results[0].is_err()); // the noise, reported
//! assert_eq!(results[1], Ok(Frame { seq: 3, msg: HostMsg::Ping { nonce: 42 } }));
//! ```

use core::marker::PhantomData;

use crate::frame::{decode_in_place, Frame, FrameError, MAX_ENCODED_LEN};
use crate::message::Message;

/// Assembles frames of message type `M` from a byte stream.
pub struct Decoder<M> {
    buf: [u8; MAX_ENCODED_LEN],
    len: usize,
    /// Dropping bytes until the next delimiter after [`FrameError::TooLong`].
    discarding: bool,
    _msg: PhantomData<fn() -> M>,
}

impl<M: Message> Default for Decoder<M> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M: Message> Decoder<M> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Decoder {
            buf: [0; MAX_ENCODED_LEN],
            len: 0,
            discarding: false,
            _msg: PhantomData,
        }
    }

    /// Drops any partial frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.discarding = false;
    }

    /// Takes one byte; returns a frame or an error when one ends here.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame<M>, FrameError>> {
        if byte == 0 {
            let len = core::mem::take(&mut self.len);
            if core::mem::take(&mut self.discarding) || len == 0 {
                return None;
            }
            return Some(match self.buf.get_mut(..len) {
                Some(encoded) => decode_in_place(encoded),
                None => Err(FrameError::TooLong),
            });
        }
        if self.discarding {
            return None;
        }
        match self.buf.get_mut(self.len) {
            Some(slot) => {
                *slot = byte;
                self.len += 1;
                None
            }
            None => {
                self.len = 0;
                self.discarding = true;
                Some(Err(FrameError::TooLong))
            }
        }
    }

    /// Takes a chunk of bytes; the iterator yields every frame or error that
    /// ends inside it. Bytes after the last delimiter stay buffered for the
    /// next call. Dropping the iterator early leaves the unread bytes unread.
    pub fn feed<'d, 'b>(&'d mut self, bytes: &'b [u8]) -> Feed<'d, 'b, M> {
        Feed {
            decoder: self,
            bytes: bytes.iter(),
        }
    }
}

/// Iterator returned by [`Decoder::feed`].
pub struct Feed<'d, 'b, M> {
    decoder: &'d mut Decoder<M>,
    bytes: core::slice::Iter<'b, u8>,
}

impl<M: Message> Iterator for Feed<'_, '_, M> {
    type Item = Result<Frame<M>, FrameError>;

    fn next(&mut self) -> Option<Self::Item> {
        for &byte in self.bytes.by_ref() {
            if let Some(result) = self.decoder.push(byte) {
                return Some(result);
            }
        }
        None
    }
}
