//! End-to-end benchmark of the two calibration formulations on simulated campaigns of the
//! paper's cube with 16 socket pairs: nested (forward kinematics in every residual, dense QR)
//! against implicit-loop (pose unknowns, Schur complement). `cargo xtask scale --sweep` runs
//! the same comparison up to 10^5 poses with peak memory.
//!
//! `stages`: `cpm calibrate`'s work on 10^6 readings (62,500 poses x 16 sensors) stage by
//! stage, so that a regression shows in one place: reading the file, the fit, the statistics
//! of its residuals, writing residuals.csv, building and rendering the report.
use std::hint::black_box;

use cpm::calib::implicit::{identify_implicit, ImplicitOptions};
use cpm::calib::paper::{designed_sensors, random_workspace_poses};
use cpm::calib::*;
use cpm::geometry::{InstallationErrors, JointTable};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};

fn campaign(poses: usize) -> (MeasurementModel, Campaign) {
    let mut model = MeasurementModel::new(JointTable::paper_cubic());
    model.nominal.sensors = designed_sensors();
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, poses, 100.0, 25.0, 3.0, 1),
        sensors: (0..16).collect(),
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
    (model, data)
}

fn formulations(c: &mut Criterion) {
    let mut group = c.benchmark_group("calibration");
    group.sample_size(10);
    for poses in [100usize, 1000] {
        let (model, data) = campaign(poses);
        group.bench_with_input(BenchmarkId::new("nested_dense", poses), &poses, |b, _| {
            b.iter(|| identify(&model, black_box(&data), &IdentifyOptions::default()))
        });
        group.bench_with_input(BenchmarkId::new("implicit_schur", poses), &poses, |b, _| {
            b.iter(|| identify_implicit(&model, black_box(&data), &ImplicitOptions::default()))
        });
    }
    group.finish();
}

/// The implicit formulation's two solvers side by side: the streamed Schur accumulation (no
/// stored Jacobian, parallel over poses) and cpm-lm's general Schur solver on the stored
/// sparse Jacobian (the peer: the same normal equations, the same result).
fn implicit_solvers(c: &mut Criterion) {
    let mut group = c.benchmark_group("implicit");
    group.sample_size(10);
    for poses in [1000usize, 10_000] {
        let (model, data) = campaign(poses);
        for (label, streamed) in [("streamed", true), ("stored_jacobian", false)] {
            let opts = ImplicitOptions {
                streamed,
                ..ImplicitOptions::default()
            };
            group.bench_with_input(BenchmarkId::new(label, poses), &poses, |b, _| {
                b.iter(|| identify_implicit(&model, black_box(&data), &opts))
            });
        }
    }
    group.finish();
}

/// The real inclinometer session (tests/data/jugglebot_tilt, measured: 285 poses, 570 angles)
/// as `cpm calibrate` and `cpm refine` load it: the model with the instruments' unknowns, the
/// description's tolerances.
fn tilt_session() -> (MeasurementModel, Campaign, IdentifyOptions) {
    use std::path::{Path, PathBuf};
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/jugglebot_tilt");
    let robot = cpm::io::Robot::load(&dir.join("robot.toml")).expect("robot");
    let effects = robot.declared_effects().expect("effects");
    let model = robot.model(&effects);
    let paths: Vec<PathBuf> = vec![dir.join("session_1.csv")];
    let merged = cpm::cli::common::load_data(
        &paths,
        &robot,
        &cpm::cli::common::read_options(&model),
        &cpm::cli::common::registration_options(&model),
    )
    .expect("data");
    let model = cpm::cli::common::with_instruments(&model, &merged.campaign).unwrap_or(model);
    let options = IdentifyOptions {
        tolerances: robot.tolerances().expect("tolerances"),
        ..IdentifyOptions::default()
    };
    (model, merged.campaign, options)
}

/// `refine` and `calibrate`'s fit on the real 285-pose inclinometer session (goal: refine
/// under 5 s on 2 cores).
fn real_session(c: &mut Criterion) {
    let (model, data, options) = tilt_session();
    let mut group = c.benchmark_group("real_tilt_session");
    group.sample_size(10);
    group.bench_function("identify_map", |b| {
        b.iter(|| identify(&model, black_box(&data), &options).expect("fit"))
    });
    let refine_options = RefineOptions {
        identify: options.clone(),
        ..RefineOptions::default()
    };
    group.bench_function("refine", |b| {
        b.iter(|| refine(&model, black_box(&data), &refine_options).expect("refine"))
    });
    group.finish();
}

/// `cpm calibrate` on 10^6 readings, stage by stage (each stage on the previous one's
/// output, made once outside the timing).
fn stages(c: &mut Criterion) {
    use cpm::calib::diagnostics::{diagnose, outliers_by_kind};
    use cpm::calib::fit::formulation::{identify_with, Formulation};
    use cpm::io::{merge, read_data, write_readings, ReadOptions, Robot};
    use cpm::report::fit::{FitInputs, FitReport};
    let mut robot =
        Robot::from_description(cpm::geometry::RobotDescription::paper_cubic(), "cube.toml")
            .expect("the paper's cube");
    robot.table.sensors = designed_sensors();
    let (model, data) = campaign(62_500);
    let text = write_readings(&data, &robot, "benchmark");
    let read = || read_data(&text, "readings.csv", &robot, &ReadOptions::default());
    let merged = merge(vec![read().expect("read")], &robot);
    let options = IdentifyOptions::default();
    let fit = || identify_with(Formulation::Implicit, &model, &merged.campaign, &options);
    let cal = fit().expect("fit");
    let mut group = c.benchmark_group("stages");
    group.sample_size(10);
    group.bench_function("read", |b| b.iter(|| read().expect("read")));
    group.bench_function("fit", |b| b.iter(|| fit().expect("fit")));
    let r = &cal.residuals_um;
    group.bench_function("statistics", |b| {
        b.iter(|| {
            let outliers = outliers_by_kind(black_box(r), &merged.campaign, Some(1.0));
            let d = diagnose(black_box(r), r.len() - 36, Some(1.0), &[], 0.01);
            let noise = cpm::calib::noise::by_kind(&model, &merged.campaign, &cal);
            (outliers, d, noise)
        })
    });
    let w = merged.campaign.observation_weights(cal.sigma_ref_um);
    let native: Vec<f64> = r.iter().zip(&w).map(|(r, w)| -r / w).collect();
    // As `cpm calibrate` writes residuals.csv: streamed as it is made (here to a sink).
    group.bench_function("residuals_csv", |b| {
        b.iter(|| {
            let mut out = std::io::sink();
            cpm::report::residuals::write_residual_rows(
                &mut out,
                &robot,
                &merged,
                black_box(&native),
                1,
            )
        })
    });
    let provenance = cpm::io::Provenance {
        robot: "cube.toml".into(),
        data: vec!["readings.csv".into()],
    };
    let inputs = FitInputs {
        robot: &robot,
        merged: &merged,
        provenance: &provenance,
        loss: &options.lm.loss,
    };
    group.bench_function("report", |b| {
        b.iter(|| {
            let report = FitReport::new(&inputs, &model, black_box(&cal), None);
            let mut markdown = String::new();
            report.markdown_sections(&mut markdown);
            (report.to_json().expect("json"), markdown)
        })
    });
    group.finish();
}

criterion_group!(
    benches,
    formulations,
    implicit_solvers,
    real_session,
    stages
);
criterion_main!(benches);
