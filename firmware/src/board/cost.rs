//! QEMU instruction count of one control step (feature `qemu-cost`).
//!
//! Runs the host benchmark's scenario (`benches/step_cost.rs`) on the
//! emulated Cortex-M3 without a host: after the boot-time zero, arm, both
//! pumps regulating, chamber 0 inflating, telemetry every 10 ms, a
//! heartbeat frame every 100 ms. Around
//! each step (`receive` + `tick`) it reads the SysTick counter. Run QEMU with
//! `-icount shift=0`: every instruction then takes exactly 1 ns of virtual
//! time, and SysTick counts at the core clock ([`super::QEMU_CORE_CLOCK_HZ`]),
//! so one count is 1e9 / 24e6 = 41.7 instructions. After [`STEPS`] steps it
//! prints the mean and maximum over semihosting and exits QEMU.
//!
//! It also measures the stack's high-water mark: [`paint_stack`] fills the
//! free RAM between the statics and the stack pointer with a pattern at
//! start-up; the report counts the words that were overwritten.

use cortex_m::peripheral::SYST;
use cortex_m_semihosting::debug::{exit, EXIT_SUCCESS};
use cortex_m_semihosting::hprintln;
use dexitac_firmware::control::ZERO_AT_TICK;
use dexitac_firmware::{Clock, Controller, FrameSink};
use dexitac_protocol::{EncodedFrame, HostMsg};

extern "C" {
    /// End of the statics (cortex-m-rt linker symbol), the stack's floor.
    static _stack_end: u32;
    /// Initial stack pointer (cortex-m-rt linker symbol).
    static _stack_start: u32;
}

/// The word painted into unused stack.
const PAINT: u32 = 0xDEC0_ADDE;

/// Fills the free stack below the current stack pointer (minus a margin for
/// this function's own frame) with [`PAINT`].
pub fn paint_stack() {
    let floor = core::ptr::addr_of!(_stack_end) as usize;
    let sp = cortex_m::register::msp::read() as usize - 64;
    let mut at = floor;
    while at < sp {
        // SAFETY: [floor, sp) is RAM above every static and below the live
        // stack frames; nothing else uses it yet.
        unsafe { core::ptr::write_volatile(at as *mut u32, PAINT) };
        at += 4;
    }
}

/// Bytes of stack used so far: from the top down to the lowest word that
/// no longer holds [`PAINT`].
fn stack_high_water_bytes() -> usize {
    let floor = core::ptr::addr_of!(_stack_end) as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let mut at = floor;
    // SAFETY: reads of RAM words between the statics and the stack top.
    while at < top && unsafe { core::ptr::read_volatile(at as *const u32) } == PAINT {
        at += 4;
    }
    top - at
}

/// Steps measured before the report.
const STEPS: u32 = 5_000;

/// Virtual nanoseconds (= instructions under `-icount shift=0`) per
/// SysTick count, times 1000.
const INSTRUCTIONS_PER_COUNT_X1000: u64 = 1_000_000_000_000 / super::QEMU_CORE_CLOCK_HZ as u64;

/// Counts SysTick counts spent in the control step.
pub struct Meter {
    sum_counts: u64,
    max_counts: u32,
    steps: u32,
    seq: u16,
}

fn frame(seq: u16, msg: HostMsg) -> Option<EncodedFrame> {
    EncodedFrame::new(seq, &msg).ok()
}

impl Meter {
    /// No steps measured yet.
    pub fn new() -> Meter {
        Meter {
            sum_counts: 0,
            max_counts: 0,
            steps: 0,
            seq: 0,
        }
    }

    /// Feeds the scripted input due at `now_ms`: the scenario's setup
    /// commands once the sensors are zeroed, then a heartbeat every 100 ms.
    pub fn script(
        &mut self,
        now_ms: u32,
        controller: &mut Controller,
        clock: &impl Clock,
        tx: &mut impl FrameSink,
    ) {
        if now_ms == ZERO_AT_TICK + 2 {
            for msg in dexitac_firmware::cost_scenario::setup_commands() {
                self.seq = self.seq.wrapping_add(1);
                if let Some(f) = frame(self.seq, msg) {
                    controller.receive(&f, clock, tx);
                }
            }
        }
        if now_ms % 100 == 0 {
            self.seq = self.seq.wrapping_add(1);
            if let Some(f) = frame(self.seq, HostMsg::Heartbeat) {
                controller.receive(&f, clock, tx);
            }
        }
    }

    /// Records a step that started at SysTick value `start`; reports and
    /// exits QEMU after [`STEPS`] steps.
    pub fn record(&mut self, start: u32) {
        let end = SYST::get_current();
        // SysTick counts down and reloads at 0.
        let counts = if end <= start {
            start - end
        } else {
            start + SYST::get_reload() + 1 - end
        };
        self.sum_counts += u64::from(counts);
        self.max_counts = self.max_counts.max(counts);
        self.steps += 1;
        if self.steps == STEPS {
            let mean_x1000 = self.sum_counts * INSTRUCTIONS_PER_COUNT_X1000 / u64::from(STEPS);
            let max = u64::from(self.max_counts) * INSTRUCTIONS_PER_COUNT_X1000 / 1000;
            hprintln!(
                "control step: mean {} instructions, max {} (over {} steps; SysTick resolution {} instructions)",
                mean_x1000 / 1000,
                max,
                STEPS,
                INSTRUCTIONS_PER_COUNT_X1000 / 1000
            );
            hprintln!(
                "stack high-water mark: {} bytes; statics end at {:#x}",
                stack_high_water_bytes(),
                core::ptr::addr_of!(_stack_end) as usize
            );
            exit(EXIT_SUCCESS);
        }
    }
}
