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
//! | positive pump | PB1 |
//! | negative pump | PB5 |
//! | positive tank sensor | PA0 (ADC1_IN0) |
//! | negative tank sensor | PA1 (ADC1_IN1) |
//! | host link USART1 | PA9 TX, PA10 RX, **115 200 baud 8N1** |
//!
//! Every output is push-pull, high = energised (valve open, pump on), and
//! drives a low-side driver whose gate is pulled down: outputs float low
//! during reset, which is the safe state (all valves closed, pumps off).
//! PA11/PA12 (USB), PA13/PA14 (SWD) and PA15/PB3/PB4 (JTAG) stay free.
//!
//! # Control loop
//!
//! The USART1 receive interrupt moves each byte into [`RX_QUEUE`]. The main
//! loop, on every new millisecond: hands the received bytes to
//! [`Controller::receive`], runs [`Controller::tick`], feeds the independent
//! watchdog (only here: a stalled loop resets the MCU within
//! [`WATCHDOG_TIMEOUT_MS`]); in between it moves queued reply bytes into the
//! USART data register without blocking.

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{exception, ExceptionFrame};
use critical_section::Mutex;
use defmt_rtt as _;
use dexitac_firmware::control::valves::ValveLevels;
use dexitac_firmware::reset::reset_cause;
use dexitac_firmware::{
    ByteQueue, Clock, Config, Controller, PressureSource, PumpOutputs, Pumps, TankReadings, Valves,
    FIRMWARE_VERSION,
};
use dexitac_protocol::{Chambers, PROTOCOL_VERSION};
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

/// Received bytes not yet handed to the controller. 256 bytes hold more
/// than 20 ms of line time at 115 200 baud.
const RX_QUEUE_LEN: usize = 256;
/// Bytes waiting to be sent: a few telemetry frames and replies.
const TX_QUEUE_LEN: usize = 512;
/// Bytes handed to the controller per tick, at most.
const RX_CHUNK_LEN: usize = 64;

/// Milliseconds since start-up, counted by SysTick.
static MILLIS: AtomicU32 = AtomicU32::new(0);
/// Bytes dropped because [`RX_QUEUE`] was full.
static RX_OVERFLOWS: AtomicU32 = AtomicU32::new(0);
/// The USART1 receiver, owned by its interrupt after start-up.
static RX: Mutex<RefCell<Option<Rx<USART1>>>> = Mutex::new(RefCell::new(None));
/// Received bytes, from the USART1 interrupt to the control loop.
static RX_QUEUE: Mutex<RefCell<ByteQueue<RX_QUEUE_LEN>>> =
    Mutex::new(RefCell::new(ByteQueue::new()));

/// Output pins that are energised when high: masks for the panic path.
/// GPIOA: outlets PA2..PA8.
const GPIOA_OUTPUT_MASK: u32 = 0b1_1111_1100;
/// GPIOB: outlet PB0, pumps PB1 and PB5, inlets PB8..PB15.
const GPIOB_OUTPUT_MASK: u32 = 0xFF00 | (1 << 5) | (1 << 1) | 1;

/// The system tick: one millisecond.
#[exception]
fn SysTick() {
    MILLIS.fetch_add(1, Ordering::Relaxed);
}

/// USART1: move every received byte into [`RX_QUEUE`].
#[interrupt]
fn USART1() {
    critical_section::with(|cs| {
        let mut rx = RX.borrow_ref_mut(cs);
        let mut queue = RX_QUEUE.borrow_ref_mut(cs);
        let Some(rx) = rx.as_mut() else {
            return;
        };
        // `read` clears a line error (overrun, framing, noise) by reading
        // SR then DR; the broken frame then fails its CRC in the decoder.
        while let Ok(byte) = rx.read() {
            if queue.push(byte).is_err() {
                RX_OVERFLOWS.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
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
    fn read_tanks(&mut self) -> TankReadings {
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

/// The clock configuration: 72 MHz from the 8 MHz crystal on the board,
/// the internal 8 MHz RC under QEMU.
fn clock_config() -> rcc::Config {
    if cfg!(feature = "qemu") {
        rcc::Config::hsi()
    } else {
        rcc::Config::hse(8.MHz())
            .sysclk(72.MHz())
            .hclk(72.MHz())
            .pclk1(36.MHz())
            .pclk2(72.MHz())
            .adcclk(12.MHz())
    }
}

/// Sets up the board and runs the control loop forever.
pub fn run() -> ! {
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

    let mut flash = dp.FLASH.constrain();
    let mut rcc = dp.RCC.freeze(clock_config(), &mut flash.acr);
    let sysclk_hz = if cfg!(feature = "qemu") {
        QEMU_CORE_CLOCK_HZ
    } else {
        rcc.clocks.sysclk().raw()
    };

    let mut gpioa = dp.GPIOA.split(&mut rcc);
    let mut gpiob = dp.GPIOB.split(&mut rcc);

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
    let positive_pump = gpiob.pb1.into_push_pull_output(&mut gpiob.crl).erase();
    let negative_pump = gpiob.pb5.into_push_pull_output(&mut gpiob.crl).erase();

    let sensors = sensors::init(dp.ADC1, gpioa.pa0, gpioa.pa1, &mut gpioa.crl, &mut rcc);

    let tx_pin = gpioa.pa9.into_alternate_push_pull(&mut gpioa.crh);
    let rx_pin = gpioa.pa10;
    let serial = dp.USART1.serial(
        (tx_pin, rx_pin),
        SerialConfig::default().baudrate(BAUD_RATE.bps()),
        &mut rcc,
    );
    let (mut serial_tx, mut serial_rx) = serial.split();
    serial_rx.listen();
    critical_section::with(|cs| RX.borrow(cs).replace(Some(serial_rx)));
    // SAFETY: the handler only touches RX and RX_QUEUE, both behind
    // critical sections; unmasking cannot break a critical section.
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
        "dexitac firmware {}.{}.{}, protocol {}, reset cause {}, sysclk {} Hz",
        FIRMWARE_VERSION.major,
        FIRMWARE_VERSION.minor,
        FIRMWARE_VERSION.patch,
        PROTOCOL_VERSION,
        cause,
        sysclk_hz
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
    let mut controller = Controller::new(Config::default(), cause);
    let mut tx_queue = ByteQueue::<TX_QUEUE_LEN>::new();
    control_loop(
        &mut controller,
        &mut io,
        &mut tx_queue,
        &mut serial_tx,
        &mut watchdog,
    )
}

/// Runs one control tick per millisecond; sends queued bytes in between.
fn control_loop<S: sensors::TankSensors>(
    controller: &mut Controller,
    io: &mut Io<S>,
    tx_queue: &mut ByteQueue<TX_QUEUE_LEN>,
    serial_tx: &mut Tx<USART1>,
    watchdog: &mut IndependentWatchdog,
) -> ! {
    let mut last_ms = io.now_ms();
    let mut rx_chunk = [0u8; RX_CHUNK_LEN];
    let mut last_report = Report::default();
    #[cfg(feature = "qemu-cost")]
    let mut meter = cost::Meter::new(controller, io, tx_queue);
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
        let n = critical_section::with(|cs| RX_QUEUE.borrow_ref_mut(cs).pop_into(&mut rx_chunk));
        #[cfg(feature = "qemu-cost")]
        let (start, script) = (
            cortex_m::peripheral::SYST::get_current(),
            meter.scripted_input(now_ms),
        );
        #[cfg(feature = "qemu-cost")]
        if let Some(frame) = &script {
            controller.receive(frame, io, tx_queue);
        }
        controller.receive(rx_chunk.get(..n).unwrap_or(&[]), io, tx_queue);
        controller.tick(io, tx_queue);
        #[cfg(feature = "qemu-cost")]
        meter.record(start);
        watchdog.feed();
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
    tx_dropped: u32,
    rx_overflows: u32,
    loop_overruns: u32,
}

/// Logs the link and loop counters when they changed since `last`.
fn report_link(controller: &Controller, last: Report) -> Report {
    let link = controller.link_stats();
    let now = Report {
        frame_errors: link.frame_errors,
        tx_dropped: link.tx_dropped,
        rx_overflows: RX_OVERFLOWS.load(Ordering::Relaxed),
        loop_overruns: controller.loop_overruns(),
    };
    if now != last {
        defmt::warn!(
            "bad frames {}, tx dropped {}, rx overflows {}, loop overruns {}",
            now.frame_errors,
            now.tx_dropped,
            now.rx_overflows,
            now.loop_overruns
        );
    }
    now
}

/// Drives every valve and pump output low (closed / off) by direct register
/// writes, whatever state the HAL objects are in. For the panic and fault
/// handlers.
fn force_safe_outputs() {
    // SAFETY: BSRR writes are atomic set/reset operations that touch only
    // the given pins; writing reset bits cannot conflict with any other
    // user of the ports, which is stopped anyway when this runs.
    unsafe {
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
    match info.location() {
        Some(l) => defmt::error!("panic at {=str}:{=u32}", l.file(), l.line()),
        None => defmt::error!("panic"),
    }
    halt()
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    force_safe_outputs();
    defmt::error!("hard fault at pc {=u32:#x}", frame.pc());
    halt()
}
