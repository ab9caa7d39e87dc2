//! What several commands share: argument groups and their set-up (frame
//! sources, recording flags, the live view, the board's port) and the
//! Ctrl-C handler.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

pub mod board;
pub mod live;
pub mod out_dir;
pub mod progress;
pub mod record;
pub mod sources;

/// Installs a Ctrl-C handler that sets `stop` (once per process).
pub fn stop_on_ctrl_c(stop: &Arc<AtomicBool>) {
    let flag = Arc::clone(stop);
    if let Err(e) = ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)) {
        tracing::warn!("Ctrl-C handler not installed ({e}); stop with the scenario's end");
    }
}
