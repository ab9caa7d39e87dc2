//! The two tank pressure sensors on ADC1 (PA0 positive, PA1 negative),
//! converted with [`dexitac_firmware::sensor::CALIBRATION`].

use dexitac_firmware::sensor::CALIBRATION;
use dexitac_firmware::{PumpOutputs, SensorError, TankReadings};
use dexitac_protocol::Chambers;
use stm32f1xx_hal::adc::{Adc, SampleTime};
use stm32f1xx_hal::gpio::{Analog, Cr, PA0, PA1};
use stm32f1xx_hal::pac::ADC1;
use stm32f1xx_hal::prelude::*;
use stm32f1xx_hal::rcc::Rcc;

/// Where the control loop gets tank readings from.
pub trait TankSensors {
    /// Reads both tanks (the outputs are for simulated sensors).
    fn read(&mut self, now_ms: u32, pumps: PumpOutputs, chambers: &Chambers) -> TankReadings;
}

/// ADC1 with the two sensor inputs.
pub struct AdcSensors {
    adc: Adc<ADC1>,
    positive: PA0<Analog>,
    negative: PA1<Analog>,
}

/// Sets up ADC1 (calibrated at power-up by the HAL) and the analog pins.
pub fn init(adc1: ADC1, pa0: PA0, pa1: PA1, crl: &mut Cr<'A', false>, rcc: &mut Rcc) -> AdcSensors {
    let mut adc = Adc::new(adc1, rcc);
    // 71.5 cycles at 12 MHz: ~7 us per conversion, quiet enough for a
    // sensor behind a divider.
    adc.set_sample_time(SampleTime::T_71);
    AdcSensors {
        adc,
        positive: pa0.into_analog(crl),
        negative: pa1.into_analog(crl),
    }
}

/// One conversion -> pascal; a failed conversion is [`SensorError::NoSample`].
fn convert(result: nb::Result<u16, ()>) -> Result<i32, SensorError> {
    match result {
        Ok(counts) => CALIBRATION.counts_to_pa(counts),
        Err(_) => Err(SensorError::NoSample),
    }
}

impl TankSensors for AdcSensors {
    fn read(&mut self, _now_ms: u32, _pumps: PumpOutputs, _chambers: &Chambers) -> TankReadings {
        TankReadings {
            positive_pa: convert(self.adc.read(&mut self.positive)),
            negative_pa: convert(self.adc.read(&mut self.negative)),
        }
    }
}
