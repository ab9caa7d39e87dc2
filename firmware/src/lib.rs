//! DexiTac firmware library: the hardware-independent parts of the STM32F103
//! firmware, built and unit-tested on the host.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

use dexitac_protocol::FirmwareVersion;

/// This firmware's version, reported in the hello reply.
pub const FIRMWARE_VERSION: FirmwareVersion = FirmwareVersion {
    major: 0,
    minor: 1,
    patch: 0,
};
