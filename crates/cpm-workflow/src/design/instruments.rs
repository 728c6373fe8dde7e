//! `cpm design --instruments LIST`: the poses of a campaign measured with a tracker, point
//! targets, inclinometers, gauges on the description's sockets, or a mix
//! (`cpm_calib::design::instruments`), with the Cramér-Rao bounds of the mix and of each
//! instrument alone at the chosen poses.
use serde::Serialize;

use super::{DesignJobOptions, Designed};
use crate::calib::design::instruments::{InstrumentBounds, InstrumentNoise, Instruments};
use crate::calib::design::limits::{cone_angles_deg, gauge_clearance_mm};
use crate::calib::design::{DesignLimits, SelectOptions};
use crate::error::{input_error, usage_error};
use crate::io::{self, Robot};
use crate::output::OutputSet;
use crate::progress::Progress;
use crate::report::format::{sig, tidy_csv};

/// `design.json` of an instrument design.
#[derive(Debug, Clone, Serialize)]
pub struct InstrumentDesignReport {
    /// The cpm version.
    pub cpm_version: String,
    /// The robot description.
    pub robot: String,
    /// The instruments, as asked (`gauges`, `tracker`, `points`, `tilts`).
    pub instruments: Vec<String>,
    /// The noise of each instrument the bounds are for.
    pub noise: InstrumentNoise,
    /// The criterion of the pose choice.
    pub criterion: String,
    /// Candidate poses chosen from.
    pub candidates: usize,
    /// What the mix identifies at the chosen poses.
    pub bounds: InstrumentBounds,
    /// Each instrument alone at the same poses.
    pub alone: Vec<AloneBounds>,
    /// The limits every chosen pose honours (joint cones, link-link and, with gauges,
    /// gauge-link clearance), `null` when none is given (`--cone-deg`, `--clearance-mm`,
    /// `[limits]`).
    pub limits: Option<DesignLimits>,
    /// Where the limits come from, in words (`null` without limits).
    pub limits_from: Option<String>,
    /// Largest base and platform joint cone angles over the chosen poses, deg.
    pub max_cone_deg: (f64, f64),
    /// The observation budget (`--readings`).
    pub max_observations: usize,
}

/// One instrument alone at the design's poses.
#[derive(Debug, Clone, Serialize)]
pub struct AloneBounds {
    /// The instrument.
    pub instrument: String,
    /// What it identifies there.
    pub bounds: InstrumentBounds,
}

impl InstrumentDesignReport {
    fn markdown(&self) -> String {
        let mut s = format!(
            "# Experiment design for {}\n\nInstruments: {}. Poses chosen {}-optimally from {} candidates on the combinations the instruments identify (cpm {}). Computed at the nominal machine; nothing is measured.\n\nNoise: gauge {} um, tracker {} um and {} urad, point {} um, inclinometer angle {} urad. Each instrument's nuisance parameters (tracker and point frames, target positions, inclinometer mount, base tilt) are estimated with the machine.\n\n| instruments | poses x observations | rank of parameters | joint errors determined | their Cramér-Rao RMS (um) | largest (um) | minimum-norm RMS of the joint errors (um) |\n|---|---|---|---|---|---|---|\n",
            self.robot,
            self.instruments.join(", "),
            self.criterion,
            self.candidates,
            self.cpm_version,
            sig(self.noise.gauge_um, 3),
            sig(self.noise.tracker_position_um, 3),
            sig(self.noise.tracker_orientation_urad, 3),
            sig(self.noise.point_um, 3),
            sig(self.noise.tilt_urad, 3),
        );
        let row = |name: &str, b: &InstrumentBounds| {
            let na = |v: f64| {
                if v.is_finite() {
                    sig(v, 3)
                } else {
                    "n/a".to_string()
                }
            };
            format!(
                "| {name} | {} x {} | {} of {} | {} | {} | {} | {} |\n",
                b.poses,
                b.observations / b.poses.max(1),
                b.rank,
                b.parameters,
                b.joint_errors_determined,
                na(b.joint_crb_rms_um),
                na(b.joint_crb_max_um),
                na(b.joint_min_norm_rms_um),
            )
        };
        s.push_str(&row(
            &format!("**{}** (the design)", self.instruments.join(" + ")),
            &self.bounds,
        ));
        for a in &self.alone {
            s.push_str(&row(&format!("{} alone", a.instrument), &a.bounds));
        }
        match (&self.limits, &self.limits_from) {
            (Some(l), Some(from)) => s.push_str(&format!(
                "\nLimits honoured at every chosen pose ({from}): joint cones base {} deg, platform {} deg (largest reached: {:.2} deg, {:.2} deg); gauge-link clearance {} mm{}.\n",
                l.joints.base_cone_deg,
                l.joints.platform_cone_deg,
                self.max_cone_deg.0,
                self.max_cone_deg.1,
                l.clearance.gauge_link_mm,
                l.clearance
                    .link_link_mm
                    .map_or(String::new(), |v| format!(", link-link clearance {v} mm"))
            )),
            _ => s.push_str(&format!(
                "\nNo joint or clearance limits given (`--cone-deg`, `--clearance-mm`, `[limits]`): largest joint cones reached {:.2} deg (base), {:.2} deg (platform).\n",
                self.max_cone_deg.0, self.max_cone_deg.1
            )),
        }
        s.push_str("\n## Blind directions of the design\n\n");
        if self.bounds.blind_directions.is_empty() {
            s.push_str("None named.\n");
        }
        for b in &self.bounds.blind_directions {
            s.push_str(&format!("- {b}\n"));
        }
        s.push_str("\nA joint error that is not determined on its own has no estimate: only the combinations the instruments see are measured (the minimum-norm RMS is the bound of one point of the solution set, for compensation).\n\n## Outputs\n\n- `poses.csv`: the poses to drive, in the order chosen\n- `design.json`: these figures\n");
        s
    }
}

/// The instruments of `--instruments LIST` on `robot`.
fn parse(list: &str, robot: &Robot) -> anyhow::Result<(Instruments, Vec<String>)> {
    let mut ins = Instruments::default();
    let mut names = Vec::new();
    for item in list.split(',').map(str::trim) {
        let missing = |what: &str| {
            input_error(format!(
                "--instruments {item}: {} declares no {what}",
                robot.file
            ))
        };
        match item {
            "gauges" => {
                if robot.table.sensors.is_empty() {
                    return Err(missing("[[sensor]]"));
                }
                ins.gauges = (0..robot.table.sensors.len()).collect();
            }
            "tracker" => ins.tracker = true,
            "points" => {
                if robot.description.targets.is_empty() {
                    return Err(missing("[[target]]"));
                }
                ins.targets = (0..robot.description.targets.len()).collect();
            }
            "tilts" => {
                if robot.description.inclinometers.is_empty() {
                    return Err(missing("[[inclinometer]]"));
                }
                ins.inclinometers = (0..robot.description.inclinometers.len()).collect();
            }
            other => {
                return Err(usage_error(format!(
                    "--instruments: `{other}` is none of gauges, tracker, points, tilts"
                )))
            }
        }
        if names.iter().any(|n| n == item) {
            return Err(usage_error(format!("--instruments: `{item}` given twice")));
        }
        names.push(item.to_string());
    }
    Ok((ins, names))
}

/// The design of `--instruments LIST` (checks of the shared options done by the caller).
pub fn design(
    options: &DesignJobOptions,
    list: &str,
    robot: &Robot,
    gauge_sigma_um: f64,
    progress: &dyn Progress,
) -> anyhow::Result<Designed> {
    if options.sockets.is_some() || options.stroke_mm.is_some() {
        return Err(usage_error(
            "--instruments chooses poses for the instruments as described; --sockets and --stroke-mm design gauge sockets: give one or the other",
        ));
    }
    if options.candidates == 0
        || options.candidates > 100_000
        || !(options.range_mm > 0.0 && options.range_deg >= 0.0)
        || !(options.range_mm.is_finite() && options.range_deg.is_finite())
    {
        return Err(usage_error(
            "--candidates must be 1 to 100000 and --range-mm > 0, --range-deg >= 0 (finite)",
        ));
    }
    let (ins, names) = parse(list, robot)?;
    let model = robot.model(&[]);
    let (pos, rot) = robot.tracker_sigmas();
    let (point, tilt) = robot.instrument_sigmas();
    let default = InstrumentNoise::default();
    let noise = InstrumentNoise {
        gauge_um: gauge_sigma_um,
        tracker_position_um: pos.unwrap_or(default.tracker_position_um),
        tracker_orientation_urad: rot.unwrap_or(default.tracker_orientation_urad),
        point_um: point.or(pos).unwrap_or(default.point_um),
        tilt_urad: tilt.or(rot).unwrap_or(default.tilt_urad),
    };
    let per_pose = ins.observations_per_pose(&model);
    // The budget is a ceiling: as many whole poses as it holds.
    let n = options.poses.unwrap_or(options.readings / per_pose);
    if n == 0 {
        return Err(usage_error(format!(
            "--readings {}: fewer than the {per_pose} observations of one pose of {}: raise --readings",
            options.readings,
            names.join(" + ")
        )));
    }
    let limits = super::plain_limits(options, robot)?;
    let (cands, rejected) = super::candidate_poses(options, robot, progress);
    // Only poses within the limits (joint cones, link lengths and link-link clearance; the
    // gauge-link clearance of every gauge read there).
    let cands = match &limits {
        None => cands,
        Some((l, from)) => {
            let c = l.constraints();
            let sensors: Vec<&crate::geometry::Sensor> = ins
                .gauges
                .iter()
                .map(|&s| &robot.table.sensors[s])
                .collect();
            let mut first = None;
            let kept: Vec<crate::geometry::Pose> = cands
                .into_iter()
                .filter(|pose| {
                    let r = c.check_pose(&robot.table, pose).and_then(|()| {
                        sensors.iter().try_for_each(|s| {
                            let d = gauge_clearance_mm(&robot.table, s, pose);
                            if d >= l.clearance.gauge_link_mm {
                                Ok(())
                            } else {
                                Err(format!(
                                    "gauge {}: {d:.1} mm from a link < {} mm",
                                    s.name, l.clearance.gauge_link_mm
                                ))
                            }
                        })
                    });
                    if let Err(e) = &r {
                        first.get_or_insert(e.clone());
                    }
                    r.is_ok()
                })
                .collect();
            if kept.is_empty() {
                return Err(usage_error(format!(
                    "no candidate pose honours {from} (the first refused: {}): relax them, or try a smaller --range-mm or --range-deg",
                    first.unwrap_or_default()
                )));
            }
            kept
        }
    };
    if n > cands.len() {
        return Err(usage_error(format!(
            "{n} poses asked ({per_pose} observations per pose) but {} admissible candidates ({} rejected): raise --candidates or lower --readings / --poses",
            cands.len(),
            rejected.total()
        )));
    }
    let criterion = options.criterion;
    progress.stage(&format!("choosing {n} of {} poses", cands.len()));
    let select = SelectOptions {
        criterion,
        ..SelectOptions::default()
    };
    let chosen = ins
        .design(&model, &cands, n, &noise, &select)
        .map_err(anyhow::Error::new)?;
    let bounds = ins.bounds(&model, &chosen, &noise)?;
    let mut alone = Vec::new();
    if names.len() > 1 {
        for name in &names {
            let (one, _) = parse(name, robot)?;
            alone.push(AloneBounds {
                instrument: name.clone(),
                bounds: one.bounds(&model, &chosen, &noise)?,
            });
        }
    }
    let report = InstrumentDesignReport {
        cpm_version: env!("CARGO_PKG_VERSION").to_string(),
        robot: robot.file.clone(),
        instruments: names,
        noise,
        criterion: options.criterion.name().to_string(),
        candidates: cands.len(),
        bounds,
        alone,
        limits: limits.as_ref().map(|(l, _)| *l),
        limits_from: limits.as_ref().map(|(_, f)| f.clone()),
        max_cone_deg: chosen.iter().fold((0.0_f64, 0.0_f64), |m, pose| {
            cone_angles_deg(&robot.table, pose)
                .iter()
                .fold(m, |(a, b), (x, y)| (a.max(*x), b.max(*y)))
        }),
        max_observations: options.readings,
    };
    progress.stage("writing the design");
    let dir = &options.out;
    let mut set = OutputSet::new();
    set.add(
        dir.join("poses.csv"),
        tidy_csv(&io::write_pose_list(&chosen)),
    );
    let json = serde_json::to_string_pretty(&serde_json::to_value(&report)?)?;
    set.add(dir.join("design.json"), json.clone());
    let markdown = report.markdown();
    set.add(dir.join("report.md"), markdown.as_str());
    crate::load::stage_report_html(&mut set, dir, "cpm experiment design", &markdown);
    let b = &report.bounds;
    let um = |v: f64| {
        if v.is_finite() {
            format!("{v:.3} um")
        } else {
            "n/a".to_string()
        }
    };
    let summary = format!(
        "{} poses x {} observations ({}); rank {} of {}; {} of 36 joint errors determined, Cramér-Rao RMS {}; minimum-norm RMS {}",
        b.poses,
        per_pose,
        report.instruments.join(" + "),
        b.rank,
        b.parameters,
        b.joint_errors_determined,
        um(b.joint_crb_rms_um),
        um(b.joint_min_norm_rms_um)
    );
    Ok(Designed {
        outputs: set,
        inputs: vec![options.robot.clone()],
        json,
        summary,
    })
}
