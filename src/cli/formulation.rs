//! `--formulation` of `cpm calibrate`: the workflow layer's choice
//! ([`cpm_workflow::formulation`]).
pub use cpm_workflow::formulation::*;
