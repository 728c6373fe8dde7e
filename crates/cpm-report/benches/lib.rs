//! Benchmarks of cpm-report: rendering a calibration report (report.md, calibration.json and
//! report.html) from the typed report of a fit of the paper's cube to simulated readings.
use std::hint::black_box;

use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::{identify, simulate, IdentifyOptions, Plan, SimulationOptions};
use cpm_geometry::{InstallationErrors, RobotDescription};
use cpm_io::{read_data, ReadOptions, Robot};
use cpm_report::calibrate::{CalibrateReport, CalibratedFile};
use cpm_report::fit::{FitInputs, FitReport};
use criterion::{criterion_group, criterion_main, Criterion};

/// The report of a fit of the paper's cube (16 designed sensors) to 40 simulated poses.
fn report() -> CalibrateReport {
    let mut robot = Robot::from_description(RobotDescription::paper_cubic(), "cube.toml")
        .expect("the paper's cube");
    robot.table.sensors = designed_sensors();
    let model = robot.model(&[]);
    let plan = Plan {
        poses: random_workspace_poses(&robot.table, 40, 100.0, 25.0, 3.0, 1),
        sensors: (0..16).collect(),
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
    let text = cpm_io::write_readings(&data, &robot, "benchmark");
    let file = read_data(&text, "readings.csv", &robot, &ReadOptions::default()).expect("read");
    let merged = cpm_io::merge(vec![file], &robot);
    let options = IdentifyOptions::default();
    let cal = identify(&model, &merged.campaign, &options).expect("fit");
    let provenance = cpm_io::Provenance {
        robot: "cube.toml".into(),
        data: vec!["readings.csv".into()],
    };
    let inputs = FitInputs {
        robot: &robot,
        merged: &merged,
        provenance: &provenance,
        loss: &options.lm.loss,
    };
    CalibrateReport {
        provenance: vec!["benchmark".into()],
        calibrated: CalibratedFile {
            minimum_norm: false,
            undetermined: 0,
            known_effects: Vec::new(),
        },
        figures: Vec::new(),
        fit: FitReport::new(&inputs, &model, &cal, None),
    }
}

fn bench(c: &mut Criterion) {
    let r = report();
    c.bench_function("calibrate_report_markdown", |b| {
        b.iter(|| black_box(&r).markdown())
    });
    c.bench_function("calibration_json", |b| {
        b.iter(|| black_box(&r).fit.to_json().expect("json"))
    });
    let md = r.markdown();
    c.bench_function("report_html", |b| {
        b.iter(|| cpm_report::html::report_page("cpm calibration report", black_box(&md), &[]))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
