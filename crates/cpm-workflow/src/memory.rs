//! Jobs on a campaign held in memory: the robot as loaded and measurements already read
//! (from arrays, from text, from files), for callers that hold them (the Python binding):
//! no file is written or read again unless the fit needs other read options.
//!
//! [`calibrate`] is [`fit::calibrate`](crate::fit::calibrate) with the robot and the data
//! given ([`Source`]); the options are the same ([`CalibrateOptions`]: its `robot` and `data`
//! paths are not used). The fit, the outputs and the report are the same functions: the
//! same measurements give the same numbers, to the last bit, whether read from a file or
//! given in memory.
//!
//! Measurements read in memory name themselves (their
//! [`DataFile::file`](crate::io::DataFile::file)) in errors and outputs. The sources and
//! [`InMemory`] live in [`crate::sources`] (re-exported here). The read-back check of `calibrated.toml` predicts gauge readings from the
//! campaign in memory, whatever their source; other kinds of measurement are read again from
//! their files, so it is made for them when every source is a file.
//!
//! One's own instruments ([`Instrument`], written in code) come with their measurements as
//! values ([`Source::Instruments`]) to [`calibrate_with_instruments`]; [`calibrated_model`]
//! reads the `calibrated.toml` it stages back into the model that predicts what the fit did
//! (the job checks it so on the campaign in memory before staging it), and `validate` takes
//! them in [`InMemory::instruments`].
use std::path::PathBuf;
use std::sync::Arc;

use crate::calib::instruments::Instrument;
use crate::fit::{CalibrateOptions, Calibrated, FitOptions, Inputs};
use crate::ingest::RegistrationOptions;
use crate::io::{ReadOptions, Robot};
use crate::progress::{check_cancelled, Progress};
pub use crate::sources::{
    calibrated_model, read_sources, Given, InMemory, InstrumentRows, ReadData, Source,
};

/// Loads a fit's inputs from memory: [`FitOptions::load`] with the robot given and the data
/// read by [`read_sources`] (its `robot` and `data` paths are not used).
pub fn load(
    options: &FitOptions,
    robot: Robot,
    sources: &[Source],
    progress: &dyn Progress,
) -> anyhow::Result<Inputs> {
    load_with_instruments(options, robot, sources, &[], progress)
}

/// [`load`] with one's own instruments: the model's
/// [`instruments`](crate::calib::MeasurementModel::instruments), whose measurements the
/// sources hold ([`Source::Instruments`]); their sessions are the measurements'.
pub fn load_with_instruments(
    options: &FitOptions,
    robot: Robot,
    sources: &[Source],
    instruments: &[Arc<dyn Instrument>],
    progress: &dyn Progress,
) -> anyhow::Result<Inputs> {
    options.validate()?;
    let data_paths: Vec<PathBuf> = sources
        .iter()
        .filter_map(|s| match s {
            Source::Path(p) => Some(p.clone()),
            _ => None,
        })
        .collect();
    // The read-back of calibrated.toml reads the data files: only when all are files.
    let data_paths = if data_paths.len() == sources.len() {
        data_paths
    } else {
        Vec::new()
    };
    let names = sources.iter().map(Source::name).collect();
    let read = |robot: &Robot, o: &ReadOptions, r: &RegistrationOptions| {
        read_sources(sources, robot, o, r)
    };
    let inputs = crate::fit::load_inputs_with(
        options,
        robot,
        read,
        data_paths,
        names,
        instruments,
        progress,
    )?;
    options.prepare(inputs, progress)
}

/// `cpm calibrate` on a campaign in memory: [`fit::calibrate`](crate::fit::calibrate) with
/// the robot and the data given. Nothing is written (commit the staged set); a cancelled job
/// returns [`Cancelled`](crate::Cancelled).
pub fn calibrate(
    options: &CalibrateOptions,
    robot: Robot,
    sources: &[Source],
    progress: &dyn Progress,
) -> anyhow::Result<Calibrated> {
    calibrate_with_instruments(options, robot, sources, &[], progress)
}

/// [`calibrate`] with one's own instruments ([`load_with_instruments`]): each brings its block
/// of parameters, named in the reports by the instrument
/// ([`Instrument::param_name`], [`Instrument::param_unit`]) and written into
/// `calibrated.toml`'s `[calibration.instruments]` (its per-instrument parameters).
pub fn calibrate_with_instruments(
    options: &CalibrateOptions,
    robot: Robot,
    sources: &[Source],
    instruments: &[Arc<dyn Instrument>],
    progress: &dyn Progress,
) -> anyhow::Result<Calibrated> {
    let job = || -> anyhow::Result<Calibrated> {
        check_cancelled(progress)?;
        let inputs = load_with_instruments(&options.fit, robot, sources, instruments, progress)?;
        check_cancelled(progress)?;
        progress.stage(&format!(
            "fitting {} to {} observations",
            crate::load::describe_model(&inputs.model),
            inputs.merged.campaign.len()
        ));
        let fitted = crate::fit::fit_with(
            &inputs,
            &options.fit.out,
            options.minimum_norm,
            options.formulation,
        )?;
        crate::load::warn_excluded(progress, &fitted.excluded);
        check_cancelled(progress)?;
        Ok(Calibrated { inputs, fitted })
    };
    crate::progress::unless_cancelled(job(), progress)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io;
    use crate::io::rows::{GaugeRows, TrackerRows};

    fn ex(f: &str) -> PathBuf {
        PathBuf::from("../../examples").join(f)
    }

    /// Gauge readings given in memory are read back too: `calibrated.toml` is checked
    /// against the campaign in memory (no file needed), and a description with a joint
    /// moved by 2 mm is seen worse by the same check.
    #[test]
    fn readings_in_memory_are_read_back_without_files() {
        let robot_path = ex("hexapod_66.toml");
        let data_path = ex("hexapod_66_readings.csv");
        let out = std::env::temp_dir().join("cpm-memory-test-read-back-unwritten");
        let options = CalibrateOptions::new(&robot_path, vec![data_path.clone()], &out);
        let robot = Robot::load(&robot_path).unwrap();
        let sources = [Source::Text {
            name: "readings in memory".to_string(),
            text: std::fs::read_to_string(&data_path).unwrap().into(),
        }];
        let c = calibrate(&options, robot, &sources, &crate::Silent).unwrap();
        assert!(c.inputs.data_paths.is_empty());
        let text = String::from_utf8(
            c.fitted
                .set
                .contents(&out.join("calibrated.toml"))
                .unwrap()
                .to_vec(),
        )
        .unwrap();
        let check = |t: &str| {
            crate::validate::file_reproduces_fit(
                t,
                &c.inputs.robot,
                &[],
                &c.inputs.model,
                &c.inputs.merged.campaign,
                &c.fitted.cal,
                None,
                &c.fitted.excluded,
            )
            .unwrap()
            .expect("gauge readings in memory are checked")
        };
        let (fit, file) = check(&text);
        assert!(crate::fit::reproduces(fit, file), "{fit} {file}");
        // The first base joint's x moved by 2 mm.
        let key = "base_mm = [";
        let at = text.find(key).unwrap() + key.len();
        let end = at + text[at..].find(',').unwrap();
        let x: f64 = text[at..end].trim().parse().unwrap();
        let moved = format!("{}{}{}", &text[..at], x + 2.0, &text[end..]);
        let (_, worse) = check(&moved);
        assert!(worse > file + 1.0, "{worse} against {file}");
    }

    /// The same file from memory and from its path: the same calibration, bit for bit.
    #[test]
    fn memory_and_file_give_the_same_fit() {
        let robot_path = ex("hexapod_66.toml");
        let data_path = ex("hexapod_66_readings.csv");
        let out = std::env::temp_dir().join("cpm-memory-test-unwritten");
        let options = CalibrateOptions::new(&robot_path, vec![data_path.clone()], &out);
        let from_file = crate::fit::calibrate(&options, &crate::Silent).unwrap();
        let robot = Robot::load(&robot_path).unwrap();
        let text: Arc<str> = std::fs::read_to_string(&data_path).unwrap().into();
        let name = data_path.display().to_string();
        let model = robot.model(&robot.declared_effects().unwrap());
        let read_with = crate::load::read_options(&model);
        let registration = crate::load::registration_options(&model);
        let data =
            crate::ingest::read_data(&text, &name, &robot, &read_with, &registration).unwrap();
        let sources = [Source::Read(ReadData {
            data: Arc::new(data),
            options: read_with,
            registration,
            given: Given::Text(text),
        })];
        let in_memory = calibrate(&options, robot, &sources, &crate::Silent).unwrap();
        let (a, b) = (&from_file.fitted.cal, &in_memory.fitted.cal);
        assert_eq!(a.estimate_um, b.estimate_um);
        assert_eq!(a.residuals_um, b.residuals_um);
        // The calibrated description, byte for byte (calibration.json holds timings).
        let toml = |c: &Calibrated| {
            c.fitted
                .set
                .contents(&out.join("calibrated.toml"))
                .map(<[u8]>::to_vec)
        };
        assert!(toml(&from_file).is_some());
        assert_eq!(toml(&from_file), toml(&in_memory));
    }

    /// Readings given as values (numpy arrays in Python) and the same readings in their
    /// file: the same calibration, bit for bit.
    #[test]
    fn rows_and_file_give_the_same_fit() {
        let robot_path = ex("hexapod_66.toml");
        let data_path = ex("hexapod_66_readings.csv");
        let out = std::env::temp_dir().join("cpm-memory-test-rows-unwritten");
        let options = CalibrateOptions::new(&robot_path, vec![data_path.clone()], &out);
        let from_file = crate::fit::calibrate(&options, &crate::Silent).unwrap();
        // The file's columns as values.
        let text = std::fs::read_to_string(&data_path).unwrap();
        let mut t = io::table::Table::parse(&text, "readings").unwrap();
        let mut rows = GaugeRows::new("readings as values", vec![], vec![], vec![], vec![]);
        rows.simulated = t.simulated_mark;
        let number =
            |t: &io::table::Table<&[u8]>, r: &io::table::Row, c: &str| t.number(r, c).unwrap();
        while let Some(r) = t.next_row().unwrap() {
            rows.pose_labels
                .push(t.text(&r, "pose").unwrap().to_string());
            rows.sensors.push(t.text(&r, "sensor").unwrap().to_string());
            let cols = ["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"];
            rows.poses.push(cols.map(|c| number(&t, &r, c)));
            rows.lengths_mm.push(number(&t, &r, "length_mm"));
        }
        let robot = Robot::load(&robot_path).unwrap();
        let sources = [Source::GaugeRows(Arc::new(rows))];
        let from_rows = calibrate(&options, robot, &sources, &crate::Silent).unwrap();
        let (a, b) = (&from_file.fitted.cal, &from_rows.fitted.cal);
        assert_eq!(a.estimate_um, b.estimate_um);
        assert_eq!(a.std_um, b.std_um);
        assert_eq!(a.residuals_um, b.residuals_um);
        assert!(b.simulated);
        assert_eq!(from_rows.inputs.merged.campaign.readings.len(), 90);
    }
    /// A tracker campaign given as values (numpy arrays in Python) and the same
    /// measurements in their file: the same registration and calibration, bit for bit.
    #[test]
    fn tracker_rows_and_file_give_the_same_fit() {
        let robot_path = ex("hexapod_66.toml");
        let scratch = tempfile::Builder::new()
            .prefix("cpm-memory-tracker-rows-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let mut o = crate::simulate::SimulateOptions::new(&robot_path);
        o.plan.random = Some(30);
        o.plan.seed = 7;
        o.paper_table2 = true;
        o.measure = crate::simulate::Measure::Poses;
        o.noise = Some("gaussian:5".to_string());
        o.tracker_frame = Some("900,-200,30,0.3,-0.2,20".to_string());
        let text = crate::simulate::simulate(&o, &crate::Silent).unwrap().text;
        let data_path = dir.join("tracker.csv");
        std::fs::write(&data_path, &text).unwrap();
        let out = dir.join("cal");
        let options = CalibrateOptions::new(&robot_path, vec![data_path.clone()], &out);
        let from_file = crate::fit::calibrate(&options, &crate::Silent).unwrap();
        // The file's columns as values.
        let robot = Robot::load(&robot_path).unwrap();
        let links = robot.num_links();
        let mut t = io::table::Table::parse(&text, "tracker").unwrap();
        let (mut labels, mut readings, mut poses) = (vec![], vec![], vec![]);
        let number =
            |t: &io::table::Table<&[u8]>, r: &io::table::Row, c: &str| t.number(r, c).unwrap();
        let mut simulated = t.simulated_mark;
        while let Some(r) = t.next_row().unwrap() {
            labels.push(t.text(&r, "pose").unwrap().to_string());
            readings.extend((1..=links).map(|k| number(&t, &r, &format!("reading_{k}"))));
            let cols = ["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"];
            poses.push(cols.map(|c| number(&t, &r, c)));
            simulated |= t.optional_bool(&r, "simulated").unwrap() == Some(true);
        }
        let mut rows = TrackerRows::new(
            "tracker as values",
            labels,
            links,
            readings,
            io::rows::TrackerPoses::Rpy(poses),
        );
        rows.simulated = simulated;
        let sources = [Source::TrackerRows(Arc::new(rows))];
        let from_rows = calibrate(&options, robot, &sources, &crate::Silent).unwrap();
        let registration = |c: &Calibrated| {
            let mut r = c.inputs.merged.registration.clone().expect("registered");
            r.sessions.iter_mut().for_each(|s| s.file.clear());
            format!("{r:?}")
        };
        assert_eq!(registration(&from_file), registration(&from_rows));
        let (a, b) = (&from_file.fitted.cal, &from_rows.fitted.cal);
        assert_eq!(a.estimate_um, b.estimate_um);
        assert_eq!(a.std_um, b.std_um);
        assert_eq!(a.residuals_um, b.residuals_um);
        assert!(b.simulated);
        assert_eq!(from_rows.inputs.merged.campaign.pose_measurements.len(), 30);
    }

    /// Two tracker sessions, each in a frame of its own, registered together whether read
    /// from files or given as text: the same registration and fit, bit for bit (a campaign
    /// of several tracker sets in memory needs no files).
    #[test]
    fn two_tracker_sets_in_memory_are_registered_together_as_files_are() {
        let robot_path = ex("hexapod_66.toml");
        let scratch = tempfile::Builder::new()
            .prefix("cpm-memory-two-trackers-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let mut paths = Vec::new();
        let mut sources = Vec::new();
        for (k, frame) in ["1200,-300,40,0.5,-0.3,30", "-800,900,-20,-0.4,0.2,-120"]
            .iter()
            .enumerate()
        {
            let mut o = crate::simulate::SimulateOptions::new(&robot_path);
            o.plan.random = Some(30);
            o.plan.seed = 40 + k as u64;
            o.paper_table2 = true;
            o.measure = crate::simulate::Measure::Poses;
            o.noise = Some("gaussian:5".to_string());
            o.tracker_frame = Some(frame.to_string());
            let text = crate::simulate::simulate(&o, &crate::Silent).unwrap().text;
            let path = dir.join(format!("session{k}.csv"));
            std::fs::write(&path, &text).unwrap();
            sources.push(Source::Text {
                name: path.display().to_string(),
                text: text.into(),
            });
            paths.push(path);
        }
        let out = dir.join("cal");
        let options = CalibrateOptions::new(&robot_path, paths.clone(), &out);
        let from_files = crate::fit::calibrate(&options, &crate::Silent).unwrap();
        let robot = Robot::load(&robot_path).unwrap();
        let from_text = calibrate(&options, robot, &sources, &crate::Silent).unwrap();
        let registration = |c: &Calibrated| format!("{:?}", c.inputs.merged.registration);
        assert!(from_files.inputs.merged.registration.is_some());
        assert_eq!(registration(&from_files), registration(&from_text));
        let (a, b) = (&from_files.fitted.cal, &from_text.fitted.cal);
        assert_eq!(a.estimate_um, b.estimate_um);
        assert_eq!(a.residuals_um, b.residuals_um);
    }
}
