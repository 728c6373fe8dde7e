//! Identification: Jacobian against finite differences, recovery without noise, consistency
//! with the Cramér-Rao bound, rank of the paper's design.
use cpm_calib::campaign::paper_circle;
use cpm_calib::model::{predict, Prepared};
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};

fn designed_model() -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::paper_cubic());
    m.nominal.sensors = designed_sensors();
    m
}

fn designed_plan(model: &MeasurementModel, poses: usize, seed: u64) -> Plan {
    Plan {
        poses: random_workspace_poses(&model.nominal, poses, 100.0, 25.0, 3.0, seed),
        sensors: (0..model.nominal.sensors.len()).collect(),
    }
}

fn paper_plan(model: &MeasurementModel) -> Plan {
    Plan {
        poses: paper_circle(&model.nominal.home),
        sensors: vec![0],
    }
}

/// The designed model, the paper's Table 2 errors and their noise-free readings at `poses`
/// random poses (seed `seed`).
fn noise_free_table2(poses: usize, seed: u64) -> (MeasurementModel, Vec<f64>, Campaign) {
    let model = designed_model();
    let plan = designed_plan(&model, poses, seed);
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let sim = SimulationOptions {
        noise: Noise::None,
        ..SimulationOptions::default()
    };
    let data = simulate(&model, &truth, &plan, &sim).unwrap();
    (model, truth, data)
}

#[test]
fn identification_jacobian_matches_central_differences() {
    let model = designed_model();
    let plan = designed_plan(&model, 6, 11);
    let c = plan.skeleton();
    let e = InstallationErrors::paper_table2().to_vec_um();
    let prepared = Prepared::new(&model, &c).unwrap();
    let mut j = nalgebra::DMatrix::zeros(c.len(), 36);
    predict(&model, &prepared, &c, &e, Some(&mut j)).unwrap();
    let h = 1e-2; // um
    let mut worst: f64 = 0.0;
    for k in 0..36 {
        let mut ep = e.clone();
        let mut em = e.clone();
        ep[k] += h;
        em[k] -= h;
        let yp = predict(&model, &prepared, &c, &ep, None).unwrap();
        let ym = predict(&model, &prepared, &c, &em, None).unwrap();
        for r in 0..c.len() {
            let fd = (yp[r] - ym[r]) / (2.0 * h);
            worst = worst.max((fd - j[(r, k)]).abs());
        }
    }
    // Entries are O(1e-3) mm/um; FK is solved to 1e-11 mm, so differences carry ~1e-9.
    assert!(worst < 1e-7, "worst |analytic - FD| = {worst:e} mm/um");
}

#[test]
fn noise_free_recovery_to_a_micro_micrometre() {
    let (model, truth, data) = noise_free_table2(30, 5);
    let cal = identify(&model, &data, &IdentifyOptions::default()).unwrap();
    assert_eq!(cal.identifiability.rank, 36);
    for k in 0..36 {
        let e = cal.estimate_um[k].expect("determined");
        assert!((e - truth[k]).abs() < 1e-6, "{k}: {e} vs {}", truth[k]);
    }
    assert!(cal.residual_rms_um < 1e-6);
    assert!(
        cal.solver.termination.was_successful(),
        "{}",
        cal.solver.brief()
    );
}

#[test]
fn paper_design_fits_its_readings_but_determines_nothing() {
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let plan = paper_plan(&model);
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let sim = SimulationOptions {
        noise: Noise::None,
        ..SimulationOptions::default()
    };
    let data = simulate(&model, &truth, &plan, &sim).unwrap();
    let cal = identify(&model, &data, &IdentifyOptions::default()).unwrap();
    assert_eq!(cal.identifiability.rank, 8);
    assert!(cal.estimate_um.iter().all(|e| e.is_none()));
    assert!(cal.std_um.iter().all(|e| e.is_none()));
    // The residual goes to (nearly) zero: what the readings see is fitted; the blind part of
    // the truth acts only at second order (errors of 0.1 mm over links of 350 mm).
    assert!(cal.residual_rms_um < 0.05, "{}", cal.residual_rms_um);
    // In the identifiable subspace, the estimate matches the truth.
    let vr = cal.identifiability.row_space();
    let d = nalgebra::DVector::from_vec(
        cal.minimum_norm_um
            .iter()
            .zip(&truth)
            .map(|(a, b)| a - b)
            .collect(),
    );
    let seen = vr.transpose() * d;
    assert!(
        seen.amax() < 1.0,
        "identifiable part off by {}",
        seen.amax()
    );
    let text = cal.identifiability.summary();
    assert!(
        text.contains("rotated about sensor `paper`'s base socket"),
        "{text}"
    );
    assert!(
        text.contains("link 3 moved together by the same vector"),
        "{text}"
    );
}

#[test]
fn paper_design_rank_is_stable_under_threshold_changes() {
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let c = paper_plan(&model).skeleton();
    let j = identification_jacobian(&model, &c, &[0.0; 36]).unwrap();
    let base = RankOptions::default();
    let ranks: Vec<usize> = [0.5, 1.0, 2.0]
        .iter()
        .map(|f| {
            analyze(
                &j,
                1.0,
                &RankOptions {
                    rank_rtol: base.rank_rtol * f,
                    ..base
                },
                &[],
            )
            .rank
        })
        .collect();
    assert_eq!(ranks, vec![8, 8, 8]);
    // And with the errors of Table 2 as the linearisation point.
    let j2 = identification_jacobian(&model, &c, &InstallationErrors::paper_table2().to_vec_um())
        .unwrap();
    assert_eq!(analyze(&j2, 1.0, &base, &[]).rank, 8);
}

#[test]
fn estimation_errors_are_consistent_with_the_cramer_rao_bound() {
    let model = designed_model();
    let plan = designed_plan(&model, 25, 9);
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let sigma = 3.0;
    let mut z2 = Vec::new();
    for seed in 0..16 {
        let sim = SimulationOptions {
            noise: Noise::Gaussian { sigma_um: sigma },
            repeats: 1,
            seed,
        };
        let data = simulate(&model, &truth, &plan, &sim).unwrap();
        let opts = IdentifyOptions {
            sigma_um: Some(sigma),
            ..IdentifyOptions::default()
        };
        let cal = identify(&model, &data, &opts).unwrap();
        for k in 0..36 {
            let z = (cal.estimate_um[k].unwrap() - truth[k]) / cal.std_um[k].unwrap();
            z2.push(z * z);
        }
    }
    // Mean squared z-score: 1 for an efficient, unbiased estimator; 576 samples
    // (correlated within a seed) keep it well inside [0.6, 1.5].
    let mean = z2.iter().sum::<f64>() / z2.len() as f64;
    assert!((0.6..1.5).contains(&mean), "mean z^2 = {mean}");
}

#[test]
fn first_order_model_agrees_with_exact_to_second_order() {
    let model = designed_model();
    let plan = designed_plan(&model, 8, 4);
    let c = plan.skeleton();
    let fo = MeasurementModel {
        kind: ModelKind::FirstOrder,
        ..model.clone()
    };
    let pe = Prepared::new(&model, &c).unwrap();
    let pf = Prepared::new(&fo, &c).unwrap();
    let e = InstallationErrors::paper_table2().to_vec_um();
    let mut gaps = Vec::new();
    for scale in [1.0, 0.1] {
        let es: Vec<f64> = e.iter().map(|v| v * scale).collect();
        let ye = predict(&model, &pe, &c, &es, None).unwrap();
        let yf = predict(&fo, &pf, &c, &es, None).unwrap();
        let gap = ye
            .iter()
            .zip(&yf)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        gaps.push(gap);
    }
    // Quadratic: ten times smaller errors, a hundred times smaller gap (within 30 %).
    let ratio = gaps[0] / gaps[1];
    assert!((70.0..130.0).contains(&ratio), "gaps {gaps:?}");
}

#[test]
fn table3_is_consistent_with_the_papers_readings_only_as_p_minus_dp() {
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let check = cpm_calib::paper::table3_check(&model, &paper_plan(&model)).unwrap();
    // Under p - dp the readings differ by less than the paper's noise (5.8 um RMS); under
    // p + dp by far more.
    assert!(check.minus < 2.0, "{check:?}");
    assert!(check.plus > 20.0, "{check:?}");
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let mut c = paper_plan(&model).skeleton();
    c.readings[3].sensor = 7;
    let e = identify(&model, &c, &IdentifyOptions::default()).unwrap_err();
    assert!(e.to_string().contains("reading 3.sensor"), "{e}");
    let mut c = paper_plan(&model).skeleton();
    c.readings[1].length_mm = f64::NAN;
    let e = identify(&model, &c, &IdentifyOptions::default()).unwrap_err();
    assert!(e.to_string().contains("reading 1.length_mm"), "{e}");
    let empty = Campaign::default();
    assert!(matches!(
        identify(&model, &empty, &IdentifyOptions::default()),
        Err(CalibError::NoInformation(_))
    ));
    let opts = IdentifyOptions {
        sigma_um: Some(-1.0),
        ..IdentifyOptions::default()
    };
    let c = paper_plan(&model).skeleton();
    assert!(identify(&model, &c, &opts).is_err());
}

#[test]
fn a_spike_is_flagged_and_a_robust_loss_contains_it() {
    let model = designed_model();
    let plan = designed_plan(&model, 30, 5);
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um: 2.0 },
        repeats: 1,
        seed: 3,
    };
    let mut data = simulate(&model, &truth, &plan, &sim).unwrap();
    // A 5 mm spike in one reading (a ballbar that slipped).
    data.readings[100].length_mm += 5.0;
    let err = |cal: &Calibration| {
        (0..36)
            .map(|k| (cal.estimate_um[k].unwrap() - truth[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            / 6.0
    };
    // Least squares that keeps the spike follows it.
    let plain = identify(
        &model,
        &data,
        &IdentifyOptions {
            keep_outliers: true,
            ..IdentifyOptions::default()
        },
    )
    .unwrap();
    assert!(plain.outliers.contains(&100), "{:?}", plain.outliers);
    assert!(plain.set_aside.is_empty());
    // By default least squares sets it aside (far beyond 10 robust standard deviations) and
    // continues without it: as good as the robust loss, the noise estimate clean.
    let aside = identify(&model, &data, &IdentifyOptions::default()).unwrap();
    assert_eq!(aside.set_aside, vec![100]);
    assert!(aside.outliers.contains(&100));
    assert!(err(&aside) < 2.0, "set-aside fit rms error {}", err(&aside));
    assert!(aside.sigma_excludes_outliers);
    assert!((aside.sigma_um - 2.0).abs() < 0.3, "{} um", aside.sigma_um);
    // Its residual stays the spike's, at full weight.
    assert!(
        aside.residuals_um[100].abs() > 4000.0,
        "{}",
        aside.residuals_um[100]
    );
    let mut robust_opts = IdentifyOptions::default();
    robust_opts.lm.loss = cpm_lm::Loss::Huber(10.0);
    let robust = identify(&model, &data, &robust_opts).unwrap();
    assert_eq!(robust.outliers, vec![100]);
    assert!(err(&plain) > 20.0, "plain fit rms error {}", err(&plain));
    assert!(err(&robust) < 2.0, "robust fit rms error {}", err(&robust));
    // The noise estimate of the robust fit leaves the spike out (the fit does not follow
    // it): close to the simulated 2 um, where the spike alone would make it ~30 um.
    assert!(robust.sigma_excludes_outliers && !plain.sigma_excludes_outliers);
    assert!(
        (robust.sigma_um - 2.0).abs() < 0.3,
        "robust sigma {} um",
        robust.sigma_um
    );
    assert!(plain.sigma_um > 10.0, "plain sigma {} um", plain.sigma_um);
}

#[test]
fn compensating_with_well_determined_combinations_helps_even_on_the_paper_design() {
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let plan = paper_plan(&model);
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).unwrap();
    let cal = identify(&model, &data, &IdentifyOptions::default()).unwrap();
    let targets = cpm_calib::paper::random_poses(&model.nominal.home, 50, 60.0, 8.0, 3);
    let comp = cal.compensation_um(&[0.0; 36], 10.0);
    // Only combinations with a small bound are applied: the result lies in their span.
    let weak: Vec<usize> = (0..cal.identifiability.rank)
        .filter(|&c| cal.identifiability.combination_std_um[c] > 10.0)
        .collect();
    assert!(!weak.is_empty());
    for c in weak {
        let v = cal.identifiability.v.column(c);
        assert!(v.dot(&nalgebra::DVector::from_column_slice(&comp)).abs() < 1e-9);
    }
    let acc = accuracy(&model, &truth, &comp, &targets).unwrap();
    assert!(
        acc.calibrated.rms_position_um < 0.5 * acc.nominal.rms_position_um,
        "{acc:?}"
    );
}

/// A parameter the data pull beyond its tolerance's limit without determining it is held at
/// the limit, with the sign the data pulled it to, named and not measured; the others stay
/// within it. Without a limit (the Gaussian prior alone) the same data carry it past. A
/// parameter the data determine is never held, however far out.
#[test]
fn a_parameter_pulled_beyond_its_limit_without_being_determined_is_held_there() {
    let (model, truth, data) = noise_free_table2(30, 5);
    // Tolerances 20 times tighter than the truth, and a declared noise at which the data see
    // each parameter about 1.5 tolerances wide: the data pull several tolerances out without
    // determining what they pull.
    let largest = truth.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let tolerance = largest / 20.0;
    let unit = identify(
        &model,
        &data,
        &IdentifyOptions {
            tolerances: Tolerances::none(),
            sigma_um: Some(1.0),
            ..IdentifyOptions::default()
        },
    )
    .unwrap();
    let mut stds: Vec<f64> = unit.std_um.iter().flatten().copied().collect();
    stds.sort_by(f64::total_cmp);
    let sigma = 1.5 * tolerance / stds[stds.len() / 2];
    let fit = |limit: f64| {
        let mut t = Tolerances::default();
        t.set("installation_errors", tolerance).unwrap();
        t.set_limit(limit).unwrap();
        identify(
            &model,
            &data,
            &IdentifyOptions {
                tolerances: t,
                sigma_um: Some(sigma),
                ..IdentifyOptions::default()
            },
        )
        .unwrap()
    };
    let free = fit(f64::INFINITY);
    assert!(free.held_at_limit.is_empty());
    let limit = 3.0;
    let prior = free.prior.as_ref().unwrap();
    let runaways: Vec<usize> = (0..36)
        .filter(|&k| free.minimum_norm_um[k].abs() > limit * tolerance && !prior.determined(k))
        .collect();
    assert!(
        !runaways.is_empty(),
        "no undetermined parameter beyond {limit} tolerances"
    );
    let held = fit(limit);
    assert!(!held.held_at_limit.is_empty());
    assert_eq!(held.tolerance_limit, limit);
    let after = held.prior.as_ref().unwrap();
    for k in 0..36 {
        let v = held.minimum_norm_um[k];
        if held.held_at_limit.contains(&k) {
            assert_eq!(v.abs(), limit * tolerance, "{k}: held at the limit");
            if runaways.contains(&k) {
                let pulled = free.minimum_norm_um[k].signum();
                assert_eq!(v.signum(), pulled, "{k}: held where the data pulled it");
            }
            assert!(held.estimate_um[k].is_none(), "{k}: held, not measured");
        } else if !after.determined(k) {
            assert!(v.abs() <= limit * tolerance * (1.0 + 1e-9), "{k}: {v} um");
        }
    }
    // What the free fit carried furthest is held.
    let worst = runaways
        .iter()
        .copied()
        .max_by(|a, b| {
            free.minimum_norm_um[*a]
                .abs()
                .total_cmp(&free.minimum_norm_um[*b].abs())
        })
        .unwrap();
    assert!(held.held_at_limit.contains(&worst));
    // The same data at a small noise determine every parameter: measured, none held, though
    // 20 tolerances out.
    let mut t = Tolerances::default();
    t.set("installation_errors", tolerance).unwrap();
    let sure = identify(
        &model,
        &data,
        &IdentifyOptions {
            tolerances: t,
            sigma_um: Some(1e-3 * sigma),
            ..IdentifyOptions::default()
        },
    )
    .unwrap();
    assert!(sure.held_at_limit.is_empty());
    assert!(sure
        .minimum_norm_um
        .iter()
        .any(|v| v.abs() > 10.0 * tolerance));
    // A limit that is no number of tolerances is refused.
    assert!(Tolerances::default().set_limit(0.0).is_err());
    assert!(Tolerances::default().set_limit(f64::NAN).is_err());
}
