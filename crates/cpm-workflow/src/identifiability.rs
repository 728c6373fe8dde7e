//! `cpm identifiability` as a library function: what a campaign (or a plan, before measuring)
//! can identify: rank, singular values, the parameters the data determine, Cramér-Rao bounds,
//! and at a noise, against the a-priori tolerances, which directions a fit would hold near
//! nominal ([`identifiability`] with [`IdentifiabilityOptions`]). It writes no file.
//!
//! ```
//! use cpm_workflow::identifiability::{identifiability, IdentifiabilityOptions};
//! use cpm_workflow::Silent;
//!
//! let mut options = IdentifiabilityOptions::new("../../examples/hexapod_66.toml");
//! options.plan.random = Some(40);
//! let job = identifiability(&options, &Silent)?;
//! assert_eq!(job.doc.source, "plan");
//! assert!(job.ident.rank <= job.ident.num_params);
//! println!("{}", serde_json::to_string_pretty(&job.doc)?);
//! # Ok::<(), anyhow::Error>(())
//! ```
use std::path::{Path, PathBuf};

use crate::calib::{Identifiability, MeasurementModel, RankOptions};
use crate::error::usage_error;
use crate::io::Robot;
use crate::plan::PlanOptions;
use crate::progress::{check_cancelled, Progress};
use crate::report::fit::{IdentifiabilityDoc, IdentifiabilityReport};

/// The options of `cpm identifiability`: the robot and either measurement files or a plan.
/// [`IdentifiabilityOptions::new`] gives the defaults.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IdentifiabilityOptions {
    /// The robot description.
    pub robot: PathBuf,
    /// Measurement files (readings or tracker poses); default empty: give a plan instead.
    pub data: Vec<PathBuf>,
    /// The plan (where the poses come from) when there are no measurement files; default: no
    /// source ([`PlanOptions::default`]).
    #[serde(flatten)]
    pub plan: PlanOptions,
    /// The effects modelled beside the installation errors (`Some(vec![])` for none; by
    /// name: a list, or `--effects`' text); default `None`: the description's
    /// `[calibration] effects`.
    #[serde(with = "crate::options::effects")]
    pub effects: Option<Vec<crate::calib::Effect>>,
    /// Noise standard deviation for the Cramér-Rao bounds, um; default `None`: the
    /// description's `[calibration] sensor_noise_um`, else 1 (bounds per um of noise).
    pub sigma_um: Option<f64>,
    /// Relative rank threshold, in (0, 1): singular values below it times the largest count as
    /// zero; default 1e-4.
    pub rank_rtol: f64,
    /// A-priori tolerances, each in its group's unit (by name `GROUP=VALUE`); default empty:
    /// the description's, else cpm-calib's.
    pub tolerance: Vec<crate::options::Tolerance>,
    /// Groups held at nominal, on top of the description's `[calibration] hold`; default
    /// empty.
    pub hold: Vec<crate::options::Group>,
}

impl IdentifiabilityOptions {
    /// The options for `robot`, every other option at its default (give `data` or a plan).
    pub fn new(robot: impl Into<PathBuf>) -> Self {
        Self {
            robot: robot.into(),
            data: Vec::new(),
            plan: PlanOptions::default(),
            effects: None,
            sigma_um: None,
            rank_rtol: 1e-4,
            tolerance: Vec::new(),
            hold: Vec::new(),
        }
    }

    /// Every input file.
    pub fn inputs(&self) -> Vec<&Path> {
        std::iter::once(self.robot.as_path())
            .chain(self.data.iter().map(PathBuf::as_path))
            .chain(self.plan.plan.as_deref())
            .collect()
    }

    /// Checks what needs no file (usage errors): the rank threshold, one source of poses
    /// (measurement files or a plan, `sensors` with a plan only), the noise.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.check_rank_and_source(!self.data.is_empty(), false)?;
        if let Some(s) = self.sigma_um.filter(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(usage_error(format!("--sigma-um must be > 0, got {s}")));
        }
        Ok(())
    }

    /// The checks the job makes once the robot is read (in the order the command makes them);
    /// `held_plan`: the plan's poses are held in memory (a plan given).
    fn check_rank_and_source(&self, has_data: bool, held_plan: bool) -> anyhow::Result<()> {
        if !(self.rank_rtol > 0.0 && self.rank_rtol < 1.0) {
            return Err(usage_error("--rank-rtol must be in (0, 1)"));
        }
        match (!has_data, self.plan.given() || held_plan) {
            (false, false) if !self.plan.sensors.is_empty() => {
                Err(usage_error("--sensors applies to a plan, not to --data"))
            }
            (false, false) | (true, true) => Ok(()),
            (false, true) => Err(usage_error(
                "give either --data or a plan (--plan, --circle, --random), not both",
            )),
            (true, false) => Err(usage_error(
                "give the measurements (--data FILE) or a plan (--plan FILE, --circle or --random N)",
            )),
        }
    }
}

/// What [`identifiability`] gives: the report (`--json` prints it) and what its text needs.
#[derive(Debug)]
pub struct Identified {
    /// The report: the analysis, its source, the effects and the directions against the
    /// tolerances.
    pub doc: IdentifiabilityDoc,
    /// The analysis itself (singular values, rank, the parameters determined, bounds).
    pub ident: Identifiability,
    /// The parameter names, in the model's order.
    pub names: Vec<String>,
    /// The robot as read.
    pub robot: Robot,
    /// The model analysed (with the instruments' unknowns when the campaign has points or
    /// inclinometers).
    pub model: MeasurementModel,
    /// The noise of the bounds, um.
    pub sigma_um: f64,
    /// True when the noise was given or declared (else the bounds are per um of noise).
    pub sigma_declared: bool,
}

/// `cpm identifiability`: reads the robot and the measurements (or builds the plan) and
/// analyses what the campaign identifies at the nominal geometry.
pub fn identifiability(
    options: &IdentifiabilityOptions,
    progress: &dyn Progress,
) -> anyhow::Result<Identified> {
    identifiability_in(options, crate::sources::InMemory::none(), progress)
}

/// [`identifiability`] with inputs held in memory (the robot as loaded, the measurements:
/// see [`InMemory`](crate::sources::InMemory)) in place of the files the options name.
pub fn identifiability_in(
    options: &IdentifiabilityOptions,
    mut held: crate::sources::InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Identified> {
    check_cancelled(progress)?;
    progress.stage("reading the robot description");
    let robot = held.robot_or_load(&options.robot, progress)?;
    crate::load::require_six_links(&robot)?;
    let effects = crate::load::resolve_effects(options.effects.as_deref(), &robot)?;
    let model = robot.model(&effects);
    let sources = held.sources_or(&options.data);
    let from_data = !sources.is_empty();
    options.check_rank_and_source(from_data, held.poses.is_some())?;
    let (campaign, source) = if from_data {
        progress.stage("reading the measurements");
        let read = crate::load::read_options(&model);
        let registration = crate::load::registration_options(&model);
        let merged = crate::sources::read_sources(&sources, &robot, &read, &registration)?;
        crate::load::warn_excluded(progress, &merged.excluded);
        let names: Vec<String> = sources.iter().map(crate::sources::Source::name).collect();
        (merged.campaign, names.join(", "))
    } else {
        progress.stage("building the plan");
        let spec = crate::plan::build_plan_in(&options.plan, held.poses.as_deref(), &robot, true)?;
        (spec.skeleton(), "plan".to_string())
    };
    check_cancelled(progress)?;
    let model = match crate::load::with_instruments(&model, &campaign) {
        Some(m) => {
            progress.note(&crate::load::instruments_note(&m));
            m
        }
        None => model,
    };
    let sigma_um = match options.sigma_um {
        Some(s) => crate::load::sigma(Some(s), &robot)?.unwrap_or(1.0),
        None => robot.sensor_noise_um().unwrap_or(1.0),
    };
    progress.stage(&format!(
        "analysing {} observations, {}",
        campaign.len(),
        crate::load::describe_model(&model)
    ));
    let rank = RankOptions {
        rank_rtol: options.rank_rtol,
        ..RankOptions::default()
    };
    let ident = crate::calib::identifiability(&model, &campaign, sigma_um, &rank)?;
    // Against the tolerances at this noise: what a fit determines, what it holds.
    let tolerances = crate::fit::tolerances_of(&robot, &options.tolerance, &options.hold, false)?;
    let prior = crate::calib::prior::prior_std(&model, &tolerances)
        .map_err(|e| usage_error(format!("tolerances: {e}")))?;
    let names = model.parameter_names();
    let against = if prior.iter().any(|p| p.is_finite()) {
        let j = crate::calib::identification_jacobian(
            &model,
            &campaign,
            &vec![0.0; model.num_params()],
        )?;
        Some(crate::report::identifiability::AgainstTolerances::new(
            &j, &prior, sigma_um, &names,
        ))
    } else {
        None
    };
    let doc = IdentifiabilityDoc {
        analysis: IdentifiabilityReport::new(&ident, &names),
        source,
        simulated: campaign.simulated && from_data,
        effects: effects.iter().map(|e| e.name().to_string()).collect(),
        against_tolerances: against,
    };
    let sigma_declared = options.sigma_um.is_some() || robot.sensor_noise_um().is_some();
    Ok(Identified {
        doc,
        ident,
        names,
        robot,
        model,
        sigma_um,
        sigma_declared,
    })
}
