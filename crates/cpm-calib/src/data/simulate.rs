//! Simulated campaigns: truth = nominal + installation errors, clearance, sensor noise.
//!
//! Every campaign made here has `simulated = true`, and every output built from it says so.
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::data::campaign::{Campaign, Plan};
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

    /// One draw of this noise, um.
    pub fn draw_um<R: Rng>(&self, rng: &mut R) -> f64 {
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

/// Simulates the tracker pose measurements of `skeleton` (its commanded poses, logged
/// commands, times and temperatures are kept; the measured poses are replaced) on the machine
/// whose true parameters are `truth_um`, through the prediction path the fit uses: every
/// effect of `model` (clearance, backlash, compliance, drift, pose maps, a known
/// `tracker_frame`, ...) acts as it does in [`predict`]. Each measured pose gets independent
/// noise: `position` per coordinate (um) and a Gaussian rotation of
/// `orientation_sigma_urad` per axis, both in the tracker's frame. Skeleton readings, if any,
/// are simulated as [`simulate_campaign`] does, with `position` as their noise.
///
/// ```
/// use cpm_calib::campaign::PoseMeasurement;
/// use cpm_calib::{simulate_pose_measurements, Campaign, MeasurementModel, Noise};
/// let model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
/// let home = model.nominal.home;
/// let skeleton = Campaign {
///     poses: vec![home],
///     pose_measurements: vec![PoseMeasurement { pose: 0, measured: home, time_s: None, temperature_c: None }],
///     ..Campaign::default()
/// };
/// let truth = vec![0.0; 36];
/// let c = simulate_pose_measurements(&model, &truth, &skeleton, Noise::None, 0.0, 1).unwrap();
/// assert!(c.simulated);
/// // The nominal machine at home, with only its joint clearance: within microns of home.
/// let d = (c.pose_measurements[0].measured.position_mm - home.position_mm).norm();
/// assert!(d < 0.05, "{d} mm");
/// ```
pub fn simulate_pose_measurements(
    model: &MeasurementModel,
    truth_um: &[f64],
    skeleton: &Campaign,
    position: Noise,
    orientation_sigma_urad: f64,
    seed: u64,
) -> Result<Campaign, CalibError> {
    if !(orientation_sigma_urad.is_finite() && orientation_sigma_urad >= 0.0) {
        return Err(CalibError::invalid(
            "orientation_sigma_urad",
            format!("{orientation_sigma_urad}: must be finite and non-negative"),
        ));
    }
    let options = SimulationOptions {
        noise: position,
        repeats: 1,
        seed,
    };
    // The readings (if any) as simulate_campaign makes them; the orientation residuals below
    // are taken against the identity, so that they are the predicted rotation itself.
    let mut campaign = simulate_campaign(model, truth_um, skeleton, &options)?;
    for m in campaign.pose_measurements.iter_mut() {
        m.measured = cpm_geometry::Pose::identity();
    }
    let exact = MeasurementModel {
        kind: crate::ModelKind::Exact,
        ..model.clone()
    };
    // Every component predicted: the skeleton's unmeasured components are measured here.
    campaign.unmeasured.clear();
    let prepared = Prepared::new(model, &campaign)?;
    let y = predict(&exact, &prepared, &campaign, truth_um, None)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed ^ 0x0074_7261_636b_6572);
    let orientation = Normal::new(0.0, orientation_sigma_urad).ok();
    for (q, m) in campaign.pose_measurements.iter_mut().enumerate() {
        let at = |a: usize| prepared.pose_rows[q][a].map_or(0.0, |o| y[o]);
        let position_mm = nalgebra::Vector3::new(at(0), at(1), at(2));
        let w = nalgebra::Vector3::new(at(3), at(4), at(5)) * 1e-3;
        let mut twist = nalgebra::Vector6::zeros();
        for a in 0..3 {
            twist[a] = position.draw_um(&mut rng) * 1e-3;
        }
        for a in 0..3 {
            twist[3 + a] = orientation.map_or(0.0, |d| d.sample(&mut rng)) * 1e-6;
        }
        m.measured =
            cpm_geometry::Pose::new(position_mm, cpm_geometry::rotation::exp(&w)).perturbed(&twist);
    }
    campaign.simulated = true;
    Ok(campaign)
}
