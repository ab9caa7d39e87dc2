//! Figures the commands write: a simulated run's disturbance figure and
//! density heatmaps ([`sim_run`]), the tactile benchmark's Pareto plot
//! ([`pareto`]) and a finger's workspace views ([`workspace`]).

pub mod pareto;
pub mod sim_run;
pub mod workspace;
