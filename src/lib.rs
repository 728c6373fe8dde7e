//! cpm: calibration of parallel manipulators. Facade over the workspace crates.
#![forbid(unsafe_code)]

pub use cpm_calib as calib;
pub use cpm_clearance as clearance;
pub use cpm_geometry as geometry;
/// File formats: robot descriptions, measurement CSV files, `calibration.json` (the
/// [`cpm-io`](cpm_io) crate, usable without the command line's dependencies).
pub use cpm_io as io;
pub use cpm_kinematics as kinematics;
pub use cpm_lm as lm;

pub mod cli;
pub mod fuzzing;
pub mod html;
pub mod output;
pub mod paper_report;
pub mod plot;
