//! `dexitac cameras`: the V4L2 video capture devices (`/dev/video*`) with
//! name, bus, formats and frame sizes. Exit 0 when it found one, 1 when
//! there is none ("no capture devices found") or on a non-Linux system.

use crate::exit::Outcome;

/// Runs `dexitac cameras`: [`Outcome::Negative`] when there is none.
pub fn run() -> anyhow::Result<Outcome> {
    #[cfg(target_os = "linux")]
    {
        let list = dexitac_rig::camera::v4l2::list_cameras();
        if list.is_empty() {
            tracing::warn!(
                "dexitac cameras: no capture devices found (no /dev/video* video capture node; \
                 is the fingertip plugged in, and may you read /dev/video*?)"
            );
            return Ok(Outcome::Negative);
        }
        for cam in list {
            println!("{}: {} ({})", cam.path.display(), cam.name, cam.bus);
            for (format, sizes) in &cam.formats {
                println!("    {format}: {}", sizes.join(" "));
            }
        }
        Ok(Outcome::Success)
    }
    #[cfg(not(target_os = "linux"))]
    {
        tracing::warn!(
            "dexitac cameras: {}",
            dexitac_rig::camera::CameraError::Unsupported
        );
        Ok(Outcome::Negative)
    }
}
