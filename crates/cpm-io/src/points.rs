//! Instrument files: a laser tracker's 3-D points of the reflectors (`[[target]]`)
//! on the platform, one row per target per pose, in the tracker's frame, and inclinometer
//! angles (`[[inclinometer]]`), one row per instrument per pose (`docs/formats.md`).
//!
//! Each file is a session. The reader parses and checks it (units included) and returns the
//! points as measured, in the tracker's frame ([`DataFile::point_frame`] `None`): registering
//! the session roughly (the rigid frame that best takes the nominal targets at the commanded
//! poses onto the measured points, [`cpm_calib::points::rough_frame`], applied to the points so
//! that the fit's `point_frame` of the session is a small correction) is a fit, made on the fit
//! side (`cpm_workflow::ingest`).
use std::collections::HashMap;
use std::io::Read;

use cpm_calib::{Campaign, PointMeasurement, TiltMeasurement};
use cpm_geometry::{Pose, Vector3};

use crate::campaign::{
    check_pose_cell, exclude_poses, link_reading_columns, link_readings, opt, simulated_header,
    too_many_rows, DataFile, ReadOptions, Unusable,
};
use crate::table::{field, num, shorten, show, FileKind, Header, Row, Table};
use crate::{InputError, Robot};

/// Columns of the commanded pose in a point file (the measured point takes `x_mm, y_mm,
/// z_mm`).
pub const COMMANDED_COLUMNS: [&str; 6] = [
    "cmd_x_mm",
    "cmd_y_mm",
    "cmd_z_mm",
    "cmd_roll_deg",
    "cmd_pitch_deg",
    "cmd_yaw_deg",
];

/// What one pose of a point file says about the commanded configuration.
struct PoseOf {
    line: usize,
    commanded: Option<Pose>,
    readings: Option<Vec<f64>>,
}

fn commanded_pose(t: &Header, row: &Row) -> Result<Option<Pose>, InputError> {
    if !t.has(COMMANDED_COLUMNS[0]) {
        return Ok(None);
    }
    let mut v = [0.0; 6];
    for (k, c) in COMMANDED_COLUMNS.iter().enumerate() {
        v[k] = t.number(row, c)?;
        check_pose_cell(t, row, c, v[k])?;
    }
    Ok(Some(Pose::from_xyz_rpy_deg(
        [v[0], v[1], v[2]],
        [v[3], v[4], v[5]],
    )))
}

fn agree(a: &PoseOf, b: &PoseOf) -> Option<String> {
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-6 + 1e-9 * x.abs().max(y.abs());
    if let (Some(p), Some(q)) = (&a.commanded, &b.commanded) {
        for k in 0..3 {
            if !close(p.position_mm[k], q.position_mm[k]) {
                return Some(COMMANDED_COLUMNS[k].to_string());
            }
        }
        if (p.rotation.matrix() - q.rotation.matrix()).amax() > 1e-9 {
            return Some("cmd_roll_deg".to_string());
        }
    }
    if let (Some(u), Some(w)) = (&a.readings, &b.readings) {
        if let Some(i) = u.iter().zip(w).position(|(x, y)| !close(*x, *y)) {
            return Some(format!("reading_{}", i + 1));
        }
    }
    None
}

/// The most axes an inclinometer has (`angle_1_deg` .. `angle_3_deg`).
pub const MAX_TILT_AXES: usize = 3;

/// The largest inclinometer angle, deg: an angle is the elevation of an axis above the
/// horizontal, within +-90 deg; a value beyond is refused as impossible (not flagged as a
/// glitch for the fit).
pub const MAX_TILT_DEG: f64 = 90.0;

/// A tilt file whose angles spread less than this fraction of the spread the commanded poses
/// give (over at least [`TILT_UNITS_MIN_DEG`]) is refused as radians: radians spread 57 times
/// less than degrees, a real instrument follows the commanded tilts to a few per cent.
pub const TILT_UNITS_RATIO: f64 = 0.1;

/// The commanded spread of an angle, deg, from which [`TILT_UNITS_RATIO`] applies.
pub const TILT_UNITS_MIN_DEG: f64 = 1.0;

/// Measured points that spread less than this fraction of the spread of the nominal targets
/// at the commanded poses (over at least [`POINT_UNITS_MIN_MM`]) are refused as metres; more
/// than its inverse, as another unit (positions are in mm).
pub const POINT_UNITS_RATIO: f64 = 0.01;

/// The commanded spread of the targets, mm, from which [`POINT_UNITS_RATIO`] applies.
pub const POINT_UNITS_MIN_MM: f64 = 1.0;

/// What an instrument file holds: the name column, the instruments the description declares
/// and the measured columns.
struct Instrument<'a> {
    /// `target` or `inclinometer`.
    column: &'static str,
    /// `[[target]]` or `[[inclinometer]]`.
    table: &'static str,
    names: Vec<&'a str>,
    /// Measured columns (all required for points; the angles for tilts, cells may be empty).
    measured: Vec<String>,
    points: bool,
}

/// Reads a point measurement file from its table (see the module doc).
pub(crate) fn read_point_measurements_table<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let instrument = Instrument {
        column: "target",
        table: "[[target]]",
        names: robot
            .description
            .targets
            .iter()
            .map(|s| s.name.as_str())
            .collect(),
        measured: ["x_mm", "y_mm", "z_mm"].map(String::from).to_vec(),
        points: true,
    };
    read_instrument_table(t, robot, options, &instrument)
}

/// Reads an inclinometer file from its table: `pose`, `inclinometer`, `angle_1_deg` ..
/// (degrees; an empty cell is an angle not measured), the commanded link readings or pose.
pub(crate) fn read_tilt_measurements_table<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    let axes: Vec<String> = (1..=MAX_TILT_AXES)
        .map(|k| format!("angle_{k}_deg"))
        .filter(|c| t.has(c))
        .collect();
    // The angles are numbered from 1 without a gap: angle_2_deg without angle_1_deg is a
    // column lost (or misnamed), never a file whose first axis is simply not logged.
    if let Some(k) = (1..=axes.len()).find(|k| !t.has(&format!("angle_{k}_deg"))) {
        return Err(InputError::field(
            &t.file,
            t.header_line,
            format!("angle_{k}_deg"),
            format!(
                "missing column: an inclinometer file gives angle_1_deg, angle_2_deg, ... in order (one per axis of its [[inclinometer]], degrees); it has {} but not angle_{k}_deg",
                axes.join(", ")
            ),
        ));
    }
    let instrument = Instrument {
        column: "inclinometer",
        table: "[[inclinometer]]",
        names: robot
            .description
            .inclinometers
            .iter()
            .map(|s| s.name.as_str())
            .collect(),
        measured: axes,
        points: false,
    };
    read_instrument_table(t, robot, options, &instrument)
}

/// Checks the header of an instrument file: the required and known columns, an angle
/// column for a tilt file, the commanded configuration (link readings or all six commanded
/// pose columns), instruments declared. Returns whether the link readings are logged.
fn check_instrument_header<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    instrument: &Instrument,
    what: &str,
) -> Result<bool, InputError> {
    let n = robot.num_links();
    let mut required = vec!["pose", instrument.column];
    if instrument.points {
        required.extend(["x_mm", "y_mm", "z_mm"]);
    }
    t.check_columns(&required, &["time_s", "simulated"], |h| {
        COMMANDED_COLUMNS.contains(&h)
            || crate::table::reading_index(h).is_some()
            || (!instrument.points && instrument.measured.iter().any(|c| c == h))
    })?;
    if instrument.measured.is_empty() {
        return Err(InputError::field(
            &t.file,
            t.header_line,
            "angle_1_deg",
            "missing column: an inclinometer file gives angle_1_deg (and angle_2_deg, ...: one per axis, degrees)",
        ));
    }
    let has_readings = link_reading_columns(t, n)?;
    let cmd = COMMANDED_COLUMNS.iter().filter(|c| t.has(c)).count();
    if cmd != 0 && cmd != 6 {
        let missing = COMMANDED_COLUMNS.iter().find(|c| !t.has(c)).expect("one");
        return Err(InputError::field(
            &t.file,
            t.header_line,
            *missing,
            "missing column: the commanded pose takes all of cmd_x_mm, cmd_y_mm, cmd_z_mm, cmd_roll_deg, cmd_pitch_deg, cmd_yaw_deg",
        ));
    }
    if cmd == 0 && !has_readings {
        return Err(InputError::line(
            &t.file,
            t.header_line,
            format!(
                "a {what} file needs the commanded configuration: reading_1..reading_{n} columns (the link readings) or cmd_x_mm, cmd_y_mm, cmd_z_mm, cmd_roll_deg, cmd_pitch_deg, cmd_yaw_deg (the commanded pose)"
            ),
        ));
    }
    if instrument.names.is_empty() {
        return Err(InputError::field(
            &t.file,
            t.header_line,
            instrument.column,
            format!(
                "{} declares no {}: {what} measurements need them in the robot description",
                robot.file, instrument.table
            ),
        ));
    }
    Ok(has_readings)
}

/// The commanded configuration of each pose, pushed to `campaign.poses`: the logged link
/// readings drive the machine (the commanded pose, or forward kinematics of the commanded
/// lengths on the design geometry ([`Robot::design_table`], as for a tracker row), starts
/// forward kinematics); without readings the controller's inverse kinematics of the commanded
/// pose. Returns the commanded lengths and the poses whose link readings give none (excluded,
/// or the file refused when too many).
fn commanded_configurations(
    poses: &[PoseOf],
    robot: &Robot,
    campaign: &mut Campaign,
) -> (Vec<Vec<f64>>, Vec<Unusable>) {
    // The design, never the robot's installation errors: a calibrated description reads
    // the file to the commanded poses the fit saw (where the link forces are evaluated).
    let design = robot.design_table();
    let mut commanded: Vec<Vec<f64>> = Vec::new();
    // Poses whose link readings give none: excluded, or the file refused when too many.
    let mut unusable = Vec::new();
    for (j, p) in poses.iter().enumerate() {
        let pose = match (&p.commanded, &p.readings) {
            (Some(c), _) => *c,
            (None, Some(u)) => {
                let l: Vec<f64> = u
                    .iter()
                    .enumerate()
                    .map(|(i, v)| robot.length_mm(i, *v))
                    .collect();
                match cpm_kinematics::forward(
                    &design,
                    &l,
                    &design.home,
                    &cpm_kinematics::ForwardOptions::default(),
                ) {
                    Ok((pose, _)) => pose,
                    Err(e) => {
                        unusable.push(Unusable {
                            pose: j,
                            what: format!(
                                "gives no pose: forward kinematics of its link readings: {e} (wrong units or link mapping?)"
                            ),
                            note: String::new(),
                            field: Some("reading_1".to_string()),
                        });
                        design.home
                    }
                }
            }
            (None, None) => unreachable!("checked with the header"),
        };
        campaign.poses.push(pose);
        if let Some(u) = &p.readings {
            commanded.push(
                u.iter()
                    .enumerate()
                    .map(|(i, v)| robot.length_mm(i, *v))
                    .collect::<Vec<f64>>(),
            );
        }
    }
    (commanded, unusable)
}

fn read_instrument_table<R: Read>(
    t: &mut Table<R>,
    robot: &Robot,
    options: &ReadOptions,
    instrument: &Instrument,
) -> Result<DataFile, InputError> {
    let n = robot.num_links();
    let what = if instrument.points { "point" } else { "tilt" };
    let has_readings = check_instrument_header(t, robot, instrument, what)?;
    let index_of: HashMap<&str, usize> = instrument
        .names
        .iter()
        .enumerate()
        .map(|(i, s)| (*s, i))
        .collect();
    let mut campaign = Campaign {
        simulated: t.simulated_mark,
        ..Campaign::default()
    };
    let mut poses: Vec<PoseOf> = Vec::new();
    let mut index: HashMap<String, usize> = HashMap::new();
    let mut labels = Vec::new();
    let mut lines = Vec::new();
    let mut rows = 0;
    let mut seen: HashMap<(usize, usize), usize> = HashMap::new();
    while let Some(row) = t.next_row()? {
        let t: &Header = t;
        if rows >= options.max_rows {
            return Err(too_many_rows(t, &row, options.max_rows));
        }
        rows += 1;
        let label = t.required_text(&row, "pose")?.to_string();
        let name = t.required_text(&row, instrument.column)?;
        let Some(&which) = index_of.get(name) else {
            return Err(t.err(
                &row,
                instrument.column,
                format!(
                    "unknown {} {:?} (the robot description's {} names: {})",
                    instrument.column,
                    shorten(name),
                    instrument.table,
                    instrument.names.join(", ")
                ),
            ));
        };
        let mut values = Vec::with_capacity(instrument.measured.len());
        for c in &instrument.measured {
            let v = if instrument.points {
                Some(t.number(&row, c)?)
            } else {
                t.optional_number(&row, c)?
            };
            if let Some(v) = v {
                check_pose_cell(t, &row, c, v)?;
                if !instrument.points && !(v.abs() <= MAX_TILT_DEG) {
                    return Err(t.err(
                        &row,
                        c,
                        format!(
                            "{v} degrees: an inclinometer angle (the elevation of its axis above the horizontal) is within [-{MAX_TILT_DEG}, {MAX_TILT_DEG}] degrees"
                        ),
                    ));
                }
            }
            values.push(v);
        }
        if !instrument.points {
            let axes = robot.description.inclinometers[which].axes.len();
            if let Some(k) = values.iter().skip(axes).position(Option::is_some) {
                return Err(t.err(
                    &row,
                    &instrument.measured[axes + k],
                    format!(
                        "inclinometer {:?} has {axes} axes in the robot description: this angle has none",
                        shorten(name)
                    ),
                ));
            }
        }
        let this = PoseOf {
            line: row.line,
            commanded: commanded_pose(t, &row)?,
            readings: if has_readings {
                Some(link_readings(t, &row, n)?)
            } else {
                None
            },
        };
        let j = match index.get(&label) {
            Some(&j) => {
                if let Some(f) = agree(&poses[j], &this) {
                    return Err(t.err(
                        &row,
                        &f,
                        format!(
                            "pose {:?} was commanded otherwise on line {}: the rows of one pose share its commanded pose and link readings",
                            shorten(&label),
                            poses[j].line
                        ),
                    ));
                }
                j
            }
            None => {
                index.insert(label.clone(), poses.len());
                labels.push(label.clone());
                poses.push(this);
                poses.len() - 1
            }
        };
        if let Some(first) = seen.insert((j, which), row.line) {
            return Err(t.err(
                &row,
                instrument.column,
                format!(
                    "{} {:?} at pose {:?} appears again (first on line {first}): one row per {} and pose",
                    instrument.column,
                    shorten(name),
                    shorten(&label),
                    instrument.column
                ),
            ));
        }
        if t.optional_bool(&row, "simulated")? == Some(true) {
            campaign.simulated = true;
        }
        let time_s = t.optional_number(&row, "time_s")?;
        if instrument.points {
            let v: Vec<f64> = values.iter().map(|v| v.unwrap_or(0.0)).collect();
            campaign.point_measurements.push(PointMeasurement {
                pose: j,
                target: which,
                session: 0,
                measured_mm: Vector3::new(v[0], v[1], v[2]),
                time_s,
            });
            lines.push(row.line);
        } else {
            for (axis, v) in values.iter().enumerate() {
                if let Some(v) = v {
                    campaign.tilt_measurements.push(TiltMeasurement {
                        pose: j,
                        inclinometer: which,
                        axis,
                        session: 0,
                        angle_mrad: v.to_radians() * 1e3,
                        time_s,
                    });
                    lines.push(row.line);
                }
            }
        }
    }
    if poses.is_empty() {
        return Err(InputError::file(
            &t.file,
            format!("no {what} measurements: the file has a header but no rows"),
        ));
    }
    // The commanded configuration of each pose; those whose readings give none.
    let (commanded, unusable) = commanded_configurations(&poses, robot, &mut campaign);
    if has_readings {
        campaign.commanded_lengths_mm = Some(commanded);
    }
    let mut file = DataFile {
        file: t.file.clone(),
        kind: if instrument.points {
            FileKind::PointMeasurements
        } else {
            FileKind::TiltMeasurements
        },
        campaign,
        pose_labels: labels,
        pose_lines: poses.iter().map(|p| p.line).collect(),
        reading_lines: Vec::new(),
        registration: None,
        tracker_rows: Vec::new(),
        checked: true,
        point_lines: lines,
        point_frame: None,
        excluded: Vec::new(),
    };
    exclude_poses(&mut file, unusable)?;
    if instrument.points {
        check_point_units(&t.file, robot, &file.campaign, &file.point_lines)?;
    } else {
        check_tilt_units(
            &t.file,
            robot,
            &file.campaign,
            &file.point_lines,
            &instrument.measured,
        )?;
    }
    Ok(file)
}

/// Largest minus smallest of `values` (0 for none).
fn spread(values: impl Iterator<Item = f64>) -> f64 {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if hi >= lo {
        hi - lo
    } else {
        0.0
    }
}

/// Refuses a point file whose measured points spread a hundred times less (metres, most
/// likely) or more than the nominal targets at the commanded poses ([`POINT_UNITS_RATIO`]).
/// The tracker's frame may be anywhere, so only the spreads about the centroids are compared
/// (RMS distances). The error names the row farthest from the centroid and its largest
/// coordinate.
fn check_point_units(
    file: &str,
    robot: &Robot,
    campaign: &Campaign,
    lines: &[usize],
) -> Result<(), InputError> {
    let targets = robot.target_positions_mm();
    let m = &campaign.point_measurements;
    let radius = |p: &[Vector3<f64>]| -> (f64, usize) {
        let n = p.len().max(1) as f64;
        let c = p.iter().fold(Vector3::zeros(), |a, v| a + v) / n;
        let far = (0..p.len())
            .max_by(|a, b| (p[*a] - c).norm().total_cmp(&(p[*b] - c).norm()))
            .unwrap_or(0);
        let r = (p.iter().map(|v| (v - c).norm_squared()).sum::<f64>() / n).sqrt();
        (r, far)
    };
    let nominal: Vec<Vector3<f64>> = m
        .iter()
        .map(|q| campaign.poses[q.pose].transform_point(&targets[q.target]))
        .collect();
    let measured: Vec<Vector3<f64>> = m.iter().map(|q| q.measured_mm).collect();
    let (commanded, _) = radius(&nominal);
    let (got, far) = radius(&measured);
    if !(commanded >= POINT_UNITS_MIN_MM) {
        return Ok(());
    }
    let ratio = got / commanded;
    let hint = if ratio < POINT_UNITS_RATIO {
        "metres? Positions are in mm"
    } else if ratio > 1.0 / POINT_UNITS_RATIO {
        "micrometres, or not positions? Positions are in mm"
    } else {
        return Ok(());
    };
    let p = measured[far];
    let k = p.iamax();
    Err(InputError::field(
        file,
        lines.get(far).copied().unwrap_or(0),
        ["x_mm", "y_mm", "z_mm"][k],
        format!(
            "the measured points spread {got:.4} mm (RMS about their centre) while the targets at the commanded poses spread {commanded:.3} mm: {hint}"
        ),
    ))
}

/// Refuses a tilt file whose angles spread much less than the commanded poses tilt the
/// instruments' axes ([`TILT_UNITS_RATIO`]): radians, most likely. Each measured column is
/// compared with the angle the nominal instrument would read at the commanded poses
/// (`asin(up . R a)`); mount and levelling only add offsets, which a spread ignores. The error
/// names the row of the largest angle of that column.
fn check_tilt_units(
    file: &str,
    robot: &Robot,
    campaign: &Campaign,
    lines: &[usize],
    columns: &[String],
) -> Result<(), InputError> {
    let specs = &robot.description.inclinometers;
    for (axis, column) in columns.iter().enumerate() {
        let rows: Vec<(usize, &TiltMeasurement)> = campaign
            .tilt_measurements
            .iter()
            .enumerate()
            .filter(|(_, m)| m.axis == axis)
            .collect();
        let expected = rows.iter().filter_map(|(_, m)| {
            let spec = &specs[m.inclinometer];
            let a = spec.axes.get(axis)?;
            let mount = cpm_geometry::Pose::from_xyz_rpy_deg([0.0; 3], spec.mount_rpy_deg);
            let a = mount.rotation * Vector3::from(*a);
            let a = campaign.poses[m.pose].rotation * a.try_normalize(1e-12)?;
            Some(a.z.clamp(-1.0, 1.0).asin().to_degrees())
        });
        let commanded = spread(expected);
        let measured = spread(rows.iter().map(|(_, m)| (m.angle_mrad * 1e-3).to_degrees()));
        if !(commanded >= TILT_UNITS_MIN_DEG && measured < TILT_UNITS_RATIO * commanded) {
            continue;
        }
        let (k, m) = rows
            .iter()
            .max_by(|a, b| a.1.angle_mrad.abs().total_cmp(&b.1.angle_mrad.abs()))
            .expect("a spread needs rows");
        let v = (m.angle_mrad * 1e-3).to_degrees();
        return Err(InputError::field(
            file,
            lines.get(*k).copied().unwrap_or(0),
            column.as_str(),
            format!(
                "the angles of {column} spread {measured:.4} degrees while the commanded poses tilt that axis over {commanded:.2} degrees: radians? Angles are in degrees ({} rad would be {:.3} deg)",
                show(v, None),
                v.to_degrees()
            ),
        ));
    }
    Ok(())
}

/// The simulated line and the header of an instrument file up to the measured columns:
/// `pose`, the instrument's column, the link readings and the commanded pose.
fn header(campaign: &Campaign, links: usize, note: &str, column: &str) -> String {
    let mut s = String::new();
    if campaign.simulated {
        s.push_str(&simulated_header(note));
    }
    s.push_str(&format!("pose,{column}"));
    for k in 1..=links {
        s.push_str(&format!(",reading_{k}"));
    }
    for c in COMMANDED_COLUMNS {
        s.push_str(&format!(",{c}"));
    }
    s
}

/// A row's first cells: the pose label (its number from 1), the instrument `name`, the
/// commanded link readings (the campaign's commanded lengths, or the nominal inverse
/// kinematics) and the commanded pose.
fn commanded_cells(s: &mut String, campaign: &Campaign, robot: &Robot, pose: usize, name: &str) {
    let p = &campaign.poses[pose];
    let lengths = match &campaign.commanded_lengths_mm {
        Some(l) => l[pose].clone(),
        None => cpm_kinematics::inverse_lengths(&robot.table, p),
    };
    s.push_str(&format!("{},{}", pose + 1, field(name)));
    for (i, len) in lengths.iter().enumerate() {
        s.push_str(&format!(",{}", num(robot.reading(i, *len))));
    }
    let rpy = p.rpy_deg();
    for v in p.position_mm.iter().chain(rpy.iter()) {
        s.push_str(&format!(",{}", num(*v)));
    }
}

/// Writes the point measurements of a campaign (the format the readers read): one row per
/// measurement with the commanded link readings (the campaign's commanded lengths, or the
/// nominal inverse kinematics) and the commanded pose, the target's name and the measured
/// point as given (tracker frame). `note` goes on the simulated line.
pub fn write_point_measurements(campaign: &Campaign, robot: &Robot, note: &str) -> String {
    let n = robot.num_links();
    let has_time = campaign
        .point_measurements
        .iter()
        .any(|m| m.time_s.is_some());
    let mut s = header(campaign, n, note, "target");
    s.push_str(",x_mm,y_mm,z_mm");
    if has_time {
        s.push_str(",time_s");
    }
    if campaign.simulated {
        s.push_str(",simulated");
    }
    s.push('\n');
    for m in &campaign.point_measurements {
        commanded_cells(
            &mut s,
            campaign,
            robot,
            m.pose,
            &robot.description.targets[m.target].name,
        );
        for v in m.measured_mm.iter() {
            s.push_str(&format!(",{}", num(*v)));
        }
        if has_time {
            s.push_str(&format!(",{}", opt(m.time_s)));
        }
        if campaign.simulated {
            s.push_str(",true");
        }
        s.push('\n');
    }
    s
}

/// Writes the inclinometer angles of a campaign (the format the readers read): one row per
/// inclinometer per pose, with the commanded link readings and pose and the angles in degrees
/// (an angle not measured is an empty cell). `note` goes on the simulated line.
pub fn write_tilt_measurements(campaign: &Campaign, robot: &Robot, note: &str) -> String {
    let n = robot.num_links();
    let axes = robot
        .description
        .inclinometers
        .iter()
        .map(|c| c.axes.len())
        .max()
        .unwrap_or(0);
    let has_time = campaign
        .tilt_measurements
        .iter()
        .any(|m| m.time_s.is_some());
    let mut s = header(campaign, n, note, "inclinometer");
    for k in 1..=axes {
        s.push_str(&format!(",angle_{k}_deg"));
    }
    if has_time {
        s.push_str(",time_s");
    }
    if campaign.simulated {
        s.push_str(",simulated");
    }
    s.push('\n');
    // Rows in the order of their first angle.
    let mut order: Vec<(usize, usize)> = Vec::new();
    for m in &campaign.tilt_measurements {
        if !order.contains(&(m.pose, m.inclinometer)) {
            order.push((m.pose, m.inclinometer));
        }
    }
    for (j, c) in order {
        commanded_cells(
            &mut s,
            campaign,
            robot,
            j,
            &robot.description.inclinometers[c].name,
        );
        let mine = || {
            campaign
                .tilt_measurements
                .iter()
                .filter(move |m| m.pose == j && m.inclinometer == c)
        };
        for k in 0..axes {
            s.push(',');
            if let Some(m) = mine().find(|m| m.axis == k) {
                s.push_str(&num((m.angle_mrad * 1e-3).to_degrees()));
            }
        }
        if has_time {
            s.push_str(&format!(",{}", opt(mine().next().and_then(|m| m.time_s))));
        }
        if campaign.simulated {
            s.push_str(",true");
        }
        s.push('\n');
    }
    s
}
