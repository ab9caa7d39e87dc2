//! A scripted fake board for the link and task-loop tests: an in-memory
//! byte port ([`FakeBoard`]) that decodes every host frame, logs it, and
//! lets a script answer it (or not). Answers are queued synchronously while
//! the host writes, so what the host reads next depends only on the script,
//! never on thread timing.
//!
//! Reads of an empty port sleep 1 ms and time out, as a serial port with a
//! short read timeout does.
//!
//! Shared by several test binaries, each using part of it.
#![allow(dead_code)]

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use dexitac_protocol::{
    Decoder, EncodedFrame, FaultFlags, Frame, HelloReply, HostMsg, McuMsg, NackReason, ResetCause,
    CHAMBER_COUNT, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA, PROTOCOL_VERSION,
};

/// What the board sends back, in order.
#[derive(Default)]
pub struct Outbox {
    bytes: VecDeque<u8>,
    seq: u16,
}

impl Outbox {
    fn encode(&mut self, msg: &McuMsg) -> Vec<u8> {
        let frame = EncodedFrame::new(self.seq, msg).expect("every message fits a frame");
        self.seq = self.seq.wrapping_add(1);
        frame.to_vec()
    }

    /// Queues `msg`.
    pub fn send(&mut self, msg: McuMsg) {
        let bytes = self.encode(&msg);
        self.bytes.extend(bytes);
    }

    /// Queues `msg` with one bit flipped (line noise): the host's decoder
    /// must reject it.
    pub fn send_corrupted(&mut self, msg: McuMsg) {
        let mut bytes = self.encode(&msg);
        // The byte before the trailing delimiter (the CRC's last byte); a
        // flip that made it a delimiter would split the frame instead.
        let at = bytes.len() - 2;
        bytes[at] ^= if bytes[at] == 0x01 { 0x02 } else { 0x01 };
        self.bytes.extend(bytes);
    }

    /// Acks `frame`.
    pub fn ack(&mut self, frame: &Frame<HostMsg>) {
        self.send(McuMsg::Ack { seq: frame.seq });
    }

    /// Nacks `frame` with `reason`.
    pub fn nack(&mut self, frame: &Frame<HostMsg>, reason: NackReason) {
        self.send(McuMsg::Nack {
            seq: frame.seq,
            reason,
        });
    }
}

/// A hello reply matching this host: protocol version, hard limits and
/// chamber count as compiled in, no latched faults.
pub fn matching_hello() -> HelloReply {
    HelloReply {
        protocol_version: PROTOCOL_VERSION,
        firmware_version: dexitac_firmware::FIRMWARE_VERSION,
        positive_tank_max_pa: POSITIVE_TANK_MAX_PA,
        negative_tank_min_pa: NEGATIVE_TANK_MIN_PA,
        chamber_count: CHAMBER_COUNT as u8,
        reset_cause: ResetCause::PowerOn,
        latched_faults: FaultFlags::NONE,
        last_stop: Default::default(),
        min_telemetry_interval_ms: 8,
        calibration: Default::default(),
    }
}

/// A healthy board's answer: a hello reply to `Hello`, an ack to anything else.
pub fn answer(hello: HelloReply, frame: &Frame<HostMsg>, out: &mut Outbox) {
    match frame.msg {
        HostMsg::Hello => out.send(McuMsg::HelloReply(hello)),
        _ => out.ack(frame),
    }
}

/// Every frame the host sent, in order (shared with the test while the
/// board is owned by the link).
#[derive(Clone, Default)]
pub struct HostLog(Arc<Mutex<Vec<Frame<HostMsg>>>>);

impl HostLog {
    fn lock(&self) -> MutexGuard<'_, Vec<Frame<HostMsg>>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Every frame so far.
    pub fn frames(&self) -> Vec<Frame<HostMsg>> {
        self.lock().clone()
    }

    /// Every message so far except heartbeats (sent whenever the link is
    /// idle, so their number depends on timing).
    pub fn commands(&self) -> Vec<HostMsg> {
        self.lock()
            .iter()
            .map(|f| f.msg)
            .filter(|m| *m != HostMsg::Heartbeat)
            .collect()
    }
}

/// The script: called with every valid host frame, queues the answers.
pub type Script = Box<dyn FnMut(&Frame<HostMsg>, &mut Outbox) + Send>;

/// The fake board: the host end of its serial line.
pub struct FakeBoard {
    script: Script,
    decoder: Decoder<HostMsg>,
    out: Outbox,
    log: HostLog,
}

impl FakeBoard {
    /// A board that runs `script` on every host frame.
    pub fn new(script: impl FnMut(&Frame<HostMsg>, &mut Outbox) + Send + 'static) -> Self {
        FakeBoard {
            script: Box::new(script),
            decoder: Decoder::new(),
            out: Outbox::default(),
            log: HostLog::default(),
        }
    }

    /// A board that answers like [`answer`] with `hello`.
    pub fn healthy(hello: HelloReply) -> Self {
        FakeBoard::new(move |frame, out| answer(hello, frame, out))
    }

    /// The log of what the host sent (keep it before handing the board to a link).
    pub fn log(&self) -> HostLog {
        self.log.clone()
    }
}

impl Write for FakeBoard {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let frames: Vec<_> = self.decoder.feed(buf).collect();
        for frame in frames {
            let frame = frame.expect("the host sends valid frames");
            self.log.lock().push(frame);
            (self.script)(&frame, &mut self.out);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Read for FakeBoard {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.out.bytes.is_empty() {
            std::thread::sleep(Duration::from_millis(1));
            return Err(io::ErrorKind::TimedOut.into());
        }
        let mut n = 0;
        while let Some(slot) = buf.get_mut(n) {
            let Some(byte) = self.out.bytes.pop_front() else {
                break;
            };
            *slot = byte;
            n += 1;
        }
        Ok(n)
    }
}
