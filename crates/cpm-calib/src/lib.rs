//! Installation-error calibration of parallel manipulators from length-sensor readings.
//!
//! The pipeline of Lim et al. (2002), made honest about what the data can identify:
//! 1. a [`MeasurementModel`]: commanded pose -> nominal-IK link lengths -> clearance-corrected
//!    effective lengths -> forward kinematics with the candidate joints -> sensor length;
//! 2. a [`Campaign`] of readings, measured or [`simulate()`]d (marked simulated);
//! 3. [`identify()`]: the eq. 16 cost minimised with `cpm-lm` in the identifiable subspace, with
//!    an analytic Jacobian by implicit differentiation of forward kinematics;
//! 4. [`identifiability()`]: rank, singular values, blind directions in words, Cramér-Rao bounds;
//! 5. [`accuracy()`]: platform pose error over validation poses, nominal against calibrated.
//!
//! ```
//! use cpm_calib::{campaign::paper_circle, identify, simulate, IdentifyOptions, MeasurementModel,
//!                 Plan, SimulationOptions};
//! use cpm_geometry::{InstallationErrors, JointTable};
//! let model = MeasurementModel::new(JointTable::paper_cubic());
//! let plan = Plan { poses: paper_circle(&model.nominal.home), sensors: vec![0] };
//! let truth = InstallationErrors::paper_table2().to_vec_um();
//! let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).unwrap();
//! let cal = identify(&model, &data, &IdentifyOptions::default()).unwrap();
//! // One sensor on a circle at constant orientation cannot identify 36 errors:
//! assert!(cal.identifiability.rank < 36);
//! assert!(cal.estimate_um.iter().all(|e| e.is_none()));
//! ```
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod accuracy;
pub mod campaign;
mod compose;
pub mod design;
pub mod diagnostics;
pub mod effects;
pub mod error;
pub mod identifiability;
pub mod identify;
pub mod implicit;
pub mod linalg;
pub mod misfit;
pub mod model;
pub mod paper;
pub mod refine;
pub mod registration;
pub mod simulate;

pub use accuracy::{accuracy, AccuracyReport, PoseErrorStats};
pub use campaign::{Campaign, Plan, Reading};
pub use effects::{Channel, Effect, EffectInput, EffectModel, EffectSettings, KnownEffect};
pub use error::CalibError;
pub use identifiability::{analyze, try_analyze, Identifiability, RankOptions};
pub use identify::{
    identifiability, identification_jacobian, identify, Calibration, IdentifyOptions,
    DOWNWEIGHT_LEVEL, MAX_DOWNWEIGHTED_SHARE,
};
pub use model::{MeasurementModel, ModelKind};
pub use refine::{refine, RefineOptions, Refinement};
pub use simulate::{simulate, simulate_campaign, Noise, SimulationOptions};

/// The examples of the crate's README.md, run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
