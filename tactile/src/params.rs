//! The paper's constants in one place, and the run-time tunable [`Params`].
//!
//! Every constant names the section of the DexiTac paper (or of
//! `shared/SPEC.md`) it comes from; deviations from the paper are explained
//! next to the constant. [`Params::default`] is built from these constants
//! only, and a sensor's TOML file (`dexitac analyze --config SENSOR.toml`)
//! overrides any subset of fields:
//!
//! ```
//! let params = dexitac_tactile::params::Params::from_toml_str(
//!     "[density]\nkernel_width_px = 12.0\n[contact]\nthreshold = \"absolute\"\n",
//! )
//! .unwrap();
//! assert_eq!(params.density.kernel_width_px, 12.0);
//! assert_eq!(params.frame.work_width_px, 640);
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::area::{AreaSpec, MaskImage};
use crate::surface::SurfaceSpec;

/// Working frame width (Sec. III-B: "grayscale images of dimension 640x480").
pub const WORK_WIDTH_PX: u32 = 640;
/// Working frame height (Sec. III-B).
pub const WORK_HEIGHT_PX: u32 = 480;
/// Gaussian kernel width h (Sec. III-B, Eq. 1: "h ... equal to 15 pixels
/// which is the mean distance between adjacent markers").
pub const KERNEL_WIDTH_PX: f64 = 15.0;
/// Absolute contact threshold T on the marker density (Sec. III-B, Eq. 2:
/// T = 0.3 /mm^2). The paper's Eq. 1 prefactor 1/(M sqrt(2 pi) h^2) is not a
/// normalised 2-D Gaussian and its 1/M makes an absolute threshold depend on
/// the marker count; we use the normalised 2-D Gaussian 1/(2 pi h^2) and
/// report markers per mm^2 (SPEC section 3), so T keeps its unit.
pub const ABSOLUTE_THRESHOLD_PER_MM2: f64 = 0.3;
/// Relative contact threshold: a pixel is in contact where the density is
/// below this fraction of the rest (no-contact) density at that pixel. Not in
/// the paper (SPEC section 3): unlike any absolute level it does not trip on
/// the density fall-off at the sensor rim. One missing marker drops the local
/// density to about 0.86 of rest, two adjacent ones to about 0.75; a lone
/// dropout does not open the density stages (they run only when some marker
/// moved strongly, [`crate::contact::worth_a_look`]). Was 0.75 until session
/// 13; 0.80 with [`RELATIVE_EXTENT`] measured (BENCHMARKS.md, "After session
/// 13"): a flat punch 4-6 mm wide dents the density only in a ring that
/// reaches 0.73-0.78, which 0.75 missed or cut into arcs (another renderer's
/// large contacts: 18 of 22 found, p95 37 px; now 22 of 22, 5.4 px), and the
/// real cr TacTip taps are found on 92 % of the frames instead of 84 %.
pub const RELATIVE_THRESHOLD: f64 = 0.80;
/// A contact region grows from its samples below [`RELATIVE_THRESHOLD`]
/// through the connected samples below this fraction of the rest density
/// (hysteresis, as in Canny's edge linking), and its centroid weighs each
/// sample by how far it lies below this level. A shallow ring or a dent
/// whose floor ripples around the threshold stays one region. Tried 0.85,
/// 0.90 and 0.95 (BENCHMARKS.md, "After session 13").
pub const RELATIVE_EXTENT: f64 = 0.90;
/// Sensor scale, mm per working pixel. Not given in the paper; 0.1 mm/px puts
/// the rest density of a 15 px hex grid at 0.51 markers/mm^2, so the paper's
/// T = 0.3 /mm^2 sits at 0.58 of rest. Set it per sensor in the config.
pub const MM_PER_PX: f64 = 0.1;
/// Marker pitch of the DigiTac skin, px (Sec. III-B: 15 px between adjacent
/// markers). Used for matching markers against the rest frame.
pub const MARKER_PITCH_PX: f64 = 15.0;

/// Largest [`FrameParams::upscale`].
pub const MAX_UPSCALE: f64 = 8.0;
/// Floor of the "marker moved" test, px. Not in the paper: below the
/// jitter of a marker centroid at 640x480 under strong noise (about 0.05 px
/// per axis at noise sigma 5) times [`MOVE_NOISE_SIGMAS`], it only matters on
/// a very quiet sensor, where it keeps sub-0.1 px centroid bias from
/// counting (BENCHMARKS.md, tactile pipeline).
pub const MOVE_NOISE_FLOOR_PX: f64 = 0.1;
/// A marker moved when its displacement exceeds this many sigmas of the
/// frame's own marker jitter (`tracking::track_adaptive`). Not in the paper;
/// 6 sigma keeps the expected number of noise-only "moved" markers per frame
/// (~700 markers) near 1e-5 for Gaussian jitter.
pub const MOVE_NOISE_SIGMAS: f64 = 6.0;

/// Error loading or validating a [`Params`] configuration.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    /// The config file could not be read.
    #[error("cannot read config {path}: {source}")]
    Io {
        /// The file that failed.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The config is not valid TOML or has unknown / mistyped fields.
    #[error("invalid config: {0}")]
    Parse(#[from] toml::de::Error),
    /// A field has a value outside its allowed range.
    #[error("invalid config value {field} = {value}: {reason}")]
    Invalid {
        /// Dotted field name, e.g. `density.kernel_width_px`.
        field: &'static str,
        /// The offending value, formatted.
        value: String,
        /// What is allowed.
        reason: &'static str,
    },
}

/// All run-time tunables of the tactile pipeline.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Frame preparation.
    pub frame: FrameParams,
    /// Marker detection.
    pub markers: MarkerParams,
    /// Kernel density.
    pub density: DensityParams,
    /// Contact segmentation and tracking.
    pub contact: ContactParams,
    /// The sensing area (`[area]`, input px); automatic by default.
    pub area: AreaSpec,
    /// The skin's shape (`[surface]`, input px); estimated by default.
    pub surface: SurfaceSpec,
    /// The decoded mask image of an `[area] shape = "mask"` config, filled
    /// by whoever reads the config file (this crate reads no images).
    #[serde(skip)]
    pub area_mask: Option<MaskImage>,
}

/// Frame preparation parameters (stage 1).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FrameParams {
    /// Working width after crop/rescale, px.
    pub work_width_px: u32,
    /// Working height after crop/rescale, px.
    pub work_height_px: u32,
    /// Optional crop rectangle `[x, y, width, height]` in input pixels,
    /// applied before the rescale.
    pub crop_px: Option<[u32; 4]>,
    /// Sensor scale, mm per working pixel.
    pub mm_per_px: f64,
    /// Keep the input's (or the crop's) aspect ratio: the working frame has
    /// that ratio, scaled down (never up) to fit in `work_width_px x
    /// work_height_px`. `false` stretches to exactly that size.
    pub keep_aspect: bool,
    /// How a colour frame becomes grey ([`Grey`]).
    pub grey: Grey,
    /// Magnification of the working frame over the fitted size, 1..=8
    /// (linear interpolation): for pins too small for the detector, about
    /// [`crate::calibrate::MIN_WORKING_PITCH_PX`] apart or less (a 320x240
    /// camera on a dense TacTip). `mm_per_px` is per working pixel, after
    /// it. Unset (`None`, the default): `dexitac analyze` and the Python
    /// package pick it when the rest's pins are that close
    /// ([`crate::calibrate::upscale_for`]), and the camera loop works at 1;
    /// set, it is fixed (1: never magnify, the faster frame; BENCHMARKS.md,
    /// session 35, for what the magnification buys).
    pub upscale: Option<f64>,
}

/// How a colour frame becomes grey ([`crate::frame::to_grey`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Grey {
    /// The brightest of R, G and B: a pin is as bright as its brightest
    /// channel, whatever its colour (blue pins among white ones lose half
    /// their contrast in luma), and a dark dot stays dark on a gel lit in
    /// any colour. Measured on another renderer's blue and white pins
    /// (BENCHMARKS.md): luma missed 84 of 318 blue pins on the rest.
    #[default]
    Max,
    /// BT.601 luma `(77 R + 150 G + 29 B) / 256`, what a camera's Y plane
    /// holds.
    Luma,
}

impl Default for FrameParams {
    fn default() -> Self {
        Self {
            work_width_px: WORK_WIDTH_PX,
            work_height_px: WORK_HEIGHT_PX,
            crop_px: None,
            mm_per_px: MM_PER_PX,
            keep_aspect: true,
            grey: Grey::default(),
            upscale: None,
        }
    }
}

/// Marker detection parameters (stage 2).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MarkerParams {
    /// Override the automatic scale: box-filter lobe in working px (odd,
    /// 3..=31; filter size is 3 x lobe, sigma ~ 0.4 x lobe).
    pub lobe_px: Option<u32>,
    /// Override the automatic choice of detecting on a 2x2-binned image.
    pub binned: Option<bool>,
    /// Blob strength threshold as a fraction of the rest frame's typical
    /// marker strength (0 < ratio < 1).
    pub strength_ratio: f32,
    /// Minimum marker contrast over the local background, grey levels.
    pub min_contrast: f32,
    /// Bright markers (TacTip pins), dark ones (GelSight-type dots), or
    /// `auto`: decided on the rest frame.
    pub polarity: Polarity,
    /// Follow the rest markers in small windows and search only when that
    /// loses markers (see `markers::follow_or_search`).
    pub follow: bool,
    /// When following loses markers, search for them only in boxes around
    /// their rest places (unless too many are lost), instead of the whole
    /// frame (see `markers::follow_or_search`).
    pub local_search: bool,
}

impl Default for MarkerParams {
    fn default() -> Self {
        Self {
            lobe_px: None,
            binned: None,
            strength_ratio: 0.3,
            min_contrast: 6.0,
            follow: true,
            local_search: true,
            polarity: Polarity::Auto,
        }
    }
}

/// Marker polarity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Polarity {
    /// Decided on the rest frame: the polarity whose markers form the
    /// larger lattice (bright unless dark is clearly larger).
    Auto,
    /// Bright markers on a dark skin.
    Bright,
    /// Dark markers on a bright skin.
    Dark,
}

/// Which density implementation the pipeline runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DensityMode {
    /// f64, every pixel, every marker, untruncated kernel (reference).
    Exact,
    /// f32 on a grid of `grid_step_px`, kernel truncated at
    /// `truncate_sigmas`, only inside the region around moved markers.
    Fast,
}

/// Where the kernel density's Gaussian is isotropic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DensityKernel {
    /// In the image (the paper's Eq. 1), whatever the skin's shape.
    #[default]
    Image,
    /// On the skin: on a dome ([`crate::surface::Surface::Dome`]) the
    /// distance between a sample and a marker is taken between their points
    /// on the sphere, so the kernel spans the same skin everywhere and a
    /// dome's foreshortened rim does not pull a dent inwards. The same as
    /// `image` on a flat skin. Fast mode only. Measured on the other
    /// renderer (BENCHMARKS.md, session 33): right where the pressed pins
    /// move along the camera's rays (a camera at the sphere's centre), and
    /// wrong by the parallax where they do not.
    Skin,
}

/// Kernel density parameters (stage 3, Eq. 1).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DensityParams {
    /// Kernel width h, px.
    pub kernel_width_px: f64,
    /// Implementation.
    pub mode: DensityMode,
    /// Grid step of the fast path, px (1..=16).
    pub grid_step_px: u32,
    /// Kernel truncation radius of the fast path, in units of h (2..=8).
    pub truncate_sigmas: f64,
    /// Where the kernel is isotropic: in the image (default) or on the skin.
    pub kernel: DensityKernel,
}

impl Default for DensityParams {
    fn default() -> Self {
        Self {
            kernel_width_px: KERNEL_WIDTH_PX,
            mode: DensityMode::Fast,
            // Measured (BENCHMARKS.md): with tracking, step 8 keeps the centre
            // error of step 4 (median ~0.1 px) at ~12 % less time.
            grid_step_px: 8,
            truncate_sigmas: 3.0,
            kernel: DensityKernel::Image,
        }
    }
}

/// Threshold rule for the contact region.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ThresholdMode {
    /// density < `relative_threshold` x rest density at that pixel.
    Relative,
    /// density < `absolute_threshold_per_mm2` (the paper's rule).
    Absolute,
}

/// How the contact centre is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CentreMethod {
    /// Argmin of the density (or density / rest density) over the region
    /// (the paper's Eq. 2), refined to sub-pixel.
    Density,
    /// Density region; where markers around it are lost, the centre from
    /// the tracked markers' displacement field; contacts too small to dent
    /// the density are found from tracked markers alone.
    Hybrid,
}

/// Contact parameters (stages 4-5 and the tracking extension).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContactParams {
    /// Threshold rule.
    pub threshold: ThresholdMode,
    /// Relative threshold (fraction of rest density, 0 < t < 1): a region
    /// starts below it; its area counts the samples below it.
    pub relative_threshold: f64,
    /// A relative-rule region extends through the connected samples below
    /// this fraction of rest density (`relative_threshold` <= it < 1), and
    /// its centroid is weighted by how far each lies below it.
    pub relative_extent: f64,
    /// Absolute threshold, markers per mm^2.
    pub absolute_threshold_per_mm2: f64,
    /// Minimum contact area, mm^2: smaller regions are noise or lost markers.
    pub min_area_mm2: f64,
    /// Centre method.
    pub centre: CentreMethod,
    /// Skip the density stages when no marker moved beyond noise.
    pub skip_unmoved: bool,
    /// A marker moved when it is further than this from its rest position,
    /// px, and further than `move_noise_sigmas` times the frame's marker
    /// jitter (the floor of the noise-aware moved test).
    pub move_noise_px: f64,
    /// A marker moved when its displacement exceeds this many sigmas of the
    /// marker jitter estimated on the frame itself (median displacement of
    /// all tracked markers); 0 = fixed threshold `move_noise_px` only.
    pub move_noise_sigmas: f64,
    /// Fewer moved markers than this is not a contact.
    pub min_moved_markers: usize,
}

impl Default for ContactParams {
    fn default() -> Self {
        Self {
            threshold: ThresholdMode::Relative,
            relative_threshold: RELATIVE_THRESHOLD,
            relative_extent: RELATIVE_EXTENT,
            absolute_threshold_per_mm2: ABSOLUTE_THRESHOLD_PER_MM2,
            min_area_mm2: 1.0,
            centre: CentreMethod::Hybrid,
            skip_unmoved: true,
            move_noise_px: MOVE_NOISE_FLOOR_PX,
            move_noise_sigmas: MOVE_NOISE_SIGMAS,
            min_moved_markers: 3,
        }
    }
}

impl Params {
    /// Parses and validates a TOML config; missing fields keep their defaults.
    pub fn from_toml_str(text: &str) -> Result<Self, ParamsError> {
        let params: Params = toml::from_str(text)?;
        params.validate()?;
        Ok(params)
    }

    /// Reads, parses and validates a TOML config file.
    pub fn load(path: &Path) -> Result<Self, ParamsError> {
        let text = std::fs::read_to_string(path).map_err(|source| ParamsError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text)
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ParamsError> {
        let f = &self.frame;
        check(
            "frame.work_width_px",
            f.work_width_px,
            (16..=8192).contains(&f.work_width_px),
            "must be 16..=8192",
        )?;
        check(
            "frame.work_height_px",
            f.work_height_px,
            (16..=8192).contains(&f.work_height_px),
            "must be 16..=8192",
        )?;
        if let Some(up) = f.upscale {
            check(
                "frame.upscale",
                up,
                (1.0..=MAX_UPSCALE).contains(&up),
                "must be 1..=8",
            )?;
        }
        if let Some(c) = f.crop_px {
            check(
                "frame.crop_px",
                format!("{c:?}"),
                c[2] > 0 && c[3] > 0,
                "width and height must be > 0",
            )?;
        }
        check(
            "frame.mm_per_px",
            f.mm_per_px,
            f.mm_per_px.is_finite() && f.mm_per_px > 1e-6 && f.mm_per_px < 1e3,
            "must be finite, > 1e-6 and < 1000",
        )?;
        let m = &self.markers;
        if let Some(l) = m.lobe_px {
            check(
                "markers.lobe_px",
                l,
                l % 2 == 1 && (3..=31).contains(&l),
                "must be odd, 3..=31",
            )?;
        }
        check(
            "markers.strength_ratio",
            m.strength_ratio,
            m.strength_ratio > 0.0 && m.strength_ratio < 1.0,
            "must be in (0, 1)",
        )?;
        check(
            "markers.min_contrast",
            m.min_contrast,
            m.min_contrast >= 0.0 && m.min_contrast < 255.0,
            "must be in [0, 255)",
        )?;
        let d = &self.density;
        check(
            "density.kernel_width_px",
            d.kernel_width_px,
            d.kernel_width_px.is_finite() && (0.5..=500.0).contains(&d.kernel_width_px),
            "must be in [0.5, 500]",
        )?;
        check(
            "density.grid_step_px",
            d.grid_step_px,
            (1..=16).contains(&d.grid_step_px),
            "must be 1..=16",
        )?;
        check(
            "density.truncate_sigmas",
            d.truncate_sigmas,
            (2.0..=8.0).contains(&d.truncate_sigmas),
            "must be in [2, 8]",
        )?;
        check(
            "density.kernel",
            "skin",
            d.kernel == DensityKernel::Image || d.mode == DensityMode::Fast,
            "the skin's kernel needs density.mode = \"fast\"",
        )?;
        let c = &self.contact;
        check(
            "contact.relative_threshold",
            c.relative_threshold,
            c.relative_threshold > 0.0 && c.relative_threshold < 1.0,
            "must be in (0, 1)",
        )?;
        check(
            "contact.relative_extent",
            c.relative_extent,
            c.relative_extent >= c.relative_threshold && c.relative_extent < 1.0,
            "must be in [contact.relative_threshold, 1)",
        )?;
        check(
            "contact.absolute_threshold_per_mm2",
            c.absolute_threshold_per_mm2,
            c.absolute_threshold_per_mm2.is_finite() && c.absolute_threshold_per_mm2 > 0.0,
            "must be finite and > 0",
        )?;
        check(
            "contact.min_area_mm2",
            c.min_area_mm2,
            c.min_area_mm2.is_finite() && c.min_area_mm2 >= 0.0,
            "must be finite and >= 0",
        )?;
        check(
            "contact.move_noise_px",
            c.move_noise_px,
            c.move_noise_px.is_finite() && c.move_noise_px > 0.0,
            "must be finite and > 0",
        )?;
        check(
            "contact.move_noise_sigmas",
            c.move_noise_sigmas,
            c.move_noise_sigmas.is_finite() && c.move_noise_sigmas >= 0.0,
            "must be finite and >= 0",
        )?;
        check(
            "contact.min_moved_markers",
            c.min_moved_markers,
            c.min_moved_markers >= 1,
            "must be >= 1",
        )?;
        if let Some(reason) = self.surface.problem() {
            check("surface", "dome", false, reason)?;
        }
        Ok(())
    }
}

fn check(
    field: &'static str,
    value: impl std::fmt::Display,
    ok: bool,
    reason: &'static str,
) -> Result<(), ParamsError> {
    if ok {
        Ok(())
    } else {
        Err(ParamsError::Invalid {
            field,
            value: value.to_string(),
            reason,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_papers_constants() {
        let p = Params::default();
        assert_eq!(p.frame.work_width_px, 640);
        assert_eq!(p.frame.work_height_px, 480);
        assert_eq!(p.density.kernel_width_px, 15.0);
        assert_eq!(p.contact.absolute_threshold_per_mm2, 0.3);
        p.validate().unwrap();
    }

    #[test]
    fn empty_config_is_default() {
        assert_eq!(Params::from_toml_str("").unwrap(), Params::default());
    }

    #[test]
    fn the_kernel_on_the_skin_is_read_and_needs_the_fast_mode() {
        let p = Params::from_toml_str("[density]\nkernel = \"skin\"\n").unwrap();
        assert_eq!(p.density.kernel, DensityKernel::Skin);
        let e =
            Params::from_toml_str("[density]\nkernel = \"skin\"\nmode = \"exact\"\n").unwrap_err();
        assert!(e.to_string().contains("density.kernel"), "{e}");
        let e = Params::from_toml_str("[density]\nkernel = \"sphere\"\n").unwrap_err();
        assert!(matches!(e, ParamsError::Parse(_)), "{e}");
    }

    #[test]
    fn unknown_field_is_a_typed_error() {
        let e = Params::from_toml_str("[density]\nkernel_widht_px = 3.0\n").unwrap_err();
        assert!(matches!(e, ParamsError::Parse(_)), "{e}");
    }

    #[test]
    fn out_of_range_value_names_the_field() {
        let e = Params::from_toml_str("[density]\nkernel_width_px = -1.0\n").unwrap_err();
        match e {
            ParamsError::Invalid { field, .. } => assert_eq!(field, "density.kernel_width_px"),
            other => panic!("wrong error {other}"),
        }
        let e = Params::from_toml_str("[markers]\nlobe_px = 4\n").unwrap_err();
        assert!(matches!(
            e,
            ParamsError::Invalid {
                field: "markers.lobe_px",
                ..
            }
        ));
        for up in ["0.5", "9.0", "nan"] {
            let e = Params::from_toml_str(&format!("[frame]\nupscale = {up}\n")).unwrap_err();
            assert!(
                matches!(
                    e,
                    ParamsError::Invalid {
                        field: "frame.upscale",
                        ..
                    }
                ),
                "{up}: {e}"
            );
        }
        let p = Params::from_toml_str("[frame]\nupscale = 2.5\n").unwrap();
        assert_eq!(p.frame.upscale, Some(2.5));
        assert_eq!(Params::from_toml_str("").unwrap().frame.upscale, None);
    }

    #[test]
    fn wrong_type_and_garbage_are_errors() {
        assert!(Params::from_toml_str("[frame]\nmm_per_px = \"big\"\n").is_err());
        assert!(Params::from_toml_str("\u{0}\u{1}not toml[[").is_err());
        assert!(Params::from_toml_str("[contact]\nthreshold = \"sometimes\"\n").is_err());
    }

    #[test]
    fn shipped_sensor_config_equals_the_defaults() {
        let text = include_str!("../sensors/digitac-v1.5.toml");
        assert_eq!(Params::from_toml_str(text).unwrap(), Params::default());
    }

    #[test]
    fn missing_file_is_io_error() {
        let e = Params::load(Path::new("/nonexistent/dexitac.toml")).unwrap_err();
        assert!(matches!(e, ParamsError::Io { .. }));
    }
}
