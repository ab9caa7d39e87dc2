//! The exit codes of `dexitac`: one table for every command. Commands return
//! an [`Outcome`] or an error; `main` maps both to the process's exit code
//! here and nowhere else.
//!
//! | code | meaning |
//! | --- | --- |
//! | 0 | success; `sensor health`: pass |
//! | 1 | the command ran to its end but the result is negative: `analyze` could not read some frames, `replay` found different centres, `view` lost a sensor, `sim`/`run` ended on a failed task loop (MCU trip or reset, link, sensor; `sim` says `FAILED: <status>` on its last stdout line and in `summary.json`'s `status`), `sensor tune` found no exact pin count, `cameras` found none, `faults` left faults latched, `calibrate` applied a calibration it could not store or found the stored record ignored; `sensor health`: warn |
//! | 2 | error: bad arguments, config, input or output, device, link; `sensor health`: fail |
//! | 3 | `sensor health` could not run its check |

use std::process::ExitCode;

/// The table above, for `dexitac --help`.
pub const EXIT_CODES_HELP: &str = "\
Exit codes:
  0  success (sensor health: pass)
  1  ran to its end, result negative: analyze could not read some frames, replay found
     different centres, view lost a sensor, sim/run ended on a failed task loop (trip, MCU
     reset, link, sensor; sim's last line starts with FAILED), sensor tune found no exact pin
     count, cameras found none, faults left faults latched, calibrate could not store the
     calibration or found the stored record ignored (sensor health: warn)
  2  error: bad arguments, config, input or output, device, link (sensor health: fail)
  3  sensor health could not run its check";

/// How a command that ran ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Exit 0.
    Success,
    /// Exit 1: ran to its end, the result is negative (see the table).
    Negative,
    /// Exit 2 without an error: `sensor health` found a failing skin.
    HealthFail,
}

impl Outcome {
    /// The process exit code.
    pub fn code(self) -> ExitCode {
        ExitCode::from(match self {
            Outcome::Success => 0,
            Outcome::Negative => 1,
            Outcome::HealthFail => 2,
        })
    }

    /// [`Outcome::Success`] when `ok`, else [`Outcome::Negative`].
    pub fn from_ok(ok: bool) -> Self {
        if ok {
            Outcome::Success
        } else {
            Outcome::Negative
        }
    }
}

/// Exit code of a command that failed with an error.
pub const ERROR: u8 = 2;
/// Exit code of `sensor health` when its check could not run.
pub const HEALTH_ERROR: u8 = 3;
