//! Poses, rotations, joint tables and installation errors of parallel manipulators.
//!
//! Conventions used across `cpm`:
//! - positions and lengths in millimetres (`_mm`), installation errors in micrometres (`_um`)
//!   where they cross a boundary, angles in radians inside and degrees in files (`_deg`);
//! - orientation `R = Rz(yaw) * Ry(pitch) * Rx(roll)`: rotate about the fixed x axis by roll,
//!   then about the fixed y axis by pitch, then about the fixed z axis by yaw (the paper's eq. 1
//!   as its text describes it; see [`rotation`]).
//!
//! Robots are described in TOML files ([`description`], `docs/robot-description.md`);
//! `examples/paper_cubic.toml` is the paper's cube, `examples/hexapod_66.toml` a general 6-6
//! Gough-Stewart platform.
//!
//! ```
//! use cpm_geometry::{JointTable, InstallationErrors, Pose};
//! let nominal = JointTable::paper_cubic();
//! assert_eq!(nominal.num_links(), 6);
//! let actual = InstallationErrors::paper_table2().apply(&nominal).unwrap();
//! // Link 1's base joint moved by (13.7, 1.2, 89.4) um.
//! let d = actual.links[0].base_mm - nominal.links[0].base_mm;
//! assert!((d.z - 0.0894).abs() < 1e-12);
//! let home = nominal.home;
//! assert_eq!(home.position_mm.z, 410.0);
//! # let _ = Pose::identity();
//! ```
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod description;
pub mod error;
pub mod errors;
pub mod joints;
pub mod pose;
pub mod rotation;
#[cfg(feature = "proptest")]
pub mod strategies;

pub use description::RobotDescription;
pub use error::GeometryError;
pub use errors::{InstallationErrors, PlatformSign, Side};
pub use joints::{JointTable, Link, Sensor};
pub use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
pub use pose::Pose;
