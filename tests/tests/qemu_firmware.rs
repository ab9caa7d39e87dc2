//! The real firmware under QEMU, driven over a serial pty by the host.
//!
//! Builds the firmware with `--features qemu` (a nested `cargo build` into
//! its own target directory, `target/qemu`, so it never waits for the outer
//! cargo's build lock), boots it on `qemu-system-arm -M stm32vldiscovery`
//! with USART1 on a pseudo-terminal, and checks from the host side: hello,
//! ping, arm, set chambers, the telemetry stream, a malformed and a
//! corrupted frame (nothing actuated), the guard band and the telemetry
//! minimum, the sensor calibration (an implausible one refused, a plausible
//! one applied and reported in the hello reply as not persisted: the QEMU
//! build has no flash store; refused while armed), host silence -> tripped
//! within the deadline, and the latch:
//! disarm does not clear it, the hello reply reports it, `ClearFaults`
//! naming it does.
//!
//! Skips (with a message) when `qemu-system-arm` is not installed, unless
//! `DEXITAC_REQUIRE_QEMU` is set (to anything but empty or `0`; CI sets
//! `1`), which turns the skip into a failure.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use crc::{Crc, CRC_32_ISCSI};
use dexitac_protocol::{
    ArmState, Calibration, CalibrationRecord, CalibrationSource, Decoder, EncodedFrame, Fault,
    FaultEvent, FaultFlags, HelloReply, HostMsg, LastStop, McuMsg, Message, NackReason, PumpMode,
    ResetCause, SensorCalibration, TankTargets, Telemetry, ValveState, ZeroSource, CHAMBER_COUNT,
    NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA, PROTOCOL_VERSION,
};
use serialport::TTYPort;

#[path = "../support/required.rs"]
mod required;

/// The firmware's host-silence deadline (its default configuration).
const SILENCE_MS: u32 = dexitac_firmware::control::DEFAULT_HOST_SILENCE_MS;

/// Kills QEMU on every path out of the test, panics included.
struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        if let Err(e) = self.0.kill() {
            eprintln!("killing qemu: {e}");
        }
        if let Err(e) = self.0.wait() {
            eprintln!("waiting for qemu: {e}");
        }
    }
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// The variable that makes this test required (`.ci/run` sets it).
const REQUIRE_QEMU: &str = "DEXITAC_REQUIRE_QEMU";

/// The one way out of the test when it cannot run: fails under
/// [`REQUIRE_QEMU`], otherwise says "skipped" on stderr
/// (`tests/support/required.rs`).
fn skip(why: &str) {
    required::skip(REQUIRE_QEMU, "the QEMU firmware test", why);
}

#[test]
fn the_qemu_test_fails_when_it_cannot_run_only_if_required() {
    required::check_verdicts(REQUIRE_QEMU);
}

/// Whether QEMU is here; otherwise [`skip`].
fn qemu_available() -> bool {
    let found = Command::new("qemu-system-arm")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !found {
        skip("qemu-system-arm not found (apt-get install qemu-system-arm)");
    }
    found
}

/// Builds the QEMU firmware; returns the ELF's path.
fn build_firmware() -> PathBuf {
    let root = workspace_root();
    let target_dir = root.join("target").join("qemu");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(&root)
        // Host RUSTFLAGS would replace the thumbv7m linker flags of
        // .cargo/config.toml and break the link.
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .args([
            "build",
            "-p",
            "dexitac-firmware",
            "--target",
            "thumbv7m-none-eabi",
            "--release",
            "--features",
            "qemu",
            // The outer cargo has already brought Cargo.lock up to date.
            "--locked",
            "--target-dir",
        ])
        .arg(&target_dir)
        .status()
        .expect("running cargo build for the qemu firmware");
    assert!(status.success(), "building the qemu firmware failed");
    target_dir.join("thumbv7m-none-eabi/release/dexitac-firmware")
}

/// Boots `elf` with USART1 on a pty; returns QEMU and the pty's path.
fn boot(elf: &Path) -> (Qemu, String) {
    let mut child = Command::new("qemu-system-arm")
        .args([
            "-M",
            "stm32vldiscovery",
            "-display",
            "none",
            "-monitor",
            "none",
            "-serial",
            "pty",
            "-semihosting-config",
            "enable=on,target=native",
            "-kernel",
        ])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting qemu-system-arm");
    // QEMU says "char device redirected to /dev/pts/N (label serial0)", on
    // stderr or stdout depending on the version: watch both.
    let (found_tx, found_rx) = mpsc::channel::<String>();
    let streams: Vec<Box<dyn Read + Send>> = vec![
        Box::new(child.stdout.take().expect("piped stdout")),
        Box::new(child.stderr.take().expect("piped stderr")),
    ];
    let qemu = Qemu(child);
    for stream in streams {
        let found_tx = found_tx.clone();
        thread::spawn(move || {
            for line in BufReader::new(stream).lines().map_while(Result::ok) {
                eprintln!("qemu: {line}");
                if let Some(at) = line.find("/dev/pts/") {
                    let path: String = line[at..]
                        .chars()
                        .take_while(|c| !c.is_whitespace())
                        .collect();
                    // The receiver may be gone once one stream reported.
                    if found_tx.send(path).is_err() {
                        return;
                    }
                }
            }
        });
    }
    let pty = found_rx
        .recv_timeout(Duration::from_secs(10))
        .expect("qemu did not report its pty within 10 s");
    (qemu, pty)
}

/// The host end of the link.
struct Host {
    port: TTYPort,
    decoder: Decoder<McuMsg>,
    seq: u16,
    /// Every telemetry frame received, with its arrival time.
    telemetry: Vec<(Instant, Telemetry)>,
    faults: Vec<(Instant, FaultEvent)>,
}

impl Host {
    fn open(pty: &str) -> Host {
        let port = serialport::new(pty, 115_200)
            .timeout(Duration::from_millis(20))
            .open_native()
            .expect("opening the qemu pty");
        Host {
            port,
            decoder: Decoder::new(),
            seq: 0,
            telemetry: Vec::new(),
            faults: Vec::new(),
        }
    }

    fn write(&mut self, bytes: &[u8]) {
        self.port.write_all(bytes).expect("writing to the pty");
    }

    fn send(&mut self, msg: HostMsg) -> u16 {
        self.seq = self.seq.wrapping_add(1);
        let frame = EncodedFrame::new(self.seq, &msg).expect("every message fits a frame");
        self.write(&frame);
        self.seq
    }

    /// Reads for up to `wait`, filing telemetry and faults; returns every
    /// other message (replies).
    fn pump(&mut self, wait: Duration) -> Vec<McuMsg> {
        let until = Instant::now() + wait;
        let mut replies = Vec::new();
        let mut buf = [0u8; 256];
        loop {
            match self.port.read(&mut buf) {
                Ok(n) => {
                    let now = Instant::now();
                    for result in self.decoder.feed(&buf[..n]) {
                        match result.expect("the firmware sends valid frames").msg {
                            McuMsg::Telemetry(t) => self.telemetry.push((now, t)),
                            McuMsg::Fault(f) => self.faults.push((now, f)),
                            other => replies.push(other),
                        }
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => panic!("reading the pty: {e}"),
            }
            if Instant::now() >= until {
                return replies;
            }
        }
    }

    /// Sends `msg` and waits up to 1 s for the reply to it.
    fn request(&mut self, msg: HostMsg) -> McuMsg {
        let seq = self.send(msg);
        let until = Instant::now() + Duration::from_secs(1);
        while Instant::now() < until {
            for reply in self.pump(Duration::from_millis(20)) {
                match reply {
                    McuMsg::Ack { seq: s } | McuMsg::Nack { seq: s, .. } if s == seq => {
                        return reply
                    }
                    McuMsg::HelloReply(_) if msg == HostMsg::Hello => return reply,
                    _ => {}
                }
            }
        }
        panic!("no reply to {msg:?} (seq {seq}) within 1 s");
    }

    fn ack(&mut self, msg: HostMsg) {
        let seq = self.seq.wrapping_add(1);
        assert_eq!(self.request(msg), McuMsg::Ack { seq }, "{msg:?}");
    }

    fn nack(&mut self, msg: HostMsg, reason: NackReason) {
        let seq = self.seq.wrapping_add(1);
        assert_eq!(self.request(msg), McuMsg::Nack { seq, reason }, "{msg:?}");
    }

    fn hello(&mut self) -> HelloReply {
        match self.request(HostMsg::Hello) {
            McuMsg::HelloReply(h) => h,
            other => panic!("hello answered with {other:?}"),
        }
    }

    /// Keeps the link alive with heartbeats every 100 ms for `wait`.
    fn keep_alive(&mut self, wait: Duration) {
        let until = Instant::now() + wait;
        while Instant::now() < until {
            self.send(HostMsg::Heartbeat);
            self.pump(Duration::from_millis(100));
        }
    }
}

/// A host frame with a valid CRC around arbitrary header and body bytes.
fn frame_with_valid_crc(header_and_body: &[u8]) -> Vec<u8> {
    let crc = Crc::<u32>::new(&CRC_32_ISCSI);
    let mut digest = crc.digest();
    digest.update(&[HostMsg::DIRECTION]);
    digest.update(header_and_body);
    let mut raw = header_and_body.to_vec();
    raw.extend_from_slice(&digest.finalize().to_le_bytes());
    let mut wire = vec![0u8; cobs::max_encoding_length(raw.len()) + 1];
    let n = cobs::encode(&raw, &mut wire);
    wire.truncate(n);
    wire.push(0);
    wire
}

#[test]
fn firmware_under_qemu_obeys_the_host_and_trips_on_silence() {
    if !qemu_available() {
        return;
    }
    let elf = build_firmware();
    let started = Instant::now();
    let (_qemu, pty) = boot(&elf);
    let mut host = Host::open(&pty);

    // Hello, with retries: QEMU drops output until the pty is opened.
    let hello = (0..30)
        .find_map(|_| {
            host.send(HostMsg::Hello);
            host.pump(Duration::from_millis(300))
                .into_iter()
                .find_map(|m| match m {
                    McuMsg::HelloReply(h) => Some(h),
                    _ => None,
                })
        })
        .expect("no hello reply within 9 s");
    assert_eq!(hello.protocol_version, PROTOCOL_VERSION);
    assert_eq!(hello.firmware_version, dexitac_firmware::FIRMWARE_VERSION);
    assert_eq!(hello.positive_tank_max_pa, POSITIVE_TANK_MAX_PA);
    assert_eq!(hello.negative_tank_min_pa, NEGATIVE_TANK_MIN_PA);
    assert_eq!(usize::from(hello.chamber_count), CHAMBER_COUNT);
    // QEMU does not model RCC_CSR: no reset flag.
    assert_eq!(hello.reset_cause, ResetCause::Unknown);
    // A fresh boot: nothing latched, no record of an earlier stop (QEMU's
    // RAM starts zeroed, which is no valid record).
    assert_eq!(hello.latched_faults, FaultFlags::NONE);
    assert_eq!(hello.last_stop, LastStop::None);
    assert_eq!(
        hello.min_telemetry_interval_ms,
        dexitac_firmware::control::min_telemetry_interval_ms(115_200)
    );

    // No flash store in the QEMU build: identity calibration, nothing
    // persisted; the boot zero (tanks at atmosphere) applies once taken,
    // 32 ms of firmware time after boot (the first hello may come sooner).
    let cal = hello.calibration;
    assert_eq!(cal.calibration, Calibration::IDENTITY);
    assert_eq!(cal.source, CalibrationSource::Default);
    assert_eq!(cal.record, CalibrationRecord::NotPersisted);
    let until = Instant::now() + Duration::from_secs(3);
    let cal = loop {
        let cal = host.hello().calibration;
        if cal.positive_zero.source != ZeroSource::Pending {
            break cal;
        }
        assert!(Instant::now() < until, "no boot zero within 3 s: {cal:?}");
        thread::sleep(Duration::from_millis(10));
    };
    assert_eq!(cal.positive_zero.source, ZeroSource::Boot, "{cal:?}");
    assert_eq!(cal.negative_zero.source, ZeroSource::Boot, "{cal:?}");

    host.ack(HostMsg::Ping { nonce: 0xD3C1 });

    // Calibration: an implausible gain is refused and nothing applies; a
    // plausible one applies at once and shows in the hello reply.
    let calibration = Calibration {
        positive: SensorCalibration {
            offset_pa: 1_500,
            gain_ppm: 1_020_000,
        },
        negative: SensorCalibration {
            offset_pa: -1_000,
            gain_ppm: 990_000,
        },
    };
    host.nack(
        HostMsg::SetCalibration(Calibration {
            negative: SensorCalibration {
                offset_pa: 0,
                gain_ppm: 1_500_000,
            },
            ..calibration
        }),
        NackReason::Implausible,
    );
    assert_eq!(host.hello().calibration.calibration, Calibration::IDENTITY);
    host.ack(HostMsg::SetCalibration(calibration));
    let cal = host.hello().calibration;
    assert_eq!(cal.calibration, calibration);
    assert_eq!(cal.source, CalibrationSource::Host);
    assert_eq!(cal.record, CalibrationRecord::NotPersisted);
    // The boot readings (about 0 Pa) lie within 4 kPa of the new offsets.
    assert_eq!(cal.positive_zero.source, ZeroSource::Boot);
    assert!(cal.positive_zero.zero_pa.abs() < 1_000, "{cal:?}");

    // Not armed: valve commands are refused.
    let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
    chambers[0] = ValveState::Inflate;
    chambers[1] = ValveState::Deflate;
    let seq = host.seq.wrapping_add(1);
    assert_eq!(
        host.request(HostMsg::SetChambers { chambers }),
        McuMsg::Nack {
            seq,
            reason: NackReason::NotArmed
        }
    );

    // Telemetry faster than the line carries, and targets inside the limits
    // but outside the guard band, are refused.
    host.nack(
        HostMsg::SetTelemetryInterval {
            interval_ms: hello.min_telemetry_interval_ms - 1,
        },
        NackReason::IntervalTooShort,
    );
    host.nack(
        HostMsg::SetTankTargets(
            TankTargets::new(POSITIVE_TANK_MAX_PA, -10_000).expect("inside the limits"),
        ),
        NackReason::GuardBand,
    );

    // Arm, regulate both pumps, set the chambers; stream telemetry.
    host.ack(HostMsg::SetTelemetryInterval { interval_ms: 20 });
    host.ack(HostMsg::Arm);
    host.ack(HostMsg::SetPumps {
        positive: PumpMode::Regulate,
        negative: PumpMode::Regulate,
    });
    host.ack(HostMsg::SetChambers { chambers });
    // Armed: a calibration is refused.
    host.nack(
        HostMsg::SetCalibration(Calibration::IDENTITY),
        NackReason::Refused,
    );
    host.telemetry.clear();
    host.keep_alive(Duration::from_millis(1500));

    let stream = host.telemetry.clone();
    assert!(
        stream.len() >= 25,
        "{} telemetry frames in 1.5 s",
        stream.len()
    );
    let (first_at, first) = stream[0];
    let (last_at, last) = stream[stream.len() - 1];
    let steps: Vec<u32> = stream
        .windows(2)
        .map(|w| w[1].1.time_ms.wrapping_sub(w[0].1.time_ms))
        .collect();
    // Reports keep a 20 ms cadence; a late tick (QEMU shares the host's
    // CPUs) may shift one by a few ms.
    let mean_step = f64::from(steps.iter().sum::<u32>()) / steps.len() as f64;
    assert!((mean_step - 20.0).abs() < 0.5, "{steps:?}");
    assert!(steps.iter().all(|s| (15..=25).contains(s)), "{steps:?}");
    eprintln!(
        "qemu_firmware: {} telemetry frames, loop overruns so far {}",
        stream.len(),
        last.loop_overruns
    );
    // Firmware time runs at about wall-clock speed (SysTick at 1 kHz). The
    // bound is loose: when the machine is busy, QEMU's SysTick drops periods
    // and firmware time falls behind (ratios below 0.4 seen on a 2-core
    // machine running several builds at once); a SysTick reload computed for
    // the wrong core clock (72 MHz instead of the 8 MHz QEMU runs) would be
    // off 9x, 0.11, and still fails here.
    let mcu_ms = f64::from(last.time_ms - first.time_ms);
    let wall_ms = (last_at - first_at).as_secs_f64() * 1e3;
    assert!(
        (0.25..1.5).contains(&(mcu_ms / wall_ms)),
        "firmware ms {mcu_ms} vs wall ms {wall_ms}"
    );
    assert_eq!(last.state, ArmState::Armed);
    assert_eq!(last.chambers, chambers);
    assert!(last.faults.is_empty(), "{:?}", last.faults);
    assert!(
        last.positive_tank_pa > first.positive_tank_pa,
        "{} -> {}",
        first.positive_tank_pa,
        last.positive_tank_pa
    );
    assert!(last.negative_tank_pa < first.negative_tank_pa);
    assert!(stream.iter().any(|(_, t)| t.positive_pump_on));

    // A malformed frame (valid CRC, valve state 7) is nacked, a corrupted
    // one dropped; neither actuates anything. (Neither counts as a sign of
    // life either, so heartbeats go in between.)
    host.ack(HostMsg::Heartbeat);
    let seq = host.seq.wrapping_add(1);
    host.seq = seq;
    let [lo, hi] = seq.to_le_bytes();
    let mut body = vec![PROTOCOL_VERSION, lo, hi, 2, 7];
    body.extend_from_slice(&[1; CHAMBER_COUNT - 1]);
    host.write(&frame_with_valid_crc(&body));
    let replies = host.pump(Duration::from_millis(150));
    assert!(
        replies.contains(&McuMsg::Nack {
            seq,
            reason: NackReason::Malformed
        }),
        "{replies:?}"
    );
    host.ack(HostMsg::Heartbeat);
    let mut corrupted = EncodedFrame::new(
        host.seq.wrapping_add(1),
        &HostMsg::SetChambers {
            chambers: [ValveState::Inflate; CHAMBER_COUNT],
        },
    )
    .expect("fits")
    .to_vec();
    corrupted[5] ^= 0x04;
    host.write(&corrupted);
    host.telemetry.clear();
    let replies = host.pump(Duration::from_millis(150));
    assert!(replies.is_empty(), "{replies:?}");
    let (_, t) = *host.telemetry.last().expect("telemetry keeps coming");
    assert_eq!(t.chambers, chambers);
    assert_eq!(t.state, ArmState::Armed);

    // Host silence: tripped at the deadline, pumps off, valves sealed. The
    // firmware handled the last heartbeat between the telemetry reports
    // just before and just after its ack, so in firmware time the trip
    // lies in [before + deadline, after + deadline + 2 ms].
    host.telemetry.clear();
    host.pump(Duration::from_millis(30));
    let (_, before) = *host
        .telemetry
        .last()
        .expect("telemetry before the heartbeat");
    host.ack(HostMsg::Heartbeat);
    let silent_from = Instant::now();
    host.faults.clear();
    host.telemetry.clear();
    let until = silent_from + Duration::from_secs(3);
    while host.faults.is_empty() && Instant::now() < until {
        host.pump(Duration::from_millis(20));
    }
    let (fault_at, fault) = *host
        .faults
        .first()
        .expect("a fault event within 3 s of host silence");
    assert_eq!(fault.fault, Fault::HostSilence);
    let (_, after) = *host
        .telemetry
        .first()
        .expect("telemetry after the heartbeat");
    let deadline = SILENCE_MS;
    assert!(
        (before.time_ms + deadline..=after.time_ms + deadline + 2).contains(&fault.time_ms),
        "trip at firmware time {} ms; heartbeat handled between {} and {} ms; deadline {deadline} ms",
        fault.time_ms,
        before.time_ms,
        after.time_ms
    );
    eprintln!(
        "qemu_firmware: host-silence trip {} ms (wall clock) after the last heartbeat",
        (fault_at - silent_from).as_millis()
    );
    host.pump(Duration::from_millis(50));
    let (_, t) = *host.telemetry.last().expect("telemetry after the trip");
    assert_eq!(t.state, ArmState::Tripped);
    assert!(t.faults.contains(Fault::HostSilence));
    assert!(!t.positive_pump_on && !t.negative_pump_on);
    assert_eq!(t.chambers, [ValveState::Hold; CHAMBER_COUNT]);

    // Latched: arm is refused, disarm does not clear the trip, the hello
    // reply reports it; only ClearFaults naming the fault does.
    host.nack(HostMsg::Arm, NackReason::Tripped);
    host.ack(HostMsg::Disarm);
    host.nack(HostMsg::Arm, NackReason::Tripped);
    let latched = FaultFlags::NONE.with(Fault::HostSilence);
    assert_eq!(host.hello().latched_faults, latched);
    host.ack(HostMsg::ClearFaults {
        faults: FaultFlags::NONE.with(Fault::PositiveOverLimit),
    });
    host.nack(HostMsg::Arm, NackReason::Tripped);
    host.ack(HostMsg::ClearFaults { faults: latched });
    assert_eq!(host.hello().latched_faults, FaultFlags::NONE);
    host.ack(HostMsg::Arm);
    host.ack(HostMsg::Disarm);
    eprintln!(
        "qemu_firmware: boot + checks took {:.1} s",
        started.elapsed().as_secs_f64()
    );
}
