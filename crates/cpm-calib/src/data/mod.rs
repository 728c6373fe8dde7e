//! The data room: campaigns and where they come from.
//!
//! - [`campaign`]: commanded poses and the readings taken at them;
//! - [`simulate`]: simulated campaigns (always marked simulated), tracker poses included;
//! - [`poses`]: general pose generators (random poses, workspace-filtered random poses) and
//!   J1's condition at a pose;
//! - [`sensors`]: the designed sensor sockets (16 gauges) many examples and tests use.
pub mod campaign;
pub mod poses;
pub mod sensors;
pub mod simulate;
