//! Clearance sign logic and statics balance.
use cpm_clearance::{link_forces_n, platform_wrench, ClearanceModel, Load, SignRule};
use cpm_geometry::{JointTable, Pose};
use nalgebra::Vector3;

fn poses() -> Vec<Pose> {
    let home = JointTable::paper_cubic().home;
    vec![
        home,
        Pose::from_xyz_rpy(50.0, -30.0, 420.0, 0.1, -0.05, 0.2),
        Pose::from_xyz_rpy(-80.0, 60.0, 390.0, -0.2, 0.1, -0.1),
    ]
}

#[test]
fn forces_balance_the_wrench() {
    let table = JointTable::paper_cubic();
    let load = Load {
        external_force_n: Vector3::new(5.0, -3.0, 2.0),
        ..Load::default()
    };
    for pose in poses() {
        let t = link_forces_n(&table, &pose, &load).unwrap();
        let j1 = cpm_kinematics::j1(&table, &pose);
        let w = platform_wrench(&load, &pose);
        let back = j1.transpose() * nalgebra::DVector::from_vec(t);
        for k in 0..6 {
            assert!((back[k] - w[k]).abs() < 1e-9 * (1.0 + w[k].abs()), "{k}");
        }
    }
}

#[test]
fn zero_clearance_gives_zero_correction() {
    let table = JointTable::paper_cubic();
    for rule in [SignRule::Hard, SignRule::Smooth { force_scale_n: 1.0 }] {
        let m = ClearanceModel {
            radius_um: 0.0,
            rule,
        };
        for pose in poses() {
            let dl = m
                .link_corrections_mm(&table, &pose, &Load::default())
                .unwrap();
            assert!(dl.iter().all(|v| *v == 0.0));
        }
    }
}

#[test]
fn flipping_the_load_flips_the_sign() {
    let table = JointTable::paper_cubic();
    let m = ClearanceModel::default();
    let down = Load::default();
    let up = Load {
        gravity_mm_s2: -down.gravity_mm_s2,
        ..down
    };
    for pose in poses() {
        let a = m.link_corrections_mm(&table, &pose, &down).unwrap();
        let b = m.link_corrections_mm(&table, &pose, &up).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(*x, -*y);
            assert!((x.abs() - 0.020).abs() < 1e-15 || *x == 0.0);
        }
    }
}

#[test]
fn weight_puts_z_links_in_compression() {
    let table = JointTable::paper_cubic();
    let t = link_forces_n(&table, &table.home, &Load::default()).unwrap();
    // Total weight 20 kg * 9.80665 = 196.1 N carried by links 1-3 (vertical).
    let sum: f64 = t[..3].iter().sum();
    assert!((sum + 196.133).abs() < 1e-3, "{sum}");
}

#[test]
fn smooth_rule_matches_hard_rule_away_from_zero_and_is_continuous() {
    let s = SignRule::Smooth { force_scale_n: 1.0 };
    assert!((s.factor(50.0) - 1.0).abs() < 1e-12);
    assert!((s.factor(-50.0) + 1.0).abs() < 1e-12);
    assert!(s.factor(1e-9).abs() < 1e-8);
    assert_eq!(SignRule::Hard.factor(0.0), 0.0);
}

#[test]
fn invalid_radius_is_rejected() {
    let m = ClearanceModel {
        radius_um: f64::NAN,
        rule: SignRule::Hard,
    };
    let e = m
        .link_corrections_mm(
            &JointTable::paper_cubic(),
            &Pose::identity(),
            &Load::default(),
        )
        .unwrap_err();
    assert!(e.to_string().contains("radius_um"));
}

#[test]
fn forces_match_an_svd_solve_over_wide_poses_and_singular_poses_fail() {
    // The same forces as nalgebra's SVD solve of J1^T t = w over wide random poses and
    // loads; a singular J1 fails (and does not hang the SVD).
    let table = JointTable::paper_cubic();
    let mut state = 99u64;
    let mut u = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for _ in 0..300 {
        let pose = Pose::from_xyz_rpy(
            200.0 * u(),
            200.0 * u(),
            400.0 + 100.0 * u(),
            0.6 * u(),
            0.6 * u(),
            0.6 * u(),
        );
        let load = Load {
            external_force_n: Vector3::new(100.0 * u(), 100.0 * u(), 100.0 * u()),
            ..Load::default()
        };
        let j1 = cpm_kinematics::j1(&table, &pose);
        let w = platform_wrench(&load, &pose);
        let a = j1.transpose();
        let svd = a.clone().try_svd(true, true, f64::EPSILON, 10_000).unwrap();
        let cond = svd.singular_values.max() / svd.singular_values.min();
        match link_forces_n(&table, &pose, &load) {
            Ok(t) => {
                assert!(cond <= 1e10, "{cond}");
                let want = svd
                    .solve(&nalgebra::DVector::from_column_slice(w.as_slice()), 0.0)
                    .unwrap();
                let scale = want.amax().max(1.0);
                for (a, b) in t.iter().zip(want.iter()) {
                    assert!((a - b).abs() <= 1e-9 * scale, "{a} vs {b} (cond {cond})");
                }
            }
            Err(e) => assert!(cond > 1e10, "{e} at condition {cond}"),
        }
    }
    // A planar platform (all joints in one plane with the base): J1 is singular.
    let mut flat = table.clone();
    for l in &mut flat.links {
        l.base_mm.z = 0.0;
        l.platform_mm.z = 0.0;
    }
    let pose = Pose::from_xyz_rpy(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    assert!(link_forces_n(&flat, &pose, &Load::default()).is_err());
}

/// The hard rule's corrections (taken from an LU solve when the forces' signs are certain)
/// are the signs of the SVD's forces, pose for pose, over a grid of poses and loads; and a
/// load of zero (every force zero, no sign certain) still gives zero shifts.
#[test]
fn hard_rule_corrections_are_the_signs_of_the_svd_forces() {
    let table = JointTable::paper_cubic();
    let model = ClearanceModel::default();
    let two_r_mm = 2.0 * model.radius_um * 1e-3;
    let loads = [
        Load::default(),
        Load {
            external_force_n: Vector3::new(5.0, -3.0, 2.0),
            ..Load::default()
        },
        Load {
            platform_mass_kg: 0.0,
            ..Load::default()
        },
    ];
    for load in &loads {
        for i in 0..200 {
            let f = i as f64;
            let pose = Pose::from_xyz_rpy(
                40.0 * (0.7 * f).sin(),
                40.0 * (1.3 * f).cos(),
                400.0 + 30.0 * (0.4 * f).sin(),
                0.15 * (0.9 * f).cos(),
                0.15 * (1.7 * f).sin(),
                0.15 * (0.3 * f).cos(),
            );
            let got = model.link_corrections_mm(&table, &pose, load).unwrap();
            let t = link_forces_n(&table, &pose, load).unwrap();
            let want: Vec<f64> = t
                .iter()
                .map(|&t| two_r_mm * SignRule::Hard.factor(t))
                .collect();
            assert_eq!(got, want, "pose {i}");
        }
    }
}
