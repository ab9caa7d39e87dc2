//! One module per `dexitac` command: its arguments and its `run`. What
//! several commands share is in [`crate::shared`].

pub mod analyze;
pub mod bench_pipeline;
pub mod calibrate;
pub mod cameras;
pub mod completions;
pub mod faults;
pub mod fit_actuator;
pub mod record;
pub mod replay;
pub mod run;
pub mod sensor;
pub mod sim;
pub mod synth_frames;
pub mod view;
pub mod workspace;
