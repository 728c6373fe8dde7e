//! Simulated campaigns: truth = nominal + installation errors, clearance, sensor noise.
//!
//! Every campaign made here has `simulated = true`, and every output built from it says so.
//!
//! Length readings ([`simulate`], [`simulate_campaign`]) and tracker poses
//! ([`simulate_pose_measurements`], [`simulate_tracker_poses`]) go through the prediction path
//! the fit uses; tracker points ([`simulate_tracker_points`]) and inclinometer angles
//! ([`simulate_inclinometer_angles`]) through the true machine's forward kinematics
//! ([`reached_poses`]). These are the simulators `cpm simulate` runs.
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use cpm_geometry::Pose;
use nalgebra::Vector3;

use crate::data::campaign::{Campaign, Plan, PoseMeasurement};
use crate::model::{predict, Prepared};
use crate::tilts::Inclinometer;
use crate::{CalibError, Effect, MeasurementModel, PointMeasurement, TiltMeasurement};

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
    simulate_into(model, truth_um, plan.skeleton(), options)
}

/// Simulates new readings for an existing campaign (its poses, logged commands, times and
/// temperatures are kept; lengths are replaced).
pub fn simulate_campaign(
    model: &MeasurementModel,
    truth_um: &[f64],
    skeleton: &Campaign,
    options: &SimulationOptions,
) -> Result<Campaign, CalibError> {
    simulate_into(model, truth_um, skeleton.clone(), options)
}

/// [`simulate_campaign`] of a skeleton the caller gives away: its readings receive the
/// simulated lengths in place (no second copy of a campaign of millions of readings).
fn simulate_into(
    model: &MeasurementModel,
    truth_um: &[f64],
    mut campaign: Campaign,
    options: &SimulationOptions,
) -> Result<Campaign, CalibError> {
    if options.repeats == 0 {
        return Err(CalibError::invalid("repeats", "must be at least 1"));
    }
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

/// Simulates the instrument measurements of `skeleton` ([`Campaign::instrument_measurements`], of one's own
/// [`Instrument`](crate::instruments::Instrument)s)
/// on the machine whose true parameters are `truth` (readings too, as
/// [`simulate_campaign`] does), through the prediction path the fit
/// uses: each value gets Gaussian noise of its measurement's `sigma` (the options' noise
/// applies to the readings; its seed to both).
pub fn simulate_instruments(
    model: &MeasurementModel,
    truth: &[f64],
    skeleton: &Campaign,
    options: &SimulationOptions,
) -> Result<Campaign, CalibError> {
    let mut campaign = simulate_campaign(model, truth, skeleton, options)?;
    let exact = MeasurementModel {
        kind: crate::ModelKind::Exact,
        ..model.clone()
    };
    let prepared = Prepared::new(&exact, &campaign)?;
    let y = predict(&exact, &prepared, &campaign, truth, None)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(options.seed ^ 0x696e_7374);
    let mut k = campaign.first_instrument_observation();
    for m in campaign.instrument_measurements.iter_mut() {
        let noise = rand_distr::Normal::new(0.0, m.sigma)
            .map_err(|e| CalibError::invalid("instrument measurement sigma", e.to_string()))?;
        for v in m.values.iter_mut() {
            *v = y[k] + rand_distr::Distribution::sample(&noise, &mut rng);
            k += 1;
        }
    }
    campaign.simulated = true;
    Ok(campaign)
}

/// Settings of a simulated tracker ([`simulate_tracker_poses`], [`simulate_tracker_points`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerSimulation {
    /// Noise per position coordinate, um.
    pub position: Noise,
    /// Standard deviation of the Gaussian rotation per axis, urad (pose measurements only).
    pub orientation_sigma_urad: f64,
    /// Random seed.
    pub seed: u64,
    /// The tracker's own frame: maps base coordinates into the tracker's (`None`: the base
    /// frame).
    pub frame: Option<Pose>,
}

/// `p` (base coordinates) in the tracker's frame `frame`.
fn in_frame(frame: Option<&Pose>, p: Vector3<f64>) -> Vector3<f64> {
    frame.map_or(p, |f| f.rotation * p + f.position_mm)
}

/// Simulated tracker pose measurements at `poses` (with `conditions[j]` the time, s, and
/// temperature, deg C, of pose `j`) on the machine whose true parameters are `truth_um`: the
/// controller commands `model`'s nominal inverse kinematics (logged as the commanded lengths),
/// every effect of `model` acts as [`simulate_pose_measurements`] makes it act (the prediction
/// path the fit uses), and the tracker sees the pose plus noise, in its own frame
/// (`tracker.frame`).
///
/// ```
/// use cpm_calib::simulate::{simulate_tracker_poses, TrackerSimulation};
/// use cpm_calib::{MeasurementModel, Noise};
/// let model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
/// let home = model.nominal.home;
/// let shift = cpm_geometry::Pose::new(nalgebra::Vector3::new(1000.0, 0.0, 0.0),
///                                     nalgebra::Rotation3::identity());
/// let tracker = TrackerSimulation { position: Noise::None, orientation_sigma_urad: 0.0,
///                                   seed: 1, frame: Some(shift) };
/// let c = simulate_tracker_poses(&model, &vec![0.0; 36], &[home], &[(None, None)], &tracker)
///     .unwrap();
/// assert!(c.simulated);
/// assert_eq!(c.commanded_lengths_mm.as_ref().unwrap().len(), 1);
/// // In the tracker's frame, 1 m along x from the base frame (within the clearance's microns).
/// let d = c.pose_measurements[0].measured.position_mm - home.position_mm;
/// assert!((d.x - 1000.0).abs() < 0.05 && d.y.abs() < 0.05, "{d}");
/// ```
pub fn simulate_tracker_poses(
    model: &MeasurementModel,
    truth_um: &[f64],
    poses: &[Pose],
    conditions: &[(Option<f64>, Option<f64>)],
    tracker: &TrackerSimulation,
) -> Result<Campaign, CalibError> {
    if conditions.len() != poses.len() {
        return Err(CalibError::invalid(
            "conditions",
            format!("{} for {} poses", conditions.len(), poses.len()),
        ));
    }
    let skeleton = Campaign {
        poses: poses.to_vec(),
        commanded_lengths_mm: Some(
            poses
                .iter()
                .map(|p| cpm_kinematics::inverse_lengths(&model.nominal, p))
                .collect(),
        ),
        pose_measurements: poses
            .iter()
            .zip(conditions)
            .enumerate()
            .map(|(j, (p, c))| PoseMeasurement {
                pose: j,
                measured: *p,
                time_s: c.0,
                temperature_c: c.1,
            })
            .collect(),
        simulated: true,
        ..Campaign::default()
    };
    let mut c = simulate_pose_measurements(
        model,
        truth_um,
        &skeleton,
        tracker.position,
        tracker.orientation_sigma_urad,
        tracker.seed,
    )?;
    if let Some(f) = &tracker.frame {
        for m in c.pose_measurements.iter_mut() {
            m.measured = Pose::new(
                in_frame(Some(f), m.measured.position_mm),
                f.rotation * m.measured.rotation,
            );
        }
    }
    Ok(c)
}

/// The first effect of `model` whose true values in `truth_um` are not all zero and that
/// [`reached_poses`] cannot act out (any but link offsets and scales); `None` when there is
/// none.
pub fn unsupported_machine_effect(model: &MeasurementModel, truth_um: &[f64]) -> Option<Effect> {
    model.blocks().into_iter().find_map(|b| {
        let e = b.effect?;
        let nonzero = truth_um[b.offset..b.offset + b.len]
            .iter()
            .any(|v| *v != 0.0);
        (nonzero
            && !matches!(
                e,
                Effect::LinkOffset | Effect::LinkScale | Effect::Compliance
            ))
        .then_some(e)
    })
}

/// The poses the true machine reaches at `poses`, and the commanded lengths: the controller
/// commands `model`'s nominal inverse kinematics; the machine's lengths are those plus the
/// joint clearance shift, the model's known link effects and the link offsets and scales of
/// the truth; forward kinematics on the true joints gives the pose (moved by a known pose map).
/// Installation errors, link offsets and link scales are the truth this acts out; another
/// effect with nonzero true values is an error ([`unsupported_machine_effect`]).
///
/// ```
/// use cpm_calib::simulate::reached_poses;
/// use cpm_calib::MeasurementModel;
/// let model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
/// let home = model.nominal.home;
/// let (reached, commanded) = reached_poses(&model, &vec![0.0; 36], &[home]).unwrap();
/// // The nominal machine with its joint clearance: within microns of the commanded pose.
/// assert!((reached[0].position_mm - home.position_mm).norm() < 0.05);
/// assert_eq!(commanded[0].len(), 6);
/// ```
pub fn reached_poses(
    model: &MeasurementModel,
    truth_um: &[f64],
    poses: &[Pose],
) -> Result<(Vec<Pose>, Vec<Vec<f64>>), CalibError> {
    if let Some(e) = unsupported_machine_effect(model, truth_um) {
        return Err(CalibError::invalid(
            "truth",
            format!(
                "the machine acts out installation errors, link_offset, link_scale and compliance; the truth has {} values",
                e.name()
            ),
        ));
    }
    let n = model.nominal.num_links();
    let block = |which: Effect| {
        model
            .blocks()
            .into_iter()
            .find(|b| b.effect == Some(which))
            .map(|b| truth_um[b.offset..b.offset + b.len].to_vec())
    };
    let offset = block(Effect::LinkOffset).unwrap_or_else(|| vec![0.0; n]);
    let scale = block(Effect::LinkScale).unwrap_or_else(|| vec![0.0; n]);
    // Compliance: each link shortened by its force (the statics of the model's load).
    let compliance = block(Effect::Compliance);
    let true_table = model.table_with(&truth_um[..6 * n])?;
    let mut reached_all = Vec::with_capacity(poses.len());
    let mut commanded = Vec::new();
    let mut previous: Option<crate::effects::PoseContext> = None;
    for (j, p) in poses.iter().enumerate() {
        let cmd = cpm_kinematics::inverse_lengths(&model.nominal, p);
        let shift = model
            .clearance
            .link_corrections_mm(model.statics_table(), p, &model.load)
            .map_err(|source| CalibError::Clearance { pose: j, source })?;
        // The model's known link effects (a calibrated description's) act on the machine too.
        let ctx = model
            .pose_context(p, cmd.clone(), previous.as_ref(), None, None)
            .map_err(|source| CalibError::Clearance { pose: j, source })?;
        let known = model.known_link_shift_mm(&ctx, 0.0);
        let pose_map = model.known_pose_twist(&ctx, p, 0.0);
        let compliant: Vec<f64> = match &compliance {
            Some(c) => {
                let input = crate::effects::EffectInput {
                    context: &ctx,
                    commanded: p,
                    home: &model.nominal.home,
                    settings: &model.effect_settings,
                    t0_s: 0.0,
                };
                let m = Effect::Compliance.model();
                (0..n)
                    .map(|i| {
                        (0..c.len())
                            .map(|k| c[k] * m.link_coefficient(k, i, &input))
                            .sum()
                    })
                    .collect()
            }
            None => vec![0.0; n],
        };
        previous = Some(ctx);
        let eff: Vec<f64> = (0..n)
            .map(|i| {
                cmd[i]
                    + shift[i]
                    + known[i]
                    + offset[i] * 1e-3
                    + scale[i] * 1e-6 * cmd[i]
                    + compliant[i]
            })
            .collect();
        let (reached, _) = cpm_kinematics::forward(&true_table, &eff, p, &model.fk)
            .map_err(|source| CalibError::Kinematics { pose: j, source })?;
        // A known pose error map moves the platform from where the lengths put it.
        reached_all.push(reached.perturbed(&pose_map));
        commanded.push(cmd);
    }
    Ok((reached_all, commanded))
}

/// Simulated laser-tracker points of targets at the true platform positions `targets_mm` at
/// each of `poses` on the true machine ([`reached_poses`]): every target at every pose, plus
/// `tracker.position` noise on each coordinate, in the tracker's frame `tracker.frame`, with
/// the commanded lengths logged (`tracker.orientation_sigma_urad` is not used).
///
/// ```
/// use cpm_calib::simulate::{simulate_tracker_points, TrackerSimulation};
/// use cpm_calib::{MeasurementModel, Noise};
/// let model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
/// let home = model.nominal.home;
/// let tracker = TrackerSimulation { position: Noise::Gaussian { sigma_um: 5.0 },
///                                   orientation_sigma_urad: 0.0, seed: 3, frame: None };
/// let targets = [nalgebra::Vector3::new(50.0, 0.0, 10.0), nalgebra::Vector3::zeros()];
/// let c = simulate_tracker_points(&model, &vec![0.0; 36], &targets, &[home, home], &tracker)
///     .unwrap();
/// assert_eq!(c.point_measurements.len(), 4);
/// let p = c.point_measurements[1].measured_mm; // the second target at the first pose
/// assert!((p - home.transform_point(&targets[1])).norm() < 0.1);
/// ```
pub fn simulate_tracker_points(
    model: &MeasurementModel,
    truth_um: &[f64],
    targets_mm: &[Vector3<f64>],
    poses: &[Pose],
    tracker: &TrackerSimulation,
) -> Result<Campaign, CalibError> {
    let (reached, commanded) = reached_poses(model, truth_um, poses)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(tracker.seed);
    let mut c = Campaign {
        simulated: true,
        poses: poses.to_vec(),
        ..Campaign::default()
    };
    for (j, reached) in reached.iter().enumerate() {
        for (k, t) in targets_mm.iter().enumerate() {
            let mut p = reached.transform_point(t);
            for a in 0..3 {
                p[a] += tracker.position.draw_um(&mut rng) * 1e-3;
            }
            c.point_measurements.push(PointMeasurement {
                pose: j,
                target: k,
                session: 0,
                measured_mm: in_frame(tracker.frame.as_ref(), p),
                time_s: None,
            });
        }
    }
    c.commanded_lengths_mm = Some(commanded);
    Ok(c)
}

/// Simulated inclinometer angles of every axis of every instrument of `inclinometers` (as they
/// really are: axes and mount) at each of `poses` on the true machine ([`reached_poses`]):
/// `asin(up . a)` with the axis on the reached orientation and gravity's up
/// ([`nominal_up`](crate::tilts::nominal_up)) tilted by `base_tilt` (rad about x and y), plus
/// `noise` (its um read as urad), with the commanded lengths logged.
///
/// ```
/// use cpm_calib::simulate::simulate_inclinometer_angles;
/// use cpm_calib::tilts::Inclinometer;
/// use cpm_calib::{MeasurementModel, Noise};
/// let model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
/// let inc = Inclinometer { name: "i".into(), axes: vec![nalgebra::Vector3::x()],
///                          mount: nalgebra::Rotation3::identity() };
/// let home = model.nominal.home;
/// let c = simulate_inclinometer_angles(&model, &vec![0.0; 36], &[inc], &[home], Noise::None,
///                                      1, [0.0, 0.0]).unwrap();
/// // The platform's x axis at home is level, within the clearance's tilt.
/// assert!(c.tilt_measurements[0].angle_mrad.abs() < 0.1);
/// ```
pub fn simulate_inclinometer_angles(
    model: &MeasurementModel,
    truth_um: &[f64],
    inclinometers: &[Inclinometer],
    poses: &[Pose],
    noise: Noise,
    seed: u64,
    base_tilt: [f64; 2],
) -> Result<Campaign, CalibError> {
    let (reached, commanded) = reached_poses(model, truth_um, poses)?;
    let up = nalgebra::Rotation3::new(Vector3::new(base_tilt[0], base_tilt[1], 0.0))
        * crate::tilts::nominal_up(model);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut c = Campaign {
        simulated: true,
        poses: poses.to_vec(),
        ..Campaign::default()
    };
    for (j, reached) in reached.iter().enumerate() {
        for (i, inc) in inclinometers.iter().enumerate() {
            for (axis, n) in inc.axes.iter().enumerate() {
                let a = reached.rotation * (inc.mount * n);
                let angle = up.dot(&a).clamp(-1.0, 1.0).asin() + noise.draw_um(&mut rng) * 1e-6;
                c.tilt_measurements.push(TiltMeasurement {
                    pose: j,
                    inclinometer: i,
                    axis,
                    session: 0,
                    angle_mrad: angle * 1e3,
                    time_s: None,
                });
            }
        }
    }
    c.commanded_lengths_mm = Some(commanded);
    Ok(c)
}
