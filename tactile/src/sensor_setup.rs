//! Sensor setup helpers: tune the marker detector to a skin's known pin
//! count, and check a skin's health against its rest frame.
//!
//! # Tune ([`tune`])
//!
//! Like Bristol's `vsp` tunes its blob detector to the known pin count, the
//! search runs the calibration's detector ([`markers::auto_detector`], then
//! [`markers::detect`]) on the rest frame for each strength threshold
//! (`markers.strength_ratio`, 0.05..=0.95 in steps of 0.05, stopping at
//! the first that finds fewer than the pin count) and counts the markers:
//! first at the configured scale (automatic unless
//! `markers.lobe_px` is set), then at each explicit scale (odd lobes
//! 3..=15). Per scale it takes the middle of the longest run of thresholds
//! that find exactly the pin count (the setting furthest from finding one
//! marker more or less). It stops at the first scale whose run spans at
//! least one step either side, so a config that already works changes
//! least; else it keeps the widest run. When no setting finds the count at
//! the configured `markers.min_contrast`, it also tries other contrasts
//! (2..=24 grey levels). A count is what the calibration with that setting
//! keeps, on a lattice without holes (`confirm`: a setting that counts
//! smeared blobs on a median image of taps to the pin count is not a
//! detector of the pins). Without an exact match it returns the closest
//! count, marked not exact, a setting whose lattice has no holes (and
//! half the pins) first; when every setting leaves holes, the configured
//! one, unchanged.
//!
//! # Health ([`health`])
//!
//! The rest frame is the reference: its calibration gives the rest markers
//! and the pitch. Each checked frame (a current no-contact frame; without
//! any, the rest frame itself) is detected with the same detector and
//! matched to the rest markers within 0.4 pitch:
//!
//! - **missing**: rest markers unmatched in at least half the frames
//!   (fewer: *flickering*);
//! - **merged**: an unmatched detection with two or more missing rest
//!   markers within 0.75 pitch (two pins seen as one blob);
//! - **extra**: other unmatched detections (dirt, reflections, a torn skin);
//! - **damaged**: matched markers whose blob strength is below
//!   [`HealthLimits::weak_fraction`] of the median, or that sit more than
//!   [`HealthLimits::max_offset_pitch`] pitch from their rest position;
//! - **coverage**: the fraction of the sensing area (the calibration mask)
//!   where the frame's marker density stays at or above the contact
//!   threshold (`contact.relative_threshold` x rest density): below it the
//!   pipeline would see a contact where there is none. The worst frame
//!   counts;
//! - **jitter**: with two or more frames, each marker's position standard
//!   deviation across them (camera noise, a loose sensor).
//!
//! The verdict ([`Verdict`]): *fail* when coverage is below
//! [`HealthLimits::min_coverage`] or more than
//! [`HealthLimits::max_missing_fraction`] of the markers are missing;
//! *warn* on any missing, merged, extra, damaged or flickering marker, or a
//! jitter above [`HealthLimits::max_jitter_px`]; else *pass*.

use crate::calibrate::{self, Calibration, CalibrationError};
use crate::density;
use crate::frame::GreyFrame;
use crate::markers::{self, Marker};
use crate::params::{MarkerParams, Params};
use crate::tracking::PointIndex;
use crate::PointPx;

/// Marker scales tried by [`tune`] (odd lobes, working px).
pub const TUNE_LOBES_PX: [u32; 7] = [3, 5, 7, 9, 11, 13, 15];
/// Strength thresholds tried by [`tune`], in steps of 0.05.
pub const TUNE_RATIO_STEPS: std::ops::RangeInclusive<u32> = 1..=19;
/// Marker contrasts tried when the configured one finds no exact count.
pub const TUNE_CONTRASTS: [f32; 6] = [2.0, 4.0, 8.0, 12.0, 16.0, 24.0];

/// Why a setup helper could not run.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// The pin count is not usable.
    #[error("pin count must be at least {min}, got {got}")]
    Pins {
        /// Given.
        got: usize,
        /// Smallest accepted.
        min: usize,
    },
    /// No detector setting finds any marker.
    #[error("no detector setting finds markers on the rest frame")]
    NoMarkers,
    /// The rest frame could not be calibrated.
    #[error("rest frame: {0}")]
    Calibration(#[from] CalibrationError),
    /// A checked frame differs in size from the rest frame.
    #[error("frame {index} is {got_w}x{got_h}, the rest frame {w}x{h}")]
    Size {
        /// Which frame.
        index: usize,
        /// Its width.
        got_w: usize,
        /// Its height.
        got_h: usize,
        /// Rest width.
        w: usize,
        /// Rest height.
        h: usize,
    },
}

/// One detector setting and what it found.
#[derive(Debug, Clone, PartialEq)]
pub struct TuneResult {
    /// The tuned marker parameters (the rest of the config unchanged).
    pub markers: MarkerParams,
    /// Markers found with them.
    pub found: usize,
    /// The pin count asked for.
    pub pins: usize,
    /// True when `found == pins`.
    pub exact: bool,
    /// Strength thresholds around the chosen one that also find `pins`
    /// (the margin): `(lowest, highest)`.
    pub ratio_range: Option<(f32, f32)>,
    /// Settings tried.
    pub tried: usize,
    /// The calibration with these parameters finds holes in the rest's
    /// marker lattice ([`Calibration::holey_rest_warning`]): a pressed
    /// rest, the median image of taps, or a detector that misses pins.
    pub holes: bool,
}

impl TuneResult {
    /// One line for the tuned config's header and the log: what was found
    /// against the pins and against `before` (the base config's count), and
    /// the setting.
    pub fn summary(&self, before: usize) -> String {
        let lobe = self
            .markers
            .lobe_px
            .map_or("auto".into(), |l| l.to_string());
        let margin = self.ratio_range.map_or(String::new(), |(lo, hi)| {
            format!(" (exact for {lo:.2}..={hi:.2})")
        });
        let holes = if self.holes {
            "; the rest's lattice has holes with it"
        } else {
            ""
        };
        format!(
            "{} of {} pins found (the base config found {before}); lobe_px = {lobe}, \
             strength_ratio = {:.2}{margin}, min_contrast = {}; {} settings tried{holes}",
            self.found,
            self.pins,
            self.markers.strength_ratio,
            self.markers.min_contrast,
            self.tried
        )
    }
}

/// Markers found on `rest` with `params` (as the calibration finds them).
pub fn count_markers(rest: &GreyFrame, params: &MarkerParams) -> usize {
    match markers::auto_detector(rest, params) {
        Ok(det) => markers::detect(rest, &det).len(),
        Err(_) => 0,
    }
}

/// Tunes `base.markers` to find `pins` markers on `rest` (see the
/// [module docs](self)).
pub fn tune(rest: &GreyFrame, pins: usize, base: &Params) -> Result<TuneResult, SetupError> {
    if pins < calibrate::MIN_REST_MARKERS {
        return Err(SetupError::Pins {
            got: pins,
            min: calibrate::MIN_REST_MARKERS,
        });
    }
    let mut tried = 0;
    let mut best: Option<TuneResult> = None;
    let mut contrasts = vec![base.markers.min_contrast];
    contrasts.extend(
        TUNE_CONTRASTS
            .iter()
            .filter(|&&c| c != base.markers.min_contrast),
    );
    // The configured scale (automatic unless set) first: when it finds the
    // count with a margin, the config changes as little as possible (and
    // keeps the automatic binning, which the speed depends on).
    let mut lobes = vec![base.markers.lobe_px];
    lobes.extend(
        TUNE_LOBES_PX
            .iter()
            .map(|&l| Some(l))
            .filter(|l| *l != base.markers.lobe_px),
    );
    for (k, &contrast) in contrasts.iter().enumerate() {
        if k > 0 && best.as_ref().is_some_and(|b| b.exact) {
            break;
        }
        for &lobe in &lobes {
            if lobe.is_some_and(|l| 3 * l as usize + 2 >= rest.width().min(rest.height())) {
                continue;
            }
            let params_for = |ratio: f32| MarkerParams {
                lobe_px: lobe,
                strength_ratio: ratio,
                min_contrast: contrast,
                ..base.markers.clone()
            };
            let counts = sweep(|ratio| count_markers(rest, &params_for(ratio)), pins);
            tried += counts.len();
            let candidate = pick(&counts, pins).map(|(ratio, found, range)| TuneResult {
                markers: params_for(ratio),
                found,
                pins,
                exact: found == pins,
                ratio_range: range,
                tried: 0,
                holes: false,
            });
            if let Some(mut c) = candidate {
                if better(&c, best.as_ref()) {
                    confirm(&mut c, rest, base);
                    if better(&c, best.as_ref()) {
                        best = Some(c);
                    }
                }
            }
            if best.as_ref().is_some_and(has_margin) {
                break;
            }
        }
        if best.as_ref().is_some_and(has_margin) {
            break;
        }
    }
    let mut best = best.ok_or(SetupError::NoMarkers)?;
    if !usable(&best) {
        // No setting gives a lattice without holes: the rest itself has
        // them (a pressed rest, the median image of taps), and a count on
        // it says nothing of the pins. The configured detector is kept.
        best = TuneResult {
            markers: base.markers.clone(),
            found: count_markers(rest, &base.markers),
            pins,
            exact: false,
            ratio_range: None,
            tried: 0,
            holes: false,
        };
        confirm(&mut best, rest, base);
    }
    best.tried = tried;
    Ok(best)
}

/// A count must also be what the calibration keeps of it: within
/// [`CONFIRM_TOLERANCE`] of the pins, on a lattice without holes
/// ([`Calibration::holey_rest_warning`]). Otherwise `c` is not exact, its
/// `found` is the calibration's count, and `holes` says whether the
/// lattice has them. Measured: on the median image of the raw-looking
/// TacTip taps (eval/raw_taps.py; the pins under the taps smeared), lobe
/// 15 px counted 331 blobs for 331 pins, of which the calibration kept 57
/// at a pitch of 4.3 px, and the frames were then found to have 82-140
/// markers each.
fn confirm(c: &mut TuneResult, rest: &GreyFrame, base: &Params) {
    let params = Params {
        markers: c.markers.clone(),
        ..base.clone()
    };
    let (kept, holes) = match calibrate::calibrate(std::slice::from_ref(rest), &params) {
        Ok(cal) => (cal.rest_markers.len(), cal.holey_rest_warning().is_some()),
        Err(_) => (0, false),
    };
    c.holes = holes;
    let tolerance = (CONFIRM_TOLERANCE * c.pins as f64).ceil() as usize;
    if holes || kept.abs_diff(c.pins) > tolerance {
        (c.exact, c.found, c.ratio_range) = (false, kept, None);
    }
}

/// How far (a fraction of the pins) the calibration may keep fewer or more
/// markers than the detector counted for an exact [`tune`]: it
/// drops off-lattice blobs (an LED on the rim) the count may include.
pub const CONFIRM_TOLERANCE: f64 = 0.01;

/// A confirmed ([`confirm`]) setting whose calibration finds a lattice
/// without holes and keeps at least half the pins. A setting that keeps a
/// small patch of them can have no holes: on a wiped rest, lobe 11 px at
/// strength 0.05 kept 44 of 757 pins in one corner, without holes.
fn usable(c: &TuneResult) -> bool {
    !c.holes && 2 * c.found >= c.pins
}

/// Step of the strength threshold sweep.
const RATIO_STEP: f32 = 0.05;

/// Counts at rising strength thresholds (`count_at(ratio)`), until the count
/// falls below `pins`: a higher threshold keeps a subset of the markers, so
/// the thresholds after that one only find fewer and are further from the
/// count. A pin count no setting reaches costs one detection per scale
/// instead of the whole sweep.
fn sweep(mut count_at: impl FnMut(f32) -> usize, pins: usize) -> Vec<(f32, usize)> {
    let mut counts = Vec::new();
    for s in TUNE_RATIO_STEPS {
        let ratio = s as f32 * RATIO_STEP;
        let n = count_at(ratio);
        counts.push((ratio, n));
        if n < pins {
            break;
        }
    }
    counts
}

/// Exact, with at least one threshold step to spare on each side.
fn has_margin(r: &TuneResult) -> bool {
    r.exact
        && r.ratio_range
            .is_some_and(|(lo, hi)| hi - lo >= 2.0 * RATIO_STEP - 1e-4)
}

/// A threshold pick: (ratio, markers found, run of exact ratios).
type Pick = (f32, usize, Option<(f32, f32)>);

/// The ratio to use from one scale's sweep: the middle of the longest run
/// that finds exactly `pins`, else the closest count (`None`: nothing found).
fn pick(counts: &[(f32, usize)], pins: usize) -> Option<Pick> {
    let mut best_run: Option<(usize, usize)> = None;
    let mut i = 0;
    while i < counts.len() {
        if counts[i].1 == pins {
            let start = i;
            while i < counts.len() && counts[i].1 == pins {
                i += 1;
            }
            if best_run.is_none_or(|(a, b)| i - start > b - a) {
                best_run = Some((start, i));
            }
        } else {
            i += 1;
        }
    }
    if let Some((a, b)) = best_run {
        let mid = counts[(a + b - 1) / 2].0;
        return Some((mid, pins, Some((counts[a].0, counts[b - 1].0))));
    }
    counts
        .iter()
        .filter(|c| c.1 > 0)
        .min_by_key(|c| c.1.abs_diff(pins))
        .map(|&(r, n)| (r, n, None))
}

/// True when `c` beats `best`: exact before inexact, a [`usable`] one
/// before one that is not, then a wider margin (exact) or a closer count
/// (inexact).
fn better(c: &TuneResult, best: Option<&TuneResult>) -> bool {
    let Some(b) = best else { return true };
    let width = |r: &TuneResult| r.ratio_range.map_or(0.0, |(lo, hi)| hi - lo);
    match (c.exact, b.exact) {
        (true, false) => true,
        (false, true) => false,
        (true, true) => width(c) > width(b) + 1e-6,
        (false, false) if usable(c) != usable(b) => usable(c),
        (false, false) => c.found.abs_diff(c.pins) < b.found.abs_diff(b.pins),
    }
}

/// Writes `params` as a sensor TOML that `dexitac analyze --config` reads
/// back to the same parameters (a mask image itself is not written, only
/// its path: `Params::area_mask` is read from it).
pub fn params_toml(params: &Params, header: &str) -> String {
    let f = &params.frame;
    let m = &params.markers;
    let d = &params.density;
    let c = &params.contact;
    let mut out = String::new();
    for line in header.lines() {
        out.push_str(&format!("# {line}\n"));
    }
    out.push_str("\n[frame]\n");
    out.push_str(&format!("work_width_px = {}\n", f.work_width_px));
    out.push_str(&format!("work_height_px = {}\n", f.work_height_px));
    if let Some([x, y, w, h]) = f.crop_px {
        out.push_str(&format!("crop_px = [{x}, {y}, {w}, {h}]\n"));
    }
    out.push_str(&format!("mm_per_px = {:?}\n", f.mm_per_px));
    out.push_str(&format!("keep_aspect = {}\n", f.keep_aspect));
    let grey = match f.grey {
        crate::params::Grey::Max => "max",
        crate::params::Grey::Luma => "luma",
    };
    out.push_str(&format!("grey = \"{grey}\"\n"));
    if let Some(up) = f.upscale {
        out.push_str(&format!("upscale = {up:?}\n"));
    }
    out.push_str("\n[markers]\n");
    if let Some(l) = m.lobe_px {
        out.push_str(&format!("lobe_px = {l}\n"));
    }
    if let Some(b) = m.binned {
        out.push_str(&format!("binned = {b}\n"));
    }
    out.push_str(&format!("strength_ratio = {:?}\n", m.strength_ratio));
    out.push_str(&format!("min_contrast = {:?}\n", m.min_contrast));
    let polarity = match m.polarity {
        crate::params::Polarity::Auto => "auto",
        crate::params::Polarity::Bright => "bright",
        crate::params::Polarity::Dark => "dark",
    };
    out.push_str(&format!("polarity = \"{polarity}\"\n"));
    out.push_str(&format!("follow = {}\n", m.follow));
    out.push_str(&format!("local_search = {}\n", m.local_search));
    out.push_str("\n[density]\n");
    out.push_str(&format!("kernel_width_px = {:?}\n", d.kernel_width_px));
    let mode = match d.mode {
        crate::params::DensityMode::Exact => "exact",
        crate::params::DensityMode::Fast => "fast",
    };
    out.push_str(&format!("mode = \"{mode}\"\n"));
    out.push_str(&format!("grid_step_px = {}\n", d.grid_step_px));
    out.push_str(&format!("truncate_sigmas = {:?}\n", d.truncate_sigmas));
    let kernel = match d.kernel {
        crate::params::DensityKernel::Image => "image",
        crate::params::DensityKernel::Skin => "skin",
    };
    out.push_str(&format!("kernel = \"{kernel}\"\n"));
    out.push_str("\n[contact]\n");
    let threshold = match c.threshold {
        crate::params::ThresholdMode::Relative => "relative",
        crate::params::ThresholdMode::Absolute => "absolute",
    };
    out.push_str(&format!("threshold = \"{threshold}\"\n"));
    out.push_str(&format!(
        "relative_threshold = {:?}\n",
        c.relative_threshold
    ));
    out.push_str(&format!("relative_extent = {:?}\n", c.relative_extent));
    out.push_str(&format!(
        "absolute_threshold_per_mm2 = {:?}\n",
        c.absolute_threshold_per_mm2
    ));
    out.push_str(&format!("min_area_mm2 = {:?}\n", c.min_area_mm2));
    let centre = match c.centre {
        crate::params::CentreMethod::Density => "density",
        crate::params::CentreMethod::Hybrid => "hybrid",
    };
    out.push_str(&format!("centre = \"{centre}\"\n"));
    out.push_str(&format!("skip_unmoved = {}\n", c.skip_unmoved));
    out.push_str(&format!("move_noise_px = {:?}\n", c.move_noise_px));
    out.push_str(&format!("move_noise_sigmas = {:?}\n", c.move_noise_sigmas));
    out.push_str(&format!("min_moved_markers = {}\n", c.min_moved_markers));
    out.push_str(&area_toml(&params.area));
    out.push_str(&surface_toml(&params.surface));
    out
}

/// The `[area]` table of [`params_toml`] (none for the automatic area). A
/// mask's path is written as the base config gave it: relative to that
/// config's folder.
fn area_toml(area: &crate::area::AreaSpec) -> String {
    use crate::area::AreaSpec;
    let body = match area {
        AreaSpec::Auto => return String::new(),
        AreaSpec::Whole => "shape = \"whole\"\n".to_string(),
        AreaSpec::Circle {
            centre_px,
            radius_px,
        } => format!(
            "shape = \"circle\"\ncentre_px = {}\nradius_px = {radius_px:?}\n",
            toml_pair(*centre_px)
        ),
        AreaSpec::RoundedRect {
            rect_px: [x, y, w, h],
            corner_radius_px,
        } => format!(
            "shape = \"rounded_rect\"\nrect_px = [{x:?}, {y:?}, {w:?}, {h:?}]\n\
             corner_radius_px = {corner_radius_px:?}\n"
        ),
        AreaSpec::Polygon { points_px } => {
            let points: Vec<String> = points_px.iter().map(|&p| toml_pair(p)).collect();
            format!("shape = \"polygon\"\npoints_px = [{}]\n", points.join(", "))
        }
        AreaSpec::Mask { path } => format!(
            "shape = \"mask\"\npath = {}\n",
            toml_string(&path.to_string_lossy())
        ),
    };
    format!("\n[area]\n{body}")
}

/// The `[surface]` table of [`params_toml`] (none for the automatic
/// surface).
fn surface_toml(surface: &crate::surface::SurfaceSpec) -> String {
    use crate::surface::SurfaceSpec;
    match surface {
        SurfaceSpec::Auto => String::new(),
        SurfaceSpec::Flat => "\n[surface]\nshape = \"flat\"\n".to_string(),
        SurfaceSpec::Dome {
            centre_px,
            radius_px,
        } => format!(
            "\n[surface]\nshape = \"dome\"\ncentre_px = {}\nradius_px = {radius_px:?}\n",
            toml_pair(*centre_px)
        ),
    }
}

/// A point `[x, y]` as a TOML array.
fn toml_pair([x, y]: [f64; 2]) -> String {
    format!("[{x:?}, {y:?}]")
}

/// `s` as a TOML basic string.
fn toml_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// Limits of the health verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct HealthLimits {
    /// Fail below this sensing-area coverage (0..=1).
    pub min_coverage: f64,
    /// Fail above this fraction of missing rest markers.
    pub max_missing_fraction: f64,
    /// Warn above this per-marker jitter, px.
    pub max_jitter_px: f64,
    /// A matched marker weaker than this fraction of the median strength is
    /// damaged.
    pub weak_fraction: f64,
    /// A matched marker further than this (in pitches) from its rest
    /// position is damaged (shifted pin, stretched skin).
    pub max_offset_pitch: f64,
}

impl Default for HealthLimits {
    fn default() -> Self {
        HealthLimits {
            min_coverage: 0.98,
            max_missing_fraction: 0.05,
            max_jitter_px: 0.5,
            weak_fraction: 0.5,
            max_offset_pitch: 0.25,
        }
    }
}

/// The health summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Verdict {
    /// Nothing found.
    Pass,
    /// Usable, but look at the listed markers.
    Warn,
    /// The pipeline will see contacts that are not there, or lose too much.
    Fail,
}

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Verdict::Pass => "PASS",
            Verdict::Warn => "WARN",
            Verdict::Fail => "FAIL",
        })
    }
}

/// What [`health`] found. Positions are working px.
#[derive(Debug, Clone, PartialEq)]
pub struct HealthReport {
    /// Rest markers (the reference).
    pub rest_markers: usize,
    /// Rest marker pitch, px.
    pub pitch_px: f64,
    /// Frames checked.
    pub frames: usize,
    /// Rest markers missing in at least half the frames.
    pub missing: Vec<PointPx>,
    /// Rest markers missing in some frames, fewer than half.
    pub flickering: Vec<PointPx>,
    /// Detections standing for two or more missing rest markers.
    pub merged: Vec<PointPx>,
    /// Other detections with no rest marker.
    pub extra: Vec<PointPx>,
    /// Weak or shifted markers (rest positions).
    pub damaged: Vec<PointPx>,
    /// Worst frame's fraction of the sensing area at or above the contact
    /// threshold.
    pub coverage: f64,
    /// Median and largest per-marker jitter across the frames, px (`None`
    /// with fewer than two frames).
    pub jitter_px: Option<(f64, f64)>,
    /// The verdict.
    pub verdict: Verdict,
    /// Why the verdict is not a pass, one reason per line.
    pub reasons: Vec<String>,
}

/// Checks frames against the rest frame (see the [module docs](self)).
/// `frames` empty: the rest frame is checked against itself (only damaged
/// markers and, with `pins`, the count can show).
pub fn health(
    rest: &GreyFrame,
    frames: &[GreyFrame],
    params: &Params,
    limits: &HealthLimits,
    pins: Option<usize>,
) -> Result<HealthReport, SetupError> {
    let cal = calibrate::calibrate(std::slice::from_ref(rest), params)?;
    let checked: Vec<&GreyFrame> = if frames.is_empty() {
        vec![rest]
    } else {
        frames.iter().collect()
    };
    for (index, f) in checked.iter().enumerate() {
        if (f.width(), f.height()) != (cal.width, cal.height) {
            return Err(SetupError::Size {
                index,
                got_w: f.width(),
                got_h: f.height(),
                w: cal.width,
                h: cal.height,
            });
        }
    }
    let n_rest = cal.rest_markers.len();
    let match_px = 0.4 * cal.pitch_px;
    let mut missed = vec![0usize; n_rest];
    let mut positions: Vec<Vec<PointPx>> = vec![Vec::new(); n_rest];
    let mut strengths: Vec<Vec<f32>> = vec![Vec::new(); n_rest];
    let mut unmatched: Vec<PointPx> = Vec::new();
    let mut coverage = 1.0f64;
    for f in &checked {
        let found = markers::detect(f, &cal.detector);
        let (matches, extra) = match_to_rest(&cal, &found.list, match_px);
        for (k, m) in matches.iter().enumerate() {
            match m {
                Some(m) => {
                    positions[k].push(m.pos);
                    strengths[k].push(m.strength);
                }
                None => missed[k] += 1,
            }
        }
        unmatched.extend(extra);
        coverage = coverage.min(area_coverage(&cal, &found.positions(), params));
    }
    let n_frames = checked.len();
    let at = |k: usize| cal.rest_markers[k];
    let missing: Vec<usize> = (0..n_rest).filter(|&k| 2 * missed[k] >= n_frames).collect();
    let flickering: Vec<PointPx> = (0..n_rest)
        .filter(|&k| missed[k] > 0 && 2 * missed[k] < n_frames)
        .map(at)
        .collect();
    let (merged, extra) = split_merged(&cal, &missing, &unmatched);
    let damaged = damaged_markers(&cal, &positions, &strengths, limits);
    let jitter_px = jitter(&positions, n_frames);
    let mut report = HealthReport {
        rest_markers: n_rest,
        pitch_px: cal.pitch_px,
        frames: n_frames,
        missing: missing.iter().map(|&k| at(k)).collect(),
        flickering,
        merged,
        extra,
        damaged,
        coverage,
        jitter_px,
        verdict: Verdict::Pass,
        reasons: Vec::new(),
    };
    judge(&mut report, limits, pins);
    Ok(report)
}

/// Each rest marker's detection (nearest within `radius`, each detection
/// used once), and the detections left over.
fn match_to_rest(
    cal: &Calibration,
    found: &[Marker],
    radius: f64,
) -> (Vec<Option<Marker>>, Vec<PointPx>) {
    let pos: Vec<PointPx> = found.iter().map(|m| m.pos).collect();
    let index = PointIndex::new(&pos, cal.width, cal.height, radius.max(1.0));
    let mut used = vec![false; found.len()];
    let mut out = vec![None; cal.rest_markers.len()];
    for (k, r) in cal.rest_markers.iter().enumerate() {
        if let Some((i, _)) = index.nearest(&pos, *r, radius) {
            if !used[i] {
                used[i] = true;
                out[k] = Some(found[i]);
            }
        }
    }
    let extra = pos
        .iter()
        .zip(&used)
        .filter(|(_, u)| !**u)
        .map(|(p, _)| *p)
        .collect();
    (out, extra)
}

/// Unmatched detections near two or more missing rest markers are merged
/// blobs (each reported once, across frames); the rest are extra.
fn split_merged(
    cal: &Calibration,
    missing: &[usize],
    unmatched: &[PointPx],
) -> (Vec<PointPx>, Vec<PointPx>) {
    let near = 0.75 * cal.pitch_px;
    let mut merged: Vec<PointPx> = Vec::new();
    let mut extra: Vec<PointPx> = Vec::new();
    for &p in unmatched {
        let n = missing
            .iter()
            .filter(|&&k| distance(cal.rest_markers[k], p) <= near)
            .count();
        let list = if n >= 2 { &mut merged } else { &mut extra };
        // The same blob seen in several frames counts once.
        if !list.iter().any(|q| distance(*q, p) < 0.3 * cal.pitch_px) {
            list.push(p);
        }
    }
    (merged, extra)
}

fn damaged_markers(
    cal: &Calibration,
    positions: &[Vec<PointPx>],
    strengths: &[Vec<f32>],
    limits: &HealthLimits,
) -> Vec<PointPx> {
    let mut all: Vec<f32> = strengths.iter().flatten().copied().collect();
    if all.is_empty() {
        return Vec::new();
    }
    all.sort_by(f32::total_cmp);
    let median = all[all.len() / 2] as f64;
    (0..cal.rest_markers.len())
        .filter(|&k| {
            let Some(mean_s) = mean(strengths[k].iter().map(|&s| s as f64)) else {
                return false;
            };
            let weak = mean_s < limits.weak_fraction * median;
            let n = positions[k].len() as f64;
            let c = positions[k].iter().fold(PointPx::new(0.0, 0.0), |a, p| {
                PointPx::new(a.x + p.x / n, a.y + p.y / n)
            });
            let shifted = distance(c, cal.rest_markers[k]) > limits.max_offset_pitch * cal.pitch_px;
            weak || shifted
        })
        .map(|k| cal.rest_markers[k])
        .collect()
}

/// Median and largest per-marker position standard deviation, over markers
/// seen in every frame (needs two frames).
fn jitter(positions: &[Vec<PointPx>], n_frames: usize) -> Option<(f64, f64)> {
    if n_frames < 2 {
        return None;
    }
    let mut sd: Vec<f64> = positions
        .iter()
        .filter(|p| p.len() == n_frames)
        .map(|p| {
            let n = p.len() as f64;
            let (mx, my) = (
                p.iter().map(|q| q.x).sum::<f64>() / n,
                p.iter().map(|q| q.y).sum::<f64>() / n,
            );
            (p.iter()
                .map(|q| (q.x - mx).powi(2) + (q.y - my).powi(2))
                .sum::<f64>()
                / (n - 1.0))
                .sqrt()
        })
        .collect();
    if sd.is_empty() {
        return None;
    }
    sd.sort_by(f64::total_cmp);
    Some((sd[sd.len() / 2], sd[sd.len() - 1]))
}

/// Fraction of the calibration mask where the density of `found` is at or
/// above the contact threshold.
fn area_coverage(cal: &Calibration, found: &[PointPx], params: &Params) -> f64 {
    let map = density::estimate(found, &cal.density, None);
    let t = params.contact.relative_threshold as f32;
    let (mut inside, mut ok) = (0usize, 0usize);
    for (k, &m) in cal.mask.iter().enumerate() {
        if m {
            inside += 1;
            if map.values_per_mm2[k] >= t * cal.rest_density.values_per_mm2[k] {
                ok += 1;
            }
        }
    }
    if inside == 0 {
        1.0
    } else {
        ok as f64 / inside as f64
    }
}

fn judge(r: &mut HealthReport, limits: &HealthLimits, pins: Option<usize>) {
    let mut fail = Vec::new();
    let mut warn = Vec::new();
    if r.coverage < limits.min_coverage {
        fail.push(format!(
            "coverage {:.1} % of the sensing area is below {:.1} %: the pipeline sees contacts where markers are missing",
            100.0 * r.coverage,
            100.0 * limits.min_coverage
        ));
    }
    let missing_fraction = r.missing.len() as f64 / r.rest_markers.max(1) as f64;
    if missing_fraction > limits.max_missing_fraction {
        fail.push(format!(
            "{} of {} markers missing ({:.1} % > {:.1} %)",
            r.missing.len(),
            r.rest_markers,
            100.0 * missing_fraction,
            100.0 * limits.max_missing_fraction
        ));
    } else if !r.missing.is_empty() {
        warn.push(format!("{} marker(s) missing", r.missing.len()));
    }
    if let Some(p) = pins {
        if p != r.rest_markers {
            warn.push(format!(
                "the rest frame shows {} markers, the skin has {p} pins (`dexitac sensor tune`)",
                r.rest_markers
            ));
        }
    }
    for (list, what) in [
        (&r.merged, "merged marker(s)"),
        (&r.extra, "extra detection(s)"),
        (&r.damaged, "damaged (weak or shifted) marker(s)"),
        (&r.flickering, "flickering marker(s)"),
    ] {
        if !list.is_empty() {
            warn.push(format!("{} {what}", list.len()));
        }
    }
    if let Some((_, max)) = r.jitter_px {
        if max > limits.max_jitter_px {
            warn.push(format!(
                "marker jitter up to {max:.2} px (> {:.2} px)",
                limits.max_jitter_px
            ));
        }
    }
    r.verdict = if !fail.is_empty() {
        Verdict::Fail
    } else if !warn.is_empty() {
        Verdict::Warn
    } else {
        Verdict::Pass
    };
    r.reasons = fail.into_iter().chain(warn).collect();
}

fn distance(a: PointPx, b: PointPx) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    (n > 0).then(|| s / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tune_summary_names_the_counts_and_the_setting() {
        let markers = MarkerParams {
            lobe_px: Some(7),
            strength_ratio: 0.35,
            min_contrast: 8.0,
            ..MarkerParams::default()
        };
        let r = TuneResult {
            markers,
            found: 331,
            pins: 331,
            exact: true,
            ratio_range: Some((0.3, 0.45)),
            tried: 12,
            holes: false,
        };
        assert_eq!(
            r.summary(325),
            "331 of 331 pins found (the base config found 325); lobe_px = 7, \
             strength_ratio = 0.35 (exact for 0.30..=0.45), min_contrast = 8; 12 settings tried"
        );
        let auto = TuneResult {
            markers: MarkerParams::default(),
            ratio_range: None,
            ..r
        };
        assert!(auto.summary(0).contains("lobe_px = auto, strength_ratio"));
    }
    use crate::synth::{render, rest_frame, Scene, SensorSpec};

    fn sensor() -> SensorSpec {
        SensorSpec::nominal(640, 480)
    }

    fn frame_with_dropout(dropout: f64, seed: u64) -> crate::synth::SynthFrame {
        render(&Scene {
            sensor: sensor(),
            presses: vec![],
            dropout,
            seed,
        })
    }

    #[test]
    fn tune_finds_the_pin_count_of_a_synthetic_skin() {
        let rest = rest_frame(&sensor(), 1);
        let pins = rest.markers.len();
        // Start from a threshold that finds too few markers.
        let mut base = Params::default();
        base.markers.strength_ratio = 0.95;
        base.markers.min_contrast = 120.0;
        assert!(count_markers(&rest.image, &base.markers) < pins);
        let r = tune(&rest.image, pins, &base).unwrap();
        assert!(r.exact, "{r:?}");
        assert_eq!(count_markers(&rest.image, &r.markers), pins);
        let (lo, hi) = r.ratio_range.unwrap();
        assert!(lo <= r.markers.strength_ratio && r.markers.strength_ratio <= hi);
    }

    /// `frame` with its pins wiped from a disc of 4 pitches in the middle
    /// (as a median image of taps smears them), the skin's grey there.
    fn wiped(frame: &GreyFrame) -> GreyFrame {
        let mut data = frame.data().to_vec();
        let mut sorted = data.clone();
        sorted.sort_unstable();
        let skin = sorted[sorted.len() / 10];
        let w = frame.width();
        for (k, v) in data.iter_mut().enumerate() {
            let (x, y) = ((k % w) as f64, (k / w) as f64);
            if (x - 320.0).hypot(y - 240.0) < 60.0 {
                *v = skin;
            }
        }
        GreyFrame::new(w, frame.height(), data).unwrap()
    }

    #[test]
    fn an_exact_count_on_a_lattice_with_holes_is_not_confirmed() {
        let rest = rest_frame(&sensor(), 1);
        let base = Params::default();
        let pins = count_markers(&rest.image, &base.markers);
        let claimed = |markers: &MarkerParams| TuneResult {
            markers: markers.clone(),
            found: pins,
            pins,
            exact: true,
            ratio_range: Some((0.3, 0.5)),
            tried: 1,
            holes: false,
        };
        // The intact rest: the calibration keeps the count.
        let mut c = claimed(&base.markers);
        confirm(&mut c, &rest.image, &base);
        assert!(c.exact, "{c:?}");
        // Whatever a detector counted on a rest with a hole, the lattice has it.
        let holey = wiped(&rest.image);
        let mut c = claimed(&base.markers);
        confirm(&mut c, &holey, &base);
        assert!(!c.exact && c.holes, "{c:?}");
        assert!(c.found < pins && c.ratio_range.is_none(), "{c:?}");
    }

    #[test]
    fn a_rest_with_a_hole_keeps_the_configured_detector() {
        let rest = rest_frame(&sensor(), 1);
        let base = Params::default();
        let pins = count_markers(&rest.image, &base.markers);
        let r = tune(&wiped(&rest.image), pins, &base).unwrap();
        assert!(!r.exact && r.holes, "{r:?}");
        assert_eq!(r.markers, base.markers);
        assert!(r.found < pins, "{r:?}");
    }

    #[test]
    fn tune_keeps_a_config_that_already_finds_the_pins() {
        let rest = rest_frame(&sensor(), 1);
        let base = Params::default();
        let pins = count_markers(&rest.image, &base.markers);
        let r = tune(&rest.image, pins, &base).unwrap();
        assert!(r.exact);
        assert_eq!(r.markers.lobe_px, None, "the automatic scale was replaced");
        // One sweep, at the configured scale, up to the first threshold
        // that finds fewer.
        let one_sweep = TUNE_RATIO_STEPS
            .map(|s| {
                let markers = MarkerParams {
                    strength_ratio: s as f32 * RATIO_STEP,
                    ..base.markers.clone()
                };
                count_markers(&rest.image, &markers)
            })
            .position(|n| n < pins)
            .map_or(TUNE_RATIO_STEPS.count(), |k| k + 1);
        assert_eq!(r.tried, one_sweep, "{r:?}");
    }

    #[test]
    fn the_sweep_stops_at_the_first_count_below_the_pins() {
        // Counts falling with the threshold: 120 at 0.05, 10 fewer per step.
        let mut asked = 0;
        let counts = sweep(
            |ratio| {
                asked += 1;
                120 - (10.0 * (ratio / RATIO_STEP - 1.0)).round() as usize
            },
            95,
        );
        let found: Vec<usize> = counts.iter().map(|c| c.1).collect();
        assert_eq!(found, [120, 110, 100, 90]);
        assert_eq!(asked, 4);
        // A count no threshold reaches: one detection.
        assert_eq!(sweep(|_| 50, 5000), [(RATIO_STEP, 50)]);
        // A count every threshold reaches: the whole sweep.
        assert_eq!(sweep(|_| 50, 10).len(), TUNE_RATIO_STEPS.count());
    }

    #[test]
    fn tune_reports_the_closest_count_when_none_is_exact() {
        let rest = rest_frame(&sensor(), 1);
        let pins = rest.markers.len() + 200;
        let r = tune(&rest.image, pins, &Params::default()).unwrap();
        assert!(!r.exact);
        assert!(r.found < pins && r.found > 0);
        assert!(matches!(
            tune(&rest.image, 3, &Params::default()),
            Err(SetupError::Pins { .. })
        ));
    }

    #[test]
    fn tuned_config_reads_back_to_the_same_params() {
        let mut p = Params::default();
        p.markers.lobe_px = Some(7);
        p.markers.strength_ratio = 0.35;
        p.markers.min_contrast = 4.0;
        p.frame.crop_px = Some([10, 20, 600, 440]);
        p.markers.binned = Some(false);
        p.frame.keep_aspect = false;
        p.frame.grey = crate::params::Grey::Luma;
        p.frame.upscale = Some(1.5);
        p.markers.polarity = crate::params::Polarity::Dark;
        p.markers.follow = false;
        p.markers.local_search = false;
        p.density.kernel = crate::params::DensityKernel::Skin;
        p.contact.move_noise_sigmas = 5.0;
        p.surface = crate::surface::SurfaceSpec::Dome {
            centre_px: [320.5, 240.0],
            radius_px: 264.0,
        };
        let text = params_toml(&p, "tuned by a test\nsecond line");
        assert_eq!(Params::from_toml_str(&text).unwrap(), p, "{text}");
        // Every sensing area and a flat skin.
        use crate::area::AreaSpec;
        for area in [
            AreaSpec::Whole,
            AreaSpec::Circle {
                centre_px: [320.0, 240.5],
                radius_px: 200.0,
            },
            AreaSpec::RoundedRect {
                rect_px: [100.0, 60.0, 440.0, 360.0],
                corner_radius_px: 40.0,
            },
            AreaSpec::Polygon {
                points_px: vec![[100.0, 60.0], [540.0, 60.0], [320.0, 420.0]],
            },
            AreaSpec::Mask {
                path: "masks/a \"b\" \\ c.png".into(),
            },
        ] {
            p.area = area;
            p.surface = crate::surface::SurfaceSpec::Flat;
            let text = params_toml(&p, "");
            assert_eq!(Params::from_toml_str(&text).unwrap(), p, "{text}");
        }
        let d = Params::default();
        assert_eq!(Params::from_toml_str(&params_toml(&d, "")).unwrap(), d);
    }

    #[test]
    fn a_healthy_skin_passes() {
        let rest = rest_frame(&sensor(), 1).image;
        let frames: Vec<GreyFrame> = (2..5).map(|s| rest_frame(&sensor(), s).image).collect();
        let r = health(
            &rest,
            &frames,
            &Params::default(),
            &HealthLimits::default(),
            None,
        )
        .unwrap();
        assert_eq!(r.verdict, Verdict::Pass, "{:?}", r.reasons);
        assert!(r.coverage > 0.999);
        let (median, max) = r.jitter_px.unwrap();
        assert!(median < 0.2 && max < 0.5, "{median} {max}");
    }

    #[test]
    fn dropped_markers_are_reported_missing() {
        let rest = rest_frame(&sensor(), 1);
        let f = frame_with_dropout(0.03, 9);
        let dropped = rest.markers.len() - f.markers.len();
        assert!(dropped >= 5, "{dropped}");
        let r = health(
            &rest.image,
            std::slice::from_ref(&f.image),
            &Params::default(),
            &HealthLimits::default(),
            None,
        )
        .unwrap();
        // Markers at the outline may be missed by the calibration too:
        // allow a few either way, but the count must follow the dropout.
        assert!(
            r.missing.len().abs_diff(dropped) <= 2,
            "{} missing reported, {dropped} dropped",
            r.missing.len()
        );
        assert_ne!(r.verdict, Verdict::Pass);
        // Many missing markers: the sensing area has holes.
        let f = frame_with_dropout(0.25, 4);
        let r = health(
            &rest.image,
            std::slice::from_ref(&f.image),
            &Params::default(),
            &HealthLimits::default(),
            None,
        )
        .unwrap();
        assert_eq!(r.verdict, Verdict::Fail, "{:?}", r.reasons);
        assert!(r.coverage < 0.98, "{}", r.coverage);
    }

    /// Adds an elliptic Gaussian blob (`amplitude` over the skin) at `c`, long axis
    /// along `(ux, uy)`, after erasing the pixels within `erase_px` of
    /// each point of `erase` to the skin level.
    fn paint_blob(
        frame: &GreyFrame,
        c: PointPx,
        (ux, uy): (f64, f64),
        (sigma_along, sigma_across): (f64, f64),
        amplitude: f64,
        erase: &[PointPx],
        erase_px: f64,
    ) -> GreyFrame {
        let (w, h) = (frame.width(), frame.height());
        let mut data = frame.data().to_vec();
        for y in 0..h {
            for x in 0..w {
                let p = PointPx::new(x as f64, y as f64);
                let v = &mut data[y * w + x];
                if erase.iter().any(|e| distance(*e, p) <= erase_px) {
                    *v = 25;
                }
                let (dx, dy) = (p.x - c.x, p.y - c.y);
                let along = dx * ux + dy * uy;
                let across = -dx * uy + dy * ux;
                let g = (-(along / sigma_along).powi(2) / 2.0
                    - (across / sigma_across).powi(2) / 2.0)
                    .exp();
                *v = (*v as f64).max(25.0 + amplitude * g).round().min(255.0) as u8;
            }
        }
        GreyFrame::new(w, h, data).unwrap()
    }

    #[test]
    fn merged_markers_are_reported() {
        let rest = rest_frame(&sensor(), 1);
        let centre = PointPx::new(320.0, 240.0);
        let near = |p: &PointPx| distance(*p, centre);
        let mut ms = rest.rest_markers.clone();
        ms.sort_by(|p, q| near(p).total_cmp(&near(q)));
        let a = ms[0];
        let b = *ms[1..]
            .iter()
            .min_by(|p, q| distance(**p, a).total_cmp(&distance(**q, a)))
            .unwrap();
        let mid = PointPx::new((a.x + b.x) / 2.0, (a.y + b.y) / 2.0);
        let len = distance(a, b);
        // Two pins seen as one elongated blob between them.
        let merged = paint_blob(
            &rest_frame(&sensor(), 2).image,
            mid,
            ((b.x - a.x) / len, (b.y - a.y) / len),
            (len / 2.0, 2.5),
            170.0,
            &[a, b],
            6.0,
        );
        let r = health(
            &rest.image,
            &[merged],
            &Params::default(),
            &HealthLimits::default(),
            None,
        )
        .unwrap();
        assert_eq!(r.missing.len(), 2, "{r:?}");
        assert_eq!(
            r.merged.len(),
            1,
            "merged {:?}, extra {:?}",
            r.merged,
            r.extra
        );
        assert!(distance(r.merged[0], mid) < 3.0);
        assert!(r.extra.is_empty());
        assert_eq!(r.verdict, Verdict::Warn, "{:?}", r.reasons);
    }

    #[test]
    fn specks_outside_the_sensing_area_are_dropped_and_wrong_pin_counts_warn() {
        let rest = rest_frame(&sensor(), 1);
        // A marker-like speck (dirt, a reflection) outside the round skin
        // but inside the detector's search window: the sensing area found
        // from the rest lattice drops it.
        let speck = PointPx::new(150.0, 70.0);
        assert!(distance(speck, PointPx::new(319.5, 239.5)) > 230.0);
        let frame = paint_blob(
            &rest_frame(&sensor(), 3).image,
            speck,
            (1.0, 0.0),
            (2.5, 2.5),
            170.0,
            &[],
            0.0,
        );
        let pins = rest.markers.len() + 3;
        let r = health(
            &rest.image,
            &[frame],
            &Params::default(),
            &HealthLimits::default(),
            Some(pins),
        )
        .unwrap();
        assert!(r.extra.is_empty(), "{r:?}");
        assert!(r.missing.is_empty() && r.merged.is_empty());
        assert_eq!(r.verdict, Verdict::Warn);
        assert!(
            r.reasons.iter().any(|s| s.contains("pins")),
            "{:?}",
            r.reasons
        );
    }

    /// The rest marker nearest to `p`.
    fn nearest_marker(rest: &crate::synth::SynthFrame, p: PointPx) -> PointPx {
        *rest
            .rest_markers
            .iter()
            .min_by(|a, b| distance(**a, p).total_cmp(&distance(**b, p)))
            .unwrap()
    }

    #[test]
    fn shifted_and_faded_markers_are_damaged() {
        let rest = rest_frame(&sensor(), 1);
        let a = nearest_marker(&rest, PointPx::new(300.0, 200.0));
        let b = nearest_marker(&rest, PointPx::new(360.0, 280.0));
        // Marker a sits 4.5 px (0.3 pitch) off its rest place; marker b
        // shows at 40 % of its contrast.
        let shifted_to = PointPx::new(a.x + 4.5, a.y);
        let frame = rest_frame(&sensor(), 2).image;
        let frame = paint_blob(&frame, shifted_to, (1.0, 0.0), (2.5, 2.5), 170.0, &[a], 6.0);
        let frame = paint_blob(&frame, b, (1.0, 0.0), (2.5, 2.5), 0.4 * 170.0, &[b], 6.0);
        let r = health(
            &rest.image,
            &[frame],
            &Params::default(),
            &HealthLimits::default(),
            None,
        )
        .unwrap();
        assert_eq!(r.damaged.len(), 2, "{r:?}");
        for m in [a, b] {
            assert!(
                r.damaged.iter().any(|d| distance(*d, m) < 1.0),
                "{m:?} not in {:?}",
                r.damaged
            );
        }
        assert!(r.missing.is_empty() && r.extra.is_empty());
        assert_eq!(r.verdict, Verdict::Warn);
    }

    #[test]
    fn frames_of_another_size_are_an_error() {
        let rest = rest_frame(&sensor(), 1).image;
        let small = rest_frame(&SensorSpec::nominal(320, 240), 1).image;
        let e = health(
            &rest,
            &[small],
            &Params::default(),
            &HealthLimits::default(),
            None,
        );
        assert!(matches!(e, Err(SetupError::Size { .. })));
    }
}
