//! Measurements and robots a caller holds in memory for a job (the Python binding): the
//! sources of a campaign ([`Source`]: files, measurements already read, text, values), read
//! and registered as files are ([`read_sources`]), and what a job takes in place of the
//! files its options name ([`InMemory`]: with a list of poses as values, [`pose_list`]).
//! Measurements of one's own instruments ([`crate::calib::instruments`]) come as values only
//! ([`InstrumentRows`]): no file format holds them.
//! The jobs on a campaign in memory are [`crate::memory`]'s and each job's `*_in` function.
use std::path::PathBuf;
use std::sync::Arc;

use crate::ingest::RegistrationOptions;
use crate::io::rows::{GaugeRows, PoseRows, TrackerRows};
use crate::io::{self, DataFile, FileKind, Merged, ReadOptions, Robot};
use crate::progress::Progress;

/// Measurements a job reads from memory, with how they were read.
#[derive(Debug, Clone)]
pub struct ReadData {
    /// The measurements as read (with `options`, against the job's robot).
    pub data: Arc<DataFile>,
    /// The read options they were read with.
    pub options: ReadOptions,
    /// The registration options they were read with (tracker files).
    pub registration: RegistrationOptions,
    /// What they were read from, read again when the job needs other read options.
    pub given: Given,
}

/// Measurements as given in memory, before reading.
#[derive(Debug, Clone)]
pub enum Given {
    /// The text of a measurement file.
    Text(Arc<str>),
    /// Length-sensor readings as values ([`GaugeRows`]: no text).
    GaugeRows(Arc<GaugeRows>),
    /// Tracker pose measurements as values ([`TrackerRows`]: no text).
    TrackerRows(Arc<TrackerRows>),
}

impl Given {
    /// Reads them against `robot` (`name` stands for the file of a text), as
    /// [`ingest::read_data`](crate::ingest::read_data) reads a file's text: read
    /// ([`read_unregistered`](Self::read_unregistered)), then a tracker or point set registered
    /// on its own.
    pub fn read(
        &self,
        name: &str,
        robot: &Robot,
        options: &ReadOptions,
        registration: &RegistrationOptions,
    ) -> Result<DataFile, io::InputError> {
        let mut f = self.read_unregistered(name, robot, options)?;
        crate::ingest::register_files(std::slice::from_mut(&mut f), robot, options, registration)?;
        Ok(f)
    }

    /// Reads them against `robot` as the readers do, without registering tracker or point
    /// sets ([`io::read_data`]): for a campaign registered together.
    pub fn read_unregistered(
        &self,
        name: &str,
        robot: &Robot,
        options: &ReadOptions,
    ) -> Result<DataFile, io::InputError> {
        match self {
            Given::Text(text) => io::read_data(text, name, robot, options),
            Given::GaugeRows(rows) => io::rows::read_gauge_rows(rows, robot, options),
            Given::TrackerRows(rows) => io::rows::read_tracker_rows(rows, robot, options),
        }
    }
}

/// One set of measurements of a campaign.
#[derive(Debug, Clone)]
pub enum Source {
    /// A file, read as `cpm calibrate --data PATH` reads it.
    Path(PathBuf),
    /// Measurements already read against the job's robot (the caller checks that it is the
    /// same robot: else give them as [`Source::Text`]).
    Read(ReadData),
    /// Measurement text to read (its name stands for the file).
    Text {
        /// The name in messages and outputs.
        name: String,
        /// The text, as a measurement file holds it.
        text: Arc<str>,
    },
    /// Length-sensor readings as values, to read (their `file` names them).
    GaugeRows(Arc<GaugeRows>),
    /// Tracker pose measurements as values, to read and register (their `file` names them).
    TrackerRows(Arc<TrackerRows>),
    /// Measurements of one's own instruments as values, with the poses they were taken at
    /// (their `file` names them); the instruments are the job's
    /// ([`memory::calibrate_with_instruments`](crate::memory::calibrate_with_instruments)).
    Instruments(Arc<InstrumentRows>),
}

/// Measurements of one's own instruments ([`Instrument`](crate::calib::instruments::Instrument))
/// held in memory, with the commanded poses they were taken at: a session of the campaign of
/// their own, after the other sources' poses.
#[derive(Debug, Clone, Default)]
pub struct InstrumentRows {
    /// The name in messages and outputs (it stands for a file).
    pub file: String,
    /// The commanded platform poses, base frame.
    pub poses: Vec<cpm_geometry::Pose>,
    /// A label per pose in messages and `residuals.csv`; empty: the poses' numbers from 1.
    pub pose_labels: Vec<String>,
    /// The measurements: `pose` indexes [`poses`](Self::poses), `instrument` the job's
    /// instruments, `session` their sessions (from 0, as the instruments' per-session
    /// parameters count them), values and `sigma` in the instrument's unit.
    pub measurements: Vec<crate::calib::InstrumentMeasurement>,
    /// True when the measurements were simulated (every output then says so).
    pub simulated: bool,
}

impl InstrumentRows {
    /// Appends the poses and measurements to `merged`: the poses after its own (a session
    /// of their own, commanded by the nominal inverse kinematics of `robot` where the others
    /// log commanded lengths), each named by this source's name and its label.
    pub(crate) fn append_to(&self, merged: &mut Merged, robot: &Robot) -> anyhow::Result<()> {
        if !self.pose_labels.is_empty() && self.pose_labels.len() != self.poses.len() {
            return Err(crate::error::input_error(format!(
                "{}: {} pose labels for {} poses",
                self.file,
                self.pose_labels.len(),
                self.poses.len()
            )));
        }
        if let Some((k, m)) = self
            .measurements
            .iter()
            .enumerate()
            .find(|(_, m)| m.pose >= self.poses.len())
        {
            return Err(crate::error::input_error(format!(
                "{}: measurement {} is at pose {} of {} poses",
                self.file,
                k + 1,
                m.pose + 1,
                self.poses.len()
            )));
        }
        let c = &mut merged.campaign;
        let base = c.poses.len();
        if base > 0 && !self.poses.is_empty() {
            c.session_starts.push(base);
        }
        if let Some(l) = c.commanded_lengths_mm.as_mut() {
            l.extend(
                self.poses
                    .iter()
                    .map(|p| crate::kinematics::inverse_lengths(&robot.table, p)),
            );
        }
        c.poses.extend(self.poses.iter().copied());
        c.instrument_measurements
            .extend(
                self.measurements
                    .iter()
                    .map(|m| crate::calib::InstrumentMeasurement {
                        pose: m.pose + base,
                        ..m.clone()
                    }),
            );
        c.simulated |= self.simulated;
        for j in 0..self.poses.len() {
            let label = self
                .pose_labels
                .get(j)
                .cloned()
                .unwrap_or_else(|| (j + 1).to_string());
            merged.pose_origin.push((self.file.clone(), j + 1, label));
        }
        Ok(())
    }
}

impl Source {
    /// Reads the measurements against `robot` with `options`, tracker and point sets
    /// registered on their own: a file as [`ingest::read_data_file`](crate::ingest::read_data_file)
    /// reads it, what is held in memory from what was given ([`Given::read`]).
    pub fn read(
        &self,
        robot: &Robot,
        options: &ReadOptions,
        registration: &RegistrationOptions,
    ) -> anyhow::Result<DataFile> {
        let given = match self {
            Source::Path(p) => {
                return Ok(crate::ingest::read_data_file(
                    p,
                    robot,
                    options,
                    registration,
                )?)
            }
            Source::Read(r) => {
                return Ok(r.given.read(&r.data.file, robot, options, registration)?)
            }
            Source::Text { text, .. } => Given::Text(text.clone()),
            Source::GaugeRows(rows) => Given::GaugeRows(rows.clone()),
            Source::TrackerRows(rows) => Given::TrackerRows(rows.clone()),
            Source::Instruments(rows) => {
                return Err(crate::error::input_error(format!(
                    "{}: measurements of one's own instruments are not a measurement file (they go to a job with their instruments)",
                    rows.file
                )))
            }
        };
        Ok(given.read(&self.name(), robot, options, registration)?)
    }

    /// The name of the source in messages and outputs.
    pub fn name(&self) -> String {
        match self {
            Source::Path(p) => p.display().to_string(),
            Source::Read(r) => r.data.file.clone(),
            Source::Text { name, .. } => name.clone(),
            Source::GaugeRows(rows) => rows.file.clone(),
            Source::TrackerRows(rows) => rows.file.clone(),
            Source::Instruments(rows) => rows.file.clone(),
        }
    }
}

/// What a caller holds in memory for a job, in place of the files its options name: the
/// robot as loaded (for the options' `robot` path) and the measurements (for their `data`
/// paths). What is `None` is read from the options' paths, as the command reads it.
#[derive(Debug, Clone, Default)]
pub struct InMemory {
    /// The robot as loaded.
    pub robot: Option<Robot>,
    /// The measurements.
    pub data: Option<Vec<Source>>,
    /// `validate`'s reference robot as loaded (for its `reference` path).
    pub reference: Option<Robot>,
    /// The true machine as loaded (for the `truth` path of `simulate` and of `validate`'s
    /// compensation check).
    pub truth: Option<Robot>,
    /// A list of poses as values, for the pose list file the options name (a plan's `plan`,
    /// `compensate`'s `poses`): read with the checks of that file ([`pose_list`]).
    pub poses: Option<Arc<PoseRows>>,
    /// One's own instruments, whose measurements the data hold ([`Source::Instruments`]):
    /// `validate` predicts them with each robot's values ([`calibrated_model`]).
    pub instruments: Vec<Arc<dyn crate::calib::instruments::Instrument>>,
}

impl InMemory {
    /// Nothing held: every input is read from the options' paths.
    pub fn none() -> Self {
        Self::default()
    }

    /// True when nothing is held.
    pub fn is_empty(&self) -> bool {
        self.robot.is_none()
            && self.data.is_none()
            && self.reference.is_none()
            && self.truth.is_none()
            && self.poses.is_none()
            && self.instruments.is_empty()
    }

    /// The robot held, else the one at `path` ([`load_robot`](crate::load::load_robot)).
    pub fn robot_or_load(
        &mut self,
        path: &std::path::Path,
        progress: &dyn Progress,
    ) -> anyhow::Result<Robot> {
        match self.robot.take() {
            Some(r) => Ok(r),
            None => crate::load::load_robot(path, progress),
        }
    }

    /// The measurements held, else the files at `paths`.
    pub fn sources_or(&mut self, paths: &[PathBuf]) -> Vec<Source> {
        self.data
            .take()
            .unwrap_or_else(|| paths.iter().cloned().map(Source::Path).collect())
    }
}

/// A list of poses: the rows held (`held`, read with the checks of a pose list file,
/// [`read_pose_rows`](io::rows::read_pose_rows)), else the file at `path`; with the name that
/// stands for it in messages and outputs.
pub fn pose_list(
    path: &std::path::Path,
    held: Option<&PoseRows>,
) -> Result<(Vec<io::PoseRow>, String), io::ReadError> {
    match held {
        Some(rows) => Ok((io::rows::read_pose_rows(rows)?, rows.file.clone())),
        None => Ok((io::read_pose_list_file(path)?, path.display().to_string())),
    }
}

/// Reads and merges the sources with `options` and `registration` (the read and registration
/// options of the job's model): files only are read as
/// [`load::load_data`](crate::load::load_data) reads them; measurements already read with the
/// same options are taken as they are, others read again from their
/// text. Tracker and point sets are registered as [`load::load_data`](crate::load::load_data)
/// registers files: two or more tracker sets together, whatever their source. Measurements
/// of one's own instruments ([`Source::Instruments`]) follow the others, a session each.
pub fn read_sources(
    sources: &[Source],
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> anyhow::Result<Merged> {
    let own = |s: &&Source| matches!(s, Source::Instruments(_));
    if !sources.iter().any(|s| own(&s)) {
        return read_measurement_sources(sources, robot, options, registration);
    }
    let others: Vec<Source> = sources.iter().filter(|s| !own(s)).cloned().collect();
    let mut merged = if others.is_empty() {
        io::merge(Vec::new(), robot)
    } else {
        read_measurement_sources(&others, robot, options, registration)?
    };
    for s in sources {
        if let Source::Instruments(rows) = s {
            rows.append_to(&mut merged, robot)?;
        }
    }
    Ok(merged)
}

/// [`read_sources`] of sources that are all measurement files or their contents.
fn read_measurement_sources(
    sources: &[Source],
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> anyhow::Result<Merged> {
    let paths: Vec<PathBuf> = sources
        .iter()
        .filter_map(|s| match s {
            Source::Path(p) => Some(p.clone()),
            _ => None,
        })
        .collect();
    if paths.len() == sources.len() {
        return crate::load::load_data(&paths, robot, options, registration);
    }
    // Read as the readers read, registered afterwards all together (as files are): a set
    // already read and registered on its own is read again from what was given when it has
    // to be registered with others (two or more tracker sets).
    let mut files = Vec::with_capacity(sources.len());
    for s in sources {
        let f = match s {
            Source::Path(p) => io::read_data_file(p, robot, options)?,
            Source::Read(r) if r.options == *options && r.registration == *registration => {
                DataFile::clone(&r.data)
            }
            Source::Read(r) => r.given.read_unregistered(&r.data.file, robot, options)?,
            Source::Text { name, text } => io::read_data(text, name, robot, options)?,
            Source::GaugeRows(rows) => io::rows::read_gauge_rows(rows, robot, options)?,
            Source::TrackerRows(rows) => io::rows::read_tracker_rows(rows, robot, options)?,
            // `read_sources` appends them apart.
            s @ Source::Instruments(_) => s.read(robot, options, registration)?,
        };
        files.push(f);
    }
    let trackers = files
        .iter()
        .filter(|f| f.kind == FileKind::PoseMeasurements)
        .count();
    if trackers > 1 {
        for (k, s) in sources.iter().enumerate() {
            if let Source::Read(r) = s {
                if files[k].kind == FileKind::PoseMeasurements && files[k].checked {
                    files[k] = r.given.read_unregistered(&r.data.file, robot, options)?;
                }
            }
        }
    }
    crate::ingest::register_files(&mut files, robot, options, registration)?;
    let merged = io::merge(files, robot);
    if options.check_sensor_lengths {
        crate::gauges::check_readings(robot, &merged)?;
    }
    Ok(merged)
}

/// The model of a calibrated description `robot` (the `calibrated.toml` a fit with one's own
/// `instruments` wrote, read back) with those instruments, and the parameter vector at which it
/// predicts what that fit predicted: the machine as the description holds it (nothing else
/// estimated), each instrument's own parameters at the values of `[calibration.instruments]`
/// under its name (zero, its nominal, when the description has none: a reference robot).
///
/// Errors: values of another length than the instrument's parameters; an instrument with
/// per-session parameters (they describe the fit's sessions and are not written: a held-out
/// session would need its own fitted).
pub fn calibrated_model(
    robot: &Robot,
    instruments: &[Arc<dyn crate::calib::instruments::Instrument>],
) -> anyhow::Result<(crate::calib::MeasurementModel, Vec<f64>)> {
    let mut model = robot.model(&[]);
    model.instruments = instruments.to_vec();
    let written = robot
        .description
        .calibration
        .as_ref()
        .map(|c| &c.instruments);
    let mut params = vec![0.0; model.num_params()];
    for b in model.blocks() {
        let Some(i) = b.instrument else { continue };
        let instrument = &instruments[i];
        if instrument.num_session_params() > 0 {
            return Err(crate::error::input_error(format!(
                "instrument `{}` has per-session parameters, which a calibrated description does not carry",
                instrument.name()
            )));
        }
        match written.and_then(|w| w.get(instrument.name())) {
            Some(v) if v.len() == b.len => {
                params[b.offset..b.offset + b.len].copy_from_slice(v);
            }
            Some(v) => {
                return Err(crate::error::input_error(format!(
                    "{}: [calibration.instruments] {} has {} values, the instrument {} parameters",
                    robot.file,
                    instrument.name(),
                    v.len(),
                    b.len
                )))
            }
            None => {}
        }
    }
    Ok((model, params))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{compensate, identifiability, simulate, Silent};
    use std::path::Path;

    fn ex(f: &str) -> PathBuf {
        PathBuf::from("../../examples").join(f)
    }

    /// The targets of the example as values (named "targets in memory"), and their CSV
    /// written to a file in a scratch folder named after `dir` (removed when dropped).
    fn targets(dir: &str) -> (Arc<PoseRows>, tempfile::TempDir, PathBuf) {
        let list = io::read_pose_list_file(&ex("targets.csv")).unwrap();
        let poses = list
            .iter()
            .map(|r| {
                let (p, a) = (r.pose.position_mm, r.pose.rpy_deg());
                [p.x, p.y, p.z, a[0], a[1], a[2]]
            })
            .collect();
        let mut rows = PoseRows::new("targets in memory", poses);
        rows.pose_labels = list.iter().map(|r| r.label.clone()).collect();
        let dir = tempfile::Builder::new()
            .prefix(&format!("cpm-sources-{dir}-"))
            .tempdir()
            .unwrap();
        let path = dir.path().join("targets.csv");
        std::fs::write(&path, rows.to_csv()).unwrap();
        (Arc::new(rows), dir, path)
    }

    fn held(poses: &Arc<PoseRows>) -> InMemory {
        InMemory {
            poses: Some(poses.clone()),
            ..InMemory::none()
        }
    }

    /// Targets held in memory give the commands of their file (the file named by their name).
    #[test]
    fn compensation_targets_in_memory_are_their_file() {
        let (rows, _dir, path) = targets("compensate");
        let robot = ex("hexapod_66_truth.toml");
        let file =
            compensate::compensate(&compensate::CompensateOptions::new(&robot, &path), &Silent)
                .unwrap();
        let options = compensate::CompensateOptions::new(&robot, PathBuf::new());
        let mem = compensate::compensate_in(&options, held(&rows), &Silent).unwrap();
        assert_eq!(mem.targets, file.targets);
        assert_eq!(mem.readings, file.readings);
        let named = file
            .csv
            .replace(&path.display().to_string(), "targets in memory");
        assert_eq!(mem.csv, named);
        // A bad row is named as in the file, by the name and the line.
        let mut bad = PoseRows::clone(&rows);
        bad.poses[2][1] = f64::NAN;
        let e = compensate::compensate_in(&options, held(&Arc::new(bad)), &Silent).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("targets in memory:4: field y_mm:"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }

    /// A truth and a reference held in memory simulate and check a compensation as their
    /// files do (named by their names).
    #[test]
    fn robots_held_in_memory_are_their_files() {
        let (rows, _dir, path) = targets("truth");
        let (robot, truth) = (ex("hexapod_66.toml"), ex("hexapod_66_truth.toml"));
        let mut options = simulate::SimulateOptions::new(&robot);
        options.plan.plan = Some(path.clone());
        let mut on_file = options.clone();
        on_file.truth = Some(truth.clone());
        let held_truth = || InMemory {
            truth: Some(Robot::load(&truth).unwrap()),
            ..InMemory::none()
        };
        let file = simulate::simulate(&on_file, &Silent).unwrap();
        let mem = simulate::simulate_in(&options, held_truth(), &Silent).unwrap();
        assert_eq!(mem.campaign.readings, file.campaign.readings);
        assert_eq!(mem.truth.what, file.truth.what);
        let c = compensate::compensate_in(
            &compensate::CompensateOptions::new(&truth, PathBuf::new()),
            held(&rows),
            &Silent,
        )
        .unwrap();
        let commands = path.with_file_name("commands.csv");
        std::fs::write(&commands, &c.csv).unwrap();
        let mut options = crate::validate::ValidateOptions {
            commands: Some(commands),
            ..Default::default()
        };
        let mut on_file = options.clone();
        on_file.reference = Some(robot.clone());
        on_file.truth = Some(truth.clone());
        let file = crate::validate::check_compensation(&on_file, &Silent).unwrap();
        let mut held = held_truth();
        held.reference = Some(Robot::load(&robot).unwrap());
        let mem = crate::validate::check_compensation_in(&options, held, &Silent).unwrap();
        let json = |r: &crate::report::validate::CompensationReport| r.to_json().unwrap();
        assert_eq!(json(&mem.report), json(&file.report));
        // Without a truth, held or named: the command's usage error.
        options.truth = None;
        let e = crate::validate::check_compensation_in(&options, InMemory::none(), &Silent);
        assert!(e
            .err()
            .unwrap()
            .to_string()
            .contains("--commands needs --truth"));
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }

    /// A plan held in memory is simulated and analysed as its file is.
    #[test]
    fn a_plan_in_memory_is_its_file() {
        let (rows, _dir, path) = targets("plan");
        let robot = ex("hexapod_66.toml");
        let mut options = simulate::SimulateOptions::new(&robot);
        options.truth = Some(ex("hexapod_66_truth.toml"));
        let mut on_file = options.clone();
        on_file.plan.plan = Some(path.clone());
        let file = simulate::simulate(&on_file, &Silent).unwrap();
        let mem = simulate::simulate_in(&options, held(&rows), &Silent).unwrap();
        assert_eq!(mem.text, file.text);
        let options = identifiability::IdentifiabilityOptions::new(&robot);
        let mut on_file = options.clone();
        on_file.plan.plan = Some(path.clone());
        let file = identifiability::identifiability(&on_file, &Silent).unwrap();
        let mem = identifiability::identifiability_in(&options, held(&rows), &Silent).unwrap();
        let json = |d| serde_json::to_string(d).unwrap();
        assert_eq!(json(&mem.doc), json(&file.doc));
        let _ = std::fs::remove_dir_all(Path::new(&path).parent().unwrap());
    }
}
