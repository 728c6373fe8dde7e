//! Bound-constrained least squares against SciPy: the set of `tests/data/bounded_reference.tsv`
//! (Rosenbrock boxes, Moré-Garbow-Hillstrom problems with boxes active and inactive at the
//! solution, NIST fits with positivity bounds, starts on a bound, boxes that cut the first
//! Gauss-Newton step), each solved with cpm-lm's defaults and the box.
//!
//! Every case must end in the box at SciPy's best cost (trf and dogbox, tolerances 1e-15;
//! relative 1e-6, or below 1e-20 where the minimum is zero), and a solve that reports success
//! must be first-order optimal in the box by a measure computed here from the problem alone
//! (`common/bounded.rs`). `cargo test -p cpm-lm --test bounded -- --nocapture` prints the
//! table of the set.

#[path = "common/bounded.rs"]
mod bounded;
#[path = "common/mgh.rs"]
mod mgh;
#[path = "common/nist.rs"]
mod nist;

use bounded::{cases, first_order, Bounded, Case, FirstOrder};
use cpm_lm::{minimize, Options, Report};
use proptest::prelude::*;

/// A reported success must have this first-order measure or less (a cosine: MINPACK's
/// gradient test in the interior).
const OPTIMAL: f64 = 1e-4;

fn options(case: &Case) -> Options {
    Options {
        lower: Some(case.lower.clone()),
        upper: Some(case.upper.clone()),
        ..Options::default()
    }
}

fn solved(cost: f64, reference: f64) -> bool {
    cost <= reference * (1.0 + 1e-6) || cost <= 1e-20
}

fn in_box(x: &[f64], lower: &[f64], upper: &[f64]) -> bool {
    x.iter()
        .zip(lower.iter().zip(upper))
        .all(|(v, (lo, up))| v >= lo && v <= up)
}

struct Row {
    case: Case,
    report: Report,
    x: Vec<f64>,
    at: FirstOrder,
}

fn run(case: &Case) -> Row {
    let mut problem = Bounded::new(&case.problem);
    let mut x = case.x0.clone();
    let report = minimize(&mut problem, &mut x, &options(case)).unwrap();
    let at = first_order(&mut problem, &x, &case.lower, &case.upper);
    if std::env::var("CPM_LM_CASE").is_ok_and(|v| v == case.name) {
        println!("{}: x = {x:?}\n{report:#}", case.name);
    }
    Row {
        case: case.clone(),
        report,
        x,
        at,
    }
}

fn table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| case | cut | SciPy best cost | SciPy evaluations (trf / trf-jac / dogbox) | cpm cost | \
         projected gradient | measure | evaluations | time | success |\n\
         | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n",
    );
    for r in rows {
        let c = &r.case;
        let mark = if solved(r.report.final_cost, c.reference_cost) {
            ""
        } else {
            " **(not solved)**"
        };
        s += &format!(
            "| {} | {} | {:.10e} | {} / {} / {} | {:.10e}{} | {:.2e} | {:.1e} | {} | {:.0?} | {} |\n",
            c.name,
            if c.cuts_gn { "cut" } else { "" },
            c.reference_cost,
            c.scipy[0].2,
            c.scipy[1].2,
            c.scipy[2].2,
            r.report.final_cost,
            mark,
            r.at.projected_gradient,
            r.at.measure,
            r.report.residual_evaluations,
            r.report.elapsed,
            r.report.was_successful(),
        );
    }
    s
}

#[test]
fn the_set_is_solved_to_scipys_cost_without_false_success() {
    let cases = cases();
    assert!(cases.len() >= 36, "{} cases", cases.len());
    let rows: Vec<Row> = cases.iter().map(run).collect();
    println!("{}", table(&rows));
    let mut unsolved = Vec::new();
    let mut false_success = Vec::new();
    for r in &rows {
        let c = &r.case;
        assert!(in_box(&r.x, &c.lower, &c.upper), "{}: {:?}", c.name, r.x);
        assert!(
            (r.at.cost - r.report.final_cost).abs() <= 1e-12 * r.at.cost.max(1e-300),
            "{}: the report's cost {} is not the cost at x, {}",
            c.name,
            r.report.final_cost,
            r.at.cost
        );
        let ok = solved(r.report.final_cost, c.reference_cost);
        if !ok {
            unsolved.push(c.name.as_str());
        }
        if r.report.was_successful() && !(ok && r.at.measure <= OPTIMAL) {
            false_success.push(c.name.as_str());
        }
    }
    assert!(
        false_success.is_empty(),
        "false successes: {false_success:?}"
    );
    assert!(unsolved.is_empty(), "not solved: {unsolved:?}");
}

#[test]
fn the_report_carries_the_box_optimality_and_a_stall_is_no_success() {
    // Rosenbrock in x0 <= 0.5 (the second box): the report's optimality agrees
    // with the one computed here, and x0 is on its upper bound.
    let case = cases()
        .into_iter()
        .find(|c| c.name == "rosenbrock-x0-le-0.5")
        .expect("in the set");
    let row = run(&case);
    let o = row.report.optimality.as_ref().expect("bounded");
    assert!(o.optimal && row.report.was_successful(), "{:#}", row.report);
    assert_eq!(o.active, vec![1, 0]);
    assert!((o.projected_gradient - row.at.projected_gradient).abs() < 1e-12);
    assert!(row.report.is_solution_usable());
    // An evaluation budget that ends the solve early: not a success, but usable.
    let mut problem = Bounded::new(&case.problem);
    let mut x = case.x0.clone();
    let short = Options {
        max_evaluations: 4,
        ..options(&case)
    };
    let report = minimize(&mut problem, &mut x, &short).unwrap();
    assert!(!report.was_successful() && report.is_solution_usable());
    assert!(report.final_cost < report.initial_cost);
    let o = report.optimality.as_ref().expect("bounded");
    assert!(!o.optimal && o.measure > 1e-3, "{o:?}");
    // A loose gtol holds at the start (the cosines there are 0.91 and 0.89), far from the
    // minimum: a stall, not a success.
    let mut x = case.x0.clone();
    let loose = Options {
        gtol: 0.95,
        ..options(&case)
    };
    let report = minimize(&mut problem, &mut x, &loose).unwrap();
    let at = first_order(&mut problem, &x, &case.lower, &case.upper);
    assert!(at.measure > OPTIMAL, "{at:?}");
    assert_eq!(
        report.termination,
        cpm_lm::TerminationReason::Stalled,
        "{report:#}"
    );
    assert!(!report.was_successful() && report.is_solution_usable());
    // Unbounded solves report no box optimality.
    let mut x = case.x0.clone();
    let report = minimize(&mut problem, &mut x, &Options::default()).unwrap();
    assert!(report.optimality.is_none());
}

/// The problems of the property test: smooth on the whole of [-4, 4]^n.
fn smooth_problem(k: usize) -> (&'static str, usize) {
    [
        ("mgh:Rosenbrock:2:2", 2),
        ("mgh:PowellSingular:4:4", 4),
        ("mgh:FreudensteinRoth:2:2", 2),
        ("mgh:Box3d:3:10", 3),
        ("mgh:JennrichSampson:2:10", 2),
        ("mgh:BrownDennis:4:20", 4),
    ][k]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// In a random box from a random start: the answer is in the box, the cost did not
    /// rise, and a success is first-order optimal by the measure computed here.
    #[test]
    fn answers_stay_in_the_box_and_no_success_is_false(
        k in 0usize..6,
        lo in prop::collection::vec(-4.0f64..2.0, 4),
        width in prop::collection::vec(0.05f64..4.0, 4),
        at in prop::collection::vec(0.0f64..=1.0, 4),
        pin in prop::collection::vec(0usize..4, 4),
    ) {
        let (spec, n) = smooth_problem(k);
        let lower: Vec<f64> = lo[..n].to_vec();
        let upper: Vec<f64> = (0..n).map(|j| (lo[j] + width[j]).min(4.0)).collect();
        // A start in the box, some coordinates exactly on a bound.
        let x0: Vec<f64> = (0..n)
            .map(|j| match pin[j] {
                0 => lower[j],
                1 => upper[j],
                _ => lower[j] + at[j] * (upper[j] - lower[j]),
            })
            .collect();
        let mut problem = Bounded::new(spec);
        let mut x = x0.clone();
        let o = Options {
            lower: Some(lower.clone()),
            upper: Some(upper.clone()),
            ..Options::default()
        };
        let report = minimize(&mut problem, &mut x, &o).unwrap();
        prop_assert!(in_box(&x, &lower, &upper), "{x:?} not in {lower:?}..{upper:?}");
        prop_assert!(report.final_cost <= report.initial_cost);
        let first = first_order(&mut problem, &x, &lower, &upper);
        let opt = report.optimality.as_ref().expect("bounded");
        if report.was_successful() {
            prop_assert!(first.measure <= OPTIMAL, "{spec} {x0:?} -> {x:?}: {first:?}\n{report:#}");
        }
        if !opt.optimal {
            prop_assert!(!report.was_successful(), "{report:#}");
        }
    }
}
