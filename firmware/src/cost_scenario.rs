//! The scenario whose control-step cost is measured, on the host
//! (`benches/step_cost.rs`) and under QEMU (the `qemu-cost` build), so that
//! both numbers describe the same work: armed, both pumps regulating, one
//! chamber inflating, telemetry every 10 ms.

use dexitac_protocol::{HostMsg, PumpMode, ValveState, CHAMBER_COUNT};

/// The commands that set the scenario up, in order.
pub fn setup_commands() -> [HostMsg; 4] {
    let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
    chambers[0] = ValveState::Inflate;
    [
        HostMsg::Arm,
        HostMsg::SetPumps {
            positive: PumpMode::Regulate,
            negative: PumpMode::Regulate,
        },
        HostMsg::SetChambers { chambers },
        HostMsg::SetTelemetryInterval { interval_ms: 10 },
    ]
}
