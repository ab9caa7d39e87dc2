//! Fixed-size byte queues for the serial link's transmit side, and the
//! [`FrameSink`] trait through which the controller sends frames.
//!
//! Every outgoing frame has a [`Priority`]. [`TxQueues`] keeps one queue per
//! priority and hands the USART whole frames, an urgent one (ack, nack,
//! hello reply, fault event) before any telemetry frame that waits: telemetry
//! can only be dropped for lack of room in its own queue, never an urgent
//! frame to make room for telemetry. (Received bytes go from the USART
//! interrupt to the control loop through a `heapless::spsc` queue on the
//! board.) No allocation; a full queue refuses a frame whole.
//!
//! ```
//! use dexitac_firmware::{FrameSink, Priority, TxQueues};
//! let mut q = TxQueues::<8, 8>::new();
//! q.send(&[9, 9, 0], Priority::Telemetry).unwrap();
//! q.send(&[1, 0], Priority::Urgent).unwrap();
//! let mut out = Vec::new();
//! while let Some(b) = q.pop() { out.push(b); }
//! assert_eq!(out, [1, 0, 9, 9, 0]); // the urgent frame first
//! ```

/// The queue has no room for the bytes offered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QueueFull;

impl core::fmt::Display for QueueFull {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("queue full")
    }
}

/// How urgent an outgoing frame is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Priority {
    /// Replies and fault events: sent before any waiting telemetry.
    Urgent,
    /// Periodic telemetry: dropped first when the line is busy.
    Telemetry,
}

/// Where the controller sends complete wire frames (0x00 delimiter included).
pub trait FrameSink {
    /// Takes the whole frame or none of it.
    fn send(&mut self, frame: &[u8], priority: Priority) -> Result<(), QueueFull>;
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

impl<const N: usize> ByteQueue<N> {
    /// Appends a whole frame, or nothing if it does not fit.
    pub fn push_frame(&mut self, frame: &[u8]) -> Result<(), QueueFull> {
        if frame.len() > self.room() {
            return Err(QueueFull);
        }
        frame.iter().try_for_each(|&b| self.push(b))
    }
}

/// One frame queue per [`Priority`]: `U` bytes for urgent frames, `T` for
/// telemetry. Bytes leave one whole frame at a time (frames end in 0x00),
/// urgent frames first.
#[derive(Debug, Clone)]
pub struct TxQueues<const U: usize, const T: usize> {
    urgent: ByteQueue<U>,
    telemetry: ByteQueue<T>,
    /// The queue whose frame is on the line (None: between frames).
    sending: Option<Priority>,
}

impl<const U: usize, const T: usize> Default for TxQueues<U, T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const U: usize, const T: usize> TxQueues<U, T> {
    /// Both queues empty.
    pub const fn new() -> Self {
        TxQueues {
            urgent: ByteQueue::new(),
            telemetry: ByteQueue::new(),
            sending: None,
        }
    }

    /// The queue the next byte comes from.
    fn source(&self) -> Option<Priority> {
        match self.sending {
            Some(p) => Some(p),
            None if !self.urgent.is_empty() => Some(Priority::Urgent),
            None if !self.telemetry.is_empty() => Some(Priority::Telemetry),
            None => None,
        }
    }

    /// The next byte to send, without removing it.
    pub fn peek(&self) -> Option<u8> {
        match self.source()? {
            Priority::Urgent => self.urgent.peek(),
            Priority::Telemetry => self.telemetry.peek(),
        }
    }

    /// Removes and returns the next byte to send.
    pub fn pop(&mut self) -> Option<u8> {
        let source = self.source()?;
        let byte = match source {
            Priority::Urgent => self.urgent.pop(),
            Priority::Telemetry => self.telemetry.pop(),
        }?;
        // A frame ends with its 0x00 delimiter (COBS keeps 0x00 out of it).
        self.sending = if byte == 0 { None } else { Some(source) };
        Some(byte)
    }

    /// Whether nothing waits.
    pub const fn is_empty(&self) -> bool {
        self.urgent.is_empty() && self.telemetry.is_empty()
    }
}

impl<const U: usize, const T: usize> FrameSink for TxQueues<U, T> {
    fn send(&mut self, frame: &[u8], priority: Priority) -> Result<(), QueueFull> {
        match priority {
            Priority::Urgent => self.urgent.push_frame(frame),
            Priority::Telemetry => self.telemetry.push_frame(frame),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urgent_frames_wait_for_the_frame_on_the_line_then_go_first() {
        let mut q = TxQueues::<16, 8>::new();
        q.send(&[7, 7, 0], Priority::Telemetry).unwrap();
        q.send(&[8, 8, 0], Priority::Telemetry).unwrap();
        assert_eq!(q.pop(), Some(7));
        // An ack arrives while the first telemetry frame is on the line.
        q.send(&[1, 0], Priority::Urgent).unwrap();
        let rest: std::vec::Vec<u8> = core::iter::from_fn(|| q.pop()).collect();
        assert_eq!(rest, [7, 0, 1, 0, 8, 8, 0]);
    }

    #[test]
    fn full_telemetry_queue_never_blocks_an_urgent_frame() {
        let mut q = TxQueues::<4, 4>::new();
        q.send(&[7, 7, 7, 0], Priority::Telemetry).unwrap();
        assert_eq!(q.send(&[8, 0], Priority::Telemetry), Err(QueueFull));
        assert_eq!(q.send(&[1, 2, 0], Priority::Urgent), Ok(()));
        assert_eq!(q.peek(), Some(1));
    }

    #[test]
    fn queue_wraps_around_in_order() {
        let mut q = ByteQueue::<3>::new();
        for round in 0..10u8 {
            q.push_frame(&[round, round.wrapping_add(1)]).unwrap();
            assert_eq!(q.pop(), Some(round));
            assert_eq!(q.pop(), Some(round.wrapping_add(1)));
            assert!(q.is_empty());
        }
    }

    #[test]
    fn full_queue_refuses_a_frame_whole() {
        let mut q = ByteQueue::<4>::new();
        q.push_frame(&[1, 2]).unwrap();
        assert_eq!(q.push_frame(&[3, 4, 5]), Err(QueueFull));
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
