//! The model room: what the calibration predicts and how.
//!
//! - [`measurement`] (re-exported here, so `cpm_calib::model::MeasurementModel` is the
//!   measurement model): commanded pose -> link lengths -> clearance -> forward kinematics ->
//!   sensor reading, and its Jacobian;
//! - `compose`: how the effects' channels compose into a prediction and its Jacobian;
//! - [`patterns`]: named physical error patterns (subspaces of the parameters in words);
//! - [`effects`]: the effect library (link offsets, scale, backlash, thermal drift, ...);
//! - the instrument models: [`instruments`] (the open [`Instrument`](instruments::Instrument)
//!   trait and the tracker), [`points`] (point targets) and [`tilts`] (inclinometers). They
//!   live here rather than in a room of their own because the model binds them and predicts
//!   through them on the one prediction path.
mod compose;
pub mod effects;
pub mod instruments;
pub mod measurement;
pub mod patterns;
pub mod points;
pub mod tilts;

pub use measurement::*;
