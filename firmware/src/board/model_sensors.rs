//! QEMU build: a simulated tank pair ([`TankModel`]) in place of the ADC,
//! which QEMU's `stm32vldiscovery` does not model (a conversion would hang).

use dexitac_firmware::tank_model::{TankModel, TankModelParams};
use dexitac_firmware::{PumpOutputs, TankReadings};
use dexitac_protocol::Chambers;
use stm32f1xx_hal::gpio::{Cr, PA0, PA1};
use stm32f1xx_hal::pac::ADC1;
use stm32f1xx_hal::rcc::Rcc;

/// Where the control loop gets tank readings from.
pub trait TankSensors {
    /// Reads both tanks, advancing the model with the current outputs.
    fn read(&mut self, now_ms: u32, pumps: PumpOutputs, chambers: &Chambers) -> TankReadings;
}

/// The simulated tanks.
pub struct ModelSensors {
    model: TankModel,
    last_ms: Option<u32>,
}

/// The model at atmospheric pressure; the ADC and its pins stay unused.
pub fn init(
    _adc1: ADC1,
    _pa0: PA0,
    _pa1: PA1,
    _crl: &mut Cr<'A', false>,
    _rcc: &mut Rcc,
) -> ModelSensors {
    ModelSensors {
        model: TankModel::new(TankModelParams::default()),
        last_ms: None,
    }
}

impl TankSensors for ModelSensors {
    fn read(&mut self, now_ms: u32, pumps: PumpOutputs, chambers: &Chambers) -> TankReadings {
        let dt_ms = self.last_ms.map_or(0, |last| now_ms.wrapping_sub(last));
        self.last_ms = Some(now_ms);
        self.model.advance(dt_ms, pumps, chambers);
        let (positive_pa, negative_pa) = self.model.tanks_pa();
        TankReadings {
            positive_pa: Ok(positive_pa),
            negative_pa: Ok(negative_pa),
        }
    }
}
