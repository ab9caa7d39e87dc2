//! The two tank pressure sensors and their supply on ADC1: PA0 positive,
//! PA1 negative, PB1 the sensor supply through a 1/2 divider (wiring in
//! [`dexitac_firmware::sensor`]). Each channel is converted
//! [`OVERSAMPLE`] times per tick; the control core converts and filters.

use dexitac_firmware::sensor::{ChannelSamples, OVERSAMPLE};
use dexitac_firmware::{PumpOutputs, SensorError, SensorSamples};
use dexitac_protocol::Chambers;
use stm32f1xx_hal::adc::{Adc, SampleTime};
use stm32f1xx_hal::gpio::{Analog, Cr, PA0, PA1, PB1};
use stm32f1xx_hal::pac::ADC1;
use stm32f1xx_hal::prelude::*;
use stm32f1xx_hal::rcc::Rcc;

/// Where the control loop gets sensor samples from.
pub trait TankSensors {
    /// Converts every input (the outputs are for simulated sensors).
    fn read(&mut self, now_ms: u32, pumps: PumpOutputs, chambers: &Chambers) -> SensorSamples;
}

/// ADC1 with the three inputs.
pub struct AdcSensors {
    adc: Adc<ADC1>,
    positive: PA0<Analog>,
    negative: PA1<Analog>,
    supply: PB1<Analog>,
}

/// Sets up ADC1 (calibrated at power-up by the HAL) and the analog pins.
pub fn init(
    adc1: ADC1,
    (pa0, pa1, pb1): (PA0, PA1, PB1),
    (crl_a, crl_b): (&mut Cr<'A', false>, &mut Cr<'B', false>),
    rcc: &mut Rcc,
) -> AdcSensors {
    let mut adc = Adc::new(adc1, rcc);
    // 28.5 cycles at 12 MHz: 3.4 us per conversion, 24 conversions a tick
    // take about 80 us of the 1 ms period; fine for dividers of 10-20 kOhm.
    adc.set_sample_time(SampleTime::T_28);
    AdcSensors {
        adc,
        positive: pa0.into_analog(crl_a),
        negative: pa1.into_analog(crl_a),
        supply: pb1.into_analog(crl_b),
    }
}

/// [`OVERSAMPLE`] conversions of one input (`$adc.read(&mut $pin)`); a
/// failed conversion is [`SensorError::NoSample`].
macro_rules! sample {
    ($adc:expr, $pin:expr) => {{
        let mut out = [0u16; OVERSAMPLE];
        let mut result: ChannelSamples = Ok(out);
        for slot in out.iter_mut() {
            match $adc.read($pin) {
                Ok(counts) => *slot = counts,
                Err(nb::Error::WouldBlock | nb::Error::Other(())) => {
                    result = Err(SensorError::NoSample);
                    break;
                }
            }
        }
        result.map(|_| out)
    }};
}

impl TankSensors for AdcSensors {
    fn read(&mut self, _now_ms: u32, _pumps: PumpOutputs, _chambers: &Chambers) -> SensorSamples {
        SensorSamples {
            positive: sample!(self.adc, &mut self.positive),
            negative: sample!(self.adc, &mut self.negative),
            supply: sample!(self.adc, &mut self.supply),
        }
    }
}
