//! Inverse and forward kinematics of parallel manipulators, and their Jacobians.
//!
//! With `s_i = R p_i` the platform joint in base orientation, the link vector is
//! `q_i = t + s_i - b_i = l_i z_i` (paper eq. 3-5). Differentiating gives
//! `dl_i = [z_i^T, (s_i x z_i)^T] [dt; dw] + [-z_i^T, z_i^T R] [db_i; dp_i]`, i.e.
//! `dl = J1 dx + J2 de` (eq. 10-11) with the twist `dx = [dt; dw]` in the base frame and the
//! installation errors `de` ordered link by link, base then platform (see
//! [`cpm_geometry::errors`]).
//!
//! ```
//! use cpm_geometry::JointTable;
//! use cpm_kinematics::{forward, inverse_lengths, ForwardOptions};
//! let table = JointTable::paper_cubic();
//! let l = inverse_lengths(&table, &table.home);
//! assert!((l[0] - 354.0).abs() < 1e-12);
//! let (pose, report) = forward(&table, &l, &table.home, &ForwardOptions::default()).unwrap();
//! assert!(report.residual_mm < 1e-9);
//! assert!((pose.position_mm - table.home.position_mm).norm() < 1e-9);
//! ```
//!
//! Newton's forward kinematics finds the assembly mode whose basin holds its start; the
//! [`workspace`] module judges a pose where the machine is (length limits, J1's condition,
//! forward kinematics returning it) or along a path from home. [`linalg`] holds the SVD
//! (faer, exactly scaled) used for condition numbers and eq. 12.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod error;
pub mod fk;
pub mod ik;
pub mod jacobian;
pub mod linalg;
pub mod lu6;
pub mod sensor;
pub mod workspace;

pub use error::KinematicsError;
pub use fk::{
    forward, forward_from, forward_from_toward, ForwardOptions, ForwardReport, ForwardStart,
};
pub use ik::{inverse, inverse_lengths, inverse_lengths_into, LinkState};
pub use jacobian::{first_order_pose_error, j1, j1_of_six, j2};
pub use sensor::{sensor_length_mm, sensor_pose_gradient};
pub use workspace::{reachable_at, reachable_from_home, ReachableAt, Unreachable};
