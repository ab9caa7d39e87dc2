//! One module per `dexitac` command, plus the argument groups and helpers
//! several commands share ([`sources`]).

pub mod analyze;
pub mod bench_pipeline;
pub mod kinematics;
pub mod record;
pub mod run;
pub mod sensor;
pub mod sim;
pub mod sources;
pub mod synth_frames;
pub mod view;
