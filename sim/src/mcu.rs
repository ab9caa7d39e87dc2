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
//!
//! [`SimMcu::spawn_with_plant_in_process`] runs the same thread on an
//! in-process serial line ([`LinePort`]) instead of a pty, for the simulator
//! in real time: no kernel worker carries its bytes.
//!
//! [`VirtualMcu`] is the same core on a virtual clock, for runs that repeat
//! exactly: no thread and no pty, it runs when its [`VirtualPort`] is read
//! or written, and faults can be scheduled into it ([`McuInjection`]).

use std::collections::VecDeque;
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
    /// Added to what the pressure sensors read, Pa (a sensor fault).
    reading_offset_pa: (i32, i32),
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
        let (positive_pa, negative_pa) = (
            positive_pa.saturating_add(self.reading_offset_pa.0),
            negative_pa.saturating_add(self.reading_offset_pa.1),
        );
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
    /// The control tick, ms.
    tick_ms: u64,
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

    /// Like [`SimMcu::spawn_with_plant`], on an in-process serial line
    /// instead of a pty: the returned port is the host's end (reads time out
    /// after `read_timeout`). No kernel worker carries its bytes: on a pty,
    /// the tty layer's worker thread that moves them between the two ends
    /// was seen runnable but without a CPU for 1.25 s next to a release
    /// build (BENCHMARKS.md, "The real-time stall"), and the host's link
    /// waited for it. [`SimMcu::port_path`] is empty.
    pub fn spawn_with_plant_in_process(
        config: SimMcuConfig,
        plant: SharedPlant,
        read_timeout: Duration,
    ) -> io::Result<(SimMcu, LinePort)> {
        let (host, mcu) = LinePort::pair(read_timeout, Duration::from_millis(1));
        let sim = SimMcu::start(
            config,
            Some(plant),
            PathBuf::new(),
            move |config, plant, shared, stop| run(mcu, config, plant, shared, stop),
        )?;
        Ok((sim, host))
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
        SimMcu::start(
            config,
            plant,
            port_path,
            move |config, plant, shared, stop| {
                // The slave end stays open in the thread so the pty does not
                // hang up while the host closes and reopens its port.
                let _slave = slave;
                run(master, config, plant, shared, stop)
            },
        )
    }

    /// Starts the MCU thread running `body` on the shared state.
    fn start(
        config: SimMcuConfig,
        plant: Option<SharedPlant>,
        port_path: PathBuf,
        body: impl FnOnce(SimMcuConfig, Option<SharedPlant>, &Mutex<Shared>, &AtomicBool) -> io::Result<()>
            + Send
            + 'static,
    ) -> io::Result<SimMcu> {
        let tick_ms = u64::from(config.firmware.tick_period_ms.max(1));
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
                .spawn(move || body(config, plant, &shared, &stop))?
        };
        Ok(SimMcu {
            port_path,
            tick_ms,
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

    /// The outputs and state once two more control ticks have been
    /// published (waiting up to `timeout`, then the latest). The MCU thread
    /// writes its replies to the port before it publishes the snapshot that
    /// shows their effect: a host that exits on a command's ack can leave
    /// [`SimMcu::snapshot`] a pass behind it.
    pub fn snapshot_after_ticks(&self, timeout: Duration) -> McuSnapshot {
        let due_ms = self.snapshot().time_ms + 2 * self.tick_ms;
        let until = std::time::Instant::now() + timeout;
        loop {
            let s = self.snapshot();
            if s.time_ms >= due_ms || std::time::Instant::now() >= until {
                return s;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
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
        reading_offset_pa: (0, 0),
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

/// The firmware's control core, its hardware and (optionally) the plant,
/// stepped on the simulated clock: what the MCU thread and the virtual MCU
/// share.
struct McuCore {
    config: SimMcuConfig,
    hw: SimHw,
    page: RamPage,
    controller: Controller,
    plant: Option<SharedPlant>,
    /// Simulated time of the last tick; the firmware's clock is `hw.now_ms`.
    world_ms: u64,
    tick_ms: u64,
    tx: TxBuffer,
    /// Called after each tick with the plant stepped (virtual MCU only).
    observer: Option<TickObserver>,
}

/// Sees each control tick of a virtual MCU: simulated time, ms, the valve
/// outputs and the plant.
pub type TickObserver = Box<dyn FnMut(u64, &Chambers, &Plant) + Send>;

impl McuCore {
    fn new(config: SimMcuConfig, plant: Option<SharedPlant>, world_ms: u64) -> McuCore {
        let page = config.calibration_page.clone();
        McuCore {
            hw: new_hw(&config),
            controller: new_controller(&config, &page, ResetCause::PowerOn),
            tick_ms: u64::from(config.firmware.tick_period_ms.max(1)),
            config,
            page,
            plant,
            world_ms,
            tx: TxBuffer::default(),
            observer: None,
        }
    }

    /// A board reset: outputs safe, disarmed, the firmware's clock from 0.
    fn reset(&mut self) {
        // A faulty sensor (an injected reading offset) stays faulty.
        let offset_pa = self.hw.reading_offset_pa;
        self.hw = new_hw(&self.config);
        self.hw.reading_offset_pa = offset_pa;
        self.controller = new_controller(&self.config, &self.page, ResetCause::Software);
    }

    /// Bytes from the host, at the current tick.
    fn receive(&mut self, bytes: &[u8]) {
        self.controller.receive(bytes, &self.hw, &mut self.tx);
        // As the board does after each receive: store a new calibration
        // (only while disarmed, pumps off; in memory here).
        self.controller.store_calibration(&mut self.page);
    }

    /// Skips `ms` of simulated time without running it.
    fn skip(&mut self, ms: u64) {
        self.world_ms += ms;
        self.hw.now_ms += ms;
    }

    /// Runs the ticks up to `due_ms` (the plant locked for all of them).
    fn tick_to(&mut self, due_ms: u64, mut plant: Option<&mut Plant>) {
        while self.world_ms + self.tick_ms <= due_ms {
            self.tick(plant.as_deref_mut());
        }
    }

    /// One control tick (and plant step).
    fn tick(&mut self, plant: Option<&mut Plant>) {
        let tick_ms = self.tick_ms;
        self.world_ms += tick_ms;
        self.hw.now_ms += tick_ms;
        self.hw
            .model
            .advance(tick_ms as u32, self.hw.pumps, &self.hw.chambers);
        self.controller.tick(&mut self.hw, &mut self.tx);
        if let Some(plant) = plant {
            plant.step(
                self.world_ms,
                tick_ms as u32,
                self.hw.model.tanks_pa(),
                &self.hw.chambers,
            );
            if let Some(observer) = self.observer.as_mut() {
                observer(self.world_ms, &self.hw.chambers, plant);
            }
        }
    }

    fn snapshot(&self) -> McuSnapshot {
        snapshot(&self.hw, &self.controller)
    }
}

/// The MCU thread: read bytes, run the 1 kHz ticks due on the simulated
/// clock, write the replies.
fn run(
    mut port: impl io::Read + Write,
    config: SimMcuConfig,
    plant: Option<SharedPlant>,
    shared: &Mutex<Shared>,
    stop: &AtomicBool,
) -> io::Result<()> {
    let clock = config
        .clock
        .clone()
        .unwrap_or_else(|| SimClock::scaled(config.speed));
    let mut core = McuCore::new(config, plant, clock.now_ms());
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::Relaxed) {
        if std::mem::take(&mut lock(shared).reset_requested) {
            core.reset();
        }
        let n = dexitac_rig::link::read_ready(&mut port, &mut buf)?;
        let now_ms = clock.now_ms();
        if now_ms > core.world_ms + MAX_LAG_MS {
            // Stalled for longer than the lag bound: skip the lost time
            // rather than running the physics in a burst.
            core.skip(now_ms - core.world_ms - MAX_LAG_MS);
        }
        // After any skip: bytes that arrived while this thread was stalled
        // are stamped with the time it resumed, so its own stall never looks
        // like host silence.
        core.receive(buf.get(..n).unwrap_or(&[]));
        // A bounded batch, then back to the port: bytes that arrived during
        // a stall are read before the ticks they preceded run out.
        let mut due_ms = now_ms.min(core.world_ms + MAX_BATCH_TICKS * core.tick_ms);
        // Never wait for the plant's readers (camera threads could hold the
        // lock while preempted): if it is busy, these ticks run on the next
        // pass, a millisecond later.
        let shared_plant = core.plant.clone();
        let mut plant = match shared_plant.as_ref().map(|p| p.try_lock()) {
            None => None,
            Some(Ok(guard)) => Some(guard),
            Some(Err(std::sync::TryLockError::Poisoned(p))) => Some(p.into_inner()),
            Some(Err(std::sync::TryLockError::WouldBlock)) => {
                due_ms = core.world_ms;
                None
            }
        };
        core.tick_to(due_ms, plant.as_deref_mut());
        drop(plant);
        if !core.tx.0.is_empty() {
            port.write_all(&core.tx.0)?;
            core.tx.0.clear();
        }
        let mut guard = lock(shared);
        guard.snapshot = core.snapshot();
        guard.calibration = core.controller.calibration_report();
    }
    Ok(())
}

/// One end of an in-process serial line: bytes written at one end are read
/// at the other, in order; a read waits up to its timeout for the first byte
/// and returns 0 when none came.
pub struct LinePort {
    rx: Arc<Pipe>,
    tx: Arc<Pipe>,
    read_timeout: Duration,
}

#[derive(Default)]
struct Pipe {
    bytes: Mutex<VecDeque<u8>>,
    ready: std::sync::Condvar,
}

impl LinePort {
    /// The two ends, with their read timeouts.
    pub fn pair(timeout_a: Duration, timeout_b: Duration) -> (LinePort, LinePort) {
        let (ab, ba) = (Arc::new(Pipe::default()), Arc::new(Pipe::default()));
        (
            LinePort {
                rx: Arc::clone(&ba),
                tx: Arc::clone(&ab),
                read_timeout: timeout_a,
            },
            LinePort {
                rx: ab,
                tx: ba,
                read_timeout: timeout_b,
            },
        )
    }
}

impl io::Read for LinePort {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let guard = self
            .rx
            .bytes
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let (mut bytes, _) = self
            .rx
            .ready
            .wait_timeout_while(guard, self.read_timeout, |b| b.is_empty())
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let n = buf.len().min(bytes.len());
        for (slot, b) in buf.iter_mut().zip(bytes.drain(..n)) {
            *slot = b;
        }
        Ok(n)
    }
}

impl Write for LinePort {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.tx
            .bytes
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .extend(buf);
        self.tx.ready.notify_all();
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Serial line time of one byte at 115 200 baud (start, 8 data, stop bits), µs.
const BYTE_TIME_US: u64 = 87;

/// Something scheduled to happen to a virtual MCU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum McuInjection {
    /// The board resets (power glitch, watchdog) at this simulated time, ms.
    ResetAt {
        /// When, ms.
        at_ms: u64,
    },
    /// The MCU does nothing from this time for this long, then catches up
    /// tick by tick (a starved MCU thread, a late USB adapter): no tick,
    /// no byte in or out meanwhile.
    StallAt {
        /// When, ms.
        at_ms: u64,
        /// For how long, ms.
        for_ms: u64,
    },
    /// From this time on, the pressure sensors read this much more than the
    /// tanks hold (a sensor fault), Pa.
    ReadingOffsetAt {
        /// When, ms.
        at_ms: u64,
        /// Offset of the positive and the negative tank's reading, Pa.
        offset_pa: (i32, i32),
    },
}

struct VirtualState {
    core: McuCore,
    /// Host -> MCU bytes in flight: (arrival µs, bytes).
    to_mcu: VecDeque<(u64, Vec<u8>)>,
    /// MCU -> host bytes in flight: (arrival µs, byte).
    to_host: VecDeque<(u64, u8)>,
    /// When the line towards each side is free again, µs.
    line_free_us: (u64, u64),
    injections: Vec<McuInjection>,
    /// An injected stall: (from, until), ms.
    stall: Option<(u64, u64)>,
}

impl VirtualState {
    /// Runs the MCU (and the plant) up to `now_us`: host bytes are received
    /// at the tick their last bit arrives, replies leave at the tick that
    /// sent them, a byte time apart.
    fn catch_up(&mut self, now_us: u64) {
        let plant = self.core.plant.clone();
        let mut guard = plant.as_ref().map(|p| lock_plant(p));
        loop {
            let next_ms = self.core.world_ms + self.core.tick_ms;
            if next_ms * 1_000 > now_us {
                break;
            }
            if let Some((from, until)) = self.stall {
                if next_ms > from && now_us < until * 1_000 {
                    break;
                }
            }
            self.inject(next_ms);
            self.deliver_to_mcu(next_ms * 1_000);
            self.core.tick(guard.as_deref_mut());
            self.send_to_host(next_ms * 1_000);
        }
        drop(guard);
    }

    fn inject(&mut self, t_ms: u64) {
        let core = &mut self.core;
        self.injections.retain(|i| match *i {
            McuInjection::ResetAt { at_ms } if at_ms <= t_ms => {
                core.reset();
                false
            }
            // Never queued: `VirtualMcu::inject` keeps a stall apart.
            McuInjection::StallAt { .. } => false,
            McuInjection::ReadingOffsetAt { at_ms, offset_pa } if at_ms <= t_ms => {
                core.hw.reading_offset_pa = offset_pa;
                false
            }
            _ => true,
        });
    }

    fn deliver_to_mcu(&mut self, t_us: u64) {
        while self.to_mcu.front().is_some_and(|(at, _)| *at <= t_us) {
            if let Some((_, bytes)) = self.to_mcu.pop_front() {
                self.core.receive(&bytes);
            }
        }
        self.send_to_host(t_us);
    }

    fn send_to_host(&mut self, t_us: u64) {
        let mut at = self.line_free_us.1.max(t_us);
        for b in self.core.tx.0.drain(..) {
            at += BYTE_TIME_US;
            self.to_host.push_back((at, b));
        }
        self.line_free_us.1 = at;
    }

    fn queue_from_host(&mut self, t_us: u64, bytes: &[u8]) {
        let at = self.line_free_us.0.max(t_us) + BYTE_TIME_US * bytes.len() as u64;
        self.line_free_us.0 = at;
        self.to_mcu.push_back((at, bytes.to_vec()));
    }
}

/// A simulated MCU on a virtual clock ([`SimClock::virtual_clock`]): the
/// same control core (and plant) as [`SimMcu`], without a thread or a pty.
/// It runs only when its port ([`VirtualMcu::port`]) is read or written
/// and then catches up with the clock, tick by tick; bytes take their
/// serial line time (115 200 baud) each way. A read that finds no byte
/// moves the clock on by the read timeout: the host's waits are what moves
/// virtual time.
#[derive(Clone)]
pub struct VirtualMcu {
    state: Arc<Mutex<VirtualState>>,
    clock: SimClock,
}

fn lock_virtual(state: &Mutex<VirtualState>) -> MutexGuard<'_, VirtualState> {
    state
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl VirtualMcu {
    /// A virtual MCU (with `plant`, stepped every tick) on `clock`, which
    /// must be virtual.
    pub fn new(config: SimMcuConfig, plant: Option<SharedPlant>, clock: SimClock) -> VirtualMcu {
        let core = McuCore::new(config, plant, clock.now_ms());
        VirtualMcu {
            state: Arc::new(Mutex::new(VirtualState {
                core,
                to_mcu: VecDeque::new(),
                to_host: VecDeque::new(),
                line_free_us: (0, 0),
                injections: Vec::new(),
                stall: None,
            })),
            clock,
        }
    }

    /// Calls `observer` after every tick (with the plant stepped).
    pub fn observe(&self, observer: TickObserver) {
        lock_virtual(&self.state).core.observer = Some(observer);
    }

    /// Schedules `injection`.
    pub fn inject(&self, injection: McuInjection) {
        let mut state = lock_virtual(&self.state);
        if let McuInjection::StallAt { at_ms, for_ms } = injection {
            state.stall = Some((at_ms, at_ms + for_ms));
        } else {
            state.injections.push(injection);
        }
    }

    /// The host's end of the serial line; a read that finds no byte waits
    /// up to `read_timeout_ms` of virtual time.
    pub fn port(&self, read_timeout_ms: u64) -> VirtualPort {
        VirtualPort {
            mcu: self.clone(),
            read_timeout_us: read_timeout_ms.max(1) * 1_000,
        }
    }

    /// Runs the MCU and the plant up to `t_us` (no further than the clock).
    pub fn catch_up_to(&self, t_us: u64) {
        lock_virtual(&self.state).catch_up(t_us.min(self.clock.now_us()));
    }

    /// The outputs and state at the clock's time.
    pub fn snapshot(&self) -> McuSnapshot {
        let mut state = lock_virtual(&self.state);
        state.catch_up(self.clock.now_us());
        state.core.snapshot()
    }

    /// The sensor calibration the controller applies.
    pub fn calibration(&self) -> CalibrationReport {
        lock_virtual(&self.state)
            .core
            .controller
            .calibration_report()
    }
}

/// The host's end of a [`VirtualMcu`]'s serial line.
pub struct VirtualPort {
    mcu: VirtualMcu,
    read_timeout_us: u64,
}

impl io::Read for VirtualPort {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let clock = &self.mcu.clock;
        let mut state = lock_virtual(&self.mcu.state);
        let deadline_us = clock.now_us() + self.read_timeout_us;
        loop {
            let now_us = clock.now_us();
            state.catch_up(now_us);
            let ready = state.to_host.front().is_some_and(|(at, _)| *at <= now_us);
            if ready || now_us >= deadline_us {
                break;
            }
            // On to the next byte's arrival or the next tick, whichever is
            // first; a millisecond at least (a stalled MCU's next tick lies
            // in the past).
            let next_tick_us = (state.core.world_ms + state.core.tick_ms) * 1_000;
            let next_byte_us = state.to_host.front().map_or(u64::MAX, |(at, _)| *at);
            let next_us = next_tick_us.min(next_byte_us).max(now_us + 1_000);
            clock.sleep_until_us(next_us.min(deadline_us));
        }
        let now_us = clock.now_us();
        let mut n = 0;
        for slot in buf.iter_mut() {
            match state.to_host.front() {
                Some(&(at, b)) if at <= now_us => {
                    *slot = b;
                    n += 1;
                    state.to_host.pop_front();
                }
                _ => break,
            }
        }
        Ok(n)
    }
}

impl Write for VirtualPort {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let now_us = self.mcu.clock.now_us();
        let mut state = lock_virtual(&self.mcu.state);
        state.catch_up(now_us);
        state.queue_from_host(now_us, buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    #[test]
    fn an_in_process_line_carries_bytes_in_order_and_its_reads_time_out() {
        let (mut a, mut b) = LinePort::pair(Duration::from_millis(1), Duration::from_millis(1));
        let mut buf = [0u8; 8];
        assert_eq!(b.read(&mut buf).unwrap(), 0, "nothing sent yet");
        a.write_all(&[1, 2, 3]).unwrap();
        a.write_all(&[4]).unwrap();
        assert_eq!(b.read(&mut buf[..2]).unwrap(), 2);
        assert_eq!(&buf[..2], &[1, 2]);
        assert_eq!(b.read(&mut buf).unwrap(), 2);
        assert_eq!(&buf[..2], &[3, 4]);
        // The other way, from another thread, while the reader waits.
        let (mut c, mut d) = LinePort::pair(Duration::from_secs(5), Duration::from_millis(1));
        let writer = std::thread::spawn(move || d.write_all(&[9]).unwrap());
        assert_eq!(c.read(&mut buf).unwrap(), 1);
        assert_eq!(buf[0], 9);
        writer.join().unwrap();
        assert_eq!(a.read(&mut buf).unwrap(), 0, "nothing came back to a");
    }
}
