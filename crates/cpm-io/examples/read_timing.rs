//! Wall time of reading a length-sensor readings file alone (issue 18: 10^6 rows in under a
//! second). Writes a simulated campaign of the paper's cube with its 16 designed sensors
//! (`POSES` x 16 rows, default 62,500 poses: 10^6 rows) to a file once, then reads it back
//! from the file with [`cpm_io::read_data_file`] `REPEATS` times (default 3) and prints each
//! wall time.
//!
//! `cargo run --release -p cpm-io --example read_timing -- [POSES] [REPEATS]`
use std::time::Instant;

use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::{simulate, Plan, SimulationOptions};
use cpm_geometry::{InstallationErrors, RobotDescription};
use cpm_io::{read_data_file, write_readings, ReadOptions, Robot};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let poses: usize = args.next().map_or(Ok(62_500), |a| a.parse())?;
    let repeats: usize = args.next().map_or(Ok(3), |a| a.parse())?;
    let mut robot = Robot::from_description(RobotDescription::paper_cubic(), "cube.toml")?;
    robot.table.sensors = designed_sensors();
    let path = std::env::temp_dir().join(format!("cpm-io-read-timing-{poses}.csv"));
    if !path.exists() {
        let plan = Plan {
            poses: random_workspace_poses(&robot.table, poses, 100.0, 25.0, 3.0, 1),
            sensors: (0..16).collect(),
        };
        let truth = InstallationErrors::paper_table2().to_vec_um();
        let data = simulate(
            &robot.model(&[]),
            &truth,
            &plan,
            &SimulationOptions::default(),
        )?;
        std::fs::write(&path, write_readings(&data, &robot, "read_timing"))?;
    }
    let bytes = std::fs::metadata(&path)?.len();
    for _ in 0..repeats {
        let start = Instant::now();
        let d = read_data_file(&path, &robot, &ReadOptions::default())?;
        let s = start.elapsed().as_secs_f64();
        println!(
            "read {} rows ({} poses, {:.1} MB, simulated) from {}: {s:.3} s",
            d.campaign.readings.len(),
            d.campaign.poses.len(),
            bytes as f64 / 1e6,
            path.display()
        );
    }
    Ok(())
}
