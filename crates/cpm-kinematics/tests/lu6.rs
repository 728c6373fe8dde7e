//! `Lu6` and `try_inverse6` give nalgebra's numbers bit for bit (solve, inverse,
//! determinant): random matrices of every scale, small integers (ties between pivot
//! candidates), zero columns, repeated rows and non-finite entries.
use cpm_kinematics::lu6::{try_inverse6, Lu6};
use nalgebra::{Matrix6, Vector6};
use proptest::prelude::*;

/// Bit equality, with any NaN equal to any NaN (the payload is not part of the result).
fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

fn same_vector(a: Option<Vector6<f64>>, b: Option<Vector6<f64>>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.iter().zip(b.iter()).all(|(x, y)| same(*x, *y)),
        _ => false,
    }
}

fn same_matrix(a: Option<Matrix6<f64>>, b: Option<Matrix6<f64>>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.iter().zip(b.iter()).all(|(x, y)| same(*x, *y)),
        _ => false,
    }
}

/// Checks `a` against nalgebra: the solve of `b`, the solve from rows, the inverse.
fn check(a: &Matrix6<f64>, b: &Vector6<f64>) -> Result<(), TestCaseError> {
    let ours = Lu6::new(a).solve(b);
    let theirs = a.lu().solve(b);
    prop_assert!(
        same_vector(ours, theirs),
        "solve of {a} {b}: {ours:?} vs {theirs:?}"
    );
    let rows: [[f64; 6]; 6] = std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
    prop_assert!(same_vector(Lu6::from_rows(&rows).solve(b), theirs));
    let (ours, theirs) = (try_inverse6(a), a.try_inverse());
    prop_assert!(
        same_matrix(ours, theirs),
        "inverse of {a}: {ours:?} vs {theirs:?}"
    );
    prop_assert!(same_matrix(Lu6::new(a).inverse(), a.lu().try_inverse()));
    let (ours, theirs) = (Lu6::new(a).determinant(), a.determinant());
    prop_assert!(same(ours, theirs), "determinant of {a}: {ours} vs {theirs}");
    Ok(())
}

/// An entry: a value of any scale, a small integer (ties), zero, or not finite.
fn entry() -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => (-1.0f64..1.0, -30i32..30).prop_map(|(m, e)| m * 2f64.powi(e)),
        3 => (-3i32..=3).prop_map(f64::from),
        1 => Just(0.0),
        1 => Just(-0.0),
        1 => prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)],
    ]
}

fn matrix() -> impl Strategy<Value = Matrix6<f64>> {
    (
        proptest::collection::vec(entry(), 36),
        0usize..4,
        0usize..6,
        0usize..6,
    )
        .prop_map(|(v, kind, i, j)| {
            let mut m = Matrix6::from_iterator(v);
            match kind {
                // A zero column: the pivot there is zero.
                1 => m.set_column(i, &Vector6::zeros()),
                // Two equal rows: singular in exact arithmetic.
                2 => {
                    let r = m.row(i).into_owned();
                    m.set_row(j, &r);
                }
                // Well conditioned: a dominant diagonal.
                3 => m += Matrix6::identity() * 100.0,
                _ => {}
            }
            m
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]
    #[test]
    fn the_numbers_are_nalgebras(a in matrix(), b in proptest::collection::vec(entry(), 6)) {
        check(&a, &Vector6::from_iterator(b))?;
    }

    #[test]
    fn finite_matrices_of_random_scale(
        v in proptest::collection::vec(-1.0f64..1.0, 36),
        b in proptest::collection::vec(-1e3f64..1e3, 6),
        scale in -20i32..20,
    ) {
        let a = Matrix6::from_iterator(v) * 2f64.powi(scale);
        check(&a, &Vector6::from_iterator(b))?;
    }
}

#[test]
fn a_zero_pivot_fails_as_nalgebra_does() {
    let mut a = Matrix6::<f64>::identity();
    a[(3, 3)] = 0.0;
    assert!(Lu6::new(&a).solve(&Vector6::repeat(1.0)).is_none());
    assert!(a.lu().solve(&Vector6::repeat(1.0)).is_none());
    assert!(try_inverse6(&a).is_none() && a.try_inverse().is_none());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    /// `inverse_norm` (reciprocal pivots, no row swaps) is the Frobenius norm of nalgebra's
    /// inverse to the rounding a condition number allows, and fails where the inverse does.
    #[test]
    fn inverse_norm_is_the_inverses_norm(
        v in proptest::collection::vec(-1.0f64..1.0, 36),
        scale in -20i32..20,
        kind in 0usize..3,
        i in 0usize..6,
    ) {
        let mut a = Matrix6::from_iterator(v) * 2f64.powi(scale);
        if kind == 1 {
            a.set_column(i, &Vector6::zeros());
        } else if kind == 2 {
            a += Matrix6::identity() * 2f64.powi(scale);
        }
        let ours = Lu6::new(&a).inverse_norm();
        match a.try_inverse() {
            None => prop_assert!(ours.is_none(), "{a}: {ours:?} for a singular matrix"),
            Some(inv) => {
                let (ours, theirs) = (ours.expect("an inverse"), inv.norm());
                let kappa = a.norm() * theirs;
                prop_assert!(
                    (ours - theirs).abs() <= 1e-14 * kappa * theirs,
                    "{a}: {ours} vs {theirs} (condition bound {kappa})"
                );
            }
        }
    }
}

/// `condition_at_most` passes a well conditioned matrix, refuses one beyond the bound and a
/// singular one, and never passes a matrix whose condition number exceeds the bound.
#[test]
fn condition_at_most_is_a_sound_shortcut() {
    use cpm_kinematics::fk::condition_at_most;
    let good = Matrix6::<f64>::identity() * 3.0;
    assert!(condition_at_most(&good, 10.0)); // |I|_F |I^-1|_F = 6
    assert!(!condition_at_most(&good, 5.9));
    let mut bad = Matrix6::<f64>::identity();
    bad[(2, 2)] = 1e-9;
    assert!(!condition_at_most(&bad, 1e8));
    bad[(2, 2)] = 0.0;
    assert!(!condition_at_most(&bad, f64::INFINITY));
    let (mut passed, mut refused) = (0, 0);
    for k in 0..200u32 {
        let a = Matrix6::from_fn(|r, c| ((r * 7 + c * 13 + k as usize * 31) % 17) as f64 - 8.0)
            + Matrix6::identity() * f64::from(k % 5);
        let sv = a.singular_values();
        let kappa = sv.max() / sv.min();
        for bound in [10.0, 100.0, 1e3, 1e6] {
            if condition_at_most(&a, bound) {
                assert!(kappa <= bound, "{a}: condition {kappa} passed for {bound}");
                passed += 1;
            } else {
                refused += 1;
            }
        }
    }
    // The matrices give both answers, so the check above is not vacuous.
    assert!(
        passed > 100 && refused > 100,
        "{passed} passed, {refused} refused"
    );
}
