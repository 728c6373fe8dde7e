//! `cpm simulate` as a library function: a simulated measurement campaign (length-sensor
//! readings, tracker poses, tracker points of `[[target]]`s or inclinometer angles), marked
//! simulated in the file ([`simulate`] with [`SimulateOptions`]).
//!
//! The true machine is the robot with the errors of `truth` (another description: its
//! geometry, link reading models, sensor sockets and known effects), of the paper's Table 2,
//! and of `truth_effect` values; the plan says where the poses are.
//!
//! ```
//! use cpm_workflow::simulate::{simulate, SimulateOptions};
//! use cpm_workflow::Silent;
//!
//! let mut options = SimulateOptions::new("../../examples/hexapod_66.toml");
//! options.plan.random = Some(20);
//! options.truth = Some("../../examples/hexapod_66_truth.toml".into());
//! options.noise = Some("gaussian:2".into());
//! let job = simulate(&options, &Silent)?;
//! assert_eq!(job.campaign.poses.len(), 20);
//! assert!(job.text.contains("simulated"));
//! # Ok::<(), anyhow::Error>(())
//! ```
use std::path::{Path, PathBuf};

use crate::calib::simulate::{
    simulate_inclinometer_angles, simulate_tracker_points, simulate_tracker_poses,
    unsupported_machine_effect, TrackerSimulation,
};
use crate::calib::tilts::Inclinometer;
use crate::calib::{simulate_campaign, Campaign, Effect, Noise, SimulationOptions};
use crate::error::{input_error, render_error, usage_error};
use crate::geometry::{InstallationErrors, Pose};
use crate::io::{self, Robot};
use crate::plan::{PlanOptions, PlanSpec};
use crate::progress::{check_cancelled, Progress};
use crate::report::commands::SimulateSummary;
use crate::truth::truth_effect_for;

/// What the simulated campaign measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Measure {
    /// Length-sensor readings (every plan sensor at every pose).
    Lengths,
    /// Tracker pose measurements with the commanded link readings.
    Poses,
    /// Laser-tracker points of the description's `[[target]]`s (reflectors on the platform),
    /// every target at every pose, with the commanded link readings and pose.
    Points,
    /// Inclinometer angles of the description's `[[inclinometer]]`s (every axis of every
    /// instrument at every pose), with the commanded link readings and pose.
    Tilts,
}

impl Measure {
    /// The name on the command line and in the summary: `lengths`, `poses`, `points`, `tilts`.
    pub fn name(self) -> String {
        format!("{self:?}").to_lowercase()
    }
}

/// The options of `cpm simulate`. [`SimulateOptions::new`] gives the defaults.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SimulateOptions {
    /// The robot description.
    pub robot: PathBuf,
    /// The plan: where the poses come from (exactly one source); default: no source
    /// ([`PlanOptions::default`]). Its seed is also the noise's.
    #[serde(flatten)]
    pub plan: PlanOptions,
    /// The true machine: a robot description whose geometry (joints plus
    /// `[installation_errors_um]`), link reading models and sensor sockets differ from
    /// `robot`'s by the errors to simulate; default `None`.
    pub truth: Option<PathBuf>,
    /// The paper's Table 2 as the true installation errors (six links); default `false`.
    pub paper_table2: bool,
    /// True values of effects, `EFFECT=V1,V2,..` in the effect's unit, one per parameter;
    /// default empty.
    pub truth_effect: Vec<String>,
    /// The effects modelled (`Some(vec![])` for none; by name: a list, or `--effects`'
    /// text); default `None`: the description's `[calibration] effects`.
    #[serde(with = "crate::options::effects")]
    pub effects: Option<Vec<Effect>>,
    /// The noise: `none`, `uniform:HALF_WIDTH_UM` or `gaussian:SIGMA_UM` (urad for
    /// [`Measure::Tilts`]); default `None`: gaussian with the description's
    /// `[calibration] sensor_noise_um`, else none.
    pub noise: Option<String>,
    /// Orientation noise of simulated tracker poses, urad (standard deviation per axis);
    /// default 0.
    pub orientation_noise_urad: f64,
    /// With [`Measure::Poses`] or [`Measure::Points`]: the tracker's own frame,
    /// `x,y,z,roll,pitch,yaw` (mm, deg); default `None`: the base frame.
    pub tracker_frame: Option<String>,
    /// With [`Measure::Tilts`]: the base's tilt against gravity, `RX,RY` in degrees; default
    /// `None`: level.
    pub base_tilt_deg: Option<String>,
    /// What to measure; default [`Measure::Lengths`].
    pub measure: Measure,
    /// Where the data go (`-`: standard output); default `None`: the caller's choice.
    /// Checked by [`SimulateOptions::validate`]; the job itself writes nothing.
    pub out: Option<PathBuf>,
}

/// The largest simulated noise, um.
pub const MAX_NOISE_UM: f64 = 1000.0;

/// The largest simulated angle noise (inclinometers), urad: 0.1 rad, 5.7 deg.
pub const MAX_NOISE_URAD: f64 = 1e5;

impl SimulateOptions {
    /// The options for simulating `robot`, every other option at its default (give a plan).
    pub fn new(robot: impl Into<PathBuf>) -> Self {
        Self {
            robot: robot.into(),
            plan: PlanOptions::default(),
            truth: None,
            paper_table2: false,
            truth_effect: Vec::new(),
            effects: None,
            noise: None,
            orientation_noise_urad: 0.0,
            tracker_frame: None,
            base_tilt_deg: None,
            measure: Measure::Lengths,
            out: None,
        }
    }

    /// Every input file (an output may not replace one).
    pub fn inputs(&self) -> Vec<&Path> {
        std::iter::once(self.robot.as_path())
            .chain(self.truth.as_deref())
            .chain(self.plan.plan.as_deref())
            .collect()
    }

    /// Checks what needs no input file read (usage errors): the output file, the noise, the
    /// orientation noise, the tracker frame, the base tilt and the truth's sources.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.check_out()?;
        self.parse_noise()?;
        self.check_orientation_noise()?;
        self.parse_tracker_frame()?;
        self.parse_base_tilt()?;
        if self.paper_table2 && self.truth.is_some() {
            return Err(usage_error("--truth and --paper-table2 exclude each other"));
        }
        Ok(())
    }

    fn check_out(&self) -> anyhow::Result<()> {
        if let Some(out) = &self.out {
            crate::load::out_target("--out", out, &self.inputs())?;
        }
        Ok(())
    }

    /// The noise given (`None`: the description's).
    fn parse_noise(&self) -> anyhow::Result<Option<Noise>> {
        let Some(s) = &self.noise else {
            return Ok(None);
        };
        let noise = if self.measure == Measure::Tilts {
            parse_noise_in(s, "urad", MAX_NOISE_URAD, "5.7 deg")
        } else {
            parse_noise(s)
        };
        noise
            .map(Some)
            .map_err(|m| usage_error(format!("--noise {m}")))
    }

    fn check_orientation_noise(&self) -> anyhow::Result<()> {
        if !(self.orientation_noise_urad.is_finite()
            && (0.0..=1e5).contains(&self.orientation_noise_urad))
        {
            return Err(usage_error(
                "--orientation-noise-urad must be between 0 and 100000 (0.1 rad)",
            ));
        }
        Ok(())
    }

    /// The tracker's frame (`None`: the base frame).
    fn parse_tracker_frame(&self) -> anyhow::Result<Option<Pose>> {
        let Some(spec) = &self.tracker_frame else {
            return Ok(None);
        };
        if self.measure == Measure::Lengths {
            return Err(usage_error(
                "--tracker-frame needs --measure poses or --measure points",
            ));
        }
        let v: Vec<f64> = spec
            .split(',')
            .map(|x| x.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .filter(|v| v.len() == 6)
            .ok_or_else(|| {
                usage_error(format!(
                    "--tracker-frame {spec:?}: expected six numbers x,y,z,roll,pitch,yaw (mm, deg)"
                ))
            })?;
        if v[..3].iter().any(|x| x.abs() > 1e5) || v[3..].iter().any(|x| x.abs() > 360.0) {
            return Err(usage_error(format!(
                "--tracker-frame {spec:?}: at most 100 m and 360 deg"
            )));
        }
        Ok(Some(Pose::from_xyz_rpy_deg(
            [v[0], v[1], v[2]],
            [v[3], v[4], v[5]],
        )))
    }

    /// The base's tilt, rad about x and y (level: zero).
    fn parse_base_tilt(&self) -> anyhow::Result<[f64; 2]> {
        let Some(spec) = &self.base_tilt_deg else {
            return Ok([0.0; 2]);
        };
        if self.measure != Measure::Tilts {
            return Err(usage_error("--base-tilt-deg needs --measure tilts"));
        }
        let v: Vec<f64> = spec
            .split(',')
            .map(|x| x.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .filter(|v| v.len() == 2 && v.iter().all(|a| a.abs() <= 10.0))
            .ok_or_else(|| {
                usage_error(format!(
                    "--base-tilt-deg {spec:?}: expected two angles RX,RY in degrees, each within 10"
                ))
            })?;
        Ok([v[0].to_radians(), v[1].to_radians()])
    }

    /// A simulation that fails with `truth_effect` values given is a bad option value (a
    /// usage error naming the option); otherwise the error as it is.
    fn blame_truth(&self, e: impl Into<anyhow::Error>) -> anyhow::Error {
        let e = e.into();
        if self.truth_effect.is_empty() {
            e
        } else {
            usage_error(format!(
                "--truth-effect {}: the machine with these values cannot be simulated: {}",
                self.truth_effect.join(" --truth-effect "),
                render_error(&e)
            ))
        }
    }
}

/// Parses a noise specification (um).
pub fn parse_noise(spec: &str) -> Result<Noise, String> {
    parse_noise_in(spec, "um", MAX_NOISE_UM, "1 mm")
}

/// Parses a noise specification in an instrument's unit (`um`, or `urad` for angles), with
/// its largest plausible value (and that value in words).
pub fn parse_noise_in(spec: &str, unit: &str, max: f64, max_words: &str) -> Result<Noise, String> {
    let spec = spec.trim();
    if spec == "none" {
        return Ok(Noise::None);
    }
    let (kind, value) = spec.split_once(':').ok_or_else(|| {
        format!("{spec:?}: expected none, uniform:HALF_WIDTH_UM or gaussian:SIGMA_UM")
    })?;
    let v: f64 = value
        .trim()
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v >= 0.0)
        .ok_or_else(|| format!("{spec:?}: {value:?} is not a non-negative number of {unit}"))?;
    if v > max {
        return Err(format!(
            "{spec:?}: {} {unit} is implausibly large (over {} {unit} = {max_words}; the noise is in {unit})",
            crate::io::table::show(v, None),
            crate::io::table::show(max, None)
        ));
    }
    match kind.trim() {
        "uniform" => Ok(Noise::Uniform { half_width_um: v }),
        "gaussian" | "normal" => Ok(Noise::Gaussian { sigma_um: v }),
        other => Err(format!(
            "{spec:?}: unknown noise kind {other:?} (none, uniform, gaussian)"
        )),
    }
}

/// The noise in words, e.g. `gaussian 1 um`, `uniform +-10 um`.
pub fn describe_noise(noise: &Noise) -> String {
    match noise {
        Noise::None => "none".into(),
        Noise::Uniform { half_width_um } => format!("uniform +-{half_width_um} um"),
        Noise::Gaussian { sigma_um } => format!("gaussian {sigma_um} um"),
    }
}

/// The true machine: model effects and the full true parameter vector.
#[derive(Debug, Clone)]
pub struct Truth {
    /// The effects of the simulated machine (the modelled ones, then those the truth adds).
    pub effects: Vec<Effect>,
    /// The true parameters of the model of `effects` (installation errors first).
    pub params: Vec<f64>,
    /// The truth in words (the file's header and the summary).
    pub what: String,
    /// The true platform position of each of the robot's `[[target]]`s, mm (the truth's
    /// target of the same name, else the robot's).
    pub targets: Vec<nalgebra::Vector3<f64>>,
    /// Each of the robot's `[[inclinometer]]`s as it really is (the truth's of the same name,
    /// its axes and mount, else the robot's).
    pub inclinometers: Vec<Inclinometer>,
}

/// What the truth description `t` adds to `robot`: it replaces `installation`, matched
/// `targets` and `inclinometers`, pushes the effect values into `values`, and returns the
/// truth in words.
fn truth_file(
    robot: &Robot,
    t: &Robot,
    installation: &mut Vec<f64>,
    values: &mut Vec<(Effect, Vec<f64>)>,
    targets: &mut [nalgebra::Vector3<f64>],
    inclinometers: &mut [Inclinometer],
) -> anyhow::Result<String> {
    let n = robot.num_links();
    for (k, spec) in robot.description.inclinometers.iter().enumerate() {
        if let Some(tc) = t
            .description
            .inclinometers
            .iter()
            .find(|x| x.name == spec.name)
        {
            inclinometers[k] = Inclinometer::from_spec(tc);
        }
    }
    for (k, spec) in robot.description.targets.iter().enumerate() {
        if let Some(tt) = t.description.targets.iter().find(|x| x.name == spec.name) {
            targets[k] = tt.platform_mm.into();
        }
    }
    let diff = io::robot::truth_from_description(robot, t)
        .map_err(|m| input_error(format!("{}: {m}", t.file)))?;
    *installation = diff.installation_um.clone();
    if diff.has_link_terms() {
        values.push((Effect::LinkOffset, diff.link_offset_um.clone()));
        values.push((Effect::LinkScale, diff.link_scale_ppm.clone()));
    }
    // The truth's sensor sockets (its [[sensor]] tables, matched by name) where they
    // differ from the robot's: simulated as socket errors, so the readings are the
    // truth's. A robot sensor the truth does not declare keeps the robot's sockets.
    let sockets: Vec<f64> = robot
        .table
        .sensors
        .iter()
        .flat_map(
            |b| match t.table.sensors.iter().find(|a| a.name == b.name) {
                Some(a) => {
                    let (db, dp) = (a.base_mm - b.base_mm, a.platform_mm - b.platform_mm);
                    [db.x, db.y, db.z, dp.x, dp.y, dp.z].map(|v| v * 1e3)
                }
                None => [0.0; 6],
            },
        )
        .collect();
    if sockets.iter().any(|v| *v != 0.0) {
        values.push((Effect::SocketError, sockets));
    }
    // Known effect values of the truth beyond those of the robot are simulated too.
    let (robot_model, truth_model) = (robot.model(&[]), t.model(&[]));
    let mut known = Vec::new();
    // The library and any other effect (a pose map term) either description knows.
    let mut library = Effect::ALL.to_vec();
    for k in truth_model
        .known_effects
        .iter()
        .chain(&robot_model.known_effects)
    {
        if !library.contains(&k.effect) {
            library.push(k.effect);
        }
    }
    for e in library {
        let (a, b) = (truth_model.known(e), robot_model.known(e));
        if a.is_none() && b.is_none() {
            continue;
        }
        let need = e.num_params(n, robot.table.sensors.len());
        if a.is_some_and(|a| a.len() != need) {
            return Err(input_error(format!(
                "{}: [calibration.known_effects] {e} has {} values, the robot {need} parameters (sensors differ?)",
                t.file,
                a.map_or(0, |a| a.len())
            )));
        }
        let v: Vec<f64> = (0..need)
            .map(|k| a.map_or(0.0, |a| a[k]) - b.map_or(0.0, |b| b[k]))
            .collect();
        if v.iter().any(|x| *x != 0.0) {
            if values.iter().any(|(x, _)| *x == e) {
                return Err(input_error(format!(
                    "{}: [calibration.known_effects] {e} adds to the link reading models' difference; give one or the other",
                    t.file
                )));
            }
            known.push(e.name());
            values.push((e, v));
        }
    }
    Ok(if known.is_empty() {
        format!("{} (its geometry and link reading models)", t.file)
    } else {
        format!(
            "{} (its geometry, link reading models and known {})",
            t.file,
            known.join(", ")
        )
    })
}

/// The true machine of `options` on `robot`, with the `declared` effects modelled; `held`:
/// the truth description as loaded, in place of the file `options.truth` names.
pub fn truth(
    options: &SimulateOptions,
    held: Option<Robot>,
    robot: &Robot,
    declared: Vec<Effect>,
) -> anyhow::Result<Truth> {
    let n = robot.num_links();
    let mut effects = declared;
    let mut installation = vec![0.0; 6 * n];
    let mut values: Vec<(Effect, Vec<f64>)> = Vec::new();
    let mut what = "zero installation errors (nominal machine)".to_string();
    let mut targets: Vec<nalgebra::Vector3<f64>> = robot
        .description
        .targets
        .iter()
        .map(|t| t.platform_mm.into())
        .collect();
    let mut inclinometers: Vec<Inclinometer> = robot
        .description
        .inclinometers
        .iter()
        .map(Inclinometer::from_spec)
        .collect();
    if options.paper_table2 {
        if n != 6 {
            return Err(usage_error(format!(
                "--paper-table2 needs a six-link robot; {} has {n} links",
                robot.file
            )));
        }
        installation = InstallationErrors::paper_table2().to_vec_um();
        what = "the paper's Table 2".into();
    }
    let t = match (held, &options.truth) {
        (Some(t), _) => Some(t),
        (None, Some(path)) => Some(Robot::load(path)?),
        (None, None) => None,
    };
    if let Some(t) = t {
        what = truth_file(
            robot,
            &t,
            &mut installation,
            &mut values,
            &mut targets,
            &mut inclinometers,
        )?;
    }
    for s in &options.truth_effect {
        let (e, v) = truth_effect_for(s, robot)?;
        values.retain(|(x, _)| *x != e);
        values.push((e, v));
    }
    if !options.truth_effect.is_empty() {
        // Provenance: the header says which effects were simulated, with their values.
        what = format!(
            "{what}, plus --truth-effect {}",
            options.truth_effect.join(" --truth-effect ")
        );
    }
    for (e, _) in &values {
        if !effects.contains(e) {
            effects.push(*e);
        }
    }
    let model = robot.model(&effects);
    let mut params = installation;
    params.resize(model.num_params(), 0.0);
    for b in model.blocks() {
        if let Some(e) = b.effect {
            if let Some((_, v)) = values.iter().find(|(x, _)| *x == e) {
                params[b.offset..b.offset + b.len].copy_from_slice(v);
            }
        }
    }
    Ok(Truth {
        effects,
        params,
        what,
        targets,
        inclinometers,
    })
}

/// The tracker (position noise, orientation noise, seed, frame) of `cpm simulate`.
fn tracker(
    noise: &Noise,
    orientation_urad: f64,
    seed: u64,
    frame: Option<Pose>,
) -> TrackerSimulation {
    TrackerSimulation {
        position: *noise,
        orientation_sigma_urad: orientation_urad,
        seed,
        frame,
    }
}

/// Refuses a truth the true machine of [`simulate_tracker_points`] and
/// [`simulate_inclinometer_angles`] cannot act out (effects other than link offsets and
/// scales with nonzero values).
fn machine_truth(robot: &Robot, truth: &Truth, what: &str) -> anyhow::Result<()> {
    let model = robot.model(&truth.effects);
    match unsupported_machine_effect(&model, &truth.params) {
        Some(e) => Err(usage_error(format!(
            "--measure {what} simulates installation errors, link_offset, link_scale and compliance; the truth has {} values",
            e.name()
        ))),
        None => Ok(()),
    }
}

/// Laser-tracker points of every `[[target]]` at each of `poses` on the true machine
/// ([`simulate_tracker_points`]), in the tracker's frame `frame` (default: the base frame).
fn simulate_points(
    robot: &Robot,
    truth: &Truth,
    poses: &[Pose],
    noise: &Noise,
    seed: u64,
    frame: Option<Pose>,
) -> anyhow::Result<Campaign> {
    if truth.targets.is_empty() {
        return Err(usage_error(format!(
            "--measure points needs [[target]] tables (name, platform_mm) in {}",
            robot.file
        )));
    }
    machine_truth(robot, truth, "points")?;
    let model = robot.model(&truth.effects);
    let tracker = tracker(noise, 0.0, seed, frame);
    Ok(simulate_tracker_points(
        &model,
        &truth.params,
        &truth.targets,
        poses,
        &tracker,
    )?)
}

/// Inclinometer angles of every `[[inclinometer]]` axis at each of `poses` on the true machine
/// ([`simulate_inclinometer_angles`]), gravity's up tilted by `base_tilt` (rad about x and y).
fn simulate_tilts(
    robot: &Robot,
    truth: &Truth,
    poses: &[Pose],
    noise: &Noise,
    seed: u64,
    base_tilt: [f64; 2],
) -> anyhow::Result<Campaign> {
    if truth.inclinometers.is_empty() {
        return Err(usage_error(format!(
            "--measure tilts needs [[inclinometer]] tables (name, axes) in {}",
            robot.file
        )));
    }
    machine_truth(robot, truth, "tilts")?;
    let model = robot.model(&truth.effects);
    Ok(simulate_inclinometer_angles(
        &model,
        &truth.params,
        &truth.inclinometers,
        poses,
        *noise,
        seed,
        base_tilt,
    )?)
}

/// What [`simulate`] gives: the simulated campaign and its file's text (for the caller to
/// write: nothing is written).
#[derive(Debug)]
pub struct Simulated {
    /// The robot as read.
    pub robot: Robot,
    /// The true machine.
    pub truth: Truth,
    /// What was measured.
    pub measure: Measure,
    /// The noise simulated.
    pub noise: Noise,
    /// The noise in words (urad for inclinometer angles).
    pub noise_words: String,
    /// The random seed.
    pub seed: u64,
    /// The simulated campaign.
    pub campaign: Campaign,
    /// The data file (CSV, marked simulated).
    pub text: String,
}

impl Simulated {
    /// What was measured in words, e.g. `240 readings and 0 pose measurements`.
    pub fn measured(&self) -> String {
        let c = &self.campaign;
        if !c.tilt_measurements.is_empty() {
            format!(
                "{} inclinometer angles of {} inclinometers",
                c.tilt_measurements.len(),
                self.robot.description.inclinometers.len()
            )
        } else if c.point_measurements.is_empty() {
            format!(
                "{} readings and {} pose measurements",
                c.readings.len(),
                c.pose_measurements.len()
            )
        } else {
            format!(
                "{} point measurements of {} targets",
                c.point_measurements.len(),
                self.robot.description.targets.len()
            )
        }
    }

    /// The line `cpm simulate` prints after writing `out`.
    pub fn console_line(&self, out: &Path) -> String {
        format!(
            "SIMULATED: {} at {} poses (truth: {}; noise {}; seed {}) -> {}",
            self.measured(),
            self.campaign.poses.len(),
            self.truth.what,
            self.noise_words,
            self.seed,
            out.display()
        )
    }

    /// The summary of the data written to `out` (`--json`).
    pub fn summary(&self, out: &Path) -> SimulateSummary {
        let c = &self.campaign;
        SimulateSummary {
            effects: self
                .truth
                .effects
                .iter()
                .map(|e| e.name().to_string())
                .collect(),
            measure: self.measure.name(),
            noise: self.noise_words.clone(),
            out: out.display().to_string(),
            point_measurements: c.point_measurements.len(),
            pose_measurements: c.pose_measurements.len(),
            poses: c.poses.len(),
            readings: c.readings.len(),
            seed: self.seed,
            simulated: true,
            tilt_measurements: c.tilt_measurements.len(),
            truth: self.truth.what.clone(),
        }
    }
}

/// The campaign of `options.measure` at the plan's poses on the true machine, and its file's
/// text (whose header says `note`).
fn measure(
    options: &SimulateOptions,
    robot: &Robot,
    truth: &Truth,
    spec: &PlanSpec,
    noise: Noise,
    note: &str,
) -> anyhow::Result<(Campaign, String)> {
    let seed = options.plan.seed;
    Ok(match options.measure {
        Measure::Lengths => {
            let model = robot.model(&truth.effects);
            let sim = SimulationOptions {
                noise,
                repeats: 1,
                seed,
            };
            let skeleton = spec.skeleton();
            let c = simulate_campaign(&model, &truth.params, &skeleton, &sim)
                .map_err(|e| options.blame_truth(e))?;
            let text = io::write_readings(&c, robot, note);
            (c, text)
        }
        Measure::Poses => {
            let tracker = tracker(
                &noise,
                options.orientation_noise_urad,
                seed,
                options.parse_tracker_frame()?,
            );
            // Through the prediction path the fit uses: every effect of the truth acts as
            // `calibrate` and `validate` model it.
            let c = simulate_tracker_poses(
                &robot.model(&truth.effects),
                &truth.params,
                &spec.plan.poses,
                &spec.conditions,
                &tracker,
            )
            .map_err(|e| options.blame_truth(e))?;
            let text = io::write_pose_measurements(&c, robot, note);
            (c, text)
        }
        Measure::Points => {
            let frame = options.parse_tracker_frame()?;
            let mut c = simulate_points(robot, truth, &spec.plan.poses, &noise, seed, frame)
                .map_err(|e| options.blame_truth(e))?;
            for m in c.point_measurements.iter_mut() {
                m.time_s = spec.conditions.get(m.pose).and_then(|(t, _)| *t);
            }
            let text = io::points::write_point_measurements(&c, robot, note);
            (c, text)
        }
        Measure::Tilts => {
            let tilt = options.parse_base_tilt()?;
            let mut c = simulate_tilts(robot, truth, &spec.plan.poses, &noise, seed, tilt)
                .map_err(|e| options.blame_truth(e))?;
            for m in c.tilt_measurements.iter_mut() {
                m.time_s = spec.conditions.get(m.pose).and_then(|(t, _)| *t);
            }
            let text = io::points::write_tilt_measurements(&c, robot, note);
            (c, text)
        }
    })
}

/// `cpm simulate`: reads the robot (and the truth and plan files), builds the true machine
/// and the plan, and simulates the campaign.
pub fn simulate(options: &SimulateOptions, progress: &dyn Progress) -> anyhow::Result<Simulated> {
    simulate_in(options, crate::sources::InMemory::none(), progress)
}

/// [`simulate`] with the robot, the truth and the plan's poses held in memory (the robots as
/// loaded, the poses as values: see [`InMemory`](crate::sources::InMemory)) in place of the files the
/// options name.
pub fn simulate_in(
    options: &SimulateOptions,
    mut held: crate::sources::InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Simulated> {
    options.check_out()?;
    if options.paper_table2 && (options.truth.is_some() || held.truth.is_some()) {
        return Err(usage_error("--truth and --paper-table2 exclude each other"));
    }
    check_cancelled(progress)?;
    progress.stage("reading the robot description");
    let robot = held.robot_or_load(&options.robot, progress)?;
    let declared = crate::load::resolve_effects(options.effects.as_deref(), &robot)?;
    let noise = match options.parse_noise()? {
        Some(noise) => noise,
        None => match robot.sensor_noise_um() {
            Some(s) => Noise::Gaussian { sigma_um: s },
            None => Noise::None,
        },
    };
    options.check_orientation_noise()?;
    options.parse_tracker_frame()?;
    options.parse_base_tilt()?;
    let truth = truth(options, held.truth.take(), &robot, declared)?;
    check_cancelled(progress)?;
    progress.stage("building the plan");
    let lengths = options.measure == Measure::Lengths;
    let spec = crate::plan::build_plan_in(&options.plan, held.poses.as_deref(), &robot, lengths)?;
    check_cancelled(progress)?;
    progress.stage(&format!("simulating {} poses", spec.plan.poses.len()));
    // Inclinometer noise is in urad.
    let noise_words = match options.measure {
        Measure::Tilts => describe_noise(&noise).replace(" um", " urad"),
        _ => describe_noise(&noise),
    };
    let note = format!(
        "robot {}, truth {}, noise {}, seed {}",
        robot.file, truth.what, noise_words, options.plan.seed
    );
    let (campaign, text) = measure(options, &robot, &truth, &spec, noise, &note)?;
    check_cancelled(progress)?;
    Ok(Simulated {
        robot,
        truth,
        measure: options.measure,
        noise,
        noise_words,
        seed: options.plan.seed,
        campaign,
        text,
    })
}
