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
//! Beside length readings, a campaign may hold tracker poses, point targets ([`points`]),
//! inclinometer angles ([`tilts`]) and measurements of one's own [`Instrument`]
//! ([`instruments`]), all predicted through the one path the fit uses.
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
//!
//! # Module map
//!
//! The crate is in rooms by purpose: [`model`] (the measurement model, effects, instrument
//! models), [`fit`] (identification, registration, refinement, implicit loop, sessions, noise
//! per kind), [`analysis`] (identifiability, residual diagnostics, misfit, accuracy), [`data`]
//! (campaigns, simulation, pose generators), [`design`] (experiment design) and [`paper`] (the
//! reproduction of the paper only). Every module's path from before the rooms is kept
//! (`cpm_calib::identify`, `cpm_calib::misfit`, ...).
//!
//! # One's own robot from files
//!
//! A robot description (`docs/robot-description.md`) gives the model with the clearance and
//! load it declares ([`MeasurementModel::from_description`];
//! [`MeasurementModel::with_paper_clearance`] is the paper's 10 um and assumed load). The
//! `cpm-io` crate reads the measurement files (`docs/formats.md`): here the 90 simulated
//! readings of the 6-6 hexapod that `examples/` ships.
//!
//! ```
//! use cpm_calib::{identifiability, identify, IdentifyOptions, MeasurementModel, RankOptions};
//! use cpm_geometry::RobotDescription;
//! use std::path::Path;
//!
//! let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
//! let description = RobotDescription::load(examples.join("hexapod_66.toml"))?;
//! let model = MeasurementModel::from_description(&description)?;
//! assert_eq!(model.load.platform_mass_kg, 10.0); // as declared, not the paper's 20 kg
//!
//! let robot = cpm_io::Robot::from_description(description, "hexapod_66.toml")?;
//! let data = cpm_io::read_data_file(&examples.join("hexapod_66_readings.csv"), &robot,
//!                                   &cpm_io::ReadOptions::default())?;
//! assert_eq!(robot.model(&[]), model); // cpm-io builds the same model
//!
//! // What the campaign can determine (Cramér-Rao bounds per um of sensor noise) ...
//! let before = identifiability(&model, &data.campaign, 1.0, &RankOptions::default())?;
//! println!("{}", before.summary());
//! // ... and the fit.
//! let cal = identify(&model, &data.campaign, &IdentifyOptions::default())?;
//! println!("solver: {}", cal.solver.brief());
//! println!("residual RMS {:.2} um; {} of {} parameters determined", cal.residual_rms_um,
//!          cal.estimate_um.iter().flatten().count(), model.num_params());
//! assert!(cal.simulated);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![warn(missing_docs)]
#![forbid(unsafe_code)]

// The crate in rooms by purpose (see README.md's module map).
pub mod analysis;
pub mod data;
pub mod design;
pub mod error;
pub mod fit;
pub mod linalg;
pub mod model;
pub mod paper;

// Every module's path from before the rooms, kept.
pub use analysis::{accuracy, diagnostics, identifiability, misfit, promise};
pub use data::{campaign, simulate};
pub use fit::{identify, implicit, noise, prior, refine, registration, session};
pub use model::{effects, points, tilts};
/// Open instruments ([`model::instruments`]), with their simulation
/// ([`simulate::simulate_instruments`]) at its old path.
pub mod instruments {
    pub use crate::data::simulate::simulate_instruments;
    pub use crate::model::instruments::*;
}

pub use accuracy::{accuracy, AccuracyReport, PoseErrorStats};
pub use campaign::{
    Campaign, InstrumentMeasurement, Logged, ObservationKind, Plan, PointMeasurement, Reading,
    TiltMeasurement,
};
pub use effects::{Channel, Effect, EffectInput, EffectModel, EffectSettings, KnownEffect};
pub use error::CalibError;
pub use identifiability::{
    analyze, analyze_scaled, try_analyze, try_analyze_scaled, Identifiability, RankOptions,
    RankScaling,
};
pub use identify::{
    identifiability, identification_jacobian, identify, Calibration, IdentifyOptions, Tolerances,
    DOWNWEIGHT_LEVEL, MAX_DOWNWEIGHTED_SHARE, MAX_SET_ASIDE_ROUNDS, SET_ASIDE_SIGMAS,
};
pub use instruments::{Instrument, InstrumentInput};
pub use model::{MeasurementModel, ModelKind};
pub use prior::Determination;
pub use refine::{refine, AgainstCalibrate, RefineOptions, Refinement};
pub use simulate::{
    simulate, simulate_campaign, simulate_pose_measurements, Noise, SimulationOptions,
};

/// The examples of the crate's README.md, run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
