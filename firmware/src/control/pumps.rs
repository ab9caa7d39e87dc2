//! Pump control: bang-bang with hysteresis toward the tank target, never at
//! or past the hard limit; and the per-pump monitor (run time, stuck sensor).
//!
//! Both tanks are handled in "pumping direction" units: the positive tank's
//! pressure as is, the negative tank's pressure negated, so a pump always
//! raises its tank's value and the limit is always an upper bound
//! ([`Tank::toward_limit_pa`]).

use dexitac_protocol::{PumpMode, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA};

/// One of the two buffer tanks (each with its pump and sensor).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tank {
    /// The positive (pressure) tank, filled by the positive pump.
    Positive,
    /// The negative (vacuum) tank, emptied by the negative pump.
    Negative,
}

impl Tank {
    /// The hard limit of this tank in pascal (compile-time, from the protocol
    /// crate): +50 kPa or -57 kPa.
    pub const fn limit_pa(self) -> i32 {
        match self {
            Tank::Positive => POSITIVE_TANK_MAX_PA,
            Tank::Negative => NEGATIVE_TANK_MIN_PA,
        }
    }

    /// `pressure_pa` in pumping direction: the positive tank's pressure, or
    /// the negated negative tank's pressure (the pump raises this value).
    pub const fn toward_limit_pa(self, pressure_pa: i32) -> i32 {
        match self {
            Tank::Positive => pressure_pa,
            Tank::Negative => pressure_pa.saturating_neg(),
        }
    }

    /// Whether `pressure_pa` is at or past this tank's hard limit.
    pub const fn at_or_past_limit(self, pressure_pa: i32) -> bool {
        self.toward_limit_pa(pressure_pa) >= self.toward_limit_pa(self.limit_pa())
    }
}

/// The pump's next state: on below `target - hysteresis`, off at or past
/// the target, unchanged in between; always off when the mode is off or the
/// tank is at or past its hard limit.
pub fn regulate(
    tank: Tank,
    mode: PumpMode,
    was_on: bool,
    pressure_pa: i32,
    target_pa: i32,
    hysteresis_pa: i32,
) -> bool {
    if mode == PumpMode::Off || tank.at_or_past_limit(pressure_pa) {
        return false;
    }
    let value = tank.toward_limit_pa(pressure_pa);
    let target = tank.toward_limit_pa(target_pa);
    if value >= target {
        false
    } else if value < target.saturating_sub(hysteresis_pa) {
        true
    } else {
        was_on
    }
}

/// What a [`PumpMonitor`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PumpFindings {
    /// The pump has run without pause for longer than the run-time limit.
    pub run_time_exceeded: bool,
    /// The pump ran for a whole plausibility window and its tank's filtered
    /// reading did not move toward the limit by the minimum rise: a stuck
    /// sensor, a dead pump or a leak.
    pub no_rise: bool,
}

/// Limits of a [`PumpMonitor`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MonitorLimits {
    /// Longest continuous run, in milliseconds.
    pub max_run_ms: u32,
    /// Length of a plausibility window, in milliseconds.
    pub rise_window_ms: u32,
    /// Smallest rise (in pumping direction) of the filtered reading over a
    /// window while the pump runs, in pascal.
    pub min_rise_pa: i32,
}

/// Watches one pump and its tank's filtered reading while the pump runs.
///
/// The plausibility check compares the reading at the end of each window
/// with the reading at its start (both filtered), so noise that averages
/// out cannot reset it, unlike a check that restarts on any small change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PumpMonitor {
    /// When the pump was last switched on, if it is on.
    on_since_ms: Option<u32>,
    /// Start of the current plausibility window: time and reading in
    /// pumping direction.
    window_start_ms: u32,
    window_start_pa: i32,
}

impl PumpMonitor {
    /// Checks the period that ends `now_ms`, during which the pump was as
    /// last reported by [`PumpMonitor::record`]. `toward_limit_pa` is the
    /// filtered reading in pumping direction ([`Tank::toward_limit_pa`]).
    pub fn check(
        &mut self,
        toward_limit_pa: i32,
        now_ms: u32,
        limits: &MonitorLimits,
    ) -> PumpFindings {
        let Some(on_since_ms) = self.on_since_ms else {
            return PumpFindings::default();
        };
        let mut no_rise = false;
        if now_ms.wrapping_sub(self.window_start_ms) >= limits.rise_window_ms {
            no_rise = toward_limit_pa.saturating_sub(self.window_start_pa) < limits.min_rise_pa;
            self.window_start_ms = now_ms;
            self.window_start_pa = toward_limit_pa;
        }
        PumpFindings {
            run_time_exceeded: now_ms.wrapping_sub(on_since_ms) > limits.max_run_ms,
            no_rise,
        }
    }

    /// Records the pump's state from `now_ms` on.
    pub fn record(&mut self, on: bool, toward_limit_pa: i32, now_ms: u32) {
        match (on, self.on_since_ms) {
            (true, None) => {
                self.on_since_ms = Some(now_ms);
                self.window_start_pa = toward_limit_pa;
                self.window_start_ms = now_ms;
            }
            (false, Some(_)) => self.on_since_ms = None,
            _ => {}
        }
    }

    /// Forgets the pump's history (pump off).
    pub fn reset(&mut self) {
        self.on_since_ms = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: MonitorLimits = MonitorLimits {
        max_run_ms: 1000,
        rise_window_ms: 200,
        min_rise_pa: 100,
    };

    #[test]
    fn pump_starts_below_band_and_stops_at_target() {
        let t = Tank::Positive;
        assert!(regulate(
            t,
            PumpMode::Regulate,
            false,
            10_000,
            40_000,
            2_000
        ));
        assert!(regulate(t, PumpMode::Regulate, true, 39_000, 40_000, 2_000));
        assert!(!regulate(
            t,
            PumpMode::Regulate,
            false,
            39_000,
            40_000,
            2_000
        ));
        assert!(!regulate(
            t,
            PumpMode::Regulate,
            true,
            40_000,
            40_000,
            2_000
        ));
    }

    #[test]
    fn negative_pump_regulates_downward() {
        let t = Tank::Negative;
        assert!(regulate(t, PumpMode::Regulate, false, 0, -40_000, 2_000));
        assert!(!regulate(
            t,
            PumpMode::Regulate,
            true,
            -40_000,
            -40_000,
            2_000
        ));
        assert!(regulate(
            t,
            PumpMode::Regulate,
            true,
            -39_000,
            -40_000,
            2_000
        ));
    }

    #[test]
    fn pump_never_runs_at_limit_even_with_target_at_limit() {
        assert!(!regulate(
            Tank::Positive,
            PumpMode::Regulate,
            true,
            POSITIVE_TANK_MAX_PA,
            POSITIVE_TANK_MAX_PA,
            0
        ));
        assert!(!regulate(
            Tank::Negative,
            PumpMode::Regulate,
            true,
            NEGATIVE_TANK_MIN_PA,
            NEGATIVE_TANK_MIN_PA,
            0
        ));
    }

    #[test]
    fn pump_off_mode_keeps_pump_off() {
        assert!(!regulate(
            Tank::Positive,
            PumpMode::Off,
            true,
            0,
            40_000,
            2_000
        ));
    }

    #[test]
    fn monitor_flags_a_reading_that_does_not_rise() {
        let mut m = PumpMonitor::default();
        m.record(true, 1_000, 0);
        assert!(!m.check(1_050, 199, &LIMITS).no_rise);
        assert!(m.check(1_050, 200, &LIMITS).no_rise);
    }

    #[test]
    fn monitor_is_not_fooled_by_noise_around_a_stuck_value() {
        // +-80 Pa of noise every tick (below the 100 Pa rise): the old
        // "reset on any change" check never fired; this one does.
        let mut m = PumpMonitor::default();
        m.record(true, 1_000, 0);
        let flagged = (1..=200u32).any(|t| {
            let noise = if t % 2 == 0 { 80 } else { -80 };
            m.check(1_000 + noise, t, &LIMITS).no_rise
        });
        assert!(flagged);
    }

    #[test]
    fn monitor_accepts_a_rising_reading() {
        let mut m = PumpMonitor::default();
        m.record(true, 1_000, 0);
        for t in 1..=900u32 {
            let p = 1_000 + (t as i32) * 2;
            assert!(!m.check(p, t, &LIMITS).no_rise);
        }
    }

    #[test]
    fn monitor_flags_run_time_over_limit() {
        let mut m = PumpMonitor::default();
        m.record(true, 0, 0);
        assert!(!m.check(0, 1000, &LIMITS).run_time_exceeded);
        assert!(m.check(0, 1001, &LIMITS).run_time_exceeded);
        m.record(false, 0, 1001);
        assert_eq!(m.check(0, 5000, &LIMITS), PumpFindings::default());
    }
}
