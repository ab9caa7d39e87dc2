//! The serial link to the MCU: framing, sequence numbers, acks, retries,
//! heartbeat, telemetry, and reconnection after the board resets.
//!
//! The host side of the wire protocol ([`dexitac_protocol`]). A [`Link`]
//! owns a byte port — a real serial port ([`Link::open`], through the
//! `serialport` crate), a pseudo-terminal of the simulated rig, or any
//! `Read + Write` in tests — and turns commands into frames and frames into
//! replies and [`McuEvent`]s.
//!
//! - Every frame goes out as `0x00 | frame`: the leading delimiter ends any
//!   noise on the line, so the frame itself arrives intact.
//! - [`Link::command`] waits for the ack or nack carrying the frame's sequence
//!   number; on a timeout it sends the same frame again (same sequence
//!   number; every command is idempotent), up to [`LinkConfig::retries`] times.
//! - [`Link::hello`] checks the protocol version, the hard limits and the
//!   chamber count compiled into the firmware, with a clear error on mismatch.
//! - Telemetry and fault frames that arrive while waiting are queued and
//!   returned by [`Link::poll`]. A board reset shows as telemetry silence
//!   (the firmware restarts with telemetry off: [`Link::telemetry_silent_for`]) or as a
//!   telemetry clock that runs backwards ([`McuEvent::McuReset`]); either
//!   way [`Link::reconnect`] or [`Link::hello`] tells the reset cause.
//! - [`Link::keep_alive`] sends a heartbeat when nothing was sent for
//!   [`LinkConfig::heartbeat_ms`], so an armed MCU does not trip on host
//!   silence.
//! - Every time (ack timeouts, heartbeat, silence) is read on the link's
//!   [`Clock`]: the wall clock by default, the simulated rig's clock with
//!   [`Link::with_clock`] (a virtual clock's port advances the time while
//!   the link waits for bytes).

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::source::Clock;

use dexitac_protocol::{
    Decoder, EncodedFrame, FaultEvent, Frame, HelloReply, HostMsg, McuMsg, NackReason, Telemetry,
    CHAMBER_COUNT, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA, PROTOCOL_VERSION,
};

/// Serial link settings.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    /// Line speed, baud (the firmware's USART1 runs at 115 200).
    pub baud: u32,
    /// How long to wait for an ack before sending again, ms of the link's clock.
    pub ack_timeout_ms: u64,
    /// How many times a command is sent again after a timeout.
    pub retries: u32,
    /// Send a heartbeat when nothing was sent for this long, ms of the
    /// link's clock. Keep it well under the firmware's host-silence deadline
    /// (500 ms by default).
    pub heartbeat_ms: u64,
    /// Read timeout of one port read, ms (the granularity of every wait).
    pub read_timeout_ms: u64,
}

impl Default for LinkConfig {
    fn default() -> Self {
        LinkConfig {
            baud: 115_200,
            ack_timeout_ms: 100,
            retries: 3,
            heartbeat_ms: 100,
            read_timeout_ms: 2,
        }
    }
}

/// Why a link operation failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The serial port could not be opened.
    #[error("cannot open serial port {path}: {source}")]
    Open {
        /// The port's path.
        path: PathBuf,
        /// What serialport said.
        source: serialport::Error,
    },
    /// Reading or writing the port failed (e.g. the USB adapter was unplugged).
    #[error("serial I/O error: {0}")]
    Io(#[from] io::Error),
    /// No answer to a frame after every retry.
    #[error("no answer to {msg:?} (seq {seq}) after {attempts} attempts")]
    Timeout {
        /// The command.
        msg: HostMsg,
        /// Its sequence number.
        seq: u16,
        /// How many times it was sent.
        attempts: u32,
    },
    /// The MCU refused a command.
    #[error("the MCU refused {msg:?} (seq {seq}): {reason:?}")]
    Nack {
        /// The command.
        msg: HostMsg,
        /// Its sequence number.
        seq: u16,
        /// The MCU's reason.
        reason: NackReason,
    },
    /// The firmware speaks another protocol version.
    #[error("firmware speaks protocol v{mcu}, this host v{host}: flash a matching firmware (`cargo fw-run`)")]
    VersionMismatch {
        /// The firmware's version.
        mcu: u8,
        /// This host's version.
        host: u8,
    },
    /// The firmware's compiled-in hard limits or chamber count differ from the host's.
    #[error(
        "firmware limits differ from the host's: tanks {mcu_max_pa}/{mcu_min_pa} Pa with {mcu_chambers} chambers, expected {POSITIVE_TANK_MAX_PA}/{NEGATIVE_TANK_MIN_PA} Pa with {CHAMBER_COUNT}"
    )]
    LimitsMismatch {
        /// The firmware's positive tank limit, Pa.
        mcu_max_pa: i32,
        /// The firmware's negative tank limit, Pa.
        mcu_min_pa: i32,
        /// The firmware's chamber count.
        mcu_chambers: u8,
    },
    /// The port is closed (a reconnect failed).
    #[error("the serial port is closed")]
    Disconnected,
    /// A frame did not fit its buffer (a protocol crate bug).
    #[error("frame encoding failed")]
    Encode,
}

/// Something the MCU reported on its own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum McuEvent {
    /// A telemetry report.
    Telemetry(Telemetry),
    /// A fault tripped the safety loop.
    Fault(FaultEvent),
    /// The MCU restarted (its telemetry clock went backwards): it is
    /// disarmed and must be set up again.
    McuReset,
}

/// Counters of the link's traffic.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Frames sent, retries included.
    pub frames_sent: u64,
    /// Commands sent again after an ack timeout.
    pub retries: u64,
    /// Valid frames received.
    pub frames_received: u64,
    /// Received byte runs that were not valid frames.
    pub frame_errors: u64,
}

/// One read from a port whose reads time out: a timeout (or an interrupted
/// or would-block read) means "no bytes yet", `Ok(0)`.
pub fn read_ready(port: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    match port.read(buf) {
        Ok(n) => Ok(n),
        Err(e)
            if matches!(
                e.kind(),
                io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
            ) =>
        {
            Ok(0)
        }
        Err(e) => Err(e),
    }
}

/// A byte port the link can drive.
pub trait Port: Read + Write + Send {}
impl<T: Read + Write + Send> Port for T {}

/// The host end of the serial link.
pub struct Link<P> {
    /// `None` only while [`Link::reconnect`] reopens the port.
    port: Option<P>,
    config: LinkConfig,
    decoder: Decoder<McuMsg>,
    next_seq: u16,
    clock: Clock,
    last_tx_us: Option<u64>,
    last_command_written_us: Option<u64>,
    last_mcu_time_ms: Option<u32>,
    last_rx_us: u64,
    last_telemetry_us: u64,
    events: VecDeque<McuEvent>,
    stats: LinkStats,
    path: Option<PathBuf>,
}

/// A link over a real (or pseudo-terminal) serial port.
pub type SerialLink = Link<Box<dyn serialport::SerialPort>>;

fn open_port(
    path: &Path,
    config: &LinkConfig,
) -> Result<Box<dyn serialport::SerialPort>, LinkError> {
    serialport::new(path.to_string_lossy(), config.baud)
        .timeout(Duration::from_millis(config.read_timeout_ms.max(1)))
        .open()
        .map_err(|source| LinkError::Open {
            path: path.to_path_buf(),
            source,
        })
}

impl SerialLink {
    /// Opens the serial port at `path`. Nothing is sent yet: call
    /// [`Link::hello`] next.
    pub fn open(path: impl AsRef<Path>, config: LinkConfig) -> Result<Self, LinkError> {
        let path = path.as_ref();
        let port = open_port(path, &config)?;
        let mut link = Link::new(port, config);
        link.path = Some(path.to_path_buf());
        Ok(link)
    }

    /// Reopens the port (after an unplug or a board reset) and says hello
    /// again, trying until `deadline`. Pending events are dropped; the MCU
    /// comes back disarmed.
    pub fn reconnect(&mut self, deadline: Instant) -> Result<HelloReply, LinkError> {
        let path = self.path.clone().ok_or_else(|| {
            LinkError::Io(io::Error::new(
                io::ErrorKind::Unsupported,
                "link has no port path",
            ))
        })?;
        // Close the old port first: ports are opened exclusively.
        self.port = None;
        loop {
            let attempt = open_port(&path, &self.config).and_then(|port| {
                self.port = Some(port);
                self.decoder.reset();
                self.events.clear();
                self.last_mcu_time_ms = None;
                self.hello()
            });
            match attempt {
                Ok(reply) => return Ok(reply),
                Err(e) if Instant::now() >= deadline => return Err(e),
                Err(e) => {
                    tracing::debug!("link: reconnecting to {}: {e}", path.display());
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        }
    }
}

impl<P: Port> Link<P> {
    /// A link over an already open port, on the wall clock. The port's
    /// reads should time out after a few milliseconds (a `TimedOut` or
    /// `WouldBlock` read counts as "no bytes yet").
    pub fn new(port: P, config: LinkConfig) -> Self {
        Link::with_clock(port, config, Clock::wall())
    }

    /// A link over an already open port whose timeouts run on `clock`.
    pub fn with_clock(port: P, config: LinkConfig, clock: Clock) -> Self {
        Link {
            port: Some(port),
            config,
            decoder: Decoder::new(),
            next_seq: 0,
            last_rx_us: clock.now_us(),
            last_telemetry_us: clock.now_us(),
            clock,
            last_tx_us: None,
            last_command_written_us: None,
            last_mcu_time_ms: None,
            events: VecDeque::new(),
            stats: LinkStats::default(),
            path: None,
        }
    }

    /// The settings.
    pub fn config(&self) -> &LinkConfig {
        &self.config
    }

    /// Traffic counters.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// Moves the link's timeouts to `clock` (the task loop's). The times
    /// noted so far are forgotten: the next [`Link::keep_alive`] sends a
    /// heartbeat, and the silence counts from now.
    pub fn set_clock(&mut self, clock: Clock) {
        self.last_rx_us = clock.now_us();
        self.last_telemetry_us = self.last_rx_us;
        self.last_tx_us = None;
        self.last_command_written_us = None;
        self.clock = clock;
    }

    /// The clock the link's timeouts run on.
    pub fn clock(&self) -> &Clock {
        &self.clock
    }

    /// When the bytes of the last request's first attempt were written
    /// (handed to the kernel's tty driver), µs on the link's clock.
    pub fn last_command_written_us(&self) -> Option<u64> {
        self.last_command_written_us
    }

    /// Time since the last valid frame from the MCU (or since the link was
    /// made), on the link's clock. With telemetry on, a value of several
    /// telemetry periods means the line is dead; a board that restarted
    /// still acks, so see [`Link::telemetry_silent_for`] for that.
    pub fn silent_for(&self) -> Duration {
        Duration::from_micros(self.clock.now_us().saturating_sub(self.last_rx_us))
    }

    /// Time since the last telemetry report (or since the link was made or
    /// moved to its clock). Acks keep coming from a board that restarted
    /// (it boots with telemetry off), telemetry does not: with telemetry
    /// on, a value of several periods means the MCU reset.
    pub fn telemetry_silent_for(&self) -> Duration {
        Duration::from_micros(self.clock.now_us().saturating_sub(self.last_telemetry_us))
    }

    /// Says hello: checks protocol version, hard limits and chamber count.
    pub fn hello(&mut self) -> Result<HelloReply, LinkError> {
        let reply = match self.request(HostMsg::Hello)? {
            (_, McuMsg::HelloReply(reply)) => reply,
            // `request` only returns the reply it waited for.
            (seq, _) => {
                return Err(LinkError::Timeout {
                    msg: HostMsg::Hello,
                    seq,
                    attempts: 0,
                })
            }
        };
        if reply.protocol_version != PROTOCOL_VERSION {
            return Err(LinkError::VersionMismatch {
                mcu: reply.protocol_version,
                host: PROTOCOL_VERSION,
            });
        }
        if reply.positive_tank_max_pa != POSITIVE_TANK_MAX_PA
            || reply.negative_tank_min_pa != NEGATIVE_TANK_MIN_PA
            || usize::from(reply.chamber_count) != CHAMBER_COUNT
        {
            return Err(LinkError::LimitsMismatch {
                mcu_max_pa: reply.positive_tank_max_pa,
                mcu_min_pa: reply.negative_tank_min_pa,
                mcu_chambers: reply.chamber_count,
            });
        }
        Ok(reply)
    }

    /// Sends a command and waits for its ack; a nack is an error.
    pub fn command(&mut self, msg: HostMsg) -> Result<(), LinkError> {
        match self.request(msg)? {
            (_, McuMsg::Ack { .. }) => Ok(()),
            (seq, McuMsg::Nack { reason, .. }) => Err(LinkError::Nack { msg, seq, reason }),
            (seq, _) => Err(LinkError::Timeout {
                msg,
                seq,
                attempts: 0,
            }),
        }
    }

    /// Sends a command without waiting for its ack (its ack is consumed by
    /// later reads). Returns the sequence number used.
    pub fn send(&mut self, msg: HostMsg) -> Result<u16, LinkError> {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        self.write_frame(seq, msg)?;
        Ok(seq)
    }

    /// Sends a heartbeat if nothing was sent for [`LinkConfig::heartbeat_ms`].
    /// Returns whether it sent one.
    pub fn keep_alive(&mut self) -> Result<bool, LinkError> {
        let now_us = self.clock.now_us();
        let due = self
            .last_tx_us
            .is_none_or(|t| now_us.saturating_sub(t) >= self.config.heartbeat_ms * 1_000);
        if due {
            self.send(HostMsg::Heartbeat)?;
        }
        Ok(due)
    }

    /// Reads for up to `wait` (at least one port read) and returns every
    /// event received so far.
    pub fn poll(&mut self, wait: Duration) -> Result<Vec<McuEvent>, LinkError> {
        let wait_us = u64::try_from(wait.as_micros()).unwrap_or(u64::MAX);
        let until_us = self.clock.now_us().saturating_add(wait_us);
        loop {
            self.read_some(|_| false)?;
            if self.clock.now_us() >= until_us {
                break;
            }
        }
        Ok(self.events.drain(..).collect())
    }

    /// Sends `msg` and waits for the reply that answers it: an ack or nack
    /// with its sequence number, or for `Hello` a hello reply.
    fn request(&mut self, msg: HostMsg) -> Result<(u16, McuMsg), LinkError> {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        let answers = |m: &McuMsg| match m {
            McuMsg::Ack { seq: s } | McuMsg::Nack { seq: s, .. } => {
                *s == seq && msg != HostMsg::Hello
            }
            McuMsg::HelloReply(_) => msg == HostMsg::Hello,
            _ => false,
        };
        let attempts = self.config.retries + 1;
        for attempt in 0..attempts {
            if attempt > 0 {
                self.stats.retries += 1;
                tracing::debug!(
                    "link: no answer to #{seq} {msg:?}, sending again (attempt {})",
                    attempt + 1
                );
            } else {
                tracing::trace!("link: #{seq} {msg:?}");
            }
            self.write_frame(seq, msg)?;
            if attempt == 0 {
                self.last_command_written_us = self.last_tx_us;
            }
            let until_us = self.clock.now_us() + self.config.ack_timeout_ms * 1_000;
            while self.clock.now_us() < until_us {
                if let Some(reply) = self.read_some(answers)? {
                    tracing::trace!("link: #{seq} answered: {reply:?}");
                    return Ok((seq, reply));
                }
            }
        }
        tracing::warn!("link: #{seq} {msg:?} unanswered after {attempts} attempt(s)");
        Err(LinkError::Timeout { msg, seq, attempts })
    }

    fn write_frame(&mut self, seq: u16, msg: HostMsg) -> Result<(), LinkError> {
        let frame = EncodedFrame::new(seq, &msg).map_err(|_| LinkError::Encode)?;
        let mut bytes = Vec::with_capacity(frame.len() + 1);
        bytes.push(0);
        bytes.extend_from_slice(&frame);
        let port = self.port.as_mut().ok_or(LinkError::Disconnected)?;
        // No flush: on a tty it is tcdrain, which blocks until the far end
        // has taken the bytes (on a pty: until the simulated MCU's thread
        // runs), stalling the heartbeat. Serial ports and ptys do not buffer
        // in user space, so the bytes are handed to the kernel here.
        port.write_all(&bytes)?;
        self.stats.frames_sent += 1;
        self.last_tx_us = Some(self.clock.now_us());
        Ok(())
    }

    /// One port read. Frames that `wanted` accepts are returned (the first
    /// one); every other frame is filed as an event or dropped (stray acks).
    fn read_some(&mut self, wanted: impl Fn(&McuMsg) -> bool) -> Result<Option<McuMsg>, LinkError> {
        let mut buf = [0u8; 256];
        let port = self.port.as_mut().ok_or(LinkError::Disconnected)?;
        let n = read_ready(port, &mut buf)?;
        let mut found = None;
        let frames: Vec<_> = self.decoder.feed(buf.get(..n).unwrap_or(&[])).collect();
        for result in frames {
            let Ok(Frame { msg, .. }) = result else {
                self.stats.frame_errors += 1;
                continue;
            };
            self.stats.frames_received += 1;
            self.last_rx_us = self.clock.now_us();
            if found.is_none() && wanted(&msg) {
                found = Some(msg);
                continue;
            }
            self.file_event(msg);
        }
        Ok(found)
    }

    fn file_event(&mut self, msg: McuMsg) {
        match msg {
            McuMsg::Telemetry(t) => {
                if self.last_mcu_time_ms.is_some_and(|last| t.time_ms < last) {
                    self.events.push_back(McuEvent::McuReset);
                }
                self.last_mcu_time_ms = Some(t.time_ms);
                self.last_telemetry_us = self.clock.now_us();
                self.events.push_back(McuEvent::Telemetry(t));
            }
            McuMsg::Fault(f) => self.events.push_back(McuEvent::Fault(f)),
            // Late answers to a retried request.
            McuMsg::HelloReply(_) | McuMsg::Ack { .. } | McuMsg::Nack { .. } => {}
        }
    }
}
