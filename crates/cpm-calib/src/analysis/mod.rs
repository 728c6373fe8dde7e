//! The analysis room: statistics of a campaign and of a fit.
//!
//! - [`identifiability`]: rank, singular values, blind directions, Cramér-Rao bounds;
//! - [`diagnostics`]: residual size (chi-square), whiteness, outliers, regressors;
//! - [`misfit`]: does the model fit? The chi-square verdict, by the rule of [`diagnostics`];
//! - [`accuracy`]: platform pose error over validation poses, nominal against calibrated;
//! - [`promise`]: what a compensation can promise: the pose error predicted at a target, with
//!   its 95 % band, from the fitted parameters' covariance.
pub mod accuracy;
pub mod diagnostics;
pub mod identifiability;
pub mod misfit;
pub mod promise;
