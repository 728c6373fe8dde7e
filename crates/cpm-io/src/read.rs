//! Reading measurement files of any kind: the kind is told from the header and the file
//! handed to its reader ([`crate::campaign`] for readings and tracker poses,
//! [`crate::points`] for point targets and inclinometer angles); tracker files are registered
//! together after reading.
use std::io::Read;
use std::path::Path;

use crate::campaign::{
    finish, open, read_pose_measurements_table, read_readings_table, register_tracker_files,
    DataFile, ReadOptions,
};
use crate::points::{read_point_measurements_table, read_tilt_measurements_table};
use crate::table::{FileKind, Table};
use crate::{InputError, ReadError, Robot};

/// Reads a measurement file of either kind (told from the header) from text.
pub fn read_data(
    text: &str,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    read_data_from(text.as_bytes(), file, robot, options).map_err(ReadError::into_input)
}

/// Reads a measurement file of either kind, streaming its rows from the file at `path`.
pub fn read_data_file(
    path: &Path,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, ReadError> {
    read_data_from(open(path)?, &path.display().to_string(), robot, options)
}

/// Reads a measurement file of either kind (told from the header) from a reader, row by row:
/// the first problem stops the reading there.
pub fn read_data_from<R: Read>(
    source: R,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, ReadError> {
    let mut t = Table::from_reader(source, file)?;
    let r = match t.kind() {
        Ok(FileKind::Readings) => read_readings_table(&mut t, robot, options),
        Ok(FileKind::PoseMeasurements) => read_pose_measurements_table(&mut t, robot, options),
        Ok(FileKind::PointMeasurements) => {
            read_point_measurements_table(&mut t, robot, options)
        }
        Ok(FileKind::TiltMeasurements) => {
            read_tilt_measurements_table(&mut t, robot, options)
        }
        Ok(FileKind::Poses) => Err(InputError::line(
            file,
            t.header_line,
            "this is a list of poses (no sensor readings and no link readings): measurements need `sensor` and `length_mm` columns, or `reading_1`.. columns with a measured pose",
        )),
        Err(e) => Err(e),
    };
    let mut f = r.map_err(|e| finish(&mut t, e))?;
    register_tracker_files(std::slice::from_mut(&mut f), robot, options)?;
    Ok(f)
}

/// Reads several measurement files (see [`read_data_file`]); the tracker files among them are
/// registered together ([`register_tracker_files`]: a frame per file, reading offsets shared)
/// before their consistency checks.
pub fn read_data_files(
    paths: &[std::path::PathBuf],
    robot: &Robot,
    options: &ReadOptions,
) -> Result<Vec<DataFile>, ReadError> {
    let mut files = Vec::with_capacity(paths.len());
    for path in paths {
        let file = path.display().to_string();
        let mut t = Table::from_reader(open(path)?, &file)?;
        let r = match t.kind() {
            Ok(FileKind::PoseMeasurements) => read_pose_measurements_table(&mut t, robot, options),
            _ => {
                drop(t);
                files.push(read_data_file(path, robot, options)?);
                continue;
            }
        };
        files.push(r.map_err(|e| finish(&mut t, e))?);
    }
    register_tracker_files(&mut files, robot, options)?;
    Ok(files)
}
