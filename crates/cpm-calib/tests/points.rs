//! Point targets (laser-tracker reflectors): the analytic Jacobian of the point prediction
//! against finite differences, a fit that recovers the targets and the session frames, and
//! what one, two or three targets can identify.
use cpm_calib::model::{predict, Predictions, Prepared};
use cpm_calib::paper::random_workspace_poses;
use cpm_calib::points::PointTarget;
use cpm_calib::*;
use cpm_geometry::JointTable;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};

const SIGMA_UM: f64 = 5.0;

fn targets(k: usize) -> Vec<PointTarget> {
    [
        ("smr1", [90.0, 10.0, 30.0]),
        ("smr2", [-50.0, 80.0, 25.0]),
        ("smr3", [-40.0, -85.0, 35.0]),
    ]
    .iter()
    .take(k)
    .map(|(n, p)| PointTarget {
        name: n.to_string(),
        platform_mm: Vector3::from(*p),
    })
    .collect()
}

/// The 6-6 hexapod with `k` targets, two point sessions and `effects` plus the point blocks.
fn model(k: usize, effects: &[Effect]) -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::hexapod_66());
    m.targets = targets(k);
    m.point_sessions = 2;
    m.effects = effects.to_vec();
    m.effects
        .extend([Effect::TargetPosition, Effect::PointFrame]);
    m
}

/// Every target at every pose; the first half of the poses in session 0, the rest in 1.
fn skeleton(model: &MeasurementModel, poses: usize, seed: u64) -> Campaign {
    let mut c = Campaign {
        poses: random_workspace_poses(&model.nominal, poses, 60.0, 12.0, 4.0, seed),
        point_sigma_um: SIGMA_UM,
        simulated: true,
        ..Campaign::default()
    };
    for j in 0..poses {
        for t in 0..model.targets.len() {
            c.point_measurements.push(PointMeasurement {
                pose: j,
                target: t,
                session: usize::from(j >= poses / 2),
                measured_mm: Vector3::zeros(),
                time_s: None,
            });
        }
    }
    c.session_starts = vec![poses / 2];
    c
}

/// Truth: installation errors of tens of um, targets up to ~1 mm off their drawing, session
/// frames `frame_um` (and urad) from the base frame.
fn truth(model: &MeasurementModel, frame_um: f64) -> Vec<f64> {
    let mut v: Vec<f64> = (0..model.num_params())
        .map(|k| 40.0 * ((k as f64) * 0.77).sin())
        .collect();
    for b in model.blocks() {
        match b.effect {
            Some(Effect::TargetPosition) => {
                for k in 0..b.len {
                    v[b.offset + k] = 800.0 * ((k as f64) * 1.3).cos();
                }
            }
            Some(Effect::PointFrame) => {
                for k in 0..b.len {
                    v[b.offset + k] = frame_um * ((k as f64) * 0.9).sin();
                }
            }
            _ => {}
        }
    }
    v
}

fn measure(model: &MeasurementModel, truth: &[f64], c: &mut Campaign, seed: u64) {
    let prepared = Prepared::new(model, c).unwrap();
    let y = predict(model, &prepared, c, truth, None).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut gauss = || {
        let (u1, u2): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random_range(0.0..1.0));
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let p0 = c.first_point_observation();
    for (q, pm) in c.point_measurements.iter_mut().enumerate() {
        for a in 0..3 {
            pm.measured_mm[a] = y[p0 + 3 * q + a] + gauss() * SIGMA_UM * 1e-3;
        }
    }
}

#[test]
fn point_jacobian_matches_finite_differences() {
    // Frames far from the base frame (20 mm, 20 mrad): the rotation's left Jacobian matters.
    let m = model(3, &[Effect::LinkOffset]);
    let c = skeleton(&m, 12, 3);
    let x = truth(&m, 2e4);
    let mut problem = Predictions::new(&m, &c).unwrap();
    let check = cpm_lm::check_jacobian(&mut problem, &x, 1e-3).unwrap();
    assert!(check.is_consistent(1e-6), "{check}");
    // The check can fail: a Jacobian with the target columns' sign flipped is caught.
    let prepared = Prepared::new(&m, &c).unwrap();
    let mut j = nalgebra::DMatrix::zeros(c.len(), m.num_params());
    predict(&m, &prepared, &c, &x, Some(&mut j)).unwrap();
    let tb = m.blocks()[2];
    assert_eq!(tb.effect, Some(Effect::TargetPosition));
    let h = 1.0;
    let mut xp = x.clone();
    xp[tb.offset] += h;
    let y0 = predict(&m, &prepared, &c, &x, None).unwrap();
    let y1 = predict(&m, &prepared, &c, &xp, None).unwrap();
    let fd = (y1[0] - y0[0]) / h;
    assert!(
        (fd - j[(0, tb.offset)]).abs() < 1e-9 && fd.abs() > 1e-4,
        "{fd}"
    );
}

#[test]
fn point_fit_recovers_targets_and_frames_within_their_deviations() {
    // Frames a rough registration leaves (0.5 mm, 0.5 mrad): the gauge freedoms are nearly
    // linear there, so the truth's identifiable combinations compare with the estimate's.
    let m = model(3, &[]);
    let x = truth(&m, 500.0);
    let mut c = skeleton(&m, 40, 5);
    measure(&m, &x, &mut c, 9);
    let options = IdentifyOptions {
        sigma_um: Some(SIGMA_UM),
        ..IdentifyOptions::default()
    };
    let cal = identify(&m, &c, &options).unwrap();
    assert!(
        (cal.residual_rms_um - SIGMA_UM).abs() < 0.3 * SIGMA_UM,
        "{}",
        cal.residual_rms_um
    );
    // No single parameter is determined (the gauge freedoms of the frames and the targets);
    // every identifiable combination v^T x is, and the truth's sits within its deviations.
    let id = &cal.identifiability;
    assert!(cal.estimate_um.iter().all(Option::is_none));
    assert_eq!(cal.combinations.len(), id.rank);
    let mut z2 = Vec::new();
    for (k, comb) in cal.combinations.iter().enumerate() {
        let v = id.v.column(k);
        let est: f64 = v.iter().zip(&cal.minimum_norm_um).map(|(a, b)| a * b).sum();
        assert!(
            (est - comb.estimate_um).abs() <= 1e-6 * (1.0 + est.abs()),
            "combination {k}: {est} vs {}",
            comb.estimate_um
        );
        let truth: f64 = v.iter().zip(&x).map(|(a, b)| a * b).sum();
        z2.push(((est - truth) / comb.std_um).powi(2));
    }
    let worst = z2.iter().copied().fold(0.0, f64::max).sqrt();
    let mean = z2.iter().sum::<f64>() / z2.len() as f64;
    eprintln!("combinations: worst {worst:.2} sd, mean square {mean:.2}");
    assert!(
        worst < 4.5 && mean < 2.0,
        "worst {worst} sd, mean square {mean}"
    );
    // The fit with its minimum-norm point predicts what the truth predicts, to the noise.
    let prepared = Prepared::new(&m, &c).unwrap();
    let y_fit = predict(&m, &prepared, &c, &cal.minimum_norm_um, None).unwrap();
    let y_true = predict(&m, &prepared, &c, &x, None).unwrap();
    let d = y_fit
        .iter()
        .zip(&y_true)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        / y_fit.len() as f64;
    assert!(d.sqrt() * 1e3 < SIGMA_UM, "{} um", d.sqrt() * 1e3);
}

/// The rank of the point-target campaign with `k` targets, the RMS Cramér-Rao bound of its
/// identifiable combinations (um, at the point noise), and the blind directions named.
fn rank_with(k: usize) -> (usize, usize, f64, Vec<String>) {
    let m = model(k, &[]);
    let c = skeleton(&m, 40, 5);
    let id = identifiability(&m, &c, SIGMA_UM, &RankOptions::default()).unwrap();
    let words = id
        .blind_directions
        .iter()
        .map(|b| b.description.clone())
        .collect();
    let s = &id.combination_std_um;
    let rms = (s.iter().map(|v| v * v).sum::<f64>() / s.len() as f64).sqrt();
    (id.rank, m.num_params(), rms, words)
}

#[test]
fn one_two_three_targets_identify_more_and_name_what_they_miss() {
    let (r1, n1, s1, w1) = rank_with(1);
    let (r2, n2, s2, _) = rank_with(2);
    let (r3, n3, s3, w3) = rank_with(3);
    eprintln!(
        "ranks {r1}/{n1} {r2}/{n2} {r3}/{n3}; combination CRLB RMS {s1:.2} {s2:.2} {s3:.2} um"
    );
    // Parameters: 36 joints + 3 per target + 12 frames; blind: 6 base/frame + 6
    // platform/target gauge freedoms, whatever the number of targets.
    assert_eq!((n1, n2, n3), (51, 54, 57));
    for (r, n) in [(r1, n1), (r2, n2), (r3, n3)] {
        assert_eq!(n - r, 12, "{r} of {n}");
    }
    // More targets, better known combinations.
    assert!(s1 > s2 && s2 > s3, "{s1} {s2} {s3}");
    for w in [&w1, &w3] {
        let all = w.join("; ");
        assert!(
            all.contains("every session's point frame") && all.contains("every target"),
            "{all}"
        );
    }
}
