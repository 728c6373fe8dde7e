//! A fit stops inside its least-squares iterations when its caller sets
//! [`IdentifyOptions::cancel`]: a user effect trips the flag after a number of evaluations
//! (well after the fit started), and `identify` and `refine` answer `CalibError::Cancelled`.
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use cpm_calib::effects::{Channel, EffectInput, EffectModel};
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;

/// The flag the tripwire sets, and how many link coefficients it was asked for.
static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
static CALLS: AtomicUsize = AtomicUsize::new(0);
static TRIP_AT: AtomicUsize = AtomicUsize::new(usize::MAX);

/// A link effect that does nothing but count its evaluations and set the flag at `TRIP_AT`.
#[derive(Debug)]
struct Tripwire;
impl EffectModel for Tripwire {
    fn name(&self) -> &str {
        "tripwire"
    }
    fn num_params(&self, _: usize, _: usize) -> usize {
        1
    }
    fn param_name(&self, _: usize, _: &[String]) -> String {
        "trip".into()
    }
    fn unit(&self) -> &str {
        "um"
    }
    fn channels(&self) -> &[Channel] {
        &[Channel::LinkLength]
    }
    fn link_coefficient(&self, _: usize, _: usize, _: &EffectInput) -> f64 {
        if CALLS.fetch_add(1, Ordering::SeqCst) + 1 == TRIP_AT.load(Ordering::SeqCst) {
            FLAG.get().expect("flag").store(true, Ordering::SeqCst);
        }
        0.0
    }
}

fn setup() -> (MeasurementModel, Campaign, Arc<AtomicBool>) {
    let flag = FLAG
        .get_or_init(|| Arc::new(AtomicBool::new(false)))
        .clone();
    let tripwire = Effect::user(&Tripwire).unwrap();
    let mut model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
    model.nominal.sensors = designed_sensors();
    let poses = random_workspace_poses(&model.nominal, 30, 100.0, 25.0, 3.0, 11);
    let skeleton = Plan {
        poses,
        sensors: (0..16).collect(),
    }
    .skeleton();
    let truth: Vec<f64> = (0..36).map(|k| 30.0 * (k as f64 * 0.7).sin()).collect();
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um: 1.0 },
        repeats: 1,
        seed: 3,
    };
    let data = simulate_campaign(&model, &truth, &skeleton, &sim).unwrap();
    model.effects = vec![tripwire];
    (model, data, flag)
}

// One test, in order: the counter and the flag are shared by the whole binary.
#[test]
fn a_fit_and_a_refinement_stop_inside_their_iterations_when_cancelled() {
    let (model, data, flag) = setup();
    let options = IdentifyOptions {
        sigma_um: Some(1.0),
        cancel: Some(flag.clone()),
        ..IdentifyOptions::default()
    };
    // Not tripped: the fit runs to its end; count what it evaluates.
    CALLS.store(0, Ordering::SeqCst);
    let full = identify(&model, &data, &options).unwrap();
    let whole = CALLS.load(Ordering::SeqCst);
    assert!(
        full.solver.iterations.len() >= 2,
        "{:?}",
        full.solver.termination
    );
    // Tripped half way through the same fit: cancelled, not a result.
    CALLS.store(0, Ordering::SeqCst);
    TRIP_AT.store(whole / 2, Ordering::SeqCst);
    let err = identify(&model, &data, &options)
        .map(|_| ())
        .expect_err("cancelled");
    assert!(matches!(err, CalibError::Cancelled), "{err}");
    let used = CALLS.load(Ordering::SeqCst);
    assert!(
        used >= whole / 2 && used < whole,
        "{used} of {whole} evaluations"
    );
    // Already set: refused before any work.
    CALLS.store(0, Ordering::SeqCst);
    let err = identify(&model, &data, &options)
        .map(|_| ())
        .expect_err("cancelled");
    assert!(matches!(err, CalibError::Cancelled), "{err}");
    assert_eq!(CALLS.load(Ordering::SeqCst), 0);
    // A refinement (whose candidate fits fail one by one when cancelled) says so too.
    flag.store(false, Ordering::SeqCst);
    CALLS.store(0, Ordering::SeqCst);
    TRIP_AT.store(whole + whole / 2, Ordering::SeqCst);
    let refine_options = RefineOptions {
        candidates: vec![Effect::LinkOffset, Effect::LinkScale],
        identify: options.clone(),
        ..RefineOptions::default()
    };
    let err = refine(&model, &data, &refine_options)
        .map(|_| ())
        .expect_err("cancelled");
    assert!(matches!(err, CalibError::Cancelled), "{err}");
}
