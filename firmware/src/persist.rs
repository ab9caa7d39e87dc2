//! What stopped the outputs last, kept across a reset in four words of RAM
//! that the start-up code does not initialise (the board's `.uninit`
//! section).
//!
//! The board writes a record when the safety loop trips, on a panic, on a
//! HardFault and on an unexpected interrupt, and reads it once at boot for
//! the hello reply ([`dexitac_protocol::HelloReply::last_stop`]). After a
//! power loss the RAM holds noise: a magic word and a check word tell a
//! record from noise, so noise decodes as [`LastStop::None`].
//!
//! ```
//! use dexitac_firmware::persist::{decode, encode};
//! use dexitac_protocol::{Fault, LastStop};
//! let stop = LastStop::Trip { fault: Fault::NegativeOverLimit };
//! assert_eq!(decode(encode(stop)), stop);
//! assert_eq!(decode([0xFFFF_FFFF; 4]), LastStop::None);
//! ```

use dexitac_protocol::{Fault, LastStop};

/// Marks a record (ASCII "DXT1").
pub const MAGIC: u32 = 0x4458_5431;
/// Mixed into the check word so that a zeroed RAM is no record either.
const CHECK_SALT: u32 = 0xA5C3_5A3C;

/// Words in a record.
pub const RECORD_WORDS: usize = 4;

const KIND_NONE: u32 = 0;
const KIND_TRIP: u32 = 1;
const KIND_PANIC: u32 = 2;
const KIND_HARD_FAULT: u32 = 3;
const KIND_INTERRUPT: u32 = 4;

fn check(kind: u32, value: u32) -> u32 {
    MAGIC ^ kind.rotate_left(8) ^ value.rotate_left(16) ^ CHECK_SALT
}

/// The record for `stop`: magic, kind, value, check.
pub fn encode(stop: LastStop) -> [u32; RECORD_WORDS] {
    let (kind, value) = match stop {
        LastStop::None => (KIND_NONE, 0),
        LastStop::Trip { fault } => (KIND_TRIP, fault as u32),
        LastStop::Panic { line } => (KIND_PANIC, line),
        LastStop::HardFault { pc } => (KIND_HARD_FAULT, pc),
        // Sign-extended IRQ number, recovered by `as i16` below.
        LastStop::UnexpectedInterrupt { irqn } => (KIND_INTERRUPT, i32::from(irqn) as u32),
    };
    [MAGIC, kind, value, check(kind, value)]
}

/// The stop a record describes; anything that is not a valid record is
/// [`LastStop::None`].
pub fn decode(words: [u32; RECORD_WORDS]) -> LastStop {
    let [magic, kind, value, check_word] = words;
    if magic != MAGIC || check_word != check(kind, value) {
        return LastStop::None;
    }
    match kind {
        KIND_TRIP => Fault::ALL
            .iter()
            .find(|f| **f as u32 == value)
            .map_or(LastStop::None, |&fault| LastStop::Trip { fault }),
        KIND_PANIC => LastStop::Panic { line: value },
        KIND_HARD_FAULT => LastStop::HardFault { pc: value },
        KIND_INTERRUPT => i16::try_from(value as i32).map_or(LastStop::None, |irqn| {
            LastStop::UnexpectedInterrupt { irqn }
        }),
        _ => LastStop::None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_round_trips() {
        for stop in [
            LastStop::None,
            LastStop::Trip {
                fault: Fault::ClockFallback,
            },
            LastStop::Panic { line: 412 },
            LastStop::HardFault { pc: 0x0800_1234 },
            LastStop::UnexpectedInterrupt { irqn: -3 },
            LastStop::UnexpectedInterrupt { irqn: 37 },
        ] {
            assert_eq!(decode(encode(stop)), stop);
        }
    }

    proptest::proptest! {
        /// Noise is almost never a record, and a record with one flipped
        /// bit is never read as a different stop.
        #[test]
        fn corrupted_record_is_no_record(line in 0u32..100_000, word in 0usize..4, bit in 0u32..32) {
            let mut words = encode(LastStop::Panic { line });
            words[word] ^= 1 << bit;
            proptest::prop_assert_eq!(decode(words), LastStop::None);
        }
    }
}
