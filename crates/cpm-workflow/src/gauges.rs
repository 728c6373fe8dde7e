//! Readings against the declared gauges: a `[[sensor]]` that names a `[[gauge]]` (a setup of
//! that gauge) reads only lengths within the gauge's range, within one stroke, and, when the
//! sensor gives its `bar_mm`, within its setup's window. `calibrate` (and every command that
//! reads measurements) refuses readings outside; `simulate` refuses plan poses outside.
use crate::geometry::Pose;
use crate::io::{InputError, Merged, Robot};

/// What one gauged sensor may read.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorWindow {
    /// The gauge's name.
    pub gauge: String,
    /// Lowest and highest length, mm: the setup's window with a bar, else the gauge's range.
    pub window_mm: (f64, f64),
    /// The gauge's stroke, mm: the most the sensor's readings may span.
    pub stroke_mm: f64,
    /// The bar of the setup, mm, when the sensor gives it.
    pub bar_mm: Option<f64>,
}

impl SensorWindow {
    /// `gauge g1, bar 150 mm: window 300.0..500.0 mm` or `gauge g1: lengths 150.0..1000.0 mm`.
    pub fn describe(&self) -> String {
        match self.bar_mm {
            Some(b) => format!(
                "gauge `{}` with a {b} mm bar reads {:.3}..{:.3} mm",
                self.gauge, self.window_mm.0, self.window_mm.1
            ),
            None => format!(
                "gauge `{}` reads {:.3}..{:.3} mm",
                self.gauge, self.window_mm.0, self.window_mm.1
            ),
        }
    }
}

/// The shortest and the longest length seen so far, each with where it was seen.
type Span = Option<((f64, usize), (f64, usize))>;

/// Readings may leave a window by this much, mm (rounding of the files).
pub const WINDOW_TOLERANCE_MM: f64 = 1e-6;

/// Per sensor of `robot` (in order): its window, when it names a gauge.
pub fn sensor_windows(robot: &Robot) -> Vec<Option<SensorWindow>> {
    let d = &robot.description;
    d.sensors
        .iter()
        .map(|s| {
            let g = d.gauge(Some(s.gauge.as_deref()?))?;
            let window_mm = match s.bar_mm {
                Some(b) => g.window_mm(b),
                None => (g.shortest_length_mm(), g.longest_length_mm()),
            };
            Some(SensorWindow {
                gauge: g.name.clone(),
                window_mm,
                stroke_mm: g.stroke_mm,
                bar_mm: s.bar_mm,
            })
        })
        .collect()
}

/// Checks the length readings of `merged` against the gauges: each within its sensor's
/// window and, per sensor, all within one stroke. The first reading outside is an
/// [`InputError`] naming its file, line and the `length_mm` field.
pub fn check_readings(robot: &Robot, merged: &Merged) -> Result<(), InputError> {
    let windows = sensor_windows(robot);
    if windows.iter().all(Option::is_none) {
        return Ok(());
    }
    let names: Vec<&str> = robot
        .table
        .sensors
        .iter()
        .map(|s| s.name.as_str())
        .collect();
    // Per sensor: (shortest, its reading index), (longest, its reading index).
    let mut span: Vec<Span> = vec![None; windows.len()];
    for (k, r) in merged.campaign.readings.iter().enumerate() {
        let Some(Some(w)) = windows.get(r.sensor) else {
            continue;
        };
        let (file, line) = merged.reading_origin.get(k).unwrap_or(("<data>", 0));
        let l = r.length_mm;
        let (lo, hi) = w.window_mm;
        if !(l >= lo - WINDOW_TOLERANCE_MM && l <= hi + WINDOW_TOLERANCE_MM) {
            return Err(InputError::field(
                file,
                line,
                "length_mm",
                format!(
                    "sensor `{}` read {l} mm, outside what its {} (robot description {}): a wrong sensor, bar or gauge?",
                    names[r.sensor],
                    w.describe(),
                    robot.file
                ),
            ));
        }
        let s = span[r.sensor].get_or_insert(((l, k), (l, k)));
        if l < s.0 .0 {
            s.0 = (l, k);
        }
        if l > s.1 .0 {
            s.1 = (l, k);
        }
        if s.1 .0 - s.0 .0 > w.stroke_mm + WINDOW_TOLERANCE_MM {
            let other = if s.0 .1 == k { s.1 .1 } else { s.0 .1 };
            let other_at = merged
                .reading_origin
                .get(other)
                .map_or_else(String::new, |(f, l)| format!(" ({f}:{l})"));
            return Err(InputError::field(
                file,
                line,
                "length_mm",
                format!(
                    "sensor `{}` read {l} mm, but also {} mm{other_at}: {:.3} mm apart, more than the {} mm stroke of gauge `{}` in one setup (robot description {})",
                    names[r.sensor],
                    if s.0 .1 == k { s.1 .0 } else { s.0 .0 },
                    s.1 .0 - s.0 .0,
                    w.stroke_mm,
                    w.gauge,
                    robot.file
                ),
            ));
        }
    }
    Ok(())
}

/// Checks the nominal socket distances of plan `poses` for `sensors` against the gauges;
/// `locate(pose)` gives `(file, line)` of a pose for the error.
pub fn check_plan(
    robot: &Robot,
    sensors: &[usize],
    poses: &[Pose],
    locate: &dyn Fn(usize) -> (String, usize),
) -> Result<(), InputError> {
    let windows = sensor_windows(robot);
    for &s in sensors {
        let Some(Some(w)) = windows.get(s) else {
            continue;
        };
        let sensor = &robot.table.sensors[s];
        let mut range: Span = None;
        for (k, p) in poses.iter().enumerate() {
            let l = (p.position_mm + p.rotation * sensor.platform_mm - sensor.base_mm).norm();
            let (lo, hi) = w.window_mm;
            let (file, line) = locate(k);
            if !(l >= lo && l <= hi) {
                return Err(InputError::line(
                    file,
                    line,
                    format!(
                        "sensor `{}` would read {l:.3} mm at this pose, outside what its {} (robot description {})",
                        sensor.name,
                        w.describe(),
                        robot.file
                    ),
                ));
            }
            let r = range.get_or_insert(((l, k), (l, k)));
            if l < r.0 .0 {
                r.0 = (l, k);
            }
            if l > r.1 .0 {
                r.1 = (l, k);
            }
            if r.1 .0 - r.0 .0 > w.stroke_mm {
                return Err(InputError::line(
                    file,
                    line,
                    format!(
                        "sensor `{}` would read {l:.3} mm at this pose and {:.3} mm at pose {} of the plan: more than the {} mm stroke of gauge `{}` in one setup",
                        sensor.name,
                        if r.0 .1 == k { r.1 .0 } else { r.0 .0 },
                        if r.0 .1 == k { r.1 .1 + 1 } else { r.0 .1 + 1 },
                        w.stroke_mm,
                        w.gauge
                    ),
                ));
            }
        }
    }
    Ok(())
}
