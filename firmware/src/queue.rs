//! Fixed-size byte queues for the serial link, and the [`FrameSink`] trait
//! through which the controller sends frames.
//!
//! The board keeps one [`ByteQueue`] for received bytes (filled by the
//! USART interrupt, drained by the control loop) and one for bytes to send
//! (filled by the controller a whole frame at a time, drained into the
//! USART data register). No allocation; a full queue refuses instead of
//! overwriting.
//!
//! ```
//! use dexitac_firmware::{ByteQueue, FrameSink};
//! let mut q = ByteQueue::<4>::new();
//! q.send(&[1, 2, 3]).unwrap();
//! assert!(q.send(&[4, 5]).is_err()); // all or nothing
//! assert_eq!(q.pop(), Some(1));
//! ```

/// The queue has no room for the bytes offered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QueueFull;

impl core::fmt::Display for QueueFull {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("queue full")
    }
}

/// Where the controller sends complete wire frames (0x00 delimiter included).
pub trait FrameSink {
    /// Takes the whole frame or none of it.
    fn send(&mut self, frame: &[u8]) -> Result<(), QueueFull>;
}

/// A ring buffer of at most `N` bytes.
#[derive(Debug, Clone)]
pub struct ByteQueue<const N: usize> {
    buf: [u8; N],
    head: usize,
    len: usize,
}

impl<const N: usize> Default for ByteQueue<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> ByteQueue<N> {
    /// An empty queue.
    pub const fn new() -> Self {
        ByteQueue {
            buf: [0; N],
            head: 0,
            len: 0,
        }
    }

    /// Bytes in the queue.
    pub const fn len(&self) -> usize {
        self.len
    }

    /// Whether the queue is empty.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Free room, in bytes.
    pub const fn room(&self) -> usize {
        N - self.len
    }

    /// Appends one byte.
    pub fn push(&mut self, byte: u8) -> Result<(), QueueFull> {
        if self.len >= N {
            return Err(QueueFull);
        }
        let at = (self.head + self.len) % N;
        let slot = self.buf.get_mut(at).ok_or(QueueFull)?;
        *slot = byte;
        self.len += 1;
        Ok(())
    }

    /// The oldest byte, without removing it.
    pub fn peek(&self) -> Option<u8> {
        if self.len == 0 {
            return None;
        }
        self.buf.get(self.head).copied()
    }

    /// Removes and returns the oldest byte.
    pub fn pop(&mut self) -> Option<u8> {
        let byte = self.peek()?;
        self.head = (self.head + 1) % N;
        self.len -= 1;
        Some(byte)
    }

    /// Moves up to `out.len()` bytes into `out`; returns how many.
    pub fn pop_into(&mut self, out: &mut [u8]) -> usize {
        let mut n = 0;
        for slot in out.iter_mut() {
            match self.pop() {
                Some(byte) => {
                    *slot = byte;
                    n += 1;
                }
                None => break,
            }
        }
        n
    }
}

impl<const N: usize> FrameSink for ByteQueue<N> {
    fn send(&mut self, frame: &[u8]) -> Result<(), QueueFull> {
        if frame.len() > self.room() {
            return Err(QueueFull);
        }
        frame.iter().try_for_each(|&b| self.push(b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn queue_wraps_around_in_order() {
        let mut q = ByteQueue::<3>::new();
        for round in 0..10u8 {
            q.send(&[round, round.wrapping_add(1)]).unwrap();
            assert_eq!(q.pop(), Some(round));
            assert_eq!(q.pop(), Some(round.wrapping_add(1)));
            assert!(q.is_empty());
        }
    }

    #[test]
    fn full_queue_refuses_a_frame_whole() {
        let mut q = ByteQueue::<4>::new();
        q.send(&[1, 2]).unwrap();
        assert_eq!(q.send(&[3, 4, 5]), Err(QueueFull));
        assert_eq!(q.len(), 2);
        let mut out = [0; 8];
        assert_eq!(q.pop_into(&mut out), 2);
        assert_eq!(&out[..2], &[1, 2]);
    }

    #[test]
    fn zero_capacity_queue_refuses_everything() {
        let mut q = ByteQueue::<0>::new();
        assert_eq!(q.push(1), Err(QueueFull));
        assert_eq!(q.pop(), None);
    }
}
