"""The SIMULATED campaign of the Python benchmarks as arrays, one row per reading:
examples/hexapod_66.toml, ``poses`` random poses read by its 3 gauges (truth
examples/hexapod_66_truth.toml, gaussian noise 1 um, seed 7)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, List, Tuple

import numpy as np

import cpm

ROOT = Path(__file__).resolve().parents[2]


def campaign(poses: int) -> Tuple[Any, np.ndarray, List[str], np.ndarray, List[str]]:
    """The robot, then per reading: its commanded pose (x, y, z mm; roll, pitch, yaw deg),
    sensor name, length (mm) and pose label."""
    robot = cpm.Robot.from_toml(ROOT / "examples" / "hexapod_66.toml")
    sim = cpm.simulate(robot, random=poses, truth=str(ROOT / "examples" / "hexapod_66_truth.toml"),
                       noise="gaussian:1", seed=7)
    info = sim.sources[0].info
    k = np.asarray(info["reading_pose"], dtype=int)
    p = np.asarray(info["poses"])[k]
    sensors = list(info["reading_sensor"])
    lengths = np.asarray(info["lengths_mm"])
    labels = [info["pose_labels"][j] for j in k]
    return robot, p, sensors, lengths, labels
