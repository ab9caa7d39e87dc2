//! Stage 1, frame preparation (Sec. III-B): any 8-bit grey, RGB or RGBA
//! frame -> grey -> optional crop -> rescale to the working size
//! (640x480 by default).
//!
//! Grey is the brightest of R, G and B by default, or the BT.601 luma
//! `(77 R + 150 G + 29 B) / 256` ([`Grey`]). Rescaling maps
//! pixel centres (`x_in = crop_x + (x_work + 0.5) * sx - 0.5`); an integer
//! downscale averages `k x k` blocks, any other downscale averages each
//! working pixel's footprint (area weights), and an upscale (stretching,
//! `keep_aspect = false`, or [`FrameParams::upscale`]) interpolates
//! linearly.
//! [`Prepared::to_input`] maps working coordinates back to the input image.
//! The sensing-area mask comes from the rest calibration
//! ([`crate::calibrate`]).

use crate::area::WorkToInput;
use crate::params::{FrameParams, Grey};
use crate::PointPx;

/// Largest accepted input side, px (a bigger frame is an error, not an OOM).
pub const MAX_SIDE_PX: usize = 16_384;

/// Errors of frame preparation.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Width or height is zero.
    #[error("empty frame ({width}x{height})")]
    Empty {
        /// Width, px.
        width: usize,
        /// Height, px.
        height: usize,
    },
    /// A side exceeds [`MAX_SIDE_PX`].
    #[error("frame {width}x{height} too large (max side {MAX_SIDE_PX} px)")]
    TooLarge {
        /// Width, px.
        width: usize,
        /// Height, px.
        height: usize,
    },
    /// The buffer length does not match width x height x channels.
    #[error("buffer has {got} bytes, expected {expected}")]
    BadLength {
        /// Bytes expected.
        expected: usize,
        /// Bytes given.
        got: usize,
    },
    /// Channel count other than 1, 3 or 4.
    #[error("unsupported channel count {0} (1, 3 or 4)")]
    Channels(usize),
    /// The crop rectangle lies outside the frame.
    #[error("crop {crop:?} outside the {width}x{height} frame")]
    Crop {
        /// The crop `[x, y, w, h]`.
        crop: [u32; 4],
        /// Frame width, px.
        width: usize,
        /// Frame height, px.
        height: usize,
    },
}

/// An 8-bit grey image, row-major, no padding.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GreyFrame {
    width: usize,
    height: usize,
    data: Vec<u8>,
}

impl GreyFrame {
    /// Wraps a buffer; checks the size.
    pub fn new(width: usize, height: usize, data: Vec<u8>) -> Result<Self, FrameError> {
        check_size(width, height)?;
        if data.len() != width * height {
            return Err(FrameError::BadLength {
                expected: width * height,
                got: data.len(),
            });
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    /// Width, px.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height, px.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Pixels, row-major.
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// The negative (255 - v): dark markers become bright ones.
    pub fn inverted(&self) -> GreyFrame {
        GreyFrame {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&v| !v).collect(),
        }
    }

    /// This frame under a Gaussian blur of `sigma_px` ([`gaussian_blur`]),
    /// rounded to grey levels; a `sigma_px` that is not positive copies it.
    pub fn blurred(&self, sigma_px: f64) -> GreyFrame {
        let mut v: Vec<f32> = self.data.iter().map(|&p| f32::from(p)).collect();
        gaussian_blur(&mut v, self.width, self.height, sigma_px);
        GreyFrame {
            width: self.width,
            height: self.height,
            // In 0..=255: a blur is a weighted mean.
            data: v
                .iter()
                .map(|&p| p.round().clamp(0.0, 255.0) as u8)
                .collect(),
        }
    }

    /// Pixel at `(x, y)`, 0 outside the image.
    pub fn get(&self, x: i64, y: i64) -> u8 {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            0
        } else {
            self.data[y as usize * self.width + x as usize]
        }
    }
}

/// The normalised Gaussian taps of [`gaussian_blur`], truncated at 3
/// sigma: the radius in px and the `2 radius + 1` weights.
fn gaussian_kernel(sigma_px: f64) -> (i64, Vec<f32>) {
    let radius = (3.0 * sigma_px).ceil() as i64;
    let mut kernel: Vec<f32> = (-radius..=radius)
        .map(|i| (-0.5 * (i as f64 / sigma_px).powi(2)).exp() as f32)
        .collect();
    let sum: f32 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= sum);
    (radius, kernel)
}

/// Separable Gaussian blur of a `width x height` row-major image in place
/// (kernel truncated at 3 sigma, edges clamped); a `sigma_px` that is not
/// positive (or NaN) does nothing.
pub fn gaussian_blur(data: &mut [f32], width: usize, height: usize, sigma_px: f64) {
    if sigma_px.is_nan() || sigma_px <= 0.0 || width == 0 || height == 0 {
        return;
    }
    let (radius, kernel) = gaussian_kernel(sigma_px);
    // Each output is the taps' products added in kernel order to 0, as a
    // per-pixel loop would add them; the loops run over x innermost (for
    // vectors), which leaves every sum the same.
    let r = radius as usize;
    let last = |i: i64, n: usize| i.clamp(0, n as i64 - 1) as usize;
    // The image's pixels (a longer buffer's tail is left alone).
    let data = &mut data[..width * height];
    let mut tmp = vec![0f32; data.len()];
    // Rows: x in lo..hi reach no edge with any tap.
    let (lo, hi) = (r.min(width), width.saturating_sub(r).max(r.min(width)));
    for (row, out) in data.chunks_exact(width).zip(tmp.chunks_exact_mut(width)) {
        for (k, &kv) in kernel.iter().enumerate().filter(|_| hi > lo) {
            for (o, &v) in out[lo..hi].iter_mut().zip(&row[lo + k - r..]) {
                *o += kv * v;
            }
        }
        for x in (0..lo).chain(hi..width) {
            for (k, &kv) in kernel.iter().enumerate() {
                out[x] += kv * row[last(x as i64 + k as i64 - radius, width)];
            }
        }
    }
    // Columns: each tap is a whole (edge-clamped) row.
    for (y, out) in data.chunks_exact_mut(width).enumerate() {
        out.fill(0.0);
        for (k, &kv) in kernel.iter().enumerate() {
            let src = last(y as i64 + k as i64 - radius, height) * width;
            for (o, &v) in out.iter_mut().zip(&tmp[src..src + width]) {
                *o += kv * v;
            }
        }
    }
}

fn check_size(width: usize, height: usize) -> Result<(), FrameError> {
    if width == 0 || height == 0 {
        return Err(FrameError::Empty { width, height });
    }
    if width > MAX_SIDE_PX || height > MAX_SIDE_PX {
        return Err(FrameError::TooLarge { width, height });
    }
    Ok(())
}

/// A raw camera frame: 1 (grey), 3 (RGB) or 4 (RGBA) interleaved 8-bit
/// channels.
#[derive(Debug, Clone, Copy)]
pub struct RawFrame<'a> {
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Channels per pixel.
    pub channels: usize,
    /// Interleaved pixels, row-major.
    pub data: &'a [u8],
}

/// A working-size grey frame and the map back to input pixels.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The working grey frame.
    pub grey: GreyFrame,
    /// Input px per working px, x.
    pub scale_x: f64,
    /// Input px per working px, y.
    pub scale_y: f64,
    /// Crop origin in input px.
    pub origin_px: PointPx,
}

impl Prepared {
    /// The map from working to input pixels.
    pub fn map(&self) -> WorkToInput {
        WorkToInput {
            scale_x: self.scale_x,
            scale_y: self.scale_y,
            origin_px: self.origin_px,
        }
    }

    /// Working-frame point -> input-image point (pixel centres at integers).
    pub fn to_input(&self, p: PointPx) -> PointPx {
        self.map().apply(p)
    }
}

/// Stage 1 entry: grey, crop, rescale to the working size.
pub fn prepare(raw: &RawFrame<'_>, params: &FrameParams) -> Result<Prepared, FrameError> {
    fit(to_grey(raw, params.grey)?, params)
}

/// [`prepare`] for a frame whose buffer the caller gives up (a decoded
/// file): a grey frame already at the working size is moved, not copied.
pub fn prepare_owned(
    width: usize,
    height: usize,
    channels: usize,
    data: Vec<u8>,
    params: &FrameParams,
) -> Result<Prepared, FrameError> {
    if channels == 1 {
        fit(GreyFrame::new(width, height, data)?, params)
    } else {
        let raw = RawFrame {
            width,
            height,
            channels,
            data: &data,
        };
        prepare(&raw, params)
    }
}

/// Crops and rescales a grey frame to the working size.
fn fit(grey: GreyFrame, params: &FrameParams) -> Result<Prepared, FrameError> {
    let (cx, cy, cw, ch) = match params.crop_px {
        None => (0, 0, grey.width, grey.height),
        Some(c) => {
            let [x, y, w, h] = c.map(|v| v as usize);
            if w == 0 || h == 0 || x + w > grey.width || y + h > grey.height {
                return Err(FrameError::Crop {
                    crop: c,
                    width: grey.width,
                    height: grey.height,
                });
            }
            (x, y, w, h)
        }
    };
    let (ow, oh) = working_size(cw, ch, params);
    check_size(ow, oh)?;
    let out =
        if (cx, cy, cw, ch, ow, oh) == (0, 0, grey.width, grey.height, grey.width, grey.height) {
            grey // already the working frame: no copy
        } else {
            resize(&grey, [cx, cy, cw, ch], ow, oh)
        };
    Ok(Prepared {
        grey: out,
        scale_x: cw as f64 / ow as f64,
        scale_y: ch as f64 / oh as f64,
        origin_px: PointPx::new(cx as f64, cy as f64),
    })
}

/// The map from working to input pixels for `width x height` input frames
/// (crop, then rescale to [`working_size`]); the identity when the crop
/// does not fit (then [`prepare`] refuses the frames).
pub fn map_for(width: usize, height: usize, params: &FrameParams) -> WorkToInput {
    let [cx, cy, cw, ch] = params
        .crop_px
        .map(|c| c.map(|v| v as usize))
        .filter(|&[x, y, w, h]| w > 0 && h > 0 && x + w <= width && y + h <= height)
        .unwrap_or([0, 0, width, height]);
    let (ow, oh) = working_size(cw, ch, params);
    if ow == 0 || oh == 0 {
        return WorkToInput::IDENTITY;
    }
    WorkToInput {
        scale_x: cw as f64 / ow as f64,
        scale_y: ch as f64 / oh as f64,
        origin_px: PointPx::new(cx as f64, cy as f64),
    }
}

/// The working size for a `cw x ch` input region: the configured size, or
/// with `keep_aspect` the region's aspect ratio, scaled down to fit in the
/// configured size and never up (a square 420x420 crop stays 420x420, a
/// 1280x960 frame becomes 640x480, nothing is stretched; upscaling adds no
/// information, only pixels to search); then times
/// [`FrameParams::upscale`] (pins too small for the detector).
pub fn working_size(cw: usize, ch: usize, params: &FrameParams) -> (usize, usize) {
    let up = params
        .upscale
        .unwrap_or(1.0)
        .clamp(1.0, crate::params::MAX_UPSCALE);
    let times = |v: usize| (v as f64 * up).round() as usize;
    let (ow, oh) = (
        params.work_width_px as usize,
        params.work_height_px as usize,
    );
    if !params.keep_aspect || cw == 0 || ch == 0 {
        return (times(ow), times(oh));
    }
    let s = (ow as f64 / cw as f64).min(oh as f64 / ch as f64).min(1.0);
    (
        ((cw as f64 * s * up).round() as usize).clamp(1, times(ow)),
        ((ch as f64 * s * up).round() as usize).clamp(1, times(oh)),
    )
}

/// Converts any supported raw frame to grey (no resize), as `grey` says.
pub fn to_grey(raw: &RawFrame<'_>, grey: Grey) -> Result<GreyFrame, FrameError> {
    check_size(raw.width, raw.height)?;
    if !matches!(raw.channels, 1 | 3 | 4) {
        return Err(FrameError::Channels(raw.channels));
    }
    let expected = raw.width * raw.height * raw.channels;
    if raw.data.len() != expected {
        return Err(FrameError::BadLength {
            expected,
            got: raw.data.len(),
        });
    }
    let data = match (raw.channels, grey) {
        (1, _) => raw.data.to_vec(),
        (3, Grey::Luma) => luma::<3>(raw.data),
        (3, Grey::Max) => max_channel::<3>(raw.data),
        (_, Grey::Luma) => luma::<4>(raw.data),
        (_, Grey::Max) => max_channel::<4>(raw.data),
    };
    GreyFrame::new(raw.width, raw.height, data)
}

/// BT.601 luma of interleaved `C`-channel pixels (R, G, B first).
fn luma<const C: usize>(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8; data.len() / C];
    for (o, p) in out.iter_mut().zip(data.chunks_exact(C)) {
        let (r, g, b) = (p[0] as u16, p[1] as u16, p[2] as u16);
        // 77 + 150 + 29 = 256: the sum fits u16 (255 * 256 = 65280), so the
        // wrapping ops never wrap; they only drop the overflow checks.
        let y = r
            .wrapping_mul(77)
            .wrapping_add(g.wrapping_mul(150))
            .wrapping_add(b.wrapping_mul(29));
        *o = (y >> 8) as u8;
    }
    out
}

/// The brightest of R, G and B of interleaved `C`-channel pixels.
///
/// RGB on x86-64 with SSSE3 goes 16 pixels at a time ([`simd::max_rgb`]):
/// 38 us per 640x480 frame against 225 us pixel by pixel (criterion,
/// BENCHMARKS.md, session 12), which the compiler does not vectorise
/// (stride 3). The rest, and the tail, go pixel by pixel.
fn max_channel<const C: usize>(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8; data.len() / C];
    let done = if C == 3 {
        simd::max_rgb(data, &mut out)
    } else {
        0
    };
    for (o, p) in out[done..].iter_mut().zip(data[C * done..].chunks_exact(C)) {
        *o = p[0].max(p[1]).max(p[2]);
    }
    out
}

/// Vector paths of [`max_channel`].
mod simd {
    /// Writes `out[k] = max(rgb[3k], rgb[3k + 1], rgb[3k + 2])` for the
    /// first pixels, 16 at a time, when the CPU can; returns how many it
    /// wrote (0 without SSSE3 or off x86-64).
    pub(super) fn max_rgb(rgb: &[u8], out: &mut [u8]) -> usize {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("ssse3") {
            // SAFETY: the CPU has SSSE3 (checked just above).
            return unsafe { x86::max_rgb_ssse3(rgb, out) };
        }
        let _ = (rgb, out);
        0
    }

    /// The pass across of [`super::magnify`] in groups of 8 outputs:
    /// each group's first input sample, the `pshufb` masks that put the
    /// two samples of each output side by side in 16-bit lanes (outputs
    /// 0-3 and 4-7), and their weights. A magnification advances at most 7
    /// samples over 8 outputs, so a group's samples lie in the 16 bytes
    /// from its first.
    pub(super) struct LerpPlan {
        groups: Vec<LerpGroup>,
    }

    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    struct LerpGroup {
        first: usize,
        masks: [[u8; 16]; 2],
        weights: [[i16; 8]; 2],
    }

    impl LerpPlan {
        /// The full groups of the `ow` outputs of `across`
        /// ([`super::Taps::linear`] of `n_in` samples, weights below
        /// 2^15), as long as their samples fit.
        pub(super) fn new(across: &super::Taps, n_in: usize, ow: usize) -> Self {
            let mut groups = Vec::with_capacity(ow / 8);
            'group: for g in 0..ow / 8 {
                let first = across.start[8 * g];
                let mut group = LerpGroup {
                    first,
                    masks: [[0x80; 16]; 2],
                    weights: [[0; 8]; 2],
                };
                for k in 0..8 {
                    let (a, w) = across.of(8 * g + k);
                    let b = (a + 1).min(n_in.saturating_sub(1));
                    let (ia, ib) = (a - first, b - first);
                    if ib > 15 || w.iter().any(|&w| w > i16::MAX as u32) {
                        break 'group;
                    }
                    let (half, lane) = (k / 4, 2 * (k % 4));
                    group.masks[half][2 * lane] = ia as u8;
                    group.masks[half][2 * lane + 2] = ib as u8;
                    group.weights[half][lane] = w[0] as i16;
                    group.weights[half][lane + 1] = w[1] as i16;
                }
                groups.push(group);
            }
            Self { groups }
        }
    }

    /// Writes the first outputs of [`super::across_lerp`] over `row` (the
    /// row's samples first, then whatever follows them), 8 at a time, when
    /// the CPU can; returns how many it wrote (0 without SSSE3 or off
    /// x86-64). The same integers as the scalar pass.
    pub(super) fn across_lerp(plan: &LerpPlan, row: &[u8], out: &mut [u16]) -> usize {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("ssse3") {
            // SAFETY: the CPU has SSSE3 (checked just above).
            return unsafe { x86::across_lerp_ssse3(plan, row, out) };
        }
        let _ = (plan, row, out);
        0
    }

    /// Writes the first outputs of [`super::down_lerp`], 8 at a time, on
    /// x86-64 (SSE2); returns how many. The same integers as the scalar
    /// pass.
    pub(super) fn down_lerp(ra: &[u16], rb: &[u16], v: [u32; 2], out: &mut [u8]) -> usize {
        #[cfg(target_arch = "x86_64")]
        {
            x86::down_lerp_sse2(ra, rb, v, out)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (ra, rb, v, out);
            0
        }
    }

    #[cfg(target_arch = "x86_64")]
    mod x86 {
        use std::arch::x86_64::{
            __m128i, _mm_add_epi32, _mm_loadu_si128, _mm_madd_epi16, _mm_max_epu8, _mm_or_si128,
            _mm_packs_epi32, _mm_packus_epi16, _mm_set1_epi32, _mm_setr_epi16, _mm_shuffle_epi8,
            _mm_srli_epi32, _mm_storel_epi64, _mm_storeu_si128, _mm_unpackhi_epi16,
            _mm_unpacklo_epi16,
        };

        /// See [`super::across_lerp`].
        ///
        /// # Safety
        /// The CPU must have SSSE3.
        #[target_feature(enable = "ssse3")]
        pub(super) unsafe fn across_lerp_ssse3(
            plan: &super::LerpPlan,
            row: &[u8],
            out: &mut [u16],
        ) -> usize {
            let load = |p: *const u8| unsafe { _mm_loadu_si128(p.cast::<__m128i>()) };
            let round = _mm_set1_epi32(32);
            let mut done = 0;
            for (g, group) in plan.groups.iter().enumerate() {
                if group.first + 16 > row.len() || 8 * g + 8 > out.len() {
                    break;
                }
                // SAFETY: the 16 bytes from `first` are inside `row`, the
                // 8 outputs inside `out` (checked above); the masks and
                // weights are 16-byte arrays; unaligned loads and stores.
                unsafe {
                    let px = load(row.as_ptr().add(group.first));
                    let half = |h: usize| {
                        let pairs = _mm_shuffle_epi8(px, load(group.masks[h].as_ptr()));
                        let sum = _mm_madd_epi16(pairs, load(group.weights[h].as_ptr().cast()));
                        _mm_srli_epi32::<6>(_mm_add_epi32(sum, round))
                    };
                    // At most 255 x 64: the signed pack keeps it.
                    let v = _mm_packs_epi32(half(0), half(1));
                    _mm_storeu_si128(out.as_mut_ptr().add(8 * g).cast::<__m128i>(), v);
                }
                done = 8 * g + 8;
            }
            done
        }

        /// See [`super::down_lerp`]: the two rows interleaved in 16-bit
        /// pairs (each at most 255 x 64) and weighted with `pmaddwd` (SSE2,
        /// part of x86-64).
        pub(super) fn down_lerp_sse2(ra: &[u16], rb: &[u16], v: [u32; 2], out: &mut [u8]) -> usize {
            let n = out.len().min(ra.len()).min(rb.len()) / 8 * 8;
            // SAFETY: SSE2 is part of x86-64; block i reads elements
            // 8 i .. 8 i + 8 of `ra` and `rb` and writes bytes 8 i .. 8 i + 8
            // of `out`, all inside (n above); unaligned loads and stores.
            unsafe {
                let (va, vb) = (v[0] as i16, v[1] as i16);
                let w = _mm_setr_epi16(va, vb, va, vb, va, vb, va, vb);
                let round = _mm_set1_epi32(1 << 13);
                for i in (0..n).step_by(8) {
                    let a = _mm_loadu_si128(ra.as_ptr().add(i).cast::<__m128i>());
                    let b = _mm_loadu_si128(rb.as_ptr().add(i).cast::<__m128i>());
                    let lerp = |pairs| {
                        _mm_srli_epi32::<14>(_mm_add_epi32(_mm_madd_epi16(pairs, w), round))
                    };
                    let lo = lerp(_mm_unpacklo_epi16(a, b));
                    let hi = lerp(_mm_unpackhi_epi16(a, b));
                    let bytes = _mm_packus_epi16(_mm_packs_epi32(lo, hi), lo);
                    _mm_storel_epi64(out.as_mut_ptr().add(i).cast::<__m128i>(), bytes);
                }
            }
            n
        }

        /// The `pshufb` mask that moves channel `ch` of the pixels whose
        /// bytes lie in 16-byte register `reg` (of 3: 16 RGB pixels) to
        /// their pixel's lane; other lanes get 0x80 (zero).
        const fn mask(reg: usize, ch: usize) -> [u8; 16] {
            let mut m = [0x80u8; 16];
            let mut k = 0;
            while k < 16 {
                let j = 3 * k + ch;
                if j / 16 == reg {
                    m[k] = (j % 16) as u8;
                }
                k += 1;
            }
            m
        }

        /// `MASKS[ch][reg]`.
        const MASKS: [[[u8; 16]; 3]; 3] = {
            let mut t = [[[0u8; 16]; 3]; 3];
            let mut ch = 0;
            while ch < 3 {
                let mut reg = 0;
                while reg < 3 {
                    t[ch][reg] = mask(reg, ch);
                    reg += 1;
                }
                ch += 1;
            }
            t
        };

        /// See [`super::max_rgb`].
        ///
        /// # Safety
        /// The CPU must have SSSE3.
        #[target_feature(enable = "ssse3")]
        pub(super) unsafe fn max_rgb_ssse3(rgb: &[u8], out: &mut [u8]) -> usize {
            let blocks = out.len().min(rgb.len() / 3) / 16;
            // SAFETY (every load and store below): block i reads bytes
            // 48 i .. 48 i + 48 of `rgb` and writes 16 i .. 16 i + 16 of
            // `out`, inside both for i < blocks; unaligned loads and stores.
            let load = |p: *const u8| unsafe { _mm_loadu_si128(p.cast::<__m128i>()) };
            let masks: [[__m128i; 3]; 3] = MASKS.map(|c| c.map(|m| load(m.as_ptr())));
            for i in 0..blocks {
                unsafe {
                    let p = rgb.as_ptr().add(48 * i);
                    let regs = [load(p), load(p.add(16)), load(p.add(32))];
                    let channel = |ch: usize| {
                        let m = &masks[ch];
                        _mm_or_si128(
                            _mm_or_si128(
                                _mm_shuffle_epi8(regs[0], m[0]),
                                _mm_shuffle_epi8(regs[1], m[1]),
                            ),
                            _mm_shuffle_epi8(regs[2], m[2]),
                        )
                    };
                    let v = _mm_max_epu8(_mm_max_epu8(channel(0), channel(1)), channel(2));
                    _mm_storeu_si128(out.as_mut_ptr().add(16 * i).cast::<__m128i>(), v);
                }
            }
            16 * blocks
        }
    }
}

/// Crops `rect = [x, y, w, h]` (inside `src`) and rescales to `ow x oh`.
fn resize(src: &GreyFrame, rect: [usize; 4], ow: usize, oh: usize) -> GreyFrame {
    let [rx, ry, rw, rh] = rect;
    let data = if rw == ow && rh == oh {
        let mut d = Vec::with_capacity(ow * oh);
        for y in 0..oh {
            let start = (ry + y) * src.width + rx;
            d.extend_from_slice(&src.data[start..start + ow]);
        }
        d
    } else if rw % ow == 0 && rh % oh == 0 && rw / ow == rh / oh {
        block_average(src, rect, rw / ow, ow, oh)
    } else {
        resample(src, rect, ow, oh)
    };
    GreyFrame {
        width: ow,
        height: oh,
        data,
    }
}

fn block_average(src: &GreyFrame, rect: [usize; 4], k: usize, ow: usize, oh: usize) -> Vec<u8> {
    let [rx, ry, ..] = rect;
    let mut sums = vec![0u32; ow];
    let mut out = Vec::with_capacity(ow * oh);
    let n = (k * k) as u32;
    for y in 0..oh {
        sums.iter_mut().for_each(|s| *s = 0);
        for dy in 0..k {
            let row = &src.data[(ry + y * k + dy) * src.width + rx..][..ow * k];
            for (s, block) in sums.iter_mut().zip(row.chunks_exact(k)) {
                *s += block.iter().map(|&v| v as u32).sum::<u32>();
            }
        }
        out.extend(sums.iter().map(|&s| ((s + n / 2) / n) as u8));
    }
    out
}

/// The taps of a 1-D resampling of `n_in` samples to `n_out`, in `one`ths
/// (the weights of an output sum to exactly `one`, so a flat frame stays
/// flat). A downscale ([`Taps::area`]) averages each output's span; an
/// upscale ([`Taps::linear`]) interpolates between the two samples
/// around its centre.
struct Taps {
    /// First input sample of each output.
    start: Vec<usize>,
    /// Taps per output (the longest span's).
    len: usize,
    /// `len` weights per output (0 past its span).
    weights: Vec<u32>,
}

impl Taps {
    /// The taps for `n_in` to `n_out` samples: [`Self::area`] when
    /// `n_out <= n_in`, else [`Self::linear`].
    fn new(n_in: usize, n_out: usize, one: u32) -> Self {
        if n_out <= n_in {
            Self::area(n_in, n_out, one)
        } else {
            Self::linear(n_in, n_out, one)
        }
    }

    /// Linear interpolation (`n_out > n_in`): output `k`'s centre is input
    /// `(k + 0.5) s - 0.5` (`s = n_in / n_out`, pixel centres kept),
    /// clamped to the first and last samples.
    fn linear(n_in: usize, n_out: usize, one: u32) -> Self {
        let s = n_in as f64 / n_out as f64;
        let last = n_in.saturating_sub(1);
        let mut start = Vec::with_capacity(n_out);
        let mut weights = Vec::with_capacity(2 * n_out);
        for k in 0..n_out {
            let f = ((k as f64 + 0.5) * s - 0.5).clamp(0.0, last as f64);
            let first = (f.floor() as usize).min(last.saturating_sub(1));
            let far = ((f - first as f64) * one as f64).round() as u32;
            start.push(first);
            weights.extend([one - far.min(one), far.min(one)]);
        }
        Self {
            start,
            len: 2,
            weights,
        }
    }

    /// Area (box) averaging (`n_out <= n_in`): output `k` spans input
    /// `[k s, (k + 1) s)` (`s = n_in / n_out`), and each input sample it
    /// touches weighs the length of the span it covers.
    fn area(n_in: usize, n_out: usize, one: u32) -> Self {
        let s = n_in as f64 / n_out as f64;
        let len = s.ceil() as usize + 1;
        let mut start = Vec::with_capacity(n_out);
        let mut weights = vec![0u32; n_out * len];
        for (k, w) in weights.chunks_exact_mut(len).enumerate() {
            let (a, b) = (k as f64 * s, ((k + 1) as f64 * s).min(n_in as f64));
            // The last taps may pass the end (weight 0): start early enough
            // that all `len` are inside.
            let first = (a.floor() as usize).min(n_in.saturating_sub(len));
            start.push(first);
            // Each weight the step of the rounded running total: they sum
            // to `one` exactly, and the running sums are never more than
            // half a unit off (the error of a weighted sum is then at most
            // half a unit times the samples' total variation).
            let mut below = 0u32;
            let mut covered = 0.0;
            for (t, wt) in w.iter_mut().enumerate() {
                let i = (first + t) as f64;
                covered += (b.min(i + 1.0) - a.max(i)).max(0.0);
                let total = ((covered / s * one as f64).round() as u32).min(one);
                *wt = total - below;
                below = total;
            }
        }
        Self {
            start,
            len,
            weights,
        }
    }

    /// Output `k`'s first input sample and weights.
    fn of(&self, k: usize) -> (usize, &[u32]) {
        (self.start[k], &self.weights[k * self.len..][..self.len])
    }
}

/// [`Taps`] weights down the rows: 1/256ths, so that a weighted sum of
/// 8-bit pixels fits in `u16` (at most 256 x 255), whose multiplies and
/// adds SSE2 has (it has no 32-bit multiply).
const AREA_ONE_DOWN: u32 = 256;

/// [`Taps`] weights across: 1/4096ths (a row sum of at most 2^16 times
/// that, below 2^28, in `u32`).
const AREA_ONE_ACROSS: u32 = 4096;

/// `rect` resampled to `ow x oh`, separably and in fixed point
/// ([`Taps`]), each axis on its own: where it shrinks, each output
/// pixel is the mean of the input pixels its footprint covers, weighted by
/// how much of each it covers (what OpenCV's `INTER_AREA` computes), within
/// about a grey level of the exact mean (bilinear sampling would read only
/// the 4 pixels nearest each output's centre: at 1.5x it drops half the
/// input's pixels, aliasing pins and noise); where it grows, linearly
/// interpolated.
fn resample(src: &GreyFrame, rect: [usize; 4], ow: usize, oh: usize) -> Vec<u8> {
    let [rx, ry, rw, rh] = rect;
    if ow > rw && oh > rh {
        return magnify(src, rect, ow, oh);
    }
    let across = Taps::new(rw, ow, AREA_ONE_ACROSS);
    let down = Taps::new(rh, oh, AREA_ONE_DOWN);
    // `across.len` spare zeros past the end: every output's taps can be
    // read as one fixed-size block.
    let mut column_sums = vec![0u16; rw + across.len];
    let mut out = vec![0u8; ow * oh];
    for (y, out_row) in out.chunks_exact_mut(ow).enumerate() {
        let (first, wy) = down.of(y);
        column_sums.fill(0);
        for (t, &w) in wy.iter().enumerate() {
            if w == 0 {
                continue;
            }
            let w = w as u16;
            let row = &src.data[(ry + first + t) * src.width + rx..][..rw];
            // Wrapping: no overflow check in the loop (so it vectorises);
            // the weights sum to 256, so no sum passes 256 x 255. In
            // blocks of 16 (the vectoriser's lanes), then the rest.
            let add = |sums: &mut [u16], px: &[u8]| {
                for (s, &v) in sums.iter_mut().zip(px) {
                    *s = s.wrapping_add(w.wrapping_mul(v as u16));
                }
            };
            let (body, tail) = row.split_at(rw - rw % 16);
            for (sums, px) in column_sums.chunks_exact_mut(16).zip(body.chunks_exact(16)) {
                add(sums, px);
            }
            add(&mut column_sums[body.len()..], tail);
        }
        match across.len {
            2 => across_row::<2>(&across, &column_sums, out_row),
            3 => across_row::<3>(&across, &column_sums, out_row),
            4 => across_row::<4>(&across, &column_sums, out_row),
            5 => across_row::<5>(&across, &column_sums, out_row),
            6 => across_row::<6>(&across, &column_sums, out_row),
            _ => {
                for (x, o) in out_row.iter_mut().enumerate() {
                    let (first, wx) = across.of(x);
                    let sum = wx
                        .iter()
                        .zip(&column_sums[first..])
                        .map(|(&w, &s)| w * s as u32)
                        .sum();
                    *o = area_pixel(sum);
                }
            }
        }
    }
    out
}

/// [`resample`] where both axes grow ([`FrameParams::upscale`]: pins too
/// close for the detector): linear interpolation, across each input row
/// first (weights in 1/4096ths, kept in 1/64ths of a grey level, at most
/// 255 x 64 in `u16`), then down the rows (1/256ths): each input row is
/// interpolated once, and only the two the output row lies between are
/// kept. Within about a grey level of the f64 bilinear value (the
/// proptest). Across is a gather, which the compiler leaves scalar (7.1 M
/// instructions for 640x480 -> 666x500, against 1-3 M for the whole
/// pipeline; 2.2 M now, BENCHMARKS.md, session 35); with SSSE3 it goes 8
/// outputs a `pshufb` pair ([`simd::across_lerp`]), and down the rows 8
/// outputs a `pmaddwd` pair ([`simd::down_lerp`]); the scalar paths
/// ([`across_lerp`], [`down_lerp`]) compute the same integers.
fn magnify(src: &GreyFrame, rect: [usize; 4], ow: usize, oh: usize) -> Vec<u8> {
    let [rx, ry, rw, rh] = rect;
    let across = Taps::linear(rw, ow, AREA_ONE_ACROSS);
    let down = Taps::linear(rh, oh, AREA_ONE_DOWN);
    let plan = simd::LerpPlan::new(&across, rw, ow);
    let row_across = |j: usize, out: &mut [u16]| {
        let start = (ry + j) * src.width + rx;
        // The row and what follows it in the frame: the vector path reads
        // 16 bytes from each group's first sample where they are there.
        let done = simd::across_lerp(&plan, &src.data[start..], out);
        across_lerp(&src.data[start..start + rw], &across, done, out);
    };
    // The two input rows the current output row lies between (the first
    // never decreases as the output row goes down).
    let (mut ra, mut rb) = ((usize::MAX, vec![0u16; ow]), (usize::MAX, vec![0u16; ow]));
    let mut out = vec![0u8; ow * oh];
    for (y, o) in out.chunks_exact_mut(ow).enumerate() {
        let (a, v) = down.of(y);
        let b = (a + 1).min(rh - 1);
        if rb.0 == a {
            std::mem::swap(&mut ra, &mut rb);
        }
        for (j, row) in [(a, &mut ra), (b, &mut rb)] {
            if row.0 != j {
                row_across(j, &mut row.1);
                row.0 = j;
            }
        }
        let done = simd::down_lerp(&ra.1, &rb.1, [v[0], v[1]], o);
        down_lerp(&ra.1, &rb.1, [v[0], v[1]], done, o);
    }
    out
}

/// [`magnify`]'s pass across, outputs `from..`: `out[x]` is the row
/// interpolated at output `x` ([`Taps::linear`], 1/4096ths), in 1/64ths
/// of a grey level, rounded.
fn across_lerp(row: &[u8], across: &Taps, from: usize, out: &mut [u16]) {
    let last = row.len() - 1;
    for (x, o) in out.iter_mut().enumerate().skip(from) {
        let (a, w) = across.of(x);
        let b = (a + 1).min(last);
        *o = ((w[0] * row[a] as u32 + w[1] * row[b] as u32 + 32) >> 6) as u16;
    }
}

/// [`magnify`]'s pass down, outputs `from..`: rows `ra` and `rb` (1/64ths
/// of a grey level) weighted by `v` (1/256ths), rounded to grey levels;
/// at most `(255 x 64 x 256 + 2^13) >> 14 = 255`.
fn down_lerp(ra: &[u16], rb: &[u16], v: [u32; 2], from: usize, out: &mut [u8]) {
    let pairs = ra.iter().zip(rb).skip(from);
    for (o, (&a, &b)) in out.iter_mut().skip(from).zip(pairs) {
        *o = ((v[0] * a as u32 + v[1] * b as u32 + (1 << 13)) >> 14) as u8;
    }
}

/// One output row of [`resample`]'s pass across, for `L` taps an
/// output (a fixed block each: unrolled, one bounds check).
fn across_row<const L: usize>(across: &Taps, column_sums: &[u16], out_row: &mut [u8]) {
    let taps = across.start.iter().zip(across.weights.chunks_exact(L));
    for (o, (&first, wx)) in out_row.iter_mut().zip(taps) {
        // Always there (`Taps` starts each output's taps early enough,
        // and the sums have `L` spare zeros).
        let (Ok(wx), Some(Ok(sums))) = (
            <&[u32; L]>::try_from(wx),
            column_sums.get(first..first + L).map(<&[u16; L]>::try_from),
        ) else {
            continue;
        };
        // Wrapping: no overflow checks (the sum stays below 2^28).
        let sum = wx
            .iter()
            .zip(sums)
            .fold(0u32, |a, (&w, &s)| a.wrapping_add(w.wrapping_mul(s as u32)));
        *o = area_pixel(sum);
    }
}

/// The grey level of a weighted sum in units of `AREA_ONE_DOWN x
/// AREA_ONE_ACROSS`, rounded.
fn area_pixel(sum: u32) -> u8 {
    const ONE: u32 = AREA_ONE_DOWN * AREA_ONE_ACROSS;
    (sum.wrapping_add(ONE / 2) / ONE).min(255) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::Strategy;

    /// [`gaussian_blur`] as a plain per-pixel loop (the sums it must equal).
    fn plain_blur(data: &mut [f32], width: usize, height: usize, sigma_px: f64) {
        let (radius, kernel) = gaussian_kernel(sigma_px);
        let (wi, hi) = (width as i64, height as i64);
        let mut tmp = vec![0f32; data.len()];
        for y in 0..height {
            for x in 0..wi {
                let mut acc = 0f32;
                for (k, &kv) in kernel.iter().enumerate() {
                    acc += kv * data[y * width + (x + k as i64 - radius).clamp(0, wi - 1) as usize];
                }
                tmp[y * width + x as usize] = acc;
            }
        }
        for y in 0..hi {
            for x in 0..width {
                let mut acc = 0f32;
                for (k, &kv) in kernel.iter().enumerate() {
                    acc += kv * tmp[(y + k as i64 - radius).clamp(0, hi - 1) as usize * width + x];
                }
                data[y as usize * width + x] = acc;
            }
        }
    }

    proptest::proptest! {
        /// The blur's sums are the per-pixel loop's, bit for bit, for
        /// frames narrower and wider than the kernel.
        #[test]
        fn the_blur_equals_the_per_pixel_loop(
            (width, height, pixels) in (1usize..40, 1usize..30).prop_flat_map(|(w, h)| {
                (proptest::prelude::Just(w), proptest::prelude::Just(h),
                 proptest::collection::vec(0.0f32..255.0, w * h))
            }),
            sigma_px in 0.3f64..4.0,
        ) {
            let (mut fast, mut plain) = (pixels.clone(), pixels);
            gaussian_blur(&mut fast, width, height, sigma_px);
            plain_blur(&mut plain, width, height, sigma_px);
            proptest::prop_assert_eq!(fast, plain);
        }
    }

    /// A grey raw frame of `data`.
    fn grey_raw(width: usize, height: usize, data: &[u8]) -> RawFrame<'_> {
        RawFrame {
            width,
            height,
            channels: 1,
            data,
        }
    }

    fn params(w: u32, h: u32) -> FrameParams {
        FrameParams {
            work_width_px: w,
            work_height_px: h,
            ..FrameParams::default()
        }
    }

    #[test]
    fn rgb_becomes_luma_or_its_brightest_channel() {
        let data = [255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255, 40, 90, 200];
        let raw = RawFrame {
            width: 5,
            height: 1,
            channels: 3,
            data: &data,
        };
        let g = to_grey(&raw, Grey::Luma).unwrap();
        assert_eq!(g.data(), &[76, 149, 28, 255, 87]);
        let g = to_grey(&raw, Grey::Max).unwrap();
        assert_eq!(g.data(), &[255, 255, 255, 255, 200]);
        let rgba: Vec<u8> = data.chunks(3).flat_map(|p| [p[0], p[1], p[2], 7]).collect();
        let raw = RawFrame {
            channels: 4,
            data: &rgba,
            ..raw
        };
        assert_eq!(to_grey(&raw, Grey::Max).unwrap().data(), g.data());
    }

    #[test]
    fn the_brightest_channel_is_the_same_in_vector_blocks_and_in_the_tail() {
        // 70 pixels: four vector blocks of 16 and a tail of 6, each channel
        // the brightest somewhere.
        let rgba: Vec<u8> = (0..70u32 * 4).map(|i| (i * 37 % 251) as u8).collect();
        let rgb: Vec<u8> = rgba.chunks(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        let want: Vec<u8> = rgba.chunks(4).map(|p| p[0].max(p[1]).max(p[2])).collect();
        assert_eq!(max_channel::<3>(&rgb), want);
        assert_eq!(max_channel::<4>(&rgba), want);
    }

    #[test]
    fn bad_buffers_are_typed_errors() {
        let raw = |w, h, c, d: &'static [u8]| RawFrame {
            width: w,
            height: h,
            channels: c,
            data: d,
        };
        assert!(matches!(
            to_grey(&raw(0, 5, 1, &[]), Grey::Max),
            Err(FrameError::Empty { .. })
        ));
        assert!(matches!(
            to_grey(&raw(2, 2, 1, &[1, 2, 3]), Grey::Max),
            Err(FrameError::BadLength { .. })
        ));
        assert!(matches!(
            to_grey(&raw(1, 1, 2, &[1, 2]), Grey::Max),
            Err(FrameError::Channels(2))
        ));
        assert!(matches!(
            to_grey(&raw(MAX_SIDE_PX + 1, 1, 1, &[]), Grey::Max),
            Err(FrameError::TooLarge { .. })
        ));
    }

    #[test]
    fn halving_averages_blocks_and_maps_back() {
        let data: Vec<u8> = (0..16).map(|i| (i * 10) as u8).collect();
        let raw = grey_raw(4, 4, &data);
        let p = prepare(&raw, &params(2, 2)).unwrap();
        assert_eq!(p.grey.data(), &[25, 45, 105, 125]);
        let q = p.to_input(PointPx::new(0.0, 0.0));
        assert_eq!(q, PointPx::new(0.5, 0.5));
    }

    #[test]
    fn same_size_is_identity_and_crop_is_checked() {
        let data: Vec<u8> = (0..12).collect();
        let raw = grey_raw(4, 3, &data);
        let p = prepare(&raw, &params(4, 3)).unwrap();
        assert_eq!(p.grey.data(), &data[..]);
        assert_eq!(p.to_input(PointPx::new(2.0, 1.0)), PointPx::new(2.0, 1.0));
        let mut fp = params(2, 2);
        fp.crop_px = Some([1, 1, 2, 2]);
        let c = prepare(&raw, &fp).unwrap();
        assert_eq!(c.grey.data(), &[5, 6, 9, 10]);
        assert_eq!(c.to_input(PointPx::new(0.0, 0.0)), PointPx::new(1.0, 1.0));
        fp.crop_px = Some([3, 0, 2, 2]);
        assert!(matches!(prepare(&raw, &fp), Err(FrameError::Crop { .. })));
    }

    #[test]
    fn an_owned_frame_is_prepared_as_a_borrowed_one_and_moved_when_it_can_be() {
        let grey: Vec<u8> = (0..12).collect();
        let rgb: Vec<u8> = (0..36).map(|v| (v * 7 % 256) as u8).collect();
        for (channels, data) in [(1, grey), (3, rgb)] {
            let raw = RawFrame {
                width: 4,
                height: 3,
                channels,
                data: &data,
            };
            for fp in [params(4, 3), params(2, 2)] {
                let want = prepare(&raw, &fp).unwrap();
                let got = prepare_owned(4, 3, channels, data.clone(), &fp).unwrap();
                assert_eq!(got.grey.data(), want.grey.data());
                assert_eq!(got.map(), want.map());
            }
        }
        // A grey frame at the working size keeps its buffer.
        let data: Vec<u8> = (0..12).collect();
        let at = data.as_ptr();
        let p = prepare_owned(4, 3, 1, data, &params(4, 3)).unwrap();
        assert_eq!(p.grey.data().as_ptr(), at);
        assert!(matches!(
            prepare_owned(4, 3, 1, vec![0; 11], &params(4, 3)),
            Err(FrameError::BadLength { .. })
        ));
    }

    /// The area average in f64: each output the mean of the input over
    /// its footprint `[k s, (k + 1) s)` in both axes.
    fn area_reference(src: &[u8], w: usize, h: usize, ow: usize, oh: usize) -> Vec<f64> {
        let cover = |k: usize, s: f64, i: usize| {
            let (a, b) = (k as f64 * s, (k + 1) as f64 * s);
            (b.min(i as f64 + 1.0) - a.max(i as f64)).max(0.0) / s
        };
        let (sx, sy) = (w as f64 / ow as f64, h as f64 / oh as f64);
        let mut out = vec![0.0; ow * oh];
        for (k, o) in out.iter_mut().enumerate() {
            let (x, y) = (k % ow, k / ow);
            for j in 0..h {
                for i in 0..w {
                    *o += cover(x, sx, i) * cover(y, sy, j) * src[j * w + i] as f64;
                }
            }
        }
        out
    }

    /// A `w x h` frame of random pixels (`w`, `h` from `sizes`) and an
    /// output size whose sides `out` draws from each input side.
    fn resample_case(
        sizes: (std::ops::Range<usize>, std::ops::Range<usize>),
        out: fn(usize) -> std::ops::RangeInclusive<usize>,
    ) -> impl Strategy<Value = (usize, usize, usize, usize, Vec<u8>)> {
        sizes.prop_flat_map(move |(w, h)| {
            (
                proptest::prelude::Just(w),
                proptest::prelude::Just(h),
                out(w),
                out(h),
                proptest::collection::vec(0u8..=255, w * h),
            )
        })
    }

    proptest::proptest! {
        /// A non-integer downscale averages each working pixel's
        /// footprint, within the fixed point's bound of the f64 area
        /// average: half a grey level of rounding, plus half a weight unit
        /// (1/256 down the rows, 1/4096 across) times the largest total
        /// variation of 255 per step a footprint can hold; a flat frame
        /// stays exactly flat.
        #[test]
        fn a_downscale_averages_each_footprint(
            (w, h, ow, oh, pixels) in resample_case((2..30, 2..24), |n| 1..=n),
            flat in 0u8..=255,
        ) {
            let rect = [0, 0, w, h];
            let frame = GreyFrame::new(w, h, pixels.clone()).unwrap();
            let got = resample(&frame, rect, ow, oh);
            let steps = |n: usize, o: usize| (n as f64 / o as f64).ceil();
            let bound = 0.5
                + 255.0 * steps(h, oh) / (2.0 * AREA_ONE_DOWN as f64)
                + 255.0 * steps(w, ow) / (2.0 * AREA_ONE_ACROSS as f64);
            for (g, want) in got.iter().zip(area_reference(&pixels, w, h, ow, oh)) {
                proptest::prop_assert!((*g as f64 - want).abs() <= bound, "{} vs {}", g, want);
            }
            let flat_frame = GreyFrame::new(w, h, vec![flat; w * h]).unwrap();
            let got = resample(&flat_frame, rect, ow, oh);
            proptest::prop_assert!(got.iter().all(|&v| v == flat));
        }
    }

    proptest::proptest! {
        /// A magnification's vector passes give the scalar passes'
        /// integers, with the frame's next rows behind the region's
        /// (the pass across reads 16 bytes from each group's first sample).
        #[test]
        fn a_magnification_is_the_same_in_vectors_and_scalars(
            (w, h, ow, oh, pixels) in resample_case((1..40, 1..12), |n| n + 1..=3 * n + 1),
            rx in 0usize..4,
        ) {
            let rw = w.saturating_sub(rx).max(1);
            let (rx, ow) = (w - rw, ow.max(rw + 1));
            let frame = GreyFrame::new(w, h, pixels).unwrap();
            let got = magnify(&frame, [rx, 0, rw, h], ow, oh);
            let across = Taps::linear(rw, ow, AREA_ONE_ACROSS);
            let down = Taps::linear(h, oh, AREA_ONE_DOWN);
            let mut rows = vec![0u16; h * ow];
            for (j, r) in rows.chunks_exact_mut(ow).enumerate() {
                across_lerp(&frame.data()[j * w + rx..][..rw], &across, 0, r);
            }
            let mut want = vec![0u8; ow * oh];
            for (y, o) in want.chunks_exact_mut(ow).enumerate() {
                let (a, v) = down.of(y);
                let b = (a + 1).min(h - 1);
                down_lerp(&rows[a * ow..][..ow], &rows[b * ow..][..ow], [v[0], v[1]], 0, o);
            }
            proptest::prop_assert_eq!(got, want);
        }
    }

    #[test]
    fn a_non_integer_downscale_averages_and_maps_back() {
        // 3x3 -> 2x2: each working pixel covers 1.5 x 1.5 input pixels.
        let data = [0u8, 90, 180, 0, 90, 180, 0, 90, 180];
        let raw = grey_raw(3, 3, &data);
        let p = prepare(&raw, &params(2, 2)).unwrap();
        // (0 + 0.5 * 90) / 1.5 = 30, (0.5 * 90 + 180) / 1.5 = 150.
        assert_eq!(p.grey.data(), &[30, 150, 30, 150]);
        assert_eq!(p.to_input(PointPx::new(0.0, 0.0)), PointPx::new(0.25, 0.25));
    }

    #[test]
    fn upscale_is_bilinear_and_bounded() {
        let data = [0u8, 255];
        let raw = grey_raw(2, 1, &data);
        // Upscaling only happens when asked to stretch.
        assert_eq!(prepare(&raw, &params(4, 2)).unwrap().grey.width(), 2);
        let stretch = FrameParams {
            keep_aspect: false,
            ..params(4, 2)
        };
        let p = prepare(&raw, &stretch).unwrap();
        assert_eq!(p.grey.width(), 4);
        assert_eq!(p.grey.data()[0], 0);
        assert_eq!(p.grey.data()[3], 255);
        assert!(p.grey.data()[1] > 0 && p.grey.data()[1] < 128);
    }

    #[test]
    fn upscale_magnifies_the_fitted_size_and_maps_back() {
        let data: Vec<u8> = (0..12).map(|v| v * 20).collect();
        let raw = grey_raw(4, 3, &data);
        let up = FrameParams {
            upscale: Some(2.0),
            ..params(640, 480)
        };
        let p = prepare(&raw, &up).unwrap();
        assert_eq!((p.grey.width(), p.grey.height()), (8, 6));
        // Working pixel (1, 1) is input (0.25, 0.25): between the first two
        // pixels of the first two rows, a quarter of the way.
        assert_eq!(p.to_input(PointPx::new(1.0, 1.0)), PointPx::new(0.25, 0.25));
        let v = |x: f64, y: f64| 20.0 * (x + 4.0 * y);
        assert!((p.grey.data()[8 + 1] as f64 - v(0.25, 0.25)).abs() <= 1.0);
        // A 1280x960 frame at upscale 1.5: fitted to 640x480, then 960x720.
        assert_eq!(
            working_size(
                1280,
                960,
                &FrameParams {
                    upscale: Some(1.5),
                    ..FrameParams::default()
                }
            ),
            (960, 720)
        );
    }

    proptest::proptest! {
        /// An upscale interpolates linearly between the two input pixels
        /// around each working pixel's centre: within 1.5 grey levels of
        /// the f64 bilinear value (1/256ths down the rows, half a unit
        /// each, plus rounding).
        #[test]
        fn an_upscale_interpolates_linearly(
            (w, h, ow, oh, pixels) in resample_case((1..12, 1..10), |n| n..=3 * n),
        ) {
            let frame = GreyFrame::new(w, h, pixels.clone()).unwrap();
            let got = resample(&frame, [0, 0, w, h], ow, oh);
            let at = |x: usize, y: usize| pixels[y * w + x] as f64;
            let centre = |k: usize, n: usize, o: usize| {
                ((k as f64 + 0.5) * n as f64 / o as f64 - 0.5).clamp(0.0, (n - 1) as f64)
            };
            for (k, &g) in got.iter().enumerate() {
                let (fx, fy) = (centre(k % ow, w, ow), centre(k / ow, h, oh));
                let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
                let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
                let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
                let want = (at(x0, y0) * (1.0 - tx) + at(x1, y0) * tx) * (1.0 - ty)
                    + (at(x0, y1) * (1.0 - tx) + at(x1, y1) * tx) * ty;
                proptest::prop_assert!((g as f64 - want).abs() <= 1.5, "{} vs {}", g, want);
            }
        }
    }
}
