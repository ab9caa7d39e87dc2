//! A simulated MCU: the firmware's control core behind a pseudo-terminal.
//!
//! [`SimMcu::spawn`] opens a pty pair and runs, on its own thread, the very
//! [`Controller`] the STM32F103 runs, ticked at the firmware's 1 kHz on a
//! simulated clock, with the firmware's [`TankModel`] in place of the
//! pressure sensors. The host opens [`SimMcu::port_path`] like any serial
//! port. The clock runs `speed` times faster than the wall clock, so tests
//! and `dexitac sim --speed X` can run accelerated.
//!
//! [`SimMcu::reset`] restarts the controller (as a board reset would), and
//! [`SimMcu::snapshot`] shows the outputs the controller drives.
//!
//! The sensor calibration the host sets ([`dexitac_protocol::HostMsg::SetCalibration`])
//! is stored as on the board, in the same record format, in a flash page
//! kept in memory ([`SimMcuConfig::calibration_page`], erased at first): it
//! survives [`SimMcu::reset`] and is read back at the restart, like the
//! board's last flash page. [`SimMcu::calibration`] shows what the
//! controller applies. The simulated sensors themselves are exact, so a
//! calibration other than the identity makes the readings differ from the
//! tank model's pressures, as it would on a board with true sensors.
//!
//! [`SimMcu::spawn_with_plant`] also steps a [`Plant`] (actuators, fingers,
//! object) once per control tick with the tank pressures and the valve
//! outputs, on the same simulated clock as the host's loop
//! ([`SimMcuConfig::clock`]). The plant's time keeps running across an MCU
//! reset; the firmware's own clock restarts from zero.

use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use dexitac_firmware::calibration::RamPage;
use dexitac_firmware::sensor::{SensorSamples, NOMINAL_FRONT_END, OVERSAMPLE};
use dexitac_firmware::tank_model::{TankModel, TankModelParams};
use dexitac_firmware::{
    Clock, Config, Controller, FrameSink, PressureSource, Priority, PumpOutputs, Pumps, QueueFull,
    Valves,
};
use dexitac_protocol::{
    ArmState, CalibrationReport, Chambers, FaultFlags, ResetCause, ValveState, CHAMBER_COUNT,
};
use serialport::{SerialPort, TTYPort};

use crate::plant::Plant;
use dexitac_rig::source::Clock as SimClock;

/// A plant shared between the MCU thread (which steps it) and its readers.
pub type SharedPlant = Arc<Mutex<Plant>>;

/// Most control ticks run between two port reads.
const MAX_BATCH_TICKS: u64 = 20;
/// Longest simulated time caught up after a stall, ms; beyond it time is skipped.
const MAX_LAG_MS: u64 = 1_000;

/// Settings of the simulated MCU.
#[derive(Debug, Clone)]
pub struct SimMcuConfig {
    /// The firmware configuration (silence deadline, hysteresis, ...).
    pub firmware: Config,
    /// The pneumatic model.
    pub tanks: TankModelParams,
    /// Simulated time per wall-clock time (1 = real time); used when no
    /// clock is given.
    pub speed: f64,
    /// The simulated clock shared with the host's loop (None: a new clock
    /// at `speed`, started by the spawn).
    pub clock: Option<SimClock>,
    /// The flash page of the calibration record at start (erased by
    /// default); the MCU writes it when the host sets a calibration and
    /// reads it at every (re)start.
    pub calibration_page: RamPage,
}

impl Default for SimMcuConfig {
    fn default() -> Self {
        SimMcuConfig {
            firmware: Config::default(),
            tanks: TankModelParams::default(),
            speed: 1.0,
            clock: None,
            calibration_page: RamPage::default(),
        }
    }
}

/// What the simulated MCU drives, as the rig's sensors would see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McuSnapshot {
    /// Simulated time since the (last) reset, ms.
    pub time_ms: u64,
    /// Valve state per chamber.
    pub chambers: Chambers,
    /// Pump outputs.
    pub pumps: PumpOutputs,
    /// Tank pressures, Pa.
    pub tanks_pa: (i32, i32),
    /// Chamber pressures, Pa.
    pub chambers_pa: [i32; CHAMBER_COUNT],
    /// Safety state.
    pub state: ArmState,
    /// Latched faults (until `ClearFaults`).
    pub faults: FaultFlags,
    /// Frames the controller accepted.
    pub frames_ok: u32,
    /// Byte runs the controller rejected.
    pub frame_errors: u32,
}

/// The hardware the controller sees: clock, tank model, output latches.
struct SimHw {
    now_ms: u64,
    model: TankModel,
    chambers: Chambers,
    pumps: PumpOutputs,
}

impl Clock for SimHw {
    fn now_ms(&self) -> u32 {
        // The firmware's millisecond counter wraps like the board's.
        self.now_ms as u32
    }
}

/// The simulated sensors' supply and the ADC reference, mV (nominal).
const SENSOR_SUPPLY_MV: u32 = 5_000;
const ADC_REFERENCE_MV: u32 = 3_300;

impl PressureSource for SimHw {
    fn read_samples(&mut self) -> SensorSamples {
        let (positive_pa, negative_pa) = self.model.tanks_pa();
        let fe = NOMINAL_FRONT_END;
        let counts =
            |pa| Ok([fe.sensor_counts(pa, SENSOR_SUPPLY_MV, ADC_REFERENCE_MV); OVERSAMPLE]);
        SensorSamples {
            positive: counts(positive_pa),
            negative: counts(negative_pa),
            supply: Ok([fe.supply_counts(SENSOR_SUPPLY_MV, ADC_REFERENCE_MV); OVERSAMPLE]),
        }
    }
}

impl Valves for SimHw {
    fn set_chambers(&mut self, chambers: &Chambers) {
        self.chambers = *chambers;
    }
}

impl Pumps for SimHw {
    fn set_pumps(&mut self, pumps: PumpOutputs) {
        self.pumps = pumps;
    }
}

/// Bytes the controller sends, gathered for one write to the pty.
#[derive(Default)]
struct TxBuffer(Vec<u8>);

impl FrameSink for TxBuffer {
    /// Unbounded: every frame is kept, in order, whatever its priority.
    fn send(&mut self, frame: &[u8], _priority: Priority) -> Result<(), QueueFull> {
        self.0.extend_from_slice(frame);
        Ok(())
    }
}

struct Shared {
    snapshot: McuSnapshot,
    calibration: CalibrationReport,
    reset_requested: bool,
}

/// A running simulated MCU; stops when dropped.
pub struct SimMcu {
    port_path: PathBuf,
    shared: Arc<Mutex<Shared>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<io::Result<()>>>,
}

fn lock(shared: &Mutex<Shared>) -> MutexGuard<'_, Shared> {
    // A panic on the MCU thread leaves the data consistent (plain values).
    shared
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl SimMcu {
    /// Opens a pty pair and starts the MCU thread on its master end.
    pub fn spawn(config: SimMcuConfig) -> io::Result<SimMcu> {
        SimMcu::spawn_inner(config, None)
    }

    /// Like [`SimMcu::spawn`], and steps `plant` once per control tick.
    pub fn spawn_with_plant(config: SimMcuConfig, plant: SharedPlant) -> io::Result<SimMcu> {
        SimMcu::spawn_inner(config, Some(plant))
    }

    fn spawn_inner(config: SimMcuConfig, plant: Option<SharedPlant>) -> io::Result<SimMcu> {
        let (mut master, slave) = TTYPort::pair().map_err(io::Error::from)?;
        master
            .set_timeout(Duration::from_millis(1))
            .map_err(io::Error::from)?;
        let port_path = slave
            .name()
            .map(PathBuf::from)
            .ok_or_else(|| io::Error::other("pty without a name"))?;
        let hw = new_hw(&config);
        let controller = new_controller(&config, &config.calibration_page, ResetCause::PowerOn);
        let shared = Arc::new(Mutex::new(Shared {
            snapshot: snapshot(&hw, &controller),
            calibration: controller.calibration_report(),
            reset_requested: false,
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (shared, stop) = (Arc::clone(&shared), Arc::clone(&stop));
            std::thread::Builder::new()
                .name("sim-mcu".into())
                // The slave end stays open in the thread so the pty does not
                // hang up while the host closes and reopens its port.
                .spawn(move || run(master, slave, config, plant, &shared, &stop))?
        };
        Ok(SimMcu {
            port_path,
            shared,
            stop,
            thread: Some(thread),
        })
    }

    /// The serial port path the host opens.
    pub fn port_path(&self) -> &Path {
        &self.port_path
    }

    /// The latest outputs and state.
    pub fn snapshot(&self) -> McuSnapshot {
        lock(&self.shared).snapshot
    }

    /// The sensor calibration the controller applies now (as its hello
    /// reply reports it).
    pub fn calibration(&self) -> CalibrationReport {
        lock(&self.shared).calibration
    }

    /// Restarts the controller as a board reset would (outputs to the safe
    /// state, disarmed, clock from zero).
    pub fn reset(&self) {
        lock(&self.shared).reset_requested = true;
    }

    /// Stops the thread and reports how it ended.
    pub fn stop(mut self) -> io::Result<()> {
        self.halt()
    }

    fn halt(&mut self) -> io::Result<()> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(io::Error::other("simulated MCU thread panicked")),
            None => Ok(()),
        }
    }
}

impl Drop for SimMcu {
    fn drop(&mut self) {
        // Errors were the thread's own; nothing more to do while dropping.
        if self.halt().is_err() {
            eprintln!("simulated MCU stopped with an error");
        }
    }
}

/// Locks the plant (a panic while stepping leaves plain values behind).
pub fn lock_plant(plant: &Mutex<Plant>) -> MutexGuard<'_, Plant> {
    plant
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn new_hw(config: &SimMcuConfig) -> SimHw {
    SimHw {
        now_ms: 0,
        model: TankModel::new(config.tanks),
        chambers: [ValveState::Hold; CHAMBER_COUNT],
        pumps: PumpOutputs::default(),
    }
}

/// A controller after a reset of `cause`, with the calibration stored in `page`.
fn new_controller(config: &SimMcuConfig, page: &RamPage, cause: ResetCause) -> Controller {
    Controller::new(config.firmware, cause).with_calibration_record(&page.bytes)
}

fn snapshot(hw: &SimHw, controller: &Controller) -> McuSnapshot {
    let mut chambers_pa = [0; CHAMBER_COUNT];
    for (i, p) in chambers_pa.iter_mut().enumerate() {
        *p = hw.model.chamber_pa(i).unwrap_or(0);
    }
    let link = controller.link_stats();
    McuSnapshot {
        time_ms: hw.now_ms,
        chambers: hw.chambers,
        pumps: hw.pumps,
        tanks_pa: hw.model.tanks_pa(),
        chambers_pa,
        state: controller.state(),
        faults: controller.faults(),
        frames_ok: link.frames_ok,
        frame_errors: link.frame_errors,
    }
}

/// The MCU thread: read bytes, run the 1 kHz ticks due on the simulated
/// clock, write the replies.
fn run(
    mut port: TTYPort,
    _slave: TTYPort,
    config: SimMcuConfig,
    plant: Option<SharedPlant>,
    shared: &Mutex<Shared>,
    stop: &AtomicBool,
) -> io::Result<()> {
    let clock = config
        .clock
        .unwrap_or_else(|| SimClock::scaled(config.speed));
    let tick_ms = u64::from(config.firmware.tick_period_ms.max(1));
    let mut hw = new_hw(&config);
    let mut page = config.calibration_page.clone();
    let mut controller = new_controller(&config, &page, ResetCause::PowerOn);
    // Simulated time of the last tick; the firmware's clock is `hw.now_ms`.
    let mut world_ms = clock.now_ms();
    let mut tx = TxBuffer::default();
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::Relaxed) {
        if std::mem::take(&mut lock(shared).reset_requested) {
            hw = new_hw(&config);
            controller = new_controller(&config, &page, ResetCause::Software);
        }
        let n = dexitac_rig::link::read_ready(&mut port, &mut buf)?;
        let now_ms = clock.now_ms();
        if now_ms > world_ms + MAX_LAG_MS {
            // Stalled for longer than the lag bound: skip the lost time
            // rather than running the physics in a burst.
            let skipped = now_ms - world_ms - MAX_LAG_MS;
            world_ms += skipped;
            hw.now_ms += skipped;
        }
        // After any skip: bytes that arrived while this thread was stalled
        // are stamped with the time it resumed, so its own stall never looks
        // like host silence.
        controller.receive(buf.get(..n).unwrap_or(&[]), &hw, &mut tx);
        // As the board does after each receive: store a new calibration
        // (only while disarmed, pumps off; in memory here).
        controller.store_calibration(&mut page);
        // A bounded batch, then back to the port: bytes that arrived during
        // a stall are read before the ticks they preceded run out.
        let mut due_ms = now_ms.min(world_ms + MAX_BATCH_TICKS * tick_ms);
        // Never wait for the plant's readers (low-priority camera threads
        // could hold the lock while preempted): if it is busy, these ticks
        // run on the next pass, a millisecond later.
        let mut plant = match plant.as_ref().map(|p| p.try_lock()) {
            None => None,
            Some(Ok(guard)) => Some(guard),
            Some(Err(std::sync::TryLockError::Poisoned(p))) => Some(p.into_inner()),
            Some(Err(std::sync::TryLockError::WouldBlock)) => {
                due_ms = world_ms;
                None
            }
        };
        while world_ms + tick_ms <= due_ms {
            world_ms += tick_ms;
            hw.now_ms += tick_ms;
            hw.model.advance(tick_ms as u32, hw.pumps, &hw.chambers);
            controller.tick(&mut hw, &mut tx);
            if let Some(plant) = plant.as_mut() {
                plant.step(world_ms, tick_ms as u32, hw.model.tanks_pa(), &hw.chambers);
            }
        }
        drop(plant);
        if !tx.0.is_empty() {
            port.write_all(&tx.0)?;
            tx.0.clear();
        }
        let mut guard = lock(shared);
        guard.snapshot = snapshot(&hw, &controller);
        guard.calibration = controller.calibration_report();
    }
    Ok(())
}
