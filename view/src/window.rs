//! A native window showing the dashboard, like an OpenCV `imshow` window.
//!
//! [`minifb`] with only its X11 backend: libX11 and libXcursor are loaded
//! at run time (x11-dl), so the build needs no system package and a
//! machine without X (CI, a server over SSH) still runs everything else;
//! opening the window then fails with [`ViewError::NoDisplay`] and the
//! caller suggests PNG snapshots. Wayland desktops run it through XWayland.
//! The window shows the rendered image unscaled (1:1 pixels).
//!
//! The window belongs to the thread that opened it: keep it on the thread
//! that renders.

use image::RgbImage;
use minifb::{Key, Window, WindowOptions};

use crate::ViewError;

/// The live view's window.
pub struct ViewWindow {
    window: Window,
    buffer: Vec<u32>,
}

impl std::fmt::Debug for ViewWindow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViewWindow")
            .field("size", &self.window.get_size())
            .finish()
    }
}

impl ViewWindow {
    /// Opens a `width x height` window on the X display `$DISPLAY`.
    pub fn open(title: &str, width: u32, height: u32) -> Result<Self, ViewError> {
        let display = std::env::var("DISPLAY").unwrap_or_default();
        if display.is_empty() {
            return Err(ViewError::NoDisplay("DISPLAY is not set".into()));
        }
        let mut window = Window::new(
            title,
            width as usize,
            height as usize,
            WindowOptions::default(),
        )
        .map_err(|e| {
            let msg = e.to_string();
            if msg.contains("XOpenDisplay") || msg.contains("load Xlib") {
                ViewError::NoDisplay(format!("cannot open X display {display:?}: {msg}"))
            } else {
                ViewError::Window(msg)
            }
        })?;
        // The caller paces the redraws.
        window.set_target_fps(0);
        Ok(ViewWindow {
            window,
            buffer: Vec::new(),
        })
    }

    /// Shows `img` and handles the window's events.
    pub fn show(&mut self, img: &RgbImage) -> Result<(), ViewError> {
        self.buffer.clear();
        self.buffer.extend(
            img.as_raw()
                .chunks_exact(3)
                .map(|p| (u32::from(p[0]) << 16) | (u32::from(p[1]) << 8) | u32::from(p[2])),
        );
        self.window
            .update_with_buffer(&self.buffer, img.width() as usize, img.height() as usize)
            .map_err(|e| ViewError::Window(e.to_string()))
    }

    /// Handles the window's events without a new picture.
    pub fn poll(&mut self) {
        self.window.update();
    }

    /// The user closed the window or pressed Esc or q.
    pub fn close_requested(&self) -> bool {
        !self.window.is_open()
            || self.window.is_key_down(Key::Escape)
            || self.window.is_key_down(Key::Q)
    }

    /// Sets the window's title.
    pub fn set_title(&mut self, title: &str) {
        self.window.set_title(title);
    }
}
