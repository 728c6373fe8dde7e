//! File formats of `cpm` as a library: robot descriptions (TOML) as calibration models,
//! measurement CSV files (length-sensor readings, tracker pose measurements, point targets,
//! inclinometer angles, pose lists, actuator commands). `calibration.json` and the other
//! reports are the typed reports of the `cpm` crate (`cpm::report`). `docs/formats.md` and
//! `docs/robot-description.md` document each format.
//!
//! A calibration program can depend on this crate alone (with `cpm-calib`) to read what the
//! `cpm` command reads, without the command line's dependencies (clap, plotters,
//! indicatif). The `cpm` crate re-exports it as `cpm::io`.
//!
//! Every reader names the file, the line and the field of the first problem it finds
//! ([`InputError`]), e.g. `data.csv:17: field length_mm: "abc" is not a number`; a file that
//! cannot be read at all is a [`ReadError::Io`]. Readers stream a file row by row and stop at
//! the first bad row, except that a long file may lose one pose in
//! [`POSES_PER_EXCLUDED_POSE`] the machine cannot reach, recorded in [`DataFile::excluded`].
//!
//! This crate parses and writes, nothing else: a tracker file is returned as logged
//! ([`DataFile::checked`] false). Registering its frame is a fit, and checking its poses
//! against the robot follows it: both are the fit side's (`cpm_workflow::ingest`, whose
//! `read_data_file` and friends read with this crate, then register; what may read a tracker
//! file uses those).
//!
//! One's own robot from files: a description and a readings file (`examples/` ships a 6-6
//! hexapod and 90 simulated readings of it), read and fitted:
//!
//! ```
//! use cpm_io::{read_data_file, ReadOptions, Robot};
//! use std::path::Path;
//! let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
//! let robot = Robot::load(&examples.join("hexapod_66.toml")).unwrap();
//! let data = read_data_file(&examples.join("hexapod_66_readings.csv"), &robot,
//!                           &ReadOptions::default()).unwrap();
//! assert_eq!(data.campaign.readings.len(), 90);
//! assert!(data.campaign.simulated); // the file says so in its first line
//! // The model carries the description's clearance, load and [calibration] settings.
//! let model = robot.model(&[]);
//! let cal = cpm_calib::identify(&model, &data.campaign, &Default::default()).unwrap();
//! println!("{}", cal.identifiability.summary());
//! ```
//!
//! Writing and reading back, and what a bad row gives:
//!
//! ```
//! use cpm_io::{read_data, write_readings, ReadOptions, Robot};
//! use cpm_calib::{campaign::paper_circle, simulate, MeasurementModel, Plan, SimulationOptions};
//! let robot = Robot::from_description(cpm_geometry::RobotDescription::paper_cubic(), "cube.toml").unwrap();
//! let model = robot.model(&[]);
//! let plan = Plan { poses: paper_circle(&robot.table.home), sensors: vec![0] };
//! let data = simulate(&model, &vec![0.0; 36], &plan, &SimulationOptions::default()).unwrap();
//! let text = write_readings(&data, &robot, "example");
//! assert!(text.starts_with("# simulated by cpm"));
//! let back = read_data(&text, "data.csv", &robot, &ReadOptions::default()).unwrap();
//! assert_eq!(back.campaign.readings.len(), 36);
//! assert!(back.campaign.simulated);
//! let bad = text.replace("paper,", "nosuch,");
//! let err = read_data(&bad, "data.csv", &robot, &ReadOptions::default()).unwrap_err();
//! assert!(err.to_string().starts_with("data.csv:3: field sensor: unknown sensor \"nosuch\""));
//! ```
pub mod campaign;
pub mod error;
pub mod points;
pub mod read;
pub mod robot;
pub mod rows;
pub mod sockets;
pub mod table;
pub mod write;

/// Where the inputs of a fit came from, for the record (`calibration.json` `robot`, `data`;
/// the headers of generated files).
#[derive(Debug, Clone, Default)]
pub struct Provenance {
    /// The robot description file.
    pub robot: String,
    /// The measurement files.
    pub data: Vec<String>,
}
pub use campaign::{
    max_excluded_poses, merge, read_commands_file, read_pose_list, read_pose_list_file,
    read_pose_list_from, read_pose_measurements, read_readings, write_commands, write_pose_list,
    write_pose_measurements, write_readings, DataFile, ExcludedPose, Merged, PoseRow, ReadOptions,
    ReadingOrigins, RegistrationReport, SessionRegistration, TrackerRow, MAX_ROWS,
    POSES_PER_EXCLUDED_POSE, REGISTRATION_APPLY_MM,
};
pub use error::{read_text, InputError, ReadError};
pub use read::{
    read_data, read_data_file, read_data_file_for_two, read_data_files, read_data_from,
    SecondReading,
};
pub use robot::{calibrated_description, calibrated_toml, parse_effects, Robot};
pub use table::FileKind;
