//! cpm: calibration of parallel manipulators. Facade over the workspace crates, and the `cpm`
//! command line (`docs/cli.md`).
//!
//! The crates, each usable alone:
//! - [`geometry`] (`cpm-geometry`): poses, joint tables, robot descriptions (TOML);
//! - [`kinematics`] (`cpm-kinematics`): inverse and forward kinematics, Jacobians;
//! - [`clearance`] (`cpm-clearance`): joint clearance and the statics that orient it;
//! - [`lm`] (`cpm-lm`): the Levenberg-Marquardt least-squares solver;
//! - [`calib`] (`cpm-calib`): measurement model, identification, identifiability, design;
//! - [`io`] (`cpm-io`): robot descriptions and measurement files, with errors that name the
//!   file, line and field;
//! - [`report`] (`cpm-report`): every report as typed data, rendered to JSON, Markdown and
//!   (with the `cli` feature) SVG figures and HTML.
//!
//! # A tour: one's own robot from files
//!
//! A robot description (`docs/robot-description.md`) and a readings file (`docs/formats.md`;
//! `examples/hexapod_66_readings.csv` holds 90 simulated readings of the 6-6 hexapod of
//! `examples/hexapod_66.toml`, labelled simulated in its first line). Read them, ask what the
//! campaign can identify, fit, and look at the result:
//!
//! ```
//! use cpm::calib::{identify, IdentifyOptions};
//! use cpm::io::{read_data_file, ReadOptions, Robot};
//! use std::path::Path;
//!
//! let robot = Robot::load(Path::new("examples/hexapod_66.toml"))?;
//! let data = read_data_file(Path::new("examples/hexapod_66_readings.csv"), &robot,
//!                           &ReadOptions::default())?;
//! // The model of this robot: its joints, sensors, clearance and load as declared.
//! let model = robot.model(&robot.declared_effects()?);
//!
//! // Before fitting: which of the 36 installation errors can these readings determine, and
//! // how well (Cramér-Rao bounds for the declared sensor noise, per um without one)?
//! let noise_um = robot.sensor_noise_um().unwrap_or(1.0);
//! let id = cpm::calib::identifiability(&model, &data.campaign, noise_um, &Default::default())?;
//! println!("{}", id.summary());
//!
//! let cal = identify(&model, &data.campaign, &IdentifyOptions::default())?;
//! println!("solver: {}", cal.solver.brief());
//! println!("residual RMS {:.2} um (noise {:.2} um{})", cal.residual_rms_um, cal.sigma_um,
//!          if cal.sigma_estimated { ", estimated from the residual" } else { "" });
//! for (k, (e, s)) in cal.estimate_um.iter().zip(&cal.std_um).enumerate().take(6) {
//!     match (e, s) {
//!         (Some(e), Some(s)) => println!("parameter {k}: {e:.1} +- {s:.1} um"),
//!         _ => println!("parameter {k}: not determined by these data"),
//!     }
//! }
//! assert!(cal.simulated); // the readings were simulated, and the result says so
//! assert_eq!(cal.identifiability.num_params, 36);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! `cpm calibrate --robot examples/hexapod_66.toml --data examples/hexapod_66_readings.csv
//! --out cal/` does the same and writes `calibration.json`, `report.md`, `report.html` and
//! `calibrated.toml`.
#![forbid(unsafe_code)]

pub use cpm_calib as calib;
pub use cpm_clearance as clearance;
pub use cpm_geometry as geometry;
/// File formats: robot descriptions, measurement CSV files, `calibration.json` (the
/// [`cpm-io`](cpm_io) crate, usable without the command line's dependencies).
pub use cpm_io as io;
pub use cpm_kinematics as kinematics;
pub use cpm_lm as lm;
/// The reports (the [`cpm-report`](cpm_report) crate): typed values rendered to JSON and
/// Markdown; with the `cli` feature also to SVG figures (`report::figures`) and HTML
/// (`report::html`).
pub use cpm_report as report;

#[cfg(feature = "cli")]
pub mod cli;
#[cfg(feature = "cli")]
pub mod fuzzing;
/// The jobs as library functions (the [`cpm-workflow`](cpm_workflow) crate): calibrate,
/// refine, validate with typed options, progress and cancellation. With the `workflow`
/// feature alone (`default-features = false, features = ["workflow"]`) they come without
/// the command line's crates.
#[cfg(feature = "workflow")]
pub use cpm_workflow as workflow;
/// Outputs that never destroy (the workflow layer's [`cpm_workflow::output`]).
#[cfg(feature = "workflow")]
pub use cpm_workflow::output;
#[cfg(feature = "cli")]
pub mod paper_report;
