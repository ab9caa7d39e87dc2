//! QEMU build: a simulated tank pair ([`TankModel`]) in place of the ADC,
//! which QEMU's `stm32vldiscovery` does not model (a conversion would hang).
//! The model's pressures become the counts a sensor on a 5.0 V supply would
//! give, so the control core's conversion runs as on the board.

use dexitac_firmware::sensor::{NOMINAL_FRONT_END, OVERSAMPLE};
use dexitac_firmware::tank_model::{TankModel, TankModelParams};
use dexitac_firmware::{PumpOutputs, SensorSamples};
use dexitac_protocol::Chambers;
use stm32f1xx_hal::gpio::{Cr, PA0, PA1, PB1};
use stm32f1xx_hal::pac::ADC1;
use stm32f1xx_hal::rcc::Rcc;

/// The simulated sensor supply and ADC reference, in millivolt.
const SUPPLY_MV: u32 = 5_000;
const VDDA_MV: u32 = 3_300;

/// Where the control loop gets sensor samples from.
pub trait TankSensors {
    /// Converts every input, advancing the model with the current outputs.
    fn read(&mut self, now_ms: u32, pumps: PumpOutputs, chambers: &Chambers) -> SensorSamples;
}

/// The simulated tanks.
pub struct ModelSensors {
    model: TankModel,
    last_ms: Option<u32>,
}

/// The model at atmospheric pressure; the ADC and its pins stay unused.
pub fn init(
    _adc1: ADC1,
    _pins: (PA0, PA1, PB1),
    _crl: (&mut Cr<'A', false>, &mut Cr<'B', false>),
    _rcc: &mut Rcc,
) -> ModelSensors {
    ModelSensors {
        model: TankModel::new(TankModelParams::default()),
        last_ms: None,
    }
}

impl TankSensors for ModelSensors {
    fn read(&mut self, now_ms: u32, pumps: PumpOutputs, chambers: &Chambers) -> SensorSamples {
        let dt_ms = self.last_ms.map_or(0, |last| now_ms.wrapping_sub(last));
        self.last_ms = Some(now_ms);
        self.model.advance(dt_ms, pumps, chambers);
        let (positive_pa, negative_pa) = self.model.tanks_pa();
        let fe = NOMINAL_FRONT_END;
        let counts = |pa| Ok([fe.sensor_counts(pa, SUPPLY_MV, VDDA_MV); OVERSAMPLE]);
        SensorSamples {
            positive: counts(positive_pa),
            negative: counts(negative_pa),
            supply: Ok([fe.supply_counts(SUPPLY_MV, VDDA_MV); OVERSAMPLE]),
        }
    }
}
