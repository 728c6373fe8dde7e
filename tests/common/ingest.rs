//! Reading measurements as `cpm` does, for the tests: [`cpm::workflow::ingest`] (tracker files
//! registered and checked) with the default registration options. Each test binary uses what
//! it needs.
#![allow(dead_code)]
use cpm::io::{DataFile, InputError, ReadError, ReadOptions, Robot};

/// [`cpm::workflow::ingest::read_data`] with the default registration options.
pub fn read_data(
    text: &str,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, InputError> {
    cpm::workflow::ingest::read_data(text, file, robot, options, &Default::default())
}

/// [`cpm::workflow::ingest::read_data_file`] with the default registration options.
pub fn read_data_file(
    path: &std::path::Path,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, ReadError> {
    cpm::workflow::ingest::read_data_file(path, robot, options, &Default::default())
}

/// [`cpm::workflow::ingest::read_data_from`] with the default registration options.
pub fn read_data_from<R: std::io::Read>(
    source: R,
    file: &str,
    robot: &Robot,
    options: &ReadOptions,
) -> Result<DataFile, ReadError> {
    cpm::workflow::ingest::read_data_from(source, file, robot, options, &Default::default())
}
