//! The files of the paper reproduction (`cargo xtask reproduce-paper`): `report.md` and
//! `summary.json` (both from the typed [`PaperReport`]), `report.html`, the SVG figures, and
//! the campaign under limits as a robot description, readings and a setup sheet.
use cpm_calib::paper::PaperReproduction;

use crate::figures::{self as plot, PlotError};
use crate::paper::PaperReport;

/// The `summary.json` of the reproduction (the typed [`PaperReport`]'s summary).
pub fn summary_json(r: &PaperReproduction) -> serde_json::Value {
    PaperReport::new(r).summary_json()
}

/// The norm of each joint's error on `side` (0 base, 1 platform) from the 36 components.
fn norms(v: &[f64], side: usize) -> Vec<f64> {
    (0..v.len() / 6)
        .map(|i| {
            let o = 6 * i + 3 * side;
            (v[o] * v[o] + v[o + 1] * v[o + 1] + v[o + 2] * v[o + 2]).sqrt()
        })
        .collect()
}

/// Per-joint error norms with their standard deviation (first order, components taken as
/// independent: sd(|e|) = sqrt(sum (e_a / |e|)^2 sd_a^2)); a joint with a component the data
/// do not determine has no norm (NaN: drawn "n.d.", not determined).
fn joint_norms(est: &[(Option<f64>, Option<f64>)], side: usize) -> (Vec<f64>, Vec<f64>) {
    (0..est.len() / 6)
        .map(|i| {
            let o = 6 * i + 3 * side;
            let e: Option<Vec<(f64, f64)>> =
                (o..o + 3).map(|k| Some((est[k].0?, est[k].1?))).collect();
            match e {
                Some(e) => {
                    let n = e.iter().map(|(v, _)| v * v).sum::<f64>().sqrt();
                    let sd = if n > 0.0 {
                        e.iter()
                            .map(|(v, s)| (v / n * s).powi(2))
                            .sum::<f64>()
                            .sqrt()
                    } else {
                        e.iter().map(|(_, s)| s * s).sum::<f64>().sqrt()
                    };
                    (n, sd)
                }
                None => (f64::NAN, f64::NAN),
            }
        })
        .unzip()
}

/// Every output file of the reproduction as (name, contents), in writing order: the figures,
/// `summary.json`, `report.md` and `report.html`, all from one [`PaperReport`].
pub fn files(r: &PaperReproduction) -> Result<Vec<(String, String)>, PlotError> {
    let mut out: Vec<(String, String)> = Vec::new();
    let report = PaperReport::new(r);
    let c = &report.text.components;
    let t2: Vec<f64> = c.iter().map(|c| c.table2).collect();
    let t3: Vec<f64> = c.iter().map(|c| c.table3).collect();
    let p: Vec<_> = c.iter().map(|c| (c.paper, c.paper_std)).collect();
    let d: Vec<_> = c.iter().map(|c| (c.designed, c.designed_std)).collect();
    let links: Vec<String> = (1..=6).map(|i| format!("link {i}")).collect();
    for (side, name, file) in [
        (1, "platform", "fig5_platform.svg"),
        (0, "base", "fig6_base.svg"),
    ] {
        let (pn, ps) = joint_norms(&p, side);
        let (dn, ds) = joint_norms(&d, side);
        let svg = plot::grouped_bars_with_errors(
            &format!(
                "Per-joint error norm, {name} side (simulated; cf. paper Fig. {})",
                if side == 1 { 5 } else { 6 }
            ),
            "|installation error| (um)",
            &links,
            &[
                ("Table 2 (true)".to_string(), norms(&t2, side)).into(),
                ("Table 3 (paper's estimate)".to_string(), norms(&t3, side)).into(),
                plot::BarSeries {
                    name: "cpm, paper design".into(),
                    values: pn,
                    std: Some(ps),
                },
                plot::BarSeries {
                    name: "cpm, designed campaign".into(),
                    values: dn,
                    std: Some(ds),
                },
            ],
        )?;
        out.push((file.to_string(), svg));
    }
    let svg = plot::spectrum(
        "Singular values of the identification Jacobian (simulated)",
        &[
            (
                "paper design (circle, 1 sensor)".to_string(),
                report.summary.paper_design.singular_values.clone(),
            ),
            (
                "designed (16 sensors, orientation changes)".to_string(),
                report.text.designed_singular_values.clone(),
            ),
        ],
        Some((
            "paper-design rank threshold".to_string(),
            report.text.rank_threshold,
        )),
    )?;
    out.push(("singular_values.svg".to_string(), svg));
    out.push((
        "summary.json".to_string(),
        serde_json::to_string_pretty(&report.summary_json()).unwrap_or_default(),
    ));
    let md = report.report_md();
    let figures: Vec<(String, String)> = out
        .iter()
        .filter(|(n, _)| n.ends_with(".svg"))
        .cloned()
        .collect();
    let html = crate::html::report_page("cpm: the paper reproduced (simulated)", &md, &figures);
    out.push(("report.md".to_string(), md));
    out.push(("report.html".to_string(), html));
    Ok(out)
}

/// The human-readable report (rendered from the typed [`PaperReport`]).
pub fn report_md(r: &PaperReproduction) -> String {
    PaperReport::new(r).report_md()
}

/// The name of the gauge in the designed campaign's `robot.toml`.
pub const DESIGNED_GAUGE: &str = "gauge";

/// The files of a campaign under limits on the paper's cube, as (name, contents):
/// `robot.toml` (the cube with one `[[sensor]]` per setup of `design`), `readings.csv`
/// (`data`, readings format; marked simulated when `data` is, `note` on that line),
/// `setup_sheet.md` and `setup_sheet.csv`. `file` names the description in messages.
pub fn designed_files(
    design: &cpm_calib::design::SetupDesign,
    data: &cpm_calib::Campaign,
    note: &str,
    file: &str,
) -> Result<Vec<(&'static str, String)>, String> {
    let mut desc = cpm_geometry::description::RobotDescription::paper_cubic();
    // The candidate socket places, the gauge (one sensor per setup names it and its bar) and
    // the limits: `cpm design` and `cpm calibrate` read them back.
    let cands = cpm_calib::design::SocketCandidates::paper_cubic();
    for (side, list) in [
        (cpm_geometry::description::SocketSide::Base, &cands.base),
        (
            cpm_geometry::description::SocketSide::Platform,
            &cands.platform,
        ),
    ] {
        desc.sockets
            .extend(list.iter().map(|s| cpm_geometry::description::SocketSpec {
                name: s.name.clone(),
                side,
                position_mm: s.position_mm.into(),
            }));
    }
    design.describe(&mut desc, DESIGNED_GAUGE);
    let toml = desc.to_toml_string().map_err(|e| e.to_string())?;
    let robot = cpm_io::Robot::from_description(desc, file).map_err(|e| e.to_string())?;
    Ok(vec![
        (
            "robot.toml",
            format!(
                "# The paper's cube with the sockets of a campaign under limits:\n# one [[sensor]] per setup (socket pair + bar), in mounting order; see setup_sheet.md;\n# the candidate socket places ([[socket]]), the gauge ([[gauge]]) and the limits ([limits]).\n\n{toml}"
            ),
        ),
        ("readings.csv", cpm_io::write_readings(data, &robot, note)),
        ("setup_sheet.md", design.setup_sheet_md(&robot.table)),
        ("setup_sheet.csv", crate::format::tidy_csv(&design.setup_sheet_csv())),
    ])
}

/// The campaign under limits as files under `designed/` ([`designed_files`]), as (path
/// relative to the output directory, contents); `dir` is that directory, named in the
/// messages of the description. Nothing when it was not run.
pub fn limited_files(
    r: &PaperReproduction,
    dir: &std::path::Path,
) -> Result<Vec<(std::path::PathBuf, String)>, String> {
    let Some(l) = &r.limited else {
        return Ok(Vec::new());
    };
    let d = dir.join("designed");
    let mut out = Vec::new();
    let note = format!(
        "paper's cube, campaign under limits, truth the paper's Table 2, noise {}, seed {}",
        r.options.noise, r.options.seed
    );
    for (name, text) in designed_files(
        &l.design,
        &l.data,
        &note,
        &d.join("robot.toml").display().to_string(),
    )? {
        out.push((std::path::Path::new("designed").join(name), text));
    }
    Ok(out)
}
