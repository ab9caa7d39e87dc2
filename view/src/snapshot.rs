//! Headless PNG snapshots of the dashboard, no window needed: one every
//! `every_s` seconds of *event* time (so an accelerated simulation or a
//! replay gives the same pictures as a live run), plus one at the end.
//!
//! Files are `DIR/view_SSSS.SSSs.png`, named by the dashboard's time (they
//! sort in time order).

use std::path::{Path, PathBuf};

use image::RgbImage;

use crate::dashboard::secs_to_ms;
use crate::{Dashboard, ViewError};

/// Snapshot writer.
#[derive(Debug, Clone)]
pub struct Snapshots {
    dir: PathBuf,
    every_ms: u64,
    next_ms: u64,
    last_written_ms: Option<u64>,
    written: Vec<PathBuf>,
}

impl Snapshots {
    /// Snapshots into `dir` (created) every `every_s` s of event time
    /// (finite, at least 0.01 s).
    pub fn new(dir: &Path, every_s: f64) -> Result<Self, ViewError> {
        if !(every_s.is_finite() && every_s >= 0.01) {
            return Err(ViewError::Config(format!(
                "snapshot period {every_s} s: must be at least 0.01 s"
            )));
        }
        std::fs::create_dir_all(dir).map_err(|e| ViewError::Snapshot {
            path: dir.to_path_buf(),
            reason: e.to_string(),
        })?;
        let every_ms = secs_to_ms(every_s).max(10);
        Ok(Snapshots {
            dir: dir.to_path_buf(),
            every_ms,
            next_ms: every_ms,
            last_written_ms: None,
            written: Vec::new(),
        })
    }

    /// Files written so far.
    pub fn written(&self) -> &[PathBuf] {
        &self.written
    }

    /// True when the dashboard's time `now_ms` reached the next snapshot
    /// (then schedules the one after it).
    pub fn due(&mut self, now_ms: Option<u64>) -> bool {
        let Some(now) = now_ms else { return false };
        if now < self.next_ms {
            return false;
        }
        // After a jump in time, the next snapshot is the next multiple.
        self.next_ms = (now / self.every_ms + 1).saturating_mul(self.every_ms);
        true
    }

    /// True unless a snapshot was already written at `now_ms` (the final one).
    pub fn final_due(&self, now_ms: Option<u64>) -> bool {
        self.last_written_ms != Some(now_ms.unwrap_or(0))
    }

    /// Writes `img`, the dashboard rendered at `now_ms`.
    pub fn save(&mut self, img: &RgbImage, now_ms: u64) -> Result<PathBuf, ViewError> {
        let path = self
            .dir
            .join(format!("view_{:08.3}s.png", now_ms as f64 / 1e3));
        img.save(&path).map_err(|e| ViewError::Snapshot {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        self.last_written_ms = Some(now_ms);
        self.written.push(path.clone());
        Ok(path)
    }

    /// Renders and writes a snapshot if one is due; returns its path.
    pub fn after_event(&mut self, dashboard: &Dashboard) -> Result<Option<PathBuf>, ViewError> {
        if !self.due(dashboard.now_ms()) {
            return Ok(None);
        }
        self.save(&dashboard.render(), dashboard.now_ms().unwrap_or(0))
            .map(Some)
    }

    /// Renders and writes the final snapshot (unless one was just written
    /// at this time).
    pub fn finish(&mut self, dashboard: &Dashboard) -> Result<Option<PathBuf>, ViewError> {
        if !self.final_due(dashboard.now_ms()) {
            return Ok(None);
        }
        self.save(&dashboard.render(), dashboard.now_ms().unwrap_or(0))
            .map(Some)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DashboardConfig;
    use dexitac_rig::event::RuntimeEvent;

    #[test]
    fn one_snapshot_per_period_of_event_time_and_one_at_the_end() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut snaps = Snapshots::new(dir.path(), 1.0).expect("snapshots");
        let mut d = Dashboard::new(DashboardConfig::default());
        for t in (0..=3_500).step_by(100) {
            d.apply(&RuntimeEvent::CommandSent {
                t_ms: t,
                msg: dexitac_protocol::HostMsg::SealAll,
                reason: "setup",
                from_frame: None,
            });
            snaps.after_event(&d).expect("write");
        }
        snaps.finish(&d).expect("final");
        let names: Vec<_> = snaps
            .written()
            .iter()
            .map(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .unwrap_or("")
                    .to_string()
            })
            .collect();
        assert_eq!(
            names,
            [
                "view_0001.000s.png",
                "view_0002.000s.png",
                "view_0003.000s.png",
                "view_0003.500s.png"
            ]
        );
        let img = image::open(&snaps.written()[0]).expect("png").into_rgb8();
        assert_eq!(img, {
            // The PNG holds exactly the renderer's pixels (lossless).
            let mut at_1s = Dashboard::new(DashboardConfig::default());
            for t in (0..=1_000).step_by(100) {
                at_1s.apply(&RuntimeEvent::CommandSent {
                    t_ms: t,
                    msg: dexitac_protocol::HostMsg::SealAll,
                    reason: "setup",
                    from_frame: None,
                });
            }
            at_1s.render()
        });
    }

    #[test]
    fn bad_periods_and_directories_are_errors() {
        let dir = tempfile::tempdir().expect("tempdir");
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                Snapshots::new(dir.path(), bad),
                Err(ViewError::Config(_))
            ));
        }
        let file = dir.path().join("a-file");
        std::fs::write(&file, b"x").expect("write");
        assert!(matches!(
            Snapshots::new(&file.join("sub"), 1.0),
            Err(ViewError::Snapshot { .. })
        ));
    }
}
