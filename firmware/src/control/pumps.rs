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
    /// Hold the pump off for the next period (not a fault): it is to run,
    /// but the fastest pump the limits allow could then carry the tank past
    /// its hard limit from the last reading that was seen to follow the
    /// tank ([`PumpMonitor`]). It may run again once the reading moves.
    pub hold_off: bool,
    /// The pump has been held off ([`PumpFindings::hold_off`]) and is still
    /// to run, and the reading has not moved since the hold began for the
    /// hold limit ([`MonitorLimits::max_hold_ms`]): a stuck sensor.
    pub unconfirmed_hold: bool,
}

/// Limits of a [`PumpMonitor`] (one tank, pumping direction).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MonitorLimits {
    /// Longest continuous run, in milliseconds.
    pub max_run_ms: u32,
    /// Length of a plausibility window, in milliseconds.
    pub rise_window_ms: u32,
    /// Smallest rise (in pumping direction) of the filtered reading over a
    /// window while the pump runs, in pascal. A move of the filtered reading
    /// by this much (either way) also shows that the sensor follows the tank.
    pub min_rise_pa: i32,
    /// The tank's hard limit in pumping direction, in pascal.
    pub limit_pa: i32,
    /// The fastest pump allowed for: its stall pressure in pumping
    /// direction, in pascal ...
    pub stall_pa: i32,
    /// ... and its time constant into the tank, in milliseconds.
    pub fastest_tau_ms: u32,
    /// How far the true pressure may lie above a filtered reading that
    /// follows the tank, in pascal.
    pub reading_margin_pa: i32,
    /// The control period: how long a pump runs before the next check, in
    /// milliseconds.
    pub period_ms: u32,
    /// Longest hold of a pump that is to run without its reading moving,
    /// in milliseconds ([`PumpFindings::unconfirmed_hold`]).
    pub max_hold_ms: u32,
}

/// Watches one pump and its tank's filtered reading.
///
/// Two checks while the pump runs:
///
/// - The plausibility window compares the reading at the end of each
///   window with the reading at its start (both filtered), so noise that
///   averages out cannot reset it, unlike a check that restarts on any
///   small change. It catches a dead pump or a leak, but with windows of
///   1 s a stuck sensor may go unnoticed for up to two windows, long enough
///   for a strong pump to pass the limit.
/// - The bound: an upper bound on the tank's true pressure, kept in
///   millipascal. While the reading is *trusted* (the pump has been off
///   since the reading was last seen to follow the tank) it is the reading
///   plus [`MonitorLimits::reading_margin_pa`]. While the pump runs it
///   grows as the fastest allowed pump would drive the tank
///   (`d/dt = (stall - bound) / tau`, explicit Euler steps, which never
///   under-estimate), and is lowered to the reading plus the margin only
///   when the reading *confirms*: rises by [`MonitorLimits::min_rise_pa`]
///   from the reading of the last confirmation (a fall is no proof: a
///   sensor may freeze low, and the pump should raise it). A stuck sensor never
///   confirms, so the bound reaches the limit before the true pressure can,
///   and the pump is stopped one period before. After the pump stops, the
///   reading is trusted again only once it has moved by the minimum rise
///   (a frozen reading never does: a pump that starts on it trips again
///   when the bound allows no further run).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PumpMonitor {
    /// When the pump was last switched on, if it is on.
    on_since_ms: Option<u32>,
    /// Start of the current plausibility window: time and reading in
    /// pumping direction.
    window_start_ms: u32,
    window_start_pa: i32,
    /// Upper bound on the true pressure in pumping direction, millipascal.
    bound_mpa: i64,
    /// The reading (pumping direction) at the last confirmation, pascal.
    anchor_pa: i32,
    /// The pump has not run since the reading was last seen to follow the
    /// tank (true at boot: the tank is at rest).
    trusted: bool,
    /// Time of the last [`PumpMonitor::check`].
    last_check_ms: Option<u32>,
    /// Since when the pump has been held off by the bound without the
    /// reading moving (cleared when the reading is trusted again).
    held_since_ms: Option<u32>,
}

impl Default for PumpMonitor {
    fn default() -> Self {
        Self::new()
    }
}

const MPA_PER_PA: i64 = 1_000;

impl PumpMonitor {
    /// A monitor of a pump that is off, on a tank at rest.
    pub const fn new() -> Self {
        PumpMonitor {
            on_since_ms: None,
            window_start_ms: 0,
            window_start_pa: 0,
            bound_mpa: 0,
            anchor_pa: 0,
            trusted: true,
            last_check_ms: None,
            held_since_ms: None,
        }
    }

    /// Checks the period that ends `now_ms`, during which the pump was as
    /// last reported by [`PumpMonitor::record`]. `toward_limit_pa` is the
    /// filtered reading in pumping direction ([`Tank::toward_limit_pa`]),
    /// `None` without a valid reading; `runs_next` says whether the pump is
    /// to run in the coming period.
    pub fn check(
        &mut self,
        toward_limit_pa: Option<i32>,
        now_ms: u32,
        runs_next: bool,
        limits: &MonitorLimits,
    ) -> PumpFindings {
        let elapsed_ms = self
            .last_check_ms
            .map_or(0, |last| now_ms.wrapping_sub(last));
        self.last_check_ms = Some(now_ms);
        if self.on_since_ms.is_some() {
            self.bound_mpa = grow_bound(self.bound_mpa, elapsed_ms, limits);
        }
        if let Some(pa) = toward_limit_pa {
            self.follow_reading(pa, limits);
        }
        let hold_off = runs_next
            && grow_bound(self.bound_mpa, limits.period_ms, limits)
                >= i64::from(limits.limit_pa) * MPA_PER_PA;
        if hold_off && self.held_since_ms.is_none() {
            self.held_since_ms = Some(now_ms);
        }
        let unconfirmed_hold = hold_off
            && self
                .held_since_ms
                .is_some_and(|since| now_ms.wrapping_sub(since) >= limits.max_hold_ms);
        let (Some(on_since_ms), Some(pa)) = (self.on_since_ms, toward_limit_pa) else {
            return PumpFindings {
                hold_off,
                unconfirmed_hold,
                ..PumpFindings::default()
            };
        };
        let mut no_rise = false;
        if now_ms.wrapping_sub(self.window_start_ms) >= limits.rise_window_ms {
            no_rise = pa.saturating_sub(self.window_start_pa) < limits.min_rise_pa;
            self.window_start_ms = now_ms;
            self.window_start_pa = pa;
        }
        PumpFindings {
            run_time_exceeded: now_ms.wrapping_sub(on_since_ms) > limits.max_run_ms,
            no_rise,
            hold_off,
            unconfirmed_hold,
        }
    }

    /// Updates the bound from a valid reading: the reading plus the margin
    /// while trusted, or when it confirms. With the pump running only a
    /// rise of the minimum rise confirms; a fall by as much (chambers
    /// drawing air, or a sensor freezing low) only moves the reference of
    /// the next rise down. With the pump off, a move either way trusts the
    /// reading again.
    fn follow_reading(&mut self, pa: i32, limits: &MonitorLimits) {
        let reading_bound_mpa = (i64::from(pa) + i64::from(limits.reading_margin_pa)) * MPA_PER_PA;
        let rise_pa = pa.saturating_sub(self.anchor_pa);
        let pumping = self.on_since_ms.is_some();
        if self.trusted || (!pumping && rise_pa.saturating_abs() >= limits.min_rise_pa) {
            self.trusted = !pumping;
            if !pumping {
                self.held_since_ms = None;
            }
            self.bound_mpa = reading_bound_mpa;
            self.anchor_pa = pa;
        } else if pumping && rise_pa >= limits.min_rise_pa {
            self.bound_mpa = self.bound_mpa.min(reading_bound_mpa);
            self.anchor_pa = pa;
        } else if pumping && rise_pa <= -limits.min_rise_pa {
            self.anchor_pa = pa;
        }
    }

    /// Records the pump's state from `now_ms` on; `toward_limit_pa` is the
    /// filtered reading in pumping direction.
    pub fn record(&mut self, on: bool, toward_limit_pa: i32, now_ms: u32) {
        match (on, self.on_since_ms) {
            (true, None) => {
                self.on_since_ms = Some(now_ms);
                self.window_start_pa = toward_limit_pa;
                self.window_start_ms = now_ms;
                self.trusted = false;
            }
            (false, Some(_)) => self.on_since_ms = None,
            _ => {}
        }
    }

    /// Forgets the pump's run (pump off). The bound, whether the reading is
    /// trusted and since when the pump has been held off stay: a trip does
    /// not make a stuck sensor trustworthy.
    pub fn reset(&mut self) {
        self.on_since_ms = None;
    }

    /// Since when the pump has been held off by the bound without its
    /// reading moving, if it has.
    pub fn held_since_ms(&self) -> Option<u32> {
        self.held_since_ms
    }

    /// The upper bound on the true pressure in pumping direction, pascal
    /// (rounded up).
    pub fn bound_pa(&self) -> i32 {
        let pa = (self.bound_mpa + MPA_PER_PA - 1).div_euclid(MPA_PER_PA);
        i32::try_from(pa).unwrap_or(i32::MAX)
    }
}

/// `bound_mpa` after `dt_ms` of the fastest allowed pump: explicit Euler
/// steps of at most the time constant, each at least 1 mPa (never less than
/// the exact growth).
fn grow_bound(bound_mpa: i64, dt_ms: u32, limits: &MonitorLimits) -> i64 {
    let tau = i64::from(limits.fastest_tau_ms.max(1));
    let stall_mpa = i64::from(limits.stall_pa) * MPA_PER_PA;
    let mut bound = bound_mpa;
    let mut left = i64::from(dt_ms);
    while left > 0 && bound < stall_mpa {
        let step = left.min(tau);
        // stall > bound here, so the rounded-up quotient is positive.
        bound += (((stall_mpa - bound) * step + tau - 1) / tau).max(1);
        left -= step;
    }
    bound
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: MonitorLimits = MonitorLimits {
        max_run_ms: 1000,
        rise_window_ms: 200,
        min_rise_pa: 100,
        limit_pa: 50_000,
        stall_pa: 80_000,
        fastest_tau_ms: 3_076,
        reading_margin_pa: 3_000,
        period_ms: 1,
        max_hold_ms: 5_000,
    };

    /// Limits with a bound that never reaches the limit (window tests).
    const FAR_LIMIT: MonitorLimits = MonitorLimits {
        limit_pa: i32::MAX,
        ..LIMITS
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
        assert!(!m.check(Some(1_050), 199, true, &FAR_LIMIT).no_rise);
        assert!(m.check(Some(1_050), 200, true, &FAR_LIMIT).no_rise);
    }

    #[test]
    fn monitor_is_not_fooled_by_noise_around_a_stuck_value() {
        // +-80 Pa of noise every tick (below the 100 Pa rise): the old
        // "reset on any change" check never fired; this one does.
        let mut m = PumpMonitor::default();
        m.record(true, 1_000, 0);
        let flagged = (1..=200u32).any(|t| {
            let noise = if t % 2 == 0 { 80 } else { -80 };
            m.check(Some(1_000 + noise), t, true, &FAR_LIMIT).no_rise
        });
        assert!(flagged);
    }

    #[test]
    fn monitor_accepts_a_rising_reading() {
        let mut m = PumpMonitor::default();
        m.record(true, 1_000, 0);
        for t in 1..=900u32 {
            let p = 1_000 + (t as i32) * 2;
            assert!(!m.check(Some(p), t, true, &FAR_LIMIT).no_rise);
        }
    }

    #[test]
    fn monitor_flags_run_time_over_limit() {
        let mut m = PumpMonitor::default();
        m.record(true, 0, 0);
        assert!(!m.check(Some(0), 1000, true, &FAR_LIMIT).run_time_exceeded);
        assert!(m.check(Some(0), 1001, true, &FAR_LIMIT).run_time_exceeded);
        m.record(false, 0, 1001);
        assert_eq!(
            m.check(Some(0), 5000, false, &FAR_LIMIT),
            PumpFindings::default()
        );
    }

    /// Runs the monitor on `reading(t)` for t = 1..=ms with the pump on
    /// from t = 1; returns the first tick at which the bound stops it.
    fn first_unconfirmed(
        m: &mut PumpMonitor,
        ms: u32,
        reading: impl Fn(u32) -> i32,
    ) -> Option<u32> {
        for t in 1..=ms {
            if m.check(Some(reading(t)), t, true, &LIMITS).hold_off {
                return Some(t);
            }
            m.record(true, reading(t), t);
        }
        None
    }

    #[test]
    fn bound_stops_a_pump_on_a_frozen_reading_before_the_fastest_pump_reaches_the_limit() {
        let mut m = PumpMonitor::new();
        // Trusted at 42 kPa: bound 45 kPa. The fastest pump (stall 80 kPa,
        // tau 3 076 ms) takes 3076 * ln(35 / 30) = 474 ms from 45 to 50 kPa.
        // The pump starts at t = 1: it has run t - 1 ms when stopped.
        let ran_ms = first_unconfirmed(&mut m, 2_000, |_| 42_000).unwrap() - 1;
        assert!((440..=474).contains(&ran_ms), "{ran_ms}");
    }

    #[test]
    fn bound_lets_a_slow_pump_whose_reading_rises_top_up() {
        // 30 % weak pump near the target: 5 kPa/s, from 42 to 44 kPa.
        let mut m = PumpMonitor::new();
        let rising = |t: u32| 42_000 + (5 * t as i32).min(2_000);
        assert_eq!(first_unconfirmed(&mut m, 400, rising), None);
    }

    #[test]
    fn a_frozen_reading_holds_the_pump_off_and_is_reported_after_the_hold_limit() {
        let mut m = PumpMonitor::new();
        let held_at = first_unconfirmed(&mut m, 2_000, |_| 42_000).unwrap();
        assert_eq!(m.held_since_ms(), Some(held_at));
        // The pump stays off; the reading stays frozen: held, no fault ...
        m.record(false, 42_000, held_at);
        let fault_at = held_at + LIMITS.max_hold_ms;
        for t in held_at + 1..fault_at {
            let f = m.check(Some(42_000), t, true, &LIMITS);
            assert!(f.hold_off && !f.unconfirmed_hold, "{t}");
            m.record(false, 42_000, t);
        }
        // ... until the hold limit.
        let f = m.check(Some(42_000), fault_at, true, &LIMITS);
        assert!(f.hold_off && f.unconfirmed_hold);
        // A trip (reset) does not trust the reading: the pump is held again
        // at its next start, and reported at once.
        m.reset();
        for t in fault_at + 1..fault_at + 10_000 {
            m.check(Some(42_000), t, false, &LIMITS);
            m.record(false, 42_000, t);
        }
        let f = m.check(Some(42_000), fault_at + 10_000, true, &LIMITS);
        assert!(f.hold_off && f.unconfirmed_hold);
    }

    #[test]
    fn a_held_pump_is_released_when_its_reading_moves() {
        let mut m = PumpMonitor::new();
        let held_at = first_unconfirmed(&mut m, 2_000, |_| 42_000).unwrap();
        m.record(false, 42_000, held_at);
        // A chamber draws air from the tank: the reading falls by the
        // minimum rise with the pump off.
        let fallen = 42_000 - LIMITS.min_rise_pa;
        let f = m.check(Some(fallen), held_at + 300, true, &LIMITS);
        assert!(!f.hold_off && !f.unconfirmed_hold);
        assert_eq!(m.bound_pa(), fallen + 3_000);
        assert_eq!(m.held_since_ms(), None);
    }

    #[test]
    fn a_reading_that_moves_with_the_pump_off_is_trusted_again() {
        let mut m = PumpMonitor::new();
        assert!(first_unconfirmed(&mut m, 2_000, |_| 42_000).is_some());
        m.reset();
        // The tank leaks: the reading falls by the minimum rise.
        m.check(Some(42_000 - LIMITS.min_rise_pa), 2_100, false, &LIMITS);
        assert_eq!(m.bound_pa(), 42_000 - LIMITS.min_rise_pa + 3_000);
        assert!(!m.check(Some(41_000), 2_101, true, &LIMITS).hold_off);
    }
}
