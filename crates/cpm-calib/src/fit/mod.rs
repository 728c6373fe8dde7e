//! The fitting room: estimating parameters from a campaign.
//!
//! - [`identify`]: the rank-aware fit of the installation errors and effects (eq. 16, cpm-lm);
//! - [`registration`]: closed-form registration of tracker frames and rough reading offsets,
//!   done before any fit;
//! - [`formulation`]: nested or implicit, chosen by the campaign's size;
//! - [`refine`]: fit, study the residual, add the missing effect, refit;
//! - [`implicit`]: implicit-loop calibration, the actual poses as unknowns;
//! - [`noise`]: noise per kind of observation, estimated from a fit's residual, and the fit
//!   reweighed by it;
//! - [`session`]: a new measurement session re-registered against a machine held fixed;
//! - [`prior`]: the a-priori tolerances of the parameters, the prior of the fit.
pub mod formulation;
pub mod identify;
pub mod implicit;
pub mod noise;
pub mod prior;
pub mod refine;
pub mod registration;
pub mod session;
