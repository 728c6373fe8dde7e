//! Project chores: `cargo xtask reproduce-paper` (the paper's example end to end).
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

fn usage() -> ExitCode {
    eprintln!("usage: cargo xtask <task>\n\ntasks:\n  reproduce-paper [--out DIR] [--seed N]   run the paper's example end to end (simulated)");
    ExitCode::from(2)
}

fn reproduce_paper(args: &[String]) -> ExitCode {
    let mut out = PathBuf::from("target/reproduce-paper");
    let mut options = cpm::calib::paper::PaperOptions::default();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match (a.as_str(), it.next()) {
            ("--out", Some(v)) => out = PathBuf::from(v),
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
    let result = cpm::calib::paper::reproduce(&options, |stage| {
        eprintln!("[{:6.1} s] {stage}", t0.elapsed().as_secs_f64());
    });
    let r = match result {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut files = cpm::output::OutputSet::new();
    if let Err(e) = cpm::paper_report::render(&r, &out, &mut files) {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    match files.commit() {
        Ok(written) => {
            let summary = cpm::paper_report::summary_json(&r);
            println!("SIMULATED data (paper's Table 2 as truth), {:.1} s", t0.elapsed().as_secs_f64());
            println!(
                "paper design: {} readings, rank {} of 36, residual RMS {:.2} um; Table 3 vs Table 2 readings RMS: {:.3} um (p+dp), {:.3} um (p-dp)",
                summary["paper_design"]["readings"], summary["paper_design"]["rank"],
                r.paper.calibration.residual_rms_um, r.table3.plus, r.table3.minus
            );
            println!(
                "designed:     {} readings, rank {} of 36, error vs Table 2 RMS {} um, max {} um, Cramér-Rao RMS {} um",
                summary["designed"]["readings"], summary["designed"]["rank"],
                summary["designed"]["rms_error_um"], summary["designed"]["max_error_um"], summary["designed"]["crlb_rms_um"]
            );
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
        _ => usage(),
    }
}
