//! The status LED (PC13 on the blue pill): a blink code for the safety
//! state, computed from the state and the time so the board only writes
//! the pin.
//!
//! | state | LED |
//! |---|---|
//! | disarmed | short flash (100 ms) once a second |
//! | armed | on |
//! | tripped | *n* blinks (200 ms on, 200 ms off), then 1.2 s off; *n* = 1 + the wire number of the first latched fault ([`Fault::ALL`]: 1 positive over limit, 2 negative over limit, 3 / 4 sensor, 5 / 6 pump run time, 7 host silence, 8 / 9 pump no rise, 10 clock fallback) |
//!
//! ```
//! use dexitac_firmware::led::led_on;
//! use dexitac_protocol::{ArmState, Fault, FaultFlags};
//! let tripped = FaultFlags::NONE.with(Fault::NegativeOverLimit); // 2 blinks
//! let lit: Vec<bool> = (0..2_000).step_by(100).map(|t| led_on(ArmState::Tripped, tripped, t)).collect();
//! assert_eq!(lit.iter().filter(|on| **on).count(), 4); // 2 x 200 ms in 100 ms steps
//! ```

use dexitac_protocol::{ArmState, Fault, FaultFlags};

/// Length of one blink and of the gap after it, in milliseconds.
pub const BLINK_MS: u32 = 200;
/// Pause after a blink code, in milliseconds.
pub const CODE_PAUSE_MS: u32 = 1_200;
/// Disarmed: flash length and period, in milliseconds.
pub const IDLE_FLASH_MS: u32 = 100;
/// Disarmed: flash period, in milliseconds.
pub const IDLE_PERIOD_MS: u32 = 1_000;

/// The number of blinks that names `fault`.
pub fn blink_count(fault: Fault) -> u32 {
    fault as u32 + 1
}

/// Whether the LED is lit at `now_ms`.
pub fn led_on(state: ArmState, faults: FaultFlags, now_ms: u32) -> bool {
    match state {
        ArmState::Armed => true,
        ArmState::Disarmed => now_ms % IDLE_PERIOD_MS < IDLE_FLASH_MS,
        ArmState::Tripped => {
            let blinks = faults.iter().next().map_or(1, blink_count);
            let period = blinks * 2 * BLINK_MS + CODE_PAUSE_MS;
            let t = now_ms % period;
            t < blinks * 2 * BLINK_MS && (t / BLINK_MS) % 2 == 0
        }
    }
}
