//! Camera buffer -> grey frame: the luma plane of MJPEG, YUYV (4:2:2) and
//! GREY buffers, and the packers that make such buffers from a grey frame
//! (the fake device's recorded streams, tests and benchmarks).
//!
//! - **YUYV**: bytes `Y0 U Y1 V` per pixel pair; the grey frame is the `Y`
//!   bytes (every other byte), row by row with the driver's line stride.
//! - **MJPEG**: one JPEG per buffer (UVC cameras often leave out the Huffman
//!   tables; the decoder then uses the standard ones), decoded straight to
//!   luma by `zune-jpeg` (no colour conversion). Strict mode: a truncated or
//!   corrupt JPEG is an error, not a half-grey frame.
//! - **GREY**: 8-bit luma with the driver's line stride.

use dexitac_tactile::frame::{FrameError, GreyFrame, MAX_SIDE_PX};

use super::{Mode, PixelFormat};

/// Why a camera buffer could not be decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The buffer is shorter than the mode's frame.
    #[error("{format} buffer has {got} bytes, a {width}x{height} frame needs {expected}")]
    Truncated {
        /// The buffer's format.
        format: PixelFormat,
        /// Frame width, px.
        width: usize,
        /// Frame height, px.
        height: usize,
        /// Bytes needed.
        expected: usize,
        /// Bytes given.
        got: usize,
    },
    /// The line stride cannot hold a line.
    #[error("line stride {stride} bytes is too short for {width} px of {format}")]
    Stride {
        /// The format.
        format: PixelFormat,
        /// Frame width, px.
        width: usize,
        /// The stride, bytes.
        stride: usize,
    },
    /// The JPEG decoder rejected the buffer (corrupt or truncated frame).
    #[error("corrupt MJPEG frame: {0}")]
    Jpeg(String),
    /// The decoded frame has an impossible size.
    #[error("bad frame: {0}")]
    Frame(#[from] FrameError),
}

/// Decodes one buffer of `mode` to a grey frame (input size).
pub fn to_grey(data: &[u8], mode: &Mode) -> Result<GreyFrame, DecodeError> {
    let (w, h) = (mode.width_px as usize, mode.height_px as usize);
    match mode.format {
        PixelFormat::Mjpeg => mjpeg_luma(data),
        PixelFormat::Yuyv => yuyv_luma(data, w, h, mode.stride_bytes),
        PixelFormat::Grey => grey_plane(data, w, h, mode.stride_bytes),
    }
}

/// The `Y` bytes of a YUYV buffer. `stride_bytes` 0 means packed (`2 w`).
/// An odd width is accepted (the last pair's second `Y` is dropped).
pub fn yuyv_luma(
    data: &[u8],
    width: usize,
    height: usize,
    stride_bytes: usize,
) -> Result<GreyFrame, DecodeError> {
    check_width(width)?;
    let line = 4 * width.div_ceil(2);
    let stride = checked_stride(PixelFormat::Yuyv, width, line, stride_bytes)?;
    check_len(PixelFormat::Yuyv, data, width, height, stride, line)?;
    let mut out = Vec::with_capacity(width * height);
    for row in data.chunks(stride).take(height) {
        out.extend(row[..line].iter().step_by(2).take(width));
    }
    Ok(GreyFrame::new(width, height, out)?)
}

/// A GREY (8-bit luma) buffer with a line stride (`0`: packed).
pub fn grey_plane(
    data: &[u8],
    width: usize,
    height: usize,
    stride_bytes: usize,
) -> Result<GreyFrame, DecodeError> {
    check_width(width)?;
    let stride = checked_stride(PixelFormat::Grey, width, width, stride_bytes)?;
    check_len(PixelFormat::Grey, data, width, height, stride, width)?;
    let mut out = Vec::with_capacity(width * height);
    for row in data.chunks(stride).take(height) {
        out.extend_from_slice(&row[..width]);
    }
    Ok(GreyFrame::new(width, height, out)?)
}

fn check_width(width: usize) -> Result<(), DecodeError> {
    if width == 0 {
        return Err(FrameError::Empty { width, height: 0 }.into());
    }
    if width > MAX_SIDE_PX {
        return Err(FrameError::TooLarge { width, height: 0 }.into());
    }
    Ok(())
}

fn checked_stride(
    format: PixelFormat,
    width: usize,
    line: usize,
    stride_bytes: usize,
) -> Result<usize, DecodeError> {
    match stride_bytes {
        0 => Ok(line),
        s if s >= line => Ok(s),
        s => Err(DecodeError::Stride {
            format,
            width,
            stride: s,
        }),
    }
}

/// The last line needs only `line` bytes, not a whole stride.
fn check_len(
    format: PixelFormat,
    data: &[u8],
    width: usize,
    height: usize,
    stride: usize,
    line: usize,
) -> Result<(), DecodeError> {
    if height == 0 {
        return Err(FrameError::Empty { width, height }.into());
    }
    if height > MAX_SIDE_PX {
        return Err(FrameError::TooLarge { width, height }.into());
    }
    let expected = stride * (height - 1) + line;
    if data.len() < expected {
        return Err(DecodeError::Truncated {
            format,
            width,
            height,
            expected,
            got: data.len(),
        });
    }
    Ok(())
}

/// Decodes a JPEG straight to its luma plane.
pub fn mjpeg_luma(data: &[u8]) -> Result<GreyFrame, DecodeError> {
    use zune_core::bytestream::ZCursor;
    use zune_core::colorspace::ColorSpace;
    use zune_core::options::DecoderOptions;

    let options = DecoderOptions::new_fast()
        .jpeg_set_out_colorspace(ColorSpace::Luma)
        .set_strict_mode(true)
        .set_max_width(MAX_SIDE_PX)
        .set_max_height(MAX_SIDE_PX);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(data), options);
    decoder
        .decode_headers()
        .map_err(|e| DecodeError::Jpeg(e.to_string()))?;
    let info = decoder
        .info()
        .ok_or_else(|| DecodeError::Jpeg("no frame header".into()))?;
    let (w, h) = (info.width as usize, info.height as usize);
    let size = decoder
        .output_buffer_size()
        .ok_or_else(|| DecodeError::Jpeg("no frame header".into()))?;
    if size != w * h {
        return Err(DecodeError::Jpeg(format!(
            "decoder gave {size} bytes for a {w}x{h} luma frame"
        )));
    }
    let mut out = vec![0u8; size];
    decoder
        .decode_into(&mut out)
        .map_err(|e| DecodeError::Jpeg(e.to_string()))?;
    Ok(GreyFrame::new(w, h, out)?)
}

/// Packs a grey frame as YUYV with neutral chroma (`U = V = 128`), line
/// stride `2 w` rounded up to whole pixel pairs; an odd width repeats the
/// last pixel.
pub fn pack_yuyv(frame: &GreyFrame) -> Vec<u8> {
    let (w, h) = (frame.width(), frame.height());
    let pairs = w.div_ceil(2);
    let mut out = Vec::with_capacity(4 * pairs * h);
    for row in frame.data().chunks(w) {
        for p in 0..pairs {
            let y0 = row[2 * p];
            let y1 = row.get(2 * p + 1).copied().unwrap_or(y0);
            out.extend_from_slice(&[y0, 128, y1, 128]);
        }
    }
    out
}

/// Encodes a grey frame as a colour (3-component, as UVC cameras send) JPEG
/// of `quality` 1..=100.
pub fn encode_mjpeg(frame: &GreyFrame, quality: u8) -> Result<Vec<u8>, String> {
    let rgb: Vec<u8> = frame.data().iter().flat_map(|&v| [v, v, v]).collect();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100))
        .encode(
            &rgb,
            frame.width() as u32,
            frame.height() as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| e.to_string())?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> GreyFrame {
        let data = (0..w * h)
            .map(|i| ((i * 7 + i / w * 13) % 256) as u8)
            .collect();
        GreyFrame::new(w, h, data).unwrap()
    }

    fn mode(format: PixelFormat, w: u32, h: u32, stride: usize) -> Mode {
        Mode {
            format,
            width_px: w,
            height_px: h,
            stride_bytes: stride,
            fps: None,
        }
    }

    #[test]
    fn yuyv_takes_the_luma_bytes() {
        for (w, h) in [(640, 480), (8, 2), (7, 3), (1, 1), (33, 17)] {
            let f = ramp(w, h);
            let buf = pack_yuyv(&f);
            let back = to_grey(&buf, &mode(PixelFormat::Yuyv, w as u32, h as u32, 0)).unwrap();
            assert_eq!(back, f, "{w}x{h}");
        }
    }

    #[test]
    fn yuyv_with_padded_stride() {
        let f = ramp(6, 4);
        let packed = pack_yuyv(&f);
        let stride = 16;
        let mut padded = Vec::new();
        for row in packed.chunks(12) {
            padded.extend_from_slice(row);
            padded.extend_from_slice(&[9; 4]);
        }
        padded.truncate(padded.len() - 4); // the last line needs no padding
        let back = yuyv_luma(&padded, 6, 4, stride).unwrap();
        assert_eq!(back, f);
    }

    #[test]
    fn short_buffers_and_bad_strides_are_errors() {
        let f = ramp(8, 4);
        let buf = pack_yuyv(&f);
        let e = yuyv_luma(&buf[..buf.len() - 1], 8, 4, 0).unwrap_err();
        assert!(
            matches!(
                e,
                DecodeError::Truncated {
                    expected: 64,
                    got: 63,
                    ..
                }
            ),
            "{e}"
        );
        assert!(matches!(
            yuyv_luma(&buf, 8, 4, 10),
            Err(DecodeError::Stride { .. })
        ));
        assert!(yuyv_luma(&buf, 0, 4, 0).is_err());
        assert!(yuyv_luma(&buf, 8, 0, 0).is_err());
        assert!(grey_plane(&[1, 2, 3], 2, 2, 0).is_err());
        assert!(yuyv_luma(&[], usize::MAX / 2, 2, 0).is_err());
        assert!(grey_plane(&[], 4, usize::MAX / 4, 0).is_err());
    }

    #[test]
    fn grey_plane_drops_stride_padding() {
        let data = [1, 2, 0, 3, 4, 0, 5, 6];
        let g = grey_plane(&data, 2, 3, 3).unwrap();
        assert_eq!(g.data(), &[1, 2, 3, 4, 5, 6]);
    }

    #[test]
    fn mjpeg_round_trip_is_close() {
        for (w, h) in [(640, 480), (17, 9), (1, 1), (63, 31)] {
            let f = ramp(w, h);
            let jpeg = encode_mjpeg(&f, 95).unwrap();
            let back = to_grey(&jpeg, &mode(PixelFormat::Mjpeg, w as u32, h as u32, 0)).unwrap();
            assert_eq!((back.width(), back.height()), (w, h));
            let mean_err = f
                .data()
                .iter()
                .zip(back.data())
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
                / (w * h) as f64;
            // The ramp is sharp-edged (7 grey levels per px): q95 keeps it
            // to a few grey levels on average.
            assert!(mean_err < 6.0, "{w}x{h}: mean error {mean_err}");
        }
    }

    #[test]
    fn corrupt_jpegs_are_errors_not_panics() {
        let jpeg = encode_mjpeg(&ramp(64, 48), 90).unwrap();
        let cases: Vec<Vec<u8>> = vec![
            Vec::new(),
            vec![0xff, 0xd8],
            jpeg[..jpeg.len() / 2].to_vec(),
            jpeg[..20].to_vec(),
            b"not a jpeg at all".to_vec(),
            {
                let mut j = jpeg.clone();
                // Garble the frame header (SOF0 sizes) and the scan.
                for b in j.iter_mut().skip(2).step_by(3) {
                    *b ^= 0x5a;
                }
                j
            },
        ];
        for (i, c) in cases.iter().enumerate() {
            let r = mjpeg_luma(c);
            assert!(r.is_err(), "case {i} decoded: {:?}", r.map(|g| g.width()));
        }
    }

    #[test]
    fn random_bytes_never_panic() {
        let jpeg = encode_mjpeg(&ramp(32, 24), 80).unwrap();
        let mut rng = dexitac_tactile::synth::Rng::new(3);
        for _ in 0..300 {
            let mut j = jpeg.clone();
            for _ in 0..4 {
                let k = (rng.next_u64() as usize) % j.len();
                j[k] = rng.next_u64() as u8;
            }
            let cut = (rng.next_u64() as usize) % (j.len() + 1);
            // Either a frame of the encoded size or an error; never a panic.
            if let Ok(g) = mjpeg_luma(&j[..cut]) {
                assert!(g.width() <= MAX_SIDE_PX && g.height() <= MAX_SIDE_PX);
            }
        }
    }
}
