//! Project chores: `cargo xtask reproduce-paper` (the paper's example end to end).
#![forbid(unsafe_code)]
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

fn usage() -> ExitCode {
    eprintln!(
        "usage: cargo xtask <task>\n\ntasks:\n  reproduce-paper [--out DIR] [--seed N] [--limited off|setups=N,minimax=N,mc=N,exchanges=N,projections=N,windows=N,tradeoff=0|1,minimax_exp10=N]\n                                           run the paper's example end to end (simulated)\n  scale --poses N [--nested] [--stored] [--seed N]\n                                           implicit-loop calibration of a simulated N-pose campaign (16 socket pairs; --stored: cpm-lm's solver on the stored Jacobian); one JSON line\n  scale --sweep [--nested-max N]           10^3, 10^4, 10^5 poses side by side (nested too up to N, default 10^5)"
    );
    ExitCode::from(2)
}

/// Peak resident set size of this process, MiB (Linux; `None` elsewhere).
fn peak_rss_mb() -> Option<f64> {
    status_mb("VmHWM:")
}

/// A memory figure of /proc/self/status (`VmHWM:` peak, `VmRSS:` current), MB.
fn status_mb(key: &str) -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// CPU time (user + system) of this process so far, s (Linux; `None` elsewhere). On a
/// shared machine the wall clock also counts other processes' time.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses): utime is the 12th, stime the 13th.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn sweep(args: &[String]) -> ExitCode {
    // Each size in its own process so that peak memory is per size.
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let nested_max: usize = args
        .windows(2)
        .find(|w| w[0] == "--nested-max")
        .and_then(|w| w[1].parse().ok())
        .unwrap_or(100_000);
    for n in [1_000usize, 10_000, 100_000] {
        let mut cmd = std::process::Command::new(&exe);
        cmd.args(["scale", "--poses", &n.to_string()]);
        if n <= nested_max {
            cmd.arg("--nested");
        }
        match cmd.status() {
            Ok(s) if s.success() => {}
            Ok(s) => {
                eprintln!("error: scale --poses {n} exited with {s}");
                return ExitCode::FAILURE;
            }
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}

fn scale(args: &[String]) -> ExitCode {
    if args.first().map(String::as_str) == Some("--sweep") {
        return sweep(&args[1..]);
    }
    use cpm_calib::implicit::{identify_implicit, ImplicitOptions};
    use cpm_calib::paper::{designed_sensors, random_workspace_poses};
    use cpm_calib::*;
    let mut poses = 1000usize;
    let mut nested = false;
    let mut stored = false;
    let mut seed = 1u64;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--poses" => match it.next().and_then(|v| v.parse().ok()) {
                Some(v) if v > 0 => poses = v,
                _ => {
                    eprintln!("error: --poses expects a positive integer");
                    return ExitCode::from(2);
                }
            },
            "--seed" => match it.next().and_then(|v| v.parse().ok()) {
                Some(v) => seed = v,
                None => {
                    eprintln!("error: --seed expects an unsigned integer");
                    return ExitCode::from(2);
                }
            },
            "--nested" => nested = true,
            "--stored" => stored = true,
            _ => return usage(),
        }
    }
    let mut model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
    model.nominal.sensors = designed_sensors();
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, poses, 100.0, 25.0, 3.0, seed),
        sensors: (0..model.nominal.sensors.len()).collect(),
    };
    let truth = cpm_geometry::InstallationErrors::paper_table2().to_vec_um();
    let sim = SimulationOptions {
        seed,
        ..SimulationOptions::default()
    };
    let data = match simulate(&model, &truth, &plan, &sim) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("error: simulating: {e}");
            return ExitCode::FAILURE;
        }
    };
    let error_rms = |est: &[f64]| {
        (est.iter()
            .zip(&truth)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / 36.0)
            .sqrt()
    };
    // The plan's poses are in the campaign too: only the campaign goes into the fit.
    drop(plan);
    let rss_before_mb = peak_rss_mb();
    // Reset the peak (Linux: `5` to clear_refs resets VmHWM) so that `peak_rss_mb_fit` is
    // the peak while fitting (the campaign included), not the simulation's.
    let reset = std::fs::write("/proc/self/clear_refs", "5").is_ok();
    // Resident at the start of the fit (the simulated campaign and what the allocator kept).
    let rss_at_start_mb = status_mb("VmRSS:");
    let cpu0 = cpu_seconds();
    let t0 = Instant::now();
    let implicit = identify_implicit(
        &model,
        &data,
        &ImplicitOptions {
            streamed: !stored,
            ..ImplicitOptions::default()
        },
    );
    let seconds = t0.elapsed().as_secs_f64();
    let cpu = cpu_seconds().zip(cpu0).map(|(b, a)| b - a);
    let r = match implicit {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: implicit calibration: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut line = serde_json::json!({
        "simulated": true,
        "formulation": if stored { "implicit (Schur, stored Jacobian)" } else { "implicit (Schur, streamed)" },
        "poses": poses,
        "readings": data.readings.len(),
        "seconds": seconds,
        "cpu_seconds": cpu,
        "iterations": r.solver.num_iterations(),
        "seconds_per_iteration": seconds / r.solver.num_iterations().max(1) as f64,
        "termination": r.solver.termination.to_string(),
        "peak_rss_mb_fit": if reset { peak_rss_mb() } else { None },
        "peak_rss_mb_before_fit": rss_before_mb,
        "rss_mb_at_fit_start": rss_at_start_mb,
        "solver_seconds": {
            "total": r.solver.elapsed.as_secs_f64(),
            "residuals": r.solver.timings.residuals.as_secs_f64(),
            "jacobian": r.solver.timings.jacobian.as_secs_f64(),
            "linear_solver": r.solver.timings.linear_solver.as_secs_f64(),
        },
        "residual_evaluations": r.solver.residual_evaluations,
        "damping_per_iteration": r.solver.iterations.iter().map(|i| i.damping).collect::<Vec<_>>(),
        "rms_error_um": error_rms(&r.globals[..36]),
        "rank": r.identifiability.rank,
    });
    if nested {
        let t1 = Instant::now();
        let opts = IdentifyOptions {
            sigma_um: Some(sim.reading_sigma_um()),
            ..IdentifyOptions::default()
        };
        match identify(&model, &data, &opts) {
            Ok(c) => {
                let s = t1.elapsed().as_secs_f64();
                line["nested"] = serde_json::json!({
                    "seconds": s,
                    "iterations": c.solver.num_iterations(),
                    "seconds_per_iteration": s / c.solver.num_iterations().max(1) as f64,
                    "rms_error_um": error_rms(&c.minimum_norm_um),
                    "peak_rss_mb": peak_rss_mb(),
                });
            }
            Err(e) => line["nested"] = serde_json::json!({ "error": e.to_string() }),
        }
    }
    println!("{line}");
    ExitCode::SUCCESS
}

fn reproduce_paper(args: &[String]) -> ExitCode {
    let mut out = PathBuf::from("target/reproduce-paper");
    let mut options = cpm_calib::paper::PaperOptions::default();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match (a.as_str(), it.next()) {
            ("--out", Some(v)) => out = PathBuf::from(v),
            ("--limited", Some(v)) => {
                // Knobs of the campaign under limits: setups=N, minimax=N, mc=N, exchanges=N,
                // projections=N, tradeoff=0|1 (comma-separated), or `off`.
                if v == "off" {
                    options.limited = None;
                    continue;
                }
                let l = options.limited.get_or_insert_with(Default::default);
                for kv in v.split(',') {
                    let Some((k, n)) = kv
                        .split_once('=')
                        .and_then(|(k, n)| Some((k, n.parse::<usize>().ok()?)))
                    else {
                        eprintln!("error: --limited expects key=N pairs, got `{kv}`");
                        return ExitCode::from(2);
                    };
                    match k {
                        "setups" => l.max_setups = n,
                        "minimax" => l.search.minimax_rounds = n,
                        "mc" => l.monte_carlo_runs = n,
                        "exchanges" => l.search.select.max_exchanges = n,
                        "projections" => l.search.projections = n,
                        "windows" => l.search.windows_per_pair = n,
                        "tradeoff" => l.tradeoff = n != 0,
                        // The minimax reweighting's exponent in tenths (10 = 1.0).
                        "minimax_exp10" => l.search.minimax_exponent = n as f64 / 10.0,
                        _ => {
                            eprintln!("error: --limited: unknown key `{k}`");
                            return ExitCode::from(2);
                        }
                    }
                }
            }
            ("--seed", Some(v)) => match v.parse() {
                Ok(s) => options.seed = s,
                Err(_) => {
                    eprintln!("error: --seed expects an unsigned integer, got `{v}`");
                    return ExitCode::from(2);
                }
            },
            _ => return usage(),
        }
    }
    let t0 = Instant::now();
    let mut stages: Vec<serde_json::Value> = Vec::new();
    let result = cpm_calib::paper::reproduce(&options, |stage| {
        let s = t0.elapsed().as_secs_f64();
        eprintln!("[{s:6.1} s] {stage}");
        stages.push(serde_json::json!({ "stage": stage.to_string(), "started_s": s }));
    });
    let r = match result {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    // Every file of the reproduction, written all or none.
    let mut files = cpm_io::write::OutputSet::new();
    match cpm_report::paper_files::files(&r) {
        Ok(f) => f.into_iter().for_each(|(n, t)| files.add(out.join(n), t)),
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    }
    match cpm_report::paper_files::limited_files(&r, &out) {
        Ok(f) => f.into_iter().for_each(|(n, t)| files.add(out.join(n), t)),
        Err(e) => {
            eprintln!("error: the campaign under limits: {e}");
            return ExitCode::FAILURE;
        }
    }
    // The wall times, apart from the results (summary.json and report.md are the same on
    // every run with the same options; this file is not).
    let timings = serde_json::json!({
        "note": "wall-clock times of this run (they vary from run to run and with the machine's load; the results in summary.json do not)",
        "total_seconds": t0.elapsed().as_secs_f64(),
        "cpu_seconds": cpu_seconds(),
        "stages": stages,
        "solver_seconds": {
            "paper_design": r.paper.calibration.solver.elapsed.as_secs_f64(),
            "designed": r.designed.calibration.solver.elapsed.as_secs_f64(),
        },
    });
    files.add(
        out.join("timings.json"),
        serde_json::to_string_pretty(&timings).unwrap_or_default(),
    );
    match files.commit() {
        Ok(written) => {
            let summary = cpm_report::paper_files::summary_json(&r);
            println!(
                "SIMULATED data (paper's Table 2 as truth), {:.1} s",
                t0.elapsed().as_secs_f64()
            );
            println!(
                "paper design: {} readings, rank {} of 36, residual RMS {:.2} um; Table 3 vs Table 2 readings RMS: {:.3} um (p+dp), {:.3} um (p-dp)",
                summary["paper_design"]["readings"], summary["paper_design"]["rank"],
                r.paper.calibration.residual_rms_um, r.table3.plus, r.table3.minus
            );
            // Console figures rounded to three significant digits (the JSON keeps them whole).
            let g = |v: &serde_json::Value| match v.as_f64() {
                Some(x) => cpm_report::format::sig(x, 3),
                None => v.to_string(),
            };
            println!(
                "designed:     {} readings, rank {} of 36, error vs Table 2 RMS {} um, max {} um, Cramér-Rao RMS {} um",
                summary["designed"]["readings"], summary["designed"]["rank"],
                g(&summary["designed"]["rms_error_um"]), g(&summary["designed"]["max_error_um"]), g(&summary["designed"]["crlb_rms_um"])
            );
            let l = &summary["limited"];
            if !l.is_null() {
                println!(
                    "under limits: {} readings, {} setups, rank {} of 36, max travel {:.1} mm, min clearance {:.1} mm, max cone {:.1} / {:.1} deg; Monte Carlo RMS error {} um, worst {} um, Cramér-Rao RMS {} um",
                    l["readings"], l["setups"], l["rank"],
                    l["max_travel_mm"].as_f64().unwrap_or(f64::NAN),
                    l["min_clearance_mm"].as_f64().unwrap_or(f64::NAN),
                    l["max_base_cone_deg"].as_f64().unwrap_or(f64::NAN),
                    l["max_platform_cone_deg"].as_f64().unwrap_or(f64::NAN),
                    g(&l["monte_carlo"]["rms_error_um"]), g(&l["monte_carlo"]["max_error_um_worst"]), g(&l["crlb_rms_um"])
                );
                let w = &l["worst_error"];
                if !w.is_null() {
                    println!(
                        "  worst error: (a) largest per-parameter Monte Carlo RMS {} um ({}); (b) largest |error| over all runs {} um, {:.0} % of runs within 6 um",
                        g(&w["worst_parameter_rms_error_um"]), w["worst_parameter"],
                        g(&w["max_abs_error_um_all_runs"]),
                        100.0 * w["fraction_runs_max_le_6um"].as_f64().unwrap_or(f64::NAN)
                    );
                }
                for t in l["tradeoff"].as_array().into_iter().flatten() {
                    println!(
                        "  stroke {:>5} mm: Cramér-Rao RMS {} um (worst {} um), {} readings, {} setups",
                        g(&t["stroke_mm"]), g(&t["crlb_rms_um"]), g(&t["crlb_max_um"]), t["readings"], t["setups"]
                    );
                }
            }
            for w in written {
                println!("wrote {}", w.display());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: writing {}: {e}", out.display());
            ExitCode::FAILURE
        }
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("reproduce-paper") => reproduce_paper(&args[1..]),
        Some("scale") => scale(&args[1..]),
        _ => usage(),
    }
}
