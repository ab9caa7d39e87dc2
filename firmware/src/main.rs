//! The firmware binary for the STM32F103 (`cargo fw`), or for QEMU's
//! `stm32vldiscovery` machine with `--features qemu`. All the work is in
//! [`board`] (hardware) and the `dexitac_firmware` library (control core).
//! On the host this binary only explains how to build it.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board;

#[cfg(target_os = "none")]
#[cortex_m_rt::entry]
fn main() -> ! {
    board::run()
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "dexitac-firmware runs on the STM32F103: build it with `cargo fw` (thumbv7m-none-eabi)"
    );
    std::process::exit(2);
}
