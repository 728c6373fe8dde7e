//! What each instrument identifies on the 6-6 hexapod of `examples/` (its clearance and load),
//! from about 300 observations: three gauges, one laser-tracker reflector, three reflectors, a
//! two-axis inclinometer, a 6-D tracker, and a mix of gauges, one reflector and the
//! inclinometer, at random poses and at designed ones (A-optimal on the combinations the
//! instruments identify). Each instrument at its own noise (`InstrumentNoise::default()`: gauge
//! 1 um, points and tracker positions 10 um, orientations and angles 20 urad), each with its
//! nuisance parameters (frames, target positions, mount, levelling). All computed at the
//! nominal machine; no data are measured. Printed as a table with `--nocapture`.
use std::path::Path;

use cpm_calib::design::instruments::{InstrumentBounds, InstrumentNoise, Instruments};
use cpm_calib::design::SelectOptions;
use cpm_calib::paper::random_workspace_poses;
use cpm_calib::points::PointTarget;
use cpm_calib::tilts::Inclinometer;
use cpm_calib::MeasurementModel;
use cpm_geometry::{Pose, RobotDescription};
use nalgebra::{Rotation3, Vector3};

const BUDGET: usize = 300;

/// The example hexapod with three reflectors on its platform and a two-axis inclinometer
/// (first angle along +y, second along -x).
fn model() -> MeasurementModel {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let d = RobotDescription::load(examples.join("hexapod_66.toml")).unwrap();
    let mut m = MeasurementModel::from_description(&d).unwrap();
    m.targets = [
        [90.0, 10.0, 30.0],
        [-50.0, 80.0, 30.0],
        [-40.0, -85.0, 30.0],
    ]
    .iter()
    .enumerate()
    .map(|(k, p)| PointTarget {
        name: format!("smr{}", k + 1),
        platform_mm: Vector3::from(*p),
    })
    .collect();
    m.inclinometers = vec![Inclinometer {
        name: "scl3300".into(),
        axes: vec![Vector3::y(), -Vector3::x()],
        mount: Rotation3::identity(),
    }];
    m
}

fn poses(m: &MeasurementModel, n: usize, seed: u64) -> Vec<Pose> {
    random_workspace_poses(&m.nominal, n, 40.0, 8.0, 4.0, seed)
}

fn row(name: &str, b: &InstrumentBounds) -> String {
    format!(
        "| {name} | {} x {} = {} | {} of {} | {}/36 | {:.2} | {:.2} |",
        b.poses,
        b.observations / b.poses,
        b.observations,
        b.rank,
        b.parameters,
        b.joint_errors_determined,
        b.joint_crb_rms_um,
        b.joint_min_norm_rms_um
    )
}

#[test]
fn each_instrument_identifies_what_it_can_and_a_designed_mix_does_best() {
    let m = model();
    let noise = InstrumentNoise::default();
    let cases: Vec<(&str, Instruments)> = vec![
        (
            "3 gauges",
            Instruments {
                gauges: vec![0, 1, 2],
                ..Default::default()
            },
        ),
        (
            "1 SMR",
            Instruments {
                targets: vec![0],
                ..Default::default()
            },
        ),
        (
            "3 SMRs",
            Instruments {
                targets: vec![0, 1, 2],
                ..Default::default()
            },
        ),
        (
            "inclinometer",
            Instruments {
                inclinometers: vec![0],
                ..Default::default()
            },
        ),
        (
            "6-D tracker",
            Instruments {
                tracker: true,
                ..Default::default()
            },
        ),
    ];
    let mut table = vec![
        "| instruments | poses x obs = obs | rank | joint errors determined | CRB RMS of those (um) | min-norm RMS of the 36 (um) |".to_string(),
        "|---|---|---|---|---|---|".to_string(),
    ];
    let mut bounds = Vec::new();
    for (name, ins) in &cases {
        let n = BUDGET.div_ceil(ins.observations_per_pose(&m));
        let b = ins.bounds(&m, &poses(&m, n, 11), &noise).unwrap();
        table.push(row(name, &b));
        bounds.push(b);
    }
    let mix = Instruments {
        gauges: vec![0, 1, 2],
        targets: vec![0],
        inclinometers: vec![0],
        ..Default::default()
    };
    let n = BUDGET.div_ceil(mix.observations_per_pose(&m));
    let random_mix = mix.bounds(&m, &poses(&m, n, 11), &noise).unwrap();
    table.push(row("mix, random poses", &random_mix));
    let candidates = poses(&m, 600, 12);
    let chosen = mix
        .design(&m, &candidates, n, &noise, &SelectOptions::default())
        .unwrap();
    let designed = mix.bounds(&m, &chosen, &noise).unwrap();
    table.push(row("mix, designed poses", &designed));
    let gauges_designed = cases[0]
        .1
        .design(
            &m,
            &candidates,
            BUDGET / 3,
            &noise,
            &SelectOptions::default(),
        )
        .unwrap();
    let gauges_designed = cases[0].1.bounds(&m, &gauges_designed, &noise).unwrap();
    table.push(row("3 gauges, designed poses", &gauges_designed));
    println!("{}", table.join("\n"));
    for (b, (name, _)) in bounds.iter().zip(&cases) {
        println!("{name}: blind {:?}", b.blind_directions);
    }

    let [gauges, smr1, smr3, incl, tracker] = &bounds[..] else {
        unreachable!()
    };
    // Gauges on the example's sockets see every joint error.
    assert_eq!(gauges.joint_errors_determined, 36);
    // Points and a tracker bring their frames' gauge freedoms: the base joints move with the
    // frame, so not every joint error is determined on its own, but the combinations are.
    assert!(smr3.rank > smr1.rank, "{} vs {}", smr3.rank, smr1.rank);
    assert!(smr3.joint_min_norm_rms_um < smr1.joint_min_norm_rms_um);
    assert!(tracker.rank >= smr3.rank - 3);
    // An inclinometer sees orientation only: blind to every position, named so.
    assert!(incl.rank < 36, "{}", incl.rank);
    assert!(incl.joint_errors_determined < 36);
    assert!(!incl.blind_directions.is_empty());
    // The design helps the mix and the gauges.
    assert!(designed.joint_min_norm_rms_um < random_mix.joint_min_norm_rms_um);
    assert!(gauges_designed.joint_crb_rms_um < gauges.joint_crb_rms_um);
    assert_eq!(designed.poses, n);
}

/// The bounds hold in simulation: the designed mix (gauges, one reflector, the inclinometer)
/// measured 40 times on a machine with known joint errors and nuisance values, each campaign
/// fitted: the RMS error of the 36 joint errors is within 15 % of the Cramér-Rao RMS. The
/// measurements come from the fit's own prediction path plus gaussian noise at each
/// instrument's sigma (SIMULATED).
#[test]
fn monte_carlo_of_the_designed_mix_meets_its_bound() {
    use cpm_calib::model::{predict, Prepared};
    use cpm_calib::{identify, IdentifyOptions};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    let m = model();
    let noise = InstrumentNoise::default();
    let mix = Instruments {
        gauges: vec![0, 1, 2],
        targets: vec![0],
        inclinometers: vec![0],
        ..Default::default()
    };
    let n = BUDGET.div_ceil(mix.observations_per_pose(&m));
    let chosen = mix
        .design(
            &m,
            &poses(&m, 600, 12),
            n,
            &noise,
            &SelectOptions::default(),
        )
        .unwrap();
    let bound = mix.bounds(&m, &chosen, &noise).unwrap();
    let fm = mix.model(&m);
    let skeleton = mix.skeleton(&fm, &chosen, &noise);
    let mut truth: Vec<f64> = (0..fm.num_params())
        .map(|k| 30.0 * ((k as f64) * 0.77 + 0.3).sin())
        .collect();
    for b in fm.blocks().iter().skip(1) {
        for k in 0..b.len {
            truth[b.offset + k] = 300.0 * ((k as f64) * 1.3 + 0.2).cos();
        }
    }
    let prepared = Prepared::new(&fm, &skeleton).unwrap();
    let exact = predict(&fm, &prepared, &skeleton, &truth, None).unwrap();
    let options = IdentifyOptions {
        sigma_um: Some(noise.gauge_um),
        ..IdentifyOptions::default()
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let unit = Normal::new(0.0, 1.0).unwrap();
    let runs = 40;
    let mut sq = 0.0;
    for _ in 0..runs {
        let mut c = skeleton.clone();
        c.simulated = true;
        for (k, r) in c.readings.iter_mut().enumerate() {
            r.length_mm = exact[k] + noise.gauge_um * 1e-3 * unit.sample(&mut rng);
        }
        let p0 = c.first_point_observation();
        for (q, pm) in c.point_measurements.iter_mut().enumerate() {
            for a in 0..3 {
                pm.measured_mm[a] =
                    exact[p0 + 3 * q + a] + noise.point_um * 1e-3 * unit.sample(&mut rng);
            }
        }
        let t0 = c.first_tilt_observation();
        for (q, t) in c.tilt_measurements.iter_mut().enumerate() {
            t.angle_mrad = exact[t0 + q] + noise.tilt_urad * 1e-3 * unit.sample(&mut rng);
        }
        let cal = identify(&fm, &c, &options).unwrap();
        assert!(cal.solver.was_successful());
        for k in 0..36 {
            sq += (cal.estimate_um[k].unwrap() - truth[k]).powi(2);
        }
    }
    let mc = (sq / (36 * runs) as f64).sqrt();
    println!(
        "designed mix, {runs} simulated campaigns: joint errors {mc:.2} um RMS off the truth, Cramér-Rao RMS {:.2} um",
        bound.joint_crb_rms_um
    );
    assert!(
        (mc / bound.joint_crb_rms_um - 1.0).abs() < 0.15,
        "Monte Carlo {mc} um against the bound {} um",
        bound.joint_crb_rms_um
    );
}
