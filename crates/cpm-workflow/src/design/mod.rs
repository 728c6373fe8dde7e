//! The design job (`cpm design`): choose sensor sockets and poses for a calibration campaign
//! (`cpm_calib::design::design`, or `design_setups` under an instrument's limits, or the poses
//! of a mix of instruments), and stage the poses, the sockets, a robot description with the
//! chosen sensors and the report. Nothing is written: the caller commits
//! [`Designed::outputs`].
use std::path::PathBuf;

use crate::calib::design::{
    candidates, design as design_sockets, design_setups, sockets::Socket, Clearance, Constraints,
    Criterion, DesignLimits, DesignOptions, Gauge, GaugeKind, JointLimits, SelectOptions,
    SetupOptions, SocketCandidates,
};
use crate::calib::Effect;
use crate::error::{input_error, usage_error};
use crate::geometry::description::{SensorSpec, SocketSide};
use crate::io::{self, Robot};
use crate::output::OutputSet;
use crate::progress::Progress;
use crate::report::format::tidy_csv;

pub mod instruments;

/// The criterion and the gauge of [`DesignJobOptions`] by the names `cpm design` gives them
/// (`--criterion a|d|e`, `--gauge telescoping|ballbar`), for options given by name.
mod named {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Unknown names as serde's error, listing the known ones.
    fn unknown<E: serde::de::Error>(name: &str, known: &'static [&'static str]) -> E {
        E::unknown_variant(name, known)
    }

    pub mod criterion {
        use super::*;
        use crate::calib::design::Criterion;

        const NAMES: &[&str] = &["a", "d", "e"];

        pub fn serialize<S: Serializer>(c: &Criterion, s: S) -> Result<S::Ok, S::Error> {
            s.serialize_str(match c {
                Criterion::AOptimal => "a",
                Criterion::DOptimal => "d",
                Criterion::EOptimal => "e",
            })
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Criterion, D::Error> {
            let name = String::deserialize(d)?;
            match name.as_str() {
                "a" => Ok(Criterion::AOptimal),
                "d" => Ok(Criterion::DOptimal),
                "e" => Ok(Criterion::EOptimal),
                other => Err(unknown(other, NAMES)),
            }
        }
    }

    pub mod gauge {
        use super::*;
        use crate::calib::design::GaugeKind;

        const NAMES: &[&str] = &["telescoping", "ballbar"];

        pub fn serialize<S: Serializer>(g: &Option<GaugeKind>, s: S) -> Result<S::Ok, S::Error> {
            match g {
                None => s.serialize_none(),
                Some(g) => s.serialize_str(g.name()),
            }
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<GaugeKind>, D::Error> {
            match Option::<String>::deserialize(d)?.as_deref() {
                None => Ok(None),
                Some("telescoping") => Ok(Some(GaugeKind::Telescoping)),
                Some("ballbar") => Ok(Some(GaugeKind::Ballbar)),
                Some(other) => Err(unknown(other, NAMES)),
            }
        }
    }
}

/// The options of [`design`], as `cpm design` takes them (defaults: those of
/// [`DesignJobOptions::new`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DesignJobOptions {
    /// The robot description.
    pub robot: PathBuf,
    /// Candidate socket places (`name,side,x_mm,y_mm,z_mm`, or the socket pairs of a design's
    /// `sockets.csv`); default `None`: the description's `[[socket]]` and `[[socket_region]]`
    /// places, else its sensors' sockets.
    pub sockets: Option<PathBuf>,
    /// Reading budget (poses x socket pairs; with `instruments`, scalar observations).
    /// Default 2000.
    pub readings: usize,
    /// Base sockets to use. Default 3.
    pub base_sockets: usize,
    /// Platform sockets to use. Default 3.
    pub platform_sockets: usize,
    /// Poses to drive; default `None`: as many as the budget allows.
    pub poses: Option<usize>,
    /// Random candidate poses (plus circles) to choose from. Default 1000.
    pub candidates: usize,
    /// Half range of candidate positions about home, mm. Default 50.
    pub range_mm: f64,
    /// Half range of candidate roll, pitch, yaw about home, deg. Default 10.
    pub range_deg: f64,
    /// Selection criterion. Default A-optimal. By name (`a`, `d`, `e`), as `--criterion`.
    #[serde(with = "named::criterion")]
    pub criterion: Criterion,
    /// Sensor noise for the reported bounds, um; default `None`: the description's, else 1.
    pub sigma_um: Option<f64>,
    /// Random seed of the candidates. Default 1.
    pub seed: u64,
    /// The gauge's stroke per setup, mm: turns the setup design on (also on when the
    /// description declares a `[[gauge]]`). Default `None`.
    pub stroke_mm: Option<f64>,
    /// The description's `[[gauge]]` to design for; default its first.
    pub gauge_name: Option<String>,
    /// Kind of gauge; default the description's gauge, else telescoping.
    #[serde(with = "named::gauge")]
    pub gauge: Option<GaugeKind>,
    /// Shortest socket-to-socket length the gauge reads, mm; default the description's
    /// gauge, else 150 (100 for a ballbar).
    pub shortest_mm: Option<f64>,
    /// Longest socket-to-socket length the gauge reads, mm; default the description's gauge,
    /// else 1000.
    pub longest_mm: Option<f64>,
    /// Extension bars available, mm; default empty: the description's gauge's, else any.
    pub bars_mm: Vec<f64>,
    /// Smallest distance between the gauge axis and any link axis, mm; default the
    /// description's `[limits]`, else 30.
    pub clearance_mm: Option<f64>,
    /// Largest cone angle of every joint from home, deg; default the description's
    /// `[limits]`, else 40.
    pub cone_deg: Option<f64>,
    /// Most setups (gauge mounts) of a design under limits. Default 16.
    pub setups: usize,
    /// The output directory (checked, never written by the job).
    pub out: PathBuf,
    /// Choose the poses for this mix of instruments (`gauges`, `tracker`, `points`,
    /// `tilts`, comma-separated) instead of designing gauge sockets. Default `None`.
    pub instruments: Option<String>,
}

impl DesignJobOptions {
    /// The options with every default, for `robot` and the output directory `out`.
    pub fn new(robot: impl Into<PathBuf>, out: impl Into<PathBuf>) -> Self {
        Self {
            robot: robot.into(),
            sockets: None,
            readings: 2000,
            base_sockets: 3,
            platform_sockets: 3,
            poses: None,
            candidates: 1000,
            range_mm: 50.0,
            range_deg: 10.0,
            criterion: Criterion::AOptimal,
            sigma_um: None,
            seed: 1,
            stroke_mm: None,
            gauge_name: None,
            gauge: None,
            shortest_mm: None,
            longest_mm: None,
            bars_mm: Vec::new(),
            clearance_mm: None,
            cone_deg: None,
            setups: 16,
            out: out.into(),
            instruments: None,
        }
    }

    /// Checks what needs no file: the output directory (the other checks need the
    /// description and are made by [`design`]).
    pub fn validate(&self) -> anyhow::Result<()> {
        crate::load::check_out_dir(&self.out)
    }
}

/// What [`design`] made: the staged outputs, the inputs they may not replace, the
/// `design.json` text and a one-line summary.
#[derive(Debug)]
pub struct Designed {
    /// Every output file, staged (commit with [`crate::load::commit_dir`]).
    pub outputs: OutputSet,
    /// The input files (the description, the sockets file).
    pub inputs: Vec<PathBuf>,
    /// `design.json`.
    pub json: String,
    /// The one-line summary `cpm design` prints.
    pub summary: String,
}

/// Candidate sockets of a description: its `[[socket]]` and `[[socket_region]]` places when
/// it has any, else its sensors' sockets (distinct positions on each side).
pub fn sockets_of(robot: &Robot) -> SocketCandidates {
    let mut c = SocketCandidates {
        base: Vec::new(),
        platform: Vec::new(),
    };
    let places = robot.description.socket_places();
    if !places.is_empty() {
        for (name, side, p) in places {
            match side {
                SocketSide::Base => c.base.push(Socket::new(&name, p)),
                SocketSide::Platform => c.platform.push(Socket::new(&name, p)),
            }
        }
        return c;
    }
    for s in &robot.table.sensors {
        for (list, at, prefix) in [
            (&mut c.base, s.base_mm, 'b'),
            (&mut c.platform, s.platform_mm, 'p'),
        ] {
            if !list.iter().any(|q| (q.position_mm - at).norm() < 1e-9) {
                let name = format!("{prefix}{}", list.len() + 1);
                list.push(Socket::new(&name, at.into()));
            }
        }
    }
    c
}

/// Runs `cpm design`.
/// Runs the design job: reads the description (and the sockets file), chooses the
/// sockets and poses (or the poses of `instruments`), and stages every output.
pub fn design(options: &DesignJobOptions, progress: &dyn Progress) -> anyhow::Result<Designed> {
    design_in(options, crate::sources::InMemory::none(), progress)
}

/// [`design`] with the robot held in memory (as loaded: see
/// [`InMemory`](crate::sources::InMemory)) in place of the description the options name.
pub fn design_in(
    options: &DesignJobOptions,
    mut held: crate::sources::InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Designed> {
    options.validate()?;
    progress.stage("reading the robot description");
    let robot = held.robot_or_load(&options.robot, progress)?;
    crate::load::require_six_links(&robot)?;
    if let Some(list) = &options.instruments {
        let sigma = gauge_sigma_um(options, &robot)?;
        return instruments::design(options, list, &robot, sigma, progress);
    }
    let sockets = match &options.sockets {
        Some(p) => {
            io::sockets::read_sockets_from(io::campaign::open(p)?, &p.display().to_string())?
        }
        None => sockets_of(&robot),
    };
    let limits = limited_constraints(options, &robot)?;
    if sockets.base.len() < options.base_sockets
        || sockets.platform.len() < options.platform_sockets
    {
        return Err(input_error(format!(
            "{} base and {} platform socket places to choose from ({}), {} and {} asked for: give more places with --sockets FILE or ask for fewer",
            sockets.base.len(),
            sockets.platform.len(),
            options.sockets.as_ref().map_or_else(
                || {
                    if robot.description.socket_places().is_empty() {
                        format!("the [[sensor]] tables of {}", robot.file)
                    } else {
                        format!("the [[socket]] and [[socket_region]] tables of {}", robot.file)
                    }
                },
                |p| p.display().to_string()
            ),
            options.base_sockets,
            options.platform_sockets
        )));
    }
    if options.candidates == 0
        || !(options.range_mm > 0.0 && options.range_deg >= 0.0)
        || !(options.range_mm.is_finite() && options.range_deg.is_finite())
    {
        return Err(usage_error(
            "--candidates must be >= 1 and --range-mm > 0, --range-deg >= 0 (finite)",
        ));
    }
    for (n, name, max) in [
        (options.candidates, "--candidates", 100_000),
        (options.readings, "--readings", 10_000_000),
        (options.poses.unwrap_or(0), "--poses", 1_000_000),
    ] {
        if n > max {
            return Err(usage_error(format!("{name} {n}: at most {max}")));
        }
    }
    let sigma = gauge_sigma_um(options, &robot)?;
    let model = robot.model(&[]);
    let (cands, rejected) = candidate_poses(options, &robot, progress);
    if cands.is_empty() {
        return Err(usage_error(format!(
            "no admissible candidate pose ({} rejected): try a smaller --range-mm or --range-deg",
            rejected.total()
        )));
    }
    if let Some((constraints, gauge_name)) = limits {
        return run_limited(
            options,
            progress,
            &robot,
            &model,
            &sockets,
            &cands,
            constraints,
            &gauge_name,
        );
    }
    let plain = plain_limits(options, &robot)?;
    let select = DesignOptions {
        limits: plain.as_ref().map(|(l, _)| *l),
        max_readings: options.readings,
        base_sockets: options.base_sockets,
        platform_sockets: options.platform_sockets,
        poses: options.poses,
        select: SelectOptions {
            criterion: options.criterion,
            ..SelectOptions::default()
        },
        sigma_um: sigma,
        ..DesignOptions::default()
    };
    let d = design_sockets(&model, &sockets, &cands, &select, &|s| {
        progress.stage(s)
    })
    .map_err(|e| match e {
        crate::calib::CalibError::Invalid { field, why } if field.starts_with("limits") => {
            usage_error(format!(
                "{why}: the design cannot honour {}; relax them, or try a smaller --range-mm or --range-deg",
                plain.as_ref().map_or("the limits", |(_, from)| from.as_str())
            ))
        }
        crate::calib::CalibError::Invalid { .. } => usage_error(e.to_string()),
        other => anyhow::Error::new(other),
    })?;
    progress.stage("writing the design");
    let mut desc = robot.description.clone();
    desc.sensors = d.sensors.iter().map(SensorSpec::from_sensor).collect();
    // The limits the poses honour, as the description's [limits] (never one they break).
    if let Some((l, _)) = &plain {
        desc.limits = Some(
            l.constraints()
                .to_limits_spec(robot.description.limits.as_ref()),
        );
    }
    // Known values of the old sensors' effects do not carry over to the new sensors.
    drop_sensor_effects(&mut desc);
    let robot_toml = format!(
        "# {} with the sensors chosen by cpm design {}\n\n{}",
        robot.file,
        env!("CARGO_PKG_VERSION"),
        desc.to_toml_string()?
    );
    let dir = &options.out;
    let report = crate::report::design::DesignReport::new(&robot.file, &d);
    let mut set = OutputSet::new();
    set.add(
        dir.join("poses.csv"),
        tidy_csv(&io::write_pose_list(&d.poses)),
    );
    set.add(dir.join("sockets.csv"), tidy_csv(&d.sockets_csv()));
    set.add(dir.join("robot.toml"), robot_toml);
    set.add(dir.join("design.json"), report.to_json()?);
    stage_report(&mut set, dir, "cpm experiment design", &report.markdown());
    Ok(Designed {
        outputs: set,
        inputs: inputs_of(options),
        json: report.to_json()?,
        summary: format!(
            "{} poses x {} socket pairs = {} readings; rank {} of {}; Cramér-Rao RMS {:.3} um for {} um noise",
            d.poses.len(),
            d.sensors.len(),
            d.num_readings(),
            d.indices.rank,
            d.indices.num_params,
            d.indices.crlb_rms_um,
            d.indices.sigma_um
        ),
    })
}

// ---- Design under an instrument's limits (--stroke-mm) -------------------------------------

/// The description `robot` with one sensor per setup of `design` instead of its own, the
/// gauge and the limits (known sensor effects dropped).
fn described(
    options: &DesignJobOptions,
    robot: &Robot,
    design: &crate::calib::design::SetupDesign,
    gauge_name: &str,
) -> anyhow::Result<String> {
    let mut desc = robot.description.clone();
    design.describe(&mut desc, gauge_name);
    // A noise nobody declared (the bounds' default of 1 um) is not written as the gauge's.
    let declared = options.sigma_um.is_some()
        || robot.sensor_noise_um().is_some()
        || robot
            .description
            .gauge(Some(gauge_name))
            .is_some_and(|g| g.noise_um.is_some());
    if !declared {
        if let Some(g) = desc.gauges.iter_mut().find(|g| g.name == gauge_name) {
            g.noise_um = None;
        }
    }
    drop_sensor_effects(&mut desc);
    Ok(desc.to_toml_string()?)
}

/// The limits of a design under limits: the description's `[[gauge]]` (`--gauge-name`, else
/// its first) and `[limits]`, overridden by the flags; `None` (the unconstrained design) when
/// neither `--stroke-mm` nor a `[[gauge]]` is given. Also the gauge's name in the written
/// description.
fn limited_constraints(
    options: &DesignJobOptions,
    robot: &Robot,
) -> anyhow::Result<Option<(Constraints, String)>> {
    let declared = Constraints::from_description(&robot.description, options.gauge_name.as_deref())
        .map_err(|e| usage_error(format!("--gauge-name: {e}")))?;
    if declared.is_none() && options.stroke_mm.is_none() {
        return Ok(None);
    }
    let name = match (&declared, &options.gauge_name) {
        (_, Some(n)) => n.clone(),
        (Some(_), None) => robot.description.gauges[0].name.clone(),
        (None, None) => "gauge".to_string(),
    };
    let mut c = declared.unwrap_or_else(|| {
        let gauge = match options.gauge {
            Some(GaugeKind::Ballbar) => Gauge::ballbar(),
            _ => Gauge::default(),
        };
        Constraints {
            gauge: Gauge {
                sigma_um: robot.sensor_noise_um().unwrap_or(1.0),
                ..gauge
            },
            ..Constraints::default()
        }
    });
    if let Some(k) = options.gauge {
        c.gauge.kind = k;
    }
    if let Some(v) = options.stroke_mm {
        c.gauge.stroke_mm = v;
    }
    if let Some(v) = options.shortest_mm {
        c.gauge.shortest_mm = v;
    }
    if let Some(v) = options.longest_mm {
        c.gauge.longest_mm = v;
    }
    if !options.bars_mm.is_empty() {
        c.gauge.bars_mm = options.bars_mm.clone();
    }
    if let Some(v) = options.sigma_um {
        c.gauge.sigma_um = crate::load::sigma(Some(v), robot)?.unwrap_or(v);
    }
    if let Some(v) = options.clearance_mm {
        c.clearance.gauge_link_mm = v;
    }
    if let Some(v) = options.cone_deg {
        c.joints.base_cone_deg = v;
        c.joints.platform_cone_deg = v;
    }
    c.validate().map_err(|e| usage_error(e.to_string()))?;
    Ok(Some((c, name)))
}

#[allow(clippy::too_many_arguments)]
fn run_limited(
    options: &DesignJobOptions,
    progress: &dyn Progress,
    robot: &Robot,
    model: &crate::calib::MeasurementModel,
    sockets: &SocketCandidates,
    cands: &[crate::geometry::Pose],
    constraints: Constraints,
    gauge_name: &str,
) -> anyhow::Result<Designed> {
    if options.setups == 0 || options.setups > 1000 {
        return Err(usage_error("--setups must be between 1 and 1000"));
    }
    let setup = SetupOptions {
        max_readings: options.readings,
        max_setups: options.setups,
        select: SelectOptions {
            criterion: options.criterion,
            max_exchanges: 400,
            ..SelectOptions::default()
        },
        seed: options.seed,
        ..SetupOptions::default()
    };
    let d = design_setups(model, sockets, cands, &constraints, &setup, &|s| {
        progress.stage(s)
    })
    .map_err(|e| match e {
        crate::calib::CalibError::Invalid { .. } | crate::calib::CalibError::NoInformation(_) => {
            usage_error(e.to_string())
        }
        other => anyhow::Error::new(other),
    })?;
    progress.stage("writing the design");
    let dir = &options.out;
    let robot_toml = format!(
        "# {} with one sensor per setup of cpm design {} (see setup_sheet.md), the gauge\n# and the limits of the design\n\n{}",
        robot.file,
        env!("CARGO_PKG_VERSION"),
        described(options, robot, &d, gauge_name)?
    );
    let report =
        crate::report::design::LimitedDesignReport::new(robot, &d, &constraints, gauge_name);
    let mut set = OutputSet::new();
    set.add(dir.join("robot.toml"), robot_toml);
    set.add(dir.join("setup_sheet.md"), d.setup_sheet_md(&robot.table));
    set.add(dir.join("setup_sheet.csv"), tidy_csv(&d.setup_sheet_csv()));
    for (k, s) in d.setups.iter().enumerate() {
        set.add(
            dir.join("plans").join(format!("{}.csv", s.name)),
            tidy_csv(&d.setup_poses_csv(k)),
        );
    }
    set.add(dir.join("design.json"), report.to_json()?);
    stage_report(
        &mut set,
        dir,
        "cpm experiment design (instrument limits)",
        &report.markdown(),
    );
    Ok(Designed {
        outputs: set,
        inputs: inputs_of(options),
        json: report.to_json()?,
        summary: format!(
            "{} setups, {} readings; rank {} of {}; Cramér-Rao RMS {:.3} um for {} um noise; max travel {:.1} mm, min clearance {:.1} mm",
            d.setups.len(),
            d.num_readings(),
            d.indices.rank,
            d.indices.num_params,
            d.indices.crlb_rms_um,
            d.indices.sigma_um,
            d.max_travel_mm(),
            d.min_clearance_mm()
        ),
    })
}

/// The candidate poses of `options` about `robot`'s home, and what was rejected.
fn candidate_poses(
    options: &DesignJobOptions,
    robot: &Robot,
    progress: &dyn Progress,
) -> (Vec<crate::geometry::Pose>, candidates::Rejections) {
    progress.stage("candidate poses");
    candidates::default_candidates(
        &robot.table,
        &candidates::Workspace::default(),
        options.candidates,
        options.range_mm,
        options.range_deg,
        options.seed,
    )
}

/// The gauges' noise for the bounds, um: `sigma_um` (checked), else the description's, else 1.
fn gauge_sigma_um(options: &DesignJobOptions, robot: &Robot) -> anyhow::Result<f64> {
    Ok(match options.sigma_um {
        Some(s) => crate::load::sigma(Some(s), robot)?.unwrap_or(1.0),
        None => robot.sensor_noise_um().unwrap_or(1.0),
    })
}

/// Drops the known values of the sensors' own effects from `desc`: they do not carry over to
/// new sensors.
fn drop_sensor_effects(desc: &mut crate::geometry::RobotDescription) {
    if let Some(c) = desc.calibration.as_mut() {
        for e in [
            Effect::SensorOffset,
            Effect::SensorScale,
            Effect::SocketError,
        ] {
            c.known_effects.remove(e.name());
        }
    }
}

/// Stages `report.md` (`markdown`) and `report.html` in `dir`.
fn stage_report(set: &mut OutputSet, dir: &std::path::Path, title: &str, markdown: &str) {
    set.add(dir.join("report.md"), markdown);
    crate::load::stage_report_html(set, dir, title, markdown);
}

/// The job's input files, which its outputs may not replace: the description and the
/// sockets file.
fn inputs_of(options: &DesignJobOptions) -> Vec<PathBuf> {
    std::iter::once(options.robot.clone())
        .chain(options.sockets.clone())
        .collect()
}

/// The limits of a design without a gauge: the description's `[limits]` overridden by
/// `--cone-deg` and `--clearance-mm` (the defaults of [`crate::geometry::description::LimitsSpec`] for what neither gives),
/// with where they came from in words; `None` when none of them is given.
pub fn plain_limits(
    options: &DesignJobOptions,
    robot: &Robot,
) -> anyhow::Result<Option<(DesignLimits, String)>> {
    let declared = robot.description.limits;
    if declared.is_none() && options.cone_deg.is_none() && options.clearance_mm.is_none() {
        return Ok(None);
    }
    let spec = declared.unwrap_or_default();
    let mut from = Vec::new();
    if let Some(v) = options.cone_deg {
        if !(v.is_finite() && v > 0.0 && v <= 180.0) {
            return Err(usage_error(format!(
                "--cone-deg {v}: must be in (0, 180] deg"
            )));
        }
        from.push(format!("--cone-deg {v}"));
    }
    if let Some(v) = options.clearance_mm {
        if !(v.is_finite() && v >= 0.0) {
            return Err(usage_error(format!(
                "--clearance-mm {v}: must be finite and >= 0"
            )));
        }
        from.push(format!("--clearance-mm {v}"));
    }
    if let Some(l) = &declared {
        let mut what = Vec::new();
        if options.cone_deg.is_none() {
            what.push(format!(
                "base_cone_deg = {}, platform_cone_deg = {}",
                l.base_cone_deg, l.platform_cone_deg
            ));
        }
        if let Some(r) = l.link_radius_mm {
            what.push(format!("link_radius_mm = {r}"));
        }
        if let (None, Some(c)) = (options.clearance_mm, l.gauge_link_clearance_mm) {
            what.push(format!("gauge_link_clearance_mm = {c}"));
        }
        if !what.is_empty() {
            from.push(format!("[limits] {} of {}", what.join(", "), robot.file));
        }
    }
    let limits = DesignLimits {
        joints: JointLimits {
            base_cone_deg: options.cone_deg.unwrap_or(spec.base_cone_deg),
            platform_cone_deg: options.cone_deg.unwrap_or(spec.platform_cone_deg),
        },
        clearance: Clearance {
            gauge_link_mm: options.clearance_mm.unwrap_or(spec.gauge_link_mm(None)),
            link_link_mm: spec.link_link_mm(),
        },
    };
    // Limits neither the flags nor the description give: their defaults, stated.
    if options.cone_deg.is_none() && declared.is_none() {
        from.push(format!(
            "the default --cone-deg {}",
            limits.joints.base_cone_deg
        ));
    }
    let described_clearance =
        declared.is_some_and(|l| l.gauge_link_clearance_mm.is_some() || l.link_radius_mm.is_some());
    if options.clearance_mm.is_none() && !described_clearance {
        from.push(format!(
            "the default --clearance-mm {}",
            limits.clearance.gauge_link_mm
        ));
    }
    Ok(Some((limits, from.join(" and "))))
}

#[cfg(test)]
mod tests {
    use super::{design, DesignJobOptions};
    use crate::progress::Collect;
    use std::path::PathBuf;

    fn example(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples")
            .join(name)
    }

    /// The job stages every output in the output directory (writing none), with the
    /// `design.json` it returns; the summary counts what the poses file holds.
    #[test]
    fn a_design_is_staged_not_written() {
        let out = std::env::temp_dir().join(format!("cpm-design-job-{}", std::process::id()));
        let mut options = DesignJobOptions::new(example("hexapod_66.toml"), &out);
        options.readings = 60;
        let d = design(&options, &Collect::default()).unwrap();
        assert!(!out.exists(), "the job wrote {}", out.display());
        let names: Vec<String> = d
            .outputs
            .paths()
            .map(|p| p.strip_prefix(&out).unwrap().display().to_string())
            .collect();
        for f in [
            "poses.csv",
            "sockets.csv",
            "robot.toml",
            "design.json",
            "report.md",
        ] {
            assert!(names.iter().any(|n| n == f), "{f} not in {names:?}");
        }
        assert_eq!(
            d.outputs.contents(&out.join("design.json")),
            Some(d.json.as_bytes())
        );
        let poses = std::str::from_utf8(d.outputs.contents(&out.join("poses.csv")).unwrap())
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('#'))
            .count()
            - 1;
        assert!(
            d.summary.starts_with(&format!("{poses} poses x ")),
            "{}",
            d.summary
        );
        assert_eq!(d.inputs, vec![example("hexapod_66.toml")]);
        // More sockets than the description has: refused, naming where the places came from.
        options.base_sockets = 50;
        let e = design(&options, &Collect::default()).unwrap_err();
        assert!(e.to_string().contains("50 and 3 asked for"), "{e}");
    }
}
