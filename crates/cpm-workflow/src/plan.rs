//! Plans of poses before measuring: a pose list file, a circle about home or random
//! well-conditioned poses ([`PlanOptions`], [`build_plan`]), with the sensors read at every
//! pose. `cpm identifiability` analyses a plan, `cpm simulate` measures one.
use std::path::PathBuf;

use crate::calib::{campaign::circle, Plan};
use crate::error::{input_error, usage_error};
use crate::io::rows::PoseRows;
use crate::io::{self, ReadOptions, Robot};

/// Where the poses of a plan come from: exactly one of [`plan`](Self::plan),
/// [`circle`](Self::circle) and [`random`](Self::random). [`PlanOptions::default`] gives the
/// defaults (no source; a circle of 36 poses of radius 100 mm; random poses within 50 mm and
/// 10 degrees of home; every sensor; seed 1).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanOptions {
    /// A CSV list of poses (`--plan`); default `None`.
    pub plan: Option<PathBuf>,
    /// Poses on a circle about home in its xy plane at the home orientation (`--circle`);
    /// default `false`.
    pub circle: bool,
    /// This many random poses about home, well conditioned and within the link limits
    /// (`--random`); default `None`.
    pub random: Option<usize>,
    /// Radius of the circle, mm; default 100.
    pub radius_mm: f64,
    /// Number of poses of the circle; default 36.
    pub count: usize,
    /// Half range of the random positions about home, mm; default 50.
    pub range_mm: f64,
    /// Half range of the random roll, pitch and yaw about home, degrees; default 10.
    pub range_deg: f64,
    /// Sensors read at every pose, by name; default empty: every sensor of the robot.
    pub sensors: Vec<String>,
    /// Random seed (random poses, simulated noise); default 1.
    pub seed: u64,
}

impl Default for PlanOptions {
    fn default() -> Self {
        Self {
            plan: None,
            circle: false,
            random: None,
            radius_mm: 100.0,
            count: 36,
            range_mm: 50.0,
            range_deg: 10.0,
            sensors: Vec::new(),
            seed: 1,
        }
    }
}

impl PlanOptions {
    /// True when a source of poses is given.
    pub fn given(&self) -> bool {
        self.plan.is_some() || self.circle || self.random.is_some()
    }
}

/// A plan with per-pose time and temperature (from a plan file).
#[derive(Debug, Clone)]
pub struct PlanSpec {
    /// The plan.
    pub plan: Plan,
    /// Per pose: time (s) and temperature (deg C) when the plan file gives them.
    pub conditions: Vec<(Option<f64>, Option<f64>)>,
}

impl PlanSpec {
    /// The plan's campaign skeleton, with the plan file's times and temperatures.
    pub fn skeleton(&self) -> crate::calib::Campaign {
        let mut c = self.plan.skeleton();
        for r in c.readings.iter_mut() {
            let (t, temp) = self.conditions[r.pose];
            r.time_s = t.into();
            r.temperature_c = temp.into();
        }
        c
    }
}

/// The sensors `names` (all when empty) as indices.
pub fn sensor_indices(names: &[String], robot: &Robot) -> anyhow::Result<Vec<usize>> {
    if robot.table.sensors.is_empty() {
        return Err(input_error(format!(
            "{}: the robot description has no [[sensor]]: nothing to read",
            robot.file
        )));
    }
    if names.is_empty() {
        return Ok((0..robot.table.sensors.len()).collect());
    }
    names
        .iter()
        .map(|n| {
            robot.table.sensor_index(n.trim()).ok_or_else(|| {
                usage_error(format!(
                    "--sensors: unknown sensor {:?} (the robot description has: {})",
                    n.trim(),
                    robot.sensor_names()
                ))
            })
        })
        .collect()
}

/// The largest number of poses of a circle and of random poses.
pub const MAX_PLAN_POSES: usize = 1_000_000;

/// Builds the plan of `args` (exactly one source must be given); with `need_sensors`, the
/// sensors read at every pose are resolved and the poses checked against their gauges.
///
/// ```
/// use cpm_workflow::plan::{build_plan, PlanOptions};
///
/// let robot = cpm_workflow::io::Robot::load(std::path::Path::new("../../examples/hexapod_66.toml"))?;
/// let options = PlanOptions { circle: true, count: 12, ..PlanOptions::default() };
/// let spec = build_plan(&options, &robot, true)?;
/// assert_eq!(spec.plan.poses.len(), 12);
/// assert_eq!(spec.plan.sensors.len(), robot.table.sensors.len());
/// # Ok::<(), anyhow::Error>(())
/// ```
pub fn build_plan(
    args: &PlanOptions,
    robot: &Robot,
    need_sensors: bool,
) -> anyhow::Result<PlanSpec> {
    build_plan_in(args, None, robot, need_sensors)
}

/// [`build_plan`] with the poses of the plan file held in memory (`poses`, read with the
/// file's checks: [`crate::sources::pose_list`]) in place of the file `args.plan` names; the
/// plan is then given by them.
pub fn build_plan_in(
    args: &PlanOptions,
    poses: Option<&PoseRows>,
    robot: &Robot,
    need_sensors: bool,
) -> anyhow::Result<PlanSpec> {
    let from_list = args.plan.is_some() || poses.is_some();
    let given = [from_list, args.circle, args.random.is_some()]
        .iter()
        .filter(|g| **g)
        .count();
    if given != 1 {
        return Err(usage_error(
            "give the poses with exactly one of --plan FILE, --circle or --random N",
        ));
    }
    let sensors = if need_sensors {
        sensor_indices(&args.sensors, robot)?
    } else {
        Vec::new()
    };
    let table = &robot.table;
    let ratio = ReadOptions::default().max_condition_ratio;
    for (n, name) in [
        (args.random.unwrap_or(0), "--random"),
        (if args.circle { args.count } else { 0 }, "--count"),
    ] {
        if n > MAX_PLAN_POSES {
            return Err(usage_error(format!(
                "{name} {n}: at most {MAX_PLAN_POSES} poses"
            )));
        }
    }
    if from_list {
        let path = args.plan.clone().unwrap_or_default();
        let (rows, file) = crate::sources::pose_list(&path, poses)?;
        io::campaign::check_pose_list_units(&rows, &file, robot)?;
        for r in &rows {
            io::campaign::check_reachable(table, &r.pose, ratio, &file, r.line, &r.label)?;
        }
        let poses: Vec<_> = rows.iter().map(|r| r.pose).collect();
        crate::gauges::check_plan(robot, &sensors, &poses, &|k| (file.clone(), rows[k].line))?;
        return Ok(PlanSpec {
            conditions: rows.iter().map(|r| (r.time_s, r.temperature_c)).collect(),
            plan: Plan {
                poses: rows.iter().map(|r| r.pose).collect(),
                sensors,
            },
        });
    }
    let poses = if args.circle {
        if !(args.radius_mm.is_finite() && args.radius_mm >= 0.0) || args.count == 0 {
            return Err(usage_error(
                "--circle needs --radius-mm >= 0 and --count >= 1",
            ));
        }
        let poses = circle(&table.home, args.radius_mm, args.count);
        for (k, p) in poses.iter().enumerate() {
            io::campaign::check_reachable(table, p, ratio, "--circle", k + 1, &(k + 1).to_string())
                .map_err(|e| usage_error(format!("{}; try a smaller --radius-mm", e.message)))?;
        }
        poses
    } else {
        let n = args.random.unwrap_or(0);
        if n == 0
            || !(args.range_mm >= 0.0 && args.range_deg >= 0.0)
            || !(args.range_mm.is_finite() && args.range_deg.is_finite())
        {
            return Err(usage_error(
                "--random needs N >= 1 and finite, non-negative --range-mm, --range-deg",
            ));
        }
        let poses = crate::calib::paper::random_workspace_poses(
            table,
            n,
            args.range_mm,
            args.range_deg,
            3.0,
            args.seed,
        );
        if poses.len() < n {
            return Err(usage_error(format!(
                "--random: found only {} of {n} well-conditioned poses within the link limits; try a smaller --range-mm or --range-deg",
                poses.len()
            )));
        }
        poses
    };
    let how = if args.circle { "--circle" } else { "--random" };
    crate::gauges::check_plan(robot, &sensors, &poses, &|k| (how.to_string(), k + 1))
        .map_err(|e| usage_error(e.to_string()))?;
    Ok(PlanSpec {
        conditions: vec![(None, None); poses.len()],
        plan: Plan { poses, sensors },
    })
}
