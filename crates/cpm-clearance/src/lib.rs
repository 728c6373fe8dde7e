//! Link force statics and force-direction joint clearance correction (paper eq. 13-14).
//!
//! Each joint is a ball in a spherical socket with radial play `r` (the clearance radius).
//! Under load the ball sits against the socket wall in the direction of the link force, so a
//! link in tension reads longer, and one in compression shorter, by the clearances at its two
//! ends: `dl_i = (r_base + r_platform) * sign(t_i)` with `t_i` the axial force, tension
//! positive. Forces follow from the statics of the platform, `J1^T t = w` ([`statics`]).
//!
//! ```
//! use cpm_clearance::{ClearanceModel, Load, SignRule};
//! use cpm_geometry::JointTable;
//! let table = JointTable::paper_cubic();
//! let load = Load::default(); // 20 kg platform, gravity along -z
//! let model = ClearanceModel { radius_um: 10.0, rule: SignRule::Hard };
//! let dl = model.link_corrections_mm(&table, &table.home, &load).unwrap();
//! // The three z links carry the weight in compression: each reads 20 um short.
//! assert!((dl[0] + 0.020).abs() < 1e-12);
//! ```
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod clearance;
pub mod error;
pub mod statics;

pub use clearance::{ClearanceModel, SignRule};
pub use error::ClearanceError;
pub use statics::{link_forces_n, platform_wrench, Load};
