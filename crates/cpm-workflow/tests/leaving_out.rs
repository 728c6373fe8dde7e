//! The fit-level retry `fit::leaving_out` (issue 33): a fit that cannot start at one pose
//! (forward kinematics of its commanded link lengths does not converge) leaves that pose out
//! with all its observations, records it (file, line, label, why) and returns the fit of the
//! rest, the very fit of the campaign without that pose; a second pose within the budget of
//! one in 20 is left out too, one more is refused naming its file and line, and an error that
//! names no pose is returned at once.
use std::path::Path;

use cpm_workflow::calib::paper::random_workspace_poses;
use cpm_workflow::calib::{
    identify, simulate, CalibError, IdentifyOptions, Plan, SimulationOptions,
};
use cpm_workflow::fit::{leaving_out, Inputs};
use cpm_workflow::ingest::read_data;
use cpm_workflow::io::{merge, write_readings, Provenance, ReadOptions, Robot};
use cpm_workflow::kinematics::KinematicsError;
use cpm_workflow::Collect;

const FILE: &str = "log.csv";

/// The example hexapod and `poses` simulated poses of it (every sensor at each), read as the
/// file `log.csv`, as the fit's inputs.
fn inputs(poses: usize) -> Inputs {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let robot = Robot::load(&examples.join("hexapod_66.toml")).expect("example robot");
    let plan = Plan {
        poses: random_workspace_poses(&robot.table, poses, 30.0, 5.0, 3.0, 11),
        sensors: (0..robot.table.sensors.len()).collect(),
    };
    let truth = vec![0.0; robot.model(&[]).num_params()];
    let data = simulate(
        &robot.model(&[]),
        &truth,
        &plan,
        &SimulationOptions::default(),
    )
    .expect("simulate");
    let text = write_readings(&data, &robot, "test");
    let file = read_data(
        &text,
        FILE,
        &robot,
        &ReadOptions::default(),
        &Default::default(),
    )
    .expect("read");
    assert_eq!(file.campaign.poses.len(), poses);
    let mut merged = merge(vec![file], &robot);
    // The commands the controller sent (its inverse kinematics of each pose), as a log of
    // link readings would carry them.
    robot.model(&[]).log_commands(&mut merged.campaign);
    assert!(merged.campaign.commanded_lengths_mm.is_some());
    Inputs {
        model: robot.model(&[]),
        provenance: Provenance {
            robot: robot.file.clone(),
            data: vec![FILE.to_string()],
        },
        robot,
        merged: merged.into(),
        identify: IdentifyOptions::default(),
        data_paths: Vec::new(),
    }
}

/// The campaign index of the pose labelled `label` in `merged` (`None` once left out).
fn index_of(merged: &cpm_workflow::io::Merged, label: &str) -> Option<usize> {
    merged.pose_origin.iter().position(|o| o.2 == label)
}

/// Forward kinematics failing at pose `pose` (what the model reports there).
fn fk_failure(pose: usize) -> CalibError {
    CalibError::Kinematics {
        pose,
        source: KinematicsError::NonConvergence {
            iterations: 50,
            residual_mm: 777.0,
            condition: 5e3,
        },
    }
}

#[test]
fn a_pose_where_the_fit_cannot_start_is_left_out_and_the_fit_of_the_rest_returned() {
    let mut inputs = inputs(40);
    let k = index_of(&inputs.merged, "17").expect("pose 17");
    let line = inputs.merged.pose_origin[k].1;
    // Pose 17's first link commanded 1000 mm longer: no pose has those lengths, so the model
    // cannot predict there and the fit cannot start.
    std::sync::Arc::make_mut(&mut inputs.merged)
        .campaign
        .commanded_lengths_mm
        .as_mut()
        .unwrap()[k][0] += 1000.0;
    let options = inputs.identify.clone();
    let err = identify(&inputs.model, &inputs.merged.campaign, &options)
        .expect_err("the whole campaign cannot be fitted");
    assert_eq!(cpm_workflow::load::error_pose(&err), Some(k), "{err}");

    let mut calls = 0;
    let (cal, excluded) = leaving_out(&inputs, |merged| {
        calls += 1;
        identify(&inputs.model, &merged.campaign, &options)
    })
    .expect("one pose in 40 is left out");
    assert_eq!(calls, 2, "one failure, one retry");
    assert_eq!(excluded.len(), 1);
    let (at, e) = &excluded[0];
    assert_eq!(*at, k);
    assert_eq!(
        (e.file.as_str(), e.line, e.label.as_str()),
        (FILE, line, "17")
    );
    assert!(
        e.reason
            .starts_with("the fit cannot start there: forward kinematics did not converge"),
        "{}",
        e.reason
    );
    // The warning the commands give.
    let progress = Collect::default();
    cpm_workflow::load::warn_excluded(&progress, std::slice::from_ref(e));
    let notes = progress.notes.lock().unwrap().clone();
    assert_eq!(
        notes,
        [format!(
            "warning: {FILE}:{line}: pose \"17\" excluded: {}",
            e.reason
        )]
    );
    // The result is the fit of the campaign without pose 17, number for number, and the
    // inputs without it record why.
    let without = inputs.without_poses(&excluded);
    assert_eq!(without.merged.campaign.poses.len(), 39);
    assert_eq!(index_of(&without.merged, "17"), None);
    assert_eq!(without.merged.excluded, std::slice::from_ref(e));
    let reference = identify(&inputs.model, &without.merged.campaign, &options).expect("fit");
    assert_eq!(cal.estimate_um, reference.estimate_um);
    assert_eq!(cal.std_um, reference.std_um);
    assert_eq!(cal.minimum_norm_um, reference.minimum_norm_um);
    assert_eq!(cal.residual_rms_um, reference.residual_rms_um);
    assert_eq!(cal.residuals_um, reference.residuals_um);
}

#[test]
fn two_poses_in_forty_are_left_out_a_third_is_refused_naming_its_line() {
    let inputs = inputs(40);
    // Fails at each of `bad` still in the campaign, in order; else the number of poses.
    let run = |bad: &[&str]| {
        let mut calls = 0;
        let r = leaving_out(&inputs, |merged| {
            calls += 1;
            match bad.iter().find_map(|l| index_of(merged, l)) {
                Some(j) => Err(fk_failure(j)),
                None => Ok(merged.campaign.poses.len()),
            }
        });
        (r, calls)
    };
    let (r, calls) = run(&["17", "5"]);
    let (n, excluded) = r.expect("two poses in 40 are left out");
    assert_eq!((n, calls), (38, 3));
    let labels: Vec<&str> = excluded.iter().map(|(_, e)| e.label.as_str()).collect();
    assert_eq!(labels, ["17", "5"]);
    // Each with its index in the campaign as it was then: 5 comes before 17.
    let (k17, k5) = (
        index_of(&inputs.merged, "17").unwrap(),
        index_of(&inputs.merged, "5").unwrap(),
    );
    assert!(k5 < k17);
    assert_eq!((excluded[0].0, excluded[1].0), (k17, k5));
    assert_eq!(
        inputs.without_poses(&excluded).merged.campaign.poses.len(),
        38
    );

    // A third pose is one more than one in 20: refused, naming the third pose's file and
    // line, after the two retries.
    let (r, calls) = run(&["17", "5", "30"]);
    let err = r.expect_err("a third pose is refused");
    let line = inputs.merged.pose_origin[index_of(&inputs.merged, "30").unwrap()].1;
    let text = format!("{err:#}");
    assert!(
        text.starts_with(&format!("{FILE}:{line}: pose \"30\"")),
        "{text}"
    );
    assert!(
        text.contains("forward kinematics did not converge"),
        "{text}"
    );
    assert_eq!(calls, 3);
}

#[test]
fn fewer_than_twenty_poses_lose_none_and_an_error_at_no_pose_is_returned_at_once() {
    let small = inputs(19);
    let mut calls = 0;
    let err = leaving_out(&small, |merged| {
        calls += 1;
        Err::<(), _>(fk_failure(index_of(merged, "3").unwrap()))
    })
    .expect_err("19 poses may lose none");
    assert_eq!(calls, 1);
    let line = small.merged.pose_origin[index_of(&small.merged, "3").unwrap()].1;
    assert!(
        format!("{err:#}").starts_with(&format!("{FILE}:{line}: pose \"3\"")),
        "{err:#}"
    );

    let inputs = inputs(40);
    let mut calls = 0;
    let err = leaving_out(&inputs, |_| {
        calls += 1;
        Err::<(), _>(CalibError::NoInformation("nothing to fit".into()))
    })
    .expect_err("no pose to leave out");
    assert_eq!(calls, 1);
    assert!(format!("{err:#}").contains("nothing to fit"), "{err:#}");
}
