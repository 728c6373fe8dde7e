//! The SIMULATED campaign of the camera tests (cpm-calib's `tests/camera.rs` and
//! cpm-workflow's): a camera 1.5 m from the 500 mm-class machine (`JointTable::paper_cubic`),
//! 0.1 px noise, random installation errors as the truth.
use std::sync::Arc;

use cpm_calib::instruments::simulate_instruments;
use cpm_calib::paper::random_workspace_poses;
use cpm_calib::*;
use cpm_geometry::JointTable;
use nalgebra::Vector3;

use super::instrument::Camera;

/// The camera's noise, px.
pub const NOISE_PX: f64 = 0.1;

/// The camera 1.5 m from the marker at home, above and to the side, focal length 8000 px
/// (about 0.19 mm per pixel at that distance); the marker 60 mm off the platform's centre.
pub fn camera(table: &JointTable) -> Camera {
    let marker = Vector3::new(60.0, -40.0, 20.0);
    let at_home = table.home.position_mm + table.home.rotation * marker;
    let centre = at_home + Vector3::new(0.6, -0.55, 0.58).normalize() * 1500.0;
    Camera::looking_at(centre, table.home.position_mm, 8000.0, marker)
}

/// Uniform values in [-a, a], seeded (splitmix64): the random truth of a simulation.
fn uniform(n: usize, a: f64, seed: u64) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^= z >> 31;
            a * (2.0 * (z >> 11) as f64 / (1u64 << 53) as f64 - 1.0)
        })
        .collect()
}

/// A SIMULATED campaign on `model`'s machine with the camera added: `poses` poses, the
/// camera's measurement of the marker at each (0.1 px), and when `gauges` the readings of
/// every sensor of `model` (1 um); `seed` draws other poses and noise (the same truth). The truth: installation errors uniform in +-100 um, the camera 2 mm and
/// 1 mrad off its nominal pose, 15 px off in focal length. Returns the model with the camera,
/// the campaign and the truth.
pub fn campaign(
    mut model: MeasurementModel,
    gauges: bool,
    poses: usize,
    seed: u64,
) -> (MeasurementModel, Campaign, Vec<f64>) {
    model.instruments = vec![Arc::new(camera(&model.nominal))];
    let poses = random_workspace_poses(&model.nominal, poses, 80.0, 8.0, 3.0, 17 + seed);
    let sensors = if gauges {
        (0..model.nominal.sensors.len()).collect()
    } else {
        Vec::new()
    };
    let mut skeleton = Plan { poses, sensors }.skeleton();
    for pose in 0..skeleton.poses.len() {
        skeleton
            .instrument_measurements
            .push(InstrumentMeasurement {
                pose,
                instrument: 0,
                channel: 0,
                session: 0,
                values: vec![0.0; 2],
                sigma: NOISE_PX,
            });
    }
    let camera_truth = [2000.0, -1500.0, 800.0, 1000.0, -600.0, 400.0, 15.0];
    let truth = [uniform(36, 100.0, 59), camera_truth.to_vec()].concat();
    let sim = SimulationOptions {
        noise: Noise::Gaussian { sigma_um: 1.0 },
        repeats: 1,
        seed: 6 + seed,
    };
    let data = simulate_instruments(&model, &truth, &skeleton, &sim).unwrap();
    assert!(data.simulated);
    (model, data, truth)
}
