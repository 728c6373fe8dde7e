"""simulate, design, refine, validate, compensate, identifiability, export: the commands'
outputs, through their options by name."""
import subprocess

import numpy as np
import pytest

import cpm

HEX = "examples/hexapod_66.toml"
TRUTH = "examples/hexapod_66_truth.toml"
CUBE = "examples/paper_cubic.toml"


def test_simulate_is_labelled_and_follows_its_options(in_root, tmp_path):
    a = cpm.simulate(HEX, random=10, truth=TRUTH, noise="gaussian:1", seed=4)
    b = cpm.simulate(HEX, random=10, truth=TRUTH, noise="gaussian:1", seed=4)
    c = cpm.simulate(HEX, random=10, truth=TRUTH, noise="gaussian:1", seed=5)
    assert a.simulated and a.num_poses == 10
    np.testing.assert_array_equal(a.lengths_mm, b.lengths_mm)
    assert not np.array_equal(a.lengths_mm, c.lengths_mm)
    f = tmp_path / "d.csv"
    cpm.simulate(HEX, random=10, truth=TRUTH, noise="gaussian:1", seed=4, out=f)
    assert f.read_text().startswith("# simulated by cpm")
    # A plan as an array: the poses come back as given.
    poses = a.poses[:3]
    p = cpm.simulate(HEX, plan=poses, truth=TRUTH, noise="none")
    np.testing.assert_allclose(p.poses, poses, atol=1e-9)
    # truth_effect as a dict.
    d = cpm.simulate(HEX, plan=poses, truth=TRUTH, noise="none",
                     truth_effect={"link_offset": [5, 0, 0, 0, 0, 0]})
    assert not np.array_equal(d.lengths_mm, p.lengths_mm)
    with pytest.raises(cpm.UsageError, match="--noise"):
        cpm.simulate(HEX, random=3, noise="pink:3")


def test_design_then_identify(in_root, tmp_path):
    d = cpm.design(HEX, readings=120, out=tmp_path / "design")
    assert d.doc and (tmp_path / "design" / "robot.toml").exists()
    r = d.robot
    assert len(r.sensor_names) >= 1 and d.poses.shape[1] == 6 and len(d.poses) >= 1
    assert "<svg" in d.html or "<table>" in d.html
    ident = cpm.identifiability(r, plan=d.poses)
    assert ident["parameters"] == 36
    mem = cpm.design(HEX, readings=120)
    assert mem.directory is None and mem.robot.sensor_names == r.sensor_names


def test_identifiability_of_the_paper_circle(in_root):
    j = cpm.identifiability(CUBE, circle=True)
    assert j["rank"] < j["parameters"] == 36
    assert j["blind_directions"]


def test_refine_finds_the_missing_backlash(in_root, tmp_path):
    data = cpm.simulate(HEX, random=60, truth=TRUTH,
                        truth_effect=["backlash=-8,6,-10,5,-7,9"], noise="gaussian:0.5",
                        seed=1)
    r = cpm.refine(HEX, data, candidates=["backlash", "link_offset"], max_steps=2)
    effects = [s["effect"] for s in r.steps]
    assert "backlash" in effects, r.doc
    assert "residuals_before_after.svg" in r.figures
    assert "backlash" in r.text("calibrated.toml")
    assert r.html.startswith("<!DOCTYPE html>")
    assert r.calibrated_robot.num_links == 6


def test_validate_on_held_out_data(in_root, tmp_path):
    fit = cpm.simulate(HEX, random=60, truth=TRUTH, noise="gaussian:0.5", seed=1)
    held = cpm.simulate(HEX, random=20, truth=TRUTH, noise="gaussian:0.5", seed=2)
    cal = cpm.calibrate(HEX, fit)
    v = cpm.validate(cal.calibrated_robot, HEX, held)
    assert v.calibrated_rms_um < 0.2 * v.reference_rms_um
    assert v.groups and "validation.svg" in v.figures
    assert "<svg" in v.html and v._repr_html_().startswith("<iframe")


def test_compensate_equals_the_command(in_root, tmp_path, cpm_bin):
    fit = cpm.simulate(HEX, random=60, truth=TRUTH, noise="gaussian:0.5", seed=1)
    cal = cpm.calibrate(HEX, fit, out=tmp_path / "cal")
    robot = tmp_path / "cal" / "calibrated.toml"
    c = cpm.compensate(robot, "examples/targets.csv", from_home=True)
    subprocess.run([str(cpm_bin), "compensate", "--robot", str(robot), "--poses",
                    "examples/targets.csv", "--from-home", "--out", str(tmp_path / "c.csv"),
                    "-q"], check=True)
    assert c.csv == (tmp_path / "c.csv").read_text()
    assert c.readings.shape == (len(c.targets), 6)
    # Targets as an array give the same commands.
    c2 = cpm.compensate(cal.calibrated_robot, c.targets, from_home=True)
    np.testing.assert_allclose(c2.readings, c.readings, rtol=0, atol=1e-9)
    with pytest.raises(cpm.UsageError, match=r"poses has shape"):
        cpm.compensate(robot, c.targets[:, :5])


def test_compensation_checked_on_the_simulated_truth(in_root, tmp_path):
    fit = cpm.simulate(HEX, random=60, truth=TRUTH, noise="gaussian:0.5", seed=1)
    cpm.calibrate(HEX, fit, out=tmp_path / "cal")
    c = cpm.compensate(tmp_path / "cal" / "calibrated.toml", "examples/targets.csv",
                       out=tmp_path / "commands.csv")
    v = cpm.validate(None, HEX, commands=tmp_path / "commands.csv", truth=TRUTH)
    assert v.summary["simulated"] is True
    assert v.summary["compensated"]["position_rms_um"] < \
        v.summary["reference"]["position_rms_um"]
    assert len(c.readings) == v.summary["targets"]


def test_export_linuxcnc(in_root):
    hal = cpm.export(HEX, format="linuxcnc")
    assert "setp genhexkins.base.0.x" in hal
    inch = cpm.export(HEX, format="linuxcnc", units="inch")
    assert inch != hal


def test_effect_names():
    names = cpm.effect_names()
    assert "link_offset" in names and "backlash" in names and len(names) == len(set(names))


def test_the_cpm_module_runs_the_command(in_root, tmp_path, capfd):
    """`cpm._main` (the `cpm` script of the wheel) is the command: same output and exit codes
    as the binary, no Rust toolchain."""
    from cpm import _cpm

    out = tmp_path / "commands.csv"
    code = _cpm.main(["cpm", "compensate", "--robot", HEX, "--poses", "examples/targets.csv",
                      "--out", str(out)])
    assert code == 0 and out.read_text().count("\n") > 5
    assert str(out) in capfd.readouterr().out
    assert _cpm.main(["cpm", "compensate", "--robot", HEX, "--nosuch"]) == 2
    assert _cpm.main(["cpm", "compensate", "--robot", "nosuch.toml", "--poses",
                      "examples/targets.csv"]) == 4
