//! The protocol crate's framing over a real pseudo-terminal pair: the byte
//! path the host's serial link and the simulated MCU use.
//!
//! One end plays a minimal device that acks every host frame; the other end
//! sends commands, with line noise injected, and checks the answers.

use std::io::{Read, Write};
use std::thread;
use std::time::{Duration, Instant};

use dexitac_protocol::{
    Decoder, EncodedFrame, Frame, FrameError, HostMsg, McuMsg, PumpMode, ValveState, CHAMBER_COUNT,
};
use serialport::{SerialPort, TTYPort};

const DEADLINE: Duration = Duration::from_secs(10);

/// Reads from `port` until `want` frames (or errors) arrived or the deadline passed.
fn read_frames<M: dexitac_protocol::Message>(
    port: &mut TTYPort,
    decoder: &mut Decoder<M>,
    want: usize,
) -> Vec<Result<Frame<M>, FrameError>> {
    let start = Instant::now();
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    while got.len() < want && start.elapsed() < DEADLINE {
        match port.read(&mut buf) {
            Ok(n) => got.extend(decoder.feed(&buf[..n])),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => panic!("read failed: {e}"),
        }
    }
    got
}

/// The device end: acks every valid host frame, counts rejected ones, and
/// stops after `Disarm`. Returns every frame it accepted and the number of
/// errors; the caller keeps the port open until it has read every ack.
fn run_device(port: &mut TTYPort) -> (Vec<Frame<HostMsg>>, usize) {
    let mut decoder = Decoder::<HostMsg>::new();
    let mut accepted = Vec::new();
    let mut rejected = 0;
    let mut buf = [0u8; 256];
    let start = Instant::now();
    let mut out_seq = 0u16;
    while start.elapsed() < DEADLINE {
        let n = match port.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(e) => panic!("device read failed: {e}"),
        };
        let results: Vec<_> = decoder.feed(&buf[..n]).collect();
        for result in results {
            match result {
                Ok(frame) => {
                    let ack =
                        EncodedFrame::new(out_seq, &McuMsg::Ack { seq: frame.seq }).expect("fits");
                    out_seq = out_seq.wrapping_add(1);
                    port.write_all(&ack).expect("device write");
                    accepted.push(frame);
                    if frame.msg == HostMsg::Disarm {
                        return (accepted, rejected);
                    }
                }
                Err(_) => rejected += 1,
            }
        }
    }
    panic!("device: no Disarm within {DEADLINE:?}");
}

fn commands() -> Vec<HostMsg> {
    let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
    chambers[2] = ValveState::Inflate;
    chambers[5] = ValveState::Deflate;
    vec![
        HostMsg::Hello,
        HostMsg::Arm,
        HostMsg::SetPumps {
            positive: PumpMode::Regulate,
            negative: PumpMode::Regulate,
        },
        HostMsg::SetChambers { chambers },
        HostMsg::Ping { nonce: 77 },
        HostMsg::SealAll,
    ]
}

#[test]
fn commands_are_acked_in_order_over_a_pty() {
    let (mut host, device) = TTYPort::pair().expect("pty pair");
    host.set_timeout(Duration::from_millis(50))
        .expect("timeout");
    let device = thread::spawn(move || {
        let mut device = device;
        (run_device(&mut device), device)
    });

    let mut sent = Vec::new();
    for (seq, msg) in commands().into_iter().chain([HostMsg::Disarm]).enumerate() {
        let seq = seq as u16 + 100;
        host.write_all(&EncodedFrame::new(seq, &msg).expect("fits"))
            .expect("write");
        sent.push(Frame { seq, msg });
    }
    let acks = read_frames(&mut host, &mut Decoder::<McuMsg>::new(), sent.len());
    let ((accepted, rejected), _device_port) = device.join().expect("device thread");

    assert_eq!(accepted, sent);
    assert_eq!(rejected, 0);
    let acked: Vec<u16> = acks
        .iter()
        .map(|a| match a {
            Ok(Frame {
                msg: McuMsg::Ack { seq },
                ..
            }) => *seq,
            other => panic!("expected an ack, got {other:?}"),
        })
        .collect();
    assert_eq!(acked, sent.iter().map(|f| f.seq).collect::<Vec<_>>());
}

#[test]
fn line_noise_costs_frames_but_never_forges_one() {
    let (mut host, device) = TTYPort::pair().expect("pty pair");
    host.set_timeout(Duration::from_millis(50))
        .expect("timeout");
    let device = thread::spawn(move || {
        let mut device = device;
        run_device(&mut device)
    });

    // Every other command frame gets one byte overwritten; noise bursts in
    // between. Each frame starts with a 0x00, as the decoder docs advise on a
    // noisy line, so noise costs at most the frame it touches. A
    // deterministic xorshift keeps the test reproducible.
    let mut state = 0x2545_f491_u32;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state
    };
    let mut sent = Vec::new();
    let mut intact = Vec::new();
    for round in 0..40u16 {
        for (i, msg) in commands().into_iter().enumerate() {
            let seq = round * 10 + i as u16;
            let mut wire = EncodedFrame::new(seq, &msg).expect("fits").to_vec();
            if (seq % 2) == 1 {
                let at = next() as usize % (wire.len() - 1);
                let old = wire[at];
                wire[at] = loop {
                    let b = next() as u8;
                    if b != old {
                        break b;
                    }
                };
            } else {
                intact.push(Frame { seq, msg });
            }
            sent.push(Frame { seq, msg });
            host.write_all(&[0]).expect("write");
            host.write_all(&wire).expect("write");
            let noise: Vec<u8> = (0..next() % 8).map(|_| next() as u8).collect();
            host.write_all(&noise).expect("write noise");
        }
    }
    // Stop the device.
    host.write_all(&[0]).expect("write");
    let stop = Frame {
        seq: 9999,
        msg: HostMsg::Disarm,
    };
    host.write_all(&EncodedFrame::new(stop.seq, &stop.msg).expect("fits"))
        .expect("write");
    let (accepted, rejected) = device.join().expect("device thread");

    assert_eq!(accepted.last(), Some(&stop));
    let accepted = &accepted[..accepted.len() - 1];
    for frame in accepted {
        assert!(sent.contains(frame), "forged frame {frame:?}");
    }
    // Each corrupted frame is one error (or two, when the new byte is a 0x00
    // that splits it); noise bursts add more.
    assert!(
        rejected >= 120,
        "the 120 corrupted frames were not all detected: {rejected}"
    );
    let lost: Vec<_> = intact.iter().filter(|f| !accepted.contains(f)).collect();
    assert!(lost.is_empty(), "intact frames lost to noise: {lost:?}");
}
