//! `dexitac analyze`: image files -> contact centres CSV.

use std::fs::File;
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use dexitac_tactile::calibrate;
use dexitac_tactile::displacement::ShiftTracker;
use dexitac_tactile::frame::{self, Prepared, RawFrame};
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::PointPx;

use crate::AnalyzeArgs;

/// CSV header (the first eight columns are the interface; more may follow).
const HEADER: &str =
    "frame,cx,cy,n_markers,t_detect_ms,t_kde_ms,t_segment_ms,t_total_ms,area_mm2,source,skipped,shift_mm,shift_from_anchor_mm";

/// A decoded image file.
struct Decoded {
    width: usize,
    height: usize,
    channels: usize,
    data: Vec<u8>,
}

impl Decoded {
    fn raw(&self) -> RawFrame<'_> {
        RawFrame {
            width: self.width,
            height: self.height,
            channels: self.channels,
            data: &self.data,
        }
    }
}

/// Runs the subcommand; errors are printed, not returned.
pub fn run(args: &AnalyzeArgs) -> ExitCode {
    match run_inner(args) {
        Ok(0) => ExitCode::SUCCESS,
        Ok(failed) => {
            eprintln!("dexitac analyze: {failed} frame(s) could not be analysed (see above)");
            ExitCode::from(1)
        }
        Err(msg) => {
            eprintln!("dexitac analyze: error: {msg}");
            ExitCode::from(2)
        }
    }
}

fn run_inner(args: &AnalyzeArgs) -> Result<usize, String> {
    let params = match &args.config {
        Some(path) => Params::load(path).map_err(|e| e.to_string())?,
        None => Params::default(),
    };
    let mut rest_prepared = Vec::new();
    let mut rest_size = None;
    for path in &args.rest {
        let d = decode(path).map_err(|e| format!("rest frame {}: {e}", path.display()))?;
        if let Some((w, h)) = rest_size {
            if (w, h) != (d.width, d.height) {
                return Err(format!(
                    "rest frame {}: size {}x{} differs from {w}x{h}",
                    path.display(),
                    d.width,
                    d.height
                ));
            }
        }
        rest_size = Some((d.width, d.height));
        let p = frame::prepare(&d.raw(), &params.frame)
            .map_err(|e| format!("rest frame {}: {e}", path.display()))?;
        rest_prepared.push(p.grey);
    }
    let (rest_w, rest_h) = rest_size.ok_or("no rest frame")?;
    let cal = calibrate::calibrate(&rest_prepared, &params).map_err(|e| e.to_string())?;
    let pipeline = Pipeline::new(cal, params.clone());

    let (files, mut failed) = expand(&args.frames);
    if let Some(dir) = &args.markers_out {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    let out = File::create(&args.out)
        .map_err(|e| format!("cannot create {}: {e}", args.out.display()))?;
    let mut out = BufWriter::new(out);
    let io_err = |e: std::io::Error| format!("writing {}: {e}", args.out.display());
    writeln!(out, "{HEADER}").map_err(io_err)?;
    let mut progress = Progress::new(files.len());
    // Centre shifts in the order the frames are given; the anchor is the
    // first contact centre.
    let mut shifts = ShiftTracker::new(params.frame.mm_per_px);
    for (n, path) in files.iter().enumerate() {
        progress.show(n);
        match analyze_one(
            path,
            &pipeline,
            &params,
            (rest_w, rest_h),
            args.markers_out.as_deref(),
        ) {
            Ok((row, centre)) => {
                let shift = shifts.update(centre);
                if centre.is_some() && shift.from_anchor_mm.is_none() {
                    shifts.hold_anchor();
                }
                let from_anchor = match (centre, shift.from_anchor_mm) {
                    (Some(_), None) => Some(0.0),
                    (_, d) => d,
                };
                let mm = |v: Option<f64>| v.map_or("NaN".to_string(), |v| format!("{v:.4}"));
                writeln!(
                    out,
                    "{row},{},{}",
                    mm(shift.frame_to_frame_mm),
                    mm(from_anchor)
                )
                .map_err(io_err)?
            }
            Err(msg) => {
                progress.clear();
                eprintln!("dexitac analyze: {}: {msg}", path.display());
                failed += 1;
            }
        }
    }
    progress.finish();
    out.flush().map_err(io_err)?;
    Ok(failed)
}

/// One frame -> one CSV row (without the shift columns) and the contact
/// centre in working px.
fn analyze_one(
    path: &Path,
    pipeline: &Pipeline,
    params: &Params,
    rest_size: (usize, usize),
    markers_out: Option<&Path>,
) -> Result<(String, Option<PointPx>), String> {
    let d = decode(path)?;
    if (d.width, d.height) != rest_size {
        return Err(format!(
            "wrong size {}x{}: the rest frame is {}x{}",
            d.width, d.height, rest_size.0, rest_size.1
        ));
    }
    let t0 = std::time::Instant::now();
    let prepared = frame::prepare(&d.raw(), &params.frame).map_err(|e| e.to_string())?;
    // Frame preparation (grey, crop, rescale) counts as part of detection.
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;
    let r = pipeline.run(&prepared.grey).map_err(|e| e.to_string())?;
    let stem = stem_of(path);
    if let Some(dir) = markers_out {
        write_markers(
            &dir.join(format!("{stem}.csv")),
            &prepared,
            &r.markers.positions(),
        )?;
    }
    if r.markers.is_empty() {
        eprintln!(
            "dexitac analyze: {}: warning: no markers found (blank frame?)",
            path.display()
        );
    }
    let t = r.times;
    let (cx, cy, area, source) = match r.contact {
        Some(c) => {
            let p = prepared.to_input(c.centre);
            (
                fmt(p.x),
                fmt(p.y),
                format!("{:.3}", c.area_mm2),
                c.source.name(),
            )
        }
        None => ("NaN".into(), "NaN".into(), "0".into(), "none"),
    };
    let row = format!(
        "{},{cx},{cy},{},{:.4},{:.4},{:.4},{:.4},{area},{source},{}",
        csv_field(&stem),
        r.markers.len(),
        prepare_ms + t.detect_ms,
        t.kde_ms,
        t.segment_ms,
        prepare_ms + t.total_ms,
        r.skipped
    );
    Ok((row, r.contact.map(|c| c.centre)))
}

fn fmt(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "NaN".into()
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn stem_of(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

fn write_markers(path: &Path, prepared: &Prepared, markers: &[PointPx]) -> Result<(), String> {
    let err = |e: std::io::Error| format!("cannot write {}: {e}", path.display());
    let mut f = BufWriter::new(File::create(path).map_err(err)?);
    writeln!(f, "x,y").map_err(err)?;
    for m in markers {
        let p = prepared.to_input(*m);
        writeln!(f, "{:.3},{:.3}", p.x, p.y).map_err(err)?;
    }
    f.flush().map_err(err)
}

/// Decodes a PNG/JPEG into 8-bit grey, RGB or RGBA.
fn decode(path: &Path) -> Result<Decoded, String> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| format!("cannot open: {e}"))?
        .with_guessed_format()
        .map_err(|e| format!("cannot read: {e}"))?;
    let img = reader
        .decode()
        .map_err(|e| format!("cannot decode image: {e}"))?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    if width == 0 || height == 0 {
        return Err(format!("empty image ({width}x{height})"));
    }
    let (channels, data) = match img {
        image::DynamicImage::ImageLuma8(b) => (1, b.into_raw()),
        image::DynamicImage::ImageRgb8(b) => (3, b.into_raw()),
        image::DynamicImage::ImageRgba8(b) => (4, b.into_raw()),
        other => (1, other.to_luma8().into_raw()),
    };
    Ok(Decoded {
        width,
        height,
        channels,
        data,
    })
}

/// Expands directories into their image files (sorted). Returns the files
/// and the number of arguments that could not be listed.
fn expand(args: &[PathBuf]) -> (Vec<PathBuf>, usize) {
    let mut files = Vec::new();
    let mut failed = 0;
    for a in args {
        if a.is_dir() {
            match std::fs::read_dir(a) {
                Ok(entries) => {
                    let mut found: Vec<PathBuf> = entries
                        .filter_map(|e| e.ok().map(|e| e.path()))
                        .filter(|p| p.is_file() && is_image_name(p))
                        .collect();
                    found.sort();
                    files.extend(found);
                }
                Err(e) => {
                    eprintln!(
                        "dexitac analyze: {}: cannot list directory: {e}",
                        a.display()
                    );
                    failed += 1;
                }
            }
        } else {
            files.push(a.clone());
        }
    }
    (files, failed)
}

fn is_image_name(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
}

/// A one-line progress bar on stderr (only when stderr is a terminal and
/// there is more than one frame).
struct Progress {
    total: usize,
    enabled: bool,
}

impl Progress {
    fn new(total: usize) -> Self {
        Self {
            total,
            enabled: total > 1 && std::io::stderr().is_terminal(),
        }
    }

    fn show(&mut self, done: usize) {
        if !self.enabled || (done % 16 != 0 && done + 1 != self.total) {
            return;
        }
        let width = 30;
        let filled = done * width / self.total.max(1);
        eprint!(
            "\r[{}{}] {done}/{}",
            "#".repeat(filled),
            ".".repeat(width - filled),
            self.total
        );
    }

    fn clear(&self) {
        if self.enabled {
            eprint!("\r{}\r", " ".repeat(50));
        }
    }

    fn finish(&self) {
        if self.enabled {
            eprintln!("\r[{}] {}/{}", "#".repeat(30), self.total, self.total);
        }
    }
}
