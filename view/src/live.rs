//! The live loop: events from a channel into a [`Dashboard`], redrawn into
//! the window at most `fps` times a second (only when something changed),
//! snapshots written as their time comes. Runs on the thread that owns the
//! window.
//!
//! It ends when the channel closes (the run ended): the window is handed
//! back, still open, for [`linger`] (the last picture stays up until the
//! user closes it); or when the user closes the window (Esc, q, the close
//! button): it then sets the `stop` flag, which ends the run safely (the
//! task loop seals the valves and disarms).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::{Dashboard, Snapshots, ViewError, ViewWindow};
use dexitac_rig::event::RuntimeEvent;

/// Most events applied between two checks of the window.
const MAX_EVENTS_PER_PASS: usize = 5_000;

/// How to run the live loop.
#[derive(Debug)]
pub struct LiveOptions {
    /// The window (`None`: headless, snapshots only).
    pub window: Option<ViewWindow>,
    /// Snapshot writer.
    pub snapshots: Option<Snapshots>,
    /// Most redraws per second of the window.
    pub fps: f64,
    /// Set when the user closes the window.
    pub stop: Arc<AtomicBool>,
    /// Lower the calling thread's priority first (the rig's control loop
    /// keeps its deadlines while the view draws); threads it spawns later
    /// inherit it.
    pub lower_priority: bool,
}

/// What the live loop did.
#[derive(Debug, Clone, Default)]
pub struct LiveSummary {
    /// Events applied.
    pub events: u64,
    /// Dashboard renders (window frames and snapshots).
    pub renders: u64,
    /// Mean wall time of a render, ms.
    pub render_ms_mean: f64,
    /// Longest render, ms.
    pub render_ms_max: f64,
    /// The user closed the window before the run ended.
    pub closed_by_user: bool,
    /// Snapshot files written.
    pub snapshots: Vec<PathBuf>,
}

/// What [`run`] hands back.
#[derive(Debug)]
pub struct LiveEnd {
    /// What it did.
    pub summary: LiveSummary,
    /// The window, still open, when the events ended first.
    pub window: Option<ViewWindow>,
}

/// Render timing.
#[derive(Debug, Default)]
struct Timing {
    renders: u64,
    total_ms: f64,
    max_ms: f64,
}

impl Timing {
    fn render(&mut self, dashboard: &Dashboard) -> image::RgbImage {
        let t0 = Instant::now();
        let img = dashboard.render();
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        self.renders += 1;
        self.total_ms += ms;
        self.max_ms = self.max_ms.max(ms);
        img
    }
}

/// Applies one event and writes a snapshot if one is due.
fn handle(
    event: &RuntimeEvent,
    dashboard: &mut Dashboard,
    snapshots: &mut Option<Snapshots>,
    timing: &mut Timing,
) -> Result<(), ViewError> {
    dashboard.apply(event);
    if let Some(s) = snapshots.as_mut() {
        if s.due(dashboard.now_ms()) {
            let img = timing.render(dashboard);
            s.save(&img, dashboard.now_ms().unwrap_or(0))?;
        }
    }
    Ok(())
}

/// Runs the live loop until the events end or the window is closed (see
/// the [module docs](self)).
pub fn run(
    rx: &Receiver<RuntimeEvent>,
    dashboard: &mut Dashboard,
    options: LiveOptions,
) -> Result<LiveEnd, ViewError> {
    if options.lower_priority {
        dexitac_rig::task_loop::lower_thread_priority();
    }
    let LiveOptions {
        mut window,
        mut snapshots,
        fps,
        stop,
        ..
    } = options;
    let mut timing = Timing::default();
    let mut closed_by_user = false;
    match window.as_mut() {
        None => {
            for event in rx.iter() {
                handle(&event, dashboard, &mut snapshots, &mut timing)?;
            }
        }
        Some(window) => {
            let period = frame_period(fps);
            let mut next_frame = Instant::now();
            let mut dirty = true;
            loop {
                let wait = next_frame.saturating_duration_since(Instant::now());
                match rx.recv_timeout(wait) {
                    Ok(event) => {
                        handle(&event, dashboard, &mut snapshots, &mut timing)?;
                        dirty = true;
                        for event in rx.try_iter().take(MAX_EVENTS_PER_PASS) {
                            handle(&event, dashboard, &mut snapshots, &mut timing)?;
                        }
                    }
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => {
                        window.show(&timing.render(dashboard))?;
                        break;
                    }
                }
                let now = Instant::now();
                if now >= next_frame {
                    next_frame = (next_frame + period).max(now);
                    if dirty {
                        let img = timing.render(dashboard);
                        window.show(&img)?;
                        dirty = false;
                    } else {
                        window.poll();
                    }
                    if window.close_requested() {
                        closed_by_user = true;
                        stop.store(true, Ordering::Relaxed);
                        break;
                    }
                }
            }
        }
    }
    if let Some(s) = snapshots.as_mut() {
        if s.final_due(dashboard.now_ms()) {
            let img = timing.render(dashboard);
            s.save(&img, dashboard.now_ms().unwrap_or(0))?;
        }
    }
    let summary = LiveSummary {
        events: dashboard.events(),
        renders: timing.renders,
        render_ms_mean: if timing.renders > 0 {
            timing.total_ms / timing.renders as f64
        } else {
            0.0
        },
        render_ms_max: timing.max_ms,
        closed_by_user,
        snapshots: snapshots.map(|s| s.written().to_vec()).unwrap_or_default(),
    };
    Ok(LiveEnd {
        summary,
        window: window.filter(|_| !closed_by_user),
    })
}

fn frame_period(fps: f64) -> Duration {
    let fps = if fps.is_finite() {
        fps.clamp(1.0, 120.0)
    } else {
        30.0
    };
    Duration::from_secs_f64(1.0 / fps)
}

/// Keeps `window` open with its last picture until the user closes it or
/// `stop` is set (Ctrl-C).
pub fn linger(mut window: ViewWindow, title: &str, stop: &AtomicBool) {
    window.set_title(&format!("{title} - finished: Esc or q to close"));
    let period = frame_period(30.0);
    while !window.close_requested() && !stop.load(Ordering::Relaxed) {
        std::thread::sleep(period);
        window.poll();
    }
}
