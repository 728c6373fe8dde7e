//! NIST StRD nonlinear regression: every dataset from both starts with exact Jacobians and
//! default options must agree with the certified parameters to at least 6 digits (LRE, the
//! number of correct significant digits of the worst parameter, capped at 11). Lanczos1's
//! certified residual sum of squares (1.4e-25) is below what double precision can
//! reproduce, so it is judged, like every dataset, on its parameters. BoxBOD from its
//! first start is solved by the default evaporation restart ([`cpm_lm::Evaporation`]). Run with
//! `-- --nocapture` to see the table (LRE of the parameters, of the residual sum of squares
//! and of the standard deviations from `stats`).

#[path = "common/nist.rs"]
mod nist;

use cpm_lm::{check_jacobian, minimize, Damping, GeodesicAcceleration, Options};
use nist::{load, lre, min_lre, names, NistProblem};

#[test]
fn analytic_jacobians_match_finite_differences() {
    for name in names() {
        let d = load(name);
        let mut p = NistProblem::new(&d);
        for x in [&d.start1, &d.start2, &d.certified] {
            let c = check_jacobian(&mut p, x, 1e-6).unwrap();
            assert!(c.is_consistent(1e-6), "{name} at {x:?}: {c}");
        }
    }
}

#[test]
fn parser_reads_every_dataset() {
    let sizes: Vec<(usize, usize)> = names()
        .iter()
        .map(|n| {
            let d = load(n);
            assert_eq!(d.start1.len(), d.certified.len());
            assert_eq!(d.start2.len(), d.certified.len());
            assert!(d.certified_rss > 0.0);
            (d.certified.len(), d.y.len())
        })
        .collect();
    assert_eq!(sizes[0], (2, 14)); // Misra1a
    assert_eq!(
        sizes[names().iter().position(|n| *n == "Nelson").unwrap()],
        (3, 128)
    );
    assert_eq!(
        sizes[names().iter().position(|n| *n == "ENSO").unwrap()],
        (9, 168)
    );
}

#[test]
fn nist_strd_lre_at_least_6_from_both_starts() {
    let rows = run_all(&Options::default());
    println!(
        "{:<10} {:>5} {:>8} {:>8} {:>8} {:>6}  termination",
        "dataset", "start", "LRE(b)", "LRE(ss)", "LRE(sd)", "iters"
    );
    for (name, s, l, rss, sd, it, _, t) in &rows {
        println!("{name:<10} {s:>5} {l:>8.2} {rss:>8.2} {sd:>8.2} {it:>6}  {t}");
    }
    let (min, mean, _) = summary(&rows);
    println!(
        "parameter LRE over {} runs: min {min:.2}, mean {mean:.2}",
        rows.len()
    );
    // BoxBOD from its first start included: the plain method stops on the plateau
    // b2 -> infinity, and the evaporation restart (see `boxbod_start_1_...`) solves it.
    let failed: Vec<String> = rows
        .iter()
        .filter(|r| r.2 < 6.0)
        .map(|r| format!("{} start {}: LRE {:.2} ({})", r.0, r.1, r.2, r.7))
        .collect();
    assert!(failed.is_empty(), "runs below LRE 6: {failed:#?}");
    assert_eq!(rows.len(), 46);
    // The statistics reproduce NIST's certified standard deviations, except for Lanczos1
    // whose residuals are at the rounding level of the data (sigma^2 is then noise).
    let bad_sd: Vec<String> = rows
        .iter()
        .filter(|r| r.0 != "Lanczos1" && r.4 < 5.0)
        .map(|r| format!("{} start {}: standard deviation LRE {:.2}", r.0, r.1, r.4))
        .collect();
    assert!(bad_sd.is_empty(), "{bad_sd:#?}");
}

#[test]
fn boxbod_start_1_plateau_and_geodesic_acceleration() {
    let d = load("BoxBOD");
    let mut p = NistProblem::new(&d);
    // Without the restart: the plateau, where the model is the constant b1 and the residual
    // sum of squares is that of the data about their mean (9771.5); b2 has evaporated.
    let mean = d.y.iter().sum::<f64>() / d.y.len() as f64;
    let plateau: f64 = d.y.iter().map(|y| (y - mean).powi(2)).sum();
    assert!((plateau - 9771.5).abs() < 1e-9);
    let mut x = d.start1.clone();
    let no_restart = Options {
        evaporation_restart: None,
        ..Options::default()
    };
    let plain = minimize(&mut p, &mut x, &no_restart).unwrap();
    assert!(
        (2.0 * plain.final_cost - plateau).abs() < 1e-3 * plateau,
        "{plain:#}"
    );
    assert!(plain.evaporated.is_empty() && plain.restarts == 0);
    // Accelerated from the start, and by default (plain, then the restart with acceleration
    // because b2 evaporated): the certified minimum.
    let accelerated = Options {
        acceleration: Some(GeodesicAcceleration::default()),
        ..Options::default()
    };
    for options in [accelerated, Options::default()] {
        let mut x = d.start1.clone();
        let report = minimize(&mut p, &mut x, &options).unwrap();
        let rss = lre(2.0 * report.final_cost, d.certified_rss);
        let params = min_lre(&x, &d.certified);
        assert!(
            rss >= 6.0 && params >= 6.0,
            "RSS LRE {rss:.2}, parameter LRE {params:.2}\n{report:#}"
        );
        assert_eq!(report.restarts, usize::from(options.acceleration.is_none()));
    }
    // With bounds (issue 62: the solve used to end on the plateau claiming convergence, the
    // restart off): b >= 0 and an inactive upper bound both reach the certified minimum.
    for (lower, upper) in [
        (Some(vec![0.0; 2]), None),
        (None, Some(vec![f64::INFINITY; 2])),
    ] {
        let mut x = d.start1.clone();
        let mut q = NistProblem::new(&d);
        let report = minimize(
            &mut q,
            &mut x,
            &Options {
                lower,
                upper,
                ..Options::default()
            },
        )
        .unwrap();
        let rss = lre(2.0 * report.final_cost, d.certified_rss);
        let params = min_lre(&x, &d.certified);
        assert!(
            rss >= 6.0 && params >= 6.0 && report.was_successful(),
            "RSS LRE {rss:.2}, parameter LRE {params:.2}\n{report:#}"
        );
    }
}

#[test]
fn other_dampings_solve_nist_problems() {
    for damping in [Damping::Marquardt, Damping::CubicInterpolation] {
        for name in ["Misra1a", "Chwirut2", "DanWood", "Kirby2"] {
            let d = load(name);
            let mut p = NistProblem::new(&d);
            let mut x = d.start2.clone();
            let options = Options {
                damping,
                ..Options::default()
            };
            let report = minimize(&mut p, &mut x, &options).unwrap();
            let l = min_lre(&x, &d.certified);
            assert!(l >= 6.0, "{damping:?} on {name}: LRE {l:.2}\n{report:#}");
        }
    }
}

/// One row of the LRE table: dataset, start, parameter LRE, RSS LRE, standard-deviation LRE,
/// iterations, residual evaluations, termination.
type Row = (&'static str, usize, f64, f64, f64, usize, usize, String);

fn run_all(options: &Options) -> Vec<Row> {
    let mut rows = Vec::new();
    for name in names() {
        let d = load(name);
        let mut p = NistProblem::new(&d);
        for (s, start) in [(1, &d.start1), (2, &d.start2)] {
            let mut x = start.clone();
            let report = minimize(&mut p, &mut x, options).unwrap();
            let params = min_lre(&x, &d.certified);
            let rss = lre(2.0 * report.final_cost, d.certified_rss);
            let sd = report
                .statistics()
                .map(|st| {
                    st.std_dev
                        .iter()
                        .zip(&d.certified_sd)
                        .map(|(e, c)| e.map_or(0.0, |e| lre(e, *c)))
                        .fold(f64::INFINITY, f64::min)
                })
                .unwrap_or(0.0);
            rows.push((
                name,
                s,
                params,
                rss,
                sd,
                report.iterations.len(),
                report.residual_evaluations,
                report.termination.to_string(),
            ));
        }
    }
    rows
}

fn summary(rows: &[Row]) -> (f64, f64, usize) {
    let min = rows.iter().map(|r| r.2).fold(f64::INFINITY, f64::min);
    let mean = rows.iter().map(|r| r.2).sum::<f64>() / rows.len() as f64;
    let evals = rows.iter().map(|r| r.6).sum();
    (min, mean, evals)
}

#[test]
fn geodesic_acceleration_table() {
    let plain = run_all(&Options::default());
    let accel = run_all(&Options {
        acceleration: Some(GeodesicAcceleration::default()),
        ..Options::default()
    });
    println!(
        "{:<10} {:>5} | {:>8} {:>8} {:>6} | {:>8} {:>8} {:>6}",
        "dataset", "start", "LRE(b)", "LRE(ss)", "evals", "LRE(b)", "LRE(ss)", "evals"
    );
    for (p, a) in plain.iter().zip(&accel) {
        println!(
            "{:<10} {:>5} | {:>8.2} {:>8.2} {:>6} | {:>8.2} {:>8.2} {:>6}  {} / {}",
            p.0, p.1, p.2, p.3, p.6, a.2, a.3, a.6, p.7, a.7
        );
    }
    let (pm, pa, pe) = summary(&plain);
    let (am, aa, ae) = summary(&accel);
    println!(
        "parameter LRE over {} runs, plain: min {pm:.2} mean {pa:.2} ({pe} residual evaluations); \
         accelerated: min {am:.2} mean {aa:.2} ({ae} residual evaluations)",
        plain.len()
    );
    // With acceleration every run reaches LRE 6 except MGH09 from its first start, where
    // the ratio test rejects most trials along the valley and the iteration limit is hit;
    // the acceleration is therefore an option, not the default.
    let failed: Vec<String> = accel
        .iter()
        .filter(|r| r.2 < 6.0 && !(r.0 == "MGH09" && r.1 == 1))
        .map(|r| format!("{} start {}: LRE {:.2} ({})", r.0, r.1, r.2, r.7))
        .collect();
    assert!(
        failed.is_empty(),
        "accelerated runs below LRE 6: {failed:#?}"
    );
}

/// A user without an analytic Jacobian: the same problems with finite-difference Jacobians
/// (`NumericJacobian`). The minimum is defined by the residuals alone, so the certified
/// values are still reached; the differenced Jacobian only changes the path and the
/// statistics. Run with `-- --nocapture` for the table.
#[test]
fn nist_strd_with_finite_difference_jacobians() {
    use cpm_lm::{Difference, NumericJacobian};
    let mut worst = [f64::INFINITY; 2];
    let mut sum = [0.0; 2];
    let mut runs = 0;
    for name in names() {
        let d = load(name);
        for (s, start) in [(1, &d.start1), (2, &d.start2)] {
            // BoxBOD from start 1 stops on its plateau with any Jacobian (every solver does;
            // `boxbod_start_1_plateau_and_geodesic_acceleration` covers it).
            if name == "BoxBOD" && s == 1 {
                continue;
            }
            runs += 1;
            for (k, scheme) in [Difference::Forward, Difference::Central]
                .into_iter()
                .enumerate()
            {
                let mut p = NumericJacobian::new(NistProblem::new(&d), scheme);
                let mut x = start.clone();
                let report = minimize(&mut p, &mut x, &Options::default()).unwrap();
                let l = min_lre(&x, &d.certified);
                println!("{name:<10} {scheme:?}: LRE {l:.2} ({})", report.termination);
                worst[k] = worst[k].min(l);
                sum[k] += l;
            }
        }
    }
    println!(
        "finite differences over {runs} runs: forward min {:.2} mean {:.2}; central min {:.2} mean {:.2}",
        worst[0],
        sum[0] / runs as f64,
        worst[1],
        sum[1] / runs as f64
    );
    assert!(
        worst[1] >= 6.0,
        "central differences: min LRE {:.2}",
        worst[1]
    );
    assert!(
        worst[0] >= 4.5,
        "forward differences: min LRE {:.2}",
        worst[0]
    );
}
