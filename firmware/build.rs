//! Build script: the QEMU build (feature `qemu`, bare-metal target) links
//! with `qemu/qemu.x`, which moves the stack to the end of QEMU's 8 KB RAM
//! (see that file for why the root `memory.x` cannot simply be replaced).

use std::env;
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=qemu/qemu.x");
    let qemu = env::var_os("CARGO_FEATURE_QEMU").is_some();
    let bare_metal = env::var("CARGO_CFG_TARGET_OS").is_ok_and(|os| os == "none");
    if qemu && bare_metal {
        let dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default()).join("qemu");
        println!("cargo:rustc-link-search={}", dir.display());
        println!("cargo:rustc-link-arg-bins=-Tqemu.x");
    }
}
