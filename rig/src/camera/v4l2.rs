//! The V4L2 camera (Linux), through the `linuxvideo` crate: plain ioctls,
//! no libv4l, no bindgen at build time.
//!
//! Opening checks the device is a video capture device, picks the first
//! requested format the device offers, asks for the size (the driver may
//! grant another: [`Mode`] says what it granted) and the frame interval
//! (drivers that cannot set it keep theirs: `fps` is then `None`), and
//! starts streaming with `linuxvideo`'s two mmap buffers.
//!
//! Reading waits with `poll(2)` (so a stalled camera times out instead of
//! blocking for ever), dequeues a buffer, then drains any newer buffers
//! already filled: the caller always gets the newest one, and the drained
//! ones are counted in [`BufferInfo::skipped`].
//!
//! Left out: `linuxvideo` 0.3 does not expose the driver's buffer
//! timestamp, so [`BufferInfo::captured`] is `None` and the camera source
//! uses the receive time (at most about one frame period later for UVC
//! cameras, whose driver stamps the start of the transfer).

use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::time::Duration;

use linuxvideo::format::{PixFormat, PixelFormat as V4lFormat};
use linuxvideo::stream::ReadStream;
use linuxvideo::{BufType, CapabilityFlags, Device, Fract};

use super::fake::format_list;
use super::{BufferInfo, CameraError, CaptureRequest, Mode, PixelFormat, RawDevice};

/// A V4L2 camera by device node.
pub struct V4l2Device {
    path: PathBuf,
    stream: Option<ReadStream>,
}

impl V4l2Device {
    /// A camera at `path` (not opened yet).
    pub fn new(path: &Path) -> Self {
        V4l2Device {
            path: path.to_path_buf(),
            stream: None,
        }
    }

    fn err(&self, op: &'static str) -> impl Fn(std::io::Error) -> CameraError + '_ {
        move |e| CameraError::from_io(&self.path, op, e)
    }
}

impl RawDevice for V4l2Device {
    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn open(&mut self, request: &CaptureRequest) -> Result<Mode, CameraError> {
        self.close();
        let device = Device::open(&self.path).map_err(self.err("open"))?;
        let caps = device
            .capabilities()
            .map_err(self.err("query capabilities"))?;
        if !caps
            .device_capabilities()
            .contains(CapabilityFlags::VIDEO_CAPTURE)
        {
            return Err(CameraError::NotCapture {
                device: self.path.clone(),
                what: format!("{} has no video capture", caps.card()),
            });
        }
        let offered = capture_formats(&device);
        let Some(format) = request
            .formats
            .iter()
            .copied()
            .find(|f| offered.iter().any(|(o, _)| o == f))
        else {
            return Err(CameraError::NoFormat {
                device: self.path.clone(),
                wanted: format_list(&request.formats),
                offered: offered_names(&device),
            });
        };
        let wanted = PixFormat::new(
            request.width_px,
            request.height_px,
            V4lFormat::from_fourcc(format.fourcc()),
        );
        let capture = device
            .video_capture(wanted)
            .map_err(self.err("set the format"))?;
        let granted = capture.format();
        let granted_format = PixelFormat::from_fourcc(granted.pixel_format().as_fourcc())
            .ok_or_else(|| CameraError::NoFormat {
                device: self.path.clone(),
                wanted: format.to_string(),
                offered: format!("{:?} (the driver's choice)", granted.pixel_format()),
            })?;
        let fps = fps_interval(request.fps)
            .and_then(|interval| capture.set_frame_interval(interval).ok())
            .and_then(|f| {
                (f.numerator() > 0).then(|| f.denominator() as f64 / f.numerator() as f64)
            });
        let mode = Mode {
            format: granted_format,
            width_px: granted.width(),
            height_px: granted.height(),
            stride_bytes: granted.bytes_per_line() as usize,
            fps,
        };
        self.stream = Some(capture.into_stream().map_err(self.err("start streaming"))?);
        Ok(mode)
    }

    fn next_buffer(
        &mut self,
        data: &mut Vec<u8>,
        timeout: Duration,
    ) -> Result<Option<BufferInfo>, CameraError> {
        let path = &self.path;
        let io = |op| move |e| CameraError::from_io(path, op, e);
        let Some(stream) = self.stream.as_mut() else {
            return Err(CameraError::Disconnected {
                device: path.clone(),
            });
        };
        if !wait_readable(stream.as_raw_fd(), timeout).map_err(io("poll"))? {
            return Ok(None);
        }
        let mut flagged = dequeue_into(stream, data).map_err(io("dequeue a buffer"))?;
        let mut skipped = 0;
        // Older buffers first: keep dequeuing while another one is ready.
        while !stream.will_block().map_err(io("query buffers"))? {
            flagged = dequeue_into(stream, data).map_err(io("dequeue a buffer"))?;
            skipped += 1;
        }
        Ok(Some(BufferInfo {
            captured: None,
            skipped,
            flagged,
        }))
    }

    fn close(&mut self) {
        self.stream = None;
    }
}

/// Copies the next buffer into `data`; true when the driver flagged it.
fn dequeue_into(stream: &mut ReadStream, data: &mut Vec<u8>) -> std::io::Result<bool> {
    stream.dequeue(|view| {
        data.clear();
        data.extend_from_slice(&view);
        Ok(view.is_error())
    })
}

/// Waits until `fd` has a buffer; false on timeout or a signal. A
/// disconnected UVC camera reports `POLLERR`: that is an `ENODEV` error.
fn wait_readable(fd: i32, timeout: Duration) -> std::io::Result<bool> {
    let mut pfd = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
    // SAFETY: `pfd` is a valid pollfd for the duration of the call and we
    // pass a count of 1.
    let n = unsafe { libc::poll(&mut pfd, 1, ms) };
    if n < 0 {
        let e = std::io::Error::last_os_error();
        return if e.raw_os_error() == Some(libc::EINTR) {
            Ok(false)
        } else {
            Err(e)
        };
    }
    if n == 0 {
        return Ok(false);
    }
    if pfd.revents & (libc::POLLERR | libc::POLLHUP | libc::POLLNVAL) != 0 {
        return Err(std::io::Error::from_raw_os_error(libc::ENODEV));
    }
    Ok(true)
}

/// `1/fps` as a V4L2 fraction (ms resolution), `None` for a bad fps.
fn fps_interval(fps: f64) -> Option<Fract> {
    (fps.is_finite() && fps > 0.0).then(|| Fract::new(1000, (fps * 1000.0).round() as u32))
}

/// The decodable capture formats a device offers, with their description.
fn capture_formats(device: &Device) -> Vec<(PixelFormat, String)> {
    device
        .formats(BufType::VIDEO_CAPTURE)
        .filter_map(Result::ok)
        .filter_map(|d| {
            PixelFormat::from_fourcc(d.pixel_format().as_fourcc())
                .map(|f| (f, d.description().to_string()))
        })
        .collect()
}

fn offered_names(device: &Device) -> String {
    let all: Vec<String> = device
        .formats(BufType::VIDEO_CAPTURE)
        .filter_map(Result::ok)
        .map(|d| format!("{:?}", d.pixel_format()))
        .collect();
    if all.is_empty() {
        "nothing".into()
    } else {
        all.join(", ")
    }
}

/// One capture device as `dexitac cameras` lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// Device node.
    pub path: PathBuf,
    /// The card name (e.g. "DIGIT: DIGIT").
    pub name: String,
    /// USB bus position.
    pub bus: String,
    /// Formats (decodable or not) with their frame sizes (`WxH`, or
    /// `WxH..WxH` for a range).
    pub formats: Vec<(String, Vec<String>)>,
}

/// Every `/dev/video*` node that is a video capture device (UVC cameras
/// also create a metadata node, which is left out), in path order.
pub fn list_cameras() -> Vec<CameraInfo> {
    let Ok(dir) = std::fs::read_dir("/dev") else {
        return Vec::new();
    };
    let mut paths: Vec<PathBuf> = dir
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("video"))
        })
        .collect();
    paths.sort_by_key(|p| {
        let n = p.to_string_lossy();
        let digits: String = n.chars().filter(|c| c.is_ascii_digit()).collect();
        (digits.parse::<u64>().unwrap_or(u64::MAX), n.to_string())
    });
    paths.iter().filter_map(|p| describe(p)).collect()
}

fn describe(path: &Path) -> Option<CameraInfo> {
    let device = Device::open(path).ok()?;
    let caps = device.capabilities().ok()?;
    if !caps
        .device_capabilities()
        .contains(CapabilityFlags::VIDEO_CAPTURE)
    {
        return None;
    }
    let formats = device
        .formats(BufType::VIDEO_CAPTURE)
        .filter_map(Result::ok)
        .map(|d| {
            let pf = d.pixel_format();
            // `linuxvideo` asserts on driver answers it does not expect:
            // a bad driver must not take the listing down.
            let sizes =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| device.frame_sizes(pf)));
            let sizes = match sizes {
                Ok(Ok(linuxvideo::format::FrameSizes::Discrete(v))) => v
                    .iter()
                    .map(|s| format!("{}x{}", s.width(), s.height()))
                    .collect(),
                Ok(Ok(range)) => vec![format!(
                    "{}x{}..{}x{}",
                    range.min_width(),
                    range.min_height(),
                    range.max_width(),
                    range.max_height()
                )],
                _ => Vec::new(),
            };
            (format!("{:?} ({})", pf, d.description()), sizes)
        })
        .collect();
    Some(CameraInfo {
        path: path.to_path_buf(),
        name: caps.card().to_string(),
        bus: caps.bus_info().to_string(),
        formats,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_device_is_not_found_with_its_path() {
        let mut cam = V4l2Device::new(Path::new("/dev/video-dexitac-missing"));
        let e = cam.open(&CaptureRequest::default()).unwrap_err();
        assert!(matches!(e, CameraError::NotFound { .. }), "{e}");
        let msg = e.to_string();
        assert!(msg.contains("/dev/video-dexitac-missing"), "{msg}");
        assert!(msg.contains("no such camera"), "{msg}");
    }

    #[test]
    fn a_non_v4l2_node_is_not_a_capture_device() {
        let mut cam = V4l2Device::new(Path::new("/dev/null"));
        let e = cam.open(&CaptureRequest::default()).unwrap_err();
        assert!(matches!(e, CameraError::NotCapture { .. }), "{e}");
        assert!(e.to_string().contains("not a video capture device"), "{e}");
    }

    #[test]
    fn reading_an_unopened_device_is_disconnected() {
        let mut cam = V4l2Device::new(Path::new("/dev/video-dexitac-missing"));
        let r = cam.next_buffer(&mut Vec::new(), Duration::from_millis(1));
        assert!(matches!(r, Err(CameraError::Disconnected { .. })));
    }

    #[test]
    fn fps_becomes_a_frame_interval() {
        let f = fps_interval(30.0).unwrap();
        assert_eq!((f.numerator(), f.denominator()), (1000, 30_000));
        assert!(fps_interval(f64::NAN).is_none());
        assert!(fps_interval(0.0).is_none());
    }
}
