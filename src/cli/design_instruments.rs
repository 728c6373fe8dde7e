//! `cpm design --instruments LIST`: the poses of a campaign measured with a tracker, point
//! targets, inclinometers, gauges on the description's sockets, or a mix
//! (`cpm_calib::design::instruments`), with the Cramér-Rao bounds of the mix and of each
//! instrument alone at the chosen poses.
use serde::Serialize;

use super::common;
use super::design_args::{CriterionArg, DesignArgs};
use super::{input_error, usage_error, Ctx, Outcome};
use crate::calib::design::instruments::{InstrumentBounds, InstrumentNoise, Instruments};
use crate::calib::design::{candidates, SelectOptions};
use crate::io::{self, Robot};
use crate::output::OutputSet;
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

/// Runs `cpm design --instruments LIST` (checks of the shared options done by the caller).
pub fn run(
    args: &DesignArgs,
    list: &str,
    robot: &Robot,
    gauge_sigma_um: f64,
    ctx: &mut Ctx<'_>,
) -> anyhow::Result<Outcome> {
    if args.sockets.is_some() || args.stroke_mm.is_some() {
        return Err(usage_error(
            "--instruments chooses poses for the instruments as described; --sockets and --stroke-mm design gauge sockets: give one or the other",
        ));
    }
    if args.candidates == 0
        || args.candidates > 100_000
        || !(args.range_mm > 0.0 && args.range_deg >= 0.0)
        || !(args.range_mm.is_finite() && args.range_deg.is_finite())
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
    let n = args
        .poses
        .unwrap_or_else(|| args.readings.div_ceil(per_pose));
    ctx.stage("candidate poses");
    let (cands, rejected) = candidates::default_candidates(
        &robot.table,
        &candidates::Workspace::default(),
        args.candidates,
        args.range_mm,
        args.range_deg,
        args.seed,
    );
    if n == 0 || n > cands.len() {
        return Err(usage_error(format!(
            "{n} poses asked ({per_pose} observations per pose) but {} admissible candidates ({} rejected): raise --candidates or lower --readings / --poses",
            cands.len(),
            rejected.total()
        )));
    }
    let criterion = args.criterion.criterion();
    ctx.stage(format!("choosing {n} of {} poses", cands.len()));
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
        criterion: match args.criterion {
            CriterionArg::A => "A",
            CriterionArg::D => "D",
            CriterionArg::E => "E",
        }
        .to_string(),
        candidates: cands.len(),
        bounds,
        alone,
    };
    ctx.stage("writing the design");
    let dir = &args.out;
    let mut set = OutputSet::new();
    set.add(
        dir.join("poses.csv"),
        tidy_csv(&io::write_pose_list(&chosen)),
    );
    let json = serde_json::to_string_pretty(&serde_json::to_value(&report)?)?;
    set.add(dir.join("design.json"), json.clone());
    let markdown = report.markdown();
    set.add(dir.join("report.md"), markdown.as_str());
    common::stage_report_html(&mut set, dir, "cpm experiment design", &markdown);
    let written = common::commit_dir(set, dir, &[args.robot.robot.as_path()], "design", ctx)?;
    ctx.finish();
    if args.json {
        writeln!(ctx.out, "{json}")?;
    } else {
        let b = &report.bounds;
        writeln!(
            ctx.out,
            "{} poses x {} observations ({}); rank {} of {}; {} of 36 joint errors determined, Cramér-Rao RMS {:.3} um; minimum-norm RMS {:.3} um",
            b.poses,
            per_pose,
            report.instruments.join(" + "),
            b.rank,
            b.parameters,
            b.joint_errors_determined,
            b.joint_crb_rms_um,
            b.joint_min_norm_rms_um
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}
