//! Board layer: connects the STM32F103 peripherals (stm32f1xx-hal 0.11) to
//! the control core, and runs the control loop.
//!
//! # Clocks and timing
//!
//! - Board: 8 MHz crystal (HSE) x 9 by the PLL = **72 MHz** SYSCLK, APB1
//!   36 MHz, APB2 72 MHz, ADC 12 MHz.
//! - QEMU (`--features qemu`): the internal 8 MHz RC (HSI), no PLL (QEMU
//!   models neither); QEMU's `stm32vldiscovery` clocks the Cortex-M3 core,
//!   and so SysTick, at [`QEMU_CORE_CLOCK_HZ`].
//! - **SysTick at 1 kHz** counts milliseconds ([`MILLIS`]); the main loop runs
//!   one control tick per millisecond.
//!
//! # Pin map (blue pill, STM32F103C8)
//!
//! | function | pins |
//! |---|---|
//! | inlet valves, chambers 0..7 | PB8, PB9, PB10, PB11, PB12, PB13, PB14, PB15 |
//! | outlet valves, chambers 0..7 | PA2, PA3, PA4, PA5, PA6, PA7, PA8, PB0 |
//! | positive pump | PB6 |
//! | negative pump | PB5 |
//! | positive tank sensor | PA0 (ADC1_IN0) |
//! | negative tank sensor | PA1 (ADC1_IN1) |
//! | sensor supply (5 V through 1/2) | PB1 (ADC1_IN9) |
//! | status LED (active low) | PC13 |
//! | host link USART1 | PA9 TX, PA10 RX, **115 200 baud 8N1** |
//!
//! Every output is push-pull, high = energised (valve open, pump on), and
//! drives a low-side driver whose gate is pulled down: outputs float low
//! during reset, which is the safe state (all valves closed, pumps off).
//! PA11/PA12 (USB), PA13/PA14 (SWD) and PA15/PB3/PB4 (JTAG) stay free.
//!
//! # Start-up
//!
//! 1. Every output is driven low by register writes ([`force_safe_outputs`])
//!    before anything can wait.
//! 2. The crystal (HSE) gets [`HSE_START_TIMEOUT_SPINS`] polls (about 30 ms
//!    on the 8 MHz internal clock; a crystal starts in about 2 ms). If it
//!    does not start, the MCU runs from the internal RC through the PLL at
//!    64 MHz and reports [`Fault::ClockFallback`] (latched: arming waits for
//!    a person to acknowledge it).
//! 3. The record of what stopped the outputs before this boot is read from
//!    no-init RAM ([`dexitac_firmware::persist`]) for the hello reply.
//! 4. The sensor calibration is read from the last flash page
//!    ([`dexitac_firmware::calibration`], `flash_store`); a missing or bad
//!    record leaves the identity calibration, and the hello reply says why.
//!    The QEMU build reads no flash and keeps a calibration set by the host
//!    only until reset.
//!
//! # Control loop
//!
//! The USART1 receive interrupt moves each byte into a `heapless::spsc`
//! queue: the interrupt owns the producer, the loop the consumer, no lock.
//! The main loop, on every new millisecond: hands the received bytes to
//! [`Controller::receive`], writes a calibration the host set to flash if
//! one waits ([`Controller::store_calibration`]: only disarmed, pumps off;
//! the watchdog is fed first), runs [`Controller::tick`], records a new trip in
//! no-init RAM, sets the status LED ([`dexitac_firmware::led`]), feeds the
//! independent watchdog (only here: a stalled loop resets the MCU within
//! [`WATCHDOG_TIMEOUT_MS`]); in between it moves queued bytes into the USART
//! data register without blocking, urgent frames first ([`TxQueues`]).
//!
//! # Exceptions
//!
//! A panic, a HardFault and any interrupt without a handler
//! (`DefaultHandler`) force every output low, record the cause in no-init
//! RAM, then wait for the watchdog reset.

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{exception, ExceptionFrame};
use defmt_rtt as _;
use dexitac_firmware::calibration::CalibrationStore;
use dexitac_firmware::control::valves::ValveLevels;
use dexitac_firmware::led::led_on;
use dexitac_firmware::persist::{self, RECORD_WORDS};
use dexitac_firmware::reset::reset_cause;
use dexitac_firmware::{
    Clock, Config, Controller, PressureSource, PumpOutputs, Pumps, SensorSamples, TxQueues, Valves,
    FIRMWARE_VERSION,
};
use dexitac_protocol::{Chambers, Fault, LastStop, PROTOCOL_VERSION};
use heapless::spsc::{Producer, Queue};
use stm32f1xx_hal::gpio::{ErasedPin, Output, PinState, PushPull};
use stm32f1xx_hal::pac::{self, interrupt, USART1};
use stm32f1xx_hal::prelude::*;
use stm32f1xx_hal::rcc;
use stm32f1xx_hal::serial::{Config as SerialConfig, Rx, Tx};
use stm32f1xx_hal::watchdog::IndependentWatchdog;

#[cfg(not(feature = "qemu"))]
mod adc_sensors;
#[cfg(not(feature = "qemu"))]
use adc_sensors as sensors;
#[cfg(feature = "qemu")]
mod model_sensors;
#[cfg(feature = "qemu")]
use model_sensors as sensors;
#[cfg(feature = "qemu-cost")]
mod cost;
#[cfg(not(feature = "qemu"))]
mod flash_store;

/// Baud rate of the host link (USART1).
pub const BAUD_RATE: u32 = 115_200;

/// Independent watchdog timeout: 50 control periods.
pub const WATCHDOG_TIMEOUT_MS: u32 = 50;

/// SysTick rate: one tick per millisecond.
const SYSTICK_HZ: u32 = 1_000;

/// The Cortex-M3 core clock of QEMU 7.2's `stm32vldiscovery` machine
/// (`SYSCLK_FRQ` in hw/arm/stm32vldiscovery.c), which drives SysTick there
/// whatever RCC says (RCC is not modelled).
pub const QEMU_CORE_CLOCK_HZ: u32 = 24_000_000;

/// Received bytes not yet handed to the controller (the spsc queue holds
/// one less). 256 bytes hold more than 20 ms of line time at 115 200 baud.
const RX_QUEUE_LEN: usize = 256;
/// Urgent bytes waiting to be sent: every fault event (10 x 21 bytes) and a
/// dozen replies.
const TX_URGENT_LEN: usize = 384;
/// Telemetry bytes waiting to be sent: two full frames.
const TX_TELEMETRY_LEN: usize = 96;
/// Bytes handed to the controller per tick, at most.
const RX_CHUNK_LEN: usize = 64;

/// Polls of `HSERDY` before the crystal counts as dead (about 30 ms on the
/// 8 MHz internal clock).
pub const HSE_START_TIMEOUT_SPINS: u32 = 50_000;

/// Milliseconds since start-up, counted by SysTick.
static MILLIS: AtomicU32 = AtomicU32::new(0);
/// Bytes dropped because the receive queue was full.
static RX_OVERFLOWS: AtomicU32 = AtomicU32::new(0);
/// Received bytes, from the USART1 interrupt (producer) to the control loop
/// (consumer). Reached only through the two halves made once in [`run`].
static mut RX_QUEUE: Queue<u8, RX_QUEUE_LEN> = Queue::new();
/// The USART1 receiver and the queue's producer: written once in [`run`]
/// while the interrupt is masked, owned by the interrupt afterwards.
static mut USART1_ISR: Option<(Rx<USART1>, Producer<'static, u8>)> = None;

/// What stopped the outputs last, across a reset: not initialised by the
/// start-up code (cortex-m-rt's `.uninit` section).
#[link_section = ".uninit.DEXITAC_LAST_STOP"]
static mut LAST_STOP_RECORD: MaybeUninit<[u32; RECORD_WORDS]> = MaybeUninit::uninit();

/// Output pins that are energised when high: masks for the safe paths.
/// GPIOA: outlets PA2..PA8.
const GPIOA_OUTPUT_MASK: u32 = 0b1_1111_1100;
/// GPIOB: outlet PB0, pumps PB5 and PB6, inlets PB8..PB15.
const GPIOB_OUTPUT_MASK: u32 = 0xFF00 | (1 << 6) | (1 << 5) | 1;

/// The system tick: one millisecond.
#[exception]
fn SysTick() {
    MILLIS.fetch_add(1, Ordering::Relaxed);
}

/// USART1: move every received byte into the receive queue.
#[interrupt]
fn USART1() {
    // SAFETY: USART1_ISR was written once in `run` before this interrupt
    // was unmasked; from then on only this handler touches it, and it
    // does not preempt itself.
    let Some((rx, producer)) = (unsafe { (*core::ptr::addr_of_mut!(USART1_ISR)).as_mut() }) else {
        return;
    };
    // `read` clears a line error (overrun, framing, noise) by reading SR
    // then DR; the broken frame then fails its CRC in the decoder.
    while let Ok(byte) = rx.read() {
        if producer.enqueue(byte).is_err() {
            RX_OVERFLOWS.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Writes the record of what stopped the outputs (read at the next boot).
fn record_last_stop(stop: LastStop) {
    // SAFETY: plain word writes to a static only this function and
    // `take_last_stop` (before any interrupt is enabled) touch; a torn
    // record fails its check word and reads as `LastStop::None`.
    unsafe {
        core::ptr::write_volatile(
            core::ptr::addr_of_mut!(LAST_STOP_RECORD).cast::<[u32; RECORD_WORDS]>(),
            persist::encode(stop),
        );
    }
}

/// Reads the record left by the previous run and clears it.
fn take_last_stop() -> LastStop {
    // SAFETY: any bit pattern is a valid [u32; 4]; decode rejects noise.
    let words = unsafe {
        core::ptr::read_volatile(
            core::ptr::addr_of!(LAST_STOP_RECORD).cast::<[u32; RECORD_WORDS]>(),
        )
    };
    record_last_stop(LastStop::None);
    persist::decode(words)
}

/// Milliseconds from SysTick.
struct SysTickClock;

impl Clock for SysTickClock {
    fn now_ms(&self) -> u32 {
        MILLIS.load(Ordering::Relaxed)
    }
}

/// A push-pull output pin.
type OutPin = ErasedPin<Output<PushPull>>;

/// The 16 valve outputs.
struct ValvePins {
    inlets: [OutPin; 8],
    outlets: [OutPin; 8],
    levels: ValveLevels,
}

impl ValvePins {
    fn write(&mut self, levels: ValveLevels) {
        for (i, pin) in self.inlets.iter_mut().enumerate() {
            pin.set_state(PinState::from(levels.inlets & (1 << i) != 0));
        }
        for (i, pin) in self.outlets.iter_mut().enumerate() {
            pin.set_state(PinState::from(levels.outlets & (1 << i) != 0));
        }
    }
}

/// What the control core sees of the board.
struct Io<S> {
    valves: ValvePins,
    positive_pump: OutPin,
    negative_pump: OutPin,
    pumps: PumpOutputs,
    chambers: Chambers,
    sensors: S,
    clock: SysTickClock,
}

impl<S> Clock for Io<S> {
    fn now_ms(&self) -> u32 {
        self.clock.now_ms()
    }
}

impl<S: sensors::TankSensors> PressureSource for Io<S> {
    fn read_samples(&mut self) -> SensorSamples {
        self.sensors
            .read(self.clock.now_ms(), self.pumps, &self.chambers)
    }
}

impl<S> Valves for Io<S> {
    /// Break-before-make: first close every valve that must close, then
    /// open the new ones.
    fn set_chambers(&mut self, chambers: &Chambers) {
        let to = ValveLevels::from_chambers(chambers);
        if to != self.valves.levels {
            for step in self.valves.levels.transition(to) {
                self.valves.write(step);
            }
            self.valves.levels = to;
        }
        self.chambers = *chambers;
    }
}

impl<S> Pumps for Io<S> {
    fn set_pumps(&mut self, pumps: PumpOutputs) {
        self.positive_pump
            .set_state(PinState::from(pumps.positive_on));
        self.negative_pump
            .set_state(PinState::from(pumps.negative_on));
        self.pumps = pumps;
    }
}

/// Starts the crystal; false if it is not ready after
/// [`HSE_START_TIMEOUT_SPINS`] polls (then it is switched off again).
fn start_hse(rcc: &pac::RCC) -> bool {
    rcc.cr().modify(|_, w| w.hseon().set_bit());
    for _ in 0..HSE_START_TIMEOUT_SPINS {
        if rcc.cr().read().hserdy().bit_is_set() {
            return true;
        }
    }
    rcc.cr().modify(|_, w| w.hseon().clear_bit());
    false
}

/// The clock configuration: 72 MHz from the 8 MHz crystal if it started,
/// else 64 MHz from the internal RC; the internal 8 MHz RC alone under QEMU.
fn clock_config(hse_ok: bool) -> rcc::Config {
    if cfg!(feature = "qemu") {
        rcc::Config::hsi()
    } else if hse_ok {
        rcc::Config::hse(8.MHz())
            .sysclk(72.MHz())
            .hclk(72.MHz())
            .pclk1(36.MHz())
            .pclk2(72.MHz())
            .adcclk(12.MHz())
    } else {
        rcc::Config::hsi()
            .sysclk(64.MHz())
            .hclk(64.MHz())
            .pclk1(32.MHz())
            .pclk2(64.MHz())
            .adcclk(8.MHz())
    }
}

/// Sets up the board and runs the control loop forever.
pub fn run() -> ! {
    // Before anything can wait: every output low.
    force_safe_outputs();
    #[cfg(feature = "qemu-cost")]
    cost::paint_stack();
    // Both `take`s succeed: this is the only call, right after reset.
    let (Some(dp), Some(cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        defmt::error!("peripherals already taken");
        force_safe_outputs();
        halt()
    };

    // Reset cause first, then clear the flags for the next reset.
    let csr = dp.RCC.csr().read().bits();
    dp.RCC.csr().modify(|_, w| w.rmvf().set_bit());
    let cause = reset_cause(csr);
    let last_stop = take_last_stop();

    let hse_ok = cfg!(feature = "qemu") || start_hse(&dp.RCC);
    let mut flash = dp.FLASH.constrain();
    let mut rcc = dp.RCC.freeze(clock_config(hse_ok), &mut flash.acr);
    let sysclk_hz = if cfg!(feature = "qemu") {
        QEMU_CORE_CLOCK_HZ
    } else {
        rcc.clocks.sysclk().raw()
    };

    let mut gpioa = dp.GPIOA.split(&mut rcc);
    let mut gpiob = dp.GPIOB.split(&mut rcc);
    let mut gpioc = dp.GPIOC.split(&mut rcc);
    let led = gpioc
        .pc13
        .into_push_pull_output_with_state(&mut gpioc.crh, PinState::High)
        .erase();

    // Outputs start low: valves closed, pumps off.
    let valves = ValvePins {
        inlets: [
            gpiob.pb8.into_push_pull_output(&mut gpiob.crh).erase(),
            gpiob.pb9.into_push_pull_output(&mut gpiob.crh).erase(),
            gpiob.pb10.into_push_pull_output(&mut gpiob.crh).erase(),
            gpiob.pb11.into_push_pull_output(&mut gpiob.crh).erase(),
            gpiob.pb12.into_push_pull_output(&mut gpiob.crh).erase(),
            gpiob.pb13.into_push_pull_output(&mut gpiob.crh).erase(),
            gpiob.pb14.into_push_pull_output(&mut gpiob.crh).erase(),
            gpiob.pb15.into_push_pull_output(&mut gpiob.crh).erase(),
        ],
        outlets: [
            gpioa.pa2.into_push_pull_output(&mut gpioa.crl).erase(),
            gpioa.pa3.into_push_pull_output(&mut gpioa.crl).erase(),
            gpioa.pa4.into_push_pull_output(&mut gpioa.crl).erase(),
            gpioa.pa5.into_push_pull_output(&mut gpioa.crl).erase(),
            gpioa.pa6.into_push_pull_output(&mut gpioa.crl).erase(),
            gpioa.pa7.into_push_pull_output(&mut gpioa.crl).erase(),
            gpioa.pa8.into_push_pull_output(&mut gpioa.crh).erase(),
            gpiob.pb0.into_push_pull_output(&mut gpiob.crl).erase(),
        ],
        levels: ValveLevels::CLOSED,
    };
    let positive_pump = gpiob.pb6.into_push_pull_output(&mut gpiob.crl).erase();
    let negative_pump = gpiob.pb5.into_push_pull_output(&mut gpiob.crl).erase();

    let sensors = sensors::init(
        dp.ADC1,
        (gpioa.pa0, gpioa.pa1, gpiob.pb1),
        (&mut gpioa.crl, &mut gpiob.crl),
        &mut rcc,
    );

    let tx_pin = gpioa.pa9.into_alternate_push_pull(&mut gpioa.crh);
    let rx_pin = gpioa.pa10;
    let serial = dp.USART1.serial(
        (tx_pin, rx_pin),
        SerialConfig::default().baudrate(BAUD_RATE.bps()),
        &mut rcc,
    );
    let (mut serial_tx, mut serial_rx) = serial.split();
    serial_rx.listen();
    // SAFETY: `run` is called once, so this is the only reference to the
    // queue ever made; its two halves are its only users from here on.
    let rx_queue: &'static mut Queue<u8, RX_QUEUE_LEN> =
        unsafe { &mut *core::ptr::addr_of_mut!(RX_QUEUE) };
    let (producer, mut rx_consumer) = rx_queue.split();
    // SAFETY: USART1 is still masked, so nothing else reads USART1_ISR now.
    unsafe { *core::ptr::addr_of_mut!(USART1_ISR) = Some((serial_rx, producer)) };
    // SAFETY: the handler touches only USART1_ISR (set above) and an atomic.
    unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };

    let mut syst = cp.SYST;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(sysclk_hz / SYSTICK_HZ - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();

    let mut watchdog = IndependentWatchdog::new(dp.IWDG);
    watchdog.stop_on_debug(&dp.DBGMCU, true);
    watchdog.start(WATCHDOG_TIMEOUT_MS.millis());

    defmt::info!(
        "dexitac firmware {}.{}.{}, protocol {}, reset cause {}, last stop {}, sysclk {} Hz, crystal {}",
        FIRMWARE_VERSION.major,
        FIRMWARE_VERSION.minor,
        FIRMWARE_VERSION.patch,
        PROTOCOL_VERSION,
        cause,
        last_stop,
        sysclk_hz,
        hse_ok
    );

    let mut io = Io {
        valves,
        positive_pump,
        negative_pump,
        pumps: PumpOutputs::OFF,
        chambers: dexitac_firmware::control::valves::SAFE_CHAMBERS,
        sensors,
        clock: SysTickClock,
    };
    let mut controller = Controller::new(Config::default(), cause).with_last_stop(last_stop);
    #[cfg(not(feature = "qemu"))]
    let mut calibration_store = {
        let mut store = flash_store::FlashStore::new(flash);
        store.with_page(|page| controller.load_calibration_record(page));
        store
    };
    // QEMU: no flash store (QEMU 7.2 does not model the F1's flash
    // programming); a calibration from the host lasts until reset.
    #[cfg(feature = "qemu")]
    let mut calibration_store = dexitac_firmware::calibration::NoStore;
    log_calibration(&controller);
    if !hse_ok {
        controller.report_fault(Fault::ClockFallback);
    }
    let mut tx_queue = TxQueues::<TX_URGENT_LEN, TX_TELEMETRY_LEN>::new();
    control_loop(
        &mut controller,
        &mut io,
        Link {
            tx_queue: &mut tx_queue,
            serial_tx: &mut serial_tx,
            rx: &mut rx_consumer,
        },
        Watch {
            watchdog: &mut watchdog,
            led,
        },
        &mut calibration_store,
    )
}

/// Logs the calibration in use at boot.
fn log_calibration(controller: &Controller) {
    defmt::info!("calibration: {}", controller.calibration_report());
}

/// The host link as the control loop sees it.
struct Link<'a> {
    tx_queue: &'a mut TxQueues<TX_URGENT_LEN, TX_TELEMETRY_LEN>,
    serial_tx: &'a mut Tx<USART1>,
    rx: &'a mut heapless::spsc::Consumer<'static, u8>,
}

/// The watchdog and the status LED.
struct Watch<'a> {
    watchdog: &'a mut IndependentWatchdog,
    led: OutPin,
}

/// Runs one control tick per millisecond; sends queued bytes in between.
fn control_loop<S: sensors::TankSensors>(
    controller: &mut Controller,
    io: &mut Io<S>,
    link: Link<'_>,
    mut watch: Watch<'_>,
    calibration_store: &mut impl CalibrationStore,
) -> ! {
    let Link {
        tx_queue,
        serial_tx,
        rx,
    } = link;
    let mut last_ms = io.now_ms();
    let mut rx_chunk = [0u8; RX_CHUNK_LEN];
    let mut last_report = Report::default();
    #[cfg(feature = "qemu-cost")]
    let mut meter = cost::Meter::new();
    loop {
        if let Some(byte) = tx_queue.peek() {
            if serial_tx.write_u8(byte).is_ok() {
                tx_queue.pop();
            }
        }
        let now_ms = io.now_ms();
        if now_ms == last_ms {
            continue;
        }
        last_ms = now_ms;
        let mut n = 0;
        while n < RX_CHUNK_LEN {
            match (rx.dequeue(), rx_chunk.get_mut(n)) {
                (Some(byte), Some(slot)) => *slot = byte,
                _ => break,
            }
            n += 1;
        }
        #[cfg(feature = "qemu-cost")]
        let start = cortex_m::peripheral::SYST::get_current();
        #[cfg(feature = "qemu-cost")]
        meter.script(now_ms, controller, io, tx_queue);
        controller.receive(rx_chunk.get(..n).unwrap_or(&[]), io, tx_queue);
        if controller.calibration_write_pending() {
            // A page erase stalls the CPU for up to 40 ms.
            watch.watchdog.feed();
            if let Some(record) = controller.store_calibration(calibration_store) {
                defmt::info!("calibration record: {}", record);
            }
        }
        let report = controller.tick(io, tx_queue);
        #[cfg(feature = "qemu-cost")]
        meter.record(start);
        if let Some(fault) = report.new_faults.iter().next() {
            record_last_stop(LastStop::Trip { fault });
        }
        watch.led.set_state(PinState::from(!led_on(
            controller.state(),
            controller.faults(),
            now_ms,
        )));
        watch.watchdog.feed();
        if now_ms % REPORT_PERIOD_MS == 0 {
            last_report = report_link(controller, last_report);
        }
    }
}

/// How often the control loop logs link errors (if any are new).
const REPORT_PERIOD_MS: u32 = 1_000;

/// The link counters at the last log line.
#[derive(Default, Clone, Copy, PartialEq, Eq)]
struct Report {
    frame_errors: u32,
    urgent_dropped: u32,
    telemetry_dropped: u32,
    rx_overflows: u32,
    loop_overruns: u32,
}

/// Logs the link and loop counters when they changed since `last`.
fn report_link(controller: &Controller, last: Report) -> Report {
    let link = controller.link_stats();
    let now = Report {
        frame_errors: link.frame_errors,
        urgent_dropped: link.urgent_dropped,
        telemetry_dropped: link.telemetry_dropped,
        rx_overflows: RX_OVERFLOWS.load(Ordering::Relaxed),
        loop_overruns: controller.loop_overruns(),
    };
    if now != last {
        defmt::warn!(
            "bad frames {}, dropped urgent {} telemetry {}, rx overflows {}, loop overruns {}",
            now.frame_errors,
            now.urgent_dropped,
            now.telemetry_dropped,
            now.rx_overflows,
            now.loop_overruns
        );
    }
    now
}

/// Drives every valve and pump output low (closed / off) by direct register
/// writes, whatever state the HAL objects are in: at start-up (before the
/// pins are configured: the output latches then read low when they become
/// outputs) and in the panic and fault handlers.
fn force_safe_outputs() {
    // SAFETY: enabling the GPIOA/GPIOB clocks (read-modify-write of
    // APB2ENR, done before the HAL runs or after it stopped) and BSRR
    // writes, atomic set/reset operations that touch only the given pins.
    unsafe {
        (*pac::RCC::ptr())
            .apb2enr()
            .modify(|_, w| w.iopaen().set_bit().iopben().set_bit());
        (*pac::GPIOA::ptr())
            .bsrr()
            .write(|w| w.bits(GPIOA_OUTPUT_MASK << 16));
        (*pac::GPIOB::ptr())
            .bsrr()
            .write(|w| w.bits(GPIOB_OUTPUT_MASK << 16));
    }
}

/// Stops here until the independent watchdog resets the MCU (under QEMU,
/// which does not model the watchdog: exits through semihosting). Before
/// the watchdog is started (early in `run`) it stops for good, outputs safe.
fn halt() -> ! {
    #[cfg(feature = "qemu")]
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::nop();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    force_safe_outputs();
    record_last_stop(LastStop::Panic {
        line: info.location().map_or(0, |l| l.line()),
    });
    match info.location() {
        Some(l) => defmt::error!("panic at {=str}:{=u32}", l.file(), l.line()),
        None => defmt::error!("panic"),
    }
    halt()
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    force_safe_outputs();
    record_last_stop(LastStop::HardFault { pc: frame.pc() });
    defmt::error!("hard fault at pc {=u32:#x}", frame.pc());
    halt()
}

/// Any interrupt or exception without its own handler.
#[exception]
unsafe fn DefaultHandler(irqn: i16) -> ! {
    force_safe_outputs();
    record_last_stop(LastStop::UnexpectedInterrupt { irqn });
    defmt::error!("unexpected interrupt {=i16}", irqn);
    halt()
}
