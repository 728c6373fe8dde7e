# %% [markdown]
# # Calibrating a 6-6 hexapod from Python (simulated data)
#
# The calibration story of the README ("The cpm command") in Python, cell by cell (`# %%`
# cells: open it in Jupyter with jupytext, or in VS Code, or run it as a script:
# `python examples/python/calibrate.py [OUT_DIR]`). Every measurement here is SIMULATED, and
# every result says so. The Python functions are the commands: `cpm.design` is `cpm design`,
# `cpm.calibrate` is `cpm calibrate`, and so on, with the same options by name.

# %%
import sys
import tempfile
from pathlib import Path

import numpy as np

import cpm

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="cpm-example-"))
OUT.mkdir(parents=True, exist_ok=True)
print("outputs in", OUT)

# %% [markdown]
# ## What a design can identify, before measuring
# The paper's design (one length sensor read on a circle) cannot see all 36 installation
# errors: the analysis says which directions are blind, in words.

# %%
paper = cpm.identifiability(EXAMPLES / "paper_cubic.toml", circle=True)
print(f"the paper's circle: rank {paper['rank']} of {paper['parameters']}")
for b in paper["blind_directions"][:3]:
    print("  blind:", b)

# %% [markdown]
# ## Design a campaign: sockets and poses for 360 readings on the 6-6 hexapod

# %%
design = cpm.design(EXAMPLES / "hexapod_66.toml", readings=360, out=OUT / "design")
robot = design.robot  # the description with the chosen sensors
print("sensors:", robot.sensor_names, "| poses:", design.poses.shape)

# %% [markdown]
# ## Simulate the campaign (SIMULATED) of a machine with installation errors and an
# undeclared backlash; a second campaign is held out for validation

# %%
truth = EXAMPLES / "hexapod_66_truth.toml"
backlash = {"backlash": [-8, 6, -10, 5, -7, 9]}
data = cpm.simulate(robot, plan=design.directory / "poses.csv", truth=truth,
                    truth_effect=backlash, noise="gaussian:1", seed=1, out=OUT / "data.csv")
held_out = cpm.simulate(robot, random=40, truth=truth, truth_effect=backlash,
                        noise="gaussian:1", seed=2, out=OUT / "held_out.csv")
print(data)
assert data.simulated and held_out.simulated

# %% [markdown]
# ## Fit: estimates, standard deviations, what the data identify

# %%
cal = cpm.calibrate(robot, data, out=OUT / "cal")
print(cal)
print(cal.identifiability)
df = np.column_stack([cal.estimates_um[:6], cal.std_um[:6]])
print("first six installation errors (um, +- std):\n", np.round(df, 2))
for w in cal.warnings:
    print("warning:", w)
cal  # in Jupyter: the report.html of `cpm calibrate`, figures inline

# %% [markdown]
# ## Let the residual ask for more effects (here: the backlash the model lacked)

# %%
refined = cpm.refine(robot, data, out=OUT / "refined")
print("effects added:", [s["effect"] for s in refined.steps])
refined

# %% [markdown]
# ## Check on the held-out campaign, against the nominal robot

# %%
validation = cpm.validate(refined.calibrated_robot, robot, held_out, out=OUT / "validation")
print(validation)
assert validation.calibrated_rms_um < validation.reference_rms_um

# %% [markdown]
# ## Corrected actuator commands for target poses, and the joints for LinuxCNC

# %%
commands = cpm.compensate(OUT / "refined" / "calibrated.toml", EXAMPLES / "targets.csv",
                          from_home=True, out=OUT / "commands.csv")
print(commands, commands.readings[:2])
hal = cpm.export(OUT / "refined" / "calibrated.toml", format="linuxcnc",
                 ini=OUT / "joints.ini")
print(next(line for line in hal.splitlines() if line.startswith("setp")))
