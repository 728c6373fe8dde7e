//! Reading measurement files of any kind: the kind is told from the header and the file
//! handed to its reader ([`crate::campaign`] for readings and tracker poses,
//! [`crate::points`] for point targets and inclinometer angles). Tracker files are returned
//! as parsed, unregistered and unchecked against the robot ([`DataFile::checked`] false):
//! their registration and consistency checks are the fit side's (`cpm_workflow::ingest`, whose
//! readers of the same names read with these, then register).
use std::io::Read;
use std::path::Path;

use crate::campaign::{
    exclude_poses, finish, open, read_pose_measurements_table, read_readings_table,
    read_readings_unexcluded, DataFile, ReadOptions,
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
    let file = path.display().to_string();
    read_data_table(opened(path, &file)?.read_ahead(), robot, options)
}

/// The table of the file at `path` (named `file` in messages), told the file's size.
fn opened(path: &Path, file: &str) -> Result<Table<std::fs::File>, ReadError> {
    let f = open(path)?;
    let size = f.metadata().ok().map(|m| m.len());
    Ok(Table::from_reader(f, file)?.with_size_bytes(size))
}

/// Reads a measurement file of either kind (told from the header) from a reader, row by row:
/// the first problem stops the reading there.
pub fn read_data_from<R: Read>(
    source: R,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, ReadError> {
    read_data_table(Table::from_reader(source, file)?, robot, options)
}

/// [`read_data_from`] a table whose header is read.
fn read_data_table<R: Read>(
    mut t: Table<R>,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, ReadError> {
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
            &t.file,
            t.header_line,
            "this is a list of poses (no sensor readings and no link readings): measurements need `sensor` and `length_mm` columns, or `reading_1`.. columns with a measured pose",
        )),
        Err(e) => Err(e),
    };
    r.map_err(|e| finish(&mut t, e))
}

/// What a second robot's reading of a file is, beside the first's (see
/// [`read_data_file_for_two`]).
#[derive(Debug)]
pub enum SecondReading {
    /// The same as the first robot's (the same poses left out, for the same reasons).
    SameAsFirst,
    /// Its own (other poses left out).
    File(Box<DataFile>),
}

/// A measurement file read for two robots with one pass over it: the first robot's reading,
/// as [`read_data_file`] gives it, and the second robot's when it can share the pass (a
/// readings file without logged link readings, and both robots name the same sensors in the
/// same order): the second's own checks (positions, reachability, sensor lengths) and
/// exclusions are made on the rows the first read, with the result and the error
/// [`read_data_file`] gives for it. `None` for the second: read it on its own.
pub fn read_data_file_for_two(
    path: &Path,
    first: &Robot,
    second: &Robot,
    options: &ReadOptions,
) -> Result<(DataFile, Option<Result<SecondReading, ReadError>>), ReadError> {
    let file = path.display().to_string();
    let t = opened(path, &file)?;
    if !matches!(t.kind(), Ok(FileKind::Readings)) {
        drop(t);
        return Ok((read_data_file(path, first, options)?, None));
    }
    let mut t = t.read_ahead();
    let (all, unusable, theirs) = read_readings_unexcluded(&mut t, first, Some(second), options)
        .map_err(|e| finish(&mut t, e))?;
    drop(t);
    let same = |u: &[crate::campaign::Unusable]| {
        u.len() == unusable.len()
            && u.iter()
                .zip(&unusable)
                .all(|(a, b)| a.pose == b.pose && a.what == b.what)
    };
    let second = theirs.map(|r| match r {
        Err(e) => Err(ReadError::Input(e)),
        Ok(u) if same(&u) => Ok(SecondReading::SameAsFirst),
        Ok(u) => {
            let mut f = all.clone();
            exclude_poses(&mut f, u)?;
            Ok(SecondReading::File(Box::new(f)))
        }
    });
    let mut f = all;
    exclude_poses(&mut f, unusable)?;
    Ok((f, second))
}

/// Reads several measurement files (see [`read_data_file`]), the tracker files among them
/// unregistered (`cpm_workflow::ingest::read_data_files` registers them together).
pub fn read_data_files(
    paths: &[std::path::PathBuf],
    robot: &Robot,
    options: &ReadOptions,
) -> Result<Vec<DataFile>, ReadError> {
    paths
        .iter()
        .map(|path| read_data_file(path, robot, options))
        .collect()
}
