//! An instrument from outside through the workflow (issue 59 item 6): the pinhole camera of
//! cpm-calib's `tests/camera/instrument.rs` (written against cpm-calib's public API only) and
//! the design's gauge readings, both SIMULATED and held in memory, fitted by
//! `memory::calibrate_with_instruments`: the reports name the camera's parameters, and the
//! `calibrated.toml` it stages, read back with the same camera, reproduces its predictions,
//! and `validate` checks it on held-out measurements in memory.
use std::sync::Arc;

use cpm_calib::instruments::Instrument;
use cpm_calib::model::{predict, Prepared};
use cpm_calib::{paper, Campaign, MeasurementModel};
use cpm_geometry::description::{RobotDescription, SensorSpec};
use cpm_workflow::fit::{CalibrateOptions, Calibrated};
use cpm_workflow::io::Robot;
use cpm_workflow::memory::{self, InMemory, InstrumentRows, Source};
use cpm_workflow::validate::{self, ValidateOptions};

#[path = "../../cpm-calib/tests/camera/instrument.rs"]
mod instrument;
#[path = "../../cpm-calib/tests/camera/simulated.rs"]
mod simulated;

/// The paper's machine with the designed sensors, as a description in memory.
fn robot() -> Robot {
    let mut d = RobotDescription::paper_cubic();
    d.sensors = paper::designed_sensors()
        .iter()
        .map(SensorSpec::from_sensor)
        .collect();
    Robot::from_description(d, "paper cubic (in memory)").unwrap()
}

/// The SIMULATED campaign as the workflow takes it: the gauge readings as the text of their
/// file, the camera's measurements as values (`seed` draws other poses and noise). Returns
/// the sources, the camera, the truth.
fn sources(robot: &Robot, seed: u64) -> (Vec<Source>, Arc<dyn Instrument>, Vec<f64>) {
    let (model, data, truth) = simulated::campaign(robot.model(&[]), true, 60, seed);
    let gauges = Campaign {
        instrument_measurements: Vec::new(),
        ..data.clone()
    };
    let text = cpm_workflow::io::write_readings(&gauges, robot, "camera test");
    let camera = InstrumentRows {
        file: "camera (simulated, in memory)".into(),
        poses: data.poses.clone(),
        pose_labels: Vec::new(),
        measurements: data.instrument_measurements.clone(),
        simulated: true,
    };
    let sources = vec![
        Source::Text {
            name: "gauges (simulated, in memory)".into(),
            text: text.into(),
        },
        Source::Instruments(Arc::new(camera)),
    ];
    (sources, model.instruments[0].clone(), truth)
}

fn calibrate(out: &std::path::Path) -> (Calibrated, Arc<dyn Instrument>, Vec<f64>) {
    let robot = robot();
    let (sources, camera, truth) = sources(&robot, 0);
    let mut options = CalibrateOptions::new("paper cubic (in memory)", Vec::new(), out);
    options.fit.sigma_um = Some(1.0);
    let c = memory::calibrate_with_instruments(
        &options,
        robot,
        &sources,
        std::slice::from_ref(&camera),
        &cpm_workflow::Silent,
    )
    .unwrap();
    (c, camera, truth)
}

/// What `model` predicts at `params` for `campaign`.
fn predictions(model: &MeasurementModel, campaign: &Campaign, params: &[f64]) -> Vec<f64> {
    let prepared = Prepared::new(model, campaign).unwrap();
    predict(model, &prepared, campaign, params, None).unwrap()
}

#[test]
fn the_camera_is_calibrated_in_memory_named_in_the_reports_and_read_back() {
    let out = std::env::temp_dir().join("cpm-camera-test-unwritten");
    let (c, camera, truth) = calibrate(&out);
    let (cal, set) = (&c.fitted.cal, &c.fitted.set);
    assert!(cal.simulated && cal.succeeded());
    let campaign = &c.inputs.merged.campaign;
    assert_eq!(campaign.instrument_measurements.len(), 60);
    assert_eq!(
        campaign.poses.len(),
        120,
        "the camera's poses after the gauges'"
    );
    // The reports name the camera's parameters, in their units.
    let text = |f: &str| String::from_utf8(set.contents(&out.join(f)).unwrap().to_vec()).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text("calibration.json")).unwrap();
    let names: Vec<&str> = json["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    let report = text("report.md");
    for k in 0..7 {
        let name = format!("camera {} [{}]", camera.param_name(k), camera.param_unit(k));
        assert!(names.contains(&name.as_str()), "{name} in {names:?}");
        assert!(report.contains(&name), "{name} in report.md");
    }
    // residuals.csv gives the camera's residuals in px, each at its pose.
    let residuals =
        String::from_utf8(set.bytes(&out.join("residuals.csv")).unwrap().to_vec()).unwrap();
    let camera_rows: Vec<&str> = residuals
        .lines()
        .filter(|l| l.contains("camera (simulated, in memory)"))
        .collect();
    assert_eq!(camera_rows.len(), 120, "two values per measurement");
    assert!(
        camera_rows[1].contains("instrument 1 channel 1 value 2 at pose \"\"1\"\""),
        "{}",
        camera_rows[1]
    );
    assert!(
        camera_rows.iter().all(|l| l.contains(",px,")),
        "{}",
        camera_rows[0]
    );
    // In px: their RMS is the camera's noise (0.1 px), not a thousand times it.
    let values: Vec<f64> = camera_rows
        .iter()
        .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
        .collect();
    let rms = (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt();
    assert!((0.05..0.15).contains(&rms), "camera residual RMS {rms} px");
    // The installation errors the gauges determine, within their standard deviations.
    for k in 0..36 {
        let (e, s) = (cal.estimate_um[k].unwrap(), cal.std_um[k].unwrap());
        assert!(
            (e - truth[k]).abs() < 4.0 * s,
            "{k}: {e} +- {s}, truth {}",
            truth[k]
        );
    }
    // calibrated.toml holds the camera's values and, read back with the same camera,
    // predicts what the fit predicted.
    let toml = text("calibrated.toml");
    assert!(toml.contains("[calibration.instruments]"), "{toml}");
    let back = Robot::from_toml(&toml, "calibrated.toml").unwrap();
    let (model, params) = memory::calibrated_model(&back, std::slice::from_ref(&camera)).unwrap();
    // At the commands the fit assumed (the read-back machine's own inverse kinematics would
    // be other commands).
    let mut campaign = campaign.clone();
    c.inputs.model.log_commands(&mut campaign);
    let campaign = &campaign;
    let fitted = predictions(&c.inputs.model, campaign, &cal.minimum_norm_um);
    let read_back = predictions(&model, campaign, &params);
    let worst = fitted
        .iter()
        .zip(&read_back)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-6, "read back differs by {worst} (mm or px)");
    // The nominal robot with the nominal camera predicts otherwise: the check can fail.
    let (nominal, zero) =
        memory::calibrated_model(&c.inputs.robot, std::slice::from_ref(&camera)).unwrap();
    let camera_rows = campaign.first_instrument_observation();
    let off = predictions(&nominal, campaign, &zero)[camera_rows..]
        .iter()
        .zip(&fitted[camera_rows..])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(off > 1.0, "the nominal camera is {off} px off");
    // Validated on held-out data in memory (other poses, other noise): the calibrated camera
    // and machine predict the marker to about the camera's noise, the nominal ones do not.
    let (held_out, _, _) = sources(&c.inputs.robot, 1);
    let held = InMemory {
        robot: Some(back),
        reference: Some(c.inputs.robot.clone()),
        data: Some(held_out),
        instruments: vec![camera],
        ..InMemory::none()
    };
    let options = ValidateOptions {
        out: Some(out.join("validation")),
        ..ValidateOptions::default()
    };
    let v = validate::validate_in(&options, held, &cpm_workflow::Silent).unwrap();
    assert!(v.report.simulated);
    let [seen] = &v.report.instruments[..] else {
        panic!("{:?}", v.report.instruments)
    };
    assert_eq!(
        (seen.name.as_str(), seen.unit.as_str(), seen.count),
        ("camera", "px", 120)
    );
    let (calibrated, reference) = (seen.calibrated.0, seen.reference.0);
    println!("held-out marker RMS: calibrated {calibrated:.3} px, nominal {reference:.3} px");
    assert!(calibrated < 2.0 * simulated::NOISE_PX, "{calibrated} px");
    assert!(reference > 10.0 * calibrated, "{reference} px");
    let json = v.report.to_json().unwrap();
    assert!(json.contains("\"instruments\""), "{json}");
    assert!(v
        .report
        .markdown(false)
        .contains("| camera (`camera (simulated, in memory)`) | 120 | px |"));
}

#[test]
fn measurements_without_their_instrument_or_under_one_name_are_refused() {
    let robot = robot();
    let (sources, camera, _) = sources(&robot, 0);
    let out = std::env::temp_dir().join("cpm-camera-test-refused");
    let options = CalibrateOptions::new("paper cubic (in memory)", Vec::new(), out);
    let silent = &cpm_workflow::Silent;
    let e = memory::calibrate(&options, robot.clone(), &sources, silent)
        .err()
        .unwrap();
    assert!(e.to_string().contains("without the instruments"), "{e}");
    let twice = [camera.clone(), camera];
    let e = memory::calibrate_with_instruments(&options, robot, &sources, &twice, silent)
        .err()
        .unwrap();
    assert!(
        e.to_string().contains("two instruments are named `camera`"),
        "{e}"
    );
}
