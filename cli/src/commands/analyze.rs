//! `dexitac analyze`: image files -> contact centres CSV.

use anyhow::anyhow;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use dexitac_tactile::area::WorkToInput;
use dexitac_tactile::calibrate;
use dexitac_tactile::displacement::ShiftTracker;
use dexitac_tactile::frame::{self, GreyFrame, Prepared};
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::tracking::PointIndex;
use dexitac_tactile::PointPx;

use crate::exit::Outcome;
use crate::shared::progress;
use crate::shared::sources::load_sensor_config;

/// Arguments of `dexitac analyze`.
#[derive(Debug, clap::Args)]
pub struct AnalyzeArgs {
    /// Rest (no-contact) frame; repeat for several.
    #[arg(
        long,
        value_name = "REST.png",
        required_unless_present = "rest_from_frames"
    )]
    rest: Vec<PathBuf>,
    /// No rest frame: estimate the rest from the frames themselves (the
    /// pixel-wise median of up to 63 evenly spaced frames finds the pins,
    /// the frame nearest to it gives their places). When every frame
    /// presses the same place (a set of taps), the rest is a pressed skin
    /// (the lightest or the median press): only deeper presses are seen.
    #[arg(long, conflicts_with = "rest")]
    rest_from_frames: bool,
    /// Use the given rest even when its marker lattice has holes. By
    /// default a rest with holes (a pressed rest, or the median image of
    /// taps) is replaced by one estimated from the frames, as
    /// --rest-from-frames, when there are at least 16 frames and that
    /// estimate has fewer holes and at least as many markers.
    #[arg(long, conflicts_with = "rest_from_frames")]
    keep_rest: bool,
    /// Sensor config (TOML); defaults to the paper's parameters.
    #[arg(long, value_name = "SENSOR.toml")]
    config: Option<PathBuf>,
    /// Output CSV, one row per frame.
    #[arg(long, value_name = "PRED.csv")]
    out: PathBuf,
    /// Write the detected markers of each frame to `DIR/<frame>.csv` (x,y).
    #[arg(long, value_name = "DIR")]
    markers_out: Option<PathBuf>,
    /// Write the displacement field of each frame to `DIR/<frame>.csv`: one
    /// row per rest marker, `rest_x,rest_y,x,y` (x, y empty when the marker
    /// is lost), input px. In a frame blurrier than the rest, x, y have the
    /// blur's own shift of the centroid taken off, and are empty where that
    /// shift is 1 px or more.
    #[arg(long, value_name = "DIR")]
    field_out: Option<PathBuf>,
    /// Do not look for markers: read each frame's markers from
    /// `DIR/<frame>.csv`, in the format `--field-out` writes (columns
    /// `rest_x,rest_y,x,y`, input px; x, y empty for a lost marker), and run
    /// the field, density and contact stages on them. Each row's rest place
    /// is matched to the nearest rest marker of the calibration within half
    /// a pitch, which is moved by the row's displacement (x - rest_x,
    /// y - rest_y); a row with rest_x, rest_y empty is a marker without a
    /// rest marker (in the density, not in the field). For another tracker's
    /// markers, or a simulator's true pin places. The frames are still read
    /// (their names and sizes).
    #[arg(long, value_name = "DIR")]
    field_in: Option<PathBuf>,
    /// Frames (PNG or JPEG files, or directories of them).
    #[arg(required = true, value_name = "FRAME")]
    frames: Vec<PathBuf>,
}

/// CSV header (the first eight columns are the interface; more may follow).
const HEADER: &str =
    "frame,cx,cy,n_markers,t_detect_ms,t_kde_ms,t_segment_ms,t_total_ms,area_mm2,source,skipped,shift_mm,shift_from_anchor_mm";

/// A rest with holes is replaced by one estimated from the frames only when
/// there are at least this many of them (fewer say little of the rest).
const HOLEY_REST_MIN_FRAMES: usize = 16;

/// Decodes and prepares rest frames of one size: the working frames, the
/// input size and the working-to-input map.
fn load_rests(
    paths: &[&PathBuf],
    params: &Params,
) -> anyhow::Result<(Vec<GreyFrame>, (usize, usize), WorkToInput)> {
    let mut prepared = Vec::new();
    let mut size = None;
    let mut map = WorkToInput::IDENTITY;
    for path in paths {
        let d = decode(path).map_err(|e| anyhow!("rest frame {}: {e}", path.display()))?;
        if let Some((w, h)) = size {
            if (w, h) != (d.width, d.height) {
                return Err(anyhow!(
                    "rest frame {}: size {}x{} differs from {w}x{h}",
                    path.display(),
                    d.width,
                    d.height
                ));
            }
        }
        size = Some((d.width, d.height));
        let p = frame::prepare_owned(d.width, d.height, d.channels, d.data, &params.frame)
            .map_err(|e| anyhow!("rest frame {}: {e}", path.display()))?;
        map = p.map();
        prepared.push(p.grey);
    }
    let size = size.ok_or_else(|| anyhow!("no rest frame"))?;
    Ok((prepared, size, map))
}

/// The rest estimated from `paths` (as `--rest-from-frames`), or `None`
/// when they cannot be read, differ in size from the rest (`size`), or
/// give no calibration (each reason logged).
fn estimate_rest(
    paths: &[&PathBuf],
    params: &Params,
    size: (usize, usize),
) -> Option<calibrate::Calibration> {
    let (frames, got, map) = load_rests(paths, params)
        .map_err(|e| tracing::info!("no rest estimated from the frames: {e}"))
        .ok()?;
    if got != size {
        tracing::info!(
            "no rest estimated from the frames: they are {}x{} px, the rest {}x{} px",
            got.0,
            got.1,
            size.0,
            size.1
        );
        return None;
    }
    calibrate::calibrate_from_frames(&frames, params, map)
        .map_err(|e| tracing::info!("no rest estimated from the frames: {e}"))
        .ok()
}

/// A decoded image file.
struct Decoded {
    width: usize,
    height: usize,
    channels: usize,
    data: Vec<u8>,
}

impl AnalyzeArgs {
    /// Runs `dexitac analyze`: [`Outcome::Negative`] when some frames could
    /// not be analysed (each is reported, the others are in the CSV).
    pub fn run(&self) -> anyhow::Result<Outcome> {
        let failed = run_inner(self)?;
        if failed > 0 {
            tracing::error!("dexitac analyze: {failed} frame(s) could not be analysed (see above)");
        }
        Ok(Outcome::from_ok(failed == 0))
    }
}

fn run_inner(args: &AnalyzeArgs) -> anyhow::Result<usize> {
    let mut params = load_sensor_config(args.config.as_deref())?;
    let (files, mut failed) = expand(&args.frames);
    let (mut cal, mut rest_size) = calibrate_rest(args, &params, &files)?;
    if let Some(finer) = calibrate::upscale_for(&cal, &params.frame, rest_size) {
        tracing::info!(
            "the rest's pins are {:.1} px apart, too close for the detector: working frame \
             magnified {:.2}x (set [frame] upscale to fix it; 1 never magnifies)",
            cal.pitch_px,
            finer.upscale.unwrap_or(1.0)
        );
        params.frame = finer;
        (cal, rest_size) = calibrate_rest(args, &params, &files)?;
    }
    let (rest_w, rest_h) = rest_size;
    if let Some(w) = cal.holey_rest_warning() {
        let try_frames =
            !(args.rest_from_frames || args.keep_rest || files.len() < HOLEY_REST_MIN_FRAMES);
        let estimate = try_frames
            .then(|| estimate_rest(&spaced(&files), &params, rest_size))
            .flatten();
        match estimate {
            Some(est) if est.fills_holes_of(&cal) => {
                tracing::warn!(
                    "{w}. Using the rest estimated from the frames instead ({} markers, {} such \
                     places; --keep-rest keeps the given one)",
                    est.rest_markers.len(),
                    est.gaps_px.len()
                );
                cal = est;
            }
            _ => tracing::warn!("{w}"),
        }
    }
    tracing::info!(
        "rest: {} markers, pitch {:.1} px, skin {}",
        cal.rest_markers.len(),
        cal.pitch_px,
        cal.surface.describe(&cal.rest_markers)
    );
    let pipeline = Pipeline::new(cal, params.clone());

    for (flag, dir) in [
        ("--markers-out", &args.markers_out),
        ("--field-out", &args.field_out),
    ] {
        if let Some(dir) = dir {
            empty_csv_dir(flag, dir)?;
        }
    }
    let out = File::create(&args.out)
        .map_err(|e| anyhow!("cannot create {}: {e}", args.out.display()))?;
    let mut out = csv::Writer::from_writer(BufWriter::new(out));
    let io_err = |e: csv::Error| anyhow!("writing {}: {e}", args.out.display());
    out.write_record(HEADER.split(',')).map_err(io_err)?;
    let labels = frame_labels(&files);
    let bar = progress::bar(files.len() as u64, "frames");
    let mut contacts = 0usize;
    let mut times_ms = Vec::with_capacity(files.len());
    // Centre shifts in the order the frames are given; the anchor is the
    // first contact centre.
    let mut shifts = ShiftTracker::new(params.frame.mm_per_px);
    for (path, label) in files.iter().zip(&labels) {
        bar.inc(1);
        match analyze_one(
            path,
            label,
            &pipeline,
            &params,
            (rest_w, rest_h),
            Outputs {
                markers: args.markers_out.as_deref(),
                field: args.field_out.as_deref(),
                field_in: args.field_in.as_deref(),
            },
        ) {
            Ok(Row {
                mut fields,
                centre,
                total_ms,
            }) => {
                contacts += usize::from(centre.is_some());
                times_ms.push(total_ms);
                let shift = shifts.update(centre);
                if centre.is_some() && shift.from_anchor_mm.is_none() {
                    shifts.hold_anchor();
                }
                let from_anchor = match (centre, shift.from_anchor_mm) {
                    (Some(_), None) => Some(0.0),
                    (_, d) => d,
                };
                let mm = |v: Option<f64>| v.map_or("NaN".to_string(), |v| format!("{v:.4}"));
                fields.push(mm(shift.frame_to_frame_mm));
                fields.push(mm(from_anchor));
                out.write_record(&fields).map_err(io_err)?
            }
            Err(msg) => {
                tracing::error!("dexitac analyze: {}: {msg}", path.display());
                failed += 1;
            }
        }
    }
    bar.finish_and_clear();
    out.flush()
        .map_err(|e| anyhow!("writing {}: {e}", args.out.display()))?;
    times_ms.sort_by(f64::total_cmp);
    let median_ms = times_ms.get(times_ms.len() / 2).copied();
    tracing::info!(
        "dexitac analyze: {} frame(s) analysed, {contacts} with a contact, {failed} failed, median {} per frame; wrote {}",
        times_ms.len(),
        median_ms.map_or("-".to_string(), |t| format!("{t:.2} ms")),
        args.out.display()
    );
    Ok(failed)
}

/// Up to [`calibrate::REST_FROM_FRAMES_MAX`] evenly spaced frames of
/// `files`.
fn spaced(files: &[PathBuf]) -> Vec<&PathBuf> {
    let n = files.len().min(calibrate::REST_FROM_FRAMES_MAX);
    (0..n).map(|k| &files[k * files.len() / n]).collect()
}

/// The calibration from the rest frames (or from the frames themselves,
/// with `--rest-from-frames`) and the rest's input size.
fn calibrate_rest(
    args: &AnalyzeArgs,
    params: &Params,
    files: &[PathBuf],
) -> anyhow::Result<(calibrate::Calibration, (usize, usize))> {
    let (rest_prepared, rest_size, map) = if args.rest_from_frames {
        load_rests(&spaced(files), params)?
    } else {
        load_rests(&args.rest.iter().collect::<Vec<_>>(), params)?
    };
    let cal = if args.rest_from_frames {
        calibrate::calibrate_from_frames(&rest_prepared, params, map)
    } else {
        calibrate::calibrate_mapped(&rest_prepared, params, map)
    }
    .map_err(|e| anyhow!("{e}"))?;
    Ok((cal, rest_size))
}

/// One analysed frame.
struct Row {
    /// The CSV fields before the shift columns.
    fields: Vec<String>,
    /// The contact centre, working px.
    centre: Option<PointPx>,
    /// Preparation and pipeline time, ms.
    total_ms: f64,
}

/// One frame -> one CSV row (without the shift columns).
fn analyze_one(
    path: &Path,
    label: &str,
    pipeline: &Pipeline,
    params: &Params,
    rest_size: (usize, usize),
    outputs: Outputs<'_>,
) -> anyhow::Result<Row> {
    let d = decode(path)?;
    if (d.width, d.height) != rest_size {
        return Err(anyhow!(
            "wrong size {}x{}: the rest frame is {}x{}",
            d.width,
            d.height,
            rest_size.0,
            rest_size.1
        ));
    }
    let t0 = std::time::Instant::now();
    let prepared = frame::prepare_owned(d.width, d.height, d.channels, d.data, &params.frame)
        .map_err(|e| anyhow!("{e}"))?;
    // Frame preparation (grey, crop, rescale) counts as part of detection.
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;
    let file = |dir: &Path| dir.join(format!("{}.csv", label.replace('/', "__")));
    let r = match outputs.field_in {
        Some(dir) => {
            let (places, unpaired) = read_field(&file(dir), &prepared, &pipeline.calibration)?;
            pipeline.run_on_field(&places, &unpaired)
        }
        None => pipeline.run(&prepared.grey),
    }
    .map_err(|e| anyhow!("{e}"))?;
    if let Some(dir) = outputs.markers {
        write_markers(&file(dir), &prepared, &r.markers.positions())?;
    }
    if let Some(dir) = outputs.field {
        write_field(
            &file(dir),
            &prepared,
            &pipeline.calibration.rest_markers,
            &r.field.displacement,
        )?;
    }
    if r.markers.is_empty() {
        tracing::warn!(
            "dexitac analyze: {}: no markers found (blank frame?)",
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
    let fields = vec![
        label.to_string(),
        cx,
        cy,
        r.markers.len().to_string(),
        format!("{:.4}", prepare_ms + t.detect_ms),
        format!("{:.4}", t.kde_ms),
        format!("{:.4}", t.segment_ms),
        format!("{:.4}", prepare_ms + t.total_ms),
        area,
        source.to_string(),
        r.skipped.to_string(),
    ];
    Ok(Row {
        fields,
        centre: r.contact.map(|c| c.centre),
        total_ms: prepare_ms + t.total_ms,
    })
}

fn fmt(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "NaN".into()
    }
}

/// A label per frame for the CSV and the marker files: the file stem, with
/// as many parent folders in front (`run2/frame_001`) as it takes to tell
/// apart frames of the same name from different folders.
fn frame_labels(files: &[PathBuf]) -> Vec<String> {
    let parts: Vec<Vec<String>> = files
        .iter()
        .map(|p| {
            let stem = p.file_stem().map_or_else(
                || p.display().to_string(),
                |s| s.to_string_lossy().into_owned(),
            );
            let parents = p
                .parent()
                .into_iter()
                .flat_map(|d| d.components().rev())
                .map(|c| c.as_os_str().to_string_lossy().into_owned());
            std::iter::once(stem).chain(parents).collect()
        })
        .collect();
    let label = |k: usize, depth: usize| {
        let p = &parts[k];
        let mut v: Vec<&str> = p
            .iter()
            .take(depth.min(p.len()))
            .map(String::as_str)
            .collect();
        v.reverse();
        v.join("/")
    };
    let mut depth = vec![1; files.len()];
    let max_depth = parts.iter().map(Vec::len).max().unwrap_or(1);
    for _ in 0..max_depth {
        let labels: Vec<String> = (0..files.len()).map(|k| label(k, depth[k])).collect();
        let mut changed = false;
        for k in 0..files.len() {
            let clash = labels
                .iter()
                .enumerate()
                .any(|(j, l)| *l == labels[k] && files[j] != files[k]);
            if clash && depth[k] < parts[k].len() {
                depth[k] += 1;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    // The same path given twice: number the repeats.
    let mut seen = std::collections::HashMap::<String, usize>::new();
    (0..files.len())
        .map(|k| {
            let l = label(k, depth[k]);
            let n = seen.entry(l.clone()).or_insert(0);
            *n += 1;
            if *n == 1 {
                l
            } else {
                format!("{l}#{n}")
            }
        })
        .collect()
}

/// Where [`analyze_one`] writes each frame's markers and displacement
/// field (`--markers-out`, `--field-out`), if anywhere.
#[derive(Clone, Copy)]
struct Outputs<'a> {
    markers: Option<&'a Path>,
    field: Option<&'a Path>,
    /// Where each frame's markers are read from instead (`--field-in`).
    field_in: Option<&'a Path>,
}

/// Creates `dir` for `flag`'s per-frame CSVs, or refuses one that holds
/// CSVs already: files of an earlier run would mix with these, and they may
/// be someone else's to delete.
fn empty_csv_dir(flag: &str, dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| anyhow!("cannot create {}: {e}", dir.display()))?;
    let old = std::fs::read_dir(dir)
        .map_err(|e| anyhow!("cannot list {}: {e}", dir.display()))?
        .filter_map(Result::ok)
        .filter(|e| e.path().extension().is_some_and(|x| x == "csv"))
        .count();
    if old > 0 {
        return Err(anyhow!(
            "{flag} {} already holds {old} CSV file(s): give an empty or new folder",
            dir.display()
        ));
    }
    Ok(())
}

/// One row per rest marker: its rest place and where the frame's field has
/// it (empty when lost or left out for blur), input px.
fn write_field(
    path: &Path,
    prepared: &Prepared,
    rest: &[PointPx],
    displacement: &[Option<PointPx>],
) -> anyhow::Result<()> {
    let rows = rest.iter().zip(displacement).map(|(&r, u)| {
        let [rx, ry] = input_xy(prepared, r);
        let [x, y] = u.map_or([String::new(), String::new()], |u| {
            input_xy(prepared, PointPx::new(r.x + u.x, r.y + u.y))
        });
        [rx, ry, x, y]
    });
    write_csv(path, ["rest_x", "rest_y", "x", "y"], rows)
}

/// A `--field-in` CSV (the `--field-out` format): per rest marker of
/// `cal`, its place in the frame (working px, `None` when lost or without a
/// row), and the markers with no rest place (rest_x, rest_y empty). A row's
/// rest place is the nearest rest marker's within half a pitch, and the
/// marker's place is that rest marker's moved by the row's displacement
/// (another tracker's rest places differ from the calibration's by its own
/// bias, which a displacement leaves out); rows whose rest place has none
/// (a pin the calibration did not see at rest) are left out, and so is the
/// farther of two rows for one rest marker.
fn read_field(
    path: &Path,
    prepared: &Prepared,
    cal: &calibrate::Calibration,
) -> anyhow::Result<(Vec<Option<PointPx>>, Vec<PointPx>)> {
    let at = |line: u64| format!("{} line {line}", path.display());
    let mut rdr = csv::Reader::from_path(path)
        .map_err(|e| anyhow!("no markers for this frame: {}: {e}", path.display()))?;
    let header = rdr
        .headers()
        .map_err(|e| anyhow!("{}: {e}", path.display()))?
        .clone();
    let column = |name: &str| {
        header.iter().position(|h| h.trim() == name).ok_or_else(|| {
            anyhow!(
                "{}: no column `{name}` (want rest_x,rest_y,x,y, as --field-out writes)",
                path.display()
            )
        })
    };
    let cols = [
        column("rest_x")?,
        column("rest_y")?,
        column("x")?,
        column("y")?,
    ];
    let map = prepared.map();
    let rest = &cal.rest_markers;
    let reach_px = 0.5 * cal.pitch_px;
    let index = PointIndex::spanning(rest, reach_px.max(1.0));
    let mut places: Vec<Option<PointPx>> = vec![None; rest.len()];
    let mut matched = vec![f64::INFINITY; rest.len()];
    let mut unpaired = Vec::new();
    let mut unmatched = 0usize;
    for (n, record) in rdr.records().enumerate() {
        let line = n as u64 + 2;
        let record = record.map_err(|e| anyhow!("{}: {e}", at(line)))?;
        let value = |c: usize| -> anyhow::Result<Option<f64>> {
            let v = record.get(c).unwrap_or("").trim();
            if v.is_empty() {
                return Ok(None);
            }
            let x: f64 = v
                .parse()
                .map_err(|_| anyhow!("{}: `{v}` is not a number", at(line)))?;
            if x.is_finite() {
                Ok(Some(x))
            } else {
                Err(anyhow!("{}: `{v}` is not a finite number", at(line)))
            }
        };
        let point = |cx: usize, cy: usize| -> anyhow::Result<Option<PointPx>> {
            match (value(cols[cx])?, value(cols[cy])?) {
                (Some(x), Some(y)) => Ok(Some(map.to_work(PointPx::new(x, y)))),
                (None, None) => Ok(None),
                _ => Err(anyhow!("{}: one coordinate of a point is empty", at(line))),
            }
        };
        let (from, to) = (point(0, 1)?, point(2, 3)?);
        match (from, to) {
            (None, Some(p)) => unpaired.push(p),
            (None, None) => {}
            (Some(r), p) => match index.nearest(rest, r, reach_px) {
                Some((k, d)) if d < matched[k] => {
                    // The row's displacement, from the calibration's place.
                    let moved =
                        p.map(|p| PointPx::new(rest[k].x + p.x - r.x, rest[k].y + p.y - r.y));
                    (places[k], matched[k]) = (moved, d);
                }
                // No rest marker, or a nearer row has it.
                _ => unmatched += 1,
            },
        }
    }
    if unmatched > 0 {
        tracing::debug!(
            "{}: {unmatched} row(s) without a rest marker of their own, left out",
            path.display()
        );
    }
    Ok((places, unpaired))
}

/// One row per marker: its centre, input px.
fn write_markers(path: &Path, prepared: &Prepared, markers: &[PointPx]) -> anyhow::Result<()> {
    let rows = markers.iter().map(|&m| input_xy(prepared, m));
    write_csv(path, ["x", "y"], rows)
}

/// Working-frame point `p` in input px, as the per-frame CSVs write it.
fn input_xy(prepared: &Prepared, p: PointPx) -> [String; 2] {
    let p = prepared.to_input(p);
    [format!("{:.3}", p.x), format!("{:.3}", p.y)]
}

/// A CSV of `header` and `rows` at `path`.
fn write_csv<const N: usize>(
    path: &Path,
    header: [&str; N],
    rows: impl Iterator<Item = [String; N]>,
) -> anyhow::Result<()> {
    let err = |e: csv::Error| anyhow!("cannot write {}: {e}", path.display());
    let mut f = csv::Writer::from_path(path).map_err(err)?;
    f.write_record(header).map_err(err)?;
    for row in rows {
        f.write_record(row).map_err(err)?;
    }
    f.flush()
        .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))
}

/// Decodes a PNG/JPEG into 8-bit grey, RGB or RGBA.
fn decode(path: &Path) -> anyhow::Result<Decoded> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| anyhow!("cannot open: {e}"))?
        .with_guessed_format()
        .map_err(|e| anyhow!("cannot read: {e}"))?;
    let img = reader
        .decode()
        .map_err(|e| anyhow!("cannot decode image: {e}"))?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    if width == 0 || height == 0 {
        return Err(anyhow!("empty image ({width}x{height})"));
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
                    tracing::info!(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_of_the_same_name_get_distinct_labels() {
        let files: Vec<PathBuf> = ["a/run1/f0.png", "a/run2/f0.png", "b/f1.png", "b/f1.png"]
            .iter()
            .map(PathBuf::from)
            .collect();
        assert_eq!(frame_labels(&files), ["run1/f0", "run2/f0", "f1", "f1#2"]);
    }
}
