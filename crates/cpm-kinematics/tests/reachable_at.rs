//! `reachable_at` judges a pose where it is: poses whose straight path from home leaves the
//! link limits are accepted when the pose itself is fine, and every accepted pose is
//! returned by forward kinematics from its own link lengths.
use cpm_geometry::{JointTable, Pose};
use cpm_kinematics::workspace::{reachable_at, reachable_from_home, Unreachable};
use cpm_kinematics::{forward, inverse_lengths, ForwardOptions};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

#[test]
fn the_pose_that_broke_the_jacobi_svd_is_reachable() {
    let t = JointTable::paper_cubic();
    let p = Pose::from_xyz_rpy_deg(
        [99.58805020016456, 3.9843588510118195, 468.13583684966636],
        [-4.208498394311623, 10.661149891107017, -13.63256995021592],
    );
    let c = cpm_kinematics::workspace::j1_condition(&t, &p).unwrap();
    assert!((700.0..850.0).contains(&c), "{c}");
    assert_eq!(reachable_at(&t, &p, 1e4), Ok(()));
    assert_eq!(
        reachable_at(&t, &p, 500.0),
        Err(Unreachable::NearSingular { condition: c })
    );
}

#[test]
fn only_what_is_wrong_at_the_pose_counts() {
    let t = JointTable::hexapod_66();
    let mut rng = StdRng::seed_from_u64(4);
    let (mut path_only, mut accepted) = (0, 0);
    for _ in 0..4000 {
        let mut u = || rng.random_range(-1.0..1.0);
        let p = Pose::from_xyz_rpy_deg(
            [50.0 * u(), 50.0 * u(), 300.0 + 50.0 * u()],
            [60.0 * u(), 60.0 * u(), 60.0 * u()],
        );
        let at = reachable_at(&t, &p, 1e4);
        if at.is_ok() {
            accepted += 1;
            // Every link within its limits at the pose, and FK from home or near returns it.
            for (l, len) in t.links.iter().zip(inverse_lengths(&t, &p)) {
                let (lo, hi) = l.length_limits_mm.unwrap();
                assert!(len >= lo && len <= hi);
            }
            let l = inverse_lengths(&t, &p);
            let near = p.perturbed(&nalgebra::Vector6::new(
                0.3, -0.2, 0.25, 2e-3, -1.5e-3, 1e-3,
            ));
            let back = forward(&t, &l, &near, &ForwardOptions::default())
                .unwrap()
                .0;
            assert!((back.position_mm - p.position_mm).norm() < 1e-6);
            if matches!(
                reachable_from_home(&t, &p, 1e4),
                Err(Unreachable::LengthLimit { .. })
            ) {
                path_only += 1;
            }
        } else {
            assert!(
                !matches!(at, Err(Unreachable::Svd(_) | Unreachable::Invalid)),
                "{at:?}"
            );
        }
    }
    assert!(accepted > 100, "{accepted}");
    // The old rule refused some of these for a length on the imagined straight path.
    assert!(path_only > 0, "{path_only} of {accepted}");
}

#[test]
fn another_assembly_mode_is_refused() {
    // The paper cube's platform folded through the base plane (z 0.41 mm, a pose in metres):
    // well conditioned, but det J1 has the other sign and FK from home does not return it.
    let t = JointTable::paper_cubic();
    let p = Pose::from_xyz_rpy(0.0, 0.0, 0.41, 0.0, 0.0, 0.0);
    assert!(matches!(
        reachable_at(&t, &p, 1e4),
        Err(Unreachable::AssemblyModeChange { .. })
    ));
}
