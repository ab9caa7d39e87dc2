//! Whether a simulated run ended normally, and what of its scenario it
//! reached: what every output of a run ([`crate::output`], the figure,
//! `dexitac sim`'s last line and exit code) states about a failure.
//!
//! - [`RunStatus`] ([`SimReport::status`]): `ok` when the task loop ended
//!   normally (the stop flag, the frames ended), else the failure in words:
//!   `tripped: HostSilence at 11.3 s`, `MCU reset, noticed at 4.2 s`,
//!   `error: <message>`. A trip's time is the MCU's, from its fault event
//!   (in the simulator the MCU's clock is the run's simulated clock, started
//!   with it); other times, and a trip seen without its fault event, are the
//!   end of the run ([`SimReport::sim_s`]), which comes a little later.
//! - A poke is *reached* ([`SimReport::poke_reached`]) when its onset came
//!   before the end of the run; the others were scheduled but never applied,
//!   and no output reports them as having happened.

use std::fmt;

use dexitac_protocol::{ArmState, FaultEvent, ResetCause};
use dexitac_rig::task_loop::RuntimeError;

use crate::rig::{DisturbanceTiming, SimReport};

/// Why the task loop of a simulated run failed
/// ([`SimReport::loop_result`]), with the structure a status needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LoopError {
    /// The MCU tripped its safety loop: its fault event.
    McuFault(FaultEvent),
    /// The MCU restarted during the run.
    McuReset {
        /// The reset cause its hello reported (`None`: seen as its
        /// telemetry clock running backwards).
        cause: Option<ResetCause>,
        /// When the task loop noticed, ms.
        t_ms: u64,
    },
    /// Any other failure (link, sensor, configuration): its message.
    Other(String),
}

impl From<RuntimeError> for LoopError {
    fn from(e: RuntimeError) -> Self {
        match e {
            RuntimeError::McuFault(event) => LoopError::McuFault(event),
            RuntimeError::McuReset { cause, t_ms } => LoopError::McuReset { cause, t_ms },
            e => LoopError::Other(e.to_string()),
        }
    }
}

impl From<String> for LoopError {
    fn from(message: String) -> Self {
        LoopError::Other(message)
    }
}

/// The runtime error's message, as `dexitac run` prints it.
impl fmt::Display for LoopError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LoopError::McuFault(event) => RuntimeError::McuFault(*event).fmt(f),
            LoopError::McuReset { cause, t_ms } => RuntimeError::McuReset {
                cause: *cause,
                t_ms: *t_ms,
            }
            .fmt(f),
            LoopError::Other(message) => f.write_str(message),
        }
    }
}

/// How a simulated run ended (module docs); [`fmt::Display`] gives the
/// `status` of `summary.json`.
#[derive(Debug, Clone, PartialEq)]
pub enum RunStatus {
    /// The task loop ended normally: `ok`.
    Ok,
    /// The MCU tripped: `tripped: <faults> at <t> s`, the faults by their
    /// names (`HostSilence`), with the loop's message in brackets when it
    /// was not the MCU's fault event itself (the trip was seen as a refused
    /// command, say).
    Tripped {
        /// The faults: the fault event's, else those latched at the end.
        faults: Vec<dexitac_protocol::Fault>,
        /// The trip (the fault event's MCU time), else the end of the run,
        /// s of simulated time.
        at_s: f64,
        /// The loop's message when it was not the fault event.
        error: Option<String>,
    },
    /// The MCU restarted during the run: `MCU reset, noticed at <t> s`.
    McuReset {
        /// When the task loop noticed, s of simulated time.
        at_s: f64,
    },
    /// Any other failure: `error: <message>`.
    Error(String),
}

impl RunStatus {
    /// Whether the run ended normally.
    pub fn is_ok(&self) -> bool {
        matches!(self, RunStatus::Ok)
    }
}

/// `t_s` in s to the ms, without trailing zeros but with at least one
/// decimal: `11.3`, `0.262`, `12.0`.
pub fn seconds(t_s: f64) -> String {
    if !t_s.is_finite() {
        return "?".to_string();
    }
    let s = format!("{t_s:.3}");
    let trimmed = s.trim_end_matches('0');
    if trimmed.ends_with('.') {
        format!("{trimmed}0")
    } else {
        trimmed.to_string()
    }
}

impl fmt::Display for RunStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RunStatus::Ok => f.write_str("ok"),
            RunStatus::Tripped {
                faults,
                at_s,
                error,
            } => {
                let names: Vec<String> = faults.iter().map(|x| format!("{x:?}")).collect();
                let names = if names.is_empty() {
                    "no fault named".to_string()
                } else {
                    names.join(", ")
                };
                write!(f, "tripped: {names} at {} s", seconds(*at_s))?;
                match error {
                    Some(e) => write!(f, " ({e})"),
                    None => Ok(()),
                }
            }
            RunStatus::McuReset { at_s } => {
                write!(f, "MCU reset, noticed at {} s", seconds(*at_s))
            }
            RunStatus::Error(message) => write!(f, "error: {message}"),
        }
    }
}

impl SimReport {
    /// How the run ended (module docs): from [`SimReport::loop_result`], and
    /// for a failed loop that names no fault, the MCU's state at the end (a
    /// board tripped at the end is reported as the trip).
    pub fn status(&self) -> RunStatus {
        let error = match &self.loop_result {
            Ok(_) => return RunStatus::Ok,
            Err(e) => e,
        };
        let at_s = self.sim_s;
        let mcu = &self.mcu_at_end;
        match error {
            LoopError::McuFault(event) => RunStatus::Tripped {
                faults: vec![event.fault],
                at_s: f64::from(event.time_ms) / 1e3,
                error: None,
            },
            e if mcu.state == ArmState::Tripped => RunStatus::Tripped {
                faults: mcu.faults.iter().collect(),
                at_s,
                error: Some(e.to_string()),
            },
            LoopError::McuReset { t_ms, .. } => RunStatus::McuReset {
                at_s: *t_ms as f64 / 1e3,
            },
            LoopError::Other(message) => RunStatus::Error(message.clone()),
        }
    }

    /// Whether the poke's onset came before the end of the run (a run whose
    /// end is not a finite time reached every poke).
    pub fn poke_reached(&self, d: &DisturbanceTiming) -> bool {
        !self.sim_s.is_finite() || d.t_onset_s < self.sim_s
    }

    /// The pokes whose onset came before the end of the run, in order.
    pub fn pokes_reached(&self) -> impl Iterator<Item = &DisturbanceTiming> {
        self.disturbances.iter().filter(|d| self.poke_reached(d))
    }

    /// The scheduled pokes the run ended before: never applied.
    pub fn pokes_not_reached(&self) -> impl Iterator<Item = &DisturbanceTiming> {
        self.disturbances.iter().filter(|d| !self.poke_reached(d))
    }

    /// The end of the run, ms of simulated time; `None` when
    /// [`SimReport::sim_s`] is not a finite time.
    pub fn end_ms(&self) -> Option<u64> {
        (self.sim_s.is_finite() && self.sim_s >= 0.0).then(|| (self.sim_s * 1e3).round() as u64)
    }

    /// The outcome as the outputs state it: `failed` for a run whose status
    /// is not `ok`, else [`crate::rig::Outcome::name`].
    pub fn outcome_word(&self) -> &'static str {
        if self.status().is_ok() {
            self.outcome.name()
        } else {
            "failed"
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dexitac_protocol::Fault;

    #[test]
    fn seconds_are_short() {
        assert_eq!(seconds(11.3), "11.3");
        assert_eq!(seconds(11.2999), "11.3");
        assert_eq!(seconds(12.0), "12.0");
        assert_eq!(seconds(0.262), "0.262");
        assert_eq!(seconds(f64::NAN), "?");
    }

    #[test]
    fn statuses_in_words() {
        let tripped = RunStatus::Tripped {
            faults: vec![Fault::HostSilence],
            at_s: 11.3,
            error: None,
        };
        assert_eq!(tripped.to_string(), "tripped: HostSilence at 11.3 s");
        let refused = RunStatus::Tripped {
            faults: vec![Fault::HostSilence, Fault::PositiveOverLimit],
            at_s: 2.0,
            error: Some("link: refused".into()),
        };
        assert_eq!(
            refused.to_string(),
            "tripped: HostSilence, PositiveOverLimit at 2.0 s (link: refused)"
        );
        assert_eq!(
            RunStatus::McuReset { at_s: 4.25 }.to_string(),
            "MCU reset, noticed at 4.25 s"
        );
        assert_eq!(
            RunStatus::Error("sensor 1: gone".into()).to_string(),
            "error: sensor 1: gone"
        );
        assert_eq!(RunStatus::Ok.to_string(), "ok");
        assert!(RunStatus::Ok.is_ok() && !tripped.is_ok());
    }

    #[test]
    fn loop_errors_keep_the_runtime_errors_kind_and_message() {
        let event = FaultEvent {
            time_ms: 11_290,
            fault: Fault::HostSilence,
            positive_tank_pa: 40_000,
            negative_tank_pa: -45_000,
        };
        let e = LoopError::from(RuntimeError::McuFault(event));
        assert_eq!(e, LoopError::McuFault(event));
        assert_eq!(e.to_string(), RuntimeError::McuFault(event).to_string());
        let reset = RuntimeError::McuReset {
            cause: Some(ResetCause::IndependentWatchdog),
            t_ms: 4_250,
        };
        assert_eq!(
            LoopError::from(reset),
            LoopError::McuReset {
                cause: Some(ResetCause::IndependentWatchdog),
                t_ms: 4_250
            }
        );
        let config = RuntimeError::Config("bad".into());
        let text = config.to_string();
        assert_eq!(LoopError::from(config), LoopError::Other(text));
    }
}
