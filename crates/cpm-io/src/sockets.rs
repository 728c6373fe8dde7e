//! Candidate sensor sockets: the `--sockets` file of `cpm design` (`name,side,x_mm,y_mm,z_mm`
//! places, or the socket pairs `cpm design` writes as `sockets.csv`), read row by row with the
//! file, line and field of any problem.
use cpm_calib::design::{sockets::Socket, SocketCandidates};

use crate::table::Table;
use crate::{InputError, ReadError};

/// The most candidate sockets a `--sockets` file may list.
pub const MAX_SOCKETS: usize = 10_000;

/// Reads candidate sockets: `name,side,x_mm,y_mm,z_mm`.
pub fn read_sockets(text: &str, file: &str) -> Result<SocketCandidates, InputError> {
    read_sockets_from(text.as_bytes(), file).map_err(ReadError::into_input)
}

/// Reads candidate sockets from a reader, row by row.
pub fn read_sockets_from<R: std::io::Read>(
    source: R,
    file: &str,
) -> Result<SocketCandidates, ReadError> {
    let mut t = Table::from_reader(source, file)?;
    sockets_table(&mut t).map_err(|e| match t.take_io_error() {
        Some(source) => ReadError::Io {
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
        let t: &crate::table::Header = t;
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
                        crate::table::shorten(other)
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
                    crate::table::shorten(name)
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
        let t: &crate::table::Header = t;
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
            let v = cpm_geometry::Vector3::from(p);
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
