//! The effect library: analytic Jacobian of every effect against finite differences, and
//! recovery of effects from simulated campaigns.
use cpm_calib::campaign::PoseMeasurement;
use cpm_calib::model::{predict, Prepared};
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};

fn model_with(effects: &[Effect]) -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::paper_cubic());
    m.nominal.sensors = designed_sensors();
    m.effects = effects.to_vec();
    m
}

fn timed_campaign(model: &MeasurementModel, poses: usize, seed: u64) -> Campaign {
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, poses, 100.0, 25.0, 3.0, seed),
        sensors: (0..model.nominal.sensors.len()).collect(),
    };
    let mut c = plan.skeleton();
    for r in c.readings.iter_mut() {
        r.time_s = Some(60.0 * r.pose as f64).into();
        r.temperature_c = Some(20.0 + 0.05 * r.pose as f64 + (r.pose as f64 * 0.7).sin()).into();
    }
    // A tracker measures every other pose (slightly off the commanded pose).
    for j in (0..c.poses.len()).step_by(2) {
        let twist = nalgebra::Vector6::new(0.01, -0.02, 0.015, 1e-4, -2e-4, 5e-5);
        c.pose_measurements.push(PoseMeasurement {
            pose: j,
            measured: c.poses[j].perturbed(&twist),
            time_s: Some(60.0 * j as f64),
            temperature_c: None,
        });
    }
    c
}

fn params_for(model: &MeasurementModel) -> Vec<f64> {
    let mut p = InstallationErrors::paper_table2().to_vec_um();
    p.extend((0..model.num_params() - 36).map(|k| 3.0 + (k as f64 * 1.3).sin() * 2.0));
    p
}

/// Every column of `model`'s analytic Jacobian at `p` against central differences.
fn check_columns(model: &MeasurementModel, c: &Campaign, p: &[f64]) {
    let prepared = Prepared::new(model, c).unwrap();
    let np = model.num_params();
    assert_eq!(model.parameter_names().len(), np);
    let mut j = nalgebra::DMatrix::zeros(c.len(), np);
    predict(model, &prepared, c, p, Some(&mut j)).unwrap();
    let names = model.parameter_names();
    for k in 0..np {
        // 0.5 um: forward kinematics is solved to 1e-11 mm, so tracker orientation rows carry
        // ~1e-13 rad of noise; a larger step keeps that far below the tolerance, and the
        // model's curvature over 1 um is ~1e-9 of a column.
        let h = 0.5;
        let mut a = p.to_vec();
        let mut b = p.to_vec();
        a[k] += h;
        b[k] -= h;
        let ya = predict(model, &prepared, c, &a, None).unwrap();
        let yb = predict(model, &prepared, c, &b, None).unwrap();
        let mut worst: f64 = 0.0;
        let mut scale: f64 = 0.0;
        for r in 0..c.len() {
            worst = worst.max(((ya[r] - yb[r]) / (2.0 * h) - j[(r, k)]).abs());
            scale = scale.max(j[(r, k)].abs());
        }
        assert!(scale > 0.0, "{}: column is zero", names[k]);
        assert!(
            worst < 1e-8 + 1e-5 * scale,
            "{}: worst {worst:e}, column max {scale:e}",
            names[k]
        );
    }
}

#[test]
fn every_effect_column_matches_central_differences() {
    let model = model_with(&Effect::ALL);
    let c = timed_campaign(&model, 8, 21);
    check_columns(&model, &c, &params_for(&model));
}

/// Sizeable known values for every effect (tens of um, hundreds of ppm / urad).
fn known_values(model: &MeasurementModel) -> Vec<KnownEffect> {
    let (n, s) = (model.nominal.num_links(), model.nominal.sensors.len());
    Effect::ALL
        .iter()
        .enumerate()
        .map(|(index, &effect)| KnownEffect {
            effect,
            values: (0..effect.num_params(n, s))
                .map(|k| 20.0 * ((k as f64 + 1.0) * 0.9 + index as f64).cos())
                .collect(),
        })
        .collect()
}

#[test]
fn known_effect_values_act_like_estimated_ones() {
    // A known value must predict what the same value estimated predicts, for every effect:
    // the calibrated description carries known values, and reading it back must give the
    // calibrated machine.
    let base = model_with(&[]);
    let c = timed_campaign(&base, 8, 23);
    let installation = InstallationErrors::paper_table2().to_vec_um();
    for known in known_values(&base) {
        let estimated = model_with(&[known.effect]);
        let mut p = installation.clone();
        p.extend(&known.values);
        let prepared = Prepared::new(&estimated, &c).unwrap();
        let y_estimated = predict(&estimated, &prepared, &c, &p, None).unwrap();

        let mut fixed = model_with(&[]);
        fixed.known_effects = vec![known.clone()];
        let prepared = Prepared::new(&fixed, &c).unwrap();
        let y_known = predict(&fixed, &prepared, &c, &installation, None).unwrap();

        let nominal = predict(
            &base,
            &Prepared::new(&base, &c).unwrap(),
            &c,
            &installation,
            None,
        )
        .unwrap();
        let moved = y_known
            .iter()
            .zip(&nominal)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            moved > 1e-4,
            "{}: known values change nothing",
            known.effect
        );
        for (r, (a, b)) in y_known.iter().zip(&y_estimated).enumerate() {
            assert!(
                (a - b).abs() < 1e-9,
                "{} row {r}: known {a} vs estimated {b}",
                known.effect
            );
        }
    }
}

#[test]
fn columns_match_central_differences_on_top_of_known_values() {
    let mut model = model_with(&Effect::ALL);
    model.known_effects = known_values(&model);
    let c = timed_campaign(&model, 6, 29);
    check_columns(&model, &c, &params_for(&model));
}

#[test]
fn known_values_of_the_wrong_length_are_refused() {
    let mut model = model_with(&[]);
    model.known_effects = vec![KnownEffect {
        effect: Effect::Backlash,
        values: vec![1.0; 5],
    }];
    let c = timed_campaign(&model, 4, 1);
    let e = Prepared::new(&model, &c).unwrap_err().to_string();
    assert!(
        e.contains("known_effects.backlash") && e.contains("6 parameters"),
        "{e}"
    );
}

#[test]
fn declared_effects_are_recovered_from_noise_free_data() {
    for effect in [
        Effect::LinkScale,
        Effect::SensorOffset,
        Effect::Backlash,
        Effect::ThermalDrift,
        Effect::ScrewPeriodic,
    ] {
        let model = model_with(&[effect]);
        let mut c = timed_campaign(&model, 40, 3);
        c.pose_measurements.clear();
        let truth = params_for(&model);
        let prepared = Prepared::new(&model, &c).unwrap();
        let y = predict(&model, &prepared, &c, &truth, None).unwrap();
        let mut data = c.clone();
        for (r, v) in data.readings.iter_mut().zip(y) {
            r.length_mm = v;
        }
        let cal = identify(&model, &data, &IdentifyOptions::default()).unwrap();
        assert_eq!(cal.identifiability.rank, model.num_params(), "{effect}");
        for k in 36..model.num_params() {
            let e = cal.estimate_um[k].unwrap();
            assert!(
                (e - truth[k]).abs() < 1e-5,
                "{effect} {k}: {e} vs {}",
                truth[k]
            );
        }
    }
}

#[test]
fn effect_names_parse_and_unknown_names_are_listed() {
    for e in Effect::ALL {
        assert_eq!(Effect::parse(e.name()).unwrap(), e);
    }
    let err = Effect::parse("link_ofset").unwrap_err();
    assert!(err.contains("link_offset"), "{err}");
}

#[test]
fn pose_map_columns_match_central_differences() {
    // Pose map terms beside the socket, sensor and tracker channels, estimated on top of known
    // pose map values large enough (hundreds of urad) that the moved pose matters.
    let terms: Vec<Effect> = ["pose_map_y", "pose_map_y2", "pose_map_x_roll", "pose_map_z"]
        .iter()
        .map(|n| Effect::parse(n).unwrap())
        .collect();
    let mut effects = terms.clone();
    effects.extend([
        Effect::SensorScale,
        Effect::SocketError,
        Effect::TrackerFrame,
    ]);
    let mut model = model_with(&effects);
    model.known_effects = vec![
        KnownEffect {
            effect: terms[0],
            values: vec![30.0, -20.0, 15.0, 400.0, -300.0, 250.0],
        },
        KnownEffect {
            effect: Effect::parse("pose_map_x").unwrap(),
            values: vec![-10.0, 25.0, 5.0, -200.0, 350.0, 100.0],
        },
    ];
    let c = timed_campaign(&model, 8, 31);
    let mut p = params_for(&model);
    for v in p.iter_mut().skip(36).take(24) {
        *v *= 40.0;
    }
    check_columns(&model, &c, &p);
}

#[test]
fn pose_map_terms_move_the_platform_as_declared() {
    // Independent of the channel code: a known pose map term must give the readings of the
    // platform moved by the twist the term declares, computed here by hand.
    let effect = Effect::parse("pose_map_y2").unwrap();
    assert_eq!(effect.name(), "pose_map_y2");
    let mut model = model_with(&[]);
    let values = vec![12.0, -8.0, 30.0, 60.0, -40.0, 25.0];
    let plain = model.clone();
    model.known_effects = vec![KnownEffect {
        effect,
        values: values.clone(),
    }];
    let c = timed_campaign(&model, 6, 5);
    let p = InstallationErrors::paper_table2().to_vec_um();
    let y = predict(&model, &Prepared::new(&model, &c).unwrap(), &c, &p, None).unwrap();
    let table = plain.table_with(&p).unwrap();
    let lengths = plain.effective_lengths(&c).unwrap();
    let home = plain.nominal.home;
    for (k, r) in c.readings.iter().enumerate() {
        let commanded = c.poses[r.pose];
        let (fk, _) =
            cpm_kinematics::forward(&table, &lengths[r.pose], &commanded, &plain.fk).unwrap();
        let m = ((commanded.position_mm.y - home.position_mm.y) / 100.0).powi(2);
        let twist = nalgebra::Vector6::from_iterator(
            values
                .iter()
                .enumerate()
                .map(|(a, v)| v * m * if a < 3 { 1e-3 } else { 1e-6 }),
        );
        let moved = fk.perturbed(&twist);
        let expected = table.sensors[r.sensor].length_mm(&moved) + plain.sensor_correction_mm();
        assert!(
            (y[k] - expected).abs() < 1e-9,
            "reading {k}: {} vs {expected}",
            y[k]
        );
    }
}

#[test]
fn pose_map_names_round_trip() {
    let all = Effect::pose_maps(3);
    assert_eq!(Effect::pose_maps(2).len(), 27);
    assert_eq!(all.len(), 83);
    for e in &all {
        assert_eq!(Effect::parse(e.name()).unwrap(), *e);
        let json = serde_json::to_string(e).unwrap();
        assert_eq!(serde_json::from_str::<Effect>(&json).unwrap(), *e);
    }
    for bad in [
        "pose_map_",
        "pose_map_w",
        "pose_map_y4",
        "pose_map_y_y",
        "pose_map_x2_y2",
    ] {
        assert!(Effect::parse(bad).is_err(), "{bad}");
    }
    // Built-in names are unchanged in files.
    assert_eq!(
        serde_json::to_string(&Effect::LinkOffset).unwrap(),
        "\"link_offset\""
    );
}
