//! File formats of the `cpm` command: measurement CSV files, pose lists, robot descriptions
//! as calibration models, and `calibration.json`. `docs/formats.md` documents each format.
//!
//! Every reader names the file, the line and the field of the first problem it finds
//! ([`InputError`]), e.g. `data.csv:17: field length_mm: "abc" is not a number`.
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
pub mod calibration;
pub mod campaign;
pub mod error;
pub mod robot;
pub mod table;

pub use calibration::{calibration_json, Provenance};
pub use campaign::{
    merge, read_commands_file, read_data, read_data_file, read_data_files, read_data_from,
    read_pose_list, read_pose_list_file, read_pose_list_from, read_pose_measurements,
    read_readings, register_tracker_files, write_commands, write_pose_list,
    write_pose_measurements, write_readings, DataFile, Merged, PoseRow, ReadOptions,
    RegistrationReport, SessionRegistration, TrackerRow, MAX_ROWS, REGISTRATION_APPLY_MM,
};
pub use error::{read_text, InputError, ReadError};
pub use robot::{calibrated_description, calibrated_toml, parse_effects, Robot};
pub use table::FileKind;
