//! Rest calibration from one or more no-contact working frames: the marker
//! detector (scale found automatically, see [`crate::markers::auto_detector`]),
//! the reference marker set (positions averaged over the frames where a
//! marker was found in every frame), the marker pitch, the reference density
//! on the density grid and the sensing-area mask.
//!
//! The mask keeps grid cells whose rest density is at least
//! [`MASK_FRACTION`] of the typical interior rest density (90th percentile):
//! that is the skin area up to about the outer marker row. Contact regions
//! are only searched inside it.

use crate::area::{self, AreaError, SensingArea, WorkToInput};
use crate::contact;
use crate::density::{self, DensityMap, DensitySetup};
use crate::frame::GreyFrame;
use crate::markers::{self, Detector, MarkerError, RimBand};
use crate::params::{DensityKernel, FrameParams, Params, MAX_UPSCALE};
use crate::surface::Surface;
use crate::tracking::PointIndex;
use crate::PointPx;

/// Mask cut-off, as a fraction of the interior rest density.
pub const MASK_FRACTION: f32 = 0.5;
/// Fewest rest markers a calibration accepts.
pub const MIN_REST_MARKERS: usize = 7;

/// Errors of rest calibration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrationError {
    /// No rest frame given.
    #[error("no rest frame")]
    NoFrames,
    /// Rest frames differ in size.
    #[error("rest frames differ in size: {0}x{1} vs {2}x{3}")]
    SizeMismatch(usize, usize, usize, usize),
    /// Marker scale search failed.
    #[error("marker detection on the rest frame failed: {0}")]
    Markers(#[from] MarkerError),
    /// The sensing area given in the config is invalid.
    #[error(transparent)]
    Area(#[from] AreaError),
    /// Too few markers for a calibration.
    #[error("rest frames give {found} stable markers; need at least {MIN_REST_MARKERS}")]
    TooFewMarkers {
        /// Markers found.
        found: usize,
    },
}

/// The rest (no-contact) reference of one sensor.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// Working frame width, px.
    pub width: usize,
    /// Working frame height, px.
    pub height: usize,
    /// The marker detector.
    pub detector: Detector,
    /// Reference marker positions, working px: where following finds them
    /// on the rest frames (markers it loses there are left out).
    pub rest_markers: Vec<PointPx>,
    /// Median nearest-neighbour distance of the rest markers, px.
    pub pitch_px: f64,
    /// The density setup used for the rest density and every frame.
    pub density: DensitySetup,
    /// Rest density on `density.grid()`.
    pub rest_density: DensityMap,
    /// Sensing-area mask on the same grid (row-major).
    pub mask: Vec<bool>,
    /// Median of the rest density on the skin over the mask (the density
    /// times the surface's foreshortening), markers per mm^2
    /// ([`contact::rim_trust`]).
    pub rest_median_per_mm2: f32,
    /// The skin's shape (working px): the tracked contact centre is found
    /// in its chart.
    pub surface: Surface,
    /// Per rest marker, the radius of its centroid window when followed
    /// ([`markers::centroid_radii`]: smaller where a neighbour is close).
    pub centroid_radii_px: Vec<f64>,
    /// Per rest marker, its contrast on the rest frames when followed, grey
    /// levels: following calls a marker faded against its own contrast, so
    /// a dot dimmed at rest (vignetting, a second pin colour) is not lost.
    /// Empty for a rest estimated from the frames (the frame's median
    /// contrast is the reference then).
    pub rest_contrast: Vec<f32>,
    /// Places inside the rest lattice with no rest marker (a pin that
    /// neither the search nor following found at rest): a frame's markers
    /// are searched for there whenever following is checked by a search
    /// ([`rest_gaps`]).
    pub gaps_px: Vec<PointPx>,
    /// The rest markers' rivals for following
    /// ([`markers::Rivals::new`] of `rest_markers` at
    /// [`crate::pipeline::FOLLOW_REACH_PITCH`] pitches, each also
    /// travelling along its path in `blur`; computed again whenever
    /// `rest_markers` or `blur` change).
    pub rivals: markers::Rivals,
    /// Each rest marker's neighbours ([`markers::Neighbours::new`] of
    /// `rest_markers`; computed again whenever they change).
    pub neighbours: markers::Neighbours,
    /// Where blur puts the rest markers' centroids
    /// ([`markers::BlurLevels::measure`] on the first rest frame; computed
    /// again whenever `rest_markers` change).
    pub blur: markers::BlurLevels,
}

impl Calibration {
    /// What every frame's density is compared with
    /// ([`contact::segment`]).
    pub fn density_reference(&self) -> contact::DensityReference<'_> {
        contact::DensityReference {
            rest: &self.rest_density,
            mask: &self.mask,
            surface: &self.surface,
            rest_median_per_mm2: self.rest_median_per_mm2,
            on_skin: self.density.skin.is_some(),
        }
    }

    /// A warning when the rest's marker lattice has holes: more gap points
    /// ([`rest_gaps`]) than [`HOLEY_REST_SHARE`] of its markers. A rest that
    /// was pressed, or the pixel-wise median of taps, loses the pins that
    /// move differently in every frame; contacts are then measured against
    /// a rest that is not the skin's (measured on the real TacTip taps,
    /// BENCHMARKS.md: the median image of 200 taps shows 250 and 187 of 331
    /// pins).
    pub fn holey_rest_warning(&self) -> Option<String> {
        let (gaps, n) = (self.gaps_px.len(), self.rest_markers.len());
        (gaps as f64 > HOLEY_REST_SHARE * n as f64).then(|| {
            format!(
                "the rest's marker lattice has holes ({gaps} places inside it with no \
                 marker within {GAP_PITCH} pitch, against {n} markers): a pressed rest, \
                 or the median of taps? \
                 Contacts are measured against it; give a no-contact frame, or \
                 --rest-from-frames"
            )
        })
    }

    /// True when this rest (one estimated from the frames) may replace
    /// `holey`, a rest whose lattice has holes: fewer holes, and at least
    /// as many markers. Fewer holes alone let a degenerate estimate in
    /// (measured: with a config tuned on the franka taps' median image, an
    /// estimate of 11 markers and no holes replaced a rest of 204 markers
    /// and 124 holes, and the frames were followed to 10-14 markers).
    pub fn fills_holes_of(&self, holey: &Calibration) -> bool {
        self.gaps_px.len() < holey.gaps_px.len()
            && self.rest_markers.len() >= holey.rest_markers.len()
    }

    /// What following and searching a frame need of the rest.
    pub fn reference(&self) -> markers::Reference<'_> {
        markers::Reference {
            at: &self.rest_markers,
            radii_px: &self.centroid_radii_px,
            contrast: &self.rest_contrast,
            gaps_px: &self.gaps_px,
            rivals: Some(&self.rivals),
            blur: Some(&self.blur),
            neighbours: Some(&self.neighbours),
        }
    }

    /// The sensing area (working px) the detector keeps markers in.
    pub fn area(&self) -> Option<&SensingArea> {
        self.detector.area.as_ref()
    }
}

/// Pin pitch below which the detector loses pins, working px. Measured on
/// the other renderer's frames area-averaged to smaller sizes (BENCHMARKS.md,
/// session 34): at 11.5 px (640x480) every category keeps its markers and
/// contacts; at 8.6 px (480x360) 369 of 378 contacts are found, at 7.1 px
/// 315, at 5.2 px (320x240) 129, and the rest loses a tenth of its pins.
/// The same frames magnified back to this pitch find them all.
pub const MIN_WORKING_PITCH_PX: f64 = 11.0;

/// [`upscale_for`] takes the region at its own size instead of a
/// magnification at most this much smaller: a slightly larger working
/// frame, not resampled (on a 854x480 frame fitted to 640x360, resampling
/// to 819x461 took 0.8 ms a frame and blurred every pin by a varying
/// fraction of a pixel).
pub const NATIVE_SNAP: f64 = 1.25;

/// The frame preparation for a finer working frame when `cal`'s rest pins
/// are closer than [`MIN_WORKING_PITCH_PX`]: `frame` with its
/// [`FrameParams::upscale`] raised so that they are that far apart (at most
/// [`MAX_UPSCALE`]), and `mm_per_px` lowered by as much (the same skin in
/// more pixels). Where the region of the `input_px` frame (its crop, or
/// all of it) at its own size is at most [`NATIVE_SNAP`] times that (the
/// fit to the working size shrank a wide frame), the working frame is the
/// region at its own size: nothing is resampled. `None` when the pins are
/// far enough apart, the pitch is unknown, or `frame` fixes the
/// magnification (`upscale` set).
pub fn upscale_for(
    cal: &Calibration,
    frame: &FrameParams,
    input_px: (usize, usize),
) -> Option<FrameParams> {
    let pitch_px = cal.pitch_px;
    if frame.upscale.is_some()
        || !(pitch_px.is_finite() && pitch_px > 0.0 && pitch_px < MIN_WORKING_PITCH_PX)
    {
        return None;
    }
    let mut upscale = (MIN_WORKING_PITCH_PX / pitch_px).min(MAX_UPSCALE);
    // The region's own size as a magnification of the fitted one.
    let (region_w, region_h) = frame
        .crop_px
        .map_or(input_px, |[_, _, w, h]| (w as usize, h as usize));
    let (fitted_w, _) = crate::frame::working_size(
        region_w,
        region_h,
        &FrameParams {
            upscale: None,
            ..frame.clone()
        },
    );
    let native = region_w as f64 / fitted_w.max(1) as f64;
    // Never past MAX_UPSCALE: `working_size` would clamp it, and
    // `mm_per_px` below would not follow.
    if frame.keep_aspect
        && upscale < native
        && native <= NATIVE_SNAP * upscale
        && native <= MAX_UPSCALE
    {
        upscale = native;
    }
    (upscale > 1.0).then(|| FrameParams {
        upscale: Some(upscale),
        mm_per_px: frame.mm_per_px / upscale,
        ..frame.clone()
    })
}

/// Calibrates from rest frames (all the same working size).
pub fn calibrate(rest: &[GreyFrame], params: &Params) -> Result<Calibration, CalibrationError> {
    calibrate_mapped(rest, params, WorkToInput::IDENTITY)
}

/// [`calibrate`] for working frames that map to the input images by `map`
/// (crop and rescale, see [`crate::frame::Prepared`]): a sensing area given
/// in the config is in input pixels.
pub fn calibrate_mapped(
    rest: &[GreyFrame],
    params: &Params,
    map: WorkToInput,
) -> Result<Calibration, CalibrationError> {
    let (first, w, h) = same_size(rest)?;
    let given = SensingArea::from_spec(&params.area, params.area_mask.as_ref(), w, h, map)?;
    let mut detector = markers::auto_detector(first, &params.markers)?;
    detector.area = given.clone();
    let cal = finish(
        first,
        detector.clone(),
        stable_markers(rest, &detector),
        given.clone(),
        params,
        map,
    )?;
    // On a dome, detect again with the strength threshold eased by the
    // foreshortening: the thin ellipses of the outer rings were too weak
    // for the flat threshold.
    let cal = if cal.surface == Surface::Flat {
        cal
    } else {
        detector.surface = cal.surface;
        finish(
            first,
            detector.clone(),
            stable_markers(rest, &detector),
            given.clone(),
            params,
            map,
        )?
    };
    // The rest is what the live pipeline finds on the rest frames: the
    // markers settled where following finds them, the ones it cannot follow
    // dropped, each in the centroid window it was settled in, and the rest
    // density and mask made from those (area, pitch, surface and search
    // window stay the search's).
    let mut cal = cal;
    let settled = settle(rest, &cal);
    if settled.len() < MIN_REST_MARKERS {
        return Err(CalibrationError::TooFewMarkers {
            found: settled.len(),
        });
    }
    (cal.rest_markers, cal.centroid_radii_px) = settled.into_iter().unzip();
    (cal.rest_density, cal.mask, cal.rest_median_per_mm2) =
        reference(&cal.rest_markers, &cal.density, &cal.detector);
    cal.gaps_px = rest_gaps(&cal.rest_markers, cal.pitch_px, &cal.detector, w, h);
    cal.rest_contrast = rest_contrast(rest, &cal);
    cal.blur = blur_levels(first, &cal);
    link_rest(&mut cal);
    Ok(cal)
}

/// Each rest marker where following finds it on the rest frames (the mean
/// over them; [`markers::follow_all`]), so that a frame without contact,
/// followed, has its markers where the rest says; a marker that following
/// loses on any rest frame (below the detector's contrast floor, cut by the
/// frame's edge, run into a neighbour) is left out: it would be lost in
/// every frame, and a rest frame would not be followed on itself (the
/// whole-frame search, and a false contact where it is missing). The
/// search's centroid (one window of the detector's radius) and the followed
/// one (re-centred, in a window that stops short of close neighbours)
/// differ by up to a pixel on a dome's crowded outer rings and on dense
/// blurred skins; unsettled, every such marker would look moved in every
/// frame. Following from a marker's settled place can settle it elsewhere
/// again (a window that reaches a neighbour): settling is repeated from the
/// settled places until no marker moves more than [`SETTLED_PX`] (at most
/// [`SETTLE_ROUNDS`] times), each marker keeping its centroid window
/// (returned with it: windows made anew from the settled places would
/// follow differently). Measured on another renderer's dome, whose
/// outermost ring is 8.8 px apart: settled once, with windows made anew,
/// 11 of 949 markers sat 0.8-2.5 px from where every frame put them, and a
/// still frame had a contact 1 time in 6.
fn settle(rest: &[GreyFrame], cal: &Calibration) -> Vec<(PointPx, f64)> {
    let radius = |k: usize| {
        cal.centroid_radii_px
            .get(k)
            .copied()
            .unwrap_or(cal.detector.radius_px)
    };
    let mut at: Vec<(PointPx, f64)> = cal
        .rest_markers
        .iter()
        .enumerate()
        .map(|(k, &p)| (p, radius(k)))
        .collect();
    for _ in 0..SETTLE_ROUNDS {
        let (places, radii_px): (Vec<PointPx>, Vec<f64>) = at.iter().copied().unzip();
        let settled: Vec<(PointPx, f64)> = followed_on(rest, cal, &places, &radii_px)
            .into_iter()
            .zip(radii_px)
            .filter(|(s, _)| s.3 == rest.len())
            .map(|(s, r)| (PointPx::new(s.0 / s.3 as f64, s.1 / s.3 as f64), r))
            .collect();
        let still = settled.len() == at.len()
            && settled
                .iter()
                .zip(&at)
                .all(|(a, b)| (a.0.x - b.0.x).hypot(a.0.y - b.0.y) <= SETTLED_PX);
        at = settled;
        if still {
            break;
        }
    }
    at
}

/// A rest marker that settling moves less than this has settled, px.
const SETTLED_PX: f64 = 0.05;
/// Most rounds of [`settle`].
const SETTLE_ROUNDS: usize = 4;

/// Each rest marker's mean contrast on the rest frames, followed (0 where
/// it is never followed).
fn rest_contrast(rest: &[GreyFrame], cal: &Calibration) -> Vec<f32> {
    followed_on(rest, cal, &cal.rest_markers, &cal.centroid_radii_px)
        .into_iter()
        .map(|s| {
            if s.3 == 0 {
                0.0
            } else {
                (s.2 / s.3 as f64) as f32
            }
        })
        .collect()
}

/// Per marker of `at` (followed in windows of `radii_px`), the sums of its
/// followed x, y and contrast over the rest frames, and the number of
/// frames it was followed on.
fn followed_on(
    rest: &[GreyFrame],
    cal: &Calibration,
    at: &[PointPx],
    radii_px: &[f64],
) -> Vec<(f64, f64, f64, usize)> {
    let reach_px = crate::pipeline::FOLLOW_REACH_PITCH * cal.pitch_px;
    let mut sums = vec![(0.0, 0.0, 0.0, 0); at.len()];
    for frame in rest {
        let found = markers::follow_all(frame, &cal.detector, at, radii_px, reach_px);
        for (s, m) in sums.iter_mut().zip(found) {
            if let Some(m) = m {
                *s = (
                    s.0 + m.pos.x,
                    s.1 + m.pos.y,
                    s.2 + m.strength as f64,
                    s.3 + 1,
                );
            }
        }
    }
    sums
}

/// Markers of `rest[0]` of typical size found in every rest frame, at
/// their mean position.
fn stable_markers(rest: &[GreyFrame], detector: &Detector) -> Vec<PointPx> {
    let Some(first) = rest.first() else {
        return Vec::new();
    };
    let (w, h) = (first.width(), first.height());
    let mut sums: Vec<(PointPx, usize)> = markers::detect(first, detector)
        .typical_positions(w, h)
        .into_iter()
        .map(|p| (p, 1))
        .collect();
    let anchor: Vec<PointPx> = sums.iter().map(|s| s.0).collect();
    let match_px = (2.0 * detector.radius_px).max(2.0);
    for frame in &rest[1..] {
        let found = markers::detect(frame, detector).positions();
        let index = PointIndex::new(&found, w, h, match_px);
        for (s, a) in sums.iter_mut().zip(&anchor) {
            if let Some((k, _)) = index.nearest(&found, *a, match_px) {
                s.0 = PointPx::new(s.0.x + found[k].x, s.0.y + found[k].y);
                s.1 += 1;
            }
        }
    }
    sums.into_iter()
        .filter(|s| s.1 == rest.len())
        .map(|(p, n)| PointPx::new(p.x / n as f64, p.y / n as f64))
        .collect()
}

/// The first frame and the size all frames share.
fn same_size(frames: &[GreyFrame]) -> Result<(&GreyFrame, usize, usize), CalibrationError> {
    let first = frames.first().ok_or(CalibrationError::NoFrames)?;
    let (w, h) = (first.width(), first.height());
    match frames.iter().find(|f| (f.width(), f.height()) != (w, h)) {
        Some(f) => Err(CalibrationError::SizeMismatch(w, h, f.width(), f.height())),
        None => Ok((first, w, h)),
    }
}

/// Most frames [`calibrate_from_frames`] looks at (evenly spaced).
pub const REST_FROM_FRAMES_MAX: usize = 63;

/// A rest calibration for a data set without a rest frame, estimated from
/// the frames themselves: the pixel-wise median of up to
/// [`REST_FROM_FRAMES_MAX`] evenly spaced frames gives the detector's
/// thresholds; the frame with the most markers (or the median image, if it
/// has more) gives the lattice and the sensing area; each marker's rest
/// position is then its place, among the frames that have it within half
/// a pitch, nearest to that lattice's (the anchor frame's own, when the
/// lattice is a frame's); markers found in fewer than half of the frames
/// are dropped. Measured on the real TacTip taps (BENCHMARKS.md): with
/// the median of each marker's places instead, the average tap became the
/// rest, and the contact centre followed the tilt less well (LOO R^2
/// 0.91 / 0.81 against 0.92 / 0.90 on cr).
///
/// What it can see: a skin untouched in some frames is at its true rest.
/// What it cannot: when every frame presses the same place (a set of taps,
/// a held object), the rest is a pressed skin: the lightest press when the
/// median image loses the pins the presses move (the binarised TacTip
/// taps), otherwise near the median press. Contacts are then found where
/// a frame presses more than that rest; lighter ones are not seen, and a
/// contact present in every frame at one depth is invisible.
pub fn calibrate_from_frames(
    frames: &[GreyFrame],
    params: &Params,
    map: WorkToInput,
) -> Result<Calibration, CalibrationError> {
    let (_, w, h) = same_size(frames)?;
    let n = frames.len().min(REST_FROM_FRAMES_MAX);
    let picked: Vec<&GreyFrame> = (0..n).map(|k| &frames[k * frames.len() / n]).collect();
    let median = median_image(&picked);
    let given = SensingArea::from_spec(&params.area, params.area_mask.as_ref(), w, h, map)?;
    let mut detector = markers::auto_detector(&median, &params.markers)?;
    detector.area = given.clone();
    // The anchor lattice: the frame (the median image among them) with the
    // most markers. In a tap data set the median image loses the pins that
    // move differently in every frame (the middle of the skin), while the
    // lightest tap shows nearly all of them.
    let detections: Vec<Vec<PointPx>> = picked
        .iter()
        .map(|f| markers::detect(f, &detector).typical_positions(w, h))
        .collect();
    let from_median = markers::detect(&median, &detector).typical_positions(w, h);
    let anchors = if from_median.len() >= MIN_REST_MARKERS {
        // The frame that agrees best with the median image: the most of its
        // markers within a fifth of a pitch of a median-image marker (the
        // lightest tap).
        let close = 0.2 * median_spacing(&from_median);
        let index = PointIndex::new(&from_median, w, h, close);
        let agree = |d: &Vec<PointPx>| {
            d.iter()
                .filter(|p| index.nearest(&from_median, **p, close).is_some())
                .count()
        };
        detections
            .iter()
            .max_by_key(|d| agree(d))
            .filter(|d| d.len() > from_median.len())
            .cloned()
            .unwrap_or(from_median)
    } else {
        detections
            .iter()
            .max_by_key(|d| d.len())
            .cloned()
            .unwrap_or(from_median)
    };
    if anchors.len() < MIN_REST_MARKERS {
        return Err(CalibrationError::TooFewMarkers {
            found: anchors.len(),
        });
    }
    let reach = 0.5 * median_spacing(&anchors);
    // Per frame, per anchor: the marker found within `reach` of it.
    let seen: Vec<Vec<Option<PointPx>>> = detections
        .iter()
        .map(|found| {
            let index = PointIndex::new(found, w, h, reach);
            anchors
                .iter()
                .map(|a| index.nearest(found, *a, reach).map(|(k, _)| found[k]))
                .collect()
        })
        .collect();
    // A marker of the anchor lattice found in under half the frames is not
    // a pin (debris, a flickering speck) and is dropped. The others are
    // where they lie closest to their anchor place: when the anchors are a
    // frame's markers (the lightest tap of a set of taps), that frame's
    // place; when they are the median image's (a stream that mostly has no
    // contact), the frame where the marker sits nearest to it. A median
    // over the frames would be the average tap's place in a set of taps.
    let stable: Vec<PointPx> = anchors
        .iter()
        .enumerate()
        .filter_map(|(n, a)| {
            let d2 = |p: &PointPx| (p.x - a.x).powi(2) + (p.y - a.y).powi(2);
            let all = seen.iter().filter_map(|f| f[n]);
            if 2 * all.clone().count() < picked.len() {
                return None;
            }
            all.min_by(|p, q| d2(p).total_cmp(&d2(q)))
        })
        .collect();
    let mut cal = finish(&median, detector, stable, given, params, map)?;
    cal.gaps_px = rest_gaps(&cal.rest_markers, cal.pitch_px, &cal.detector, w, h);
    cal.blur = blur_levels(&median, &cal);
    link_rest(&mut cal);
    Ok(cal)
}

/// Pixel-wise median of same-size frames (the lower median for an even
/// count).
fn median_image(frames: &[&GreyFrame]) -> GreyFrame {
    let (w, h) = (frames[0].width(), frames[0].height());
    let mut column = vec![0u8; frames.len()];
    let k = (frames.len() - 1) / 2;
    let data = (0..w * h)
        .map(|i| {
            for (c, f) in column.iter_mut().zip(frames) {
                *c = f.data()[i];
            }
            *column.select_nth_unstable(k).1
        })
        .collect();
    GreyFrame::new(w, h, data).expect("the size of a valid frame")
}

/// From the stable rest markers: the sensing area (given, or found from
/// the lattice, with its rim band measured on `rest`), the markers inside
/// it, the pitch, the search window and the density reference.
fn finish(
    rest: &GreyFrame,
    mut detector: Detector,
    stable: Vec<PointPx>,
    given: Option<SensingArea>,
    params: &Params,
    map: WorkToInput,
) -> Result<Calibration, CalibrationError> {
    if stable.len() < MIN_REST_MARKERS {
        return Err(CalibrationError::TooFewMarkers {
            found: stable.len(),
        });
    }
    let (w, h) = (rest.width(), rest.height());
    let spacing_px = median_spacing(&stable);
    let lattice = |growth: f64| area::from_lattice(&stable, spacing_px, growth, w, h);
    let (area, outer) = match given {
        Some(a) => (a, None),
        None => match lattice(area::HULL_GROWTH_PITCH) {
            Some(a) => (a, lattice(area::HULL_GROWTH_PITCH + area::RIM_TRAVEL_PITCH)),
            None => (SensingArea::whole(w, h), None),
        },
    };
    let rest_markers: Vec<PointPx> = stable.into_iter().filter(|&p| area.contains(p)).collect();
    if rest_markers.len() < MIN_REST_MARKERS {
        return Err(CalibrationError::TooFewMarkers {
            found: rest_markers.len(),
        });
    }
    let pitch_px = median_spacing(&rest_markers);
    // The frame's edge cuts the markers beyond it, and their centroids move
    // inwards by up to a radius: spacings that shrink towards the frame's
    // edge, as a dome's do towards its rim. Only the uncut ones tell the
    // skin's shape (a flat GelSight Mini was taken for a dome with its rim
    // at 62 degrees). A marker is cut when the frame's edge clips its
    // centroid window.
    let reach_px = markers::window_reach_px(detector.radius_px) as f64;
    let uncut: Vec<PointPx> = rest_markers
        .iter()
        .copied()
        .filter(|p| {
            p.x >= reach_px
                && p.y >= reach_px
                && p.x <= w as f64 - 1.0 - reach_px
                && p.y <= h as f64 - 1.0 - reach_px
        })
        .collect();
    let surface = params.surface.resolve(&uncut, map);
    detector.surface = surface;
    detector.cell_px = ((pitch_px / detector.bin as f64).round() as usize).max(4);
    detector.window_px = Some(search_window(&rest_markers, &detector, pitch_px, w, h));
    detector.area = Some(area);
    detector.rim = outer.map(|outer| rim_band(rest, &detector, outer));
    let density = DensitySetup {
        width: w,
        height: h,
        h_px: params.density.kernel_width_px,
        mm_per_px: params.frame.mm_per_px,
        mode: params.density.mode,
        step_px: params.density.grid_step_px as usize,
        truncate_sigmas: params.density.truncate_sigmas,
        skin: match (params.density.kernel, surface) {
            (DensityKernel::Skin, Surface::Dome(dome)) => Some(dome),
            _ => None,
        },
    };
    let (rest_density, mask, rest_median_per_mm2) = reference(&rest_markers, &density, &detector);
    let centroid_radii_px = markers::centroid_radii(&rest_markers, detector.radius_px);
    Ok(Calibration {
        width: w,
        height: h,
        detector,
        rest_markers,
        pitch_px,
        density,
        rest_density,
        mask,
        rest_median_per_mm2,
        surface,
        centroid_radii_px,
        rest_contrast: Vec::new(),
        gaps_px: Vec::new(),
        // Made by `link_rest` once the rest markers and their blur are final.
        rivals: markers::Rivals::default(),
        neighbours: markers::Neighbours::default(),
        blur: markers::BlurLevels::default(),
    })
}

/// The lists following needs of `cal`'s rest markers, made once they and
/// their blur levels are final: their rivals for the pipeline's follow
/// reach, each travelling along its blur path, and their neighbours.
fn link_rest(cal: &mut Calibration) {
    let travel_px: Vec<f64> = (0..cal.rest_markers.len())
        .map(|k| cal.blur.path(k).map_or(0.0, |p| p.length_px()))
        .collect();
    cal.rivals = markers::Rivals::new(
        &cal.rest_markers,
        crate::pipeline::FOLLOW_REACH_PITCH * cal.pitch_px,
        &travel_px,
    );
    cal.neighbours = markers::Neighbours::new(&cal.rest_markers, cal.pitch_px);
}

/// Where blur puts `cal`'s rest markers on `rest`: followed within half a
/// pitch, in their own centroid windows.
fn blur_levels(rest: &GreyFrame, cal: &Calibration) -> markers::BlurLevels {
    markers::BlurLevels::measure(
        rest,
        &cal.detector,
        &cal.rest_markers,
        &cal.centroid_radii_px,
        0.5 * cal.pitch_px,
    )
}

/// The rim band of an automatic area (`detector.area`) out to `outer`: where
/// the rest frame is bright in it, and the rest markers' size. Bright: at
/// least half way from the skin (the 10th percentile of the area's grey
/// levels) to the rest markers' centres (their median grey level).
fn rim_band(rest: &GreyFrame, detector: &Detector, outer: SensingArea) -> RimBand {
    let probe = Detector {
        area: Some(outer.clone()),
        rim: None,
        ..detector.clone()
    };
    let positive = &*markers::positive(rest, detector.dark);
    let inside = |p: PointPx| detector.area.as_ref().is_none_or(|a| a.contains(p));
    let pins: Vec<markers::Marker> = markers::detect(rest, &probe)
        .list
        .into_iter()
        .filter(|m| inside(m.pos))
        .collect();
    let grey = |x: f64, y: f64| positive.get((x + 0.5) as i64, (y + 0.5) as i64) as f32;
    let pin_level = markers::percentile(pins.iter().map(|m| grey(m.pos.x, m.pos.y)).collect(), 0.5);
    let (w, h) = (rest.width(), rest.height());
    // Every 7th pixel of the area is enough for a percentile.
    let skin = markers::percentile(
        (0..w * h)
            .step_by(7)
            .map(|i| ((i % w) as f64, (i / w) as f64))
            .filter(|&(x, y)| inside(PointPx::new(x, y)))
            .map(|(x, y)| grey(x, y))
            .collect(),
        0.1,
    );
    let cut = skin + 0.5 * (pin_level - skin);
    let bright_at_rest = SensingArea::from_fn(w, h, |x, y| {
        let p = PointPx::new(x, y);
        outer.contains(p) && !inside(p) && grey(x, y) >= cut
    });
    let size = markers::percentile(pins.iter().map(|m| m.area_px).collect(), 0.5);
    let (lo, hi) = markers::SIZE_RANGE;
    RimBand {
        outer,
        bright_at_rest,
        pin_area_px: [lo * size, hi * size],
    }
}

/// A place is a gap when every rest marker around is further than this
/// many times its own nearest-neighbour distance, or the pitch where that
/// is larger (a regular lattice's farthest point from its markers is
/// `1 / sqrt(3)` = 0.58 pitch).
pub const GAP_PITCH: f64 = 0.8;

/// A gap has rest markers on all four sides within this many pitches (a
/// hole of several missing pins, not the lattice's rim).
pub const GAP_SIDES_PITCH: f64 = 6.0;

/// [`Calibration::holey_rest_warning`] warns above this many gap points
/// per rest marker (a good rest of the real TacTip sets has 0-2 for 331
/// markers, the median image of the taps 113-120).
pub const HOLEY_REST_SHARE: f64 = 0.02;

/// Places inside the rest lattice where a marker is missing: points of a
/// half-pitch grid inside the detector's area and search window with no
/// rest marker within [`GAP_PITCH`] of its spacing, that lie a pitch
/// inside the area and that have rest markers within [`GAP_SIDES_PITCH`]
/// on all four sides (a hole, not the lattice's rim). A rest made from
/// frames whose contact hid some pins, or the median of such frames, has
/// them.
pub fn rest_gaps(
    rest: &[PointPx],
    pitch_px: f64,
    detector: &Detector,
    w: usize,
    h: usize,
) -> Vec<PointPx> {
    if !(pitch_px.is_finite() && pitch_px > 1.0) || rest.is_empty() {
        return Vec::new();
    }
    let [x0, y0, x1, y1] = detector.window_px.unwrap_or([0, 0, w, h]);
    let around = GAP_SIDES_PITCH * pitch_px;
    let index = PointIndex::new(rest, w, h, around);
    let spacing: Vec<f64> = (0..rest.len())
        .map(|n| {
            index
                .nearest_other(rest, n, around)
                .map_or(pitch_px, |(_, d)| d.max(pitch_px))
        })
        .collect();
    let step = 0.5 * pitch_px;
    let inside = |q: PointPx| detector.area.as_ref().is_none_or(|a| a.contains(q));
    let mut gaps = Vec::new();
    let mut y = y0 as f64 + step;
    while y < y1.min(h) as f64 {
        let mut x = x0 as f64 + step;
        while x < x1.min(w) as f64 {
            let p = PointPx::new(x, y);
            x += step;
            // A pitch inside the area (the lattice's own rim is no gap).
            let d = pitch_px;
            if ![(0.0, 0.0), (d, 0.0), (-d, 0.0), (0.0, d), (0.0, -d)]
                .iter()
                .all(|&(dx, dy)| inside(PointPx::new(p.x + dx, p.y + dy)))
            {
                continue;
            }
            let mut sides = [false; 4];
            let mut empty = true;
            for (n, d2) in index.within(rest, p, around) {
                // Against the local spacing where it is wider than the
                // median pitch (a dome's apex; its foreshortened rim rings
                // are closer only radially).
                empty &= d2 > (GAP_PITCH * spacing[n]).powi(2);
                let (dx, dy) = (rest[n].x - p.x, rest[n].y - p.y);
                let side = if dx.abs() >= dy.abs() {
                    usize::from(dx > 0.0)
                } else {
                    2 + usize::from(dy > 0.0)
                };
                sides[side] = true;
            }
            if empty && sides.iter().all(|&s| s) {
                gaps.push(p);
            }
        }
        y += step;
    }
    gaps
}

/// What the rest markers give every frame's density: the rest density, the
/// sensing mask on its grid (where the rest density is, inside the
/// detector's area) and the rest density's median on the skin over the
/// mask ([`skin_median`], or the plain median when the kernel is on the
/// skin; 0 for an empty mask).
fn reference(
    rest_markers: &[PointPx],
    density: &DensitySetup,
    detector: &Detector,
) -> (DensityMap, Vec<bool>, f32) {
    let rest_density = density::estimate(rest_markers, density, None);
    let mut mask = sensing_mask(&rest_density.values_per_mm2);
    let grid = density.grid();
    if let Some(area) = &detector.area {
        for (k, m) in mask.iter_mut().enumerate() {
            *m &= area.contains(grid.point_of(k));
        }
    }
    // A kernel on the skin gave densities on the skin already.
    let surface = match density.skin {
        Some(_) => Surface::Flat,
        None => detector.surface,
    };
    let median = skin_median(&rest_density, &mask, &surface);
    (rest_density, mask, median)
}

/// The median over `mask` of `density` on the skin: a dome's image density
/// times its foreshortening there ([`Surface::foreshortening`]), markers per
/// mm^2.
fn skin_median(density: &DensityMap, mask: &[bool], surface: &Surface) -> f32 {
    let grid = density.grid;
    let inside: Vec<f32> = density
        .values_per_mm2
        .iter()
        .zip(mask)
        .enumerate()
        .filter(|&(_, (v, &m))| m && v.is_finite())
        .map(|(k, (&v, _))| v * surface.foreshortening(grid.point_of(k)) as f32)
        .collect();
    markers::percentile(inside, 0.5)
}

/// The bounding box of the rest markers grown by a pitch, the marker size and
/// the filter margin (markers cannot move further out than that and still be
/// on the skin), aligned to even pixels, clipped to the frame.
fn search_window(
    rest: &[PointPx],
    det: &Detector,
    pitch_px: f64,
    w: usize,
    h: usize,
) -> [usize; 4] {
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in rest {
        x0 = x0.min(p.x);
        y0 = y0.min(p.y);
        x1 = x1.max(p.x);
        y1 = y1.max(p.y);
    }
    let grow = pitch_px + 2.0 * det.radius_px + ((3 * det.lobe_px) / 2 * det.bin) as f64 + 2.0;
    let lo = |v: f64| ((v - grow).max(0.0) as usize) & !1;
    let hi = |v: f64, n: usize| (((v + grow).ceil().max(0.0) as usize + 1) & !1).min(n);
    [lo(x0), lo(y0), hi(x1, w), hi(y1, h)]
}

/// Median distance from each marker to its nearest neighbour, px
/// ([`area::nearest_distances`]).
fn median_spacing(points: &[PointPx]) -> f64 {
    let mut d: Vec<f64> = area::nearest_distances(points, 1, false)
        .into_iter()
        .map(|d| d.first().copied().unwrap_or(f64::INFINITY))
        .collect();
    let k = d.len() / 2;
    *d.select_nth_unstable_by(k, f64::total_cmp).1
}

/// The sensing mask of a rest density (`values_per_mm2` of a
/// [`DensityMap`]): the cells whose density is at least [`MASK_FRACTION`] of
/// the typical interior density, the 90th percentile of the positive
/// cells. Empty cells (beyond the lattice) and non-finite ones are never in
/// it, and do not lower the percentile. The calibration's mask, and the live
/// view's for a sensor it has no calibration of.
pub fn sensing_mask(rest_per_mm2: &[f32]) -> Vec<bool> {
    let mut inside: Vec<f32> = rest_per_mm2
        .iter()
        .copied()
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    if inside.is_empty() {
        return vec![false; rest_per_mm2.len()];
    }
    let k = (inside.len() - 1) * 9 / 10;
    let typical = *inside.select_nth_unstable_by(k, f32::total_cmp).1;
    rest_per_mm2
        .iter()
        .map(|&v| v.is_finite() && v >= MASK_FRACTION * typical)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{rest_frame, Category};
    use crate::test_fixtures;

    fn median_error(found: &[PointPx], truth: &[PointPx]) -> f64 {
        let mut d: Vec<f64> = test_fixtures::match_points(found, truth, 3.0)
            .into_iter()
            .map(|m| m.2)
            .collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    }

    #[test]
    fn a_rest_with_a_hole_is_warned_of() {
        // Bright spots on a 16 px lattice; the median of taps loses the
        // middle pins: those within 4 pitches of the centre are left out.
        let pins = crate::test_fixtures::hex_points(640, 480, 16.0);
        let frame = |hole_px: f64| {
            let spots: Vec<_> = pins
                .iter()
                .filter(|p| (p.x - 320.0).hypot(p.y - 240.0) >= hole_px)
                .map(|&p| (p, 2.0, 150.0))
                .collect();
            crate::test_fixtures::spots_frame(640, 480, 40.0, &spots)
        };
        let params = Params::default();
        let whole = calibrate(&[frame(0.0)], &params).unwrap();
        assert_eq!(whole.holey_rest_warning(), None, "{:?}", whole.gaps_px);
        let holey = calibrate(&[frame(64.0)], &params).unwrap();
        let w = holey.holey_rest_warning().expect("a warning");
        assert!(w.contains("--rest-from-frames"), "{w}");
        // The whole lattice may replace the holey one; a corner of it, with
        // no holes but a tenth of the markers, may not.
        assert!(whole.fills_holes_of(&holey));
        let corner: Vec<_> = pins
            .iter()
            .filter(|p| p.x < 200.0 && p.y < 150.0)
            .map(|&p| (p, 2.0, 150.0))
            .collect();
        let corner = calibrate(
            &[crate::test_fixtures::spots_frame(640, 480, 40.0, &corner)],
            &params,
        )
        .unwrap();
        assert!(
            corner.gaps_px.len() < holey.gaps_px.len(),
            "{:?}",
            corner.gaps_px
        );
        assert!(!corner.fills_holes_of(&holey));
    }

    #[test]
    fn gaps_are_missing_pins_and_a_hole_is_searched_in_every_frame() {
        let params = Params::default();
        for cat in [
            Category::Nominal,
            Category::RoundedRect,
            Category::Dome,
            Category::Housing,
            Category::TacTip,
        ] {
            // As `test_fixtures::calibrated`, with the truth at hand.
            let rest = rest_frame(&cat.sensor(640, 480, 5), 99);
            let cal = calibrate(std::slice::from_ref(&rest.image), &params).unwrap();
            // Each gap is a true pin the rest markers miss.
            let nearest = |ps: &[PointPx], q: &PointPx| {
                ps.iter()
                    .map(|p| (p.x - q.x).hypot(p.y - q.y))
                    .fold(f64::INFINITY, f64::min)
            };
            for g in &cal.gaps_px {
                let pin = rest
                    .markers
                    .iter()
                    .find(|t| (t.x - g.x).hypot(t.y - g.y) < 0.5 * cal.pitch_px);
                let pin = pin.unwrap_or_else(|| panic!("{cat:?}: gap {g:?} on no pin"));
                assert!(
                    nearest(&cal.rest_markers, pin) > 0.25 * cal.pitch_px,
                    "{cat:?}: {g:?}"
                );
            }
            assert!(cal.gaps_px.len() <= 2, "{cat:?}: {:?}", cal.gaps_px);
            assert_eq!(cal.holey_rest_warning(), None, "{cat:?}");
        }
        // Three neighbouring pins painted out of the rest frame (a pin
        // missing at rest): a gap there; a frame that has them is followed
        // and searched there, and all its markers are found, with no
        // contact.
        let sensor = Category::Nominal.sensor(640, 480, 3);
        let rest = rest_frame(&sensor, 4);
        let centre = PointPx::new(320.0, 240.0);
        let mut hidden: Vec<PointPx> = rest.markers.clone();
        hidden.sort_by(|a, b| {
            let d = |p: &PointPx| (p.x - centre.x).hypot(p.y - centre.y);
            d(a).total_cmp(&d(b))
        });
        hidden.truncate(3);
        // Each painted with the darkest level around it (the skin).
        let src = rest.image.data();
        let mut data = src.to_vec();
        let r = sensor.pitch_px * 0.4;
        for h in &hidden {
            let (x0, y0) = ((h.x - r) as usize, (h.y - r) as usize);
            let (x1, y1) = ((h.x + r) as usize, (h.y + r) as usize);
            let skin = (y0..=y1)
                .flat_map(|y| (x0..=x1).map(move |x| src[y * 640 + x]))
                .min()
                .unwrap();
            for y in y0..=y1 {
                for x in x0..=x1 {
                    if (x as f64 - h.x).hypot(y as f64 - h.y) < r {
                        data[y * 640 + x] = skin;
                    }
                }
            }
        }
        let painted = GreyFrame::new(640, 480, data).unwrap();
        let cal = calibrate(&[painted], &params).unwrap();
        assert_eq!(cal.rest_markers.len() + 3, rest.markers.len());
        for h in &hidden {
            let d = cal
                .gaps_px
                .iter()
                .map(|g| (g.x - h.x).hypot(g.y - h.y))
                .fold(f64::INFINITY, f64::min);
            assert!(
                d < 0.5 * cal.pitch_px,
                "no gap near {h:?}: {:?}",
                cal.gaps_px
            );
        }
        let p = crate::pipeline::Pipeline::new(cal, params);
        let r = p.run(&rest_frame(&sensor, 5).image).unwrap();
        assert_eq!(r.markers.len(), rest.markers.len());
        assert!(r.contact.is_none(), "{:?}", r.contact);
    }

    #[test]
    fn the_rim_band_keeps_pins_pushed_out_and_drops_the_housing() {
        // A disc of pins (pitch 20 px) and a saturated LED on the housing
        // just outside it; in the frame a deep tap has pushed the outer
        // pins 0.9 pitch outwards, out of the area, and a dust speck and a
        // pin-sized blob have appeared there.
        let (w, h, pitch) = (640, 480, 20.0);
        let c = PointPx::new(320.0, 240.0);
        let at = |r: f64, deg: f64| {
            let a = deg.to_radians();
            PointPx::new(c.x + r * a.cos(), c.y + r * a.sin())
        };
        let (led, stray, speck) = (at(196.0, 30.0), at(190.0, 150.0), at(200.0, 270.0));
        let pushed = |p: PointPx| {
            let (dx, dy) = (p.x - c.x, p.y - c.y);
            let r = dx.hypot(dy);
            let k = if r > 160.0 {
                (r + 0.9 * pitch) / r
            } else {
                1.0
            };
            PointPx::new(c.x + k * dx, c.y + k * dy)
        };
        let near = |p: PointPx, q: PointPx, d: f64| (p.x - q.x).hypot(p.y - q.y) < d;
        let pins: Vec<PointPx> = test_fixtures::hex_points(w, h, pitch)
            .into_iter()
            .filter(|p| near(*p, c, 181.0))
            .filter(|p| {
                [(led, 25.0), (stray, 14.0), (speck, 14.0)]
                    .iter()
                    .all(|&(q, d)| !near(pushed(*p), q, d))
            })
            .collect();
        let spot = |p: PointPx| (p, 3.0, 150.0);
        let led_spot = (led, 5.0, 900.0);
        let rest_spots: Vec<_> = pins.iter().map(|&p| spot(p)).chain([led_spot]).collect();
        let rest = test_fixtures::spots_frame(w, h, 30.0, &rest_spots);
        let moved: Vec<PointPx> = pins.iter().map(|&p| pushed(p)).collect();
        let frame_spots: Vec<_> = moved
            .iter()
            .map(|&p| spot(p))
            .chain([led_spot, spot(stray), (speck, 1.0, 120.0)])
            .collect();
        let frame = test_fixtures::spots_frame(w, h, 30.0, &frame_spots);
        let cal = calibrate(std::slice::from_ref(&rest), &Params::default()).unwrap();
        assert_eq!(cal.rest_markers.len(), pins.len());
        let area = cal.detector.area.as_ref().unwrap();
        let outside = moved.iter().filter(|p| !area.contains(**p)).count();
        assert!(outside >= 20, "{outside} pins pushed out of the area");
        let rim = cal.detector.rim.clone().unwrap();
        assert!(!area.contains(stray) && rim.outer.contains(stray));
        assert!(rim.bright_at_rest.contains(led) && !rim.bright_at_rest.contains(stray));
        let found = |det: &Detector, image: &GreyFrame| markers::detect(image, det).positions();
        assert_eq!(
            found(&cal.detector, &rest).len(),
            pins.len(),
            "the LED kept"
        );
        // The pin-sized blob is a pin pushed out, for all the band can
        // tell; where the rest was bright, it is the housing's.
        let with_stray: Vec<PointPx> = moved.iter().copied().chain([stray]).collect();
        let mut lit = cal.detector.clone();
        lit.rim.as_mut().unwrap().bright_at_rest =
            SensingArea::from_fn(w, h, |x, y| near(PointPx::new(x, y), stray, 4.0));
        for (det, truth) in [(&cal.detector, &with_stray), (&lit, &moved)] {
            let found = found(det, &frame);
            assert_eq!(
                test_fixtures::match_points(&found, truth, 1.5).len(),
                truth.len()
            );
            assert_eq!(found.len(), truth.len(), "the LED or the speck kept");
        }
        // Without the band the pushed pins are lost.
        let mut no_rim = cal.detector.clone();
        no_rim.rim = None;
        assert!(found(&no_rim, &frame).len() <= moved.len() - outside);
    }

    #[test]
    fn a_rest_frame_followed_on_itself_stays_where_the_rest_says() {
        // Following a rest frame from the rest markers, in their windows,
        // must find every one where the calibration put it, or a still
        // frame has moved markers: on the domes' crowded outer rings a
        // centroid window reaches the neighbours.
        for cat in [Category::Dome, Category::TacTip, Category::Nominal] {
            let sensor = cat.sensor(640, 480, 5);
            let rest = rest_frame(&sensor, 99).image;
            let cal = calibrate(std::slice::from_ref(&rest), &Params::default()).unwrap();
            let reach_px = crate::pipeline::FOLLOW_REACH_PITCH * cal.pitch_px;
            let found = markers::follow_all(
                &rest,
                &cal.detector,
                &cal.rest_markers,
                &cal.centroid_radii_px,
                reach_px,
            );
            let off: Vec<f64> = found
                .iter()
                .zip(&cal.rest_markers)
                .filter_map(|(f, r)| f.map(|f| (f.pos.x - r.x).hypot(f.pos.y - r.y)))
                .collect();
            assert_eq!(
                off.len(),
                cal.rest_markers.len(),
                "{cat:?}: every rest marker is followed"
            );
            let worst = off.iter().copied().fold(0.0, f64::max);
            let over = off.iter().filter(|&&d| d > 2.0 * SETTLED_PX).count();
            assert!(over == 0, "{cat:?}: {over} markers off, worst {worst} px");
        }
    }

    #[test]
    fn several_rest_frames_average_out_marker_noise() {
        let mut sensor = Category::Nominal.sensor(640, 480, 2);
        sensor.noise_sigma = 8.0;
        let frames: Vec<_> = (0..4).map(|k| rest_frame(&sensor, 10 + k)).collect();
        let truth = &frames[0].markers;
        let params = Params::default();
        let one = calibrate(&[frames[0].image.clone()], &params).unwrap();
        let all: Vec<GreyFrame> = frames.iter().map(|f| f.image.clone()).collect();
        let four = calibrate(&all, &params).unwrap();
        assert!(four.rest_markers.len() as f64 >= 0.97 * truth.len() as f64);
        let (e1, e4) = (
            median_error(&one.rest_markers, truth),
            median_error(&four.rest_markers, truth),
        );
        assert!(e4 < 0.8 * e1, "one frame {e1} px, four frames {e4} px");
    }

    #[test]
    fn calibration_finds_pitch_mask_and_search_window() {
        let params = Params::default();
        let cal = test_fixtures::calibrated(Category::Nominal, 640, 480, &params);
        assert!((cal.pitch_px - 15.0).abs() < 0.3, "{}", cal.pitch_px);
        let g = cal.density.grid();
        let centre = (g.ny / 2) * g.nx + g.nx / 2;
        assert!(
            cal.mask[centre] && !cal.mask[0],
            "mask must cover the skin only"
        );
        let [x0, y0, x1, y1] = cal.detector.window_px.unwrap();
        assert!(
            x0 > 0 && x1 < 640 && y0 < 30 && y1 > 450,
            "{x0} {y0} {x1} {y1}"
        );
    }

    #[test]
    fn pins_too_close_for_the_detector_magnify_the_working_frame() {
        let rest = rest_frame(&Category::Nominal.sensor(640, 480, 11), 3).image;
        let raw = crate::frame::RawFrame {
            width: rest.width(),
            height: rest.height(),
            channels: 1,
            data: rest.data(),
        };
        let at = |frame: &FrameParams| {
            let params = Params {
                frame: frame.clone(),
                ..Params::default()
            };
            let work = crate::frame::prepare(&raw, frame).unwrap().grey;
            calibrate(&[work], &params).unwrap()
        };
        let native = at(&FrameParams::default());
        assert!(upscale_for(&native, &FrameParams::default(), (640, 480)).is_none());
        // Half size: pins 7.5 px apart, magnified back to the detector's
        // pitch, with the millimetres per pixel following.
        let half = FrameParams {
            work_width_px: 320,
            work_height_px: 240,
            ..FrameParams::default()
        };
        let small = at(&half);
        let finer =
            upscale_for(&small, &half, (640, 480)).expect("pins closer than the detector's pitch");
        let gain = MIN_WORKING_PITCH_PX / small.pitch_px;
        let up = |f: &FrameParams| f.upscale.expect("a magnification");
        assert!((up(&finer) - gain).abs() < 1e-9, "{finer:?}");
        assert!((finer.mm_per_px * up(&finer) - half.mm_per_px).abs() < 1e-12);
        // A magnification the config fixes is left as it is, 1 included.
        for fixed in [1.0, 1.2] {
            let set = FrameParams {
                upscale: Some(fixed),
                ..half.clone()
            };
            assert!(upscale_for(&small, &set, (640, 480)).is_none());
        }
        let magnified = at(&finer);
        assert!(
            (magnified.pitch_px / MIN_WORKING_PITCH_PX - 1.0).abs() < 0.05,
            "{}",
            magnified.pitch_px
        );
        let (n, m) = (native.rest_markers.len(), magnified.rest_markers.len());
        assert!(m.abs_diff(n) * 50 <= n, "{m} of {n} markers");
        // A wide frame the fit shrank by little more than the magnification
        // it needs is taken at its own size; one it shrank by much more is
        // magnified only as needed.
        let default = FrameParams::default();
        let wide = upscale_for(&small, &default, (1000, 480)).unwrap();
        assert_eq!(crate::frame::working_size(1000, 480, &wide), (1000, 480));
        let wider = upscale_for(&small, &default, (1400, 480)).unwrap();
        assert!((up(&wider) - gain).abs() < 1e-9, "{wider:?}");
        // Never past MAX_UPSCALE, even to take a frame at its own size.
        let narrow = FrameParams {
            work_width_px: 16,
            work_height_px: 16,
            ..FrameParams::default()
        };
        let tiny_pins = Calibration {
            pitch_px: 1.5,
            ..small.clone()
        };
        let most = upscale_for(&tiny_pins, &narrow, (140, 140)).unwrap();
        assert!(up(&most) <= MAX_UPSCALE, "{most:?}");
        assert!((most.mm_per_px * up(&most) - narrow.mm_per_px).abs() < 1e-12);
    }

    #[test]
    fn a_domes_rest_density_is_trusted_across_its_skin() {
        // Markers evenly on a dome's skin (rings 12 px apart along it, to
        // 60 degrees from the apex), seen along its axis: the image packs
        // them tighter towards the rim, and per image pixel the apex holds
        // fewer than the median, which is no fall-off of the lattice. On
        // the skin the density is even: the rim's weighting
        // ([`contact::rim_trust`]) trusts the cells within 80 % of the
        // dome's image radius alike, where in the image it would not.
        let (r_px, pitch_px) = (200.0, 12.0);
        let dome = crate::surface::Dome {
            centre: PointPx::new(320.0, 240.0),
            radius_px: r_px,
        };
        let mut rest = vec![dome.centre];
        for i in 1..=((60f64.to_radians() * r_px / pitch_px) as usize) {
            let theta = i as f64 * pitch_px / r_px;
            let n = (std::f64::consts::TAU * r_px * theta.sin() / pitch_px).round() as usize;
            for k in 0..n {
                let phi = std::f64::consts::TAU * (k as f64 + 0.5 * (i % 2) as f64) / n as f64;
                let rho = r_px * theta.sin();
                rest.push(PointPx::new(
                    320.0 + rho * phi.cos(),
                    240.0 + rho * phi.sin(),
                ));
            }
        }
        let setup = DensitySetup {
            width: 640,
            height: 480,
            h_px: 15.0,
            mm_per_px: 0.1,
            mode: crate::params::DensityMode::Fast,
            step_px: 4,
            truncate_sigmas: 3.0,
            skin: None,
        };
        let density = density::estimate(&rest, &setup, None);
        let mask = sensing_mask(&density.values_per_mm2);
        let g = density.grid;
        let surface = Surface::Dome(dome);
        let trusted_share = |surface: &Surface| {
            let median = skin_median(&density, &mask, surface);
            let trust: Vec<f64> = (0..g.nx * g.ny)
                .filter_map(|k| {
                    let p = g.point_of(k);
                    let inner =
                        (p.x - 320.0).hypot(p.y - 240.0) < 0.8 * r_px * 60f64.to_radians().sin();
                    let on_skin = density.values_per_mm2[k] * surface.foreshortening(p) as f32;
                    (mask[k] && inner).then(|| contact::rim_trust(on_skin, median))
                })
                .collect();
            trust.iter().filter(|&&t| t >= 0.9).count() as f64 / trust.len() as f64
        };
        let (skin, image) = (trusted_share(&surface), trusted_share(&Surface::Flat));
        assert!(
            skin > 0.95 && image < 0.7,
            "on the skin {skin:.3}, in the image {image:.3}"
        );
    }

    #[test]
    fn bad_rest_sets_are_typed_errors() {
        let params = Params::default();
        assert_eq!(
            calibrate(&[], &params).unwrap_err(),
            CalibrationError::NoFrames
        );
        let a = GreyFrame::new(64, 48, vec![0; 64 * 48]).unwrap();
        let b = GreyFrame::new(32, 24, vec![0; 32 * 24]).unwrap();
        assert!(matches!(
            calibrate(&[a.clone(), b], &params),
            Err(CalibrationError::SizeMismatch(..))
        ));
        assert!(matches!(
            calibrate(&[a], &params),
            Err(CalibrationError::Markers(_))
        ));
    }

    /// A GelSight-like skin seen flat-on, `w x h`: dark dots of radius 6 px
    /// on a bright gel, a lattice of `pitch_px` (x, y) from `(x0, y0)`, their
    /// edges blurred as by a lens (a logistic step of scale 0.9 px, about a
    /// Gaussian PSF of 1.5 px). Returns the frame and the dots that show:
    /// those whose centre lies at most a pixel beyond the frame's edge.
    fn square_dots(
        (w, h): (usize, usize),
        (x0, y0): (f64, f64),
        pitch_px: (f64, f64),
    ) -> (GreyFrame, Vec<PointPx>) {
        let radius_px = 6.0;
        let centres: Vec<PointPx> = (0..)
            .map(|j| y0 + j as f64 * pitch_px.1)
            .take_while(|&y| y < h as f64)
            .flat_map(|y| {
                (0..)
                    .map(move |i| PointPx::new(x0 + i as f64 * pitch_px.0, y))
                    .take_while(|p| p.x < w as f64)
            })
            .collect();
        let mut data = vec![200u8; w * h];
        for (k, v) in data.iter_mut().enumerate() {
            let (x, y) = ((k % w) as f64, (k / w) as f64);
            let d = centres
                .iter()
                .map(|c| (c.x - x).hypot(c.y - y))
                .fold(f64::INFINITY, f64::min);
            let cover = 1.0 / (1.0 + ((d - radius_px) / 0.9).exp());
            *v = (200.0 - 140.0 * cover).round() as u8;
        }
        (GreyFrame::new(w, h, data).unwrap(), centres)
    }

    #[test]
    fn a_square_lattice_cut_by_the_frame_keeps_its_edge_and_corner_dots() {
        // As the GelSight Mini frames of eval/ show their skin: the top row
        // and the left column centred a pixel beyond the frame's edge (a
        // third of each dot in view), the top-left dot a tenth, on a square
        // lattice and on one a little wider than high (as the Mini's lens
        // makes it near the frame's corners). Each cut dot is a marker; the
        // corner ones were dropped as too small and as off the lattice, and
        // the cut dots' centroids, moved inwards, made the flat skin a dome.
        for pitch_px in [(32.0, 32.0), (34.0, 30.0)] {
            let (rest, dots) = square_dots((320, 240), (-1.0, -1.0), pitch_px);
            let cal = calibrate(&[rest], &Params::default()).unwrap();
            assert_eq!(cal.rest_markers.len(), dots.len(), "{pitch_px:?}");
            for d in &dots {
                assert!(
                    cal.rest_markers
                        .iter()
                        .any(|p| (p.x - d.x).abs() < 4.0 && (p.y - d.y).abs() < 4.0),
                    "{pitch_px:?}: dot {d:?}"
                );
            }
            assert_eq!(cal.surface, Surface::Flat, "{pitch_px:?}");
        }
    }
}
