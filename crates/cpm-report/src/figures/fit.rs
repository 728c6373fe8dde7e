//! Figures of the calibration reports: residuals against pose and time, estimates with error
//! bars (SVG, plotters).
use plotters::prelude::*;

use cpm_calib::{Calibration, Campaign, Determination, MeasurementModel, ObservationKind};

use super::{err, scatter_panels, Panel, PlotError};

/// What the residual figures need to name the observations: the gauges' sensor names, and
/// each own instrument's name and unit (in the model's order).
#[derive(Debug, Clone, Default)]
pub struct ResidualNames {
    /// Sensor names, by sensor index.
    pub sensors: Vec<String>,
    /// Each instrument's name and unit, by instrument index.
    pub instruments: Vec<(String, String)>,
}

impl ResidualNames {
    /// The names of `model`'s instruments beside `sensors`.
    pub fn new(sensors: Vec<String>, model: &MeasurementModel) -> Self {
        ResidualNames {
            sensors,
            instruments: model
                .instruments
                .iter()
                .map(|i| (i.name().to_string(), i.unit().to_string()))
                .collect(),
        }
    }
}

/// The panel and the series of observation `kind`: (panel caption, y label with the unit,
/// series name). One panel per kind of observation, each in its own unit.
fn panel_of(kind: ObservationKind, campaign: &Campaign, names: &ResidualNames) -> [String; 3] {
    const AXES: [&str; 3] = ["x", "y", "z"];
    let s = |a: &str, b: &str, c: String| [a.to_string(), b.to_string(), c];
    match kind {
        ObservationKind::Reading(i) => s(
            "gauge readings",
            "length residual (um)",
            format!(
                "sensor {}",
                names
                    .sensors
                    .get(campaign.readings[i].sensor)
                    .cloned()
                    .unwrap_or_default()
            ),
        ),
        ObservationKind::TrackerPosition(_, a) => s(
            "tracker positions",
            "position residual (um)",
            format!("tracker {}", AXES[a]),
        ),
        ObservationKind::TrackerOrientation(_, a) => s(
            "tracker orientations",
            "orientation residual (urad)",
            format!("about {}", AXES[a]),
        ),
        ObservationKind::Point(q, a) => s(
            "reflector points",
            "point residual (um)",
            format!(
                "target {} {}",
                campaign.point_measurements[q].target + 1,
                AXES[a]
            ),
        ),
        ObservationKind::Tilt(q) => {
            let t = &campaign.tilt_measurements[q];
            s(
                "inclinometer angles",
                "angle residual (urad)",
                format!("inclinometer {} axis {}", t.inclinometer + 1, t.axis + 1),
            )
        }
        ObservationKind::Instrument(q, _) => {
            let m = &campaign.instrument_measurements[q];
            let (name, unit) = names
                .instruments
                .get(m.instrument)
                .cloned()
                .unwrap_or_else(|| (format!("instrument {}", m.instrument + 1), String::new()));
            [
                format!("instrument {name}"),
                format!("residual ({unit})"),
                format!("channel {}", m.channel + 1),
            ]
        }
    }
}

/// The series an observation of kind `kind` joins, as a small key (the kind, and the sensor,
/// axis, target or channel it is of): its words ([`panel_of`]) are made once per key, not
/// once per observation (10^6 gauge readings).
fn series_key(kind: ObservationKind, campaign: &Campaign) -> (u8, usize) {
    match kind {
        ObservationKind::Reading(i) => (0, campaign.readings[i].sensor),
        ObservationKind::TrackerPosition(_, a) => (1, a),
        ObservationKind::TrackerOrientation(_, a) => (2, a),
        ObservationKind::Point(q, a) => (3, 3 * campaign.point_measurements[q].target + a),
        ObservationKind::Tilt(q) => {
            let t = &campaign.tilt_measurements[q];
            (4, 3 * t.inclinometer + t.axis)
        }
        ObservationKind::Instrument(q, _) => {
            let m = &campaign.instrument_measurements[q];
            (5 + (m.instrument.min(200) as u8), m.channel)
        }
    }
}

/// Every observation's kind, in order, without a list of them where the campaign's layout
/// gives each in constant time (no tracker component left unmeasured).
fn for_each_kind(campaign: &Campaign, mut f: impl FnMut(usize, ObservationKind)) {
    if campaign.unmeasured.is_empty() {
        for k in 0..campaign.len() {
            f(k, campaign.observation_kind(k));
        }
    } else {
        for (k, kind) in campaign.observation_kinds().into_iter().enumerate() {
            f(k, kind);
        }
    }
}

/// The residual panels against `x(observation)` (observations where it is `None` are left
/// out): one panel per kind of observation, in its own unit, a series per sensor, axis or
/// channel. `residuals` are measured minus predicted, each in its own unit (as
/// `residuals.csv`); with two runs (before/after) each run is one series of each panel.
fn residual_panels(
    campaign: &Campaign,
    names: &ResidualNames,
    runs: &[(&str, &[f64])],
    x: impl Fn(usize, ObservationKind) -> Option<f64>,
) -> Vec<Panel> {
    let mut panels: Vec<Panel> = Vec::new();
    // (run, key) -> (panel, series)
    let mut slot: std::collections::HashMap<(usize, (u8, usize)), (usize, usize)> =
        Default::default();
    for (run, (tag, residuals)) in runs.iter().enumerate() {
        // The gauge readings' series by sensor index (most observations, looked up directly).
        let mut by_sensor: Vec<Option<(usize, usize)>> = Vec::new();
        for_each_kind(campaign, |k, kind| {
            let (Some(r), Some(xv)) = (residuals.get(k), x(k, kind)) else {
                return;
            };
            let key = (run, series_key(kind, campaign));
            if key.1 .0 == 0 {
                if let Some(Some((p, i))) = by_sensor.get(key.1 .1) {
                    panels[*p].series[*i].1.push((xv, *r));
                    return;
                }
            }
            let (p, i) = *slot.entry(key).or_insert_with(|| {
                let [caption, y_label, name] = panel_of(kind, campaign, names);
                let name = if tag.is_empty() {
                    name
                } else if runs.len() > 1 {
                    tag.to_string()
                } else {
                    format!("{tag} {name}")
                };
                let p = match panels.iter().position(|p| p.caption == caption) {
                    Some(p) => p,
                    None => {
                        panels.push(Panel {
                            caption,
                            y_label,
                            series: Vec::new(),
                        });
                        panels.len() - 1
                    }
                };
                let series = &mut panels[p].series;
                let i = match series.iter().position(|s| s.0 == name) {
                    Some(i) => i,
                    None => {
                        series.push((name, Vec::new()));
                        series.len() - 1
                    }
                };
                (p, i)
            });
            if key.1 .0 == 0 {
                if by_sensor.len() <= key.1 .1 {
                    by_sensor.resize(key.1 .1 + 1, None);
                }
                by_sensor[key.1 .1] = Some((p, i));
            }
            panels[p].series[i].1.push((xv, *r));
        });
    }
    panels
}

/// The panels titled: the figure's title over the first, each panel its kind.
fn titled(title: &str, mut panels: Vec<Panel>) -> Vec<Panel> {
    for p in &mut panels {
        p.caption = format!("{title}: {}", p.caption);
    }
    panels
}

/// Residual (measured minus predicted, each kind in its own unit, as `residuals.csv`)
/// against the pose number (from 1): one panel per kind of observation.
pub fn residuals_vs_pose(
    title: &str,
    campaign: &Campaign,
    names: &ResidualNames,
    residuals: &[f64],
) -> Result<String, PlotError> {
    let panels = residual_panels(campaign, names, &[("", residuals)], |k, _| {
        Some(campaign.observation_pose(k) as f64 + 1.0)
    });
    scatter_panels(title, "pose", &titled(title, panels))
}

/// The logged time of observation `k` of kind `kind`, if any.
fn time_of(campaign: &Campaign, kind: ObservationKind) -> Option<f64> {
    match kind {
        ObservationKind::Reading(i) => campaign.readings[i].time_s.get(),
        ObservationKind::TrackerPosition(q, _) | ObservationKind::TrackerOrientation(q, _) => {
            campaign.pose_measurements[q].time_s
        }
        ObservationKind::Point(q, _) => campaign.point_measurements[q].time_s,
        ObservationKind::Tilt(q) => campaign.tilt_measurements[q].time_s,
        ObservationKind::Instrument(..) => None,
    }
}

/// Residual against the logged time, when every observation has one (as
/// [`residuals_vs_pose`], one panel per kind).
pub fn residuals_vs_time(
    title: &str,
    campaign: &Campaign,
    names: &ResidualNames,
    residuals: &[f64],
) -> Option<Result<String, PlotError>> {
    let mut all_timed = !campaign.is_empty();
    for_each_kind(campaign, |_, kind| {
        all_timed = all_timed && time_of(campaign, kind).is_some();
    });
    if !all_timed {
        return None;
    }
    let panels = residual_panels(campaign, names, &[("", residuals)], |_, kind| {
        time_of(campaign, kind)
    });
    Some(scatter_panels(title, "time (s)", &titled(title, panels)))
}

/// Before/after residuals (measured minus predicted, each kind in its own unit) against the
/// pose number (refinement): one panel per kind, the two runs as two series.
pub fn residuals_before_after(
    title: &str,
    campaign: &Campaign,
    names: &ResidualNames,
    before: &[f64],
    after: &[f64],
) -> Result<String, PlotError> {
    let panels = residual_panels(
        campaign,
        names,
        &[("before", before), ("after", after)],
        |k, _| Some(campaign.observation_pose(k) as f64 + 1.0),
    );
    scatter_panels(title, "pose", &titled(title, panels))
}

/// A physical group of estimates in one panel: its axis label with the unit (`installation
/// errors, um`) and its points `(number as in report.md, estimate, standard deviation)`.
pub struct EstimateGroup {
    /// Axis label, with the unit.
    pub label: String,
    /// The points the data determine.
    pub points: Vec<(usize, f64, f64)>,
    /// The points held by their tolerance (value where the fit ends, posterior standard
    /// deviation), drawn in another colour.
    pub held: Vec<(usize, f64, f64)>,
}

/// Estimates with +-2 sigma error bars, one panel per physical group (so each axis carries
/// one unit); the parameter numbers match report.md's table. No legend covers the data: the
/// title says what the bars are.
pub fn estimates(title: &str, groups: &[EstimateGroup]) -> Result<String, PlotError> {
    let groups: Vec<&EstimateGroup> = groups
        .iter()
        .filter(|g| !g.points.is_empty() || !g.held.is_empty())
        .collect();
    let panel_h = 320u32;
    let height = 50 + panel_h * groups.len().max(1) as u32;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(title, e))?;
        let root = root
            .titled(title, ("sans-serif", 20))
            .map_err(|e| err(title, e))?;
        let panels = root.split_evenly((groups.len().max(1), 1));
        let blue = RGBColor(31, 119, 180);
        let orange = RGBColor(255, 127, 14);
        for (g, area) in groups.iter().zip(&panels) {
            let (mut lo, mut hi) = (0.0f64, 0.0f64);
            for (_, v, s) in g.points.iter().chain(&g.held) {
                lo = lo.min(v - 2.0 * s);
                hi = hi.max(v + 2.0 * s);
            }
            let pad = ((hi - lo).abs() * 0.1).max(1e-6);
            let all = || g.points.iter().chain(&g.held).map(|p| p.0);
            let first = all().min().unwrap_or(1) as f64;
            let last = all().max().unwrap_or(1) as f64;
            let mut chart = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d((first - 1.0)..(last + 1.0), (lo - pad)..(hi + pad))
                .map_err(|e| err(title, e))?;
            let numbers: Vec<usize> = all().collect();
            chart
                .configure_mesh()
                .x_desc("parameter (numbered as in report.md)")
                .y_desc(g.label.as_str())
                .x_label_formatter(&|x| {
                    let i = x.round();
                    if (x - i).abs() < 1e-6 && i >= 1.0 && numbers.contains(&(i as usize)) {
                        format!("{}", i as usize)
                    } else {
                        String::new()
                    }
                })
                .y_label_formatter(&|y| crate::format::short(*y))
                .draw()
                .map_err(|e| err(title, e))?;
            for (points, colour) in [(&g.points, blue), (&g.held, orange)] {
                chart
                    .draw_series(points.iter().map(|(i, v, s)| {
                        ErrorBar::new_vertical(
                            *i as f64,
                            v - 2.0 * s,
                            *v,
                            v + 2.0 * s,
                            colour.filled(),
                            6,
                        )
                    }))
                    .map_err(|e| err(title, e))?;
            }
            chart
                .draw_series(LineSeries::new(
                    vec![(first - 1.0, 0.0), (last + 1.0, 0.0)],
                    RGBColor(150, 150, 150).stroke_width(1),
                ))
                .map_err(|e| err(title, e))?;
        }
        root.present().map_err(|e| err(title, e))?;
    }
    Ok(svg)
}

/// The `estimates.svg` figure: the parameters the data determine (blue, +-2 Cramér-Rao
/// standard deviations) and those held by tolerance (orange, +-2 posterior standard
/// deviations), numbered as report.md's Estimates table.
pub fn estimates_figure(model: &MeasurementModel, cal: &Calibration) -> Result<String, PlotError> {
    // One panel per physical group and unit: the installation errors, then each effect's
    // parameters of one unit; numbered as the plotted rows of report.md's table.
    let mut groups: Vec<EstimateGroup> = Vec::new();
    let mut number = 0;
    let mut any_held = false;
    for b in model.blocks() {
        for k in b.offset..b.offset + b.len {
            let determination = cal.determination(k);
            let (Some(v), std) = cal.value_and_std(k) else {
                continue;
            };
            if !v.is_finite()
                || !matches!(
                    determination,
                    Determination::Determined | Determination::HeldByTolerance
                )
            {
                continue;
            }
            number += 1;
            let label = match (b.effect, b.instrument) {
                (Some(e), _) => format!("{}, {}", e.name(), e.param_unit(k - b.offset)),
                (None, Some(i)) => format!("instrument {}", model.instruments[i].name()),
                (None, None) => "installation errors, um".to_string(),
            };
            let point = (number, v, std.filter(|s| s.is_finite()).unwrap_or(0.0));
            let i = match groups.iter().position(|g| g.label == label) {
                Some(i) => i,
                None => {
                    groups.push(EstimateGroup {
                        label,
                        points: Vec::new(),
                        held: Vec::new(),
                    });
                    groups.len() - 1
                }
            };
            if determination == Determination::Determined {
                groups[i].points.push(point);
            } else {
                any_held = true;
                groups[i].held.push(point);
            }
        }
    }
    estimates(
        &format!(
            "{} with +-2 std error bars{}",
            if any_held {
                "Determined parameters (blue) and held by tolerance (orange, posterior std)"
            } else {
                "Determined parameters"
            },
            if cal.simulated {
                " (SIMULATED data)"
            } else {
                ""
            }
        ),
        &groups,
    )
}
