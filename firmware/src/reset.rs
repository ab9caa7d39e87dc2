//! The reset cause, from the reset flags of the STM32F1 `RCC_CSR` register
//! (RM0008 section 7.3.10). The board reads the register once at start-up,
//! clears the flags (`RMVF`) and reports the cause in the hello reply.

use dexitac_protocol::ResetCause;

/// `RCC_CSR.PINRSTF`: NRST pin.
pub const PINRSTF: u32 = 1 << 26;
/// `RCC_CSR.PORRSTF`: power-on / power-down reset.
pub const PORRSTF: u32 = 1 << 27;
/// `RCC_CSR.SFTRSTF`: software reset.
pub const SFTRSTF: u32 = 1 << 28;
/// `RCC_CSR.IWDGRSTF`: independent watchdog.
pub const IWDGRSTF: u32 = 1 << 29;
/// `RCC_CSR.WWDGRSTF`: window watchdog.
pub const WWDGRSTF: u32 = 1 << 30;
/// `RCC_CSR.LPWRRSTF`: low-power management.
pub const LPWRRSTF: u32 = 1 << 31;

/// The reset cause for an `RCC_CSR` value. Several flags can be set at
/// once (the pin flag accompanies every reset, the power-on flag stays set
/// until cleared); the most specific one wins: watchdogs, low-power,
/// software, power-on, pin.
///
/// ```
/// use dexitac_firmware::reset::{reset_cause, IWDGRSTF, PINRSTF};
/// use dexitac_protocol::ResetCause;
/// assert_eq!(reset_cause(IWDGRSTF | PINRSTF), ResetCause::IndependentWatchdog);
/// assert_eq!(reset_cause(0), ResetCause::Unknown);
/// ```
pub const fn reset_cause(csr: u32) -> ResetCause {
    if csr & IWDGRSTF != 0 {
        ResetCause::IndependentWatchdog
    } else if csr & WWDGRSTF != 0 {
        ResetCause::WindowWatchdog
    } else if csr & LPWRRSTF != 0 {
        ResetCause::LowPower
    } else if csr & SFTRSTF != 0 {
        ResetCause::Software
    } else if csr & PORRSTF != 0 {
        ResetCause::PowerOn
    } else if csr & PINRSTF != 0 {
        ResetCause::Pin
    } else {
        ResetCause::Unknown
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_on_sets_pin_and_por_and_reads_power_on() {
        assert_eq!(reset_cause(PORRSTF | PINRSTF), ResetCause::PowerOn);
        assert_eq!(reset_cause(PINRSTF), ResetCause::Pin);
        assert_eq!(reset_cause(SFTRSTF | PINRSTF), ResetCause::Software);
        assert_eq!(reset_cause(WWDGRSTF), ResetCause::WindowWatchdog);
        assert_eq!(reset_cause(LPWRRSTF), ResetCause::LowPower);
    }
}
