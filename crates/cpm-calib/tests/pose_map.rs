//! Acceptance of the pose error map: campaigns on the paper's cube with 4 x 4 socket pairs,
//! 120 poses and uniform +-10 um noise whose platform carries an error that follows the pose
//! (simulated: the truth is computed here, by moving the platform forward kinematics finds,
//! not through the pose map effect).
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable, Pose};
use nalgebra::Vector6;
use rand::{Rng, SeedableRng};

const HALF_WIDTH_UM: f64 = 10.0;

fn sigma_um() -> f64 {
    HALF_WIDTH_UM / 3f64.sqrt()
}

fn base_model() -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::paper_cubic());
    m.nominal.sensors = designed_sensors();
    m
}

/// A simulated campaign: the paper's Table 2 errors, the platform moved by `twist(commanded)`
/// (mm, rad) after forward kinematics, uniform noise.
fn campaign(twist: impl Fn(&Pose) -> Vector6<f64>, poses: usize, seed: u64) -> Campaign {
    let model = base_model();
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, poses, 100.0, 25.0, 3.0, seed),
        sensors: (0..model.nominal.sensors.len()).collect(),
    };
    let mut c = plan.skeleton();
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let table = model.table_with(&truth).unwrap();
    let lengths = model.effective_lengths(&c).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    for r in c.readings.iter_mut() {
        let commanded = c.poses[r.pose];
        let (fk, _) =
            cpm_kinematics::forward(&table, &lengths[r.pose], &commanded, &model.fk).unwrap();
        let moved = fk.perturbed(&twist(&commanded));
        r.length_mm = table.sensors[r.sensor].length_mm(&moved)
            + model.sensor_correction_mm()
            + rng.random_range(-HALF_WIDTH_UM..=HALF_WIDTH_UM) * 1e-3;
    }
    c.simulated = true;
    c
}

fn options() -> RefineOptions {
    RefineOptions {
        identify: IdentifyOptions {
            sigma_um: Some(sigma_um()),
            ..IdentifyOptions::default()
        },
        ..RefineOptions::default()
    }
}

fn y_units(p: &Pose) -> f64 {
    // The home pose of the paper's cube is at y = 0.
    p.position_mm.y / 100.0
}

fn check_case(name: &str, data: &Campaign, term: &str) {
    let r = refine(&base_model(), data, &options()).unwrap();
    let expected = Effect::parse(term).unwrap();
    let added: Vec<Effect> = r.steps.iter().map(|s| s.effect).collect();
    let first = r.steps.first().expect("a step");
    eprintln!(
        "{name}: scan top {:?}; steps {added:?}; CV RMS {:.3} -> {:.3} um (noise {:.3} um)",
        r.initial_pose_structure.first(),
        first.cv_rms_before_um,
        r.final_cv_rms_um,
        sigma_um()
    );
    // The diagnostics name the structure, refine adds the term.
    assert_eq!(r.initial_pose_structure[0].effect, expected, "{name}");
    assert!(added.contains(&expected), "{name}: {added:?}");
    // Cross-validated RMS at the noise (within 10 %).
    assert!(
        r.final_cv_rms_um < 1.1 * sigma_um(),
        "{name}: CV RMS {} um",
        r.final_cv_rms_um
    );
    assert!(
        first.cv_rms_before_um > 1.1 * sigma_um(),
        "{name}: {first:?}"
    );
    // The 36 installation errors stay within their bounds (4 standard deviations).
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let cal = &r.calibration;
    let mut determined = 0;
    for k in 0..36 {
        if let (Some(e), Some(s)) = (cal.estimate_um[k], cal.std_um[k]) {
            determined += 1;
            assert!(
                (e - truth[k]).abs() < 4.0 * s,
                "{name}: {} estimate {e:.2} truth {:.2} std {s:.2}",
                InstallationErrors::component_name(k),
                truth[k]
            );
        }
    }
    assert!(determined > 0, "{name}: nothing determined");
    // The pose range the map was fitted on is reported.
    assert!(
        r.pose_range.max[1] - r.pose_range.min[1] > 100.0,
        "{:?}",
        r.pose_range
    );
}

#[test]
fn a_roll_that_follows_y_is_named_and_removed() {
    let data = campaign(
        |p| Vector6::new(0.0, 0.0, 0.0, 60e-6 * y_units(p), 0.0, 0.0),
        120,
        11,
    );
    check_case("roll 60 urad x y/100 mm", &data, "pose_map_y");
}

#[test]
fn a_sag_in_y_squared_is_named_and_removed() {
    let data = campaign(
        |p| Vector6::new(0.0, 0.0, 30e-3 * y_units(p).powi(2), 0.0, 0.0, 0.0),
        120,
        12,
    );
    check_case("z 30 um x (y/100 mm)^2", &data, "pose_map_y2");
}

fn clean_count(seeds: std::ops::Range<u64>) -> Vec<(u64, Vec<Effect>)> {
    let mut added = Vec::new();
    for seed in seeds {
        let data = campaign(|_| Vector6::zeros(), 120, 5000 + seed);
        let r = refine(&base_model(), &data, &options()).unwrap();
        if !r.steps.is_empty() {
            added.push((seed, r.steps.iter().map(|s| s.effect).collect()));
        }
    }
    added
}

#[test]
fn clean_campaigns_get_nothing_added() {
    let added = clean_count(0..20);
    eprintln!(
        "clean campaigns: something added in {} of 20 seeds {added:?}",
        added.len()
    );
    assert!(added.len() <= 1, "{added:?}");
}

/// The 100-seed version (slow): `cargo test -p cpm-calib --test pose_map -- --ignored`.
#[test]
#[ignore]
fn clean_campaigns_get_nothing_added_in_95_of_100_seeds() {
    let added = clean_count(0..100);
    eprintln!(
        "clean campaigns: something added in {} of 100 seeds {added:?}",
        added.len()
    );
    assert!(added.len() <= 5, "{added:?}");
}

/// Both cases over ten more seeds (slow): how often the map term is added and the
/// cross-validated RMS reaches the noise within 10 %.
/// `cargo test -p cpm-calib --test pose_map -- --ignored --nocapture`.
#[test]
#[ignore]
fn both_cases_over_ten_seeds() {
    type Twist = fn(&Pose) -> Vector6<f64>;
    let cases: [(&str, Twist); 2] = [
        ("pose_map_y", |p| {
            Vector6::new(0.0, 0.0, 0.0, 60e-6 * y_units(p), 0.0, 0.0)
        }),
        ("pose_map_y2", |p| {
            Vector6::new(0.0, 0.0, 30e-3 * y_units(p).powi(2), 0.0, 0.0, 0.0)
        }),
    ];
    for (term, twist) in cases {
        let expected = Effect::parse(term).unwrap();
        let mut good = 0;
        for seed in 100..110 {
            let r = refine(&base_model(), &campaign(twist, 120, seed), &options()).unwrap();
            let added = r.steps.iter().any(|s| s.effect == expected);
            let cv = r.final_cv_rms_um;
            eprintln!("{term} seed {seed}: added {added}, CV RMS {cv:.3} um");
            good += usize::from(added && cv < 1.1 * sigma_um());
        }
        eprintln!("{term}: {good} of 10 seeds add the term and reach the noise");
        assert!(good >= 9, "{term}: {good} of 10");
    }
}
