//! `dexitac synth-frames`: seeded synthetic tactile frames with truth on disk,
//! to try `dexitac analyze` without a sensor.

use crate::exit::Outcome;
use crate::shared::out_dir::{self, Owned};
use anyhow::anyhow;
use std::path::{Path, PathBuf};

use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::synth::{self, Category};

/// Arguments of `dexitac synth-frames`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Output directory: rest.png, frames/NNNN.png, truth.csv.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Scene category: nominal, edge, large, small, two, shear, degraded,
    /// saturated, dropout, rounded_rect, no_contact; or a condition
    /// category (`synth::Category::CONDITIONS`): dim, overexposed, blurred,
    /// textured, dome, housing, two_colour, rim_clamped, tactip.
    #[arg(long, default_value = "nominal")]
    category: String,
    /// Number of frames.
    #[arg(long, default_value_t = 20)]
    frames: usize,
    /// Seed (sensor and scenes).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Image width, px.
    #[arg(long, default_value_t = 640)]
    width: usize,
    /// Image height, px.
    #[arg(long, default_value_t = 480)]
    height: usize,
}

impl SynthArgs {
    /// Runs the command.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        run_inner(self)?;
        Ok(Outcome::Success)
    }
}

fn run_inner(args: &SynthArgs) -> anyhow::Result<()> {
    let cat = Category::from_name(&args.category)
        .ok_or_else(|| anyhow!("unknown category {:?}", args.category))?;
    if !(32..=4096).contains(&args.width) || !(32..=4096).contains(&args.height) {
        return Err(anyhow!("width and height must be 32..=4096"));
    }
    // An earlier run's frames must not mix with these (analyze reads the
    // whole folder): the folder's PNGs are this command's.
    out_dir::prepare(
        "synth-frames",
        &args.out,
        &[Owned::File("rest.png"), Owned::File("truth.csv")],
    )?;
    let frames_dir = args.out.join("frames");
    out_dir::prepare(
        "synth-frames",
        &frames_dir,
        &[Owned::Pattern {
            prefix: "",
            suffix: ".png",
        }],
    )?;
    let sensor = cat.sensor(args.width, args.height, args.seed);
    save(
        &synth::rest_frame(&sensor, args.seed ^ 0xA5A5).image,
        &args.out.join("rest.png"),
    )?;
    let path = args.out.join("truth.csv");
    let csv_err = |e: csv::Error| anyhow!("cannot write {}: {e}", path.display());
    let mut truth = csv::Writer::from_path(&path).map_err(csv_err)?;
    truth
        .write_record(["frame", "cx", "cy", "n_contacts"])
        .map_err(csv_err)?;
    for k in 0..args.frames {
        let f =
            synth::render(&cat.scene(&sensor, args.seed.wrapping_mul(1000).wrapping_add(k as u64)));
        let name = format!("{k:04}");
        save(&f.image, &frames_dir.join(format!("{name}.png")))?;
        let (cx, cy) = f
            .contacts
            .first()
            .map_or(("NaN".into(), "NaN".into()), |c| {
                (format!("{:.3}", c.x), format!("{:.3}", c.y))
            });
        truth
            .write_record([name, cx, cy, f.contacts.len().to_string()])
            .map_err(csv_err)?;
    }
    truth
        .flush()
        .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?;
    tracing::info!(
        "dexitac synth-frames: {} {} frames in {}",
        args.frames,
        cat.name(),
        args.out.display()
    );
    Ok(())
}

fn save(img: &GreyFrame, path: &Path) -> anyhow::Result<()> {
    image::save_buffer(
        path,
        img.data(),
        img.width() as u32,
        img.height() as u32,
        image::ExtendedColorType::L8,
    )
    .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))
}
