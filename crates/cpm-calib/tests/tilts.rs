//! Inclinometers: the analytic Jacobian of `asin(up . a_k)` against finite differences, a fit
//! whose identifiable combinations hold the truth within their deviations, and what tilts
//! cannot see, named.
use cpm_calib::model::{predict, Predictions, Prepared};
use cpm_calib::paper::random_workspace_poses;
use cpm_calib::tilts::Inclinometer;
use cpm_calib::*;
use cpm_geometry::JointTable;
use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};

const SIGMA_URAD: f64 = 20.0;

/// The 6-6 hexapod with a two-axis inclinometer (first angle along +y, second along -x),
/// mounted 2 mrad off its drawing, two sessions, and `effects` plus the instrument's blocks.
fn model(effects: &[Effect]) -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::hexapod_66());
    m.inclinometers = vec![Inclinometer {
        name: "scl3300".into(),
        axes: vec![Vector3::y(), -Vector3::x()],
        mount: Rotation3::new(Vector3::new(0.002, -0.001, 0.003)),
    }];
    m.tilt_sessions = 2;
    m.effects = effects.to_vec();
    m.effects
        .extend([Effect::InclinometerMount, Effect::BaseTilt]);
    m
}

fn skeleton(m: &MeasurementModel, poses: usize) -> Campaign {
    let mut c = Campaign {
        poses: random_workspace_poses(&m.nominal, poses, 40.0, 8.0, 4.0, 21),
        tilt_sigma_urad: SIGMA_URAD,
        simulated: true,
        ..Campaign::default()
    };
    for j in 0..poses {
        for axis in 0..2 {
            c.tilt_measurements.push(TiltMeasurement {
                pose: j,
                inclinometer: 0,
                axis,
                session: usize::from(j >= poses / 2),
                angle_mrad: 0.0,
                time_s: None,
            });
        }
    }
    c.session_starts = vec![poses / 2];
    c
}

fn truth(m: &MeasurementModel) -> Vec<f64> {
    let mut v: Vec<f64> = (0..m.num_params())
        .map(|k| 30.0 * ((k as f64) * 0.83).sin())
        .collect();
    for b in m.blocks() {
        if matches!(
            b.effect,
            Some(Effect::InclinometerMount) | Some(Effect::BaseTilt)
        ) {
            for k in 0..b.len {
                v[b.offset + k] = 800.0 * ((k as f64) * 1.1 + 0.4).cos();
            }
        }
    }
    v
}

/// The angles `m` predicts at parameters `x`, plus gaussian noise of `SIGMA_URAD` (SIMULATED
/// through the fit's own prediction path).
fn measure(m: &MeasurementModel, x: &[f64], c: &mut Campaign, seed: u64) {
    let prepared = Prepared::new(m, c).unwrap();
    let y = predict(m, &prepared, c, x, None).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    for (t, y) in c.tilt_measurements.iter_mut().zip(&y) {
        let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random_range(0.0..1.0));
        let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        t.angle_mrad = y + g * SIGMA_URAD * 1e-3;
    }
}

#[test]
fn tilt_jacobian_matches_finite_differences() {
    let m = model(&[Effect::LinkOffset]);
    let c = skeleton(&m, 12);
    let mut problem = Predictions::new(&m, &c).unwrap();
    // Central differences (cpm-lm's checker), relative step 0.025.
    let check = cpm_lm::check_jacobian(&mut problem, &truth(&m), 0.025).unwrap();
    assert!(check.is_consistent(1e-5), "{check}");
    // The angle is the elevation of the axis: at the home pose, level, zero mount and tilt,
    // nothing to see; tilted by 10 mrad about x, the +y axis rises by asin(sin 10 mrad).
    let mut level = m.clone();
    level.inclinometers[0].mount = Rotation3::identity();
    level.clearance = cpm_clearance::ClearanceModel::none();
    let mut c1 = skeleton(&level, 2);
    c1.poses = vec![level.nominal.home, level.nominal.home];
    c1.poses[1].rotation = Rotation3::new(Vector3::new(0.01, 0.0, 0.0));
    let zeros = vec![0.0; level.num_params()];
    let prepared = Prepared::new(&level, &c1).unwrap();
    let y = predict(&level, &prepared, &c1, &zeros, None).unwrap();
    assert!(y[0].abs() < 1e-9 && y[1].abs() < 1e-9, "{y:?}");
    // Forward kinematics closes on the nominal lengths of the commanded pose (no clearance).
    assert!((y[2] - 10.0).abs() < 1e-6, "{}", y[2]);
    assert!(y[3].abs() < 1e-6, "{}", y[3]);
}

#[test]
fn tilt_fit_holds_the_truth_within_its_deviations_and_names_the_blind() {
    let m = model(&[]);
    let x = truth(&m);
    let mut c = skeleton(&m, 60);
    measure(&m, &x, &mut c, 4);
    let options = IdentifyOptions {
        // The reference noise of the weighting: one tracker position's default (10 um).
        sigma_um: Some(10.0),
        ..IdentifyOptions::default()
    };
    let cal = identify(&m, &c, &options).unwrap();
    // Weighted residual: 10 um of reference per 20 urad of tilt noise.
    assert!(
        (cal.residual_rms_um - 10.0).abs() < 2.0,
        "{}",
        cal.residual_rms_um
    );
    let id = &cal.identifiability;
    // Tilts see orientation only: of 36 + 3 + 4 parameters at most the platform's two tilt
    // directions' worth of joint combinations, plus the instrument's.
    assert!(id.rank < 36, "rank {}", id.rank);
    let mut worst: f64 = 0.0;
    for (k, comb) in cal.combinations.iter().enumerate() {
        let v = id.v.column(k);
        let est: f64 = v.iter().zip(&cal.minimum_norm_um).map(|(a, b)| a * b).sum();
        let t: f64 = v.iter().zip(&x).map(|(a, b)| a * b).sum();
        worst = worst.max(((est - t) / comb.std_um).abs());
    }
    assert!(
        worst < 4.5,
        "worst {worst} sd over {} combinations",
        id.rank
    );
    let words: Vec<&str> = id
        .blind_directions
        .iter()
        .map(|b| b.description.as_str())
        .collect();
    let all = words.join("; ");
    eprintln!(
        "tilts: rank {} of {}, {} blind named ({all}), {} unexplained",
        id.rank,
        m.num_params(),
        words.len(),
        id.unexplained_null_dimensions
    );
    // Positions are invisible to tilts: every joint translation is blind.
    assert!(all.contains("all base joints translated together"), "{all}");
    assert!(
        all.contains("all platform joints translated together"),
        "{all}"
    );
}

/// Angles of a machine whose legs give under load (compliance, um per kN of link force),
/// SIMULATED through the fit's prediction path with 20 urad noise: `refine`, from a model
/// without it, finds the load-dependent effect from tilts alone, and the model it ends with
/// predicts blocks of poses it did not see better than plain calibration.
#[test]
fn refine_finds_leg_compliance_from_tilts_alone() {
    let truth_model = model(&[Effect::Compliance]);
    let mut x = truth(&truth_model);
    let b = truth_model.blocks()[1];
    assert_eq!(b.effect, Some(Effect::Compliance));
    for k in 0..b.len {
        x[b.offset + k] = 3000.0 + 400.0 * k as f64;
    }
    let mut c = skeleton(&truth_model, 150);
    measure(&truth_model, &x, &mut c, 8);
    let options = RefineOptions {
        identify: IdentifyOptions {
            sigma_um: Some(10.0),
            ..IdentifyOptions::default()
        },
        ..RefineOptions::default()
    };
    let r = refine(&model(&[]), &c, &options).unwrap();
    let steps: Vec<Effect> = r.steps.iter().map(|s| s.effect).collect();
    eprintln!(
        "tilts with leg compliance: steps {steps:?}; blocked CV {:.2} -> {:.2} um of reference",
        r.against_calibrate.calibrate_cv_rms_um, r.against_calibrate.refined_cv_rms_um
    );
    assert_eq!(steps.first(), Some(&Effect::Compliance), "{steps:?}");
    assert!(r.against_calibrate.refined_cv_rms_um < 0.8 * r.against_calibrate.calibrate_cv_rms_um);
}

/// What a real inclinometer campaign teaches: with two angles per pose, link offsets and
/// scales trade against each other and the levelling (the common offset moves the platform
/// up and down, which an inclinometer sees only through second-order tilts). The fit must not
/// report an absurd solution as measured: each offset it states lies within a few of its
/// standard deviations of the truth (large ones: the data barely see them), and the point it
/// writes stays near the truth's scale instead of running off by a hundred millimetres.
#[test]
fn link_offsets_from_tilts_alone_do_not_run_off() {
    let m = model(&[Effect::LinkOffset, Effect::LinkScale]);
    let x = truth(&m);
    let mut c = skeleton(&m, 150);
    measure(&m, &x, &mut c, 9);
    let options = IdentifyOptions {
        sigma_um: Some(10.0),
        ..IdentifyOptions::default()
    };
    let cal = identify(&m, &c, &options).unwrap();
    let b = m.blocks()[1];
    assert_eq!(b.effect, Some(Effect::LinkOffset));
    let offsets = &cal.estimate_um[b.offset..b.offset + b.len];
    let undetermined = offsets.iter().filter(|e| e.is_none()).count();
    let mut worst_z: f64 = 0.0;
    let mut sds = Vec::new();
    for k in b.offset..b.offset + b.len {
        if let (Some(e), Some(sd)) = (cal.estimate_um[k], cal.std_um[k]) {
            worst_z = worst_z.max(((e - x[k]) / sd).abs());
            sds.push(sd);
        }
    }
    let largest_mm = cal.minimum_norm_um[b.offset..b.offset + b.len]
        .iter()
        .fold(0.0_f64, |a, v| a.max(v.abs()))
        * 1e-3;
    eprintln!(
        "tilts, link offsets and scales: rank {} of {}, {undetermined} of 6 offsets not determined, deviations of the others {sds:.0?} um, worst {worst_z:.2} sd off the truth; largest offset written {largest_mm:.4} mm",
        cal.identifiability.rank,
        m.num_params()
    );
    assert!(worst_z < 4.0, "{offsets:?} sd {sds:?}");
    assert!(largest_mm < 1.0, "{largest_mm} mm");
    assert!(cal.solver.was_successful());
}

/// The solver's Jacobian ([`Predictions`], written row by row straight into the solver's faer
/// storage) is the model's ([`predict`] into a nalgebra matrix), bit for bit, and every entry
/// of it is written (the solver's storage starts as NaN): for inclinometer angles and for
/// gauge readings.
#[test]
fn the_solver_jacobian_is_the_models_bit_for_bit() {
    let same = |m: &MeasurementModel, c: &Campaign, x: &[f64]| {
        let prepared = Prepared::new(m, c).unwrap();
        let mut j = nalgebra::DMatrix::zeros(c.len(), m.num_params());
        predict(m, &prepared, c, x, Some(&mut j)).unwrap();
        let mut problem = Predictions::new(m, c).unwrap();
        let mut f = cpm_lm::faer::Mat::<f64>::from_fn(c.len(), m.num_params(), |_, _| f64::NAN);
        cpm_lm::DenseJacobian::jacobian(&mut problem, x, f.as_mut()).unwrap();
        for (r, k) in (0..c.len()).flat_map(|r| (0..m.num_params()).map(move |k| (r, k))) {
            assert_eq!(
                f[(r, k)].to_bits(),
                j[(r, k)].to_bits(),
                "row {r}, parameter {k}"
            );
        }
        assert!(j.iter().any(|v| *v != 0.0));
    };
    let m = model(&[Effect::LinkOffset]);
    same(&m, &skeleton(&m, 12), &truth(&m));
    let mut gauges = MeasurementModel::new(JointTable::paper_cubic());
    gauges.nominal.sensors = cpm_calib::paper::designed_sensors();
    gauges.effects = vec![Effect::SensorOffset, Effect::LinkScale];
    let poses = random_workspace_poses(&gauges.nominal, 10, 60.0, 10.0, 3.0, 4);
    let c = Plan {
        poses,
        sensors: (0..16).collect(),
    }
    .skeleton();
    let x: Vec<f64> = (0..gauges.num_params())
        .map(|k| 20.0 * (k as f64 * 0.7).sin())
        .collect();
    same(&gauges, &c, &x);
}
