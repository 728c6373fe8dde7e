//! SVG figures (plotters): grouped bars, log-scale spectra, scatter series; the figures of a
//! fit in [`fit`].
use plotters::prelude::*;

use crate::format::NOT_DETERMINED;

pub mod fit;

/// A plotting failure (plotters' drawing error, as text).
#[derive(Debug, thiserror::Error)]
#[error("plot `{title}`: {message}")]
pub struct PlotError {
    /// Figure title.
    pub title: String,
    /// What went wrong.
    pub message: String,
}

pub(crate) fn err(title: &str, e: impl std::fmt::Display) -> PlotError {
    PlotError {
        title: title.to_string(),
        message: e.to_string(),
    }
}

/// Twenty distinguishable colours (Tableau 10 and its light companions, reordered so that
/// neighbours differ); with [`MARKERS`] a series' style repeats only after 60 series.
pub const PALETTE: [RGBColor; 20] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
    RGBColor(0, 65, 120),
    RGBColor(170, 80, 0),
    RGBColor(20, 100, 20),
    RGBColor(140, 20, 20),
    RGBColor(90, 50, 140),
    RGBColor(196, 156, 148),
    RGBColor(247, 182, 210),
    RGBColor(60, 60, 60),
    RGBColor(120, 120, 10),
    RGBColor(10, 120, 130),
];

/// Marker shapes, cycled apart from the colours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    /// Filled circle.
    Circle,
    /// Filled triangle (point up).
    Triangle,
    /// Filled square.
    Square,
    /// Cross (x).
    Cross,
    /// Hollow circle.
    Ring,
    /// Filled diamond.
    Diamond,
}

/// The marker cycle.
pub const MARKERS: [Marker; 6] = [
    Marker::Circle,
    Marker::Triangle,
    Marker::Square,
    Marker::Cross,
    Marker::Ring,
    Marker::Diamond,
];

/// The colour and marker of series `i`: distinct for the first 60 series.
pub fn style(i: usize) -> (RGBColor, Marker) {
    (PALETTE[i % PALETTE.len()], MARKERS[i % MARKERS.len()])
}

/// The element drawing `marker` of size `r` at `at` (backend coordinates).
fn marker_element<DB: DrawingBackend>(
    marker: Marker,
    at: (i32, i32),
    r: i32,
    c: RGBColor,
) -> DynElement<'static, DB, (i32, i32)> {
    let (x, y) = at;
    match marker {
        Marker::Circle => Circle::new(at, r, c.filled()).into_dyn(),
        Marker::Ring => Circle::new(at, r, c.stroke_width(2)).into_dyn(),
        Marker::Triangle => {
            Polygon::new(vec![(x, y - r), (x - r, y + r), (x + r, y + r)], c.filled()).into_dyn()
        }
        Marker::Square => Rectangle::new([(x - r, y - r), (x + r, y + r)], c.filled()).into_dyn(),
        Marker::Diamond => Polygon::new(
            vec![
                (x, y - r - 1),
                (x + r + 1, y),
                (x, y + r + 1),
                (x - r - 1, y),
            ],
            c.filled(),
        )
        .into_dyn(),
        Marker::Cross => PathElement::new(
            vec![
                (x - r, y - r),
                (x + r, y + r),
                (x, y),
                (x - r, y + r),
                (x + r, y - r),
            ],
            c.stroke_width(2),
        )
        .into_dyn(),
    }
}

/// How a legend entry is drawn.
#[derive(Debug, Clone, Copy)]
enum Key {
    Marker(RGBColor, Marker),
    Line(RGBColor, Marker),
    Bar(RGBColor),
    Note,
}

/// Width of the legend panel right of the plot, px.
const LEGEND_WIDTH: u32 = 270;

/// Splits `root` into the plot area and a legend panel on its right (legends never cover
/// data) and draws the legend there.
fn split_with_legend<'a, DB: DrawingBackend + 'a>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    entries: &[(String, Key)],
) -> Result<DrawingArea<DB, plotters::coord::Shift>, PlotError> {
    let (w, _) = root.dim_in_pixel();
    let (plot, legend) = root.split_horizontally(w.saturating_sub(LEGEND_WIDTH));
    let font = ("sans-serif", 14).into_font();
    let mut y = 50;
    for (label, key) in entries {
        let lines = wrap(label, LEGEND_CHARS);
        let mx = 14;
        match *key {
            Key::Marker(c, m) => legend.draw(&marker_element(m, (mx, y), 4, c)),
            Key::Line(c, m) => legend
                .draw(&PathElement::new(vec![(2, y), (26, y)], c.stroke_width(2)))
                .and_then(|_| legend.draw(&marker_element(m, (mx, y), 4, c))),
            Key::Bar(c) => legend.draw(&Rectangle::new([(6, y - 6), (22, y + 6)], c.filled())),
            Key::Note => Ok(()),
        }
        .map_err(|e| err(title, e))?;
        for (k, line) in lines.iter().enumerate() {
            legend
                .draw(&Text::new(
                    line.clone(),
                    (32, y - 7 + 16 * k as i32),
                    font.clone(),
                ))
                .map_err(|e| err(title, e))?;
        }
        y += 22 + 16 * (lines.len().max(1) as i32 - 1);
    }
    Ok(plot)
}

/// The characters of a legend line that fit beside the plot.
const LEGEND_CHARS: usize = 30;

/// `text` in lines of at most `width` characters, broken between words (a longer word
/// stands alone on its line): a legend entry is never cut.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines
}

/// A series of a grouped bar chart: a value per category, optionally a standard deviation
/// (drawn as a +-2 sigma error bar). A NaN value is a bar that does not exist: the chart
/// marks it "n.d." (not determined, as the reports say), and the legend says so.
#[derive(Debug, Clone, Default)]
pub struct BarSeries {
    /// Legend text.
    pub name: String,
    /// One value per category (NaN: not determined / no estimate).
    pub values: Vec<f64>,
    /// Standard deviations per category, when known.
    pub std: Option<Vec<f64>>,
}

impl From<(String, Vec<f64>)> for BarSeries {
    fn from((name, values): (String, Vec<f64>)) -> Self {
        Self {
            name,
            values,
            std: None,
        }
    }
}

/// Grouped bar chart: one group per category, one bar per series. Returns the SVG text.
pub fn grouped_bars(
    title: &str,
    y_label: &str,
    categories: &[String],
    series: &[(String, Vec<f64>)],
) -> Result<String, PlotError> {
    let s: Vec<BarSeries> = series.iter().cloned().map(BarSeries::from).collect();
    grouped_bars_with_errors(title, y_label, categories, &s)
}

/// Grouped bars with +-2 sigma error bars where a series has standard deviations, and "n.d."
/// where a value is NaN (not determined). The legend is outside the plot, on the right.
pub fn grouped_bars_with_errors(
    title: &str,
    y_label: &str,
    categories: &[String],
    series: &[BarSeries],
) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 500)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(title, e))?;
        let top = |s: &BarSeries, i: usize| {
            let v = s.values[i];
            let e = s
                .std
                .as_ref()
                .and_then(|e| e.get(i))
                .copied()
                .unwrap_or(0.0);
            v + 2.0 * e.max(0.0)
        };
        let ymax = series
            .iter()
            .flat_map(|s| (0..s.values.len()).map(move |i| top(s, i)))
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max)
            * 1.15
            + 1e-9;
        let any_missing = series.iter().any(|s| s.values.iter().any(|v| v.is_nan()));
        let mut entries: Vec<(String, Key)> = series
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let name = if s.std.is_some() {
                    format!("{} (+-2 sd)", s.name)
                } else {
                    s.name.clone()
                };
                (name, Key::Bar(style(i).0))
            })
            .collect();
        if any_missing {
            entries.push((format!("{NOT_DETERMINED} = not determined"), Key::Note));
        }
        let area = split_with_legend(&root, title, &entries)?;
        let n = categories.len();
        let k = series.len().max(1) as f64;
        let mut chart = ChartBuilder::on(&area)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), 0f64..ymax)
            .map_err(|e| err(title, e))?;
        let cats = categories.to_vec();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n)
            .x_label_formatter(&|x| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < cats.len() {
                    cats[i as usize].clone()
                } else {
                    String::new()
                }
            })
            .y_desc(y_label)
            .y_label_formatter(&|y| crate::format::short(*y))
            .draw()
            .map_err(|e| err(title, e))?;
        let w = 0.8 / k;
        for (si, s) in series.iter().enumerate() {
            let c = style(si).0;
            let x_of = |i: usize| i as f64 - 0.4 + w * si as f64;
            chart
                .draw_series(
                    s.values
                        .iter()
                        .enumerate()
                        .filter(|(_, v)| v.is_finite())
                        .map(|(i, v)| {
                            Rectangle::new([(x_of(i), 0.0), (x_of(i) + w * 0.9, *v)], c.filled())
                        }),
                )
                .map_err(|e| err(title, e))?;
            if let Some(sd) = &s.std {
                chart
                    .draw_series(
                        s.values
                            .iter()
                            .zip(sd)
                            .enumerate()
                            .filter(|(_, (v, e))| v.is_finite() && e.is_finite())
                            .map(|(i, (v, e))| {
                                let x = x_of(i) + w * 0.45;
                                ErrorBar::new_vertical(
                                    x,
                                    (v - 2.0 * e).max(0.0),
                                    *v,
                                    v + 2.0 * e,
                                    BLACK.stroke_width(1),
                                    6,
                                )
                            }),
                    )
                    .map_err(|e| err(title, e))?;
            }
            chart
                .draw_series(s.values.iter().enumerate().filter(|(_, v)| v.is_nan()).map(
                    |(i, _)| {
                        Text::new(
                            NOT_DETERMINED,
                            (x_of(i), ymax * 0.02),
                            ("sans-serif", 11).into_font().color(&c),
                        )
                    },
                ))
                .map_err(|e| err(title, e))?;
        }
        root.present().map_err(|e| err(title, e))?;
    }
    Ok(svg)
}

/// Singular value spectra on a log scale, one series per design, with a threshold line.
pub fn spectrum(
    title: &str,
    series: &[(String, Vec<f64>)],
    threshold: Option<(String, f64)>,
) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1000, 500)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(title, e))?;
        let mut entries: Vec<(String, Key)> = series
            .iter()
            .enumerate()
            .map(|(i, s)| (s.0.clone(), Key::Line(style(i).0, style(i).1)))
            .collect();
        let grey = RGBColor(120, 120, 120);
        if let Some((name, _)) = &threshold {
            entries.push((name.clone(), Key::Line(grey, Marker::Cross)));
        }
        let area = split_with_legend(&root, title, &entries)?;
        let pos = |v: f64| v.max(1e-18);
        let all: Vec<f64> = series
            .iter()
            .flat_map(|s| s.1.iter().copied().map(pos))
            .collect();
        let ymax = all.iter().copied().fold(1e-18, f64::max) * 3.0;
        let ymin = all
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
            .min(ymax / 10.0)
            / 3.0;
        let n = series.iter().map(|s| s.1.len()).max().unwrap_or(1);
        let mut chart = ChartBuilder::on(&area)
            .caption(title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0f64..(n as f64 + 1.0), (ymin..ymax).log_scale())
            .map_err(|e| err(title, e))?;
        chart
            .configure_mesh()
            .x_desc("index (largest first)")
            .x_label_formatter(&|x| {
                // The index is a whole number: no 0.0, 2.5, ... labels.
                if (x - x.round()).abs() < 1e-9 {
                    format!("{}", x.round() as i64)
                } else {
                    String::new()
                }
            })
            .y_desc("singular value")
            .y_label_formatter(&|y| format!("{y:.0e}"))
            .draw()
            .map_err(|e| err(title, e))?;
        for (si, (_, vals)) in series.iter().enumerate() {
            let (c, m) = style(si);
            chart
                .draw_series(LineSeries::new(
                    vals.iter()
                        .enumerate()
                        .map(|(i, v)| (i as f64 + 1.0, pos(*v))),
                    c.stroke_width(2),
                ))
                .map_err(|e| err(title, e))?;
            chart
                .draw_series(vals.iter().enumerate().map(|(i, v)| {
                    EmptyElement::at((i as f64 + 1.0, pos(*v)))
                        + marker_element::<SVGBackend>(m, (0, 0), 3, c)
                }))
                .map_err(|e| err(title, e))?;
        }
        if let Some((_, t)) = threshold {
            chart
                .draw_series(DashedLineSeries::new(
                    vec![(0.0, t), (n as f64 + 1.0, t)],
                    6,
                    4,
                    grey.stroke_width(1),
                ))
                .map_err(|e| err(title, e))?;
        }
        root.present().map_err(|e| err(title, e))?;
    }
    Ok(svg)
}

/// Named series of `(x, y)` points, as [`scatter`] draws them.
pub type Series = Vec<(String, Vec<(f64, f64)>)>;

/// The most points a [`scatter`] draws; above it the series are thinned by [`thin_extremes`]
/// (a scatter of 10^6 residuals is a 90 MB SVG that shows no more than this).
pub const MAX_SCATTER_POINTS: usize = 20_000;

/// Thins series of finite `(x, y)` points to about `max_points` in all, deterministically
/// and keeping the envelope: each series' x range is cut into equal bins (as many as its
/// share of `max_points`, halved), and in each bin the points with the lowest and the highest
/// y are kept (in their original order). The outliers a residual plot is read for survive;
/// points in between are left out. Series already small enough are returned whole. Returns
/// the thinned series and the number of points kept and given (finite ones).
pub fn thin_extremes(
    series: &[(String, Vec<(f64, f64)>)],
    max_points: usize,
) -> (Series, usize, usize) {
    let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let total: usize = series
        .iter()
        .map(|s| s.1.iter().filter(finite).count())
        .sum();
    if total <= max_points {
        let whole: Vec<_> = series
            .iter()
            .map(|(n, v)| (n.clone(), v.iter().filter(finite).copied().collect()))
            .collect();
        return (whole, total, total);
    }
    let mut kept = 0;
    let out = series
        .iter()
        .map(|(name, vals)| {
            let pts: Vec<(f64, f64)> = vals.iter().filter(finite).copied().collect();
            // This series' share of the budget, at least one bin.
            let share = (max_points as f64 * pts.len() as f64 / total as f64).floor() as usize;
            let bins = (share / 2).max(1);
            if pts.len() <= 2 * bins {
                kept += pts.len();
                return (name.clone(), pts);
            }
            let (lo, hi) = pts
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
            let width = (hi - lo) / bins as f64;
            let bin = |x: f64| {
                if width > 0.0 {
                    (((x - lo) / width) as usize).min(bins - 1)
                } else {
                    0
                }
            };
            // Index of the lowest and the highest y per bin.
            let mut low: Vec<Option<usize>> = vec![None; bins];
            let mut high: Vec<Option<usize>> = vec![None; bins];
            for (i, p) in pts.iter().enumerate() {
                let b = bin(p.0);
                if low[b].is_none_or(|j| p.1 < pts[j].1) {
                    low[b] = Some(i);
                }
                if high[b].is_none_or(|j| p.1 > pts[j].1) {
                    high[b] = Some(i);
                }
            }
            let mut keep: Vec<usize> = low.into_iter().chain(high).flatten().collect();
            keep.sort_unstable();
            keep.dedup();
            kept += keep.len();
            (name.clone(), keep.into_iter().map(|i| pts[i]).collect())
        })
        .collect();
    (out, kept, total)
}

/// Scatter plot of several (x, y) series, each with its own colour and marker; the legend
/// is outside the plot. Above [`MAX_SCATTER_POINTS`] points the series are thinned by
/// [`thin_extremes`] and the legend says so (how many of how many are drawn, and which).
pub fn scatter(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<String, PlotError> {
    scatter_panels(
        title,
        x_label,
        &[Panel {
            caption: title.to_string(),
            y_label: y_label.to_string(),
            series: series.to_vec(),
        }],
    )
}

/// One panel of [`scatter_panels`]: its caption, its y axis (with the unit) and its series.
#[derive(Debug, Clone)]
pub struct Panel {
    /// The panel's caption.
    pub caption: String,
    /// The y axis label, with its unit.
    pub y_label: String,
    /// The series drawn.
    pub series: Series,
}

/// Scatter plots stacked one above the other, one per [`Panel`] (one unit each: lengths in
/// um above angles in urad, say), on a common x axis label; each panel as [`scatter`] draws
/// one, thinned on its own.
pub fn scatter_panels(title: &str, x_label: &str, panels: &[Panel]) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let n = panels.len().max(1);
        let root = SVGBackend::with_string(&mut svg, (1000, 500 * n as u32)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(title, e))?;
        let areas = root.split_evenly((n, 1));
        let empty = Panel {
            caption: title.to_string(),
            y_label: String::new(),
            series: Vec::new(),
        };
        let panels: Vec<&Panel> = if panels.is_empty() {
            vec![&empty]
        } else {
            panels.iter().collect()
        };
        for (panel, area) in panels.iter().zip(&areas) {
            scatter_on(area, title, x_label, panel)?;
        }
        root.present().map_err(|e| err(title, e))?;
    }
    Ok(svg)
}

/// Draws `panel` on `root` (see [`scatter`]); `title` names the figure in errors.
fn scatter_on<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    x_label: &str,
    panel: &Panel,
) -> Result<(), PlotError> {
    let (series, drawn, total) = thin_extremes(&panel.series, MAX_SCATTER_POINTS);
    let series = &series[..];
    let mut entries: Vec<(String, Key)> = series
        .iter()
        .enumerate()
        .map(|(i, s)| (s.0.clone(), Key::Marker(style(i).0, style(i).1)))
        .collect();
    if drawn < total {
        entries.push((String::new(), Key::Note));
        entries.push((format!("thinned: {drawn} of {total} points"), Key::Note));
        entries.push(("drawn: lowest and highest".to_string(), Key::Note));
        entries.push(("residual per series in each".to_string(), Key::Note));
        entries.push(("of equal bins along the x axis".to_string(), Key::Note));
    }
    let area = split_with_legend(root, title, &entries)?;
    let pts: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.1.iter().copied())
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y) in &pts {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    if pts.is_empty() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    let px = (x1 - x0).abs().max(1e-9) * 0.05;
    let py = (y1 - y0).abs().max(1e-9) * 0.1;
    let mut chart = ChartBuilder::on(&area)
        .caption(panel.caption.as_str(), ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d((x0 - px)..(x1 + px), (y0 - py)..(y1 + py))
        .map_err(|e| err(title, e))?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(panel.y_label.as_str())
        .x_label_formatter(&|x| crate::format::short(*x))
        .y_label_formatter(&|y| crate::format::short(*y))
        .draw()
        .map_err(|e| err(title, e))?;
    for (si, (_, vals)) in series.iter().enumerate() {
        let (c, m) = style(si);
        chart
            .draw_series(
                vals.iter()
                    .filter(|(x, y)| x.is_finite() && y.is_finite())
                    .map(|p| EmptyElement::at(*p) + marker_element::<DB>(m, (0, 0), 3, c)),
            )
            .map_err(|e| err(title, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_sixty_series_have_distinct_styles() {
        let styles: Vec<((u8, u8, u8), Marker)> = (0..60)
            .map(|i| {
                let (c, m) = style(i);
                ((c.0, c.1, c.2), m)
            })
            .collect();
        for i in 0..60 {
            for j in 0..i {
                assert_ne!(styles[i], styles[j], "series {i} and {j}");
            }
        }
        // 20 distinct colours.
        let mut colours: Vec<_> = PALETTE.iter().map(|c| (c.0, c.1, c.2)).collect();
        colours.sort();
        colours.dedup();
        assert_eq!(colours.len(), 20);
    }

    #[test]
    fn sixteen_series_draw_with_their_own_colours_and_legend() {
        let series: Vec<(String, Vec<(f64, f64)>)> = (0..16)
            .map(|k| (format!("sensor s{k}"), vec![(k as f64, (k * k) as f64)]))
            .collect();
        let svg = scatter("t", "x", "y", &series).unwrap();
        for k in 0..16 {
            assert!(svg.contains(&format!("sensor s{k}")), "legend entry {k}");
            let (c, _) = style(k);
            let hex = format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2);
            assert!(
                svg.to_uppercase().contains(&hex),
                "colour of series {k}: {hex}"
            );
        }
    }

    #[test]
    fn thinning_keeps_the_extremes_and_says_so() {
        // Three series of 30,000 points each, pseudo-random residuals with one planted
        // outlier per series; x the pose number.
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let series: Vec<(String, Vec<(f64, f64)>)> = (0..3)
            .map(|s| {
                let mut v: Vec<(f64, f64)> = (0..30_000)
                    .map(|k| ((k / 16) as f64 + 1.0, next()))
                    .collect();
                v[7_777 + s * 100].1 = 40.0 + s as f64;
                v[20_001 - s * 100].1 = -50.0 - s as f64;
                (format!("sensor {s}"), v)
            })
            .collect();
        let (thin, kept, total) = thin_extremes(&series, MAX_SCATTER_POINTS);
        assert_eq!(total, 90_000);
        assert_eq!(kept, thin.iter().map(|s| s.1.len()).sum::<usize>());
        assert!(kept <= MAX_SCATTER_POINTS + 2 * series.len(), "{kept}");
        assert!(kept > MAX_SCATTER_POINTS / 2, "{kept}");
        for (s, ((_, full), (_, t))) in series.iter().zip(&thin).enumerate() {
            let max = |v: &[(f64, f64)]| v.iter().map(|p| p.1).fold(f64::MIN, f64::max);
            let min = |v: &[(f64, f64)]| v.iter().map(|p| p.1).fold(f64::MAX, f64::min);
            assert_eq!(max(t), 40.0 + s as f64);
            assert_eq!(min(t), -50.0 - s as f64);
            assert_eq!(max(t), max(full));
            // Every kept point is one of the series', in order.
            let mut it = full.iter();
            assert!(t.iter().all(|p| it.any(|q| q == p)));
        }
        // Deterministic, and small series are left whole.
        assert_eq!(thin_extremes(&series, MAX_SCATTER_POINTS).0, thin);
        let small = vec![(
            "a".to_string(),
            vec![(1.0, 2.0), (f64::NAN, 1.0), (2.0, 3.0)],
        )];
        let (whole, k, t) = thin_extremes(&small, 10);
        assert_eq!((k, t), (2, 2));
        assert_eq!(whole[0].1, vec![(1.0, 2.0), (2.0, 3.0)]);
        // The figure says it is thinned, and how many points it draws.
        let svg = scatter("t", "pose", "residual (um)", &series).unwrap();
        assert!(svg.contains(&format!("thinned: {kept} of 90000 points")));
        assert!(svg.len() < 8_000_000, "{} bytes", svg.len());
        let svg = scatter("t", "x", "y", &small).unwrap();
        assert!(!svg.contains("thinned"));
    }

    #[test]
    fn long_legends_wrap_and_an_index_axis_has_whole_numbers() {
        let svg = spectrum(
            "s",
            &[(
                "designed (16 sensors, orientation changes)".to_string(),
                (1..=36i32).map(|k| 10f64.powi(-k / 6)).collect(),
            )],
            Some(("paper-design rank threshold".to_string(), 1e-3)),
        )
        .unwrap();
        assert!(!svg.contains("..."), "a cut legend");
        assert!(svg.contains("designed (16 sensors,") && svg.contains("orientation changes)"));
        assert!(
            !svg.contains(">5.0<") && !svg.contains(">0.0<"),
            "fractional index labels"
        );
        assert_eq!(wrap("a bb ccc", 4), ["a bb", "ccc"]);
        assert_eq!(wrap("", 4), [""]);
    }

    #[test]
    fn missing_bars_are_marked_not_determined() {
        let svg = grouped_bars_with_errors(
            "t",
            "um",
            &["a".into(), "b".into()],
            &[BarSeries {
                name: "est".into(),
                values: vec![1.0, f64::NAN],
                std: Some(vec![0.1, f64::NAN]),
            }],
        )
        .unwrap();
        // The report's words: n.d., not determined.
        assert!(
            svg.contains("\nn.d.\n") && svg.contains("n.d. = not determined"),
            "{svg}"
        );
        assert!(!svg.contains("n.i.") && !svg.contains("not identifiable"));
        assert!(svg.contains("est (+-2 sd)"));
    }
}
