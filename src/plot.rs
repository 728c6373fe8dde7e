//! SVG figures (plotters): grouped bars, log-scale spectra, scatter series.
use plotters::prelude::*;

/// A plotting failure (plotters' drawing error, as text).
#[derive(Debug, thiserror::Error)]
#[error("plot `{title}`: {message}")]
pub struct PlotError {
    /// Figure title.
    pub title: String,
    /// What went wrong.
    pub message: String,
}

fn err(title: &str, e: impl std::fmt::Display) -> PlotError {
    PlotError {
        title: title.to_string(),
        message: e.to_string(),
    }
}

const COLORS: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
];

/// Grouped bar chart: one group per category, one bar per series. Returns the SVG text.
pub fn grouped_bars(
    title: &str,
    y_label: &str,
    categories: &[String],
    series: &[(String, Vec<f64>)],
) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 500)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(title, e))?;
        let ymax = series
            .iter()
            .flat_map(|s| s.1.iter())
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max)
            * 1.15
            + 1e-9;
        let n = categories.len();
        let k = series.len().max(1) as f64;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
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
            .draw()
            .map_err(|e| err(title, e))?;
        for (si, (name, vals)) in series.iter().enumerate() {
            let c = COLORS[si % COLORS.len()];
            let w = 0.8 / k;
            chart
                .draw_series(vals.iter().enumerate().filter(|(_, v)| v.is_finite()).map(
                    |(i, v)| {
                        let x0 = i as f64 - 0.4 + w * si as f64;
                        Rectangle::new([(x0, 0.0), (x0 + w * 0.9, *v)], c.filled())
                    },
                ))
                .map_err(|e| err(title, e))?
                .label(name.clone())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 10, y + 5)], c.filled()));
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|e| err(title, e))?;
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
        let root = SVGBackend::with_string(&mut svg, (900, 500)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(title, e))?;
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
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0f64..(n as f64 + 1.0), (ymin..ymax).log_scale())
            .map_err(|e| err(title, e))?;
        chart
            .configure_mesh()
            .x_desc("index")
            .y_desc("singular value")
            .y_label_formatter(&|y| format!("{y:.0e}"))
            .draw()
            .map_err(|e| err(title, e))?;
        for (si, (name, vals)) in series.iter().enumerate() {
            let c = COLORS[si % COLORS.len()];
            chart
                .draw_series(LineSeries::new(
                    vals.iter()
                        .enumerate()
                        .map(|(i, v)| (i as f64 + 1.0, pos(*v))),
                    c.stroke_width(2),
                ))
                .map_err(|e| err(title, e))?
                .label(name.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], c));
            chart
                .draw_series(
                    vals.iter()
                        .enumerate()
                        .map(|(i, v)| Circle::new((i as f64 + 1.0, pos(*v)), 3, c.filled())),
                )
                .map_err(|e| err(title, e))?;
        }
        if let Some((name, t)) = threshold {
            let c = RGBColor(120, 120, 120);
            chart
                .draw_series(LineSeries::new(
                    vec![(0.0, t), (n as f64 + 1.0, t)],
                    c.stroke_width(1),
                ))
                .map_err(|e| err(title, e))?
                .label(name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], c));
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|e| err(title, e))?;
        root.present().map_err(|e| err(title, e))?;
    }
    Ok(svg)
}

/// Scatter plot of several (x, y) series.
pub fn scatter(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 500)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(title, e))?;
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
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((x0 - px)..(x1 + px), (y0 - py)..(y1 + py))
            .map_err(|e| err(title, e))?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .draw()
            .map_err(|e| err(title, e))?;
        for (si, (name, vals)) in series.iter().enumerate() {
            let c = COLORS[si % COLORS.len()];
            chart
                .draw_series(
                    vals.iter()
                        .filter(|(x, y)| x.is_finite() && y.is_finite())
                        .map(|p| Circle::new(*p, 3, c.filled())),
                )
                .map_err(|e| err(title, e))?
                .label(name.clone())
                .legend(move |(x, y)| Circle::new((x + 5, y), 3, c.filled()));
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|e| err(title, e))?;
        root.present().map_err(|e| err(title, e))?;
    }
    Ok(svg)
}
