//! `dexitac synth-frames`: seeded synthetic tactile frames with truth on disk,
//! to try `dexitac analyze` without a sensor.

use crate::exit::Outcome;
use anyhow::anyhow;
use std::fmt::Write as _;
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
    /// saturated, dropout, rounded_rect, no_contact.
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
    let cat = Category::ALL
        .into_iter()
        .find(|c| c.name() == args.category)
        .ok_or_else(|| anyhow!("unknown category {:?}", args.category))?;
    if !(32..=4096).contains(&args.width) || !(32..=4096).contains(&args.height) {
        return Err(anyhow!("width and height must be 32..=4096"));
    }
    let frames_dir = args.out.join("frames");
    std::fs::create_dir_all(&frames_dir)
        .map_err(|e| anyhow!("cannot create {}: {e}", frames_dir.display()))?;
    let sensor = cat.sensor(args.width, args.height, args.seed);
    save(
        &synth::rest_frame(&sensor, args.seed ^ 0xA5A5).image,
        &args.out.join("rest.png"),
    )?;
    let mut truth = String::from("frame,cx,cy,n_contacts\n");
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
        let _ = writeln!(truth, "{name},{cx},{cy},{}", f.contacts.len());
    }
    let path = args.out.join("truth.csv");
    std::fs::write(&path, truth).map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?;
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
