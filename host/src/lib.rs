//! DexiTac host library: everything the `dexitac` command runs on the PC.
#![warn(missing_docs)]

pub use dexitac_protocol as protocol;
