//! Figures of the calibration reports: residuals against pose and time, estimates with error
//! bars (SVG, plotters).
use plotters::prelude::*;

use cpm_calib::{Calibration, Campaign, MeasurementModel};

use super::{err, scatter, PlotError};

/// Residual series per sensor (and tracker) against `x(reading)`.
fn residual_series(
    campaign: &Campaign,
    sensor_names: &[String],
    residuals_um: &[f64],
    x: impl Fn(usize) -> Option<f64>,
    x_tracker: impl Fn(usize) -> Option<f64>,
    x_point: impl Fn(usize) -> Option<f64>,
) -> Vec<(String, Vec<(f64, f64)>)> {
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    // Series index per sensor index (series in the order sensors first appear).
    let mut slot: Vec<Option<usize>> = Vec::new();
    for (k, r) in campaign.readings.iter().enumerate() {
        let (Some(res), Some(xv)) = (residuals_um.get(k), x(k)) else {
            continue;
        };
        if slot.len() <= r.sensor {
            slot.resize(r.sensor + 1, None);
        }
        let i = *slot[r.sensor].get_or_insert_with(|| {
            let name = format!(
                "sensor {}",
                sensor_names.get(r.sensor).cloned().unwrap_or_default()
            );
            // Two sensors of the same name share a series, as before.
            match series.iter().position(|s| s.0 == name) {
                Some(i) => i,
                None => {
                    series.push((name, Vec::new()));
                    series.len() - 1
                }
            }
        });
        series[i].1.push((xv, *res));
    }
    if residuals_um.len() == campaign.len() && !campaign.point_measurements.is_empty() {
        let p0 = campaign.first_point_observation();
        let mut pts = Vec::new();
        for q in 0..campaign.point_measurements.len() {
            let Some(xv) = x_point(q) else { continue };
            for a in 0..3 {
                pts.push((xv, residuals_um[p0 + 3 * q + a]));
            }
        }
        series.push(("point targets".to_string(), pts));
    }
    if residuals_um.len() == campaign.len() && !campaign.pose_measurements.is_empty() {
        let mut pos = Vec::new();
        for (q, rows) in campaign.pose_observation_rows().iter().enumerate() {
            let Some(xv) = x_tracker(q) else { continue };
            for r in rows[..3].iter().flatten() {
                pos.push((xv, residuals_um[*r]));
            }
        }
        series.push(("tracker position".to_string(), pos));
    }
    series
}

/// Residual against the pose number (from 1), one series per sensor.
pub fn residuals_vs_pose(
    title: &str,
    campaign: &Campaign,
    sensor_names: &[String],
    residuals_um: &[f64],
) -> Result<String, PlotError> {
    let series = residual_series(
        campaign,
        sensor_names,
        residuals_um,
        |k| Some(campaign.readings[k].pose as f64 + 1.0),
        |q| Some(campaign.pose_measurements[q].pose as f64 + 1.0),
        |q| Some(campaign.point_measurements[q].pose as f64 + 1.0),
    );
    scatter(title, "pose", "residual (um)", &series)
}

/// Residual against the logged time, when every reading has one.
pub fn residuals_vs_time(
    title: &str,
    campaign: &Campaign,
    sensor_names: &[String],
    residuals_um: &[f64],
) -> Option<Result<String, PlotError>> {
    let all_timed = campaign.readings.iter().all(|r| r.time_s.is_some())
        && campaign
            .pose_measurements
            .iter()
            .all(|m| m.time_s.is_some())
        && campaign
            .point_measurements
            .iter()
            .all(|m| m.time_s.is_some())
        && !campaign.is_empty();
    if !all_timed {
        return None;
    }
    let series = residual_series(
        campaign,
        sensor_names,
        residuals_um,
        |k| campaign.readings[k].time_s.get(),
        |q| campaign.pose_measurements[q].time_s,
        |q| campaign.point_measurements[q].time_s,
    );
    Some(scatter(title, "time (s)", "residual (um)", &series))
}

/// Before/after residuals against the pose number (refinement).
pub fn residuals_before_after(
    title: &str,
    campaign: &Campaign,
    before_um: &[f64],
    after_um: &[f64],
) -> Result<String, PlotError> {
    let at = |k: usize| -> f64 {
        if k < campaign.len() {
            campaign.observation_pose(k) as f64 + 1.0
        } else {
            f64::NAN
        }
    };
    let pts =
        |r: &[f64]| -> Vec<(f64, f64)> { r.iter().enumerate().map(|(k, v)| (at(k), *v)).collect() };
    scatter(
        title,
        "pose",
        "residual (um)",
        &[
            ("before".to_string(), pts(before_um)),
            ("after".to_string(), pts(after_um)),
        ],
    )
}

/// A physical group of estimates in one panel: its axis label with the unit (`installation
/// errors, um`) and its points `(number as in report.md, estimate, standard deviation)`.
pub struct EstimateGroup {
    /// Axis label, with the unit.
    pub label: String,
    /// The points.
    pub points: Vec<(usize, f64, f64)>,
}

/// Estimates with +-2 sigma error bars, one panel per physical group (so each axis carries
/// one unit); the parameter numbers match report.md's table. No legend covers the data: the
/// title says what the bars are.
pub fn estimates(title: &str, groups: &[EstimateGroup]) -> Result<String, PlotError> {
    let groups: Vec<&EstimateGroup> = groups.iter().filter(|g| !g.points.is_empty()).collect();
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
        for (g, area) in groups.iter().zip(&panels) {
            let (mut lo, mut hi) = (0.0f64, 0.0f64);
            for (_, v, s) in &g.points {
                lo = lo.min(v - 2.0 * s);
                hi = hi.max(v + 2.0 * s);
            }
            let pad = ((hi - lo).abs() * 0.1).max(1e-6);
            let first = g.points.iter().map(|p| p.0).min().unwrap_or(1) as f64;
            let last = g.points.iter().map(|p| p.0).max().unwrap_or(1) as f64;
            let mut chart = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d((first - 1.0)..(last + 1.0), (lo - pad)..(hi + pad))
                .map_err(|e| err(title, e))?;
            let numbers: Vec<usize> = g.points.iter().map(|p| p.0).collect();
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
            chart
                .draw_series(g.points.iter().map(|(i, v, s)| {
                    ErrorBar::new_vertical(
                        *i as f64,
                        v - 2.0 * s,
                        *v,
                        v + 2.0 * s,
                        blue.filled(),
                        6,
                    )
                }))
                .map_err(|e| err(title, e))?;
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

/// The `estimates.svg` figure: determined installation errors with error bars.
pub fn estimates_figure(model: &MeasurementModel, cal: &Calibration) -> Result<String, PlotError> {
    // One panel per physical group and unit: the installation errors, then each effect's
    // parameters of one unit; numbered as the determined rows of report.md's table.
    let mut groups: Vec<EstimateGroup> = Vec::new();
    let mut number = 0;
    for b in model.blocks() {
        for k in b.offset..b.offset + b.len {
            let Some(v) = cal.estimate_um.get(k).copied().flatten() else {
                continue;
            };
            number += 1;
            let label = match (b.effect, b.instrument) {
                (Some(e), _) => format!("{}, {}", e.name(), e.param_unit(k - b.offset)),
                (None, Some(i)) => format!("instrument {}", model.instruments[i].name()),
                (None, None) => "installation errors, um".to_string(),
            };
            let point = (number, v, cal.std_um[k].unwrap_or(0.0));
            match groups.iter_mut().find(|g| g.label == label) {
                Some(g) => g.points.push(point),
                None => groups.push(EstimateGroup {
                    label,
                    points: vec![point],
                }),
            }
        }
    }
    estimates(
        &format!(
            "Determined parameters with +-2 std error bars{}",
            if cal.simulated {
                " (SIMULATED data)"
            } else {
                ""
            }
        ),
        &groups,
    )
}
