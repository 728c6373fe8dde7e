//! Robust fits never hide failure: a robust loss starts from the least-squares (and, when it
//! redescends, the Huber) solution, reports the share of observations it down-weighted, and a
//! fit that ignores most of the data is failed. Refine adds an effect only when the
//! cross-validated error improves, and flags outliers before choosing effects.
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};
use cpm_lm::Loss;

const SIGMA: f64 = 0.5;

fn model() -> MeasurementModel {
    let mut m = MeasurementModel::new(JointTable::paper_cubic());
    m.nominal.sensors = designed_sensors();
    m
}

fn campaign(poses: usize, sigma_um: f64, seed: u64) -> Campaign {
    let m = model();
    let plan = Plan {
        poses: random_workspace_poses(&m.nominal, poses, 100.0, 25.0, 3.0, 31),
        sensors: (0..m.nominal.sensors.len()).collect(),
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um },
        repeats: 1,
        seed,
    };
    simulate_campaign(&m, &truth, &plan.skeleton(), &sim).unwrap()
}

fn fit(c: &Campaign, loss: Loss) -> Calibration {
    let mut o = IdentifyOptions::default();
    o.lm.loss = loss;
    identify(&model(), c, &o).unwrap()
}

/// Least squares that keeps its gross outliers (no setting aside).
fn fit_keeping(c: &Campaign) -> Calibration {
    let o = IdentifyOptions {
        keep_outliers: true,
        ..IdentifyOptions::default()
    };
    identify(&model(), c, &o).unwrap()
}

fn worst_error_um(cal: &Calibration) -> f64 {
    let truth = InstallationErrors::paper_table2().to_vec_um();
    cal.minimum_norm_um
        .iter()
        .zip(&truth)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

#[test]
fn robust_losses_on_clean_data_agree_with_least_squares() {
    let c = campaign(40, SIGMA, 3);
    let ls = fit(&c, Loss::Squared);
    assert_eq!(ls.downweighted_share, 0.0);
    assert!(!ls.robust_failed);
    for loss in [
        Loss::Huber(3.0 * SIGMA),
        Loss::Cauchy(3.0 * SIGMA),
        Loss::Tukey(3.0 * SIGMA),
    ] {
        let r = fit(&c, loss);
        assert!(r.succeeded(), "{loss:?}: {:?}", r.robust_failure());
        assert!(
            r.downweighted_share < 0.2,
            "{loss:?}: {} down-weighted",
            r.downweighted_share
        );
        assert!(
            r.residual_rms_um < 1.05 * ls.residual_rms_um,
            "{loss:?}: residual {} um against {} um for least squares",
            r.residual_rms_um,
            ls.residual_rms_um
        );
        let gap = r
            .minimum_norm_um
            .iter()
            .zip(&ls.minimum_norm_um)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(gap < 1.0, "{loss:?}: {gap} um from least squares");
    }
}

#[test]
fn a_robust_fit_that_ignores_most_of_the_data_is_failed() {
    let c = campaign(40, SIGMA, 4);
    // K a tenth of the noise: nearly every residual is beyond it.
    for loss in [Loss::Tukey(0.05), Loss::Cauchy(0.05), Loss::Huber(0.02)] {
        let r = fit(&c, loss);
        assert!(
            r.downweighted_share > MAX_DOWNWEIGHTED_SHARE,
            "{loss:?}: {}",
            r.downweighted_share
        );
        assert!(r.robust_failed, "{loss:?}");
        assert!(!r.succeeded());
        let why = r.robust_failure().unwrap();
        assert!(why.contains("down-weighted"), "{why}");
    }
}

#[test]
fn a_robust_fit_follows_the_data_not_the_spikes() {
    let mut c = campaign(40, SIGMA, 5);
    for k in [7, 40, 93] {
        c.readings[k].length_mm += 2.0; // 2 mm spikes
    }
    let ls = fit_keeping(&c);
    let aside = fit(&c, Loss::Squared);
    let tukey = fit(&c, Loss::Tukey(3.0 * SIGMA));
    assert!(tukey.succeeded(), "{:?}", tukey.robust_failure());
    // Least squares by default sets the three spikes aside, and is then as good as Tukey's.
    assert_eq!(aside.set_aside, vec![7, 40, 93]);
    let e_aside = worst_error_um(&aside);
    // Gaussian noise alone puts ~10 % beyond Tukey's half-weight point (1.6 sigma at K = 3 sigma).
    assert!(
        tukey.downweighted_share < 0.2,
        "{} down-weighted",
        tukey.downweighted_share
    );
    for k in [7, 40, 93] {
        assert!(tukey.outliers.contains(&k), "{k} not flagged");
    }
    let (e_ls, e_t) = (worst_error_um(&ls), worst_error_um(&tukey));
    assert!(
        e_t < 5.0 && e_t < 0.2 * e_ls && e_aside < 5.0 && e_aside < 0.2 * e_ls,
        "Tukey {e_t} um, set aside {e_aside} um, LS keeping them {e_ls} um"
    );
}

#[test]
fn refine_adds_nothing_for_a_spike_and_flags_it() {
    let mut c = campaign(50, 2.0, 6);
    let spike = 61;
    c.readings[spike].length_mm += 5.0; // one 5 mm spike
    let options = RefineOptions {
        identify: IdentifyOptions {
            sigma_um: Some(2.0),
            ..IdentifyOptions::default()
        },
        ..RefineOptions::default()
    };
    let r = refine(&model(), &c, &options).unwrap();
    assert!(
        r.outliers_before.contains(&spike),
        "{:?}",
        r.outliers_before
    );
    println!("rejected by cross-validation: {:?}", r.rejected_by_cv);
    let added: Vec<Effect> = r.steps.iter().map(|s| s.effect).collect();
    assert!(added.is_empty(), "added {added:?}");
    for s in &r.steps {
        assert!(s.cv_rms_after_um < s.cv_rms_before_um);
    }
    for (e, before, after, _) in &r.rejected_by_cv {
        assert!(after >= before, "{e} rejected though CV improved");
    }
}
