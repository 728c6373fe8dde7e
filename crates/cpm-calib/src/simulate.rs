//! Simulated campaigns: truth = nominal + installation errors, clearance, sensor noise.
//!
//! Every campaign made here has `simulated = true`, and every output built from it says so.
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::campaign::{Campaign, Plan};
use crate::model::{predict, Prepared};
use crate::{CalibError, MeasurementModel};

/// Sensor noise of a simulated reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Noise {
    /// No noise.
    None,
    /// Uniform in `[-half_width_um, +half_width_um]` (the paper: 10 um).
    Uniform {
        /// Half width, um.
        half_width_um: f64,
    },
    /// Gaussian with standard deviation `sigma_um`.
    Gaussian {
        /// Standard deviation, um.
        sigma_um: f64,
    },
}

impl std::fmt::Display for Noise {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Noise::None => write!(f, "none"),
            Noise::Uniform { half_width_um } => write!(f, "uniform +-{half_width_um} um"),
            Noise::Gaussian { sigma_um } => write!(f, "Gaussian, sigma {sigma_um} um"),
        }
    }
}

impl Noise {
    /// Standard deviation of one draw, um.
    pub fn sigma_um(&self) -> f64 {
        match *self {
            Noise::None => 0.0,
            Noise::Uniform { half_width_um } => half_width_um / 3f64.sqrt(),
            Noise::Gaussian { sigma_um } => sigma_um,
        }
    }

    fn draw_um<R: Rng>(&self, rng: &mut R) -> f64 {
        match *self {
            Noise::None => 0.0,
            Noise::Uniform { half_width_um } => {
                if half_width_um > 0.0 {
                    rng.random_range(-half_width_um..=half_width_um)
                } else {
                    0.0
                }
            }
            Noise::Gaussian { sigma_um } => Normal::new(0.0, sigma_um)
                .map(|d| d.sample(rng))
                .unwrap_or(0.0),
        }
    }
}

/// Options of a simulation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimulationOptions {
    /// Noise per reading. Default: the paper's uniform +-10 um.
    pub noise: Noise,
    /// Readings averaged per reported value. Default 1.
    pub repeats: usize,
    /// Random seed. Default 1.
    pub seed: u64,
}

impl Default for SimulationOptions {
    fn default() -> Self {
        Self {
            noise: Noise::Uniform {
                half_width_um: 10.0,
            },
            repeats: 1,
            seed: 1,
        }
    }
}

impl SimulationOptions {
    /// Standard deviation of one reported (averaged) reading, um.
    pub fn reading_sigma_um(&self) -> f64 {
        self.noise.sigma_um() / (self.repeats.max(1) as f64).sqrt()
    }
}

/// Simulates the readings of `plan` on the machine whose true parameters (installation
/// errors, then the model's effects) are `truth_um`, measured through `model` (its clearance,
/// load and effects act as the truth's).
pub fn simulate(
    model: &MeasurementModel,
    truth_um: &[f64],
    plan: &Plan,
    options: &SimulationOptions,
) -> Result<Campaign, CalibError> {
    simulate_campaign(model, truth_um, &plan.skeleton(), options)
}

/// Simulates new readings for an existing campaign (its poses, logged commands, times and
/// temperatures are kept; lengths are replaced).
pub fn simulate_campaign(
    model: &MeasurementModel,
    truth_um: &[f64],
    skeleton: &Campaign,
    options: &SimulationOptions,
) -> Result<Campaign, CalibError> {
    if options.repeats == 0 {
        return Err(CalibError::invalid("repeats", "must be at least 1"));
    }
    let mut campaign = skeleton.clone();
    for r in campaign.readings.iter_mut() {
        r.length_mm = 0.0;
    }
    let prepared = Prepared::new(model, &campaign)?;
    let exact = MeasurementModel {
        kind: crate::ModelKind::Exact,
        ..model.clone()
    };
    let y = predict(&exact, &prepared, &campaign, truth_um, None)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(options.seed);
    for (r, yk) in campaign.readings.iter_mut().zip(y) {
        let noise: f64 = (0..options.repeats)
            .map(|_| options.noise.draw_um(&mut rng))
            .sum::<f64>()
            / options.repeats as f64;
        r.length_mm = yk + noise * 1e-3;
    }
    campaign.simulated = true;
    Ok(campaign)
}
