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

/// `ReachableAt` (forward kinematics' first step from home made once) gives what
/// `reachable_at` gives, to the bit, on poses of every kind (reachable, outside the link
/// limits, near singular, in another assembly mode, in metres) of three tables; and
/// `forward_from` what `forward` gives from the same start, with few iterations too.
#[test]
fn the_first_step_made_once_changes_nothing() {
    use cpm_geometry::InstallationErrors;
    use cpm_kinematics::{forward_from, ForwardStart, ReachableAt};
    let cube = JointTable::paper_cubic();
    let shifted = InstallationErrors::paper_table2().apply(&cube).unwrap();
    let mut rng = StdRng::seed_from_u64(34);
    let mut kinds = std::collections::BTreeSet::new();
    for t in [cube, shifted, JointTable::hexapod_66()] {
        let reach = ReachableAt::new(&t);
        let h = t.home.position_mm;
        for k in 0..6000 {
            let mut u = || rng.random_range(-1.0..1.0);
            let (mm, deg) = [(5.0, 2.0), (60.0, 15.0), (250.0, 70.0)][k % 3];
            let mut p = Pose::from_xyz_rpy_deg(
                [h.x + mm * u(), h.y + mm * u(), h.z + mm * u()],
                [deg * u(), deg * u(), deg * u()],
            );
            if k % 50 == 0 {
                // Folded through the base plane, or in metres.
                p = Pose::from_xyz_rpy(1e-3 * p.position_mm.x, 0.0, 0.41, 0.0, 0.0, 0.0);
            }
            let bound = [1e4, 50.0][k % 2];
            let (once, each) = (reach.check(&p, bound), reachable_at(&t, &p, bound));
            assert_eq!(format!("{once:?}"), format!("{each:?}"), "{p:?}");
            kinds.insert(format!("{each:?}").chars().take(8).collect::<String>());
            let mut lengths = inverse_lengths(&t, &p);
            lengths[k % 6] += 1e-3 * u();
            for iterations in [0, 1, 3, 50] {
                let options = ForwardOptions {
                    max_iterations: iterations,
                    ..ForwardOptions::default()
                };
                let start = ForwardStart::new(&t, &t.home, &options).unwrap();
                assert_eq!(
                    format!("{:?}", forward_from(&t, &lengths, &start)),
                    format!("{:?}", forward(&t, &lengths, &t.home, &options)),
                    "{p:?} {iterations}"
                );
            }
        }
    }
    // Accepted, and refused for the link limits, the condition number, the assembly mode.
    assert_eq!(kinds.len(), 4, "{kinds:?}");
}

/// The rule of `reachable_at` (see its module doc) written out here, independently of the
/// library's code: forward kinematics from home first, then det J1's sign, then a start near
/// the pose. The library must give the same verdict and the same distances on poses of all
/// kinds (reachable, other assembly modes, near singular, outside the length limits).
fn reachable_at_as_written(
    t: &JointTable,
    p: &Pose,
    max_condition: f64,
) -> Result<(), Unreachable> {
    use nalgebra::{Matrix6, Vector6};
    let lengths = inverse_lengths(t, p);
    for (i, (l, len)) in t.links.iter().zip(&lengths).enumerate() {
        if !len.is_finite() {
            return Err(Unreachable::Invalid);
        }
        if let Some((lo, hi)) = l.length_limits_mm {
            if !(*len >= lo && *len <= hi) {
                return Err(Unreachable::LengthLimit {
                    link: i,
                    length_mm: *len,
                    limits_mm: (lo, hi),
                });
            }
        }
    }
    let c = cpm_kinematics::workspace::j1_condition(t, p).map_err(Unreachable::Svd)?;
    if !(c <= max_condition) {
        return Err(Unreachable::NearSingular { condition: c });
    }
    let radius = t
        .links
        .iter()
        .map(|l| l.platform_mm.norm())
        .fold(1.0f64, f64::max);
    let distance = |start: &Pose| match forward(t, &lengths, start, &ForwardOptions::default()) {
        Ok((q, _)) => {
            let d = p.difference(&q);
            d.fixed_rows::<3>(0).norm() + d.fixed_rows::<3>(3).norm() * radius
        }
        Err(_) => f64::INFINITY,
    };
    let from_home_mm = distance(&t.home);
    if from_home_mm <= 1e-3 {
        return Ok(());
    }
    let det = |q: &Pose| {
        let j = cpm_kinematics::j1(t, q);
        Matrix6::from_fn(|r, c| j[(r, c)]).determinant()
    };
    // Six links only: more have no det J1 whose sign could change.
    if t.num_links() == 6 && !(det(p) * det(&t.home) > 0.0) {
        return Err(Unreachable::AssemblyModeChange { at: 1.0 });
    }
    let near = p.perturbed(&Vector6::new(0.3, -0.2, 0.25, 2e-3, -1.5e-3, 1e-3));
    let from_near_mm = distance(&near);
    if from_near_mm <= 1e-3 {
        return Ok(());
    }
    Err(Unreachable::ForwardMismatch {
        from_home_mm,
        from_near_mm,
    })
}

#[test]
fn the_verdicts_are_those_of_the_rule_written_out() {
    let mut rng = StdRng::seed_from_u64(36);
    for (t, z, r) in [
        (JointTable::paper_cubic(), 430.0, 150.0),
        (JointTable::hexapod_66(), 300.0, 50.0),
    ] {
        let at = cpm_kinematics::ReachableAt::new(&t);
        let mut kinds = std::collections::BTreeMap::new();
        for _ in 0..3000 {
            let mut u = || rng.random_range(-1.0..1.0);
            // A wide box: the cube's other assembly modes and near-singular poses among them.
            let p = Pose::from_xyz_rpy_deg(
                [r * u(), r * u(), z + r * 1.6 * u()],
                [70.0 * u(), 70.0 * u(), 70.0 * u()],
            );
            for bound in [1e4, 1e2] {
                let expected = reachable_at_as_written(&t, &p, bound);
                assert_eq!(reachable_at(&t, &p, bound), expected, "{p:?}");
                assert_eq!(at.check(&p, bound), expected, "{p:?}");
                let kind = match expected {
                    Ok(()) => "reachable",
                    Err(Unreachable::LengthLimit { .. }) => "length",
                    Err(Unreachable::NearSingular { .. }) => "singular",
                    Err(Unreachable::AssemblyModeChange { .. }) => "mode",
                    Err(Unreachable::ForwardMismatch { .. }) => "mismatch",
                    Err(_) => "other",
                };
                *kinds.entry(kind).or_insert(0) += 1;
            }
        }
        // The box holds poses of each kind the rule tells apart (the cube has no limits).
        assert!(
            kinds.get("reachable").copied().unwrap_or(0) > 100,
            "{kinds:?}"
        );
        assert!(
            kinds.get("singular").copied().unwrap_or(0) > 10,
            "{kinds:?}"
        );
        assert!(kinds.len() >= 3, "{kinds:?}");
    }
}

/// A table of seven links (the cube with a second y link, least-squares forward kinematics,
/// no assembly-mode sign): the library's verdicts are those of the rule written out, with
/// `ReachableAt` and without, under three condition bounds.
#[test]
fn seven_links_are_judged_by_the_rule_written_out() {
    let mut t = JointTable::paper_cubic();
    t.links.push(cpm_geometry::Link::new(
        [100.0, -205.0, 280.0],
        [100.0, 177.0, -140.0],
    ));
    let at = cpm_kinematics::ReachableAt::new(&t);
    let mut rng = StdRng::seed_from_u64(38);
    let mut kinds = std::collections::BTreeMap::new();
    for _ in 0..1500 {
        let mut u = || rng.random_range(-1.0..1.0);
        let p = Pose::from_xyz_rpy_deg(
            [150.0 * u(), 150.0 * u(), 430.0 + 240.0 * u()],
            [70.0 * u(), 70.0 * u(), 70.0 * u()],
        );
        for bound in [1e4, 1e2, 1e9] {
            let expected = reachable_at_as_written(&t, &p, bound);
            assert_eq!(reachable_at(&t, &p, bound), expected, "{p:?}");
            assert_eq!(at.check(&p, bound), expected, "{p:?}");
            let kind = format!("{expected:?}").chars().take(8).collect::<String>();
            *kinds.entry(kind).or_insert(0) += 1;
        }
    }
    // Accepted and refused as near singular, both many times. (Forward kinematics returns
    // every pose of this box: the least-squares solve has no other assembly mode here.)
    assert!(kinds.get("Ok(())").copied().unwrap_or(0) > 100, "{kinds:?}");
    assert!(
        kinds.get("Err(Near").copied().unwrap_or(0) > 100,
        "{kinds:?}"
    );
}

/// `forward_from_toward` (Newton from home stopping near a known solution, as `ReachableAt`
/// uses it) lands where `forward_from` lands, on poses of every kind: at the pose when
/// `forward_from` returns it (within the 1e-3 mm `reachable_at` asks for), elsewhere or
/// nowhere when it does not; and when it stops early, in fewer iterations.
#[test]
fn stopping_near_the_pose_lands_where_newton_lands() {
    use cpm_kinematics::fk::NEAR_SOLUTION_MM;
    use cpm_kinematics::{forward_from, forward_from_toward, ForwardStart};
    let mut rng = StdRng::seed_from_u64(37);
    for (t, z, r) in [
        (JointTable::paper_cubic(), 430.0, 150.0),
        (JointTable::hexapod_66(), 300.0, 50.0),
    ] {
        let start = ForwardStart::new(&t, &t.home, &ForwardOptions::default()).unwrap();
        let radius = t
            .links
            .iter()
            .map(|l| l.platform_mm.norm())
            .fold(1.0, f64::max);
        let (mut early, mut elsewhere) = (0, 0);
        for _ in 0..3000 {
            let mut u = || rng.random_range(-1.0..1.0);
            let p = Pose::from_xyz_rpy_deg(
                [r * u(), r * u(), z + r * 1.6 * u()],
                [70.0 * u(), 70.0 * u(), 70.0 * u()],
            );
            let lengths = inverse_lengths(&t, &p);
            if !lengths.iter().all(|l| l.is_finite()) {
                continue;
            }
            let distance = |q: &Pose| {
                let d = p.difference(q);
                d.fixed_rows::<3>(0).norm() + d.fixed_rows::<3>(3).norm() * radius
            };
            let full = forward_from(&t, &lengths, &start);
            let toward = forward_from_toward(&t, &lengths, &start, &p);
            let lands = |r: &Result<(Pose, cpm_kinematics::ForwardReport), _>| {
                r.as_ref().is_ok_and(|(q, _)| distance(q) <= 1e-3)
            };
            assert_eq!(lands(&full), lands(&toward), "{p:?}");
            match (&full, &toward) {
                (Ok((_, a)), Ok((s, b))) if lands(&full) => {
                    assert!(distance(s) <= 2.0 * NEAR_SOLUTION_MM, "{p:?}");
                    assert!(b.iterations <= a.iterations, "{p:?}");
                    early += usize::from(b.iterations < a.iterations);
                }
                _ => {
                    assert_eq!(full.is_ok(), toward.is_ok(), "{p:?}");
                    elsewhere += 1;
                }
            }
        }
        assert!(early > 300, "{early} early stops");
        assert!(elsewhere > 30, "{elsewhere} poses not returned");
    }
}
