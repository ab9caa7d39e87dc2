//! The firmware binary for the STM32F103 (`cargo fw`). On the host this
//! binary only explains how to build it.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod target {
    use defmt_rtt as _;
    use panic_probe as _;

    #[cortex_m_rt::entry]
    fn main() -> ! {
        let v = dexitac_firmware::FIRMWARE_VERSION;
        defmt::info!(
            "dexitac firmware {}.{}.{}, protocol {}",
            v.major,
            v.minor,
            v.patch,
            dexitac_protocol::PROTOCOL_VERSION
        );
        loop {
            cortex_m::asm::wfi();
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("dexitac-firmware runs on the STM32F103: build it with `cargo fw` (thumbv7m-none-eabi)");
    std::process::exit(2);
}
