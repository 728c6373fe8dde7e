//! Scale invariance of the statistics: Jacobians with entries near 1e150 or 1e-200
//! (residuals scaled alike) and columns scaled over 1e-100 .. 1e100 give the rank, relative
//! singular values and relative standard deviations of the unscaled problem, and no NaN.
use cpm_lm::stats::Statistics;
use faer::Mat;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn problem(seed: u64, deficient: bool) -> (Mat<f64>, Vec<f64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let (m, n) = (40, 8);
    let mut j = Mat::<f64>::from_fn(m, n, |_, _| rng.random_range(-1.0..1.0));
    if deficient {
        // Column 7 = 2 * column 0 - column 3: only combinations are identifiable.
        for i in 0..m {
            j[(i, 7)] = 2.0 * j[(i, 0)] - j[(i, 3)];
        }
    }
    let r = (0..m).map(|_| rng.random_range(-0.1..0.1)).collect();
    (j, r)
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(f64::MIN_POSITIVE)
}

/// `st` against `base`: same rank and identifiability, relative singular values, and
/// standard deviations times `scale[p]` (the column scale over the residual scale).
fn compare(st: &Statistics, base: &Statistics, scale: &[f64], what: &str) {
    assert_eq!(st.rank, base.rank, "{what}: rank");
    assert_eq!(st.identifiable, base.identifiable, "{what}");
    assert!(st.singular_values.iter().all(|s| s.is_finite()), "{what}");
    for k in 0..st.singular_values.len() {
        let a = st.singular_values[k] / st.singular_values[0];
        let b = base.singular_values[k] / base.singular_values[0];
        assert!(
            (a - b).abs() <= 1e-10 * b.max(1e-6),
            "{what}: relative singular value {k}: {a:e} vs {b:e}"
        );
    }
    for (p, (s, b)) in st.std_dev.iter().zip(&base.std_dev).enumerate() {
        match (s, b) {
            (Some(s), Some(b)) => {
                assert!(s.is_finite(), "{what}: std {p} = {s}");
                let e = rel(s * scale[p], *b);
                assert!(
                    e <= 1e-10,
                    "{what}: std {p}: {:e} vs {b:e} ({e:e})",
                    s * scale[p]
                );
            }
            (None, None) => {}
            _ => panic!("{what}: std {p}: {s:?} vs {b:?}"),
        }
    }
    for r in 0..st.num_params {
        for c in 0..st.num_params {
            let (x, y) = (st.correlation[(r, c)], base.correlation[(r, c)]);
            assert!(x.is_nan() == y.is_nan(), "{what}: correlation NaN pattern");
            if !y.is_nan() {
                assert!((x - y).abs() <= 1e-10, "{what}: correlation {r},{c}");
            }
        }
    }
}

#[test]
fn uniform_extreme_scales() {
    for deficient in [false, true] {
        let (j, r) = problem(7, deficient);
        let base = Statistics::try_from_jacobian(j.as_ref(), &r, None).unwrap();
        assert_eq!(base.rank, if deficient { 7 } else { 8 });
        for c in [1e150, 1e-200, 1e300, 1e-300] {
            let jc = Mat::<f64>::from_fn(j.nrows(), j.ncols(), |i, k| j[(i, k)] * c);
            let rc: Vec<f64> = r.iter().map(|v| v * c).collect();
            let st = Statistics::try_from_jacobian(jc.as_ref(), &rc, None).unwrap();
            compare(
                &st,
                &base,
                &[1.0; 8],
                &format!("J, r x {c:e}, deficient {deficient}"),
            );
            // The Jacobian alone scaled: standard deviations scale by 1/c.
            let st = Statistics::try_from_jacobian(jc.as_ref(), &r, None).unwrap();
            compare(
                &st,
                &base,
                &[c; 8],
                &format!("J x {c:e}, deficient {deficient}"),
            );
        }
    }
}

#[test]
fn column_scales_spread_over_200_decades() {
    let mut rng = StdRng::seed_from_u64(11);
    for deficient in [false, true] {
        let (j, r) = problem(3, deficient);
        let base = Statistics::try_from_jacobian(j.as_ref(), &r, None).unwrap();
        for trial in 0..20 {
            let mut d: Vec<f64> = (0..8)
                .map(|_| 10f64.powf(rng.random_range(-100.0..100.0)))
                .collect();
            if trial == 0 {
                d = vec![1e-100, 1e100, 1e-50, 1e50, 1e-100, 1e100, 1.0, 1e-99];
            }
            let jd = Mat::<f64>::from_fn(j.nrows(), j.ncols(), |i, k| j[(i, k)] * d[k]);
            let st = Statistics::try_from_jacobian(jd.as_ref(), &r, None).unwrap();
            compare(
                &st,
                &base,
                &d,
                &format!("columns x {d:?}, deficient {deficient}"),
            );
            assert!(st
                .covariance
                .col_iter()
                .all(|c| c.iter().all(|v| !v.is_nan())));
        }
    }
}
