//! `cpm design`: choose sensor sockets and poses for a calibration campaign (wraps
//! `cpm_calib::design::design`), and write the poses, the sockets and a robot description with
//! the chosen sensors.
use super::common;
use super::{input_error, usage_error, Ctx, Outcome};
use crate::calib::design::{
    candidates, design, design_setups, sockets::Socket, Constraints, DesignOptions, Gauge,
    GaugeKind, SelectOptions, SetupOptions, SocketCandidates,
};
use crate::calib::Effect;
use crate::geometry::description::{SensorSpec, SocketSide};
use crate::io::{self, table::Table, InputError, Robot};
use crate::output::OutputSet;
use crate::report::format::tidy_csv;

pub mod args;
pub mod instruments;
pub use args::{CriterionArg, DesignArgs, GaugeArg};

/// The most candidate sockets a `--sockets` file may list.
pub const MAX_SOCKETS: usize = 10_000;

/// Reads candidate sockets: `name,side,x_mm,y_mm,z_mm`.
pub fn read_sockets(text: &str, file: &str) -> Result<SocketCandidates, InputError> {
    read_sockets_from(text.as_bytes(), file).map_err(io::ReadError::into_input)
}

/// Reads candidate sockets from a reader, row by row.
pub fn read_sockets_from<R: std::io::Read>(
    source: R,
    file: &str,
) -> Result<SocketCandidates, io::ReadError> {
    let mut t = Table::from_reader(source, file)?;
    sockets_table(&mut t).map_err(|e| match t.take_io_error() {
        Some(source) => io::ReadError::Io {
            file: file.to_string(),
            source,
        },
        None => e.into(),
    })
}

/// Columns of the socket-pair format `cpm design` writes as `sockets.csv`.
pub const SOCKET_PAIR_COLUMNS: [&str; 7] = [
    "name",
    "base_x_mm",
    "base_y_mm",
    "base_z_mm",
    "platform_x_mm",
    "platform_y_mm",
    "platform_z_mm",
];

fn sockets_table<R: std::io::Read>(t: &mut Table<R>) -> Result<SocketCandidates, InputError> {
    if t.has("base_x_mm") && !t.has("side") {
        return socket_pairs_table(t);
    }
    t.check_columns(&["name", "side", "x_mm", "y_mm", "z_mm"], &[], |_| false)?;
    let mut c = SocketCandidates {
        base: Vec::new(),
        platform: Vec::new(),
    };
    let mut seen: std::collections::HashMap<(String, bool), usize> = Default::default();
    while let Some(row) = t.next_row()? {
        let t: &io::table::Header = t;
        if c.base.len() + c.platform.len() >= MAX_SOCKETS {
            return Err(InputError::line(
                &t.file,
                row.line,
                format!("more than {MAX_SOCKETS} candidate sockets"),
            ));
        }
        let name = t.required_text(&row, "name")?;
        let p = [
            t.number(&row, "x_mm")?,
            t.number(&row, "y_mm")?,
            t.number(&row, "z_mm")?,
        ];
        let base = match t.required_text(&row, "side")? {
            "base" => true,
            "platform" => false,
            other => {
                return Err(t.err(
                    &row,
                    "side",
                    format!(
                        "{:?} is neither base nor platform",
                        io::table::shorten(other)
                    ),
                ))
            }
        };
        if let Some(first) = seen.insert((name.to_string(), base), row.line) {
            return Err(t.err(
                &row,
                "name",
                format!(
                    "socket {:?} is already on line {first} (names are unique on each side)",
                    io::table::shorten(name)
                ),
            ));
        }
        if base {
            c.base.push(Socket::new(name, p));
        } else {
            c.platform.push(Socket::new(name, p));
        }
    }
    if c.base.is_empty() && c.platform.is_empty() {
        return Err(InputError::file(
            &t.file,
            "no sockets: the file has a header but no rows",
        ));
    }
    Ok(c)
}

/// The socket-pair format (`cpm design`'s `sockets.csv`): each distinct base and platform
/// position of the pairs is a candidate place, named `b1, b2, ...` and `p1, p2, ...` in order
/// of first appearance.
fn socket_pairs_table<R: std::io::Read>(t: &mut Table<R>) -> Result<SocketCandidates, InputError> {
    t.check_columns(&SOCKET_PAIR_COLUMNS, &[], |_| false)?;
    let mut c = SocketCandidates {
        base: Vec::new(),
        platform: Vec::new(),
    };
    let mut rows = 0usize;
    while let Some(row) = t.next_row()? {
        let t: &io::table::Header = t;
        rows += 1;
        if rows > MAX_SOCKETS {
            return Err(InputError::line(
                &t.file,
                row.line,
                format!("more than {MAX_SOCKETS} socket pairs"),
            ));
        }
        t.required_text(&row, "name")?;
        for (list, prefix) in [(&mut c.base, "base"), (&mut c.platform, "platform")] {
            let p = [
                t.number(&row, &format!("{prefix}_x_mm"))?,
                t.number(&row, &format!("{prefix}_y_mm"))?,
                t.number(&row, &format!("{prefix}_z_mm"))?,
            ];
            let v = nalgebra::Vector3::from(p);
            if !list.iter().any(|s| (s.position_mm - v).norm() < 1e-9) {
                let name = format!("{}{}", &prefix[..1], list.len() + 1);
                list.push(Socket::new(&name, p));
            }
        }
    }
    if rows == 0 {
        return Err(InputError::file(
            &t.file,
            "no sockets: the file has a header but no rows",
        ));
    }
    Ok(c)
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
        if !c
            .base
            .iter()
            .any(|b| (b.position_mm - s.base_mm).norm() < 1e-9)
        {
            let name = format!("b{}", c.base.len() + 1);
            c.base.push(Socket::new(&name, s.base_mm.into()));
        }
        if !c
            .platform
            .iter()
            .any(|p| (p.position_mm - s.platform_mm).norm() < 1e-9)
        {
            let name = format!("p{}", c.platform.len() + 1);
            c.platform.push(Socket::new(&name, s.platform_mm.into()));
        }
    }
    c
}

/// Runs `cpm design`.
pub fn run(args: &DesignArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    common::check_out_dir(&args.out)?;
    ctx.stage("reading the robot description");
    let robot = common::load_robot(&args.robot.robot, ctx)?;
    common::require_six_links(&robot)?;
    if let Some(list) = &args.instruments {
        let sigma = match args.sigma_um {
            Some(s) => common::sigma(Some(s), &robot)?.unwrap_or(1.0),
            None => robot.sensor_noise_um().unwrap_or(1.0),
        };
        return instruments::run(args, list, &robot, sigma, ctx);
    }
    let sockets = match &args.sockets {
        Some(p) => read_sockets_from(io::campaign::open(p)?, &p.display().to_string())?,
        None => sockets_of(&robot),
    };
    let limits = limited_constraints(args, &robot)?;
    if sockets.base.len() < args.base_sockets || sockets.platform.len() < args.platform_sockets {
        return Err(input_error(format!(
            "{} base and {} platform socket places to choose from ({}), {} and {} asked for: give more places with --sockets FILE or ask for fewer",
            sockets.base.len(),
            sockets.platform.len(),
            args.sockets.as_ref().map_or_else(
                || {
                    if robot.description.socket_places().is_empty() {
                        format!("the [[sensor]] tables of {}", robot.file)
                    } else {
                        format!("the [[socket]] and [[socket_region]] tables of {}", robot.file)
                    }
                },
                |p| p.display().to_string()
            ),
            args.base_sockets,
            args.platform_sockets
        )));
    }
    if args.candidates == 0
        || !(args.range_mm > 0.0 && args.range_deg >= 0.0)
        || !(args.range_mm.is_finite() && args.range_deg.is_finite())
    {
        return Err(usage_error(
            "--candidates must be >= 1 and --range-mm > 0, --range-deg >= 0 (finite)",
        ));
    }
    for (n, name, max) in [
        (args.candidates, "--candidates", 100_000),
        (args.readings, "--readings", 10_000_000),
        (args.poses.unwrap_or(0), "--poses", 1_000_000),
    ] {
        if n > max {
            return Err(usage_error(format!("{name} {n}: at most {max}")));
        }
    }
    let sigma = match args.sigma_um {
        Some(s) => common::sigma(Some(s), &robot)?.unwrap_or(1.0),
        None => robot.sensor_noise_um().unwrap_or(1.0),
    };
    let model = robot.model(&[]);
    ctx.stage("candidate poses");
    let (cands, rejected) = candidates::default_candidates(
        &robot.table,
        &candidates::Workspace::default(),
        args.candidates,
        args.range_mm,
        args.range_deg,
        args.seed,
    );
    if cands.is_empty() {
        return Err(usage_error(format!(
            "no admissible candidate pose ({} rejected): try a smaller --range-mm or --range-deg",
            rejected.total()
        )));
    }
    if let Some((constraints, gauge_name)) = limits {
        return run_limited(
            args,
            ctx,
            &robot,
            &model,
            &sockets,
            &cands,
            constraints,
            &gauge_name,
        );
    }
    let plain = args::plain_limits(args, &robot)?;
    let options = DesignOptions {
        limits: plain.as_ref().map(|(l, _)| *l),
        max_readings: args.readings,
        base_sockets: args.base_sockets,
        platform_sockets: args.platform_sockets,
        poses: args.poses,
        select: SelectOptions {
            criterion: args.criterion.criterion(),
            ..SelectOptions::default()
        },
        sigma_um: sigma,
        ..DesignOptions::default()
    };
    let d = design(&model, &sockets, &cands, &options, &|s| {
        ctx.stage(s.to_string())
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
    ctx.stage("writing the design");
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
    if let Some(c) = desc.calibration.as_mut() {
        for e in [
            Effect::SensorOffset,
            Effect::SensorScale,
            Effect::SocketError,
        ] {
            c.known_effects.remove(e.name());
        }
    }
    let robot_toml = format!(
        "# {} with the sensors chosen by cpm design {}\n\n{}",
        robot.file,
        env!("CARGO_PKG_VERSION"),
        desc.to_toml_string()?
    );
    let dir = &args.out;
    let report = crate::report::design::DesignReport::new(&robot.file, &d);
    let mut set = OutputSet::new();
    set.add(
        dir.join("poses.csv"),
        tidy_csv(&io::write_pose_list(&d.poses)),
    );
    set.add(dir.join("sockets.csv"), tidy_csv(&d.sockets_csv()));
    set.add(dir.join("robot.toml"), robot_toml);
    set.add(dir.join("design.json"), report.to_json()?);
    let written = commit_design(
        set,
        dir,
        args,
        "cpm experiment design",
        &report.markdown(),
        ctx,
    )?;
    ctx.finish();
    if args.json {
        writeln!(ctx.out, "{}", report.to_json()?)?;
    } else {
        writeln!(
            ctx.out,
            "{} poses x {} socket pairs = {} readings; rank {} of {}; Cramér-Rao RMS {:.3} um for {} um noise",
            d.poses.len(),
            d.sensors.len(),
            d.num_readings(),
            d.indices.rank,
            d.indices.num_params,
            d.indices.crlb_rms_um,
            d.indices.sigma_um
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}

// ---- Design under an instrument's limits (--stroke-mm) -------------------------------------

/// The description `robot` with one sensor per setup of `design` instead of its own, the
/// gauge and the limits (known sensor effects dropped).
fn described(
    args: &DesignArgs,
    robot: &Robot,
    design: &crate::calib::design::SetupDesign,
    gauge_name: &str,
) -> anyhow::Result<String> {
    let mut desc = robot.description.clone();
    design.describe(&mut desc, gauge_name);
    // A noise nobody declared (the bounds' default of 1 um) is not written as the gauge's.
    let declared = args.sigma_um.is_some()
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
    if let Some(c) = desc.calibration.as_mut() {
        for e in [
            Effect::SensorOffset,
            Effect::SensorScale,
            Effect::SocketError,
        ] {
            c.known_effects.remove(e.name());
        }
    }
    Ok(desc.to_toml_string()?)
}

/// The limits of a design under limits: the description's `[[gauge]]` (`--gauge-name`, else
/// its first) and `[limits]`, overridden by the flags; `None` (the unconstrained design) when
/// neither `--stroke-mm` nor a `[[gauge]]` is given. Also the gauge's name in the written
/// description.
fn limited_constraints(
    args: &DesignArgs,
    robot: &Robot,
) -> anyhow::Result<Option<(Constraints, String)>> {
    let declared = Constraints::from_description(&robot.description, args.gauge_name.as_deref())
        .map_err(|e| usage_error(format!("--gauge-name: {e}")))?;
    if declared.is_none() && args.stroke_mm.is_none() {
        return Ok(None);
    }
    let name = match (&declared, &args.gauge_name) {
        (_, Some(n)) => n.clone(),
        (Some(_), None) => robot.description.gauges[0].name.clone(),
        (None, None) => "gauge".to_string(),
    };
    let mut c = declared.unwrap_or_else(|| {
        let gauge = match args.gauge {
            Some(GaugeArg::Ballbar) => Gauge::ballbar(),
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
    if let Some(k) = args.gauge {
        c.gauge.kind = match k {
            GaugeArg::Telescoping => GaugeKind::Telescoping,
            GaugeArg::Ballbar => GaugeKind::Ballbar,
        };
    }
    if let Some(v) = args.stroke_mm {
        c.gauge.stroke_mm = v;
    }
    if let Some(v) = args.shortest_mm {
        c.gauge.shortest_mm = v;
    }
    if let Some(v) = args.longest_mm {
        c.gauge.longest_mm = v;
    }
    if !args.bars_mm.is_empty() {
        c.gauge.bars_mm = args.bars_mm.clone();
    }
    if let Some(v) = args.sigma_um {
        c.gauge.sigma_um = common::sigma(Some(v), robot)?.unwrap_or(v);
    }
    if let Some(v) = args.clearance_mm {
        c.clearance.gauge_link_mm = v;
    }
    if let Some(v) = args.cone_deg {
        c.joints.base_cone_deg = v;
        c.joints.platform_cone_deg = v;
    }
    c.validate().map_err(|e| usage_error(e.to_string()))?;
    Ok(Some((c, name)))
}

#[allow(clippy::too_many_arguments)]
fn run_limited(
    args: &DesignArgs,
    ctx: &mut Ctx<'_>,
    robot: &Robot,
    model: &crate::calib::MeasurementModel,
    sockets: &SocketCandidates,
    cands: &[crate::geometry::Pose],
    constraints: Constraints,
    gauge_name: &str,
) -> anyhow::Result<Outcome> {
    if args.setups == 0 || args.setups > 1000 {
        return Err(usage_error("--setups must be between 1 and 1000"));
    }
    let options = SetupOptions {
        max_readings: args.readings,
        max_setups: args.setups,
        select: SelectOptions {
            criterion: args.criterion.criterion(),
            max_exchanges: 400,
            ..SelectOptions::default()
        },
        seed: args.seed,
        ..SetupOptions::default()
    };
    let d = design_setups(model, sockets, cands, &constraints, &options, &|s| {
        ctx.stage(s.to_string())
    })
    .map_err(|e| match e {
        crate::calib::CalibError::Invalid { .. } | crate::calib::CalibError::NoInformation(_) => {
            usage_error(e.to_string())
        }
        other => anyhow::Error::new(other),
    })?;
    ctx.stage("writing the design");
    let dir = &args.out;
    let robot_toml = format!(
        "# {} with one sensor per setup of cpm design {} (see setup_sheet.md), the gauge\n# and the limits of the design\n\n{}",
        robot.file,
        env!("CARGO_PKG_VERSION"),
        described(args, robot, &d, gauge_name)?
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
    let written = commit_design(
        set,
        dir,
        args,
        "cpm experiment design (instrument limits)",
        &report.markdown(),
        ctx,
    )?;
    ctx.finish();
    if args.json {
        writeln!(ctx.out, "{}", report.to_json()?)?;
    } else {
        writeln!(
            ctx.out,
            "{} setups, {} readings; rank {} of {}; Cramér-Rao RMS {:.3} um for {} um noise; max travel {:.1} mm, min clearance {:.1} mm",
            d.setups.len(),
            d.num_readings(),
            d.indices.rank,
            d.indices.num_params,
            d.indices.crlb_rms_um,
            d.indices.sigma_um,
            d.max_travel_mm(),
            d.min_clearance_mm()
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    Ok(Outcome::Done)
}

/// Stages `report.md` (`markdown`) and `report.html` and commits the design's result
/// directory (the robot and the sockets file are inputs it may not replace).
fn commit_design(
    mut set: OutputSet,
    dir: &std::path::Path,
    args: &DesignArgs,
    title: &str,
    markdown: &str,
    ctx: &Ctx<'_>,
) -> anyhow::Result<Vec<std::path::PathBuf>> {
    set.add(dir.join("report.md"), markdown);
    common::stage_report_html(&mut set, dir, title, markdown);
    let inputs: Vec<&std::path::Path> = std::iter::once(args.robot.robot.as_path())
        .chain(args.sockets.as_deref())
        .collect();
    common::commit_dir(set, dir, &inputs, "design", ctx)
}
