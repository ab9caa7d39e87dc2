//! Stage 2, markers (Sec. III-B): Determinant-of-Hessian blob detection
//! (SURF-style box filters on an integral image), bright-blob check and
//! sub-pixel centroids.
//!
//! For a box-filter lobe `l` (odd; filter size `3l`, Gaussian-equivalent
//! sigma ~ `0.4 l`) the second derivatives at `(x, y)` are box sums over the
//! integral image `I(x, y) = sum_{x' < x, y' < y} img(x', y')`:
//! `Dyy = box(2l-1 wide, 3l tall) - 3 box(2l-1 wide, l tall)`, `Dxx` its
//! transpose, `Dxy = TL + BR - TR - BL` (four `l x l` boxes). With each
//! divided by the lobe area `l (2l - 1)`, the blob strength is
//! `sqrt(Dxx Dyy - (0.9 Dxy)^2)` (grey levels) where `Dxx < 0` and `Dyy < 0`
//! (a bright blob), else 0.
//!
//! Light: every threshold is relative to the frame's own local light (see
//! [`Detector`]): a cell grid gives the local background and marker level,
//! so markers 3x dimmer than at rest, vignetting, a light gradient, blur and
//! saturated or dimmer-coloured pins are found with the thresholds set on
//! the rest frame.
//!
//! Speed: the determinant is evaluated only at candidates, the 3x3 intensity
//! maxima of the detection image that reach the local level, and only
//! inside the calibrated search window around the sensing area. Candidates
//! whose strength passes the threshold are refined on the full-resolution
//! frame by a half-maximum intensity centroid; centroids closer than 2 px
//! are one marker; centroids outside the sensing area are dropped.
//!
//! Frames after the rest are searched only where following fails:
//! [`follow_or_search`] follows each rest marker in a small window,
//! searches for the ones it loses (moved too far, hidden or merged by a
//! contact) in boxes around their rest places, and searches the whole
//! frame when a contact lost a quarter of them, or when the followed
//! windows look like noise (`noise_like`). In those boxes, pins a press
//! squeezed into one blob are split into the two or three pins it holds
//! (`split_chain`). On a dome
//! ([`crate::surface`]) the strength threshold is eased by the
//! foreshortening, and each marker's
//! centroid window stops short of its nearest neighbour
//! ([`centroid_radii`]); where it is seen obliquely, a candidate too weak
//! at the detection scale gets a second look at full resolution and the
//! smallest lobe (the outer ring's pins nearly touch along the ring).
//!
//! The scale (lobe, and whether to detect on a 2x2-binned image for speed)
//! is found from a rest frame by [`auto_detector`]: the lobe whose
//! scale-normalised strength map peaks highest; the config can override it.
//! Markers closer than `(3l - 1) / 2` detection pixels to the image border
//! are not detected.

use crate::area::SensingArea;
use crate::frame::GreyFrame;
use crate::numeric::{collect_bounded, select_f32};
use crate::params::{MarkerParams, Polarity};
use crate::surface::Surface;
use crate::tracking::PointIndex;
use crate::PointPx;

/// Candidate full-resolution lobes for the automatic scale search.
const AUTO_LOBES_PX: [usize; 7] = [3, 5, 7, 9, 11, 13, 15];
/// Weight of `Dxy` in the determinant (SURF: box vs Gaussian filter norms).
const DXY_WEIGHT: f32 = 0.9;

/// Errors of the automatic scale search.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MarkerError {
    /// The rest frame has too few marker-like blobs to calibrate.
    #[error("rest frame has {found} marker-like blobs; need at least {needed}")]
    TooFewMarkers {
        /// Blobs found.
        found: usize,
        /// Blobs needed.
        needed: usize,
    },
    /// The frame is smaller than the box filters.
    #[error("frame {width}x{height} is too small for marker detection")]
    TooSmall {
        /// Width, px.
        width: usize,
        /// Height, px.
        height: usize,
    },
}

/// One detected marker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Marker {
    /// Sub-pixel centroid, working px.
    pub pos: PointPx,
    /// Blob strength (sqrt of the determinant of Hessian), grey levels; a
    /// marker found by [`follow`] carries its contrast instead.
    pub strength: f32,
    /// Grey level at the detection maximum (binned image when binning; 0
    /// from [`follow`]).
    pub peak: u8,
    /// Peak level over the local light: 0 at the local background, 1 at
    /// the local marker level (1 from [`follow`]).
    pub rel_level: f32,
    /// Blob strength over the local range (see [`Detector`]); from
    /// [`follow`], the contrast over the frame's median marker contrast.
    pub rel_strength: f32,
    /// Effective area above half maximum, px^2 (an LED or a reflection is
    /// several times a pin's, a dust speck a fraction).
    pub area_px: f32,
    /// The index of the marker it was followed from ([`follow`]: the rest
    /// marker), `None` from a search: a followed frame needs no matching.
    pub followed_from: Option<usize>,
}

/// The markers of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Markers {
    /// Detected markers, in raster order of their detection maxima.
    pub list: Vec<Marker>,
}

impl Markers {
    /// Number of markers.
    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// True when no marker was found.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// Marker positions.
    pub fn positions(&self) -> Vec<PointPx> {
        self.list.iter().map(|m| m.pos).collect()
    }

    /// Positions of the markers of typical size: effective area within
    /// [`SIZE_RANGE`] times the median (drops LEDs, reflections and specks
    /// from a rest frame). A marker the edge of the `width x height` frame
    /// cuts shows only part of its blob: for one cut by one edge, with at
    /// least [`CUT_MIN_STRENGTH`] of the median strength, the lower bound is
    /// halved, by two (a corner) quartered (the GelSight Mini's top corner
    /// dots, cut to a fifth of a dot, were dropped as specks, and so was a
    /// GelSlim's bottom-edge dot; BENCHMARKS.md, session 20).
    pub fn typical_positions(&self, width: usize, height: usize) -> Vec<PointPx> {
        let median = percentile(self.list.iter().map(|m| m.area_px).collect(), 0.5);
        let strong =
            CUT_MIN_STRENGTH * percentile(self.list.iter().map(|m| m.strength).collect(), 0.5);
        self.list
            .iter()
            .filter(|m| {
                // Cut: nearer the frame's edge (half a pixel beyond the
                // outer pixel centres) than its own blob's radius, as a blob
                // the edge does not cut cannot be (a speck by the edge of a
                // binarised TacTip disc is not), and strong.
                let reach_px = (m.area_px as f64 / std::f64::consts::PI).sqrt() + 0.5;
                let cut =
                    |v: f64, size: usize| v + 0.5 < reach_px || size as f64 - 0.5 - v < reach_px;
                let edges = if m.strength >= strong {
                    u8::from(cut(m.pos.x, width)) + u8::from(cut(m.pos.y, height))
                } else {
                    0
                };
                let visible = 0.5f32.powi(edges.into());
                m.area_px >= SIZE_RANGE.0 * visible * median && m.area_px <= SIZE_RANGE.1 * median
            })
            .map(|m| m.pos)
            .collect()
    }
}

/// A marker the frame's edge cuts keeps its darkness, and the mirrored
/// detection image shows its part twice: its blob strength stays near a
/// whole one's (0.7-0.8 of the median on the GelSight Mini and GelSlim rest
/// frames). A sliver of a dot beyond the edge is weak (0.17-0.21 on the
/// GelSlim rest), and is followed in one frame and lost in the next.
/// [`Markers::typical_positions`] eases its size bound only for cut markers
/// at least this strong, over the median strength.
pub const CUT_MIN_STRENGTH: f32 = 0.5;

/// A configured detector (from [`auto_detector`] or built by hand).
///
/// Its thresholds are relative to the frame's own local light: the
/// detection image is cut into cells of [`Detector::cell_px`]; each cell's
/// darkest and brightest grey level, taken over the cell and its eight
/// neighbours, are the local background `lo` and marker level `hi`. A
/// candidate must reach `lo + min_level_ratio (hi - lo)`, and its blob
/// strength divided by `hi - lo` must reach `min_rel_strength`. Dimmer
/// light, vignetting, a light gradient or blur scale `hi - lo` and the
/// strength together, so the same markers pass.
#[derive(Debug, Clone, PartialEq)]
pub struct Detector {
    /// Box-filter lobe on the detection image (odd, >= 3).
    pub lobe_px: usize,
    /// Detect on a 2x2-binned image (`2`) or at full resolution (`1`).
    pub bin: usize,
    /// A candidate peak must be at least this fraction of the way from the
    /// local background to the local marker level (0..1).
    pub min_level_ratio: f32,
    /// Minimum blob strength over the local range `hi - lo`.
    pub min_rel_strength: f32,
    /// Minimum marker contrast over the local background, grey levels; also
    /// the smallest local range `hi - lo` that can hold a marker.
    pub min_contrast: f32,
    /// Estimated marker radius, working px (sets the centroid window).
    pub radius_px: f64,
    /// Side of the light-envelope cells, detection px (about a pitch).
    pub cell_px: usize,
    /// Search only `[x0, y0, x1, y1)` (working px; `None`: the whole frame).
    /// The calibration sets it to the sensing area plus a margin.
    pub window_px: Option<[usize; 4]>,
    /// Keep only markers inside this area (`None`: all). The calibration
    /// sets it (see [`crate::area`]).
    pub area: Option<SensingArea>,
    /// Where the outer markers may be pushed beyond `area` (`None`: nowhere;
    /// the calibration sets it with an area found from the rest lattice).
    pub rim: Option<RimBand>,
    /// Dark markers on a bright skin (GelSight-type dots): the frame is
    /// inverted before detection.
    pub dark: bool,
    /// The skin's shape: on a dome, the strength threshold of a candidate
    /// is scaled by the foreshortening `cos(theta)` where it lies (the outer
    /// rings' thin ellipses give a weaker blob response). The calibration
    /// sets it.
    pub surface: Surface,
}

/// The band beyond an automatic sensing area into which a contact pushes
/// the outer markers (a deep tap on a real TacTip moves its outer ring
/// nearly a pitch past the area; see [`crate::area::RIM_TRAVEL_PITCH`]).
/// The housing's own blobs sit there too (LEDs, dust, reflections on a
/// bezel, debris), but they do not move, and where they are the rest frame
/// is bright; a pushed-out pin lands where the rest frame shows dark skin.
/// A detection in the band is kept only when it is the size of a pin and
/// the rest frame was dark where it lies.
#[derive(Debug, Clone, PartialEq)]
pub struct RimBand {
    /// The sensing area and the band together.
    pub outer: SensingArea,
    /// The band's pixels that are bright on the rest frame: at least half
    /// way from the skin's level to the rest markers' (see
    /// [`crate::calibrate`]).
    pub bright_at_rest: SensingArea,
    /// Effective area range of a pin, px^2 ([`SIZE_RANGE`] times the rest
    /// markers' median).
    pub pin_area_px: [f32; 2],
}

impl Detector {
    /// Whether a marker may lie at `p`: inside the sensing area or its rim
    /// band (followed markers; a search's first guess).
    fn may_hold(&self, p: PointPx) -> bool {
        match (&self.area, &self.rim) {
            (None, _) => true,
            (Some(a), None) => a.contains(p),
            (Some(a), Some(rim)) => a.contains(p) || rim.outer.contains(p),
        }
    }

    /// Whether a searched marker at `p` with effective area `area_px` is
    /// kept: inside the sensing area, or a pin-sized blob in the rim band
    /// where the rest frame was dark ([`RimBand`]).
    fn keeps(&self, p: PointPx, area_px: f32) -> bool {
        match (&self.area, &self.rim) {
            (None, _) => true,
            (Some(a), _) if a.contains(p) => true,
            (Some(_), None) => false,
            (Some(_), Some(rim)) => {
                rim.outer.contains(p)
                    && (rim.pin_area_px[0]..=rim.pin_area_px[1]).contains(&area_px)
                    && !rim.bright_at_rest.contains(p)
            }
        }
    }
}

/// A candidate whose DoH strength reaches this fraction of the threshold
/// at its brightest pixel inside the sensing area is looked at once more at
/// its blob's centroid ([`detect`]): a glint off a pin's middle holds the
/// brightest pixel. On the raw-looking TacTip taps (BENCHMARKS.md, "After
/// session 13") pins lit so were missed whole (1-4 per frame on the deep
/// sheared taps). Measured and not kept: outside the area (the rim band)
/// the blobs so found were debris, 1-3 more per frame on the franka taps;
/// and every failing candidate (a glint on the pin's very edge, where the
/// Hessian is not negative definite and the strength is 0) admitted the
/// fragments of franka's binarised pins: its counts within ±1 % fell from
/// 80 % of the frames to 50 %.
const GLINT_RETRY: f32 = 0.5;

/// A local range below this fraction of the frame's typical (75th
/// percentile) cell range holds no marker: it is flat skin, housing or
/// noise. Vignetting to 0.45 and a 30 % gradient stay well above it.
const RANGE_FLOOR_FRACTION: f32 = 0.2;

/// The frame with bright markers: itself, or its negative for dark ones.
pub(crate) fn positive(frame: &GreyFrame, dark: bool) -> std::borrow::Cow<'_, GreyFrame> {
    if dark {
        std::borrow::Cow::Owned(frame.inverted())
    } else {
        std::borrow::Cow::Borrowed(frame)
    }
}

/// Stage 2 entry: detects the markers of a working frame.
pub fn detect(frame: &GreyFrame, det: &Detector) -> Markers {
    let frame = &*positive(frame, det.dark);
    let window = det
        .window_px
        .unwrap_or([0, 0, frame.width(), frame.height()]);
    Markers {
        list: detect_in(frame, det, window, None),
    }
}

/// [`detect`] on a frame with bright markers ([`positive`]), searching only
/// `[x0, y0, x1, y1)` (working px; clamped to the frame). `typical_range`:
/// the frame's typical local range ([`Envelope::new`]) when the window is
/// too small to measure it.
fn detect_in(
    frame: &GreyFrame,
    det: &Detector,
    window: [usize; 4],
    typical_range: Option<f32>,
) -> Vec<Marker> {
    detect_split_in(frame, det, window, typical_range, None, &mut Vec::new())
}

/// What [`detect_split_in`] needs to split blobs of several pins: the
/// frame's typical pin effective area and the lattice's pitch.
#[derive(Debug, Clone, Copy)]
struct PinScale {
    area_px: f32,
    pitch_px: f64,
}

/// [`detect_in`], and with `scale` (a pin's effective area in this frame,
/// the lattice pitch) a candidate whose blob holds two or three touching
/// pins ([`split_chain`]), or two that a blur ran into one blob
/// ([`split_blurred_pair`]), gives those, in `chains`, instead of one
/// marker between them or none.
fn detect_split_in(
    frame: &GreyFrame,
    det: &Detector,
    window: [usize; 4],
    typical_range: Option<f32>,
    scale: Option<PinScale>,
    chains: &mut Vec<Vec<Marker>>,
) -> Vec<Marker> {
    let (fw, fh) = (frame.width(), frame.height());
    let first_chain = chains.len();
    let [x0, y0, x1, y1] = window;
    let (x1, y1) = (x1.min(fw), y1.min(fh));
    let (x0, y0) = (x0.min(x1), y0.min(y1));
    let sub;
    let (img, w, h, bin) = if det.bin == 2 && x1 - x0 >= 2 && y1 - y0 >= 2 {
        sub = bin2(frame, x0, y0, (x1 - x0) / 2, (y1 - y0) / 2);
        (&sub[..], (x1 - x0) / 2, (y1 - y0) / 2, 2)
    } else if (x0, y0, x1, y1) == (0, 0, fw, fh) {
        (frame.data(), fw, fh, 1)
    } else {
        sub = crop(frame, x0, y0, x1 - x0, y1 - y0);
        (&sub[..], x1 - x0, y1 - y0, 1)
    };
    let lobe = det.lobe_px.max(3) | 1;
    let margin = (3 * lobe - 1) / 2;
    // Where the window reaches the frame's edge, the detection image is
    // mirrored outwards by the filter margin and one pixel, so that a pin
    // the edge cuts (a deep tap pushes the outer ring out of view) is still
    // a blob, with its peak on either side of the edge.
    let at_edge = |at: bool, n: usize| if at { (margin + 1).min(n) } else { 0 };
    let pad = [
        at_edge(x0 == 0, w),
        at_edge(y0 == 0, h),
        at_edge(x1 == fw, w),
        at_edge(y1 == fh, h),
    ];
    let padded;
    let (img, w, h) = if pad == [0; 4] || w == 0 || h == 0 {
        (img, w, h)
    } else {
        padded = mirror_pad(img, w, h, pad);
        (&padded[..], w + pad[0] + pad[2], h + pad[1] + pad[3])
    };
    if w <= 2 * margin + 2 || h <= 2 * margin + 2 {
        return Vec::new();
    }
    let env = Envelope::new(img, w, h, det.cell_px, det.min_contrast, typical_range);
    let ii = integral(img, w, h);
    let mut taken = Occupancy::new([x0, y0, x1, y1]);
    let mut list = Vec::new();
    // Per marker of `list`, whether only the fine determinant found it.
    let mut found_squeezed: Vec<bool> = Vec::new();
    // A padded pixel's place is the nearest one of the window.
    let (inner_w, inner_h) = (w - pad[0] - pad[2], h - pad[1] - pad[3]);
    let to_work = |x: usize, y: usize| {
        let x = x.saturating_sub(pad[0]).min(inner_w - 1);
        let y = y.saturating_sub(pad[1]).min(inner_h - 1);
        PointPx::new(
            (x0 + x * bin) as f64 + (bin as f64 - 1.0) / 2.0,
            (y0 + y * bin) as f64 + (bin as f64 - 1.0) / 2.0,
        )
    };
    // A working-frame point's pixel of the detection image, where the
    // determinant can be taken (as far from its edges as a peak).
    let to_img = |p: PointPx| -> Option<(usize, usize)> {
        let off = (bin as f64 - 1.0) / 2.0;
        let x = ((p.x - x0 as f64 - off) / bin as f64).round() + pad[0] as f64;
        let y = ((p.y - y0 as f64 - off) / bin as f64).round() + pad[1] as f64;
        let inside = |v: f64, n: usize| v >= margin.max(1) as f64 && v < (n - margin.max(1)) as f64;
        (inside(x, w) && inside(y, h)).then_some((x as usize, y as usize))
    };
    for (x, y, peak) in bright_peaks(img, w, h, margin, &env, det.min_level_ratio) {
        let (_, range) = env.at(x, y);
        let tol = (PLATEAU_TOLERANCE * range).min(255.0) as u8;
        let (x, y) = plateau_centre(img, (w, h), (x, y), margin, tol, 3 * lobe);
        let (lo, range) = env.at(x, y);
        let guess = to_work(x, y);
        let need = |p: PointPx| det.min_rel_strength * range * det.surface.foreshortening(p) as f32;
        // Pins a press squeezed into one blob: the DoH sees a ridge (no
        // marker) or one blob between two (a marker on neither). The
        // candidate's centroid, when measured here, is used again below.
        let mut first_centroid = None;
        if let Some(PinScale {
            area_px: pin_area_px,
            pitch_px,
        }) = scale.filter(|_| det.may_hold(guess))
        {
            let blob = refine(frame, guess, det.radius_px, det.min_contrast);
            first_centroid = Some((guess, blob));
            let half_maximum = (lo + 0.5 * range).clamp(1.0, 255.0) as u8;
            if let Some(pins) = blob
                .filter(|b| b.2 >= CHAIN_MIN_WINDOW_AREA * pin_area_px)
                .and_then(|b| {
                    split_chain(frame, b.0, half_maximum, pin_area_px).or_else(|| {
                        let (near, far) = BLURRED_PAIR_PITCHES;
                        let range_px = (near * pitch_px, far * pitch_px);
                        split_blurred_pair(frame, b.0, lo, half_maximum, pin_area_px, range_px)
                            .map(Vec::from)
                    })
                })
            {
                let pin = |pos: PointPx| Marker {
                    pos,
                    strength: need(pos),
                    peak,
                    rel_level: (peak as f32 - lo) / range,
                    rel_strength: need(pos) / range,
                    area_px: pin_area_px,
                    followed_from: None,
                };
                if pins.iter().all(|&p| det.keeps(p, pin_area_px)) {
                    chains.push(pins.into_iter().map(pin).collect());
                }
                continue;
            }
        }
        let mut strength = determinant_at(&ii, w + 1, x, y, lobe).sqrt();
        // Found only by the fine determinant at its centroid (below).
        let mut squeezed = false;
        if strength < need(guess)
            && (bin > 1 || lobe > FINE_LOBE_PX)
            && det.surface.foreshortening(guess) < FINE_MAX_FORESHORTENING
        {
            // Too weak a blob at this scale, or a ridge. Where the pins of
            // a dome's outer ring, foreshortened to half their width,
            // nearly touch along the ring, the binned lobes span two of
            // them; at full resolution and the smallest lobe each is a
            // blob again (on the other renderer's domes 2-4 of the outer
            // ring's pins were missed at rest, and so in every frame).
            strength = strength.max(fine_determinant(frame, guess).unwrap_or(0.0));
        }
        if strength < need(guess) && (bin > 1 || lobe > FINE_LOBE_PX) {
            // A pin a press squeezed against its neighbour (the ring of
            // crowded pins around a dent): the coarse lobes take in the
            // neighbour and the determinant vanishes; at full resolution,
            // at the blob's centroid, it is a blob again. Only in a local
            // search, where the centroid was taken (on the other renderer's
            // harsh light, a clear pin 37 px from a dent's centre had a
            // determinant of 0; its hole moved the centre 5 px,
            // BENCHMARKS.md, session 30).
            if let Some((_, Some((c, _, _)))) = first_centroid {
                let fine = fine_determinant(frame, c).unwrap_or(0.0);
                squeezed = fine >= need(guess);
                strength = strength.max(fine);
            }
        }
        let (strength, guess) = if strength >= need(guess) {
            (strength, guess)
        } else if strength >= GLINT_RETRY * need(guess)
            && det.area.as_ref().is_none_or(|a| a.contains(guess))
        {
            // A glint off a pin's middle (real TacTip pins) is its brightest
            // pixel, where the DoH is weak: look once more at the blob's
            // centroid.
            let Some((x, y)) = refine(frame, guess, det.radius_px, det.min_contrast)
                .and_then(|(p, _, _)| to_img(p))
            else {
                continue;
            };
            let strength = determinant_at(&ii, w + 1, x, y, lobe).sqrt();
            let guess = to_work(x, y);
            if strength < need(guess) {
                continue;
            }
            (strength, guess)
        } else {
            continue;
        };
        if !det.may_hold(guess) {
            continue;
        }
        // A saturated marker's candidate is its plateau's first pixel, off
        // the centre: one more pass from the first centroid re-centres the
        // window on the blob.
        let first = match first_centroid {
            Some((at, blob)) if at == guess => blob,
            _ => refine(frame, guess, det.radius_px, det.min_contrast),
        };
        let refined = first.and_then(|r| {
            let p = r.0;
            if (p.x - guess.x).abs().max((p.y - guess.y).abs()) > RECENTRE_PX {
                refine(frame, p, det.radius_px, det.min_contrast)
            } else {
                Some(r)
            }
        });
        if let Some((pos, _, area_px)) = refined {
            if !det.keeps(pos, area_px) {
                continue;
            }
            if taken.claim(pos, DUPLICATE_PX, &list) {
                list.push(Marker {
                    pos,
                    strength,
                    peak,
                    rel_level: (peak as f32 - lo) / range,
                    rel_strength: strength / range,
                    area_px,
                    followed_from: None,
                });
                found_squeezed.push(squeezed);
            }
        }
    }
    // A blob found only at full resolution is a pin on its own: beside
    // another marker (a second candidate of an enlarged pin, whose window
    // put its centroid 2-3 px off the first) it is that marker's.
    if let Some(PinScale { pitch_px, .. }) = scale.filter(|_| found_squeezed.contains(&true)) {
        let alone2 = (SQUEEZED_ALONE_PITCH * pitch_px).powi(2);
        let beside: Vec<bool> = list
            .iter()
            .zip(&found_squeezed)
            .map(|(m, &sq)| {
                sq && list.iter().zip(&found_squeezed).any(|(o, &o_sq)| {
                    !o_sq && (o.pos.x - m.pos.x).powi(2) + (o.pos.y - m.pos.y).powi(2) < alone2
                })
            })
            .collect();
        drop_marked(&mut list, &beside);
    }
    // A marker between two pins of a split blob (a candidate of the same
    // blob whose window saw too little of it to split) is neither.
    let between: Vec<(PointPx, f64)> = chains[first_chain..]
        .iter()
        .flat_map(|pins| pins.windows(2).map(|p| between_pins(p[0].pos, p[1].pos)))
        .collect();
    if !between.is_empty() {
        list.retain(|m| {
            between
                .iter()
                .all(|&(c, r)| (m.pos.x - c.x).powi(2) + (m.pos.y - c.y).powi(2) > r * r)
        });
    }
    list
}

/// The middle of two touching pins `a` and `b`, and how near it a marker
/// sees both of them (a quarter of their distance), px.
fn between_pins(a: PointPx, b: PointPx) -> (PointPx, f64) {
    let mid = PointPx::new(0.5 * (a.x + b.x), 0.5 * (a.y + b.y));
    (mid, 0.25 * (a.x - b.x).hypot(a.y - b.y))
}

/// Markers found by following known markers instead of searching the
/// frame: each of `near` (usually the rest markers) is refined by the
/// half-maximum centroid in a small window around it, re-centred up to
/// [`FOLLOW_PASSES`] times, in a window of its radius in `radii_px`
/// ([`centroid_radii`]; the detector's for markers past the slice's end).
/// `None` (search the whole frame with [`detect`]
/// instead) when more than [`FOLLOW_MAX_LOST`] of them are lost: moved more
/// than `reach_px`, faded, or merged with another. Faded: its contrast,
/// over its own contrast at rest in `contrast` (the calibration's
/// [`crate::calibrate::Calibration::rest_contrast`]; 1 past the slice's
/// end), is below [`FOLLOW_MIN_CONTRAST`] of the frame's median of that
/// ratio (or below the detector's absolute floor): a dot dimmed by
/// vignetting at rest is not faded as long as it keeps its own contrast.
/// A frame without contact costs one window per marker instead of a pass
/// over every pixel.
pub fn follow(
    frame: &GreyFrame,
    det: &Detector,
    near: &[PointPx],
    radii_px: &[f64],
    contrast: &[f32],
    reach_px: f64,
) -> Option<Markers> {
    let frame = &*positive(frame, det.dark);
    let max_lost = (FOLLOW_MAX_LOST * near.len() as f64).floor() as usize;
    let rest = Reference {
        at: near,
        radii_px,
        contrast,
        gaps_px: &[],
        rivals: None,
        blur: None,
        neighbours: None,
    };
    let list = follow_each(frame, det, &rest, true, reach_px, max_lost)?;
    Some(Markers {
        list: list.into_iter().flatten().collect(),
    })
}

/// What each of `near` is followed to in `frame` ([`follow`], nothing
/// given up, and no marker called faded: the rest frames are where each
/// marker's own contrast is measured): `None` for the lost ones (its
/// [`Marker::strength`] is its contrast, grey levels). The calibration
/// settles the rest markers with it, so that a followed frame without
/// contact finds them where the rest says, and records their contrast.
pub fn follow_all(
    frame: &GreyFrame,
    det: &Detector,
    near: &[PointPx],
    radii_px: &[f64],
    reach_px: f64,
) -> Vec<Option<Marker>> {
    let frame = &*positive(frame, det.dark);
    let rest = Reference {
        at: near,
        radii_px,
        contrast: &[],
        gaps_px: &[],
        rivals: None,
        blur: None,
        neighbours: None,
    };
    follow_each(frame, det, &rest, false, reach_px, usize::MAX)
        .unwrap_or_else(|| vec![None; near.len()])
}

/// How [`follow_or_search`] found a frame's markers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    /// Every marker was followed in its own window (none lost; without a
    /// local search, at most [`FOLLOW_MAX_LOST`]).
    Followed,
    /// The markers were followed, and the lost ones (at most
    /// [`LOCAL_MAX_LOST`]) searched for in boxes around their rest places
    /// (`search_around`).
    Local,
    /// The whole frame was searched.
    Full,
    /// Too many markers were lost for a local search (or its boxes covered
    /// too much of the frame): the whole frame was searched and its markers
    /// paired with the rest markers, from those still near their rest
    /// places outwards through their neighbours' displacements
    /// (`pair_detected`).
    Paired,
    /// The caller gave each rest marker's place
    /// ([`crate::pipeline::Pipeline::run_on_field`]).
    Given,
}

/// Fraction of followed markers that may be lost for the frame to be
/// searched only around them ([`Search::Local`]); beyond it the whole frame
/// is searched.
pub const LOCAL_MAX_LOST: f64 = 0.25;
/// The boxes of a local search may cover at most this fraction of the
/// detector's search window; beyond it the whole frame is searched (it
/// costs no more).
pub const LOCAL_MAX_AREA: f64 = 0.5;

/// What following and searching a frame need of the rest (the
/// calibration's, [`crate::calibrate::Calibration::reference`]).
#[derive(Debug, Clone, Copy)]
pub struct Reference<'a> {
    /// The rest markers, working px.
    pub at: &'a [PointPx],
    /// Per rest marker, its centroid window's radius ([`centroid_radii`]).
    pub radii_px: &'a [f64],
    /// Per rest marker, its contrast at rest ([`follow`]).
    pub contrast: &'a [f32],
    /// Places inside the rest lattice with no rest marker (pins missing at
    /// rest): searched whenever the lost markers are.
    pub gaps_px: &'a [PointPx],
    /// The rest markers' [`Rivals`] (without them, or for a wider reach,
    /// following tests for two markers in one blob on a grid).
    pub rivals: Option<&'a Rivals>,
    /// Where blur moves each rest marker's centroid ([`BlurLevels`]): a
    /// followed marker may also lie within the reach of its path.
    pub blur: Option<&'a BlurLevels>,
    /// Each rest marker's [`Neighbours`] (without them, the local search
    /// finds them itself).
    pub neighbours: Option<&'a Neighbours>,
}

impl Reference<'_> {
    /// The rest markers' [`Neighbours`]: the calibration's, or (without
    /// them, or for other markers) found here for a pitch of `pitch_px`.
    fn neighbours_or_new(&self, pitch_px: f64) -> std::borrow::Cow<'_, Neighbours> {
        match self.neighbours.filter(|n| n.covers(self.at.len())) {
            Some(n) => std::borrow::Cow::Borrowed(n),
            None => std::borrow::Cow::Owned(Neighbours::new(self.at, pitch_px)),
        }
    }
}

/// Per rest marker, the other rest markers within [`NEIGHBOUR_PITCH`]
/// pitches: whose displacements predict its place when the local search
/// pairs it ([`follow_or_search`]). Computed once at calibration.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Neighbours {
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl Neighbours {
    /// The neighbours among `near`, a pitch of `pitch_px` apart.
    pub fn new(near: &[PointPx], pitch_px: f64) -> Self {
        let within_px = NEIGHBOUR_PITCH * pitch_px.max(0.0);
        let index = PointIndex::spanning(near, within_px);
        let mut starts = Vec::with_capacity(near.len() + 1);
        let mut items = Vec::new();
        starts.push(0);
        for (k, &p) in near.iter().enumerate() {
            items.extend(
                index
                    .within(near, p, within_px)
                    .filter(|&(n, _)| n != k)
                    .map(|(n, _)| n as u32),
            );
            starts.push(items.len() as u32);
        }
        Self { starts, items }
    }

    /// Rest marker `k`'s neighbours (none past the lists' end).
    pub fn of(&self, k: usize) -> &[u32] {
        match (self.starts.get(k), self.starts.get(k + 1)) {
            (Some(&a), Some(&b)) => &self.items[a as usize..b as usize],
            _ => &[],
        }
    }

    /// Whether the lists are for `n` rest markers.
    fn covers(&self, n: usize) -> bool {
        self.starts.len() == n + 1
    }
}

/// Per rest marker, the earlier rest markers (lower index) whose followed
/// markers could run into the same blob as its own: rest places within
/// `2 reach + DUPLICATE_PX` of each other, for a follow reach up to
/// `reach_px`, plus how far beyond it each may travel (along its
/// [`BlurPath`]). Computed once at calibration: a frame's test for two
/// followed markers in one blob then looks at those few (none, on most
/// lattices) instead of clearing and filling a frame-sized grid (whose
/// claims took 0.02-0.03 ms of a frame on the other renderer's domes,
/// BENCHMARKS.md, session 16).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rivals {
    /// The largest follow reach the lists hold for, px.
    pub reach_px: f64,
    /// Per rest marker, its earlier rivals.
    pub earlier: Vec<Vec<u32>>,
}

impl Rivals {
    /// The rivals among `near` for a follow reach of `reach_px`, each of
    /// them able to travel `travel_px` further (0 past the slice's end).
    pub fn new(near: &[PointPx], reach_px: f64, travel_px: &[f64]) -> Self {
        let travel = |k: usize| {
            travel_px
                .get(k)
                .copied()
                .filter(|t| t.is_finite())
                .unwrap_or(0.0)
                .max(0.0)
        };
        let within_px = 2.0 * reach_px.max(0.0) + DUPLICATE_PX;
        let most_px = within_px + 2.0 * (0..near.len()).map(travel).fold(0.0, f64::max);
        let index = PointIndex::spanning(near, most_px);
        let earlier = (0..near.len())
            .map(|k| {
                let mut e: Vec<u32> = index
                    .within(near, near[k], most_px)
                    .filter(|&(n, d2)| n < k && d2.sqrt() <= within_px + travel(n) + travel(k))
                    .map(|(n, _)| n as u32)
                    .collect();
                e.sort_unstable();
                e
            })
            .collect();
        Self { reach_px, earlier }
    }

    /// Whether the lists serve `n` rest markers followed within `reach_px`.
    fn covers(&self, n: usize, reach_px: f64) -> bool {
        self.earlier.len() == n && reach_px <= self.reach_px
    }
}

/// The added blur (Gaussian sigma, px) of the levels the rest is measured
/// under again ([`BlurLevels`]): frames up to 3 px blurrier than the rest.
pub const BLUR_LEVELS_PX: [f64; 6] = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0];
/// [`BlurLevels::fit`] tries the added blurs from 0 to the last level in
/// steps of this, px.
pub const BLUR_FIT_STEP_PX: f64 = 0.25;
/// [`BlurLevels::fit`] takes a blur only where it explains the gauges'
/// displacements: their median squared distance from its shifts is below
/// this fraction of their median squared displacement, and their median
/// distance from its shifts at most [`BLUR_MAX_RESIDUAL_PX`]. Measured
/// (BENCHMARKS.md, session 17): on the other renderer's blurred frames
/// (PSF 1.8-2.8 px against 1 px at rest) the fraction was 0.002-0.34 and
/// the distance 0.03-0.56 px; on its nominal frames (PSF 0.9-1.1 px) the
/// fraction was 0.65-1.0 (left as they are); the real TacTip taps (rest
/// from the frames) had 18 of 200 frames with a fraction of 0.15-0.99 and
/// a distance of 1.5-4.3 px: a deep tap that moves most gauges also fits
/// some blur better than none.
pub const BLUR_MIN_GAIN: f64 = 0.5;
/// See [`BLUR_MIN_GAIN`], px.
pub const BLUR_MAX_RESIDUAL_PX: f64 = 1.0;
/// A marker that the frame's blur moves this far or further
/// ([`BlurLevels::shifts_at`]) is left out of the frame's displacement
/// field, px: where blur makes the outer ring's blobs run together, how
/// far it moves each centroid changes with the frame's noise. On the other
/// renderer's dome, still frames with a PSF of 2.5-3 px (1 px at rest) kept
/// outliers of 2.4-4.2 px after the shifts were taken off, and 3 of 8 still
/// frames at 2.6-2.7 px had a false contact from them (BENCHMARKS.md,
/// session 17).
pub const BLUR_UNSURE_SHIFT_PX: f64 = 1.0;
/// [`BlurLevels::fit`] fits no blur when the gauges moved less than this
/// (median), px: no blur that moves them less matters.
pub const BLUR_MIN_MOVE_PX: f64 = 0.25;
/// A rest marker is a blur gauge when the blurriest level moves its
/// centroid at least this far, px.
pub const BLUR_GAUGE_MIN_SHIFT_PX: f64 = 0.5;
/// Most blur gauges: the rest markers the blurriest level moves furthest.
pub const BLUR_GAUGES: usize = 64;
/// With fewer gauges than this the lattice's centroids do not move with
/// blur: no level is fitted.
pub const BLUR_MIN_GAUGES: usize = 8;

/// Where blur puts the rest markers' centroids. A centroid window holds
/// part of a close neighbour's blob once the frame is blurrier than the
/// rest, so on a dome's crowded outer rings a still marker's centroid moves
/// with the blur alone: on the other renderer's dome, 0.5-1.7 px (median)
/// and up to 5.7 px for the outermost ring 2-2.5 px blurrier than the rest
/// (BENCHMARKS.md, session 17), all read as displacement. Calibration follows
/// the rest markers on the rest frame blurred by each of
/// [`BLUR_LEVELS_PX`]; a frame's blur is the level whose shifts best explain
/// the gauges' displacements ([`BlurLevels::fit`]), and its shifts are taken
/// off the frame's displacements.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BlurLevels {
    /// Per level of [`BLUR_LEVELS_PX`] (all, or none), per rest marker:
    /// where following finds it on the blurred rest frame, from its rest
    /// place, px (zero where following loses it).
    pub shift_px: Vec<Vec<PointPx>>,
    /// The gauges ([`BLUR_GAUGES`] at most, each moved at least
    /// [`BLUR_GAUGE_MIN_SHIFT_PX`] by the blurriest level), by rest index;
    /// empty below [`BLUR_MIN_GAUGES`].
    pub gauges: Vec<usize>,
    /// Per rest marker, its place in `gauges` (`u8::MAX`: none).
    pub slot: Vec<u8>,
    /// Per added blur [`BLUR_FIT_STEP_PX`] apart from 0, per gauge, its
    /// shift ([`BlurLevels::shifts_at`]).
    pub gauge_shift_px: Vec<Vec<PointPx>>,
}

/// Where blur moves one rest marker's centroid: its shifts at each of
/// [`BLUR_LEVELS_PX`], from its rest place (none at no added blur).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlurPath {
    at: [PointPx; BLUR_LEVELS_PX.len()],
}

impl BlurPath {
    /// True when `off` (from the rest place) lies within `reach_px` of the
    /// path: the segments from no shift through each level's.
    pub fn within(&self, off: PointPx, reach_px: f64) -> bool {
        let mut from = PointPx::default();
        self.at.iter().any(|&to| {
            let (dx, dy) = (to.x - from.x, to.y - from.y);
            let len2 = dx * dx + dy * dy;
            let t = if len2 > 0.0 {
                (((off.x - from.x) * dx + (off.y - from.y) * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let (ex, ey) = (off.x - from.x - t * dx, off.y - from.y - t * dy);
            from = to;
            ex * ex + ey * ey <= reach_px * reach_px
        })
    }

    /// The path's length, px.
    pub fn length_px(&self) -> f64 {
        let mut from = PointPx::default();
        self.at
            .iter()
            .map(|&to| {
                let d = (to.x - from.x).hypot(to.y - from.y);
                from = to;
                d
            })
            .sum()
    }
}

impl BlurLevels {
    /// Follows the rest markers `at` (each in its window of `radii_px`, or
    /// the detector's past its end, within `reach_px`) on `rest` blurred by
    /// each level.
    pub fn measure(
        rest: &GreyFrame,
        det: &Detector,
        at: &[PointPx],
        radii_px: &[f64],
        reach_px: f64,
    ) -> Self {
        let rest = positive(rest, det.dark);
        let shift_px: Vec<Vec<PointPx>> = BLUR_LEVELS_PX
            .iter()
            .map(|&sigma_px| {
                let blurred = rest.blurred(sigma_px);
                at.iter()
                    .enumerate()
                    .map(|(k, &p)| {
                        let radius_px = radii_px.get(k).copied().unwrap_or(det.radius_px);
                        follow_one(&blurred, p, radius_px, det.min_contrast, reach_px, None)
                            .map_or(PointPx::default(), |(c, _, _)| {
                                PointPx::new(c.x - p.x, c.y - p.y)
                            })
                    })
                    .collect()
            })
            .collect();
        Self::from_shifts(shift_px)
    }

    /// Rest marker `k`'s shifts at the levels, from the sharpest (`None`
    /// without levels, or past the last marker).
    pub fn path(&self, k: usize) -> Option<BlurPath> {
        let mut at = [PointPx::default(); BLUR_LEVELS_PX.len()];
        if self.shift_px.len() != at.len() {
            return None;
        }
        for (a, level) in at.iter_mut().zip(&self.shift_px) {
            *a = *level.get(k)?;
        }
        Some(BlurPath { at })
    }

    /// The levels of `shift_px` (per level of [`BLUR_LEVELS_PX`], per rest
    /// marker, its shift), with their gauges.
    pub fn from_shifts(shift_px: Vec<Vec<PointPx>>) -> Self {
        let n = shift_px.first().map_or(0, Vec::len);
        let moved = |k: usize| {
            shift_px
                .last()
                .and_then(|s| s.get(k))
                .map_or(0.0, |s| s.x.hypot(s.y))
        };
        let mut gauges: Vec<usize> = (0..n)
            .filter(|&k| moved(k) >= BLUR_GAUGE_MIN_SHIFT_PX)
            .collect();
        gauges.sort_by(|&a, &b| moved(b).total_cmp(&moved(a)).then(a.cmp(&b)));
        gauges.truncate(BLUR_GAUGES);
        if gauges.len() < BLUR_MIN_GAUGES {
            gauges.clear();
        }
        let mut slot = vec![u8::MAX; n];
        for (g, &k) in gauges.iter().enumerate() {
            // BLUR_GAUGES < u8::MAX.
            slot[k] = g as u8;
        }
        let mut levels = Self {
            shift_px,
            gauges,
            slot,
            gauge_shift_px: Vec::new(),
        };
        let last = BLUR_LEVELS_PX[BLUR_LEVELS_PX.len() - 1];
        levels.gauge_shift_px = (0..=(last / BLUR_FIT_STEP_PX).round() as usize)
            .map(|i| {
                let shift = levels.shifts_at(i as f64 * BLUR_FIT_STEP_PX);
                levels.gauges.iter().map(|&k| shift(k)).collect()
            })
            .collect();
        levels
    }

    /// The shift of each rest marker (by index) at an added blur of
    /// `sigma_px`: linear between the levels, zero at no added blur, the
    /// last level's beyond it.
    pub fn shifts_at(&self, sigma_px: f64) -> impl Fn(usize) -> PointPx + '_ {
        let levels = &BLUR_LEVELS_PX[..BLUR_LEVELS_PX.len().min(self.shift_px.len())];
        // The levels either side (`None`: no added blur, or none beyond)
        // and the fraction of the way from the lower.
        let (lo, hi, t) = match levels.iter().position(|&s| sigma_px <= s) {
            Some(0) => (None, Some(0), sigma_px / levels[0]),
            Some(j) => (
                Some(j - 1),
                Some(j),
                (sigma_px - levels[j - 1]) / (levels[j] - levels[j - 1]),
            ),
            None => (levels.len().checked_sub(1), None, 0.0),
        };
        let t = t.clamp(0.0, 1.0);
        move |k| {
            let at = |l: Option<usize>| {
                l.and_then(|l| self.shift_px[l].get(k).copied())
                    .unwrap_or_default()
            };
            let (a, b) = (at(lo), at(hi));
            PointPx::new(a.x + t * (b.x - a.x), a.y + t * (b.y - a.y))
        }
    }

    /// The added blur (px) whose shifts best explain the gauges'
    /// displacements in `markers` (the followed ones of `rest`'s markers),
    /// and the gauges' median distance from its shifts (px):
    /// the least median squared distance between the two, trying every
    /// [`BLUR_FIT_STEP_PX`] from 0 to the last level. `None` when the rest's
    /// markers do not move with blur (no gauges, or levels made for another
    /// rest), when fewer than half the gauges were followed, when they
    /// hardly moved ([`BLUR_MIN_MOVE_PX`]), or when no added blur fits best,
    /// or not well enough ([`BLUR_MIN_GAIN`]). A contact moves a few
    /// gauges; the median ignores them.
    pub fn fit(&self, rest: &[PointPx], markers: &[Marker]) -> Option<(f64, f64)> {
        if self.gauges.is_empty() || self.slot.len() != rest.len() {
            return None;
        }
        let mut seen = vec![None; self.gauges.len()];
        for m in markers {
            let Some(k) = m.followed_from else { continue };
            if let (Some(&slot), Some(r)) = (self.slot.get(k), rest.get(k)) {
                if let Some(s) = seen.get_mut(slot as usize) {
                    *s = Some(PointPx::new(m.pos.x - r.x, m.pos.y - r.y));
                }
            }
        }
        let seen: Vec<(usize, PointPx)> = seen
            .into_iter()
            .enumerate()
            .filter_map(|(g, u)| Some((g, u?)))
            .filter(|(_, u)| u.is_finite())
            .collect();
        if 2 * seen.len() < self.gauges.len() {
            return None;
        }
        let mut d2 = Vec::with_capacity(seen.len());
        let (mut best, mut best_cost, mut sharp_cost) = (0, f64::INFINITY, f64::INFINITY);
        for (step, shifts) in self.gauge_shift_px.iter().enumerate() {
            d2.clear();
            d2.extend(seen.iter().map(|&(g, u)| {
                let s = shifts.get(g).copied().unwrap_or_default();
                (u.x - s.x).powi(2) + (u.y - s.y).powi(2)
            }));
            let mid = d2.len() / 2;
            let cost = *d2.select_nth_unstable_by(mid, f64::total_cmp).1;
            if step == 0 {
                // Gauges that barely moved: whatever blur there is, it is
                // too little to matter (most frames stop here).
                if cost < BLUR_MIN_MOVE_PX * BLUR_MIN_MOVE_PX {
                    return None;
                }
                sharp_cost = cost;
            }
            // Ties go to the lesser blur.
            if cost < best_cost {
                (best, best_cost) = (step, cost);
            }
        }
        (best > 0
            && best_cost < BLUR_MIN_GAIN * sharp_cost
            && best_cost <= BLUR_MAX_RESIDUAL_PX * BLUR_MAX_RESIDUAL_PX)
            .then_some((best as f64 * BLUR_FIT_STEP_PX, best_cost.sqrt()))
    }
}

/// The markers of a frame: followed from the rest markers `rest.at`
/// ([`follow`]). With `local_pitch_px`, the markers following loses (a
/// contact moved, merged or hid them; at most [`LOCAL_MAX_LOST`] of them)
/// are searched for around their rest places, and so are the rest's gaps
/// (`search_around`, boxes reaching one `local_pitch_px` beyond them);
/// without it, up to [`FOLLOW_MAX_LOST`] lost markers are left out.
/// Otherwise, and when most of the followed windows have a rough outline
/// (uniform noise, where every window's centroid sits near its rest place:
/// `noise_like`), the whole frame is searched ([`detect`]); with
/// `local_pitch_px` (and no noise) its markers are then paired with the
/// rest markers through their neighbours (`pair_detected`,
/// [`Search::Paired`]).
///
/// A followed marker keeps its followed centroid; a searched one is added
/// where no followed marker lies within `reach_px` (it is the new place of
/// a lost one), unless no lost one takes it and it lies beside a followed
/// marker in a box that no searched one confirmed, which then takes its
/// centroid. A lost marker the local search still misses is put where
/// its paired neighbours' displacements predict it when that pixel is
/// clipped and no marker lies within [`RIDGE_CLEAR_PITCH`] (pins a press
/// squeezed into one clipped ridge, which a blur leaves no neck to split
/// at). Session 6 searched the box around the lost markers *instead
/// of* following inside it (commit 45ed751) and measured it slower and less
/// accurate: following was slower then, and centroids of the two paths
/// mixed at the box's edge (BENCHMARKS.md, section "Domes": "Tried and not
/// kept"); here following is kept wherever it holds.
pub fn follow_or_search(
    frame: &GreyFrame,
    det: &Detector,
    rest: &Reference,
    reach_px: f64,
    local_pitch_px: Option<f64>,
) -> (Markers, Search) {
    let near = rest.at;
    let positive = &*positive(frame, det.dark);
    let strict = (FOLLOW_MAX_LOST * near.len() as f64).floor() as usize;
    let max_lost = match local_pitch_px {
        Some(_) => (LOCAL_MAX_LOST * near.len() as f64).floor() as usize,
        None => strict,
    };
    let full = || {
        let window = det
            .window_px
            .unwrap_or([0, 0, frame.width(), frame.height()]);
        Markers {
            list: detect_in(positive, det, window, None),
        }
    };
    let paired = |pitch_px: f64| {
        let list = pair_detected(positive, det, rest, full().list, pitch_px, reach_px);
        (Markers { list }, Search::Paired)
    };
    let Some(found) = follow_each(positive, det, rest, true, reach_px, max_lost) else {
        return match local_pitch_px {
            Some(pitch_px) => paired(pitch_px),
            None => (full(), Search::Full),
        };
    };
    if noise_like(positive, det, &found, rest.radii_px) {
        return (full(), Search::Full);
    }
    let lost = found.iter().filter(|f| f.is_none()).count();
    let followed = || {
        // Sized once: a flattened list of options gives no size hint, and
        // `collect` reallocated it eight times (4 % of a contact-free frame).
        let mut list = Vec::with_capacity(found.len());
        list.extend(found.iter().flatten().copied());
        Markers { list }
    };
    let Some(pitch_px) = local_pitch_px else {
        return if lost <= strict {
            (followed(), Search::Followed)
        } else {
            (full(), Search::Full)
        };
    };
    if lost == 0 && rest.gaps_px.is_empty() {
        return (followed(), Search::Followed);
    }
    match search_around(positive, det, rest, &found, pitch_px, reach_px) {
        Some(list) => (Markers { list }, Search::Local),
        None => paired(pitch_px),
    }
}

/// The whole frame's markers `detected`, paired with the rest markers
/// (`followed_from`). A real tap that shears the skin moves many markers
/// further than following reaches ([`crate::pipeline::FOLLOW_REACH_PITCH`]):
/// on the real TacTip taps two thirds of the frames lost more than a
/// quarter of them, and pairing each rest marker with the nearest marker
/// within half a pitch (the [`Search::Full`] tracking) left a fifth of them
/// lost and paired others with a neighbour's pin (BENCHMARKS.md, session
/// 22).
///
/// The seeds: each rest marker is paired with the nearest of the detected
/// markers within [`PAIRED_SEED_PITCH`] of it whose nearest rest marker it
/// is. Then, in rounds, each lost rest marker with at least two paired
/// neighbours ([`Neighbours`]) is expected where their median displacement
/// puts it ([`predicted`]), and is paired with the nearest unpaired detected
/// marker within [`PAIRED_REACH_PITCH`] of that place, nearest pairs first;
/// each round's pairs predict the next ([`PAIRED_MAX_ROUNDS`]). Detected
/// markers left unpaired stay in the list (the density counts them) without
/// a rest marker.
fn pair_detected(
    frame: &GreyFrame,
    det: &Detector,
    rest: &Reference,
    mut detected: Vec<Marker>,
    pitch_px: f64,
    same_px: f64,
) -> Vec<Marker> {
    let near = rest.at;
    let (fw, fh) = (frame.width(), frame.height());
    let at: Vec<PointPx> = detected.iter().map(|m| m.pos).collect();
    let reach_px = PAIRED_REACH_PITCH * pitch_px;
    let seed_px = PAIRED_SEED_PITCH * pitch_px;
    let index = PointIndex::new(&at, fw, fh, reach_px);
    let mut used = vec![false; detected.len()];
    let mut displaced: Vec<Option<PointPx>> = vec![None; near.len()];
    let mut pair = |j: usize, k: usize, used: &mut [bool], displaced: &mut [Option<PointPx>]| {
        used[j] = true;
        displaced[k] = Some(PointPx::new(at[j].x - near[k].x, at[j].y - near[k].y));
        detected[j].followed_from = Some(k);
    };
    // Seeds: each rest marker gets the nearest of the detected markers
    // within the seed distance whose nearest rest marker it is.
    let rest_index = PointIndex::new(near, fw, fh, seed_px);
    let mut seed: Vec<Option<(f64, usize)>> = vec![None; near.len()];
    for (j, &p) in at.iter().enumerate() {
        if let Some((k, d)) = rest_index.nearest(near, p, seed_px) {
            if seed[k].is_none_or(|(best, _)| d < best) {
                seed[k] = Some((d, j));
            }
        }
    }
    for (k, s) in seed.into_iter().enumerate() {
        if let Some((_, j)) = s {
            pair(j, k, &mut used, &mut displaced);
        }
    }
    let neighbours = rest.neighbours_or_new(pitch_px);
    let mut look: Vec<usize> = (0..near.len())
        .filter(|&k| displaced[k].is_none())
        .collect();
    for _ in 0..PAIRED_MAX_ROUNDS {
        let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
        for &k in look.iter().filter(|&&k| displaced[k].is_none()) {
            let Some(q) = predicted_from(near, &displaced, neighbours.of(k), k) else {
                continue;
            };
            pairs.extend(
                index
                    .within(&at, q, reach_px)
                    .filter(|&(j, _)| !used[j])
                    .map(|(j, d2)| (d2, j, k)),
            );
        }
        pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        look.clear();
        for (_, j, k) in pairs {
            if used[j] || displaced[k].is_some() {
                continue;
            }
            pair(j, k, &mut used, &mut displaced);
            look.extend(
                neighbours
                    .of(k)
                    .iter()
                    .map(|&n| n as usize)
                    .filter(|&n| displaced[n].is_none()),
            );
        }
        if look.is_empty() {
            break;
        }
        look.sort_unstable();
        look.dedup();
    }
    for m in &mut detected {
        if let Some(k) = m.followed_from {
            measure_in_own_window(frame, det, rest, k, m, same_px);
        }
    }
    detected
}

/// [`Search::Paired`] seeds its pairing with the detected markers this many
/// pitches or less from their nearest rest marker: a marker that near has
/// no other pin to be.
pub const PAIRED_SEED_PITCH: f64 = 0.25;

/// [`Search::Paired`] pairs a lost rest marker with a detected marker
/// within this many pitches of its predicted place. On franka's real taps
/// (the followed markers as seeds, a first version) half a pitch left
/// 3.8 % of the paired markers more than 0.35 pitch from their
/// neighbours' median displacement, 0.35 pitch 1.6 % (BENCHMARKS.md,
/// session 22).
pub const PAIRED_REACH_PITCH: f64 = 0.35;

/// Rounds of [`Search::Paired`]'s pairing at most (a guard: the rounds end
/// when one pairs none). Each round pairs about one ring of lost rest
/// markers, next to the last round's pairs: on a generator frame sheared by
/// 0.6 pitch over most of its width, 12 rounds left 318 of its 757 markers
/// paired and 64 all of them
/// (`a_wide_shear_is_paired_through_the_neighbours_not_to_the_nearest_pin`).
pub const PAIRED_MAX_ROUNDS: usize = 64;

/// A searched marker `m` paired with rest marker `k` whose centroid window
/// is narrower than the detector's (a dome's outer rings) is measured again
/// in its own.
fn measure_in_own_window(
    frame: &GreyFrame,
    det: &Detector,
    rest: &Reference,
    k: usize,
    m: &mut Marker,
    same_px: f64,
) {
    let radius_px = rest.radii_px.get(k).copied().unwrap_or(det.radius_px);
    if radius_px < det.radius_px {
        if let Some((pos, _, area_px)) =
            follow_one(frame, m.pos, radius_px, det.min_contrast, same_px, None)
        {
            (m.pos, m.area_px) = (pos, area_px);
        }
    }
}

/// Most windows sampled from [`NOISE_SAMPLES`] of the followed markers
/// `found` have a rough outline ([`NOISE_ROUGHNESS`]): the frame is no
/// marker image (sensor noise), whatever centroids following found in it.
/// Around a marker the outline runs over the skin and across the edges of
/// a few blobs: the mean step between its neighbouring pixels
/// is 0.054-0.07 of the window's range on the raw taps and the renderer's
/// nominal, blurred and dim frames, 0.125 on franka's binarised pins, and
/// 0.37 on uniform noise, where every window's centroid sits near its
/// middle and so near its rest place (BENCHMARKS.md, session 14).
fn noise_like(
    frame: &GreyFrame,
    det: &Detector,
    found: &[Option<Marker>],
    radii_px: &[f64],
) -> bool {
    let step = found.len().div_ceil(NOISE_SAMPLES).max(1);
    let (mut looked, mut noisy) = (0usize, 0usize);
    for (k, m) in found.iter().enumerate().step_by(step) {
        let Some(m) = m else { continue };
        let radius_px = radii_px.get(k).copied().unwrap_or(det.radius_px);
        if let Some(rough) = outline_roughness(frame, m.pos, radius_px, det.min_contrast) {
            looked += 1;
            noisy += usize::from(rough > NOISE_ROUGHNESS);
        }
    }
    2 * noisy > looked && looked > 0
}

/// Followed markers [`noise_like`] looks at, at most.
const NOISE_SAMPLES: usize = 32;
/// [`noise_like`]: an outline is rough when the mean step between its
/// neighbouring pixels exceeds this fraction of the window's range (twice
/// franka's median, two thirds of uniform noise's).
const NOISE_ROUGHNESS: f32 = 0.25;

/// The mean absolute step between neighbouring pixels around the outline
/// of [`refine`]'s window at `at`, over the window's range (the outline's
/// darkest pixel to the brightest of the 3x3 at its middle); `None` for a
/// window off the frame or below the contrast floor.
fn outline_roughness(
    frame: &GreyFrame,
    at: PointPx,
    radius_px: f64,
    min_contrast: f32,
) -> Option<f32> {
    let rw = window_reach_px(radius_px);
    let (cx, cy) = window_centre(at);
    let (w, h) = (frame.width() as i64, frame.height() as i64);
    if cx - rw < 0 || cy - rw < 0 || cx + rw >= w || cy + rw >= h {
        return None;
    }
    let (w, rw, cx, cy) = (w as usize, rw as usize, cx as usize, cy as usize);
    let data = frame.data();
    let (x0, x1, y0, y1) = (cx - rw, cx + rw, cy - rw, cy + rw);
    // Darkest pixel and summed steps along one side.
    fn side(mut px: impl Iterator<Item = u8>) -> (u8, u32) {
        let first = px.next().unwrap_or(0);
        let (lo, _, steps) = px.fold((first, first, 0u32), |(lo, prev, steps), v| {
            (lo.min(v), v, steps + u32::from(v.abs_diff(prev)))
        });
        (lo, steps)
    }
    let row = |y: usize| data[y * w + x0..=y * w + x1].iter().copied();
    let col = |x: usize| (y0..=y1).map(move |y| data[y * w + x]);
    let (mut lo, mut steps) = (u8::MAX, 0u32);
    // The outline's four sides, each with both its corners: their steps
    // together go once round it.
    for (l, s) in [side(row(y0)), side(row(y1)), side(col(x0)), side(col(x1))] {
        lo = lo.min(l);
        steps += s;
    }
    let n = 8 * rw as u32;
    let hi = (cy - 1..=cy + 1)
        .flat_map(|y| &data[y * w + cx - 1..=y * w + cx + 1])
        .copied()
        .max()
        .unwrap_or(0);
    let range = hi as f32 - lo as f32;
    (range >= min_contrast.max(1.0)).then(|| steps as f32 / n as f32 / range)
}

/// The followed markers `found` (per rest marker of `rest.at`, `None`
/// when lost) and the markers searched for ([`detect_in`]) in boxes around
/// the lost ones and the rest's gaps: each box reaches `pitch_px` beyond a
/// lost marker's rest place or a gap, plus the detector's border margin;
/// overlapping boxes are merged where that adds no area. A searched
/// marker within `same_px` of a followed one is that one
/// (followed again from there, in its window of `rest.radii_px`, when the
/// two centroids differ by more than [`RESETTLE_PX`]). A followed marker
/// that moved more than [`UNCONFIRMED_STILL_PITCH`] (or faded, see there)
/// and lies inside a box, where the search can see, but that no searched
/// marker confirms is dropped (it settled between two blobs). Each
/// searched marker that is not a followed one is given the nearest lost
/// rest marker within half a pitch ([`Marker::followed_from`]), nearest
/// pairs first; one further from every lost rest place, the lost rest
/// marker whose place its neighbours' displacements predict within half a
/// pitch ([`NEIGHBOUR_PITCH`], [`PAIR_ROUNDS`]). A searched marker still
/// without a rest marker, within [`ORPHAN_PITCH`] of a followed marker in a
/// box that the search did not confirm, is that marker's pin: the followed
/// marker takes its centroid (`resettle_on_orphans`). A lost rest marker left
/// whose predicted place is on a clipped ridge with no marker near is put
/// there (`fill_clipped_ridges`). `None` when the boxes
/// cover more than [`LOCAL_MAX_AREA`] of the search window. `frame` has
/// bright markers ([`positive`]).
fn search_around(
    frame: &GreyFrame,
    det: &Detector,
    rest: &Reference,
    found: &[Option<Marker>],
    pitch_px: f64,
    same_px: f64,
) -> Option<Vec<Marker>> {
    let (near, radii_px, contrast) = (rest.at, rest.radii_px, rest.contrast);
    let (fw, fh) = (frame.width(), frame.height());
    let [wx0, wy0, wx1, wy1] = det.window_px.unwrap_or([0, 0, fw, fh]);
    let (wx1, wy1) = (wx1.min(fw), wy1.min(fh));
    let window_area = wx1.saturating_sub(wx0) * wy1.saturating_sub(wy0);
    let lobe = det.lobe_px.max(3) | 1;
    let margin_px = (((3 * lobe - 1) / 2 + 1) * det.bin.max(1)) as f64;
    let grow = pitch_px.max(0.0) + margin_px;
    let clamp = |v: f64, lo: usize, hi: usize| (v.max(lo as f64) as usize).min(hi);
    let area = |b: &[usize; 4]| (b[2] - b[0]) * (b[3] - b[1]);
    let union = |a: &[usize; 4], b: &[usize; 4]| {
        [
            a[0].min(b[0]),
            a[1].min(b[1]),
            a[2].max(b[2]),
            a[3].max(b[3]),
        ]
    };
    let mut boxes: Vec<[usize; 4]> = Vec::new();
    let lost_places = near.iter().zip(found).filter(|(_, f)| f.is_none());
    for p in lost_places.map(|(p, _)| p).chain(rest.gaps_px) {
        if !p.is_finite() {
            continue;
        }
        let mut b = [
            clamp(p.x - grow, wx0, wx1),
            clamp(p.y - grow, wy0, wy1),
            clamp(p.x + grow + 1.0, wx0, wx1),
            clamp(p.y + grow + 1.0, wy0, wy1),
        ];
        // Merge every box it overlaps into it where their bounding box is
        // no larger than the two (a contact's cluster becomes one box,
        // scattered lost markers stay apart), until none is left.
        while let Some(k) = boxes.iter().position(|o| {
            o[0] < b[2]
                && b[0] < o[2]
                && o[1] < b[3]
                && b[1] < o[3]
                && area(&union(o, &b)) <= area(o) + area(&b)
        }) {
            b = union(&boxes.swap_remove(k), &b);
        }
        boxes.push(b);
    }
    let covered: usize = boxes.iter().map(area).sum();
    if covered as f64 > LOCAL_MAX_AREA * window_area as f64 {
        return None;
    }
    // Whether `p` lies in a box grown by `grow_px` (shrunk, when negative).
    let in_boxes = |p: PointPx, grow_px: f64| {
        boxes.iter().any(|b| {
            p.x >= b[0] as f64 - grow_px
                && p.x < b[2] as f64 + grow_px
                && p.y >= b[1] as f64 - grow_px
                && p.y < b[3] as f64 + grow_px
        })
    };
    // Room for the searched markers too (the lost ones' new places): the
    // list is appended to, not copied.
    let mut list: Vec<Marker> = Vec::with_capacity(found.len() + found.len() / 4);
    list.extend(found.iter().flatten().copied());
    // A box is too small, and a contact's share of it too large, for its
    // own typical range: the followed markers' median contrast stands in.
    let typical_range = percentile(list.iter().map(|m| m.strength).collect(), 0.5);
    // A followed marker this far inside a box is one the search can find.
    let inset = margin_px + det.radius_px;
    let still2 = (UNCONFIRMED_STILL_PITCH * pitch_px).powi(2);
    // Each marker's contrast over its own at rest, and the frame's light
    // (as in `follow_each`).
    let ratio = |m: &Marker| {
        let at_rest = m
            .followed_from
            .and_then(|k| contrast.get(k))
            .copied()
            .filter(|&c| c > 0.0)
            .unwrap_or(1.0);
        m.strength / at_rest
    };
    let light = percentile(list.iter().map(ratio).collect(), 0.5);
    let mut unconfirmed: Vec<bool> = list
        .iter()
        .map(|m| {
            let p = m.pos;
            let kept = ratio(m) >= UNCONFIRMED_MIN_CONTRAST * light
                && m.followed_from
                    .and_then(|k| near.get(k))
                    .is_some_and(|r| (p.x - r.x).powi(2) + (p.y - r.y).powi(2) <= still2);
            !kept && in_boxes(p, -inset)
        })
        .collect();
    // The followed markers a searched centroid lands on (within `same_px`).
    let mut confirmed = vec![false; list.len()];
    // A searched marker lies in a box: only the followed markers within
    // `same_px` of one can be it (a contact's boxes hold a tenth of them).
    let in_reach: Vec<usize> = (0..list.len())
        .filter(|&j| in_boxes(list[j].pos, same_px))
        .collect();
    let followed_at: Vec<PointPx> = in_reach.iter().map(|&j| list[j].pos).collect();
    let followed_index = PointIndex::new(&followed_at, fw, fh, same_px);
    let mut searched: Vec<Marker> = Vec::new();
    let span = boxes.iter().fold([wx1, wy1, wx0, wy0], |a, b| union(&a, b));
    let mut taken = Occupancy::new(span);
    // A followed pin's effective area (a blob of two is twice that).
    let pin_area_px = percentile(list.iter().map(|m| m.area_px).collect(), 0.5);
    let mut chains: Vec<Vec<Marker>> = Vec::new();
    for &b in &boxes {
        let found = detect_split_in(
            frame,
            det,
            b,
            Some(typical_range),
            Some(PinScale {
                area_px: pin_area_px,
                pitch_px,
            }),
            &mut chains,
        );
        for m in found {
            let p = m.pos;
            let Some((j, d)) = followed_index
                .nearest(&followed_at, p, same_px)
                .map(|(i, d)| (in_reach[i], d))
            else {
                // A lost marker's new place, unless an overlapping box
                // found it already.
                if taken.claim(p, DUPLICATE_PX, &searched) {
                    searched.push(m);
                }
                continue;
            };
            (unconfirmed[j], confirmed[j]) = (false, true);
            // A followed marker: where the search's centroid differs, it
            // settled on part of a blob that moved (or between two); follow
            // it once more from the blob's peak, in its own window.
            if d > RESETTLE_PX {
                let k = list[j].followed_from.unwrap_or(usize::MAX);
                let radius_px = radii_px.get(k).copied().unwrap_or(det.radius_px);
                if let Some((pos, contrast, area_px)) =
                    follow_one(frame, p, radius_px, det.min_contrast, same_px, None)
                {
                    let m = &mut list[j];
                    m.rel_strength *= contrast / m.strength.max(1.0);
                    (m.pos, m.strength, m.area_px) = (pos, contrast, area_px);
                }
            }
        }
    }
    // Pins in one blob: a followed marker between two of them is neither
    // (its window saw both); one on a pin is that pin.
    for pins in chains {
        for p in pins.windows(2) {
            let (mid, off_px) = between_pins(p[0].pos, p[1].pos);
            // (The index answers within its cell size, `same_px`.)
            for (i, _) in followed_index.within(&followed_at, mid, off_px.min(same_px)) {
                unconfirmed[in_reach[i]] = true;
            }
        }
        for m in pins {
            match followed_index.nearest(&followed_at, m.pos, DUPLICATE_PX) {
                Some((i, _)) => (unconfirmed[in_reach[i]], confirmed[in_reach[i]]) = (false, true),
                None if taken.claim(m.pos, DUPLICATE_PX, &searched) => searched.push(m),
                None => {}
            }
        }
    }
    // A followed marker that moved and that the search does not confirm
    // settled where there is no blob (between two squeezed ones), or on
    // noise where its blob left: lost, its rest marker is matched among
    // the searched ones. One that stayed with its contrast is a faint
    // marker the search's thresholds miss (a dome's outer ring).
    drop_marked(&mut list, &unconfirmed);
    drop_marked(&mut confirmed, &unconfirmed);
    // Each searched marker is the lost rest marker's whose expected place
    // is nearest, within half a pitch (nearest pairs first, each once): its
    // rest place moved by its followed neighbours' median displacement
    // ([`predicted`]; the rest place with fewer than two). From rest places
    // alone, a press's ring of pins pushed outwards paired each with the
    // next rest marker out, one pin along (on the renderer's seed 2, 10-18 %
    // of the pins a press moved were on another pin; BENCHMARKS.md, session
    // 30). Then the ones a press moved further: the searched markers beyond
    // half a pitch of their rest places are paired with the predictions, in
    // at most [`PAIR_ROUNDS`] rounds (each round's pairs predict the next).
    let mut lost = vec![true; near.len()];
    for k in list.iter().filter_map(|m| m.followed_from) {
        if let Some(l) = lost.get_mut(k) {
            *l = false;
        }
    }
    let pair = |searched: &mut [Marker], lost: &mut [bool], k: usize, j: usize| {
        let m = &mut searched[j];
        lost[k] = false;
        m.followed_from = Some(k);
        measure_in_own_window(frame, det, rest, k, m, same_px);
    };
    let reach_px = 0.5 * pitch_px;
    let lost_ids: Vec<usize> = (0..near.len()).filter(|&k| lost[k]).collect();
    let neighbours = rest.neighbours_or_new(pitch_px);
    let followed = displacements(near, list.iter());
    let lost_at: Vec<PointPx> = lost_ids
        .iter()
        .map(|&k| predicted(near, &followed, neighbours.of(k), k))
        .collect();
    for (_, j, k) in nearest_pairs(&searched, &lost_at, &lost_ids, reach_px, fw, fh) {
        if lost[k] && searched[j].followed_from.is_none() {
            pair(&mut searched, &mut lost, k, j);
        }
    }
    if lost.iter().any(|&l| l) && searched.iter().any(|m| m.followed_from.is_none()) {
        // The followed markers' displacements, and the searched ones'
        // paired so far.
        let mut displaced = followed;
        add_displacements(&mut displaced, near, searched.iter());
        let within_px = NEIGHBOUR_PITCH * pitch_px;
        // The searched markers the rest places left unpaired (few: those a
        // press moved furthest), indexed.
        let free: Vec<usize> = (0..searched.len())
            .filter(|&j| searched[j].followed_from.is_none())
            .collect();
        let at: Vec<PointPx> = free.iter().map(|&j| searched[j].pos).collect();
        let free_index = PointIndex::new(&at, fw, fh, within_px);
        // Lost rest markers whose prediction may pair: all at first, then
        // the neighbours of the last round's pairs.
        let mut look: Vec<usize> = (0..near.len()).filter(|&k| lost[k]).collect();
        for _ in 0..PAIR_ROUNDS {
            let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
            let mut near_k: Vec<usize> = Vec::new();
            for &k in look.iter().filter(|&&k| lost[k]) {
                // The searched markers still unpaired near it, but beyond
                // half a pitch of its rest place, against its prediction.
                near_k.clear();
                near_k.extend(
                    free_index
                        .within(&at, near[k], within_px)
                        .filter(|&(i, d2)| {
                            searched[free[i]].followed_from.is_none() && d2 > reach_px * reach_px
                        })
                        .map(|(i, _)| i),
                );
                if near_k.is_empty() {
                    continue;
                }
                let q = predicted(near, &displaced, neighbours.of(k), k);
                for &i in &near_k {
                    let e2 = (q.x - at[i].x).powi(2) + (q.y - at[i].y).powi(2);
                    if e2 <= reach_px * reach_px {
                        pairs.push((e2, free[i], k));
                    }
                }
            }
            pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            look.clear();
            for (_, j, k) in pairs {
                if lost[k] && searched[j].followed_from.is_none() {
                    pair(&mut searched, &mut lost, k, j);
                    let p = searched[j].pos;
                    displaced[k] = Some(PointPx::new(p.x - near[k].x, p.y - near[k].y));
                    look.extend(
                        neighbours
                            .of(k)
                            .iter()
                            .map(|&n| n as usize)
                            .filter(|&n| lost[n]),
                    );
                }
            }
            if look.is_empty() {
                break;
            }
            look.sort_unstable();
            look.dedup();
        }
    }
    // A doubted marker's reach: [`ORPHAN_PITCH`] of the spacing at its rest
    // place (its nearest rest neighbour, at most a pitch away), for a dome's
    // outer rings lie foreshortened to half a pitch.
    let neighbours = std::cell::OnceCell::new();
    let reach_of = |m: &Marker| {
        // The search looked only inside the boxes: a followed marker
        // outside them is not doubted.
        if !in_boxes(m.pos, 0.0) {
            return 0.0;
        }
        let at_rest = m.followed_from.and_then(|k| Some((k, *near.get(k)?)));
        let spacing_px = at_rest.map_or(pitch_px, |(k, r)| {
            neighbours
                .get_or_init(|| rest.neighbours_or_new(pitch_px))
                .of(k)
                .iter()
                .filter_map(|&n| near.get(n as usize))
                .map(|q| (q.x - r.x).hypot(q.y - r.y))
                .fold(pitch_px, f64::min)
        });
        ORPHAN_PITCH * spacing_px
    };
    resettle_on_orphans(
        &mut list,
        &confirmed,
        &mut searched,
        ORPHAN_PITCH * pitch_px,
        reach_of,
    );
    list.append(&mut searched);
    fill_clipped_ridges(
        frame,
        det,
        rest,
        &mut list,
        &mut lost,
        pitch_px,
        typical_range,
        pin_area_px,
    );
    Some(list)
}

/// A searched marker that no lost rest marker took (an orphan) within
/// `reach_px` of a followed marker that no searched centroid confirmed:
/// the followed centroid left its pin, and the orphan is that pin. Clipped
/// pins that a press squeezes together run into one plateau; a followed
/// window that takes in part of a neighbour's is pulled towards it, by
/// 2-6 px, while the search splits the plateau at its pins (on the
/// renderer's dome at 2.5x the light, ten followed markers of one contact's
/// ring were 2-6 px off their pins, and the search had found the pin beside
/// five of them; BENCHMARKS.md, session 28). Unclipped pins that a press
/// squeezes show it too, less often. The followed marker takes the
/// orphan's centroid, nearest pairs first, each once; the orphan goes.
/// `reach_of` gives each followed marker's reach (0 where the search did
/// not look), at most `max_reach_px`.
fn resettle_on_orphans(
    list: &mut [Marker],
    confirmed: &[bool],
    searched: &mut Vec<Marker>,
    max_reach_px: f64,
    reach_of: impl Fn(&Marker) -> f64,
) {
    let orphans: Vec<usize> = (0..searched.len())
        .filter(|&o| searched[o].followed_from.is_none())
        .collect();
    if orphans.is_empty() {
        return;
    }
    // The unconfirmed followed markers within the orphans' bounding box
    // grown by the reach (a few dozen of the frame's markers).
    let span = orphans.iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |b, &o| {
            let p = searched[o].pos;
            [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)]
        },
    );
    let candidates: Vec<(usize, f64)> = (0..list.len())
        .filter(|&j| {
            let p = list[j].pos;
            !confirmed.get(j).copied().unwrap_or(true)
                && p.x >= span[0] - max_reach_px
                && p.x <= span[2] + max_reach_px
                && p.y >= span[1] - max_reach_px
                && p.y <= span[3] + max_reach_px
        })
        .map(|j| (j, reach_of(&list[j]).min(max_reach_px)))
        .collect();
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for &o in &orphans {
        let s = searched[o].pos;
        for &(j, reach_px) in &candidates {
            let m = list[j].pos;
            let d2 = (m.x - s.x).powi(2) + (m.y - s.y).powi(2);
            if d2 <= reach_px * reach_px {
                pairs.push((d2, j, o));
            }
        }
    }
    pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut gone = vec![false; searched.len()];
    let mut moved = vec![false; list.len()];
    for (_, j, o) in pairs {
        if gone[o] || moved[j] {
            continue;
        }
        let s = &searched[o];
        let m = &mut list[j];
        m.rel_strength *= s.strength / m.strength.max(1.0);
        (m.pos, m.strength, m.area_px) = (s.pos, s.strength, s.area_px);
        (gone[o], moved[j]) = (true, true);
    }
    drop_marked(searched, &gone);
}

/// `items` without those whose flag in `marked` is set (an item past the
/// flags' end stays), in order.
fn drop_marked<T>(items: &mut Vec<T>, marked: &[bool]) {
    let mut flags = marked.iter();
    items.retain(|_| !flags.next().copied().unwrap_or(false));
}

/// Per rest marker of `near`, the displacement of the marker of `markers`
/// paired with it ([`Marker::followed_from`]; the last one), or `None`.
fn displacements<'a>(
    near: &[PointPx],
    markers: impl Iterator<Item = &'a Marker>,
) -> Vec<Option<PointPx>> {
    let mut displaced = vec![None; near.len()];
    add_displacements(&mut displaced, near, markers);
    displaced
}

/// [`displacements`] of `markers` written over `displaced` (one slot per
/// rest marker of `near`).
fn add_displacements<'a>(
    displaced: &mut [Option<PointPx>],
    near: &[PointPx],
    markers: impl Iterator<Item = &'a Marker>,
) {
    for m in markers {
        if let Some(k) = m
            .followed_from
            .filter(|&k| k < near.len().min(displaced.len()))
        {
            displaced[k] = Some(PointPx::new(m.pos.x - near[k].x, m.pos.y - near[k].y));
        }
    }
}

/// Pins a press squeezed into one clipped ridge that no split told apart
/// (under blur the ridge has no neck between them, and `split_chain` needs
/// one): a lost rest marker whose paired neighbours' displacements
/// ([`predicted_from`]) put it on a clipped pixel, with no marker within
/// [`RIDGE_CLEAR_PITCH`] of that place, is taken to be there (`markers`
/// gains it, with `strength` and `area_px`, the followed markers' medians).
/// In rounds ([`RIDGE_ROUNDS`]): each round's pins predict the next. On the
/// other renderer's dome at twice the light and a 2.2 px PSF
/// (`eval/render_stress.py`, `bright_blur`) the ring a press squeezes ran
/// into such ridges on the side towards the rim, whose missing pins pulled
/// the density's dent outwards: the centre error went from 6.15 / 11.61 px
/// (median / p95) to 4.82 / 6.57 px, and the frames with the marker count
/// within 1 % from 79 % to 100 % (BENCHMARKS.md, session 23). The place is
/// a prediction, not a measurement: within a ridge nothing better is seen.
#[allow(clippy::too_many_arguments)]
fn fill_clipped_ridges(
    frame: &GreyFrame,
    det: &Detector,
    rest: &Reference,
    markers: &mut Vec<Marker>,
    lost: &mut [bool],
    pitch_px: f64,
    strength: f32,
    area_px: f32,
) {
    let near = rest.at;
    let (w, h) = (frame.width(), frame.height());
    if !lost.iter().any(|&l| l) {
        return;
    }
    let mut displaced = displacements(near, markers.iter());
    let neighbours = rest.neighbours_or_new(pitch_px);
    let clear_px = RIDGE_CLEAR_PITCH * pitch_px;
    // The markers so far, indexed once a place needs it (most frames have
    // no clipped pixel where a lost marker is expected).
    let at: Vec<PointPx> = markers.iter().map(|m| m.pos).collect();
    let mut index: Option<PointIndex> = None;
    let first = markers.len();
    for _ in 0..RIDGE_ROUNDS {
        let mut got = false;
        for k in 0..near.len().min(lost.len()) {
            if !lost[k] {
                continue;
            }
            let Some(q) = predicted_from(near, &displaced, neighbours.of(k), k) else {
                continue;
            };
            let (x, y) = (q.x.round(), q.y.round());
            let clipped = x >= 0.0
                && y >= 0.0
                && (x as usize) < w
                && (y as usize) < h
                && frame.data()[y as usize * w + x as usize] == u8::MAX;
            if !clipped || !det.may_hold(q) {
                continue;
            }
            let index = index.get_or_insert_with(|| PointIndex::new(&at, w, h, clear_px));
            let clear = index.nearest(&at, q, clear_px).is_none()
                && markers[first..].iter().all(|m| {
                    (m.pos.x - q.x).powi(2) + (m.pos.y - q.y).powi(2) >= clear_px * clear_px
                });
            if !clear {
                continue;
            }
            markers.push(Marker {
                pos: q,
                strength,
                peak: u8::MAX,
                rel_level: 1.0,
                rel_strength: 1.0,
                area_px,
                followed_from: Some(k),
            });
            lost[k] = false;
            displaced[k] = Some(PointPx::new(q.x - near[k].x, q.y - near[k].y));
            got = true;
        }
        if !got {
            break;
        }
    }
}

/// The local search takes a lost rest marker to be at its predicted place
/// on a clipped ridge (pins a press squeezed into one; see
/// [`follow_or_search`]) only when no marker lies within this many pitches
/// of it.
pub const RIDGE_CLEAR_PITCH: f64 = 0.4;
/// Rounds of the clipped-ridge rule ([`RIDGE_CLEAR_PITCH`]) at most: each
/// round's pins predict the next.
pub const RIDGE_ROUNDS: usize = 3;

/// Rest markers this many pitches apart are neighbours: the displacements
/// of a lost one's paired neighbours predict its place (the local search
/// of [`follow_or_search`]).
pub const NEIGHBOUR_PITCH: f64 = 1.6;
/// Rounds of pairing searched markers with the predicted places of lost
/// rest markers ([`NEIGHBOUR_PITCH`]); each round's pairs predict the next.
pub const PAIR_ROUNDS: usize = 3;

/// The pairs `(squared distance, searched index, rest index)` of the
/// searched markers and the places `at` (of rest markers `ids`) within
/// `reach_px` of each other, nearest first.
fn nearest_pairs(
    searched: &[Marker],
    at: &[PointPx],
    ids: &[usize],
    reach_px: f64,
    width: usize,
    height: usize,
) -> Vec<(f64, usize, usize)> {
    let index = PointIndex::new(at, width, height, reach_px);
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (j, m) in searched
        .iter()
        .enumerate()
        .filter(|(_, m)| m.followed_from.is_none())
    {
        pairs.extend(
            index
                .within(at, m.pos, reach_px)
                .map(|(i, d2)| (d2, j, ids[i])),
        );
    }
    pairs.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    pairs
}

/// Where rest marker `k` is expected: its rest place moved by the median
/// (per axis) of the displacements in `displaced` of its `neighbours`
/// (those that have one), or its rest place with fewer than two.
fn predicted(
    near: &[PointPx],
    displaced: &[Option<PointPx>],
    neighbours: &[u32],
    k: usize,
) -> PointPx {
    predicted_from(near, displaced, neighbours, k).unwrap_or(near[k])
}

/// [`predicted`], `None` with fewer than two displaced neighbours.
pub(crate) fn predicted_from(
    near: &[PointPx],
    displaced: &[Option<PointPx>],
    neighbours: &[u32],
    k: usize,
) -> Option<PointPx> {
    const MOST: usize = 16;
    let (mut ux, mut uy, mut n) = ([0.0f64; MOST], [0.0f64; MOST], 0);
    for &j in neighbours {
        if let Some(u) = displaced.get(j as usize).copied().flatten() {
            if n < MOST {
                (ux[n], uy[n]) = (u.x, u.y);
                n += 1;
            }
        }
    }
    if n < 2 {
        return None;
    }
    let median = |v: &mut [f64]| {
        v.sort_unstable_by(f64::total_cmp);
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    Some(PointPx::new(
        near[k].x + median(&mut ux[..n]),
        near[k].y + median(&mut uy[..n]),
    ))
}

/// The half-maximum centroid of the blob at `start`, re-centred until it
/// settles (at most [`FOLLOW_PASSES`] windows): position, contrast, area;
/// `None` as soon as a centroid lies further than `reach_px` from `start`
/// and from the path blur moves rest marker `k` along (`path`: the levels
/// and `k`; [`BlurLevels::path`]). A frame blurrier than the rest moves a
/// crowded marker's centroid towards its neighbours (a dome's outer ring
/// towards the ring inside it, by 3.6-4.5 px at 3 px more blur on the other
/// renderer's dome, beyond the reach of 0.3 pitch); the calibration
/// measured how far.
fn follow_one(
    frame: &GreyFrame,
    start: PointPx,
    radius_px: f64,
    min_contrast: f32,
    reach_px: f64,
    path: Option<(&BlurLevels, usize)>,
) -> Option<(PointPx, f32, f32)> {
    let mut at = start;
    let mut hit = None;
    for _ in 0..FOLLOW_PASSES {
        let (c, contrast, area) = refine(frame, at, radius_px, min_contrast)?;
        // Beyond the reach (of its start, or of the path blur moves it
        // along) the marker is lost: no more passes.
        let off = PointPx::new(c.x - start.x, c.y - start.y);
        if off.x * off.x + off.y * off.y > reach_px * reach_px
            && path
                .and_then(|(levels, k)| levels.path(k))
                .is_none_or(|p| !p.within(off, reach_px))
        {
            return None;
        }
        let step2 = (c.x - at.x).powi(2) + (c.y - at.y).powi(2);
        // A centroid in the pixel the window is centred on would get the
        // same window again, and so the same centroid: settled.
        let settled =
            step2 < FOLLOW_SETTLED_PX * FOLLOW_SETTLED_PX || window_centre(c) == window_centre(at);
        at = c;
        hit = Some((c, contrast, area));
        if settled {
            break;
        }
    }
    hit
}

/// Follows each of `rest.at` ([`follow`]; each with its centroid radius
/// from `rest.radii_px`, or the detector's past its end, and, with `fade`,
/// its rest contrast from `rest.contrast`, or 1 past its end; no fading
/// test without): per marker, the marker or
/// `None` when it is lost (moved beyond `reach_px`, faded, or the second of
/// two that ran into one blob). `None` once more than `max_lost` are lost.
fn follow_each(
    frame: &GreyFrame,
    det: &Detector,
    rest: &Reference,
    fade: bool,
    reach_px: f64,
    max_lost: usize,
) -> Option<Vec<Option<Marker>>> {
    let (near, radii_px, rivals) = (rest.at, rest.radii_px, rest.rivals);
    let contrast = fade.then_some(rest.contrast);
    let mut lost = 0usize;
    let mut found: Vec<Option<(PointPx, f32, f32)>> = Vec::with_capacity(near.len());
    for (k, &p) in near.iter().enumerate() {
        let radius_px = radii_px.get(k).copied().unwrap_or(det.radius_px);
        let path = rest.blur.map(|levels| (levels, k));
        let kept = follow_one(frame, p, radius_px, det.min_contrast, reach_px, path)
            .filter(|&(at, _, _)| det.may_hold(at));
        if kept.is_none() {
            lost += 1;
            if lost > max_lost {
                return None;
            }
        }
        found.push(kept);
    }
    let median = percentile(
        collect_bounded(found.iter().filter_map(|f| f.map(|f| f.1))),
        0.5,
    );
    // Each marker's contrast over its own at rest, and the frame's light:
    // the median of that ratio.
    if let Some(contrast) = contrast {
        let at_rest = |k: usize| contrast.get(k).copied().filter(|&c| c > 0.0).unwrap_or(1.0);
        let ratio = |k: usize, c: f32| c / at_rest(k);
        let light = percentile(
            collect_bounded(
                found
                    .iter()
                    .enumerate()
                    .filter_map(|(k, f)| f.map(|f| ratio(k, f.1))),
            ),
            0.5,
        );
        for (k, f) in found.iter_mut().enumerate() {
            if f.is_some_and(|f| ratio(k, f.1) < FOLLOW_MIN_CONTRAST * light) {
                *f = None;
                lost += 1;
            }
        }
    }
    if lost > max_lost {
        return None;
    }
    // Two followed markers can only run into one blob if their rest places
    // are rivals (no frame-sized grid to clear); without the list, a grid.
    let rivals = rivals.filter(|r| r.covers(near.len(), reach_px));
    let mut taken = rivals.is_none().then(|| {
        Occupancy::new(
            det.window_px
                .unwrap_or([0, 0, frame.width(), frame.height()]),
        )
    });
    let mut claimed: Vec<Marker> = Vec::new();
    let mut out: Vec<Option<Marker>> = Vec::with_capacity(found.len());
    for (k, f) in found.into_iter().enumerate() {
        let Some((pos, contrast, area_px)) = f else {
            out.push(None);
            continue;
        };
        let free = match (&mut taken, rivals) {
            (Some(grid), _) => grid.claim(pos, DUPLICATE_PX, &claimed),
            (None, Some(r)) => !r.earlier[k].iter().any(|&e| {
                out[e as usize].is_some_and(|q| {
                    (q.pos.x - pos.x).powi(2) + (q.pos.y - pos.y).powi(2)
                        < DUPLICATE_PX * DUPLICATE_PX
                })
            }),
            (None, None) => true,
        };
        if !free {
            // Two markers ran into one blob: a contact squeezes them; a
            // search sorts that out.
            lost += 1;
            out.push(None);
            if lost > max_lost {
                return None;
            }
            continue;
        }
        let m = Marker {
            pos,
            strength: contrast,
            peak: 0,
            rel_level: 1.0,
            rel_strength: contrast / median.max(1.0),
            area_px,
            followed_from: Some(k),
        };
        if taken.is_some() {
            claimed.push(m);
        }
        out.push(Some(m));
    }
    Some(out)
}

/// The centroid window's radius for each of `points`: `radius_px`, or less
/// where a neighbour is closer than the window's reach (the outer rings of
/// a dome, foreshortened to half a pitch): the window (`radius + 2` px
/// either side) then stops half-way to the nearest neighbour, whose blob
/// would otherwise pull the centroid, by an amount that changes with the
/// frame's blur and light.
pub fn centroid_radii(points: &[PointPx], radius_px: f64) -> Vec<f64> {
    let reach = window_reach_px(radius_px) as f64;
    let index = PointIndex::spanning(points, 2.0 * reach);
    (0..points.len())
        .map(|n| {
            let nearest = index
                .nearest_other(points, n, 2.0 * reach)
                .map_or(f64::INFINITY, |(_, d)| d);
            if nearest >= 2.0 * reach {
                radius_px
            } else {
                (0.5 * nearest - 2.0).clamp(1.0, radius_px)
            }
        })
        .collect()
}

/// Most refinement passes per followed marker.
pub const FOLLOW_PASSES: usize = 3;
/// A followed marker whose centroid moved less than this in a pass has
/// settled, px; so has one whose centroid stays in the pixel its window was
/// centred on (the next window would be the same).
const FOLLOW_SETTLED_PX: f64 = 0.25;
/// Fraction of followed markers that may be lost (and left out) before
/// [`follow`] gives up (and [`follow_or_search`] without a local search
/// searches the whole frame).
pub const FOLLOW_MAX_LOST: f64 = 0.01;
/// A followed marker whose contrast, over its own at rest, is below this
/// fraction of the frame's median such ratio is lost (faded, covered); see
/// [`follow`].
pub const FOLLOW_MIN_CONTRAST: f32 = 0.3;

/// The middle of the flat top that holds candidate `(x, y)`: the pixels
/// within `tol` grey levels of it. A saturated or binarised marker's maxima
/// form a plateau, and its first pixel in raster order sits on its
/// upper-left edge, where the determinant is weak; under a light gradient
/// or vignetting the plateau tilts and its maximum is a pixel anywhere on
/// its rim. The middle of the run along the row through the candidate,
/// then of the column through that; each run at most `max_run` px either
/// way and kept `margin` px inside the image.
fn plateau_centre(
    img: &[u8],
    (w, h): (usize, usize),
    (x, y): (usize, usize),
    margin: usize,
    tol: u8,
    max_run: usize,
) -> (usize, usize) {
    let (lo_x, hi_x) = (margin.max(1), w - margin.max(1) - 1);
    let (lo_y, hi_y) = (margin.max(1), h - margin.max(1) - 1);
    if x < lo_x || y < lo_y || x > hi_x || y > hi_y {
        return (x, y);
    }
    let floor = img[y * w + x].saturating_sub(tol);
    let on = |xx: usize, yy: usize| img[yy * w + xx] >= floor;
    if !(on(x + 1, y) || on(x, y + 1) || on(x - 1, y) || on(x, y - 1)) {
        return (x, y);
    }
    // The middle of the run through `at` along one axis (`on_at(k)`: the
    // pixel `k` along it is on the plateau).
    let middle = |at: usize, lo: usize, hi: usize, on_at: &dyn Fn(usize) -> bool| {
        let (mut a, mut b) = (at, at);
        while a > lo && at - a < max_run && on_at(a - 1) {
            a -= 1;
        }
        while b < hi && b - at < max_run && on_at(b + 1) {
            b += 1;
        }
        (a + b) / 2
    };
    // Any chord's middle is a disc's middle across it.
    let xm = middle(x, lo_x, hi_x, &|k| on(k, y));
    (xm, middle(y, lo_y, hi_y, &|k| on(xm, k)))
}

/// The pins of a blob that holds two or three touching ones in a row (a
/// press squeezes pins together, and the outer rings' foreshortened ones
/// against the rim; clipped pins run into one plateau): the pixels at or
/// above `level` 4-connected to `at`, within two pin diameters of it.
/// Discs of radius `r` in a row whose centres are `d` apart have the minor
/// variance `r^2/4` and the major `r^2/4 + d^2 (k^2 - 1)/12`: the blob's
/// elongation (major over minor) gives `k` ([`CHAIN_ELONGATION`]), its
/// effective area (each pixel's height above `level` over the blob's top's,
/// summed: a flat top's own area, as [`refine`] measures a pin's) must suit
/// `k` pins of about the frame's size (`pin_area_px`; [`CHAIN_AREA`]), and
/// between each two pins the blob must narrow
/// ([`CHAIN_NECK`]; a single pin that a press tilted and enlarged is an
/// ellipse, widest in its middle). The pins are placed `d` apart along the
/// major axis, centred on the blob's centroid. `None` for any other blob,
/// one that reaches the window's edge included.
fn split_chain(
    frame: &GreyFrame,
    at: PointPx,
    level: u8,
    pin_area_px: f32,
) -> Option<Vec<PointPx>> {
    let (w, h) = (frame.width(), frame.height());
    let data = frame.data();
    if !(at.x >= 0.0 && at.y >= 0.0) || pin_area_px <= 0.0 {
        return None;
    }
    let (sx, sy) = ((at.x + 0.5) as usize, (at.y + 0.5) as usize);
    if sx >= w || sy >= h || data[sy * w + sx] < level {
        return None;
    }
    let diameter_px = 2.0 * (pin_area_px as f64 / std::f64::consts::PI).sqrt();
    if !chord_says_chain(
        frame,
        (sx, sy),
        level,
        diameter_px,
        chain_reach_px(pin_area_px),
    ) {
        return None;
    }
    let blob = fill_blob(frame, (sx, sy), level, pin_area_px)?;
    let count = blob.len() as f64;
    let top = blob
        .iter()
        .map(|&(x, y)| data[y * w + x])
        .max()
        .unwrap_or(level);
    let height = (top as f64 - level as f64).max(1.0);
    let area_px: f64 = blob
        .iter()
        .map(|&(x, y)| (data[y * w + x] as f64 - level as f64) / height)
        .sum();
    let offset = |&(x, y): &(usize, usize)| (x as f64 - sx as f64, y as f64 - sy as f64);
    let (mx, my) = blob
        .iter()
        .map(offset)
        .fold((0.0, 0.0), |a, (x, y)| (a.0 + x, a.1 + y));
    let (mx, my) = (mx / count, my / count);
    let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
    for (x, y) in blob.iter().map(offset) {
        let (dx, dy) = (x - mx, y - my);
        (a, b, c) = (a + dx * dx, b + dx * dy, c + dy * dy);
    }
    let (major, minor, (ex, ey)) = principal_axes(a / count, b / count, c / count);
    let k = (2..)
        .zip(CHAIN_ELONGATION)
        .find_map(|(k, (lo, hi))| (major >= lo * minor && major < hi * minor).then_some(k))?;
    let (lo, hi) = CHAIN_AREA[k - 2];
    let pins = area_px / pin_area_px as f64;
    if !(pins >= lo as f64 && pins <= hi as f64) {
        return None;
    }
    let kf = k as f64;
    let d = (12.0 * (major - minor) / (kf * kf - 1.0)).sqrt();
    // Along the axis, pin i sits at t = (i - (k - 1)/2) d from the
    // centroid; the blob's pixels within half a pixel of t measure its
    // width there.
    let along: Vec<f64> = blob
        .iter()
        .map(offset)
        .map(|(x, y)| (x - mx) * ex + (y - my) * ey)
        .collect();
    let width = |t: f64| along.iter().filter(|&&u| (u - t).abs() < 0.5).count() as f64;
    let at_pin = |i: usize| (i as f64 - 0.5 * (kf - 1.0)) * d;
    let necked = (0..k - 1).all(|i| {
        let (t0, t1) = (at_pin(i), at_pin(i + 1));
        width(0.5 * (t0 + t1)) <= CHAIN_NECK * width(t0).min(width(t1))
    });
    if !necked {
        return None;
    }
    let (cx, cy) = (sx as f64 + mx, sy as f64 + my);
    Some(
        (0..k)
            .map(|i| PointPx::new(cx + at_pin(i) * ex, cy + at_pin(i) * ey))
            .collect(),
    )
}

/// The major and minor variance of the second moments `(a b; b c)` (a is
/// x x, c is y y), and the major axis (a unit vector).
fn principal_axes(a: f64, b: f64, c: f64) -> (f64, f64, (f64, f64)) {
    let root = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let (major, minor) = (0.5 * (a + c) + root, 0.5 * (a + c) - root);
    // The eigenvector of (a b; b c) for `major`.
    let (ex, ey) = if b.abs() > 1e-12 {
        (major - c, b)
    } else if a >= c {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    let norm = ex.hypot(ey);
    (major, minor, (ex / norm, ey / norm))
}

/// The pixels at or above `level` 4-connected to `(sx, sy)`, within two pin
/// diameters of it (`pin_area_px`: a pin's effective area); `None` when
/// they reach that far, or cover more than three pins' effective area (a
/// flat top's pixel count; a blurred pin covers about twice its effective
/// area above half maximum, so three blurred pins in a row are left
/// alone), where the fill stops.
fn fill_blob(
    frame: &GreyFrame,
    (sx, sy): (usize, usize),
    level: u8,
    pin_area_px: f32,
) -> Option<Vec<(usize, usize)>> {
    let (w, h) = (frame.width(), frame.height());
    let data = frame.data();
    if sx >= w || sy >= h || data[sy * w + sx] < level {
        return None;
    }
    let reach = chain_reach_px(pin_area_px);
    let (x0, y0) = (sx.saturating_sub(reach), sy.saturating_sub(reach));
    let (x1, y1) = ((sx + reach).min(w - 1), (sy + reach).min(h - 1));
    let max_count = (CHAIN_AREA[1].1 * pin_area_px) as usize;
    let mut blob = Vec::with_capacity(max_count + 4);
    blob.push((sx, sy));
    // One bit per pixel of the window: rows of up to 64 px on the stack
    // (the window is two pin diameters either way), a vector beyond.
    let rows = y1 - y0 + 1;
    let mut small = [0u64; 64];
    let mut large = Vec::new();
    let seen: &mut [u64] = if x1 - x0 < 64 && rows <= 64 {
        &mut small[..rows]
    } else {
        large.resize(rows * (x1 - x0 + 1).div_ceil(64), 0u64);
        &mut large
    };
    let words = (x1 - x0 + 1).div_ceil(64);
    let mut mark = |x: usize, y: usize| {
        let (k, bit) = ((y - y0) * words + (x - x0) / 64, 1u64 << ((x - x0) % 64));
        let new = seen[k] & bit == 0;
        seen[k] |= bit;
        new
    };
    mark(sx, sy);
    let mut next = 0;
    while let Some(&(x, y)) = blob.get(next) {
        next += 1;
        if x == x0 || y == y0 || x == x1 || y == y1 || blob.len() > max_count {
            return None;
        }
        for (nx, ny) in [(x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)] {
            if data[ny * w + nx] >= level && mark(nx, ny) {
                blob.push((nx, ny));
            }
        }
    }
    Some(blob)
}

/// How far from its candidate [`split_chain`] looks for a chain's pixels:
/// two pin diameters, px.
fn chain_reach_px(pin_area_px: f32) -> usize {
    (4.0 * (pin_area_px as f64 / std::f64::consts::PI).sqrt()) as usize + 2
}

/// Two pins that a blur wider than about half their distance ran into one
/// blob without a neck, which at half maximum also runs into its
/// neighbours (a press squeezes pins together; [`split_chain`] needs the
/// blob apart and necked). Above [`BLURRED_PAIR_LEVEL`] of the way from
/// the local floor `lo` to the blob's top the pair stands alone. Two equal
/// Gaussian blobs `d` apart, their sum's pixels above that level weighted
/// by their height above it, have the minor variance of one blob
/// ([`BLURRED_PAIR_MINOR`] sigma^2) and a major variance that grows with
/// d / sigma ([`BLURRED_PAIR_ELONGATION`]): from the blob's elongation and
/// minor variance, d. The blob must be Gaussian-like
/// ([`BLURRED_PAIR_MAX_FILL`]) and cover about two pins' area
/// ([`BLURRED_PAIR_PINS`] of `pin_area_px`, a pin's effective area at half
/// maximum). The pins are placed along the major axis, d apart, about the
/// weighted centroid, each then centred with the other taken off
/// ([`BLURRED_PAIR_PASSES`]).
/// Only a pair between `near_px` and `far_px` apart, before and after,
/// is kept (the lattice's [`BLURRED_PAIR_PITCHES`]).
fn split_blurred_pair(
    frame: &GreyFrame,
    at: PointPx,
    lo: f32,
    half_maximum: u8,
    pin_area_px: f32,
    (near_px, far_px): (f64, f64),
) -> Option<[PointPx; 2]> {
    let (w, h) = (frame.width(), frame.height());
    let data = frame.data();
    if !(at.x >= 0.0 && at.y >= 0.0) || pin_area_px <= 0.0 {
        return None;
    }
    let (sx, sy) = ((at.x + 0.5) as usize, (at.y + 0.5) as usize);
    if sx < 2 || sy < 2 || sx + 2 >= w || sy + 2 >= h {
        return None;
    }
    if data[sy * w + sx] < half_maximum {
        return None;
    }
    let peak = (sy - 2..=sy + 2)
        .flat_map(|y| (sx - 2..=sx + 2).map(move |x| data[y * w + x]))
        .max()? as f32;
    let level = (lo + BLURRED_PAIR_LEVEL * (peak - lo))
        .ceil()
        .clamp(1.0, 255.0) as u8;
    // Most candidates are one round pin: its chords are alike.
    let (long, across) = longest_chord_px(frame, (sx, sy), level, chain_reach_px(pin_area_px));
    if long < BLURRED_PAIR_CHORD_RATIO * across {
        return None;
    }
    let blob = fill_blob(frame, (sx, sy), level, pin_area_px)?;
    let (mut sw, mut mx, mut my) = (0.0, 0.0, 0.0);
    let mut top = level;
    for &(x, y) in &blob {
        let v = data[y * w + x];
        top = top.max(v);
        let wt = (v - level) as f64;
        (sw, mx, my) = (sw + wt, mx + wt * x as f64, my + wt * y as f64);
    }
    if sw <= 0.0 || top <= level {
        return None;
    }
    // A flat top (clipped or binarised pins) is no Gaussian.
    let height = (top - level) as f64;
    if sw / (blob.len() as f64 * height) > BLURRED_PAIR_MAX_FILL {
        return None;
    }
    // About two pins' area: a Gaussian's effective area above this level
    // is GAUSSIAN_AREA_RATIO times that above half maximum.
    let pins = sw / height / (GAUSSIAN_AREA_RATIO * pin_area_px as f64);
    let (fewest, most) = BLURRED_PAIR_PINS;
    if !(pins >= fewest && pins <= most) {
        return None;
    }
    let (mx, my) = (mx / sw, my / sw);
    let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
    for &(x, y) in &blob {
        let wt = (data[y * w + x] - level) as f64;
        let (dx, dy) = (x as f64 - mx, y as f64 - my);
        (a, b, c) = (a + wt * dx * dx, b + wt * dx * dy, c + wt * dy * dy);
    }
    let (major, minor, (ex, ey)) = principal_axes(a / sw, b / sw, c / sw);
    if minor <= 0.0 {
        return None;
    }
    // d / sigma from the elongation (the table rises steadily).
    let elongation = major / minor;
    let table = &BLURRED_PAIR_ELONGATION;
    let i = table
        .windows(2)
        .position(|p| elongation >= p[0].1 && elongation < p[1].1)?;
    // Only a blob that is not apart at half maximum (the last test: most
    // blobs are one round pin, refused above at less cost).
    if fill_blob(frame, (sx, sy), half_maximum, pin_area_px).is_some() {
        return None;
    }
    let ((r0, e0), (r1, e1)) = (table[i], table[i + 1]);
    let ratio = r0 + (r1 - r0) * (elongation - e0) / (e1 - e0);
    let d = ratio * (minor / BLURRED_PAIR_MINOR).sqrt();
    let apart = |d: f64| d >= near_px && d < far_px;
    if !apart(d) {
        return None;
    }
    // Each pin from the blob less the other: two equal pins sit d / 2
    // either side of the centroid; unequal ones do not, and shrink the
    // elongation. Each pin's height (the 3 x 3 means there, less the
    // other's tail), then its Gaussian-weighted centroid within sigma of
    // it of the frame less the other pin, a few times.
    let sigma2 = minor / BLURRED_PAIR_MINOR;
    let mut p = [
        (mx - 0.5 * d * ex, my - 0.5 * d * ey),
        (mx + 0.5 * d * ex, my + 0.5 * d * ey),
    ];
    let tail = |a: (f64, f64), b: (f64, f64)| {
        (-((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)) / (2.0 * sigma2)).exp()
    };
    let above_floor = |(x, y): (f64, f64)| -> f64 {
        let (x, y) = (x.round(), y.round());
        // (Written so that NaN is refused too.)
        if !(x >= 1.0 && y >= 1.0 && x + 1.0 < w as f64 && y + 1.0 < h as f64) {
            return 0.0;
        }
        let (x, y) = (x as usize, y as usize);
        let sum: u32 = (y - 1..=y + 1)
            .flat_map(|yy| data[yy * w + x - 1..=yy * w + x + 1].iter())
            .map(|&v| v as u32)
            .sum();
        sum as f64 / 9.0 - lo as f64
    };
    let reach = sigma2.sqrt();
    for _ in 0..BLURRED_PAIR_PASSES {
        let g = tail(p[0], p[1]);
        let (h0, h1) = (above_floor(p[0]), above_floor(p[1]));
        let split = (1.0 - g * g).max(1e-3);
        let heights = [
            ((h0 - g * h1) / split).max(1.0),
            ((h1 - g * h0) / split).max(1.0),
        ];
        let mut next = p;
        for i in 0..2 {
            let (other, a_other) = (p[1 - i], heights[1 - i]);
            let (cx, cy) = p[i];
            let (x0, x1) = (
                (cx - reach).ceil().max(0.0) as usize,
                ((cx + reach).floor() as usize).min(w - 1),
            );
            let (y0, y1) = (
                (cy - reach).ceil().max(0.0) as usize,
                ((cy + reach).floor() as usize).min(h - 1),
            );
            // The Gaussians are separable: one exp per row and column.
            let along = |v0: usize, v1: usize, c: f64| -> Vec<f64> {
                (v0..=v1)
                    .map(|v| (-(v as f64 - c).powi(2) / (2.0 * sigma2)).exp())
                    .collect()
            };
            let (near_x, near_y) = (along(x0, x1, cx), along(y0, y1, cy));
            let (other_x, other_y) = (along(x0, x1, other.0), along(y0, y1, other.1));
            let (mut weight, mut sum_x, mut sum_y) = (0.0, 0.0, 0.0);
            for (j, y) in (y0..=y1).enumerate() {
                for (i, x) in (x0..=x1).enumerate() {
                    let near = near_x[i] * near_y[j];
                    if near < BLURRED_PAIR_WINDOW {
                        continue;
                    }
                    let own =
                        data[y * w + x] as f64 - lo as f64 - a_other * other_x[i] * other_y[j];
                    let wt = own.max(0.0) * near;
                    (weight, sum_x, sum_y) =
                        (weight + wt, sum_x + wt * x as f64, sum_y + wt * y as f64);
                }
            }
            // A Gaussian weighted by a Gaussian window as wide centres half
            // way between the window and itself.
            if weight > 0.0 {
                next[i] = (2.0 * sum_x / weight - cx, 2.0 * sum_y / weight - cy);
            }
        }
        p = next;
    }
    apart((p[0].0 - p[1].0).hypot(p[0].1 - p[1].1)).then(|| p.map(|(x, y)| PointPx::new(x, y)))
}

/// A pair [`split_blurred_pair`] finds is two pins only when its
/// distance lies in this range of lattice pitches: a press squeezes pins
/// together (to 0.55-0.9 pitches on the other renderer's domes), and a
/// pair closer than half a pitch is one elongated marker (GelSlim's dots
/// next to a press: 0.4).
const BLURRED_PAIR_PITCHES: (f64, f64) = (0.5, 1.0);
/// [`split_blurred_pair`]: the blob's mean height above its level is at
/// most this fraction of its top's (a Gaussian's 0.49, a pair's 0.46-0.56,
/// a pin's disc blurred by 1-3 px 0.47-0.55; a flat top's 1).
const BLURRED_PAIR_MAX_FILL: f64 = 0.65;
/// [`split_blurred_pair`]: passes of each pin's centroid with the other
/// taken off (on two Gaussian pins 2.1 sigma apart, one 1.4 times as
/// high as the other, the dimmer one 1.26, 0.96, 0.75 and 0.34 px off
/// after 2, 3, 4 and 6 passes)...
const BLURRED_PAIR_PASSES: usize = 4;
/// ... over the pixels within one sigma of it (the weight exp(-1/2)).
const BLURRED_PAIR_WINDOW: f64 = 0.606;
/// A Gaussian blob's effective area (each pixel's height above the level
/// over the top's, summed) above [`BLURRED_PAIR_LEVEL`] over that above
/// half maximum.
const GAUSSIAN_AREA_RATIO: f64 = 0.446;
/// [`split_blurred_pair`]: a pair covers this many pins' effective area
/// (the frame's median followed marker's, at half maximum, scaled by
/// [`GAUSSIAN_AREA_RATIO`]): two Gaussians 1.5-2.6 sigma apart cover
/// 1.5-3; the followed markers' centroid windows, too small for a blurred
/// pin, measure its area short (on the other renderer's frames blurred
/// by 3 px pairs measured 2-3.6, and 4.4 on a test scene).
const BLURRED_PAIR_PINS: (f64, f64) = (1.5, 5.0);
/// [`split_blurred_pair`] measures only a blob whose longest chord
/// through the candidate (of four directions) is this many times the chord
/// across it (one round pin: about 1). A gate for speed: measuring every
/// candidate cost 0.09 ms on the renderer's large contacts.
const BLURRED_PAIR_CHORD_RATIO: f64 = 1.3;
/// [`split_blurred_pair`] looks at the blob above this fraction of the way
/// from the local floor to its top.
const BLURRED_PAIR_LEVEL: f32 = 0.75;
/// [`split_blurred_pair`]: the minor variance of two equal Gaussian blobs
/// of sigma 1, over the pixels of their sum above [`BLURRED_PAIR_LEVEL`]
/// of its top, weighted by the height above it (0.093-0.1 for any distance
/// below 3 sigma; 0.093 for one blob).
const BLURRED_PAIR_MINOR: f64 = 0.093;
/// [`split_blurred_pair`]: (d / sigma, major over minor variance) of two
/// equal Gaussian blobs d apart, measured as for [`BLURRED_PAIR_MINOR`]
/// (numerically, on a grid of sigma / 8). From 1.5 sigma (closer pins are
/// one blob to any measure) to 2.6, past which the blob has a neck at half
/// maximum, or falls apart at this level.
const BLURRED_PAIR_ELONGATION: [(f64, f64); 12] = [
    (1.5, 2.120),
    (1.6, 2.405),
    (1.7, 2.807),
    (1.8, 3.310),
    (1.9, 3.928),
    (2.0, 4.675),
    (2.1, 5.589),
    (2.2, 6.738),
    (2.3, 8.150),
    (2.4, 9.977),
    (2.5, 12.150),
    (2.6, 14.505),
];

/// Whether the chords through pixel `at` (the pixels at or above `level`,
/// along four directions, each way at most `reach` px) may cross a chain
/// of pins of `diameter_px`: most
/// candidates are one pin. A chord along the nearest of the four
/// directions to a chain's axis crosses two touching pins over at least
/// 1.85 diameters (3.7 radii at 22.5 degrees), one pin over one, and the
/// chord across it (through the neck) is much shorter
/// ([`CHAIN_MIN_CHORD`], [`CHAIN_CHORD_RATIO`]).
fn chord_says_chain(
    frame: &GreyFrame,
    at: (usize, usize),
    level: u8,
    diameter_px: f64,
    reach: usize,
) -> bool {
    let (long, across) = longest_chord_px(frame, at, level, reach);
    long >= CHAIN_MIN_CHORD * diameter_px && long >= CHAIN_CHORD_RATIO * across
}

/// The longest of the chords through pixel `(sx, sy)` along four
/// directions (the pixels at or above `level`, each way at most `reach`
/// px), and the chord across it, px.
fn longest_chord_px(
    frame: &GreyFrame,
    (sx, sy): (usize, usize),
    level: u8,
    reach: usize,
) -> (f64, f64) {
    let (w, h) = (frame.width() as i64, frame.height() as i64);
    let data = frame.data();
    let (sx, sy, reach) = (sx as i64, sy as i64, reach as i64);
    // Every step stays inside the frame: a run is a walk through `data`
    // (the common case, and four compares fewer per pixel).
    let inside = sx >= reach && sy >= reach && sx + reach < w && sy + reach < h;
    let chords_px = [(1, 0), (0, 1), (1, 1), (1, -1)].map(|(dx, dy): (i64, i64)| {
        let run = |sign: i64| {
            if inside {
                let step = sign * (dy * w + dx);
                let mut at = sy * w + sx;
                let mut n = 0;
                while n < reach {
                    at += step;
                    if data[at as usize] < level {
                        break;
                    }
                    n += 1;
                }
                return n as usize;
            }
            (1..=reach)
                .take_while(|&t| {
                    let (x, y) = (sx + sign * t * dx, sy + sign * t * dy);
                    x >= 0 && y >= 0 && x < w && y < h && data[(y * w + x) as usize] >= level
                })
                .count()
        };
        (1 + run(1) + run(-1)) as f64 * ((dx * dx + dy * dy) as f64).sqrt()
    });
    // The directions come in perpendicular pairs.
    let long = (0..4).fold(0, |b, i| if chords_px[i] > chords_px[b] { i } else { b });
    (chords_px[long], chords_px[long ^ 1])
}

/// [`split_chain`]: a blob of 2 and of 3 pins covers this many pin areas
/// (a press enlarges the pins it tilts, up to about 1.5 times).
const CHAIN_AREA: [(f32, f32); 2] = [(1.5, 3.6), (2.3, 5.0)];
/// [`split_chain`]: the major variance over the minor of 2 and of 3 discs
/// in a row (2: 2 with centres a radius apart, 5 touching; 3: 3.7 and
/// 11.7). An outer ring's pin, foreshortened to half its width, has 4 but
/// about half a pin's area.
const CHAIN_ELONGATION: [(f64, f64); 2] = [(2.0, 7.0), (7.0, 16.0)];
/// [`split_chain`]: between two pins the blob is at most this fraction of
/// its width at either pin (two discs whose centres are 1.5 radii apart:
/// 0.66).
const CHAIN_NECK: f64 = 0.85;
/// [`split_chain`] fills a blob only where its longest chord through the
/// candidate (of four directions) reaches this many pin diameters.
const CHAIN_MIN_CHORD: f64 = 1.6;
/// [`split_chain`] fills a blob only where its longest chord through the
/// candidate is this many times the chord across it (two discs whose
/// centres are a radius apart: 1.7; one round pin: 1).
const CHAIN_CHORD_RATIO: f64 = 1.5;
/// A candidate whose centroid window has this many pin areas (effective
/// area above half maximum) is looked at as a chain ([`split_chain`]); a
/// window around two touching pins holds about 1.5.
const CHAIN_MIN_WINDOW_AREA: f32 = 1.25;

/// [`plateau_centre`]'s tolerance: this fraction of the local range (a
/// binarised pin under vignetting of 0.55 varies by 3 % across itself).
const PLATEAU_TOLERANCE: f32 = 0.05;

/// The local light envelope: per cell, the darkest and brightest level over
/// the cell and its 8 neighbours.
struct Envelope {
    cell: usize,
    cols: usize,
    lo: Vec<f32>,
    range: Vec<f32>,
}

impl Envelope {
    /// `typical`: the typical range to set the floor by
    /// ([`RANGE_FLOOR_FRACTION`]); `None`: the 75th percentile of the
    /// cells' ranges.
    fn new(
        img: &[u8],
        w: usize,
        h: usize,
        cell_px: usize,
        min_contrast: f32,
        typical: Option<f32>,
    ) -> Self {
        let cell = cell_px.max(4);
        let (cols, rows) = (w.div_ceil(cell), h.div_ceil(cell));
        let (mut lo, mut hi) = (vec![u8::MAX; cols * rows], vec![0u8; cols * rows]);
        // Column-wise min / max over a cell row's image rows (vectorises),
        // then per cell over those.
        let (mut col_lo, mut col_hi) = (vec![u8::MAX; w], vec![0u8; w]);
        for (r, band) in img.chunks(cell * w).enumerate() {
            col_lo.fill(u8::MAX);
            col_hi.fill(0);
            for row in band.chunks_exact(w) {
                for ((a, b), &v) in col_lo.iter_mut().zip(col_hi.iter_mut()).zip(row) {
                    *a = (*a).min(v);
                    *b = (*b).max(v);
                }
            }
            for (c, (pl, ph)) in col_lo.chunks(cell).zip(col_hi.chunks(cell)).enumerate() {
                lo[r * cols + c] = pl.iter().copied().min().unwrap_or(u8::MAX);
                hi[r * cols + c] = ph.iter().copied().max().unwrap_or(0);
            }
        }
        let mut slo = vec![0f32; cols * rows];
        let mut range = vec![0f32; cols * rows];
        for r in 0..rows {
            for c in 0..cols {
                let (mut a, mut b) = (u8::MAX, 0u8);
                for rr in r.saturating_sub(1)..=(r + 1).min(rows - 1) {
                    for cc in c.saturating_sub(1)..=(c + 1).min(cols - 1) {
                        a = a.min(lo[rr * cols + cc]);
                        b = b.max(hi[rr * cols + cc]);
                    }
                }
                slo[r * cols + c] = a as f32;
                range[r * cols + c] = b.saturating_sub(a) as f32;
            }
        }
        let typical = typical.unwrap_or_else(|| percentile(range.clone(), 0.75));
        let floor = (RANGE_FLOOR_FRACTION * typical).max(min_contrast).max(1.0);
        // Cells below the floor can hold no marker: an infinite range
        // fails every relative test.
        range
            .iter_mut()
            .filter(|v| **v < floor)
            .for_each(|v| *v = f32::INFINITY);
        Self {
            cell,
            cols,
            lo: slo,
            range,
        }
    }

    /// Local background and range at a detection pixel.
    fn at(&self, x: usize, y: usize) -> (f32, f32) {
        let k = (y / self.cell) * self.cols + x / self.cell;
        (self.lo[k], self.range[k])
    }
}

/// A rest marker's effective area must be within these multiples of the
/// median to be a pin.
pub const SIZE_RANGE: (f32, f32) = (0.3, 2.5);

/// A first centroid this far from its candidate (px, either axis) is refined
/// once more around itself.
const RECENTRE_PX: f64 = 1.5;

/// Two refined centroids closer than this are one marker, px.
const DUPLICATE_PX: f64 = 2.0;

/// A followed marker within this many pitches of its rest place, with at
/// least [`UNCONFIRMED_MIN_CONTRAST`] of the frame's light, is kept when a
/// local search does not find it (see [`search_around`]).
const UNCONFIRMED_STILL_PITCH: f64 = 0.1;
/// See [`UNCONFIRMED_STILL_PITCH`]: a fraction of the median, over the
/// followed markers, of their contrast over their own at rest.
const UNCONFIRMED_MIN_CONTRAST: f32 = 0.6;

/// An orphan of a local search (a searched marker no lost rest marker
/// took) this far or nearer to an unconfirmed followed marker, as a
/// fraction of the spacing at the marker's rest place (at most a pitch), is
/// where that marker's pin is ([`resettle_on_orphans`]). On the renderer's
/// seeds 1-3, 0.3 (the search's own reach for a followed marker) changed
/// next to nothing, 0.45 gave part of the gain and 0.6-0.9 all of it
/// (BENCHMARKS.md, session 28); the smallest of those is kept.
const ORPHAN_PITCH: f64 = 0.6;

/// A followed marker whose centroid a local search puts further away than
/// this is followed again from the searched centroid, px.
const RESETTLE_PX: f64 = 0.5;

/// Coarse occupancy grid for de-duplicating centroids (cells of 4 px); a
/// cell holds the index + 1 of the first marker claimed in it (0: empty), so
/// that the grid is small to clear for every frame.
struct Occupancy {
    x0: f64,
    y0: f64,
    cols: usize,
    rows: usize,
    cells: Vec<u32>,
}

impl Occupancy {
    const CELL_PX: f64 = 4.0;

    /// Cells over the window `[x0, y0, x1, y1)` (px); points outside it
    /// fall in its border cells. A window, not the frame: a search box's
    /// grid is a few hundred cells to clear, not the frame's 20 000.
    fn new([x0, y0, x1, y1]: [usize; 4]) -> Self {
        let cols = ((x1.saturating_sub(x0)) as f64 / Self::CELL_PX).ceil() as usize + 1;
        let rows = ((y1.saturating_sub(y0)) as f64 / Self::CELL_PX).ceil() as usize + 1;
        Self {
            x0: x0 as f64,
            y0: y0 as f64,
            cols,
            rows,
            cells: vec![0; cols * rows],
        }
    }

    /// Claims `p` as marker `list.len()` unless a claimed marker of `list`
    /// lies within `radius` (<= half a cell).
    fn claim(&mut self, p: PointPx, radius: f64, list: &[Marker]) -> bool {
        debug_assert!(radius <= 0.5 * Self::CELL_PX);
        // `as usize` saturates negatives to 0 and truncates (= floor for >= 0).
        let (fx, fy) = (
            (p.x - self.x0) / Self::CELL_PX,
            (p.y - self.y0) / Self::CELL_PX,
        );
        let ci = (fx as usize).min(self.cols - 1);
        let cj = (fy as usize).min(self.rows - 1);
        // Within half a cell of `p` lie only its cell and the neighbours on
        // the sides of the cell `p` is nearer to: a 2x2 block, not 3x3.
        let near = |f: f64, c: usize, n: usize| {
            if f - (c as f64) < 0.5 {
                (c.saturating_sub(1), c)
            } else {
                (c, (c + 1).min(n - 1))
            }
        };
        let (i0, i1) = near(fx, ci, self.cols);
        let (j0, j1) = near(fy, cj, self.rows);
        for j in j0..=j1 {
            for i in i0..=i1 {
                let k = self.cells[j * self.cols + i];
                if let Some(q) = (k as usize).checked_sub(1).and_then(|k| list.get(k)) {
                    let q = q.pos;
                    if (q.x - p.x).powi(2) + (q.y - p.y).powi(2) < radius * radius {
                        return false;
                    }
                }
            }
        }
        let cell = &mut self.cells[cj * self.cols + ci];
        if *cell == 0 {
            // More than u32::MAX - 1 markers cannot fit a frame's cells.
            *cell = u32::try_from(list.len() + 1).unwrap_or(0);
        }
        true
    }
}

/// Candidate blob centres: 3x3 intensity maxima (a plateau yields its first
/// pixel in raster order) at least `ratio` of the way from the local
/// background to the local marker level, `margin` px inside.
fn bright_peaks(
    img: &[u8],
    w: usize,
    h: usize,
    margin: usize,
    env: &Envelope,
    ratio: f32,
) -> Vec<(usize, usize, u8)> {
    const CHUNK: usize = 16;
    let m = margin.max(1);
    if w <= 2 * m || h <= 2 * m {
        return Vec::new();
    }
    let n = w - 2 * m;
    let mut flags = vec![0u8; n];
    // Per-pixel candidate level of the current cell row; 256 = none.
    let mut level = vec![0u16; w];
    let mut out = Vec::new();
    let mut level_row = usize::MAX;
    for y in m..h - m {
        if y / env.cell != level_row {
            level_row = y / env.cell;
            for (c, part) in level.chunks_mut(env.cell).enumerate() {
                let k = level_row * env.cols + c;
                let (lo, range) = (env.lo[k], env.range[k]);
                // An infinite range (no marker possible) gives 256: none.
                let t = (lo + ratio * range).ceil().clamp(1.0, 256.0) as u16;
                part.iter_mut().for_each(|v| *v = t);
            }
        }
        let (up, row, down) = (
            &img[(y - 1) * w..y * w],
            &img[y * w..(y + 1) * w],
            &img[(y + 1) * w..(y + 2) * w],
        );
        // Strictly above the four neighbours met before it in raster order,
        // at least the four after: one candidate per plateau.
        let before = up[m - 1..]
            .iter()
            .zip(&up[m..])
            .zip(&up[m + 1..])
            .zip(&row[m - 1..])
            .map(|(((a, b), c), d)| *a.max(b).max(c).max(d));
        let after = row[m + 1..]
            .iter()
            .zip(&down[m - 1..])
            .zip(&down[m..])
            .zip(&down[m + 1..])
            .map(|(((a, b), c), d)| *a.max(b).max(c).max(d));
        for ((((f, &v), a), b), &t) in flags
            .iter_mut()
            .zip(&row[m..])
            .zip(before)
            .zip(after)
            .zip(&level[m..])
        {
            *f = u8::from(v > a) & u8::from(v >= b) & u8::from(v as u16 >= t);
        }
        for (c, chunk) in flags.chunks(CHUNK).enumerate() {
            if chunk.iter().fold(0u8, |a, &f| a | f) == 0 {
                continue;
            }
            for (i, _) in chunk.iter().enumerate().filter(|(_, &f)| f != 0) {
                let x = m + c * CHUNK + i;
                out.push((x, y, row[x]));
            }
        }
    }
    out
}

/// A marker that only [`fine_determinant`] at its centroid found (a pin a
/// press squeezed against its neighbour) is dropped when another marker of
/// the search lies within this many pitches: a squeezed neighbour is 0.6
/// pitch away or more, a second candidate of one enlarged pin 2-3 px.
const SQUEEZED_ALONE_PITCH: f64 = 0.4;

/// The smallest DoH lobe, full-resolution px ([`fine_determinant`]).
const FINE_LOBE_PX: usize = 3;
/// [`fine_determinant`] is tried only where a dome's skin is seen at least
/// this obliquely (`cos(theta)`): its outer rings (the other renderer's
/// outer ring is at 0.58; a real TacTip's at 0.6-0.7).
const FINE_MAX_FORESHORTENING: f64 = 0.7;

/// [`determinant_at`]'s strength (its square root) at the full-resolution
/// pixel nearest to `p` with the smallest lobe, [`FINE_LOBE_PX`]; `None`
/// where the filter would reach off the frame, or over a saturated pixel:
/// at that scale the corners of a flat (saturated or binarised) pin are
/// blobs too (on franka's thresholded TacTip taps, 1-4 of them per frame
/// at the disc's rim, where the skin is as oblique as a dome's outer ring).
fn fine_determinant(frame: &GreyFrame, p: PointPx) -> Option<f32> {
    let lobe = FINE_LOBE_PX;
    let reach = (3 * lobe - 1) / 2 + 1;
    let (cx, cy) = (p.x.round() as i64, p.y.round() as i64);
    let (w, h) = (frame.width() as i64, frame.height() as i64);
    let r = reach as i64;
    if cx - r < 0 || cy - r < 0 || cx + r >= w || cy + r >= h {
        return None;
    }
    let n = 2 * reach + 1;
    let sub = crop(frame, (cx - r) as usize, (cy - r) as usize, n, n);
    if sub.contains(&u8::MAX) {
        return None;
    }
    let ii = integral(&sub, n, n);
    Some(determinant_at(&ii, n + 1, reach, reach, lobe).sqrt())
}

/// Determinant of the box Hessian at one pixel (0 unless a bright blob);
/// `(x, y)` must be at least `(3 lobe - 1) / 2` px inside the image.
fn determinant_at(ii: &[u32], s: usize, x: usize, y: usize, lobe: usize) -> f32 {
    let l = lobe;
    let half = (l - 1) / 2;
    let bx = |x0: usize, y0: usize, x1: usize, y1: usize| -> i32 {
        ii[y1 * s + x1]
            .wrapping_sub(ii[y0 * s + x1])
            .wrapping_sub(ii[y1 * s + x0])
            .wrapping_add(ii[y0 * s + x0]) as i32
    };
    let dyy = bx(x + 1 - l, y - half - l, x + l, y + half + l + 1)
        - 3 * bx(x + 1 - l, y - half, x + l, y + half + 1);
    let dxx = bx(x - half - l, y + 1 - l, x + half + l + 1, y + l)
        - 3 * bx(x - half, y + 1 - l, x + half + 1, y + l);
    let dxy = bx(x - l, y - l, x, y) + bx(x + 1, y + 1, x + l + 1, y + l + 1)
        - bx(x + 1, y - l, x + l + 1, y)
        - bx(x - l, y + 1, x, y + l + 1);
    if dxx >= 0 || dyy >= 0 {
        return 0.0;
    }
    let inv_area = 1.0 / (l * (2 * l - 1)) as f32;
    let fxy = dxy as f32 * inv_area * DXY_WEIGHT;
    ((dxx as f32 * inv_area) * (dyy as f32 * inv_area) - fxy * fxy).max(0.0)
}

/// Finds the marker scale and threshold from a rest (no-contact) frame.
/// `params.lobe_px` / `params.binned` override the search. With
/// `params.polarity = auto` both bright markers (TacTip pins) and dark ones
/// (GelSight / GelSlim dots) are tried; the one whose markers form the
/// larger regular lattice wins.
pub fn auto_detector(rest: &GreyFrame, params: &MarkerParams) -> Result<Detector, MarkerError> {
    match params.polarity {
        Polarity::Bright => detector_for(rest, params, false),
        Polarity::Dark => detector_for(rest, params, true),
        Polarity::Auto => {
            let bright = detector_for(rest, params, false);
            let dark = detector_for(rest, params, true);
            let lattice = |d: &Result<Detector, MarkerError>| {
                d.as_ref().map_or(0, |d| {
                    crate::area::lattice_members(
                        &detect(rest, d).typical_positions(rest.width(), rest.height()),
                    )
                    .len()
                })
            };
            // Bright wins ties: a TacTip's dark gaps between pins are no
            // lattice of their own, but a dark count must beat it clearly.
            if lattice(&dark) > 2 * lattice(&bright) {
                dark
            } else {
                bright
            }
        }
    }
}

fn detector_for(
    rest: &GreyFrame,
    params: &MarkerParams,
    dark: bool,
) -> Result<Detector, MarkerError> {
    let rest = &*positive(rest, dark);
    let (w, h) = (rest.width(), rest.height());
    if w < 16 || h < 16 {
        return Err(MarkerError::TooSmall {
            width: w,
            height: h,
        });
    }
    let full_lobe = match params.lobe_px {
        Some(l) => l as usize,
        None => {
            let mut best = (3, f32::MIN);
            for &l in AUTO_LOBES_PX.iter().filter(|&&l| 3 * l + 2 < w.min(h)) {
                let (map, cols) = strength_map(rest.data(), w, h, l, 2);
                let score = percentile(map_peaks(&map, cols), SCALE_PEAK_QUANTILE);
                if score > best.1 {
                    best = (l, score);
                }
            }
            best.0
        }
    };
    let binned = params.binned.unwrap_or(full_lobe >= 5) && w >= 32 && h >= 32;
    let (bin, lobe_px) = if binned {
        let half = full_lobe as f64 / 2.0;
        (
            2,
            (2.0 * ((half - 1.0) / 2.0).round() + 1.0).max(3.0) as usize,
        )
    } else {
        (1, full_lobe)
    };
    let radius_px = 0.4 * full_lobe as f64 * std::f64::consts::SQRT_2;
    let mut det = Detector {
        lobe_px,
        bin,
        min_level_ratio: MIN_LEVEL_RATIO_RANGE.0,
        min_rel_strength: 1e-3,
        min_contrast: params.min_contrast,
        radius_px,
        cell_px: ((CELL_RADII * radius_px) / bin as f64).round().max(4.0) as usize,
        window_px: None,
        area: None,
        rim: None,
        dark: false,
        surface: Surface::Flat,
    };
    let all = detect(rest, &det);
    let strengths: Vec<f32> = all.list.iter().map(|m| m.rel_strength).collect();
    let needed = 3;
    if strengths.len() < needed {
        return Err(MarkerError::TooFewMarkers {
            found: strengths.len(),
            needed,
        });
    }
    det.min_rel_strength = params.strength_ratio * percentile(strengths, 0.9);
    let kept: Vec<f32> = all
        .list
        .iter()
        .filter(|m| m.rel_strength > det.min_rel_strength)
        .map(|m| m.rel_level)
        .collect();
    det.min_level_ratio = (LEVEL_FRACTION * percentile(kept, 0.05))
        .clamp(MIN_LEVEL_RATIO_RANGE.0, MIN_LEVEL_RATIO_RANGE.1);
    det.dark = dark;
    Ok(det)
}

/// [`Detector::min_level_ratio`] is set from a rest frame to this fraction
/// of the dimmest rest markers' relative level (5th percentile), so that
/// pins of a second, dimmer colour and markers faded to 40 % stay in.
const LEVEL_FRACTION: f32 = 0.35;
/// Bounds of [`Detector::min_level_ratio`] as set from a rest frame.
const MIN_LEVEL_RATIO_RANGE: (f32, f32) = (0.15, 0.5);
/// Light-envelope cell of the automatic detector, in marker radii (about a
/// pitch of a DigiTac skin); the calibration sets it to the pitch.
const CELL_RADII: f64 = 3.5;

/// Value at quantile `q` (0..=1) of `v` (0 for an empty vector).
pub(crate) fn percentile(v: Vec<f32>, q: f64) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    select_f32(v, k).unwrap_or(0.0)
}

/// 2x2 block average (floor of the sum / 4), dropping an odd last row/column.
/// `w x h` output pixels from the frame region starting at `(x0, y0)`.
fn bin2(frame: &GreyFrame, x0: usize, y0: usize, w: usize, h: usize) -> Vec<u8> {
    let src = frame.data();
    let fw = frame.width();
    let mut out = vec![0u8; w * h];
    // Vertical pair sums first (a plain lane-wise add that vectorises), then
    // the horizontal pairs of those.
    let mut pair = vec![0u16; 2 * w];
    for (y, dst) in out.chunks_exact_mut(w).enumerate() {
        let r0 = &src[(y0 + 2 * y) * fw + x0..][..2 * w];
        let r1 = &src[(y0 + 2 * y + 1) * fw + x0..][..2 * w];
        for ((p, &a), &b) in pair.iter_mut().zip(r0).zip(r1) {
            // 2 x 255 fits u16: wrapping only skips the overflow check.
            *p = (a as u16).wrapping_add(b as u16);
        }
        for (d, p) in dst.iter_mut().zip(pair.chunks_exact(2)) {
            // 4 x 255 fits u16.
            *d = (p[0].wrapping_add(p[1]) >> 2) as u8;
        }
    }
    out
}

/// `img` (`w x h`) mirrored outwards by `[left, top, right, bottom]` px
/// (about its edge pixels: `..., 1, 0 | 0, 1, ...`); left and right at
/// most `w`, top and bottom at most `h`.
fn mirror_pad(img: &[u8], w: usize, h: usize, pad: [usize; 4]) -> Vec<u8> {
    let [l, t, r, b] = [pad[0].min(w), pad[1].min(h), pad[2].min(w), pad[3].min(h)];
    let mut out = Vec::with_capacity((w + l + r) * (h + t + b));
    for y in 0..h + t + b {
        // Rows above the image mirror rows 0, 1, ...; rows below it the
        // last, the one before, ...
        let sy = if y < t {
            t - 1 - y
        } else if y - t >= h {
            2 * h - 1 - (y - t)
        } else {
            y - t
        };
        let row = &img[sy * w..(sy + 1) * w];
        out.extend(row[..l].iter().rev());
        out.extend_from_slice(row);
        out.extend(row[w - r..].iter().rev());
    }
    out
}

/// Copy of the `w x h` frame region starting at `(x0, y0)`.
fn crop(frame: &GreyFrame, x0: usize, y0: usize, w: usize, h: usize) -> Vec<u8> {
    let fw = frame.width();
    let mut out = Vec::with_capacity(w * h);
    for y in y0..y0 + h {
        out.extend_from_slice(&frame.data()[y * fw + x0..y * fw + x0 + w]);
    }
    out
}

/// Integral image with one zero row and column in front, wrapping `u32`
/// (box sums stay exact while a box holds < 2^32 / 255 pixels).
pub fn integral(img: &[u8], w: usize, h: usize) -> Vec<u32> {
    let stride = w + 1;
    let mut ii = vec![0u32; stride * (h + 1)];
    if w == 0 {
        return ii;
    }
    for (y, src) in img.chunks_exact(w).take(h).enumerate() {
        let mut run = 0u32;
        let (prev, cur) = ii.split_at_mut((y + 1) * stride);
        let prev = &prev[y * stride + 1..][..w];
        for ((c, &p), &v) in cur[1..stride].iter_mut().zip(prev).zip(src) {
            run = run.wrapping_add(v as u32);
            *c = p.wrapping_add(run);
        }
    }
    ii
}

/// Blob strength (see the module doc) every `step` pixels, and the map's
/// width ([`determinant_map`]).
fn strength_map(img: &[u8], w: usize, h: usize, lobe: usize, step: usize) -> (Vec<f32>, usize) {
    let (mut out, cols) = determinant_map(img, w, h, lobe, step);
    out.iter_mut().for_each(|v| *v = v.sqrt());
    (out, cols)
}

/// The automatic scale is the lobe whose blob peaks ([`map_peaks`]) reach
/// the highest strength at this quantile. Per peak, not per pixel: one
/// large saturated LED covers more pixels of a large lobe's map than a
/// hundred pins, but it is one peak among them.
const SCALE_PEAK_QUANTILE: f64 = 0.9;

/// The values of `map` (row-major, `cols` wide) at its positive 3x3
/// maxima (at least each of the 8 neighbours), the map's edge left out.
fn map_peaks(map: &[f32], cols: usize) -> Vec<f32> {
    let rows = map.len().checked_div(cols).unwrap_or(0);
    let mut out = Vec::new();
    for y in 1..rows.saturating_sub(1) {
        for x in 1..cols - 1 {
            let v = map[y * cols + x];
            if v > 0.0
                && (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| map[yy * cols + xx] <= v))
            {
                out.push(v);
            }
        }
    }
    out
}

/// Determinant of the box Hessian of bright blobs (0 elsewhere, i.e. the
/// square of the blob strength), every `step` pixels inside the border
/// (sampled row-major, the border left out), and the map's width. Used by
/// the scale search.
fn determinant_map(img: &[u8], w: usize, h: usize, lobe: usize, step: usize) -> (Vec<f32>, usize) {
    let m = (3 * lobe - 1) / 2;
    let step = step.max(1);
    if w <= 2 * m + 1 || h <= 2 * m + 1 {
        return (Vec::new(), 0);
    }
    let ii = integral(img, w, h);
    let s = w + 1;
    let l = lobe as isize;
    let half = (l - 1) / 2;
    let inv_area = 1.0 / (lobe * (2 * lobe - 1)) as f32;
    let n = w - 2 * m;
    let cols = n.div_ceil(step);
    let rows = (h - 2 * m).div_ceil(step);
    let mut values = vec![0f32; cols * rows];
    // Boxes as [x0, y0, x1, y1) offsets from the centre pixel.
    let boxes: [[isize; 4]; 8] = [
        [1 - l, -half - l, l, half + l + 1], // Dyy outer
        [1 - l, -half, l, half + 1],         // Dyy middle
        [-half - l, 1 - l, half + l + 1, l], // Dxx outer
        [-half, 1 - l, half + 1, l],         // Dxx middle
        [-l, -l, 0, 0],                      // Dxy top-left
        [1, 1, l + 1, l + 1],                // Dxy bottom-right
        [1, -l, l + 1, 0],                   // Dxy top-right
        [-l, 1, 0, l + 1],                   // Dxy bottom-left
    ];
    let mut sums = vec![vec![0i32; cols]; 8];
    for (r, out) in values.chunks_exact_mut(cols).enumerate() {
        let y = m + r * step;
        for (b, sum) in boxes.iter().zip(sums.iter_mut()) {
            // Corner rows, each sliced to the n centre columns of this row.
            let at = |dx: isize, dy: isize| {
                let start = ((y as isize + dy) * s as isize + m as isize + dx) as usize;
                &ii[start..start + n]
            };
            let (a, bb, c, d) = (
                at(b[2], b[3]),
                at(b[2], b[1]),
                at(b[0], b[3]),
                at(b[0], b[1]),
            );
            if step == 1 {
                for ((((o, &a), &bb), &c), &d) in sum.iter_mut().zip(a).zip(bb).zip(c).zip(d) {
                    *o = a.wrapping_sub(bb).wrapping_sub(c).wrapping_add(d) as i32;
                }
            } else {
                let it = a
                    .iter()
                    .step_by(step)
                    .zip(bb.iter().step_by(step))
                    .zip(c.iter().step_by(step))
                    .zip(d.iter().step_by(step));
                for (o, (((&a, &bb), &c), &d)) in sum.iter_mut().zip(it) {
                    *o = a.wrapping_sub(bb).wrapping_sub(c).wrapping_add(d) as i32;
                }
            }
        }
        for (k, o) in out.iter_mut().enumerate() {
            let dyy = sums[0][k] - 3 * sums[1][k];
            let dxx = sums[2][k] - 3 * sums[3][k];
            let dxy = sums[4][k] + sums[5][k] - sums[6][k] - sums[7][k];
            if dxx < 0 && dyy < 0 {
                let fxy = dxy as f32 * inv_area * DXY_WEIGHT;
                let det = (dxx as f32 * inv_area) * (dyy as f32 * inv_area) - fxy * fxy;
                *o = det.max(0.0);
            }
        }
    }
    (values, cols)
}

/// How far [`refine`]'s window reaches either side of its centre for a
/// marker of `radius_px`, px.
pub(crate) fn window_reach_px(radius_px: f64) -> i64 {
    crate::numeric::ceil_i64(radius_px) + 2
}

/// The pixel [`refine`]'s window around `p` is centred on. Guesses are
/// >= 0: adding 0.5 and truncating rounds (no libm call).
fn window_centre(p: PointPx) -> (i64, i64) {
    ((p.x + 0.5) as i64, (p.y + 0.5) as i64)
}

/// Half-maximum intensity centroid in a window around `guess` (large
/// enough for the marker when the guess is within 1.5 px): the background is
/// the darkest pixel of the window's outline, the peak the brightest of the
/// 3x3 around the guess, the weights `max(0, v - (bg + peak) / 2)`. `None`
/// when the contrast is below `min_contrast` or the centroid runs away.
/// Also returns the blob's contrast (grey levels) and its effective
/// area above half maximum (px^2).
fn refine(
    frame: &GreyFrame,
    guess: PointPx,
    radius_px: f64,
    min_contrast: f32,
) -> Option<(PointPx, f32, f32)> {
    let rw = window_reach_px(radius_px);
    let (cx, cy) = window_centre(guess);
    let (w, h) = (frame.width() as i64, frame.height() as i64);
    let (x0, x1) = ((cx - rw).max(0), (cx + rw).min(w - 1));
    let (y0, y1) = ((cy - rw).max(0), (cy + rw).min(h - 1));
    if x0 >= x1 || y0 >= y1 {
        return None;
    }
    // The 3x3 around the guess, clipped to the window (window coordinates;
    // a guess past the frame's edge keeps the edge's pixels).
    let (px1, py1) = ((cx + 1).min(x1), (cy + 1).min(y1));
    let peak = [
        ((cx - 1).max(x0).min(px1) - x0) as usize,
        (px1 - x0) as usize,
        ((cy - 1).max(y0).min(py1) - y0) as usize,
        (py1 - y0) as usize,
    ];
    let win = Window {
        first: (y0 * w + x0) as usize,
        stride: w as usize,
        span: (x1 - x0 + 1) as usize,
        rows: (y1 - y0 + 1) as usize,
        peak,
    };
    let data = frame.data();
    let m = if win.span <= LANES
        && win.rows <= LANES
        && win.first + (win.rows - 1) * win.stride + LANES <= data.len()
    {
        narrow_moments(data, &win, min_contrast)
    } else {
        plain_moments(data, &win, min_contrast)
    }?;
    if m.sw == 0 {
        return None;
    }
    let c = PointPx::new(
        x0 as f64 + m.sx as f64 / m.sw as f64,
        y0 as f64 + m.sy as f64 / m.sw as f64,
    );
    // Effective area above half maximum: the weight over the peak's
    // height above the cut (a flat top's own area, a Gaussian's half).
    let area = m.sw as f32 / (m.hi - m.cut).max(1) as f32;
    let contrast = m.hi as f32 - m.lo as f32;
    ((c.x - guess.x).abs() <= rw as f64 && (c.y - guess.y).abs() <= rw as f64)
        .then_some((c, contrast, area))
}

/// A centroid window of [`refine`]: `rows` rows of `span` pixels from
/// `first` (a frame of row length `stride`), and the 3x3 around the guess
/// as `[x0, x1, y0, y1]` (inclusive, window coordinates).
struct Window {
    first: usize,
    stride: usize,
    span: usize,
    rows: usize,
    peak: [usize; 4],
}

/// What [`refine`] measures in a window: background `lo` (the outline's
/// darkest pixel), peak `hi` (the 3x3's brightest), the half-maximum `cut`
/// and the centroid sums `(sum w, sum w x, sum w y)` of the weights
/// `max(0, v - cut)` (`x`, `y` from the window's corner).
#[derive(Debug, PartialEq, Eq)]
struct Moments {
    lo: u8,
    hi: u8,
    cut: u8,
    sw: u32,
    sx: u32,
    sy: u32,
}

/// The half-maximum between `lo` and `hi`, `None` below the contrast floor.
fn half_maximum(lo: u8, hi: u8, min_contrast: f32) -> Option<u8> {
    // lo + (hi - lo) / 2 <= 255.
    (hi as f32 - lo as f32 >= min_contrast.max(1.0)).then(|| lo + ((hi - lo) >> 1))
}

/// [`Moments`] of any window, row by row. Wrapping arithmetic lets the loop
/// vectorise with overflow checks on (release profile); it cannot wrap: a
/// window has at most 63 x 63 pixels of weight <= 255 and index <= 62, so
/// every sum < 2^26.
fn plain_moments(data: &[u8], win: &Window, min_contrast: f32) -> Option<Moments> {
    let row = |j: usize| &data[win.first + j * win.stride..][..win.span];
    let mut lo = row(0)
        .iter()
        .chain(row(win.rows - 1))
        .copied()
        .min()
        .unwrap_or(u8::MAX);
    for j in 0..win.rows {
        lo = lo.min(row(j)[0]).min(row(j)[win.span - 1]);
    }
    let [a, b, c, d] = win.peak;
    let hi = (c..=d)
        .flat_map(|j| &row(j)[a..=b])
        .copied()
        .max()
        .unwrap_or(0);
    let cut = half_maximum(lo, hi, min_contrast)?;
    let (mut sw, mut sx, mut sy) = (0u32, 0u32, 0u32);
    for j in 0..win.rows {
        let (mut rw_sum, mut rx_sum) = (0u32, 0u32);
        for (k, &v) in row(j).iter().enumerate() {
            let wgt = v.saturating_sub(cut) as u32;
            rw_sum = rw_sum.wrapping_add(wgt);
            rx_sum = rx_sum.wrapping_add(wgt.wrapping_mul(k as u32));
        }
        sw = sw.wrapping_add(rw_sum);
        sx = sx.wrapping_add(rx_sum);
        sy = sy.wrapping_add(rw_sum.wrapping_mul(j as u32));
    }
    Some(Moments {
        lo,
        hi,
        cut,
        sw,
        sx,
        sy,
    })
}

/// Lanes of [`narrow_moments`]: a window at most this wide and high (a
/// marker radius up to 5 px) is read once into a fixed block.
const LANES: usize = 16;

/// [`plain_moments`] for a window at most [`LANES`] wide and high whose
/// rows can each be read as [`LANES`] bytes, exactly: the rows are copied
/// into a fixed block once, the lanes past `span` masked off, and the
/// weights summed down the columns in `u16` (at most 16 x 255, and
/// 255 x (0 + ... + 15) for the y moment). Fixed-width lanes vectorise where
/// the window's odd width (11-13 px) would not. Not inlined: inside
/// `refine` the vectoriser gave up on such loops (3x the instructions).
#[cfg(not(target_arch = "x86_64"))]
#[inline(never)]
fn narrow_moments(data: &[u8], win: &Window, min_contrast: f32) -> Option<Moments> {
    const INDEX: [u8; LANES] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15];
    let (rows, span) = (win.rows.clamp(1, LANES), win.span.clamp(1, LANES));
    let mut block = [[0u8; LANES]; LANES];
    let mut start = win.first;
    for r in block.iter_mut().take(rows) {
        r.copy_from_slice(data.get(start..start.wrapping_add(LANES))?);
        start = start.wrapping_add(win.stride);
    }
    let mut keep = [0u8; LANES];
    for (k, &i) in keep.iter_mut().zip(&INDEX) {
        *k = if (i as usize) < span { u8::MAX } else { 0 };
    }
    // The outline: the first and last rows (the lanes past `span` lifted
    // out of the way), and the first and last columns of the column minima.
    let mut col_min = [u8::MAX; LANES];
    for r in &block[..rows] {
        for (m, &v) in col_min.iter_mut().zip(r) {
            *m = (*m).min(v);
        }
    }
    let mut ends = [0u8; LANES];
    for (i, e) in ends.iter_mut().enumerate() {
        *e = (block[0][i] | !keep[i]).min(block[rows - 1][i] | !keep[i]);
    }
    // Horizontal minimum by halving (vectorises; a fold does not).
    for half in [8, 4, 2, 1] {
        for i in 0..half {
            ends[i] = ends[i].min(ends[i + half]);
        }
    }
    let lo = ends[0].min(col_min[0]).min(col_min[span - 1]);
    // The 3x3 (at most) around the guess: its first, middle and last
    // columns of each of its rows.
    let [a, b, c, d] = win.peak;
    let (b, d) = (b.min(span - 1), d.min(rows - 1));
    let (a, c) = (a.min(b), c.min(d));
    let mid = (a + 1).min(b);
    let hi = block[c..=d]
        .iter()
        .fold(0u8, |m, r| m.max(r[a]).max(r[mid]).max(r[b]));
    let cut = half_maximum(lo, hi, min_contrast)?;
    let (mut acc_w, mut acc_y) = ([0u16; LANES], [0u16; LANES]);
    for (j, r) in block[..rows].iter().enumerate() {
        let jj = j as u16;
        for i in 0..LANES {
            let wgt = (r[i].saturating_sub(cut) & keep[i]) as u16;
            acc_w[i] = acc_w[i].wrapping_add(wgt);
            acc_y[i] = acc_y[i].wrapping_add(wgt.wrapping_mul(jj));
        }
    }
    let sw = acc_w.iter().map(|&v| v as u32).sum();
    let sx = acc_w
        .iter()
        .zip(&INDEX)
        .map(|(&v, &k)| v as u32 * k as u32)
        .sum();
    let sy = acc_y.iter().map(|&v| v as u32).sum();
    Some(Moments {
        lo,
        hi,
        cut,
        sw,
        sx,
        sy,
    })
}

/// [`narrow_moments`] in SSE2 (every x86-64 CPU has it), on the rows in
/// place: the lane mask is one compare, the outline's minimum a few
/// vector minima, and per row of weights one saturating subtract, one
/// mask and four 16-bit adds (column sums, and their running total for
/// `sum w y`); the sums over lanes come once at the end. Exact (the
/// proptest against [`plain_moments`]): no lane overflows (bounds below).
/// Measured with callgrind on the other renderer's 24 nominal dome frames
/// (955 markers): 1000 -> 610 instructions a window, the pipeline 4.25 M
/// -> 3.68 M a frame (BENCHMARKS.md, session 12); the column sums then
/// took the pipeline from 3.64 M to 3.55 M (session 26).
#[cfg(target_arch = "x86_64")]
#[inline(never)]
fn narrow_moments(data: &[u8], win: &Window, min_contrast: f32) -> Option<Moments> {
    use std::arch::x86_64::{
        __m128i, _mm_add_epi16, _mm_add_epi32, _mm_and_si128, _mm_andnot_si128, _mm_cmplt_epi8,
        _mm_cvtsi128_si32, _mm_loadu_si128, _mm_madd_epi16, _mm_max_epu8, _mm_min_epu8,
        _mm_or_si128, _mm_set1_epi16, _mm_set1_epi8, _mm_setr_epi16, _mm_setr_epi8,
        _mm_setzero_si128, _mm_shuffle_epi32, _mm_srli_si128, _mm_storeu_si128, _mm_subs_epu8,
        _mm_unpackhi_epi16, _mm_unpackhi_epi8, _mm_unpacklo_epi16, _mm_unpacklo_epi8,
    };
    let (rows, span) = (win.rows.clamp(1, LANES), win.span.clamp(1, LANES));
    // Every row must have LANES bytes: checked once, on the last.
    let last = (rows - 1).checked_mul(win.stride)?.checked_add(win.first)?;
    if last.checked_add(LANES)? > data.len() {
        return None;
    }
    // Wrapping: no overflow check per row (the last row's start was
    // checked above, and every row starts before it).
    let row_at = |j: usize| win.first.wrapping_add(j.wrapping_mul(win.stride));
    // The 3x3 (at most) around the guess: columns `a..=b` of rows `c..=d`.
    let [a, b, c, d] = win.peak;
    let (b, d) = (b.min(span - 1), d.min(rows - 1));
    let (a, c) = (a.min(b), c.min(d));
    // SAFETY: SSE2 is part of x86-64; every load reads the LANES bytes at a
    // row start j < rows, all inside `data` (checked above), or a local
    // array of LANES bytes.
    unsafe {
        let row = |j: usize| -> __m128i { _mm_loadu_si128(data.as_ptr().add(row_at(j)).cast()) };
        let zero = _mm_setzero_si128();
        let ones = _mm_set1_epi8(-1);
        let index = _mm_setr_epi8(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
        let below = |n: usize| _mm_cmplt_epi8(index, _mm_set1_epi8(n as i8));
        let keep = below(span);
        // The peak: the rows' maximum in the 3x3's lanes (those below
        // `b + 1` and not below `a`), then the maximum across lanes.
        let rows3 = _mm_max_epu8(_mm_max_epu8(row(c), row((c + 1).min(d))), row(d));
        let mut top = _mm_andnot_si128(below(a), _mm_and_si128(below(b + 1), rows3));
        top = _mm_max_epu8(top, _mm_srli_si128::<8>(top));
        top = _mm_max_epu8(top, _mm_srli_si128::<4>(top));
        top = _mm_max_epu8(top, _mm_srli_si128::<2>(top));
        top = _mm_max_epu8(top, _mm_srli_si128::<1>(top));
        let hi = _mm_cvtsi128_si32(top) as u8;
        // The outline: the first and last rows (the lanes past `span`
        // lifted out of the way), and the first and last columns of the
        // column minima.
        let mut col_min = ones;
        for j in 0..rows {
            col_min = _mm_min_epu8(col_min, row(j));
        }
        let off = _mm_andnot_si128(keep, ones);
        let mut ends = _mm_min_epu8(_mm_or_si128(row(0), off), _mm_or_si128(row(rows - 1), off));
        ends = _mm_min_epu8(ends, _mm_srli_si128::<8>(ends));
        ends = _mm_min_epu8(ends, _mm_srli_si128::<4>(ends));
        ends = _mm_min_epu8(ends, _mm_srli_si128::<2>(ends));
        ends = _mm_min_epu8(ends, _mm_srli_si128::<1>(ends));
        let mut cols = [0u8; LANES];
        _mm_storeu_si128(cols.as_mut_ptr().cast(), col_min);
        let lo = (_mm_cvtsi128_si32(ends) as u8)
            .min(cols[0])
            .min(cols[span - 1]);
        let cut = half_maximum(lo, hi, min_contrast)?;
        let cut_v = _mm_set1_epi8(cut as i8);
        // Per row, the weights widened to u16 lanes and added to the
        // column sums `c`, and the column sums so far added to `t`: at the
        // end, `c` holds each column's weight and `t` each column's
        // `sum (rows - j) w`, so that `sum j w = rows c - t`. Per lane
        // `c <= 16 x 255` and `t <= 136 x 255`, both below 2^16.
        let (mut c_lo, mut c_hi, mut t_lo, mut t_hi) = (zero, zero, zero, zero);
        for j in 0..rows {
            let w = _mm_and_si128(_mm_subs_epu8(row(j), cut_v), keep);
            c_lo = _mm_add_epi16(c_lo, _mm_unpacklo_epi8(w, zero));
            c_hi = _mm_add_epi16(c_hi, _mm_unpackhi_epi8(w, zero));
            t_lo = _mm_add_epi16(t_lo, c_lo);
            t_hi = _mm_add_epi16(t_hi, c_hi);
        }
        // Column sums (< 2^15) times 1 and times the lane index, in pairs:
        // i32 lanes. `t` can reach 2^15, so it is widened without a sign.
        let one = _mm_set1_epi16(1);
        let index_lo = _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7);
        let index_hi = _mm_setr_epi16(8, 9, 10, 11, 12, 13, 14, 15);
        let sw = _mm_madd_epi16(_mm_add_epi16(c_lo, c_hi), one);
        let sx = _mm_add_epi32(
            _mm_madd_epi16(c_lo, index_lo),
            _mm_madd_epi16(c_hi, index_hi),
        );
        let st = _mm_add_epi32(
            _mm_add_epi32(
                _mm_unpacklo_epi16(t_lo, zero),
                _mm_unpackhi_epi16(t_lo, zero),
            ),
            _mm_add_epi32(
                _mm_unpacklo_epi16(t_hi, zero),
                _mm_unpackhi_epi16(t_hi, zero),
            ),
        );
        let sum32 = |v| {
            let v = _mm_add_epi32(v, _mm_shuffle_epi32::<0b01_00_11_10>(v));
            let v = _mm_add_epi32(v, _mm_shuffle_epi32::<0b10_11_00_01>(v));
            _mm_cvtsi128_si32(v) as u32
        };
        let sw = sum32(sw);
        Some(Moments {
            lo,
            hi,
            cut,
            sw,
            sx: sum32(sx),
            sy: (rows as u32) * sw - sum32(st),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{rest_frame, Category};
    use crate::test_fixtures;

    #[test]
    fn integral_image_box_sums_match_direct_sums() {
        let img: Vec<u8> = (0..35).map(|i| (i * 37 % 251) as u8).collect();
        let ii = integral(&img, 7, 5);
        let direct: u32 = (1..4)
            .flat_map(|y| (2..6).map(move |x| (x, y)))
            .map(|(x, y)| img[y * 7 + x] as u32)
            .sum();
        let s = 8;
        let boxed = ii[4 * s + 6]
            .wrapping_sub(ii[s + 6])
            .wrapping_sub(ii[4 * s + 2])
            .wrapping_add(ii[s + 2]);
        assert_eq!(boxed, direct);
    }

    proptest::proptest! {
        /// The occupancy grid refuses a point exactly when a marker it
        /// holds (the first claimed in each cell) lies within the radius:
        /// looking at 2x2 cells misses none that 3x3 would see. Points
        /// spread over and past a window that does not start at 0.
        #[test]
        fn occupancy_refuses_exactly_the_points_near_a_held_marker(
            points in proptest::collection::vec((-6.0f64..46.0, -6.0f64..36.0), 1..120),
        ) {
            let mut grid = Occupancy::new([3, 2, 40, 30]);
            let (mut list, mut held): (Vec<Marker>, Vec<PointPx>) = (Vec::new(), Vec::new());
            let mut cells = std::collections::HashSet::new();
            for (x, y) in points {
                let p = PointPx::new(x, y);
                let near = held
                    .iter()
                    .any(|q| (q.x - x).powi(2) + (q.y - y).powi(2) < DUPLICATE_PX * DUPLICATE_PX);
                let claimed = grid.claim(p, DUPLICATE_PX, &list);
                proptest::prop_assert_eq!(claimed, !near, "point ({}, {})", x, y);
                if claimed {
                    let cell = (
                        (((x - 3.0) / Occupancy::CELL_PX) as usize).min(grid.cols - 1),
                        (((y - 2.0) / Occupancy::CELL_PX) as usize).min(grid.rows - 1),
                    );
                    if cells.insert(cell) {
                        held.push(p);
                    }
                    list.push(Marker {
                        pos: p,
                        strength: 1.0,
                        peak: 0,
                        rel_level: 1.0,
                        rel_strength: 1.0,
                        area_px: 1.0,
                        followed_from: None,
                    });
                }
            }
        }

        /// A point is within reach of a blur path exactly when it is within
        /// reach of the segment from the rest place to the last shift, for
        /// a path that runs out along one line and then stays (away from
        /// the boundary, where rounding decides).
        #[test]
        fn a_point_is_within_a_blur_path_when_it_is_near_its_segment(
            sx in -6.0f64..6.0,
            sy in -6.0f64..6.0,
            reached in 0usize..BLUR_LEVELS_PX.len(),
            ox in -12.0f64..12.0,
            oy in -12.0f64..12.0,
            reach_px in 0.5f64..5.0,
        ) {
            // Shifts growing along (sx, sy) up to level `reached`, then flat.
            let mut at = [PointPx::default(); BLUR_LEVELS_PX.len()];
            for (l, a) in at.iter_mut().enumerate() {
                let f = (l.min(reached) + 1) as f64 / (reached + 1) as f64;
                *a = PointPx::new(f * sx, f * sy);
            }
            let path = BlurPath { at };
            let len2 = sx * sx + sy * sy;
            let t = if len2 > 0.0 { ((ox * sx + oy * sy) / len2).clamp(0.0, 1.0) } else { 0.0 };
            let d = (ox - t * sx).hypot(oy - t * sy);
            proptest::prop_assume!((d - reach_px).abs() > 1e-6);
            proptest::prop_assert_eq!(path.within(PointPx::new(ox, oy), reach_px), d <= reach_px);
            let length = path.length_px();
            proptest::prop_assert!((length - len2.sqrt()).abs() < 1e-9, "{} {}", length, len2.sqrt());
        }

        /// The fixed-block moments are the plain ones, to the last bit, for
        /// every window up to 16 x 16, any 3x3 inside it and any contrast
        /// floor.
        #[test]
        fn narrow_moments_equal_the_plain_moments(
            pixels in proptest::collection::vec(proptest::prelude::any::<u8>(), 40 * 20),
            x0 in 0usize..20,
            span in 1usize..=LANES,
            rows in 1usize..=LANES,
            px in 0usize..LANES,
            py in 0usize..LANES,
            min_contrast in 0.0f32..80.0,
        ) {
            let (px, py) = (px.min(span - 1), py.min(rows - 1));
            let win = Window {
                first: x0,
                stride: 40,
                span,
                rows,
                peak: [px.saturating_sub(1), (px + 1).min(span - 1), py.saturating_sub(1), (py + 1).min(rows - 1)],
            };
            let pixels = &pixels[..(rows - 1) * 40 + x0 + LANES];
            proptest::prop_assert_eq!(
                narrow_moments(pixels, &win, min_contrast),
                plain_moments(pixels, &win, min_contrast)
            );
        }

        /// The integer-key selection picks the value a sort by
        /// `f32::total_cmp` puts at the quantile, to the bit: negative
        /// values, both zeros, infinities and NaN included.
        #[test]
        fn percentile_is_the_sorted_value(
            bits in proptest::collection::vec(proptest::prelude::any::<u32>(), 1..60),
            small in proptest::collection::vec(-3.0f32..3.0, 0..60),
            q in 0.0f64..=1.0,
        ) {
            let mut v: Vec<f32> = bits.into_iter().map(f32::from_bits).collect();
            v.extend(small);
            v.extend([0.0, -0.0]);
            let mut sorted = v.clone();
            sorted.sort_by(f32::total_cmp);
            let want = sorted[((v.len() - 1) as f64 * q).round() as usize];
            proptest::prop_assert_eq!(percentile(v, q).to_bits(), want.to_bits());
        }

        /// A chord's walk through the frame (a point at least `reach`
        /// inside) ends where the checked one does: the same frame framed
        /// by `reach` dark pixels puts every point that far inside.
        #[test]
        fn chords_walked_inside_match_the_checked_ones(
            pixels in proptest::collection::vec(0u8..4, 9 * 7),
            sx in 0usize..9,
            sy in 0usize..7,
            level in 1u8..4,
            reach in 1usize..6,
        ) {
            let frame = GreyFrame::new(9, 7, pixels.clone()).unwrap();
            let (pw, ph) = (9 + 2 * reach, 7 + 2 * reach);
            let mut framed = vec![0u8; pw * ph];
            for y in 0..7 {
                framed[(y + reach) * pw + reach..][..9].copy_from_slice(&pixels[y * 9..][..9]);
            }
            let framed = GreyFrame::new(pw, ph, framed).unwrap();
            proptest::prop_assert_eq!(
                longest_chord_px(&frame, (sx, sy), level, reach),
                longest_chord_px(&framed, (sx + reach, sy + reach), level, reach)
            );
        }

        /// The 2x2 binning is the floor of each block's mean, for any width
        /// and offset.
        #[test]
        fn binning_is_the_floor_of_the_block_mean(
            pixels in proptest::collection::vec(proptest::prelude::any::<u8>(), 23 * 9),
            x0 in 0usize..3,
            y0 in 0usize..2,
        ) {
            let frame = GreyFrame::new(23, 9, pixels.clone()).unwrap();
            let (w, h) = ((23 - x0) / 2, (9 - y0) / 2);
            let binned = bin2(&frame, x0, y0, w, h);
            for y in 0..h {
                for x in 0..w {
                    let at = |dx: usize, dy: usize| {
                        pixels[(y0 + 2 * y + dy) * 23 + x0 + 2 * x + dx] as u16
                    };
                    let mean = (at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)) / 4;
                    proptest::prop_assert_eq!(binned[y * w + x] as u16, mean, "({}, {})", x, y);
                }
            }
        }
    }

    #[test]
    fn finds_every_synthetic_marker_with_subpixel_accuracy() {
        let (rest, det) = test_fixtures::nominal_rest_and_detector();
        let found = detect(&rest.image, &det);
        let truth = &rest.markers;
        let matched = test_fixtures::match_points(&found.positions(), truth, 3.0);
        assert!(
            matched.len() as f64 >= 0.97 * truth.len() as f64,
            "{} of {}",
            matched.len(),
            truth.len()
        );
        assert!(
            found.len() <= truth.len() + 3,
            "{} false blobs",
            found.len() - truth.len()
        );
        let mut err: Vec<f64> = matched.iter().map(|&(_, _, d)| d).collect();
        err.sort_by(f64::total_cmp);
        let median = err[err.len() / 2];
        assert!(median < 0.25, "median centroid error {median} px");
    }

    #[test]
    fn mirror_padding_reflects_about_the_edge_pixels() {
        let img: Vec<u8> = (0..6).collect(); // 3 x 2: [0 1 2; 3 4 5]
        let padded = mirror_pad(&img, 3, 2, [2, 1, 1, 2]);
        // Columns -2..4 -> 1 0 | 0 1 2 | 2; rows -1..4 -> 0 | 0 1 | 1 0.
        let row = |r: &[u8]| vec![r[1], r[0], r[0], r[1], r[2], r[2]];
        let (r0, r1) = (row(&img[..3]), row(&img[3..]));
        let expected: Vec<u8> = [&r0, &r0, &r1, &r1, &r0]
            .into_iter()
            .flatten()
            .copied()
            .collect();
        assert_eq!(padded, expected);
        // Pads larger than the image are cut to its size.
        assert_eq!(mirror_pad(&img, 3, 2, [9, 9, 0, 0]).len(), 6 * 4);
    }

    #[test]
    fn pins_cut_by_the_frame_edge_are_found() {
        let (w, h, pitch) = (320, 240, 16.0);
        let mut pins = test_fixtures::hex_points(w, h, pitch);
        // A deep tap pushes the outer pins to the edge: centres 0.5-2 px
        // inside it, up to half of each pin cut off.
        let cut: Vec<PointPx> = (0..6)
            .map(|k| PointPx::new(0.5 + 0.3 * k as f64, 24.0 + 32.0 * k as f64))
            .chain((0..6).map(|k| PointPx::new(40.0 + 48.0 * k as f64, 2.0 - 0.3 * k as f64)))
            .collect();
        pins.retain(|p| cut.iter().all(|q| (p.x - q.x).hypot(p.y - q.y) > pitch));
        let spots: Vec<_> = pins.iter().chain(&cut).map(|&p| (p, 2.5, 150.0)).collect();
        let frame = test_fixtures::spots_frame(w, h, 30.0, &spots);
        let params = MarkerParams {
            polarity: Polarity::Bright,
            ..MarkerParams::default()
        };
        let det = auto_detector(&frame, &params).unwrap();
        let found = detect(&frame, &det).positions();
        for q in &cut {
            let d = found
                .iter()
                .map(|p| (p.x - q.x).hypot(p.y - q.y))
                .fold(f64::INFINITY, f64::min);
            assert!(d < 2.0, "the pin at {q:?}: nearest marker {d:.2} px away");
        }
        assert_eq!(found.len(), pins.len() + cut.len());
    }

    #[test]
    fn binarised_pins_under_vignetting_and_a_gradient_are_found() {
        // Flat-topped pins (a thresholded TacTip frame) whose light then
        // falls off towards the corners and across the frame: each pin's
        // top tilts, and its brightest pixel is on its rim.
        let (w, h, pitch) = (420, 420, 18.0);
        let pins = test_fixtures::hex_points(w, h, pitch);
        let frame = |gain: &dyn Fn(f64, f64) -> f64| {
            let data = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    let on = pins.iter().any(|p| (p.x - x).hypot(p.y - y) <= 6.0);
                    (if on { 255.0 * gain(x, y) } else { 0.0 }).round() as u8
                })
                .collect();
            GreyFrame::new(w, h, data).unwrap()
        };
        let rest = frame(&|_, _| 1.0);
        let lit = frame(&|x, y| {
            let r2 = ((x - 210.0).powi(2) + (y - 210.0).powi(2)) / 297f64.powi(2);
            (1.0 - 0.55 * r2) * (0.85 + 0.3 * x / w as f64)
        });
        let params = MarkerParams {
            polarity: Polarity::Bright,
            ..MarkerParams::default()
        };
        let det = auto_detector(&rest, &params).unwrap();
        for image in [&rest, &lit] {
            let found = detect(image, &det).positions();
            let matched = test_fixtures::match_points(&found, &pins, 1.0);
            assert_eq!(matched.len(), pins.len(), "{} found", found.len());
            assert_eq!(found.len(), pins.len());
        }
    }

    #[test]
    fn blur_is_fitted_only_where_it_explains_the_gauges() {
        // 24 markers on a ring that blur pushes outwards, 0.6 px per px of
        // added blur, and 24 inside that it leaves alone.
        let n = 24;
        let dir = |k: usize| {
            let a = std::f64::consts::TAU * (k % n) as f64 / n as f64;
            (a.cos(), a.sin())
        };
        let rest: Vec<PointPx> = (0..2 * n)
            .map(|k| {
                let r = if k < n { 100.0 } else { 50.0 };
                PointPx::new(200.0 + r * dir(k).0, 200.0 + r * dir(k).1)
            })
            .collect();
        let levels = BlurLevels::from_shifts(
            BLUR_LEVELS_PX
                .iter()
                .map(|&s| {
                    (0..2 * n)
                        .map(|k| {
                            let m = if k < n { 0.6 * s } else { 0.0 };
                            PointPx::new(m * dir(k).0, m * dir(k).1)
                        })
                        .collect()
                })
                .collect(),
        );
        assert_eq!(levels.gauges.len(), n);
        let frame = |u: &dyn Fn(usize) -> (f64, f64)| -> Vec<Marker> {
            rest.iter()
                .enumerate()
                .map(|(k, p)| Marker {
                    pos: PointPx::new(p.x + u(k).0, p.y + u(k).1),
                    strength: 100.0,
                    peak: 0,
                    rel_level: 1.0,
                    rel_strength: 1.0,
                    area_px: 20.0,
                    followed_from: Some(k),
                })
                .collect()
        };
        // Sub-pixel noise of 0.05 px, alternating.
        let noise = |k: usize| if k % 2 == 0 { 0.05 } else { -0.05 };
        let blurred = |s: f64| {
            move |k: usize| {
                let m = if k < n { 0.6 * s } else { 0.0 };
                (m * dir(k).0 + noise(k), m * dir(k).1 - noise(k))
            }
        };
        let fit = |u: &dyn Fn(usize) -> (f64, f64)| levels.fit(&rest, &frame(u)).map(|f| f.0);
        // 1.75 px blurrier; the same with a press that moved 8 of the ring
        // 3 px sideways.
        assert_eq!(fit(&blurred(1.75)), Some(1.75));
        let pressed = |k: usize| {
            let u = blurred(1.75)(k);
            if k < 8 {
                (u.0 - 3.0 * dir(k).1, u.1 + 3.0 * dir(k).0)
            } else {
                u
            }
        };
        assert_eq!(fit(&pressed), Some(1.75));
        // As sharp as the rest; moved less than BLUR_MIN_MOVE_PX.
        assert_eq!(fit(&|k| (noise(k), noise(k))), None);
        assert_eq!(fit(&blurred(0.3)), None);
        // The whole skin moved 2 px, or turned by 1.5 px: no blur explains
        // that well enough.
        assert_eq!(fit(&|k| (2.0 + noise(k), noise(k))), None);
        assert_eq!(fit(&|k| (-1.5 * dir(k).1, 1.5 * dir(k).0)), None);
        // Under half the gauges followed.
        let few: Vec<Marker> = frame(&blurred(1.75))
            .into_iter()
            .filter(|m| m.followed_from.is_some_and(|k| k > n / 2))
            .collect();
        assert_eq!(levels.fit(&rest, &few), None);
        // Levels made for another rest.
        assert_eq!(levels.fit(&rest[1..], &frame(&blurred(1.75))[1..]), None);
    }

    /// A 64 x 64 frame of level 60 with clipped (255) blobs: ellipses
    /// `(centre, semi-axes (x, y))`, their edges anti-aliased over a pixel.
    fn clipped_blobs(blobs: &[(PointPx, (f64, f64))]) -> GreyFrame {
        let data = (0..64 * 64)
            .map(|k| {
                let (x, y) = ((k % 64) as f64, (k / 64) as f64);
                let cover = blobs
                    .iter()
                    .map(|&(c, (a, b))| {
                        let r = ((x - c.x) / a).hypot((y - c.y) / b);
                        // Distance inside the edge, in px along the
                        // smaller axis (exact for discs).
                        ((1.0 - r) * a.min(b) + 0.5).clamp(0.0, 1.0)
                    })
                    .fold(0.0, f64::max);
                (60.0 + 195.0 * cover).round() as u8
            })
            .collect();
        GreyFrame::new(64, 64, data).unwrap()
    }

    #[test]
    fn pins_run_together_are_split_and_an_enlarged_pin_is_not() {
        let pin = (5.0, 5.0);
        let area = (std::f64::consts::PI * 25.0) as f32;
        let (level, at) = (157, PointPx::new(32.0, 32.0));
        let near = |got: &[PointPx], want: &[PointPx]| {
            got.len() == want.len()
                && want
                    .iter()
                    .all(|w| got.iter().any(|g| (g.x - w.x).hypot(g.y - w.y) < 0.5))
        };
        // Two pins 9 px apart along a slope, and three in a row 9.5 px
        // apart.
        let (dx, dy) = (9.0 * 0.8, 9.0 * 0.6);
        let two = [
            PointPx::new(32.0 - dx / 2.0, 32.0 - dy / 2.0),
            PointPx::new(32.0 + dx / 2.0, 32.0 + dy / 2.0),
        ];
        let got = split_chain(&clipped_blobs(&two.map(|c| (c, pin))), at, level, area);
        assert!(near(got.as_deref().unwrap_or(&[]), &two), "{got:?}");
        let three = [22.5, 32.0, 41.5].map(|x| PointPx::new(x, 32.0));
        let got = split_chain(&clipped_blobs(&three.map(|c| (c, pin))), at, level, area);
        assert!(near(got.as_deref().unwrap_or(&[]), &three), "{got:?}");
        // One pin, tilted and enlarged by a press: an ellipse of two pin
        // areas and the elongation of two pins, but no neck.
        let tilted = clipped_blobs(&[(at, (10.0, 5.0))]);
        assert_eq!(split_chain(&tilted, at, level, area), None);
        // Two touching pins unclipped (their tops at 200) and blurred by
        // 1.2 px, against a pin's effective area as `refine` measures it
        // on one such pin.
        let soft = |centres: &[PointPx]| {
            let sharp = clipped_blobs(&centres.iter().map(|&c| (c, pin)).collect::<Vec<_>>());
            let top: Vec<u8> = sharp.data().iter().map(|&v| v.min(200)).collect();
            GreyFrame::new(64, 64, top).unwrap().blurred(1.2)
        };
        let (_, _, soft_area) = refine(&soft(&[at]), at, 5.0, 1.0).unwrap();
        let touching = [PointPx::new(27.0, 32.0), PointPx::new(37.0, 32.0)];
        let got = split_chain(&soft(&touching), at, 130, soft_area);
        assert!(near(got.as_deref().unwrap_or(&[]), &touching), "{got:?}");
        // Two pins 3 px apart at their edges are two blobs: the fill holds
        // one pin.
        let apart = [PointPx::new(25.5, 32.0), PointPx::new(38.5, 32.0)];
        let blobs = clipped_blobs(&apart.map(|c| (c, pin)));
        assert_eq!(split_chain(&blobs, apart[0], level, area), None);
        // A blob larger than three pins, and one that reaches past two pin
        // diameters, are left alone.
        let big = clipped_blobs(&[(at, (9.0, 9.0))]);
        assert_eq!(split_chain(&big, at, level, area), None);
        let long = clipped_blobs(&[(at, (26.0, 4.0))]);
        assert_eq!(split_chain(&long, at, level, area), None);
    }

    #[test]
    fn clipped_pins_a_press_pushed_together_are_each_found() {
        // Flat-topped clipped pins (radius 6 px, pitch 18 px, a 1 px
        // blur). A press hides the pin under it and pushes the two pins
        // above it, and the two below, 4.5 px towards each other: each
        // pair runs into one plateau (centres 9 px apart), which following
        // sees as one blob. Without the split, one pin of a pair is 16 px
        // from the nearest marker.
        squeezed_pairs_are_found(SqueezedPairs {
            size: 420,
            pitch_px: 18.0,
            radius_px: 6.0,
            top: 255,
            push_px: 4.5,
            blur_px: 1.0,
            within_px: 0.5,
        });
    }

    /// A hex lattice of disc pins (`radius_px`, level `top` over a skin of
    /// 30) at `pitch_px` in a `size` x `size` frame, and a press at its
    /// middle that hides the pin under it and pushes the two pins above
    /// it, and the two below, `push_px` towards each other. The rest is
    /// blurred by 1 px, the frame by `blur_px`.
    struct SqueezedPairs {
        size: usize,
        pitch_px: f64,
        radius_px: f64,
        top: u8,
        push_px: f64,
        blur_px: f64,
        within_px: f64,
    }

    /// Following with the local search finds each pushed pin of `scene`
    /// within its `within_px`, and a marker for every other pin.
    fn squeezed_pairs_are_found(scene: SqueezedPairs) {
        let (w, h, pitch) = (scene.size, scene.size, scene.pitch_px);
        let rest_pins = test_fixtures::hex_points(w, h, pitch);
        let draw = |pins: &[PointPx], blur_px: f64| {
            let data = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    let on = pins
                        .iter()
                        .any(|p| (p.x - x).hypot(p.y - y) <= scene.radius_px);
                    if on {
                        scene.top
                    } else {
                        30
                    }
                })
                .collect();
            GreyFrame::new(w, h, data).unwrap().blurred(blur_px)
        };
        let nearest = |q: PointPx| {
            let d = |k: usize| (rest_pins[k].x - q.x).hypot(rest_pins[k].y - q.y);
            (0..rest_pins.len())
                .min_by(|&a, &b| d(a).total_cmp(&d(b)))
                .unwrap()
        };
        let mut pins = rest_pins.clone();
        let middle = w as f64 / 2.0;
        let pressed = nearest(PointPx::new(middle, middle));
        let c = rest_pins[pressed];
        let mut moved = Vec::new();
        for dy in [-1.0, 1.0] {
            let row = 0.75f64.sqrt() * pitch * dy;
            let left = nearest(PointPx::new(c.x - 0.5 * pitch, c.y + row));
            let right = nearest(PointPx::new(c.x + 0.5 * pitch, c.y + row));
            pins[left].x += scene.push_px;
            pins[right].x -= scene.push_px;
            moved.extend([left, right]);
        }
        let params = crate::params::Params::default();
        let rest = draw(&rest_pins, 1.0);
        let cal = crate::calibrate::calibrate(std::slice::from_ref(&rest), &params).unwrap();
        let mut shown = pins.clone();
        shown.remove(pressed);
        let (found, search) = follow_or_search(
            &draw(&shown, scene.blur_px),
            &cal.detector,
            &cal.reference(),
            0.3 * cal.pitch_px,
            Some(cal.pitch_px),
        );
        assert_eq!(search, Search::Local);
        let found = found.positions();
        for &k in &moved {
            let off = found
                .iter()
                .map(|f| (f.x - pins[k].x).hypot(f.y - pins[k].y))
                .fold(f64::INFINITY, f64::min);
            assert!(
                off < scene.within_px,
                "pin {k} at {:?}: nearest marker {off:.2} px",
                pins[k]
            );
        }
        assert_eq!(found.len() + 1, cal.rest_markers.len());
    }

    /// The generator's `scene` of `cat` (sensor seed 5), its calibration
    /// and the markers following with the local search finds (a local
    /// search it must be).
    fn locally_searched(
        cat: crate::synth::Category,
        scene: u64,
    ) -> (
        crate::calibrate::Calibration,
        crate::synth::SynthFrame,
        Markers,
    ) {
        let params = crate::params::Params::default();
        let cal = test_fixtures::calibrated(cat, 640, 480, &params);
        let f = crate::synth::render(&cat.scene(&cat.sensor(640, 480, 5), scene));
        let (found, search) = follow_or_search(
            &f.image,
            &cal.detector,
            &cal.reference(),
            0.3 * cal.pitch_px,
            Some(cal.pitch_px),
        );
        assert_eq!(search, Search::Local, "{cat:?} scene {scene}");
        (cal, f, found)
    }

    #[test]
    fn a_pin_squeezed_against_its_neighbour_is_found_once() {
        use crate::synth::Category;
        // The generator's two-colour scene 322: a pin the press pushed
        // against its neighbour (433, 220) has no determinant at the
        // binned scale, only at full resolution. Its dim scene 312: an
        // enlarged pin has a second candidate whose centroid lies 2.3 px
        // from the first.
        for (cat, scene) in [(Category::TwoColour, 322), (Category::Dim, 312)] {
            let (cal, f, found) = locally_searched(cat, scene);
            assert_eq!(cal.detector.bin, 2, "{cat:?}: the binned scale is the case");
            let found = found.positions();
            let near = |p: PointPx, list: &[PointPx], px: f64| {
                list.iter().any(|q| (q.x - p.x).hypot(q.y - p.y) < px)
            };
            let missed: Vec<_> = f
                .markers
                .iter()
                .filter(|&&t| !near(t, &found, 1.0))
                .collect();
            let extra: Vec<_> = found
                .iter()
                .filter(|&&m| !near(m, &f.markers, 1.5))
                .collect();
            assert!(
                missed.is_empty() && extra.is_empty(),
                "{cat:?}: missed {missed:?}, extra {extra:?}"
            );
            assert_eq!(found.len(), f.markers.len(), "{cat:?}");
        }
    }

    #[test]
    fn searched_markers_are_paired_where_their_neighbours_moved_them() {
        use crate::synth::Category;
        // The generator's textured scene 121: paired from their rest places
        // alone, 6 of the searched pins took a neighbour's rest marker (its
        // rest place was nearer than their own's, the press having moved
        // them out along its ring); from their neighbours' displacements,
        // none.
        let (cal, f, found) = locally_searched(Category::Textured, 121);
        assert_eq!(f.markers.len(), f.rest_markers.len(), "no dropout");
        let d = |a: PointPx, b: PointPx| (a.x - b.x).hypot(a.y - b.y);
        let wrong: Vec<PointPx> = found
            .list
            .iter()
            .filter_map(|m| {
                let r = cal.rest_markers[m.followed_from?];
                let i = (0..f.rest_markers.len())
                    .min_by(|&a, &b| d(f.rest_markers[a], r).total_cmp(&d(f.rest_markers[b], r)))?;
                (d(f.markers[i], m.pos) > 2.0).then_some(m.pos)
            })
            .collect();
        assert!(wrong.is_empty(), "markers on another pin: {wrong:?}");
    }

    #[test]
    fn a_blurred_pair_among_close_neighbours_is_split_and_a_flat_topped_one_is_not() {
        // A 64 x 64 frame of level 30 with Gaussian blobs (sigma 3.2 px)
        // `(centre, height)`, clipped at 255.
        let blobs = |list: &[(PointPx, f64)]| {
            let data = (0..64 * 64)
                .map(|k| {
                    let (x, y) = ((k % 64) as f64, (k / 64) as f64);
                    let v: f64 = list
                        .iter()
                        .map(|&(c, a)| {
                            a * (-((x - c.x).powi(2) + (y - c.y).powi(2)) / (2.0 * 3.2 * 3.2)).exp()
                        })
                        .sum();
                    (30.0 + v).round().min(255.0) as u8
                })
                .collect();
            GreyFrame::new(64, 64, data).unwrap()
        };
        // Two pins 6.8 px apart (2.1 sigma) along a slope, each with a
        // neighbour 9.5 px across the slope: at half maximum the pair runs
        // into them, above three quarters of its top it stands alone.
        let (ex, ey) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let at = |t: f64, n: f64| PointPx::new(32.3 + t * ex - n * ey, 31.8 + t * ey + n * ex);
        let pair = [at(-3.4, 0.0), at(3.4, 0.0)];
        let neighbours = [at(-3.4, 9.5), at(3.4, 9.5), at(-3.4, -9.5), at(3.4, -9.5)];
        let scene = |heights: [f64; 2], scale: f64| {
            let mut list: Vec<(PointPx, f64)> =
                neighbours.iter().map(|&c| (c, 130.0 * scale)).collect();
            list.extend(pair.iter().zip(heights).map(|(&c, a)| (c, a * scale)));
            blobs(&list)
        };
        let centre = at(0.0, 0.0);
        // A lattice pitch of 10 px.
        let (lo, pin_area_px, range_px) = (30.0, 25.0, (5.0, 10.0));
        // (One between them is 3.4 px from each.)
        for (heights, bound_px) in [([130.0, 130.0], 0.35), ([150.0, 110.0], 0.8)] {
            let frame = scene(heights, 1.0);
            let half = (30.0 + 0.5 * frame.data()[32 * 64 + 32] as f32 - 15.0) as u8;
            assert_eq!(split_chain(&frame, centre, half, pin_area_px), None);
            let got = split_blurred_pair(&frame, centre, lo, half, pin_area_px, range_px)
                .unwrap_or_else(|| panic!("{heights:?}: no pair"));
            for (g, want) in got.iter().zip(pair) {
                let off = (g.x - want.x).hypot(g.y - want.y);
                assert!(
                    off < bound_px,
                    "{heights:?}: {g:?} is {off:.2} px from {want:?}"
                );
            }
            // Alone, the pair is a blob apart at half maximum: split_chain's.
            let alone = blobs(
                &pair
                    .iter()
                    .zip(heights)
                    .map(|(&c, a)| (c, a))
                    .collect::<Vec<_>>(),
            );
            assert_eq!(
                split_blurred_pair(&alone, centre, lo, half, pin_area_px, range_px),
                None
            );
        }
        // The same pins five times as bright clip into flat tops: no
        // Gaussian to measure.
        let clipped = scene([130.0, 130.0], 5.0);
        assert_eq!(
            split_blurred_pair(&clipped, centre, lo, 142, pin_area_px, range_px),
            None
        );
    }

    #[test]
    fn a_lost_pin_is_put_where_its_neighbours_say_only_on_a_clear_clipped_ridge() {
        // A hex lattice of disc pins (radius 6 px, pitch 18 px) at rest;
        // in the frame every pin moved 5 px right. Three rest markers are
        // lost: one whose predicted place is a clipped pixel with no marker
        // near (taken), one whose place is dark skin, and one whose place
        // has a marker 2 px off (both left lost).
        let (w, h, pitch, radius) = (300usize, 300usize, 18.0, 6.0);
        let pins = test_fixtures::hex_points(w, h, pitch);
        let draw = |centres: &[PointPx], top: u8| {
            let data = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    let on = centres.iter().any(|p| (p.x - x).hypot(p.y - y) <= radius);
                    if on {
                        top
                    } else {
                        30
                    }
                })
                .collect();
            GreyFrame::new(w, h, data).unwrap()
        };
        let params = crate::params::Params::default();
        let cal = crate::calibrate::calibrate(&[draw(&pins, 200).blurred(1.0)], &params).unwrap();
        let rest = cal.reference();
        let near = rest.at;
        let middle = PointPx::new(w as f64 / 2.0, h as f64 / 2.0);
        let by_distance = |to: PointPx| {
            let mut k: Vec<usize> = (0..near.len()).collect();
            k.sort_by(|&a, &b| {
                let d = |i: usize| (near[i].x - to.x).hypot(near[i].y - to.y);
                d(a).total_cmp(&d(b))
            });
            k
        };
        let order = by_distance(middle);
        let (on_ridge, on_skin) = (order[0], by_distance(near[order[0]])[3]);
        let crowded = by_distance(PointPx::new(middle.x, middle.y + 3.0 * pitch))[0];
        let shift = |p: PointPx, dx: f64| PointPx::new(p.x + 5.0 + dx, p.y);
        let lost_ones = [on_ridge, on_skin, crowded];
        let mut markers: Vec<Marker> = (0..near.len())
            .filter(|k| !lost_ones.contains(k))
            .map(|k| Marker {
                pos: shift(near[k], 0.0),
                strength: 170.0,
                peak: 200,
                rel_level: 1.0,
                rel_strength: 1.0,
                area_px: 100.0,
                followed_from: Some(k),
            })
            .collect();
        // A marker 2 px from the crowded one's place, of no rest marker.
        let stray = shift(near[crowded], 2.0);
        markers.push(Marker {
            followed_from: None,
            pos: stray,
            ..markers[0]
        });
        // Clipped pins where the ridge's and the crowded one's are; none
        // where the skin's is.
        let frame = draw(&[shift(near[on_ridge], 0.0), stray], u8::MAX);
        let mut lost = vec![false; near.len()];
        for &k in &lost_ones {
            lost[k] = true;
        }
        let before = markers.len();
        fill_clipped_ridges(
            &frame,
            &cal.detector,
            &rest,
            &mut markers,
            &mut lost,
            cal.pitch_px,
            170.0,
            100.0,
        );
        assert_eq!(markers.len(), before + 1);
        let taken = markers[before];
        assert_eq!(taken.followed_from, Some(on_ridge));
        let want = shift(near[on_ridge], 0.0);
        assert!(
            (taken.pos.x - want.x).hypot(taken.pos.y - want.y) < 1e-9,
            "{:?}",
            taken.pos
        );
        assert_eq!(lost_ones.map(|k| lost[k]), [false, true, true]);
    }

    #[test]
    fn pins_a_press_squeezed_into_one_blurred_blob_are_each_found() {
        // Pins of radius 3 px, 170 over a skin of 30, at a pitch of 12 px;
        // the rest blurred by 1 px, the frame by 3 px (the issue's upper
        // end). A press hides the pin under it and pushes the two pins
        // above it, and the two below, 2.4 px towards each other: 7.2 px
        // apart, about twice the sigma of their blurred profile, each pair
        // is one blob without a neck, which at half maximum also runs into
        // its neighbours. Following sees one blob; the DoH one marker
        // between the two pins.
        squeezed_pairs_are_found(SqueezedPairs {
            size: 360,
            pitch_px: 12.0,
            radius_px: 3.0,
            top: 170,
            push_px: 2.4,
            blur_px: 3.0,
            within_px: 0.75,
        });
    }

    #[test]
    fn an_outer_ring_of_pins_that_nearly_touch_is_found_at_half_resolution() {
        // A dome's outer ring: pins foreshortened to half their width
        // across the ring and 7.5 px apart along it, so that they nearly
        // touch, below a lattice of round pins, with the detector the
        // renderer's domes get (a 5 px lobe, at half resolution). There
        // the ring is a ridge, or too weak a blob: 10 of the 34 were found.
        let (w, h, pitch) = (320, 240, 11.0);
        let lattice: Vec<PointPx> = test_fixtures::hex_points(w, h - 60, pitch);
        let ring: Vec<PointPx> = (0..34)
            .map(|k| PointPx::new(36.0 + 7.5 * k as f64, 206.0))
            .collect();
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let blob = |p: &PointPx, sx: f64, sy: f64| {
                    200.0
                        * (-(p.x - x).powi(2) / (2.0 * sx * sx)
                            - (p.y - y).powi(2) / (2.0 * sy * sy))
                            .exp()
                };
                let lit = lattice
                    .iter()
                    .map(|p| blob(p, 2.6, 2.6))
                    .chain(ring.iter().map(|p| blob(p, 2.4, 1.1)))
                    .fold(0.0, f64::max);
                (30.0 + lit).round() as u8
            })
            .collect();
        let frame = GreyFrame::new(w, h, data).unwrap();
        let params = MarkerParams {
            polarity: Polarity::Bright,
            lobe_px: Some(5),
            binned: Some(true),
            ..MarkerParams::default()
        };
        let mut det = auto_detector(&frame, &params).unwrap();
        assert_eq!((det.bin, det.lobe_px), (2, 3));
        // The ring lies where the dome is seen at 56-65 deg from its apex.
        det.surface = Surface::Dome(crate::surface::Dome {
            centre: PointPx::new(160.0, 40.0),
            radius_px: 200.0,
        });
        let ring_fs = ring.iter().map(|&p| det.surface.foreshortening(p));
        assert!(ring_fs.fold(0.0, f64::max) < FINE_MAX_FORESHORTENING);
        let found = detect(&frame, &det).positions();
        let on_ring = test_fixtures::match_points(&found, &ring, 1.0);
        assert_eq!(
            on_ring.len(),
            ring.len(),
            "{} of the ring found",
            on_ring.len()
        );
        let on_lattice = test_fixtures::match_points(&found, &lattice, 1.0);
        assert_eq!(on_lattice.len() + on_ring.len(), found.len());
    }

    #[test]
    fn pins_with_a_glint_off_their_middle_are_found() {
        // Raw TacTip pins: a white disc over dark skin, every third with a
        // small specular glint 3.5 px off its middle, brighter than the rest
        // of the pin: the pin's brightest pixel, where the DoH is weak.
        // Without a second look at the blob's centroid 18 of the 58 are
        // missed.
        let (w, h, pitch) = (320, 240, 20.0);
        let pins = test_fixtures::hex_points(w, h, pitch);
        let frame = |glints: bool| {
            let data = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    let mut v: f64 = 60.0;
                    for (k, p) in pins.iter().enumerate() {
                        let r = (p.x - x).hypot(p.y - y);
                        // A soft-edged disc of radius 7.5 px.
                        v = v.max(60.0 + 150.0 * (8.0 - r).clamp(0.0, 1.0));
                        if glints && k % 3 == 0 && (p.x - x).hypot(p.y - 3.5 - y) <= 1.5 {
                            v = 255.0;
                        }
                    }
                    v.round() as u8
                })
                .collect();
            GreyFrame::new(w, h, data).unwrap()
        };
        let params = MarkerParams {
            polarity: Polarity::Bright,
            ..MarkerParams::default()
        };
        let det = auto_detector(&frame(false), &params).unwrap();
        let found = detect(&frame(true), &det).positions();
        let matched = test_fixtures::match_points(&found, &pins, 1.5);
        assert_eq!(matched.len(), pins.len(), "{} found", found.len());
        assert_eq!(found.len(), pins.len());
    }

    #[test]
    fn auto_scale_follows_marker_size() {
        let mut small = Category::Nominal.sensor(640, 480, 3);
        small.marker_diameter_px = 4.0;
        small.pitch_px = 12.0;
        let mut big = small.clone();
        big.marker_diameter_px = 12.0;
        big.pitch_px = 24.0;
        let ds = auto_detector(&rest_frame(&small, 1).image, &MarkerParams::default()).unwrap();
        let db = auto_detector(&rest_frame(&big, 1).image, &MarkerParams::default()).unwrap();
        assert!(ds.radius_px < db.radius_px, "{ds:?} vs {db:?}");
        for (sensor, det) in [(small, ds), (big, db)] {
            let rest = rest_frame(&sensor, 2);
            let found = detect(&rest.image, &det);
            let matched = test_fixtures::match_points(&found.positions(), &rest.markers, 3.0);
            assert!(
                matched.len() as f64 >= 0.95 * rest.markers.len() as f64,
                "{det:?}: {} of {}",
                matched.len(),
                rest.markers.len()
            );
        }
    }

    #[test]
    fn outlines_around_markers_are_smooth_and_around_noise_rough() {
        for cat in [Category::Nominal, Category::Degraded, Category::Saturated] {
            let sensor = cat.sensor(640, 480, 3);
            let rest = rest_frame(&sensor, 4);
            let cal = crate::calibrate::calibrate(
                std::slice::from_ref(&rest.image),
                &crate::params::Params::default(),
            )
            .unwrap();
            let found: Vec<Option<Marker>> = follow_all(
                &rest.image,
                &cal.detector,
                &cal.rest_markers,
                &cal.centroid_radii_px,
                1.0,
            );
            assert!(
                !noise_like(&rest.image, &cal.detector, &found, &cal.centroid_radii_px),
                "{cat:?}"
            );
            // The same windows on uniform noise.
            let mut state = 7u64;
            let noise: Vec<u8> = (0..640 * 480)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (state >> 56) as u8
                })
                .collect();
            let noise = GreyFrame::new(640, 480, noise).unwrap();
            assert!(
                noise_like(&noise, &cal.detector, &found, &cal.centroid_radii_px),
                "{cat:?}"
            );
        }
    }

    /// A nominal synthetic sensor, its rest frame and its calibration.
    fn nominal_rest() -> (
        crate::synth::SensorSpec,
        crate::synth::SynthFrame,
        crate::calibrate::Calibration,
    ) {
        let sensor = Category::Nominal.sensor(640, 480, 3);
        let rest = rest_frame(&sensor, 4);
        let cal = crate::calibrate::calibrate(
            std::slice::from_ref(&rest.image),
            &crate::params::Params::default(),
        )
        .unwrap();
        (sensor, rest, cal)
    }

    #[test]
    fn rivals_find_the_markers_that_ran_into_one_blob_as_the_grid_does() {
        // Every rest marker, plus a second rest place 1.5 px beside every
        // tenth one (two places that following brings into one blob): the
        // second of each pair is lost, with the calibration's rivals as with
        // the frame-sized grid, and nothing else differs.
        let (_, rest, cal) = nominal_rest();
        let reach = crate::pipeline::FOLLOW_REACH_PITCH * cal.pitch_px;
        let mut near = cal.rest_markers.clone();
        let doubles: Vec<PointPx> = near
            .iter()
            .step_by(10)
            .map(|p| PointPx::new(p.x + 1.5, p.y))
            .collect();
        near.extend(&doubles);
        let rivals = Rivals::new(&near, reach, &[]);
        assert!(rivals.covers(near.len(), reach) && !rivals.covers(near.len(), 2.0 * reach));
        let follow = |rivals| {
            let rest_ref = Reference {
                at: &near,
                radii_px: &[],
                contrast: &[],
                gaps_px: &[],
                rivals,
                blur: None,
                neighbours: None,
            };
            follow_each(
                &rest.image,
                &cal.detector,
                &rest_ref,
                false,
                reach,
                usize::MAX,
            )
            .unwrap()
        };
        let (with, without) = (follow(Some(&rivals)), follow(None));
        assert_eq!(with, without);
        let n = cal.rest_markers.len();
        assert!(with[n..].iter().all(Option::is_none), "a double kept");
        let kept = with[..n].iter().flatten().count();
        assert!(kept + 5 >= n, "{kept} of {n} rest markers followed");
    }

    #[test]
    fn the_pins_a_search_finds_beside_followed_markers_of_a_squeezed_ring_replace_them() {
        // A strong press squeezes the pins around it together; under more
        // light their blobs clip and touch. A followed window that takes in
        // part of a neighbour's blob is pulled towards it while the search
        // finds the pin beside it. Over these six frames, 121 markers lay
        // more than 1.5 px from every pin and 223 pins had none within
        // 1.5 px without `resettle_on_orphans`; 105 and 224 with it.
        use crate::synth::{render, FrameConditions, Press, Scene};
        let (sensor, _, cal) = nominal_rest();
        let (mut off_pin, mut missed) = (0, 0);
        for gain in [1.0, 2.0, 3.0] {
            for width_px in [30.0, 45.0] {
                let mut sensor = sensor.clone();
                sensor.frame_conditions = FrameConditions {
                    gain,
                    ..FrameConditions::NONE
                };
                let f = render(&Scene {
                    sensor,
                    presses: vec![Press {
                        centre: PointPx::new(300.0, 250.0),
                        width_px,
                        strength: 1.5,
                        shear_px: PointPx::new(0.0, 0.0),
                        flat_radius_px: 0.0,
                    }],
                    dropout: 0.0,
                    seed: 5,
                });
                let (found, search) = follow_or_search(
                    &f.image,
                    &cal.detector,
                    &cal.reference(),
                    0.3 * cal.pitch_px,
                    Some(cal.pitch_px),
                );
                assert_eq!(search, Search::Local, "gain {gain}, width {width_px}");
                let near = |a: PointPx, b: PointPx| (a.x - b.x).hypot(a.y - b.y) <= 1.5;
                off_pin += found
                    .list
                    .iter()
                    .filter(|m| !f.markers.iter().any(|&t| near(t, m.pos)))
                    .count();
                missed += f
                    .markers
                    .iter()
                    .filter(|&&t| t.x > 10.0 && t.y > 10.0 && t.x < 630.0 && t.y < 470.0)
                    .filter(|&&t| !found.list.iter().any(|m| near(t, m.pos)))
                    .count();
            }
        }
        assert!(
            off_pin <= 110 && missed <= 226,
            "{off_pin} markers off the pins, {missed} pins without a marker"
        );
    }

    #[test]
    fn marked_items_are_dropped_in_order_and_unflagged_ones_stay() {
        let mut v = vec![1, 2, 3, 4, 5];
        drop_marked(&mut v, &[false, true, false, true]);
        assert_eq!(v, [1, 3, 5]);
    }

    #[test]
    fn an_orphan_beside_an_unconfirmed_followed_marker_becomes_its_centroid() {
        let at = |x: f64, y: f64, k: Option<usize>| Marker {
            pos: PointPx::new(x, y),
            strength: 100.0,
            peak: 0,
            rel_level: 1.0,
            rel_strength: 1.0,
            area_px: 50.0,
            followed_from: k,
        };
        // Followed: 0 pulled off its pin, 1 confirmed by the search, 2 far
        // from every orphan, 3 also pulled, beside the same orphan as 0 but
        // further from it, 4 in a foreshortened row (a reach of 2 px).
        let mut list = vec![
            at(10.0, 10.0, Some(0)),
            at(40.0, 10.0, Some(1)),
            at(80.0, 80.0, Some(2)),
            at(10.0, 15.5, Some(3)),
            at(60.0, 10.0, Some(4)),
        ];
        let confirmed = [false, true, false, false, false];
        let orphan = |x: f64, y: f64| Marker {
            strength: 160.0,
            area_px: 60.0,
            ..at(x, y, None)
        };
        // Orphans beside 0 (3 px), beside 1 (3 px), one 7 px from 2 and
        // one 3 px from 4; a searched marker that a lost rest marker took,
        // beside 0.
        let mut searched = vec![
            orphan(13.0, 10.0),
            orphan(43.0, 10.0),
            orphan(87.0, 80.0),
            orphan(63.0, 10.0),
            at(10.0, 12.0, Some(9)),
        ];
        let reach_of = |m: &Marker| if m.followed_from == Some(4) { 2.0 } else { 6.0 };
        resettle_on_orphans(&mut list, &confirmed, &mut searched, 6.0, reach_of);
        // 0 takes the orphan's centroid, contrast and area, and the orphan
        // goes; 3 (further) keeps its own.
        assert_eq!(list[0].pos, PointPx::new(13.0, 10.0));
        assert_eq!((list[0].strength, list[0].area_px), (160.0, 60.0));
        assert_eq!(list[0].followed_from, Some(0));
        assert_eq!(list[3].pos, PointPx::new(10.0, 15.5));
        // 1 was confirmed, 2 and 4 are beyond their reach: they stay, and so
        // do their orphans; the paired searched marker is no orphan.
        assert_eq!(list[1].pos, PointPx::new(40.0, 10.0));
        assert_eq!(list[2].pos, PointPx::new(80.0, 80.0));
        assert_eq!(list[4].pos, PointPx::new(60.0, 10.0));
        let left: Vec<PointPx> = searched.iter().map(|m| m.pos).collect();
        assert_eq!(
            left,
            [
                PointPx::new(43.0, 10.0),
                PointPx::new(87.0, 80.0),
                PointPx::new(63.0, 10.0),
                PointPx::new(10.0, 12.0)
            ]
        );
    }

    #[test]
    fn a_press_that_loses_markers_is_searched_around_them_or_in_the_whole_frame() {
        use crate::synth::{render, Press, Scene};
        let (sensor, rest, cal) = nominal_rest();
        let reach = 0.3 * cal.pitch_px;
        let local = Some(cal.pitch_px);
        let run = |frame: &GreyFrame, local| {
            follow_or_search(frame, &cal.detector, &cal.reference(), reach, local)
        };
        let (found, search) = run(&rest.image, local);
        assert_eq!(search, Search::Followed);
        assert_eq!(found.len(), cal.rest_markers.len());
        // A strong press moves the markers around it beyond the reach.
        let pressed = render(&Scene {
            sensor: sensor.clone(),
            presses: vec![Press {
                centre: PointPx::new(300.0, 250.0),
                width_px: 30.0,
                strength: 1.0,
                shear_px: PointPx::new(0.0, 0.0),
                flat_radius_px: 0.0,
            }],
            dropout: 0.0,
            seed: 5,
        });
        let (whole, search) = run(&pressed.image, None);
        assert_eq!(search, Search::Full);
        assert_eq!(whole, detect(&pressed.image, &cal.detector));
        // Searched around the lost markers only: as many markers as the
        // whole frame's search, each within 1.5 px of one of its markers
        // and of a true marker (the whole search's worst is 1.04 px here).
        let (around, search) = run(&pressed.image, local);
        assert_eq!(search, Search::Local);
        assert_eq!(around.len(), whole.len());
        let pairs = test_fixtures::match_points(&around.positions(), &whole.positions(), 1.5);
        assert_eq!(pairs.len(), whole.len(), "{} matched", pairs.len());
        let truth = test_fixtures::match_points(&around.positions(), &pressed.markers, 1.5);
        assert_eq!(
            truth.len(),
            around.len(),
            "{} on a true marker",
            truth.len()
        );
        // Most markers keep their followed centroid; the lost ones' new
        // places come from the search.
        let searched = around
            .list
            .iter()
            .filter(|m| m.followed_from.is_none())
            .count();
        assert!(
            searched > 0 && 10 * searched < around.len(),
            "{searched} searched"
        );
        let blank = GreyFrame::new(640, 480, vec![20; 640 * 480]).unwrap();
        for (local, want) in [(None, Search::Full), (local, Search::Paired)] {
            let (found, search) = run(&blank, local);
            assert_eq!(search, want);
            assert!(found.is_empty());
        }
    }

    #[test]
    fn a_wide_shear_is_paired_through_the_neighbours_not_to_the_nearest_pin() {
        // Real TacTip taps shear the skin under a wide contact by about half
        // a pitch: following loses the markers there, and pairing each rest
        // marker with the nearest marker within half a pitch took a
        // neighbour's pin for many.
        use crate::synth::{render, Press, Scene};
        let (sensor, rest, cal) = nominal_rest();
        let pitch = cal.pitch_px;
        let sheared = render(&Scene {
            sensor: sensor.clone(),
            presses: vec![Press {
                centre: PointPx::new(320.0, 240.0),
                width_px: 120.0,
                strength: 0.05,
                shear_px: PointPx::new(0.6 * pitch, 0.25 * pitch),
                flat_radius_px: 0.0,
            }],
            dropout: 0.0,
            seed: 7,
        });
        let reference = cal.reference();
        let (found, search) = follow_or_search(
            &sheared.image,
            &cal.detector,
            &reference,
            0.3 * pitch,
            Some(pitch),
        );
        assert_eq!(search, Search::Paired);
        // Each rest marker's true place in the sheared frame.
        let truth = |k: usize| {
            let r = cal.rest_markers[k];
            let t = (0..rest.rest_markers.len()).min_by(|&a, &b| {
                let d = |q: PointPx| (q.x - r.x).powi(2) + (q.y - r.y).powi(2);
                d(rest.rest_markers[a]).total_cmp(&d(rest.rest_markers[b]))
            })?;
            Some(sheared.markers[t])
        };
        let judge = |pairs: &mut dyn Iterator<Item = (usize, PointPx)>| {
            let (mut right, mut wrong) = (0, 0);
            for (k, p) in pairs {
                let t = truth(k).unwrap();
                if (p.x - t.x).hypot(p.y - t.y) <= 1.5 {
                    right += 1;
                } else {
                    wrong += 1;
                }
            }
            (right, wrong)
        };
        let n = cal.rest_markers.len();
        let (right, wrong) = judge(
            &mut found
                .list
                .iter()
                .filter_map(|m| Some((m.followed_from?, m.pos))),
        );
        // (757 of 757 right.)
        assert!(
            100 * right >= 99 * n && wrong == 0,
            "{right} right, {wrong} wrong of {n}"
        );
        // The nearest marker within half a pitch: fewer right, some wrong.
        let nearest = crate::tracking::track(
            &cal.rest_markers,
            &found.positions(),
            640,
            480,
            0.5 * pitch,
            0.5,
        );
        let (near_right, near_wrong) = judge(
            &mut nearest
                .displacement
                .iter()
                .enumerate()
                .filter_map(|(k, u)| {
                    let r = cal.rest_markers[k];
                    u.map(|u| (k, PointPx::new(r.x + u.x, r.y + u.y)))
                }),
        );
        // (398 right, 264 wrong.)
        assert!(
            near_right < right && 10 * near_wrong > n,
            "nearest: {near_right} right, {near_wrong} wrong"
        );
    }

    #[test]
    fn blank_frame_has_no_markers_and_no_calibration() {
        for level in [0u8, 128, 255] {
            let frame = GreyFrame::new(64, 48, vec![level; 64 * 48]).unwrap();
            let det = Detector {
                lobe_px: 3,
                bin: 1,
                min_level_ratio: 0.3,
                min_rel_strength: 0.05,
                min_contrast: 6.0,
                radius_px: 3.0,
                cell_px: 8,
                window_px: None,
                area: None,
                rim: None,
                dark: false,
                surface: Surface::Flat,
            };
            assert!(detect(&frame, &det).is_empty());
            assert!(matches!(
                auto_detector(&frame, &MarkerParams::default()),
                Err(MarkerError::TooFewMarkers { .. })
            ));
        }
    }
}
