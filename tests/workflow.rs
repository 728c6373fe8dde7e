//! The workflow layer (crates/cpm-workflow) does what the commands do: `calibrate` then
//! `validate` as library calls give what `cpm calibrate` then `cpm validate` give, to 1e-12;
//! a cancelled job writes nothing and says so in its error.
#[path = "common/cli.rs"]
mod cli;
use cli::{example, ok, p, scratch};

use cpm::workflow::{
    compensate, export, fit, identifiability, load, simulate, validate, Collect, Silent,
};
use std::path::{Path, PathBuf};

/// Every number of a JSON value, in order, with its path (timings left out).
fn numbers(v: &serde_json::Value, path: &str, out: &mut Vec<(String, f64)>) {
    match v {
        serde_json::Value::Number(n) if !path.contains("time") && !path.contains("seconds") => {
            out.push((path.to_string(), n.as_f64().unwrap()));
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                numbers(x, &format!("{path}[{i}]"), out);
            }
        }
        serde_json::Value::Object(o) => {
            for (k, x) in o {
                numbers(x, &format!("{path}.{k}"), out);
            }
        }
        _ => {}
    }
}

fn same_numbers(a: &serde_json::Value, b: &serde_json::Value, what: &str) {
    let (mut x, mut y) = (Vec::new(), Vec::new());
    numbers(a, "", &mut x);
    numbers(b, "", &mut y);
    assert_eq!(x.len(), y.len(), "{what}: as many numbers");
    assert!(x.len() > 20, "{what}: {} numbers", x.len());
    for ((pa, va), (pb, vb)) in x.iter().zip(&y) {
        assert_eq!(pa, pb, "{what}");
        assert!(
            (va - vb).abs() <= 1e-12 * va.abs().max(1.0),
            "{what}: {pa}: {va} (command) vs {vb} (library)"
        );
    }
}

#[test]
fn the_library_calibrates_and_validates_as_the_commands_do() {
    let d = scratch("workflow", "same");
    let (robot, data, later) = (
        example("hexapod_66.toml"),
        example("hexapod_66_readings.csv"),
        example("hexapod_66_later.csv"),
    );
    // The commands.
    let by_command = d.join("command");
    ok(&[
        "calibrate",
        "--robot",
        &robot,
        "--data",
        &data,
        "--out",
        &p(&by_command),
    ]);
    let cal_toml = p(&by_command.join("calibrated.toml"));
    let validated: serde_json::Value = serde_json::from_str(&ok(&[
        "validate", "--robot", &cal_toml, "--data", &later, "--json",
    ]))
    .unwrap();
    // The library.
    let by_library = d.join("library");
    let options = fit::CalibrateOptions::new(&robot, vec![PathBuf::from(&data)], &by_library);
    let job = fit::calibrate(&options, &Silent).unwrap();
    assert!(job.trouble().is_none());
    let inputs = [Path::new(&robot), Path::new(&data)];
    load::commit_dir(job.fitted.set, &by_library, &inputs, "calibrate", &Silent).unwrap();
    let v = validate::validate(
        &validate::ValidateOptions::new(by_library.join("calibrated.toml"), vec![later.into()]),
        &Silent,
    )
    .unwrap();
    // calibrated.toml alike byte for byte; calibration.json and the validation number for
    // number (timings aside).
    let read = |dir: &Path, f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    assert_eq!(
        read(&by_command, "calibrated.toml"),
        read(&by_library, "calibrated.toml")
    );
    let json = |dir: &Path| -> serde_json::Value {
        serde_json::from_str(&read(dir, "calibration.json")).unwrap()
    };
    same_numbers(&json(&by_command), &json(&by_library), "calibration.json");
    let library_validated = serde_json::from_str(&v.report.to_json().unwrap()).unwrap();
    same_numbers(&validated, &library_validated, "validation");
    assert!(v.report.calibrated.rms_um < v.report.reference.rms_um / 5.0);
}

#[test]
fn a_cancelled_job_writes_nothing_and_says_so() {
    let d = scratch("workflow", "cancel");
    let out = d.join("never");
    let progress = Collect::default();
    progress
        .cancel
        .store(true, std::sync::atomic::Ordering::Relaxed);
    let options = fit::CalibrateOptions::new(
        example("hexapod_66.toml"),
        vec![example("hexapod_66_readings.csv").into()],
        &out,
    );
    let err = fit::calibrate(&options, &progress)
        .err()
        .expect("cancelled");
    assert!(err.is::<cpm::workflow::Cancelled>(), "{err}");
    assert_eq!(
        cpm::workflow::error::exit_kind(&err),
        cpm::workflow::ExitKind::Trouble
    );
    assert!(!out.exists());
    // Not cancelled: the stages are reported as the job goes.
    let progress = Collect::default();
    let job = fit::calibrate(&options, &progress).unwrap();
    let stages = progress.stages.lock().unwrap().clone();
    assert!(
        stages.iter().any(|s| s.starts_with("fitting")),
        "{stages:?}"
    );
    assert!(job.fitted.cal.simulated);
}

/// The flag of the job the tripwire below stops, and its count of evaluations.
static TRIP_FLAG: std::sync::OnceLock<std::sync::Arc<std::sync::atomic::AtomicBool>> =
    std::sync::OnceLock::new();
static TRIP_CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// A link effect that does nothing but count its evaluations and cancel the job at the 2000th
/// (inside the fit: reading and the start take fewer).
#[derive(Debug)]
struct Tripwire;
impl cpm::calib::EffectModel for Tripwire {
    fn name(&self) -> &str {
        "workflow_tripwire"
    }
    fn num_params(&self, _: usize, _: usize) -> usize {
        1
    }
    fn param_name(&self, _: usize, _: &[String]) -> String {
        "trip".into()
    }
    fn unit(&self) -> &str {
        "um"
    }
    fn channels(&self) -> &[cpm::calib::Channel] {
        &[cpm::calib::Channel::LinkLength]
    }
    fn link_coefficient(&self, _: usize, _: usize, _: &cpm::calib::EffectInput) -> f64 {
        let n = TRIP_CALLS.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
        if n == 2000 {
            if let Some(f) = TRIP_FLAG.get() {
                f.store(true, std::sync::atomic::Ordering::SeqCst);
            }
        }
        0.0
    }
}

#[test]
fn a_job_cancelled_inside_its_fit_stops_there_and_writes_nothing() {
    let tripwire = cpm::calib::Effect::user(&Tripwire).unwrap();
    let d = scratch("workflow", "cancel-inside");
    let out = d.join("never");
    let progress = Collect::default();
    TRIP_FLAG.set(progress.cancel.clone()).unwrap();
    let mut options = fit::CalibrateOptions::new(
        example("hexapod_66.toml"),
        vec![example("hexapod_66_readings.csv").into()],
        &out,
    );
    options.fit.effects = Some(vec![tripwire]);
    let err = fit::calibrate(&options, &progress)
        .err()
        .expect("cancelled");
    assert!(err.is::<cpm::workflow::Cancelled>(), "{err}");
    // It stopped inside the fit: the fitting stage had begun, the evaluations stopped soon
    // after the flag was set (a fit to its end takes many times more), nothing was written.
    let stages = progress.stages.lock().unwrap().clone();
    assert!(
        stages.iter().any(|s| s.starts_with("fitting")),
        "{stages:?}"
    );
    let calls = TRIP_CALLS.load(std::sync::atomic::Ordering::SeqCst);
    assert!((2000..4000).contains(&calls), "{calls} evaluations");
    assert!(!out.exists());
}

#[test]
fn the_library_analyses_exports_and_compensates_as_the_commands_do() {
    let robot = example("hexapod_66.toml");
    let data = example("hexapod_66_readings.csv");
    // identifiability: the report of the job is the command's --json, byte for byte, for
    // measurements and for a plan.
    let by_command = ok(&[
        "identifiability",
        "--robot",
        &robot,
        "--data",
        &data,
        "--json",
    ]);
    let mut options = identifiability::IdentifiabilityOptions::new(&robot);
    options.data = vec![PathBuf::from(&data)];
    let job = identifiability::identifiability(&options, &Silent).unwrap();
    let v = serde_json::to_value(&job.doc).unwrap();
    assert_eq!(
        by_command,
        format!("{}\n", serde_json::to_string_pretty(&v).unwrap())
    );
    assert!(job.doc.simulated);
    let by_command = ok(&[
        "identifiability",
        "--robot",
        &robot,
        "--circle",
        "--count",
        "12",
        "--json",
    ]);
    let mut options = identifiability::IdentifiabilityOptions::new(&robot);
    options.plan.circle = true;
    options.plan.count = 12;
    let job = identifiability::identifiability(&options, &Silent).unwrap();
    let v = serde_json::to_value(&job.doc).unwrap();
    assert_eq!(
        by_command,
        format!("{}\n", serde_json::to_string_pretty(&v).unwrap())
    );
    // Options that contradict each other: the usage error of the command (exit code 2).
    options.data = vec![PathBuf::from(&data)];
    let err = options.validate().unwrap_err();
    assert_eq!(
        cpm::workflow::error::exit_kind(&err),
        cpm::workflow::ExitKind::Usage
    );

    // export: the settings on standard output, in inches.
    let truth = example("hexapod_66_truth.toml");
    let by_command = ok(&[
        "export", "--format", "linuxcnc", "--robot", &truth, "--units", "inch",
    ]);
    let mut options = export::ExportOptions::new(&truth);
    options.units = export::Units::Inch;
    let job = export::export(&options, &Silent).unwrap();
    assert_eq!(by_command, job.hal);
    assert!(job.ini.is_none());

    // compensate: the commands file on standard output, and its notes.
    let targets = example("targets.csv");
    let by_command = ok(&["compensate", "--robot", &truth, "--poses", &targets]);
    let options = compensate::CompensateOptions::new(&truth, &targets);
    let progress = Collect::default();
    let job = compensate::compensate(&options, &progress).unwrap();
    assert_eq!(by_command, job.csv);
    assert_eq!(job.readings.len(), job.targets.len());
    let bad = compensate::CompensateOptions {
        temperature_c: Some(f64::NAN),
        ..options
    };
    assert!(bad.validate().is_err());
}

#[test]
fn the_library_simulates_as_the_command_does() {
    let robot = example("hexapod_66.toml");
    let truth = example("hexapod_66_truth.toml");
    let dir = scratch("workflow", "simulate");
    // Readings with link effects and noise: the file the command writes is the job's text,
    // byte for byte, and the command's --json is the job's summary.
    let out = dir.join("data.csv");
    let by_command = ok(&[
        "simulate",
        "--robot",
        &robot,
        "--random",
        "15",
        "--truth",
        &truth,
        "--effects",
        "link_offset",
        "--noise",
        "gaussian:2",
        "--seed",
        "7",
        "--out",
        &p(&out),
        "--json",
    ]);
    let mut options = simulate::SimulateOptions::new(&robot);
    options.plan.random = Some(15);
    options.plan.seed = 7;
    options.truth = Some(PathBuf::from(&truth));
    options.effects = Some(vec![cpm::calib::Effect::LinkOffset]);
    options.noise = Some("gaussian:2".into());
    options.validate().unwrap();
    let job = simulate::simulate(&options, &Silent).unwrap();
    assert_eq!(std::fs::read_to_string(&out).unwrap(), job.text);
    assert_eq!(by_command, format!("{}\n", job.summary(&out).to_json()));
    assert_eq!(job.campaign.poses.len(), 15);
    // Tracker poses in a tracker frame, on standard output.
    let by_command = ok(&[
        "simulate",
        "--robot",
        &robot,
        "--circle",
        "--count",
        "8",
        "--truth",
        &truth,
        "--measure",
        "poses",
        "--orientation-noise-urad",
        "5",
        "--tracker-frame",
        "100,-50,20,1,2,-3",
        "--out",
        "-",
    ]);
    let mut options = simulate::SimulateOptions::new(&robot);
    options.plan.circle = true;
    options.plan.count = 8;
    options.truth = Some(PathBuf::from(&truth));
    options.measure = simulate::Measure::Poses;
    options.orientation_noise_urad = 5.0;
    options.tracker_frame = Some("100,-50,20,1,2,-3".into());
    let job = simulate::simulate(&options, &Silent).unwrap();
    assert_eq!(by_command, job.text);
    // A tracker frame for length readings: the command's usage error (exit code 2).
    options.measure = simulate::Measure::Lengths;
    let err = options.validate().unwrap_err();
    assert_eq!(
        cpm::workflow::error::exit_kind(&err),
        cpm::workflow::ExitKind::Usage
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The commands' options by name (how Python gives them, `cpm._cpm.job`): every option of
/// each command is a field of its workflow options under the same name (`--sigma-um` is
/// `sigma_um`), no field is missing from the command line, and the options struct's defaults
/// (`new`) are the command's. Options given by name can therefore not drift from the
/// command's.
#[test]
fn options_by_name_are_the_commands_with_the_commands_defaults() {
    use clap::{CommandFactory, Parser};
    use cpm::cli::{Cli, Command};
    use serde_json::Value;
    use std::collections::BTreeSet;

    let parse = |argv: &str| -> Command {
        Cli::try_parse_from(std::iter::once("cpm").chain(argv.split_whitespace()))
            .unwrap_or_else(|e| panic!("{argv}: {e}"))
            .command
    };
    let options: Value = match parse("calibrate --robot R --data D --out O") {
        Command::Calibrate(a) => serde_json::to_value(a.options()).unwrap(),
        _ => unreachable!(),
    };
    let cases: Vec<(&str, Value, Value)> = vec![
        (
            "calibrate",
            options,
            serde_json::to_value(fit::CalibrateOptions::new("R", vec!["D".into()], "O")).unwrap(),
        ),
        (
            "refine",
            match parse("refine --robot R --data D --out O") {
                Command::Refine(a) => serde_json::to_value(a.options()).unwrap(),
                _ => unreachable!(),
            },
            serde_json::to_value(cpm::workflow::refine::RefineOptions::new(
                "R",
                vec!["D".into()],
                "O",
            ))
            .unwrap(),
        ),
        (
            "validate",
            match parse("validate --robot R --data D") {
                Command::Validate(a) => serde_json::to_value(a.options()).unwrap(),
                _ => unreachable!(),
            },
            serde_json::to_value(validate::ValidateOptions::new("R", vec!["D".into()])).unwrap(),
        ),
        (
            "identifiability",
            match parse("identifiability --robot R") {
                Command::Identifiability(a) => serde_json::to_value(a.options()).unwrap(),
                _ => unreachable!(),
            },
            serde_json::to_value(identifiability::IdentifiabilityOptions::new("R")).unwrap(),
        ),
        (
            "simulate",
            match parse("simulate --robot R --out O") {
                Command::Simulate(a) => serde_json::to_value(a.options()).unwrap(),
                _ => unreachable!(),
            },
            serde_json::to_value(simulate::SimulateOptions {
                out: Some("O".into()),
                ..simulate::SimulateOptions::new("R")
            })
            .unwrap(),
        ),
        (
            "compensate",
            match parse("compensate --robot R --poses P") {
                Command::Compensate(a) => serde_json::to_value(a.options()).unwrap(),
                _ => unreachable!(),
            },
            serde_json::to_value(compensate::CompensateOptions::new("R", "P")).unwrap(),
        ),
        (
            "design",
            match parse("design --robot R --out O") {
                Command::Design(a) => serde_json::to_value(a.options()).unwrap(),
                _ => unreachable!(),
            },
            serde_json::to_value(cpm::workflow::design::DesignJobOptions::new("R", "O")).unwrap(),
        ),
        (
            "export",
            match parse("export --format linuxcnc --robot R") {
                Command::Export(a) => serde_json::to_value(a.options()).unwrap(),
                _ => unreachable!(),
            },
            serde_json::to_value(export::ExportOptions::new("R")).unwrap(),
        ),
    ];
    let cli = Cli::command();
    for (name, from_cli, from_new) in cases {
        assert_eq!(from_cli, from_new, "{name}: the defaults differ");
        let fields: BTreeSet<String> = from_new.as_object().unwrap().keys().cloned().collect();
        let flags: BTreeSet<String> = cli
            .find_subcommand(name)
            .unwrap()
            .get_arguments()
            .filter_map(|a| a.get_long())
            .filter(|l| !["json", "quiet", "help"].contains(l))
            .map(|l| l.replace('-', "_"))
            .collect();
        assert_eq!(fields, flags, "{name}: fields and options differ");
    }
    // Options given by name come back as they went (what the binding relies on).
    let mut o = validate::ValidateOptions::new("R", vec!["D".into()]);
    o.pose_sigma_um = Some(3.5);
    o.truth_effect = vec!["backlash=1,2".into()];
    let back: validate::ValidateOptions =
        serde_json::from_value(serde_json::to_value(&o).unwrap()).unwrap();
    assert_eq!(back, o);
}
