//! Rendering of the paper reproduction: `report.md` and `summary.json` (both from the typed
//! [`PaperReport`]) and SVG figures.
use cpm_calib::paper::PaperReproduction;

use crate::output::OutputSet;
use crate::plot;
use crate::report::paper::PaperReport;

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
/// do not determine has no norm (NaN: drawn "n.i.", not identifiable).
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

/// Stages every output file of the reproduction into `out`, under `dir`: the figures,
/// `summary.json`, `report.md` and `report.html`, all from one [`PaperReport`].
pub fn render(
    r: &PaperReproduction,
    dir: &std::path::Path,
    out: &mut OutputSet,
) -> Result<(), plot::PlotError> {
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
        out.add(dir.join(file), svg);
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
    out.add(dir.join("singular_values.svg"), svg);
    out.add(
        dir.join("summary.json"),
        serde_json::to_string_pretty(&report.summary_json()).unwrap_or_default(),
    );
    out.add(dir.join("report.md"), report.report_md());
    crate::html::stage_report_html(out, dir, "cpm: the paper reproduced (simulated)");
    Ok(())
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
    let robot = crate::io::Robot::from_description(desc, file).map_err(|e| e.to_string())?;
    Ok(vec![
        (
            "robot.toml",
            format!(
                "# The paper's cube with the sockets of a campaign under limits:\n# one [[sensor]] per setup (socket pair + bar), in mounting order; see setup_sheet.md;\n# the candidate socket places ([[socket]]), the gauge ([[gauge]]) and the limits ([limits]).\n\n{toml}"
            ),
        ),
        ("readings.csv", crate::io::write_readings(data, &robot, note)),
        ("setup_sheet.md", design.setup_sheet_md(&robot.table)),
        ("setup_sheet.csv", crate::report::format::tidy_csv(&design.setup_sheet_csv())),
    ])
}

/// Stages the campaign under limits as files under `dir/designed/` ([`designed_files`]).
/// Nothing when it was not run.
pub fn render_limited(
    r: &PaperReproduction,
    dir: &std::path::Path,
    out: &mut OutputSet,
) -> Result<(), String> {
    let Some(l) = &r.limited else {
        return Ok(());
    };
    let d = dir.join("designed");
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
        out.add(d.join(name), text);
    }
    Ok(())
}
