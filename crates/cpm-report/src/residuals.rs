//! `residuals.csv` of `cpm calibrate`, `cpm refine` and `cpm validate`: every observation's
//! residual in its own unit, with the file, line and what was observed.
use cpm_io::{Merged, Robot};

use crate::fit::observation_origin;

/// `residuals.csv`: every observation's residual (measured minus predicted, in its own unit:
/// um for lengths, positions and points, urad for orientations and angles) with the file,
/// line and what it is. `residuals` are the native residuals in observation order.
///
/// Tracker positions and orientations, and point coordinates, are given in the tracker's own
/// axes (the rough registration the reader applied undone): the same whatever registration a
/// command started from.
pub fn residuals_csv(robot: &Robot, merged: &Merged, residuals: &[f64]) -> String {
    let quote = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
    let c = &merged.campaign;
    let mut residuals = residuals.to_vec();
    let mut to_tracker = |rows: &[Option<usize>], file: &str| {
        let Some(r) = merged.tracker_axes(file) else {
            return;
        };
        if let [Some(a), Some(b), Some(k)] = *rows {
            let v = r * cpm_geometry::Vector3::new(residuals[a], residuals[b], residuals[k]);
            (residuals[a], residuals[b], residuals[k]) = (v.x, v.y, v.z);
        }
    };
    for (q, rows) in c.pose_observation_rows().iter().enumerate() {
        let pose = c.pose_measurements[q].pose;
        let Some((file, ..)) = merged.pose_origin.get(pose) else {
            continue;
        };
        to_tracker(&rows[..3], file);
        to_tracker(&rows[3..], file);
    }
    let p0 = c.first_point_observation();
    for (q, pm) in c.point_measurements.iter().enumerate() {
        let Some((file, ..)) = merged.pose_origin.get(pm.pose) else {
            continue;
        };
        let o = p0 + 3 * q;
        to_tracker(&[Some(o), Some(o + 1), Some(o + 2)], file);
    }
    let mut out = String::from("observation,file,line,what,unit,residual\n");
    for (k, r) in residuals.iter().enumerate() {
        let o = observation_origin(robot, merged, k);
        let unit = match merged.campaign.observation_kind(k) {
            cpm_calib::ObservationKind::TrackerOrientation(..)
            | cpm_calib::ObservationKind::Tilt(..) => "urad",
            _ => "um",
        };
        out.push_str(&format!(
            "{},{},{},{},{unit},{}\n",
            k + 1,
            quote(o.as_ref().map_or("", |o| o.file.as_str())),
            o.as_ref().map_or(0, |o| o.line),
            quote(o.as_ref().map_or("", |o| o.what.as_str())),
            r,
        ));
    }
    crate::format::tidy_csv(&out)
}
