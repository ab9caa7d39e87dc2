//! The calibration record in the last flash page (board build only; the
//! QEMU build keeps no record, [`dexitac_firmware::calibration::NoStore`]).
//!
//! The page is [`CALIBRATION_PAGE_ADDRESS`] (0x0800_FC00, the last 1 KB of
//! the STM32F103C8's 64 KB), outside the linker's `FLASH` region (root
//! `memory.x`), written with stm32f1xx-hal's `FlashWriter`: page erase,
//! half-word programming, both verified by reading back.
//!
//! The control core asks for a write ([`Controller::store_calibration`])
//! only while the MCU is not armed with both pumps off: a page erase stalls
//! every flash access, so the CPU, for 20..40 ms (datasheet t_ERASE). The
//! control loop feeds the watchdog (50 ms) just before; the stall shows as
//! a loop overrun, and SysTick, whose interrupt waits too, loses that time.
//! The ack was queued before the write and goes out after it, so a host
//! that waits for the ack is not sending while the receiver cannot keep up.
//!
//! [`Controller::store_calibration`]: dexitac_firmware::Controller::store_calibration

#[cfg(doc)]
use dexitac_firmware::calibration::CALIBRATION_PAGE_ADDRESS;
use dexitac_firmware::calibration::{
    CalibrationStore, StoreError, CALIBRATION_PAGE_OFFSET, FLASH_PAGE_LEN, RECORD_LEN,
};
use stm32f1xx_hal::flash::{FlashSize, FlashWriter, Parts, SectorSize};

/// The flash controller, for the record's page.
pub struct FlashStore {
    flash: Parts,
}

impl FlashStore {
    /// Takes the flash controller (after the clock set-up used its `acr`).
    pub fn new(flash: Parts) -> Self {
        FlashStore { flash }
    }

    fn writer(&mut self) -> FlashWriter<'_> {
        // The C8's 64 KB in 1 KB pages (medium density).
        self.flash.writer(SectorSize::Sz1K, FlashSize::Sz64K)
    }

    /// Calls `f` with the record's page as it is in flash now (empty if
    /// the HAL refuses the read, which it does only for a bad address).
    pub fn with_page<T>(&mut self, f: impl FnOnce(&[u8]) -> T) -> T {
        let writer = self.writer();
        let page = writer
            .read(CALIBRATION_PAGE_OFFSET, FLASH_PAGE_LEN)
            .unwrap_or(&[]);
        f(page)
    }
}

impl CalibrationStore for FlashStore {
    fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), StoreError> {
        let mut writer = self.writer();
        // The same record again (a retried command): no erase, no wear.
        if writer
            .read(CALIBRATION_PAGE_OFFSET, RECORD_LEN)
            .is_ok_and(|stored| stored == record.as_slice())
        {
            return Ok(());
        }
        if writer.page_erase(CALIBRATION_PAGE_OFFSET).is_err() {
            defmt::warn!("calibration: erasing the record's page failed");
            return Err(StoreError::Failed);
        }
        if writer.write(CALIBRATION_PAGE_OFFSET, record).is_err() {
            defmt::warn!("calibration: writing the record failed");
            return Err(StoreError::Failed);
        }
        Ok(())
    }
}
