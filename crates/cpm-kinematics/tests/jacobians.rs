//! J1, J2 and the sensor pose gradient against central finite differences, and eq. 12's
//! first-order pose error against the exact forward-kinematics difference.
use cpm_geometry::strategies::{installation_errors, pose_near};
use cpm_geometry::{InstallationErrors, JointTable, Pose};
use cpm_kinematics::workspace::reachable_from_home;
use cpm_kinematics::{
    first_order_pose_error, forward, inverse_lengths, j1, j2, sensor_length_mm,
    sensor_pose_gradient, ForwardOptions,
};
use nalgebra::{DVector, Vector6};
use proptest::prelude::*;

fn reachable_pose(table: JointTable) -> impl Strategy<Value = Pose> {
    let home = table.home;
    pose_near(home, 100.0, 25.0).prop_filter("not reachable from home", move |p| {
        reachable_from_home(&table, p, 1e4).is_ok()
    })
}

fn table(hexapod: bool) -> JointTable {
    if hexapod {
        JointTable::hexapod_66()
    } else {
        JointTable::paper_cubic()
    }
}

/// Central difference of `f` along twist component `k` (step `h`).
fn fd_twist(pose: &Pose, k: usize, h: f64, f: impl Fn(&Pose) -> Vec<f64>) -> Vec<f64> {
    let mut e = Vector6::zeros();
    e[k] = h;
    let plus = f(&pose.perturbed(&e));
    let minus = f(&pose.perturbed(&(-e)));
    plus.iter()
        .zip(&minus)
        .map(|(a, b)| (a - b) / (2.0 * h))
        .collect()
}

/// Translation step (mm) and rotation step (rad) of the differences.
const H_T: f64 = 1e-3;
const H_R: f64 = 1e-6;

proptest! {
    #[test]
    fn j1_matches_finite_differences(
        (hexapod, p) in prop::bool::ANY.prop_flat_map(|h| (Just(h), reachable_pose(table(h))))
    ) {
        let t = table(hexapod);
        let j = j1(&t, &p);
        prop_assert_eq!(j.shape(), (6, 6));
        for k in 0..6 {
            let h = if k < 3 { H_T } else { H_R };
            let col = fd_twist(&p, k, h, |q| inverse_lengths(&t, q));
            for i in 0..6 {
                // d(length)/d(mm) is O(1); d(length)/d(rad) is O(100 mm).
                let tol = if k < 3 { 1e-8 } else { 1e-5 };
                prop_assert!((j[(i, k)] - col[i]).abs() < tol,
                    "J1[{},{}] = {} vs fd {}", i, k, j[(i, k)], col[i]);
            }
        }
    }

    #[test]
    fn j2_matches_finite_differences(
        (hexapod, p) in prop::bool::ANY.prop_flat_map(|h| (Just(h), reachable_pose(table(h))))
    ) {
        let t = table(hexapod);
        let j = j2(&t, &p);
        prop_assert_eq!(j.shape(), (6, 36));
        let h = 1e-3;
        for c in 0..36 {
            let (link, side, axis) = (c / 6, (c % 6) / 3, c % 3);
            let moved = |d: f64| {
                let mut m = t.clone();
                if side == 0 {
                    m.links[link].base_mm[axis] += d;
                } else {
                    m.links[link].platform_mm[axis] += d;
                }
                inverse_lengths(&m, &p)
            };
            let (plus, minus) = (moved(h), moved(-h));
            for i in 0..6 {
                let fd = (plus[i] - minus[i]) / (2.0 * h);
                prop_assert!((j[(i, c)] - fd).abs() < 1e-8,
                    "J2[{},{}] = {} vs fd {}", i, c, j[(i, c)], fd);
                if i != link {
                    prop_assert_eq!(j[(i, c)], 0.0);
                }
            }
        }
    }

    #[test]
    fn sensor_gradient_matches_finite_differences(
        (hexapod, p) in prop::bool::ANY.prop_flat_map(|h| (Just(h), reachable_pose(table(h))))
    ) {
        let t = table(hexapod);
        for s in &t.sensors {
            let g = sensor_pose_gradient(s, &p);
            for k in 0..6 {
                let h = if k < 3 { H_T } else { H_R };
                let fd = fd_twist(&p, k, h, |q| vec![sensor_length_mm(s, q)])[0];
                let tol = if k < 3 { 1e-8 } else { 1e-5 };
                prop_assert!((g[k] - fd).abs() < tol, "sensor {} d/d{}: {} vs {}", s.name, k, g[k], fd);
            }
        }
    }

    /// With lengths changed and joints moved, J1 dx + J2 de reproduces dl exactly for six
    /// links (eq. 12 inverts eq. 11).
    #[test]
    fn eq12_inverts_eq11(
        p in reachable_pose(JointTable::paper_cubic()),
        dl in prop::collection::vec(-0.1..0.1f64, 6),
        e in installation_errors(6, 100.0),
    ) {
        let t = JointTable::paper_cubic();
        let de: Vec<f64> = e.to_vec_um().iter().map(|v| v * 1e-3).collect();
        let dx = first_order_pose_error(&t, &p, &dl, &de).unwrap();
        let back = j1(&t, &p) * DVector::from_column_slice(dx.as_slice())
            + j2(&t, &p) * DVector::from_column_slice(&de);
        for i in 0..6 {
            prop_assert!((back[i] - dl[i]).abs() < 1e-10, "residual {:e}", back[i] - dl[i]);
        }
    }
}

/// The exact pose error: commanded pose `p`, lengths held at the nominal IK there, FK on
/// the actual table (nominal + `errors`); the twist from `p` to the actual pose.
fn exact_pose_error(t: &JointTable, p: &Pose, errors: &InstallationErrors) -> Vector6<f64> {
    let actual = errors.apply(t).unwrap();
    let l = inverse_lengths(t, p);
    let opts = ForwardOptions {
        tolerance_mm: 1e-12,
        ..ForwardOptions::default()
    };
    let (q, _) = forward(&actual, &l, p, &opts).unwrap();
    p.difference(&q)
}

fn scaled(e: &InstallationErrors, s: f64) -> InstallationErrors {
    let v: Vec<f64> = e.to_vec_um().iter().map(|x| x * s).collect();
    InstallationErrors::try_from_vec_um(&v).unwrap()
}

/// Discrepancy of eq. 12 at error scale `s`: translation (mm) and rotation (rad) parts.
fn discrepancy(t: &JointTable, p: &Pose, e: &InstallationErrors, s: f64) -> (f64, f64) {
    let es = scaled(e, s);
    let exact = exact_pose_error(t, p, &es);
    let de: Vec<f64> = es.to_vec_um().iter().map(|v| v * 1e-3).collect();
    let first = first_order_pose_error(t, p, &[0.0; 6], &de).unwrap();
    let d = exact - first;
    (d.fixed_rows::<3>(0).norm(), d.fixed_rows::<3>(3).norm())
}

fn check_quadratic(t: &JointTable, p: &Pose, e: &InstallationErrors) -> Result<(), String> {
    let d: Vec<(f64, f64)> = [1.0, 0.1, 0.01, 0.001]
        .iter()
        .map(|s| discrepancy(t, p, e, *s))
        .collect();
    for (k, w) in d.windows(2).enumerate() {
        let rt = w[0].0 / w[1].0;
        let rr = w[0].1 / w[1].1;
        // The first decade starts at full-size errors, where third-order terms still add
        // tens of percent on badly conditioned poses (seen: 91.9 and 131.9); it must only be
        // clearly better than linear. The later decades must be quadratic to 5 %.
        let band = if k == 0 { 50.0..200.0 } else { 95.0..105.0 };
        if !band.contains(&rt) || !band.contains(&rr) {
            return Err(format!(
                "ratios per decade: translation {rt:.2}, rotation {rr:.2}; discrepancies {d:?}"
            ));
        }
    }
    // And eq. 12 is a good approximation at the paper's error size.
    let first = exact_pose_error(t, p, e).fixed_rows::<3>(0).norm();
    // Within 5 %: the second-order term grows with J1's conditioning, and random reachable
    // poses reach condition numbers where 100 um errors give ~1 % (seen: 1.05 %), and more
    // where the errors are amplified (seen: 3.2 %, paper cube, 83 um joint errors moving the
    // platform 0.25 mm; its case is in the regression file).
    // Near singular poses amplify the errors (seen: 0.1 mm of joint errors moving the
    // platform 1.5 mm, with a 12 % second-order term); there eq. 12 holds only for smaller
    // errors, which the decade ratios above check.
    let largest_mm = e.to_vec_um().iter().fold(0.0f64, |m, v| m.max(v.abs())) * 1e-3;
    let well_conditioned = first <= 5.0 * largest_mm;
    let small = !well_conditioned || d[0].0 < 5e-2 * first.max(1e-3);
    if !small {
        return Err(format!("discrepancy {:e} vs error {first:e}", d[0].0));
    }
    Ok(())
}

#[test]
fn eq12_error_is_second_order_paper_table2() {
    let t = JointTable::paper_cubic();
    let e = InstallationErrors::paper_table2();
    for p in [
        t.home,
        Pose::from_xyz_rpy(30.0, -20.0, 440.0, 0.1, -0.05, 0.2),
        Pose::from_xyz_rpy(-60.0, 50.0, 360.0, -0.2, 0.3, -0.1),
    ] {
        check_quadratic(&t, &p, &e).unwrap();
    }
    let h = JointTable::hexapod_66();
    for p in [
        h.home,
        Pose::from_xyz_rpy(20.0, 10.0, 320.0, 0.05, -0.1, 0.15),
    ] {
        check_quadratic(&h, &p, &e).unwrap();
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn eq12_error_is_second_order(
        (hexapod, p) in prop::bool::ANY.prop_flat_map(|h| (Just(h), reachable_pose(table(h)))),
        e in installation_errors(6, 100.0),
    ) {
        let t = table(hexapod);
        // Errors of the paper's size (tens of um); a nearly zero draw has no signal.
        prop_assume!(e.to_vec_um().iter().map(|v| v.abs()).fold(0.0, f64::max) > 20.0);
        if let Err(m) = check_quadratic(&t, &p, &e) {
            prop_assert!(false, "{}", m);
        }
    }
}
