//! The DexiTac wire protocol, shared by the STM32F103 firmware and the host.
//!
//! Wire types only: the messages ([`HostMsg`], [`McuMsg`]), the hard limits
//! ([`limits`]), framing ([`frame`]) and a streaming decoder ([`Decoder`]).
//! `no_std`, no allocation; the `std` feature adds `std::error::Error`
//! impls, the `defmt` feature adds `defmt::Format` to every type.
//!
//! # Frame format
//!
//! ```text
//! raw   = version:u8 | seq:u16 LE | postcard(message) | crc:u32 LE
//! crc   = CRC-32C(direction:u8 | version | seq | postcard(message))
//! wire  = COBS(raw) | 0x00
//! ```
//!
//! The direction byte (`b'H'` host to MCU, `b'M'` MCU to host) is not sent;
//! it makes a frame read in the wrong direction (an echoing line) fail its CRC.
//!
//! A receiver checks, in order: length ([`FrameError::TooLong`]), COBS
//! ([`FrameError::Cobs`]), CRC ([`FrameError::Crc`]), version
//! ([`FrameError::WrongVersion`]), message tag ([`FrameError::UnknownMessage`])
//! and message body ([`FrameError::Malformed`]). Nothing in a frame is used
//! before its CRC has matched.
//!
//! # Overhead
//!
//! A [`HostMsg::SetChambers`] command has a 9-byte postcard body (1 tag byte,
//! 8 one-byte valve states) and takes **18 bytes on the wire**: 3 header bytes,
//! 4 CRC bytes, 1 COBS byte and the 0x00 delimiter, i.e. 9 bytes of overhead
//! (the test `set_chambers_frame_is_18_bytes` pins these numbers). At
//! 115 200 baud (10 bits a byte) that frame takes 1.56 ms on the line. No frame
//! is longer than [`MAX_FRAME_LEN`] = 75 bytes (a full hello reply, which
//! carries the sensor calibration); a telemetry frame takes at most
//! [`MAX_TELEMETRY_FRAME_LEN`] = 44 bytes.
//!
//! # Example
//!
//! ```
//! use dexitac_protocol::{Decoder, EncodedFrame, Frame, HostMsg, ValveState};
//!
//! let mut chambers = [ValveState::Hold; 8];
//! chambers[0] = ValveState::Inflate;
//! let msg = HostMsg::SetChambers { chambers };
//! let wire = EncodedFrame::new(1, &msg).unwrap();
//!
//! let mut decoder = Decoder::<HostMsg>::new();
//! let got: Vec<_> = decoder.feed(&wire).collect();
//! assert_eq!(got, [Ok(Frame { seq: 1, msg })]);
//! ```
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(feature = "std")]
extern crate std;

pub mod decoder;
pub mod frame;
pub mod limits;
pub mod message;

pub use decoder::Decoder;
pub use frame::{
    decode_in_place, encode_into, BufferTooSmall, EncodedFrame, Frame, FrameError, MAX_ENCODED_LEN,
    MAX_FRAME_LEN, MAX_TELEMETRY_FRAME_LEN,
};
pub use limits::{
    CALIBRATION_GAIN_MAX_PPM, CALIBRATION_GAIN_MIN_PPM, CALIBRATION_OFFSET_MAX_PA, CHAMBER_COUNT,
    GAIN_UNITY_PPM, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA,
};
pub use message::{
    ActiveZero, ArmState, Calibration, CalibrationError, CalibrationRecord, CalibrationReport,
    CalibrationSource, Chambers, Fault, FaultEvent, FaultFlags, FirmwareVersion, HelloReply,
    HostMsg, LastStop, LimitError, McuMsg, Message, NackReason, PumpMode, ResetCause,
    SensorCalibration, TankTargets, Telemetry, ValveState, ZeroSource, NO_READING_PA,
};

/// Version of this wire protocol. Bump it when any message's layout changes;
/// each side refuses frames of another version ([`FrameError::WrongVersion`]).
///
/// Version 3: [`HostMsg::SetCalibration`], [`NackReason::Implausible`] and
/// [`HelloReply::calibration`].
pub const PROTOCOL_VERSION: u8 = 3;
