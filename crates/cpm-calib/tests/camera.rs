//! An instrument from outside (issue 59 item 6): a pinhole camera watching a marker on the
//! platform, written against cpm-calib's public API only (`camera/instrument.rs`), fitted on a
//! SIMULATED campaign by `identify` like any built-in instrument: a camera 1.5 m from the
//! 500 mm-class machine (`JointTable::paper_cubic`), 0.1 px noise, random installation errors.
use cpm_calib::*;
use cpm_geometry::JointTable;

#[path = "camera/instrument.rs"]
mod instrument;
#[path = "camera/simulated.rs"]
mod simulated;

/// The SIMULATED campaign on the paper's machine (its designed sensors when `gauges`).
fn simulated(gauges: bool, poses: usize) -> (MeasurementModel, Campaign, Vec<f64>) {
    let mut model = MeasurementModel::new(JointTable::paper_cubic());
    if gauges {
        model.nominal.sensors = paper::designed_sensors();
    }
    simulated::campaign(model, gauges, poses, 0)
}

/// Fits the campaign and prints the table (parameter, truth, estimate, std) and the
/// identifiable combinations the data see.
fn fit_and_print(
    title: &str,
    model: &MeasurementModel,
    data: &Campaign,
    truth: &[f64],
) -> Calibration {
    let options = IdentifyOptions {
        sigma_um: Some(1.0),
        ..IdentifyOptions::default()
    };
    let cal = identify(model, data, &options).unwrap();
    assert!(cal.succeeded(), "{:?}", cal.solver.termination);
    assert!(cal.simulated);
    println!("\n{title} (SIMULATED)\n| parameter | truth | estimate | std |\n|---|---|---|---|");
    for (k, name) in model.parameter_names().iter().enumerate() {
        match (cal.estimate_um[k], cal.std_um[k]) {
            (Some(e), Some(s)) => println!("| {name} | {:.1} | {e:.1} | {s:.1} |", truth[k]),
            _ => println!("| {name} | {:.1} | not determined on its own | |", truth[k]),
        }
    }
    println!("{}", cal.identifiability.summary());
    cal
}

/// Each determined parameter's deviation from the truth, in its standard deviations.
fn determined_z(cal: &Calibration, truth: &[f64]) -> Vec<(usize, f64)> {
    (0..truth.len())
        .filter_map(|k| Some((k, (cal.estimate_um[k]? - truth[k]) / cal.std_um[k]?)))
        .collect()
}

/// The worst deviation from the truth, in standard deviations, of the identifiable
/// combinations `v^T x` (what the design sees, determined parameters or not).
fn worst_combination_z(cal: &Calibration, truth: &[f64]) -> f64 {
    let dot = |v: &[f64], x: &[f64]| v.iter().zip(x).map(|(a, b)| a * b).sum::<f64>();
    cal.combinations
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let v = cal.identifiability.v.column(k);
            let v = v.as_slice();
            ((dot(v, &cal.minimum_norm_um) - dot(v, truth)) / c.std_um).abs()
        })
        .fold(0.0, f64::max)
}

#[test]
fn the_camera_block_is_named_in_its_own_units() {
    let (model, _, _) = simulated(false, 4);
    let names = model.parameter_names();
    assert_eq!(names.len(), 36 + 7);
    assert_eq!(names[36], "camera x [um]");
    assert_eq!(names[39], "camera rx [urad]");
    assert_eq!(names[42], "camera focal [px]");
}

#[test]
fn the_cameras_jacobian_matches_finite_differences() {
    let (model, data, truth) = simulated(false, 10);
    let mut problem = cpm_calib::model::Predictions::new(&model, &data).unwrap();
    let check = cpm_lm::check_jacobian(&mut problem, &truth, 0.025).unwrap();
    assert!(check.is_consistent(1e-5), "{check}");
}

#[test]
fn the_camera_with_the_designs_gauges_identifies_the_machine_and_itself() {
    let (model, data, truth) = simulated(true, 80);
    let cal = fit_and_print("Gauges of the design and the camera", &model, &data, &truth);
    let names = model.parameter_names();
    let z = determined_z(&cal, &truth);
    // The gauges determine every installation error; what is left undetermined is the
    // camera's (its distance and focal length trade against each other: a telephoto view).
    assert!((0..36).all(|k| z.iter().any(|(j, _)| *j == k)), "{z:?}");
    assert!(
        z.iter().any(|(k, _)| *k >= 36),
        "some camera parameter is determined"
    );
    // That blind direction in words: the camera moved along its axis, its focal length
    // scaled alike (f / d per unit of distance).
    let id = identifiability(&model, &data, 1.0, &RankOptions::default()).unwrap();
    let camera = simulated::camera(&model.nominal);
    let axis = camera.rotation * nalgebra::Vector3::z();
    let mut telephoto = nalgebra::DVector::zeros(model.num_params());
    telephoto.rows_mut(36, 3).copy_from(&axis);
    telephoto[42] = -camera.focal_px * 1e-3 / 1500.0;
    let null = id.null_space();
    assert_eq!(null.ncols(), 1, "one blind direction");
    let cos = null.column(0).dot(&telephoto.normalize()).abs();
    assert!(
        cos > 0.99,
        "the blind direction is not the telephoto one: cos {cos}"
    );
    let worst = z.iter().map(|(_, z)| z.abs()).fold(0.0, f64::max);
    println!("worst determined parameter: {worst:.2} sd off the truth");
    for (k, z) in z {
        assert!(z.abs() < 4.0, "{}: {z:.2} sd off", names[k]);
    }
    let worst = worst_combination_z(&cal, &truth);
    assert!(worst < 4.0, "worst combination {worst:.2} sd off");
}

#[test]
fn the_camera_alone_identifies_what_it_can_see() {
    let (model, data, truth) = simulated(false, 80);
    let id = identifiability(&model, &data, 1.0, &RankOptions::default()).unwrap();
    // One marker seen in two pixel coordinates: some directions of the 43 parameters are
    // blind.
    assert!(
        id.rank < model.num_params() && id.rank > 20,
        "rank {}",
        id.rank
    );
    // One of them in words: every base joint moved along x, and the camera with them (the
    // whole machine shifted under a camera that follows it), while one joint alone is seen.
    let seen = |moved: &[usize]| {
        let mut v = nalgebra::DVector::zeros(model.num_params());
        moved.iter().for_each(|&k| v[k] = 1.0);
        (id.row_space().transpose() * v.normalize()).norm()
    };
    let base_and_camera_x = [0, 6, 12, 18, 24, 30, 36];
    assert!(
        seen(&base_and_camera_x) < 1e-6,
        "{}",
        seen(&base_and_camera_x)
    );
    assert!(seen(&[0]) > 0.1, "{}", seen(&[0]));
    let cal = fit_and_print("The camera alone", &model, &data, &truth);
    assert_eq!(cal.combinations.len(), cal.identifiability.rank);
    for (k, z) in determined_z(&cal, &truth) {
        assert!(
            z.abs() < 4.0,
            "{}: {z:.2} sd off",
            model.parameter_names()[k]
        );
    }
    let worst = worst_combination_z(&cal, &truth);
    println!(
        "worst of the {} identifiable combinations: {worst:.2} sd off the truth",
        cal.combinations.len()
    );
    assert!(worst < 4.0, "worst combination {worst:.2} sd off");
}
