//! Workspace volume against run time: for each finger and point, the
//! voxel-occupancy volume at halving voxel edges (grid from
//! `Grid::for_gap`), the measured neighbour gap, the Richardson
//! extrapolation `2 V(v) - V(2v)` and the time. Numbers recorded in
//! gripper/KINEMATICS.md.
//!
//! `cargo run --release -p dexitac --example workspace_convergence [VOXELS_MM...]`

use std::time::Instant;

use dexitac_gripper::configuration::{FingerType, Preset};
use dexitac_gripper::workspace::{volume, Grid, TipPoint};

fn main() {
    let voxels_mm: Vec<f64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let voxels_mm = if voxels_mm.is_empty() {
        vec![8.0, 4.0, 2.0, 1.5]
    } else {
        voxels_mm
    };
    let base = Preset::PinchGrip.config();
    println!("| point | finger | voxel mm | grid rot x dex^3 | samples | max gap mm | volume mm^3 | 2V(v)-V(2v) mm^3 | time s |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for (point, name) in [
        (TipPoint::JointEnd, "joint-end"),
        (TipPoint::Fingertip, "fingertip"),
    ] {
        let config = point.config(&base);
        for finger in [FingerType::RotDex, FingerType::DexRot] {
            for &v in &voxels_mm {
                let grid = Grid::for_gap(&config, v);
                let started = Instant::now();
                let fine = match volume(&config, finger, grid, v) {
                    Ok(r) => r,
                    Err(e) => {
                        println!(
                            "| {name} | {} | {v} | {}x{}^3 | - | - | {e} | - | - |",
                            finger.name(),
                            grid.rot_levels,
                            grid.dex_levels
                        );
                        continue;
                    }
                };
                let time_s = started.elapsed().as_secs_f64();
                let extrapolated =
                    volume(&config, finger, Grid::for_gap(&config, 2.0 * v), 2.0 * v)
                        .map(|c| format!("{:.0}", 2.0 * fine.volume_mm3 - c.volume_mm3))
                        .unwrap_or_else(|e| e.to_string());
                println!(
                    "| {name} | {} | {v} | {}x{}^3 | {} | {:.2} | {:.0} | {extrapolated} | {time_s:.2} |",
                    finger.name(),
                    grid.rot_levels,
                    grid.dex_levels,
                    fine.samples,
                    fine.max_neighbour_gap_mm,
                    fine.volume_mm3,
                );
            }
        }
    }
}
