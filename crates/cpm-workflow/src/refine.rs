//! `cpm refine` as a library function: calibrate, then add the effects that the residual
//! asks for, one at a time, each with an F-test, its BIC change and cross-validation
//! (cpm_calib::refine), staging `refine.json`, `report.md`, `calibration.json`, figures and
//! `calibrated.toml`.
use crate::calib::{Effect, RefineOptions as CalibRefineOptions};
use crate::error::{input_error, trouble, usage_error};
use crate::fit::FitOptions;
use crate::load::Inputs;
use crate::output::OutputSet;
use crate::progress::{check_cancelled, Progress};
use crate::report::calibrate::CalibratedFile;
use crate::report::fit::FitReport;
use crate::report::refine::{RefineDoc, RefineReport};
use crate::staging::provenance_lines;
use crate::staging::{stage_calibrated, stage_figures, stage_residuals};

/// The options of `cpm refine`. [`RefineOptions::new`] gives the defaults.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineOptions {
    /// Robot, data, effects, noise, solver and output directory: as for calibrate.
    #[serde(flatten)]
    pub fit: FitOptions,
    /// Candidate effects (by name: a list, or `--candidates`' text); default `None`: every
    /// effect of the library that can act on the data.
    #[serde(with = "crate::options::candidates")]
    pub candidates: Option<Vec<Effect>>,
    /// Most effects added; default 4.
    pub max_steps: usize,
    /// Significance level of the F-test (before the Bonferroni correction); default 0.01.
    pub alpha: f64,
    /// Folds of the cross-validation over poses; default 5.
    pub folds: usize,
    /// Highest degree of the pose error map terms (0 to 3); default `None`: 0 with
    /// `candidates`, else `[pose_map] degree` of the description, else 2.
    pub pose_map_degree: Option<u8>,
}

impl RefineOptions {
    /// The options with every default, for `robot`, `data` and the output directory `out`.
    pub fn new(
        robot: impl Into<std::path::PathBuf>,
        data: Vec<std::path::PathBuf>,
        out: impl Into<std::path::PathBuf>,
    ) -> Self {
        Self {
            fit: FitOptions::new(robot, data, out),
            candidates: None,
            max_steps: 4,
            alpha: 0.01,
            folds: 5,
            pose_map_degree: None,
        }
    }

    /// Checks what needs no file (usage errors): the output directory, the level, the folds.
    pub fn validate(&self) -> anyhow::Result<()> {
        crate::load::check_out_dir(&self.fit.out)?;
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(usage_error("--alpha must be in (0, 1)"));
        }
        if self.folds < 2 || self.folds > 1000 {
            return Err(usage_error("--folds must be between 2 and 1000"));
        }
        Ok(())
    }
}

/// What [`refine`] gives: the inputs, the refinement, its report and every output staged.
pub struct Refined {
    /// The inputs as loaded.
    pub inputs: Inputs,
    /// The refinement (the final calibration is `result.calibration`).
    pub result: crate::calib::refine::Refinement,
    /// The staged outputs for `fit.out`.
    pub set: OutputSet,
    /// The report (`report.md` renders it, `refine.json` is its `doc`).
    pub report: RefineReport,
    /// What the last round of the search concluded, when it says something.
    pub last_round: Option<String>,
}

impl Refined {
    /// The trouble the final fit reports with its outputs written (exit code 1), if any.
    pub fn trouble(&self) -> Option<String> {
        let cal = &self.result.calibration;
        if let Some(why) = cal.robust_failure() {
            Some(format!(
                "the final fit failed: {why}; the outputs were written and say so"
            ))
        } else if cal.solver.was_successful() {
            None
        } else {
            Some(format!(
                "the final fit did not converge ({})",
                cal.solver.termination
            ))
        }
    }
}

/// Puts the options' tolerances and holds of effects (set aside to load) back into the
/// fit's tolerances: each must name a group of the model or a candidate effect (a usage
/// error otherwise, naming both), and the candidates' take effect when refine adds them.
fn candidate_tolerances(
    args: &RefineOptions,
    inputs: &mut Inputs,
    candidates: &[Effect],
    is_effect: impl Fn(&str) -> bool,
) -> anyhow::Result<()> {
    let model = &inputs.model;
    let groups: Vec<String> = model
        .blocks()
        .iter()
        .map(|b| crate::calib::prior::group_name(model, b))
        .collect();
    let t = &mut inputs.identify.tolerances;
    let names = args
        .fit
        .tolerance
        .iter()
        .map(|g| (g.group.as_str(), Some((g.value, g.to_string()))))
        .chain(args.fit.hold.iter().map(|h| (h.as_str(), None)));
    for (name, value) in names.filter(|(n, _)| is_effect(n)) {
        let option = if value.is_some() {
            "--tolerance"
        } else {
            "--hold"
        };
        if !groups.iter().any(|g| g == name) && !candidates.iter().any(|c| c.name() == name) {
            return Err(usage_error(format!(
                "{option} {name}: `{name}` is neither a parameter group of this fit ({}) nor a candidate effect ({})",
                groups.join(", "),
                candidates
                    .iter()
                    .map(|c| c.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        match value {
            Some((v, text)) => t
                .set(name, v)
                .map_err(|e| usage_error(format!("--tolerance {text:?}: {e}")))?,
            None => {
                if !t.hold.iter().any(|g| g == name) {
                    t.hold.push(name.to_string());
                }
            }
        }
        t.optional.insert(name.to_string());
    }
    crate::calib::prior::prior_std(model, t)
        .map_err(|e| usage_error(format!("tolerances: {e}")))?;
    Ok(())
}

/// `cpm refine` as a function: checks the options, loads the robot and the data, refines, and
/// stages every output for `options.fit.out` (nothing is written: commit the set). Refused
/// (an error, nothing staged) when the refined model predicts held-out data worse than plain
/// calibration.
pub fn refine(options: &RefineOptions, progress: &dyn Progress) -> anyhow::Result<Refined> {
    refine_in(options, crate::sources::InMemory::none(), progress)
}

/// [`refine`] with inputs held in memory (the robot as loaded, the measurements: see
/// [`InMemory`](crate::sources::InMemory)) in place of the files the options name.
pub fn refine_in(
    options: &RefineOptions,
    held: crate::sources::InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Refined> {
    crate::progress::unless_cancelled(refine_job(options, held, progress), progress)
}

fn refine_job(
    options: &RefineOptions,
    mut held: crate::sources::InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Refined> {
    options.validate()?;
    let args = options;
    // The options' tolerances and holds of effects: the starting model may lack one that
    // refine can add. They are set aside to load, put back, and checked against the model
    // and the candidates once those are known (`candidate_tolerances`).
    let is_effect = |g: &str| Effect::parse(g).is_ok();
    let mut fit = args.fit.clone();
    fit.tolerance.retain(|t| !is_effect(t.group.as_str()));
    fit.hold.retain(|h| !is_effect(h.as_str()));
    let mut inputs = if held.is_empty() {
        fit.load(progress)?
    } else {
        let robot = held.robot_or_load(&fit.robot, progress)?;
        let sources = held.sources_or(&fit.data);
        crate::memory::load(&fit, robot, &sources, progress)?
    };
    check_cancelled(progress)?;
    let merged = std::sync::Arc::clone(&inputs.merged);
    let campaign = &merged.campaign;
    // The library's effects that can act on these data (an explicit list is taken as given).
    let (candidates, not_applicable) = match &args.candidates {
        Some(list) => (list.clone(), Vec::new()),
        None => applicable(campaign),
    };
    // No hidden load: without a declared [load], the effects whose direction the link
    // forces set are not candidates (an explicit --candidates naming one is an error).
    let (candidates, not_applicable) = if inputs.robot.description.load.is_none() {
        let (skip, keep): (Vec<Effect>, Vec<Effect>) = candidates
            .into_iter()
            .partition(|e| crate::fit::needs_load(*e));
        if !skip.is_empty() && args.candidates.is_some() {
            return Err(input_error(format!(
                "{}: --candidates names {}, which needs the platform's load, and the description declares none: add a [load] table (docs/formats.md) or leave it out",
                inputs.robot.file,
                skip.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ")
            )));
        }
        let mut not_applicable = not_applicable;
        not_applicable.extend(skip.into_iter().map(|e| {
            (
                e,
                "no [load] declared (the link forces that give it its direction need one)",
            )
        }));
        (keep, not_applicable)
    } else {
        (candidates, not_applicable)
    };
    candidate_tolerances(args, &mut inputs, &candidates, is_effect)?;
    // An explicit --candidates list is the whole candidate set: the pose map scan joins it
    // only when --pose-map-degree asks for it.
    let pose_map_degree = match (args.pose_map_degree, &args.candidates) {
        (Some(d), _) => d,
        (None, Some(_)) => 0,
        (None, None) => inputs
            .robot
            .description
            .pose_map
            .and_then(|p| p.degree)
            .unwrap_or(2),
    };
    if pose_map_degree > 3 {
        return Err(usage_error("--pose-map-degree must be 0 to 3"));
    }
    progress.stage(&format!(
        "refining: {} to {} observations, up to {} effects from {} candidates (each round fits every candidate)",
        crate::load::describe_model(&inputs.model),
        campaign.len(),
        args.max_steps,
        candidates.len()
    ));
    let refine_options = CalibRefineOptions {
        candidates,
        alpha: args.alpha,
        max_steps: args.max_steps,
        folds: args.folds,
        pose_map_degree,
        identify: inputs.identify.clone(),
        ..CalibRefineOptions::default()
    };
    let options = refine_options;
    // A pose where the fit cannot start is left out (see `crate::fit::leaving_out`).
    let (r, excluded) = crate::fit::leaving_out(&inputs, |merged| {
        crate::calib::refine(&inputs.model, &merged.campaign, &options)
    })?;
    crate::load::warn_excluded(
        progress,
        &excluded.iter().map(|(_, e)| e.clone()).collect::<Vec<_>>(),
    );
    let inputs = if excluded.is_empty() {
        inputs
    } else {
        inputs.without_poses(&excluded)
    };
    let campaign = &inputs.merged.campaign;
    // Never worse than plain calibration on data the fits did not see: otherwise an error,
    // and nothing written.
    if r.against_calibrate.refusal(None).is_some() {
        // Its figures in sigma when the residual mixes kinds weighed differently.
        let kinds = crate::calib::noise::by_kind(&r.model, campaign, &r.calibration);
        let weighted =
            crate::calib::noise::residual_is_weighted(&kinds).then_some(r.calibration.sigma_um);
        let why = r
            .against_calibrate
            .refusal(weighted)
            .expect("refused above");
        return Err(trouble(format!("{why}; nothing was written")));
    }
    progress.stage("writing the results");
    let dir = &args.fit.out;
    let cal = &r.calibration;
    let mut set = OutputSet::new();
    let mut doc = RefineDoc::new(&r, campaign.simulated, options.min_novelty);
    doc.not_applicable = not_applicable
        .iter()
        .map(|(e, why)| crate::report::refine::NotApplicable {
            effect: e.name().to_string(),
            why: why.to_string(),
        })
        .collect();
    // The poses left out (by the readers or because the fit could not start there), as
    // calibration.json lists them.
    doc.excluded_poses = inputs
        .merged
        .excluded
        .iter()
        .map(crate::report::fit::ExcludedPoseReport::from)
        .collect();
    let mut fit = FitReport::new(&inputs.report_inputs(), &r.model, cal, None);
    crate::fit::add_session_warnings(&mut fit, &inputs, &r.model)?;
    doc.residual_weighted = fit.residual_weighted;
    doc.noise_scale_um = fit.scale.sigma;
    set.add(dir.join("refine.json"), doc.to_json()?);
    set.add(dir.join("calibration.json"), fit.to_json()?);
    stage_residuals(&mut set, dir, &inputs, cal);
    let mut figures = stage_figures(&mut set, dir, &inputs.robot, &r.model, campaign, cal)?;
    set.add(
        dir.join("residuals_before_after.svg"),
        crate::report::figures::fit::residuals_before_after(
            &format!(
                "Residual before and after refinement{}",
                if campaign.simulated {
                    " (SIMULATED)"
                } else {
                    ""
                }
            ),
            campaign,
            &crate::report::figures::fit::ResidualNames::new(
                inputs
                    .robot
                    .table
                    .sensors
                    .iter()
                    .map(|s| s.name.clone())
                    .collect(),
                &r.model,
            ),
            &crate::calib::noise::measured_minus_predicted(
                campaign,
                r.initial_sigma_ref_um,
                &r.initial_residuals_um,
            ),
            &crate::calib::noise::measured_minus_predicted(
                campaign,
                cal.sigma_ref_um,
                &cal.residuals_um,
            ),
        )?,
    );
    figures.push("residuals_before_after.svg");
    let notes = stage_calibrated(
        &mut set,
        dir,
        &inputs,
        &r.model,
        cal,
        false,
        Some(&r.model.effects),
        "Refined",
        true,
    )?;
    let last = doc.last_round_message();
    let report = RefineReport {
        provenance: provenance_lines(&inputs.provenance, campaign.simulated, "Refined"),
        starting_model: crate::load::describe_model(&inputs.model),
        final_effects: crate::load::effect_list(&r.model.effects),
        calibrated: CalibratedFile {
            minimum_norm: false,
            undetermined: notes.undetermined.len(),
            known_effects: notes.known_effects.clone(),
        },
        figures: figures.iter().map(|f| f.to_string()).collect(),
        significant_pose_structure: {
            let alpha_scan = options.alpha / r.initial_pose_structure.len().max(1) as f64;
            doc.pose_structure
                .iter()
                .filter(|p| p.p_value < alpha_scan)
                .take(3)
                .cloned()
                .collect()
        },
        fit,
        doc,
    };
    let markdown = report.markdown();
    set.add(dir.join("report.md"), markdown.as_str());
    crate::load::stage_report_html(&mut set, dir, "cpm refinement report", &markdown);
    check_cancelled(progress)?;
    Ok(Refined {
        inputs,
        result: r,
        set,
        report,
        last_round: last,
    })
}

/// The library's effects split into those that can act on `campaign` and those that cannot,
/// with why: a tracker frame without tracker poses, a thermal drift without a logged
/// temperature, the sensors' effects without gauge readings.
fn applicable(campaign: &crate::calib::Campaign) -> (Vec<Effect>, Vec<(Effect, &'static str)>) {
    let temperatures = campaign.readings.iter().any(|r| r.temperature_c.is_some())
        || campaign
            .pose_measurements
            .iter()
            .any(|p| p.temperature_c.is_some());
    let (mut yes, mut no) = (Vec::new(), Vec::new());
    for e in Effect::ALL {
        let why = match e {
            Effect::TrackerFrame if campaign.pose_measurements.is_empty() => {
                Some("no tracker poses in the data")
            }
            Effect::ThermalDrift if !temperatures => Some("no temperature logged"),
            Effect::SensorOffset | Effect::SensorScale | Effect::SocketError
                if campaign.readings.is_empty() =>
            {
                Some("no gauge readings")
            }
            _ => None,
        };
        match why {
            Some(w) => no.push((e, w)),
            None => yes.push(e),
        }
    }
    (yes, no)
}
