//! cpm-workflow: the jobs of cpm as library functions, the layer between the calibration
//! crates and the `cpm` command line (which parses arguments into these options, runs the job,
//! commits its outputs and prints).
//!
//! - [`ingest`]: measurement files read with [`io`] (parsing only), then the tracker files
//!   among them registered and checked ([`register_tracker_files`](ingest::register_tracker_files))
//!   and each point file registered roughly ([`register_point_files`](ingest::register_point_files));
//! - [`load`]: the robot, the measurement files, the effects; the model for a campaign; a
//!   fit's loaded [`Inputs`](load::Inputs); committing a result directory;
//! - [`fit`]: [`calibrate`](fit::calibrate) with [`CalibrateOptions`](fit::CalibrateOptions);
//! - [`staging`]: what every fit stages beside its report (figures, `residuals.csv`,
//!   `calibrated.toml` and its read-back check), shared by `calibrate` and `refine` (no job
//!   imports another job's staging: `.ci/command_imports.py`);
//! - [`sources`]: the measurements and robots a caller holds in memory ([`sources::Source`],
//!   [`sources::InMemory`]), read and registered as files are;
//! - [`memory`]: [`calibrate`](memory::calibrate) a campaign held in memory (the robot
//!   as loaded, measurements already read, or given as values: [`io::rows`]), for the Python
//!   binding;
//! - [`refine`]: [`refine`](refine::refine) with [`RefineOptions`](refine::RefineOptions);
//! - [`validate`]: [`validate`](validate::validate) held-out data, and
//!   [`check_compensation`](validate::check_compensation);
//! - [`identifiability`]: [`identifiability`](identifiability::identifiability) of a campaign
//!   or a plan ([`plan`]: [`build_plan`](plan::build_plan) with
//!   [`PlanOptions`](plan::PlanOptions));
//! - [`export`]: [`export`](export::export) a robot's settings for a controller;
//! - [`compensate`]: [`compensate`](compensate::compensate), the commands for target poses;
//! - [`simulate`]: [`simulate`](simulate::simulate) a measurement campaign with
//!   [`SimulateOptions`](simulate::SimulateOptions);
//! - [`options`]: the typed values of the options given as text (effects, robust loss,
//!   tolerances, held groups), parsed once for clap and for options by name;
//! - [`progress`]: the [`Progress`] trait (stages, notes, cancellation);
//! - [`error`]: the kinds of failure and the exit code each gives;
//! - [`output`]: outputs that never destroy (staged sets committed as one step).
//!
//! A job stages its files in memory and returns them with its report: nothing is written
//! until the caller commits, so a failed or cancelled job leaves no partial output.
//!
//! # Calibrate a campaign, then check the result on a later session
//!
//! What `cpm calibrate --robot R --data D --out cal/` and then `cpm validate --robot
//! cal/calibrated.toml --data LATER` do (both files simulated, and the reports say so):
//!
//! ```
//! use cpm_workflow::{fit, load, validate, Silent};
//! use std::path::PathBuf;
//!
//! let ex = |f: &str| PathBuf::from("../../examples").join(f);
//! let out = std::env::temp_dir().join(format!("cpm-workflow-doc-{}", std::process::id()));
//! let options = fit::CalibrateOptions::new(ex("hexapod_66.toml"),
//!                                          vec![ex("hexapod_66_readings.csv")], &out);
//! let job = fit::calibrate(&options, &Silent)?;
//! assert!(job.trouble().is_none(), "the fit converged");
//! println!("residual RMS {:.3} um", job.fitted.cal.residual_rms_um);
//! // Nothing is on disk until the staged set is committed (as one step).
//! let inputs = [ex("hexapod_66.toml"), ex("hexapod_66_readings.csv")];
//! let inputs: Vec<&std::path::Path> = inputs.iter().map(|p| p.as_path()).collect();
//! load::commit_dir(job.fitted.set, &out, &inputs, "calibrate", &Silent)?;
//!
//! // A later session: the calibrated robot against the nominal one it was fitted from.
//! let later = validate::ValidateOptions::new(out.join("calibrated.toml"),
//!                                            vec![ex("hexapod_66_later.csv")]);
//! let v = validate::validate(&later, &Silent)?;
//! println!("{}", v.report.console_line());
//! assert!(v.report.simulated);
//! assert!(v.report.calibrated.rms_um < v.report.reference.rms_um / 5.0);
//! # std::fs::remove_dir_all(&out)?;
//! # Ok::<(), anyhow::Error>(())
//! ```
#![forbid(unsafe_code)]

pub use cpm_calib as calib;
pub use cpm_geometry as geometry;
pub use cpm_io as io;
pub use cpm_kinematics as kinematics;
pub use cpm_report as report;

pub mod compensate;
pub mod design;
pub mod error;
pub mod export;
pub mod fit;
pub mod formulation;
pub mod gauges;
pub mod identifiability;
pub mod ingest;
pub mod load;
pub mod memory;
pub mod options;
pub mod output;
pub mod plan;
pub mod progress;
pub mod refine;
pub mod simulate;
pub mod sources;
pub mod staging;
pub mod truth;
pub mod validate;

pub use error::{Cancelled, ExitKind, JobError};
pub use progress::{Collect, Progress, Silent};
