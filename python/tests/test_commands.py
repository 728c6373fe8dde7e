"""simulate, design, refine, validate, compensate, identifiability, export: the commands'
outputs, through their options by name."""
import subprocess

import numpy as np
import pytest

import cpm
from conftest import HEXAPOD, HEXAPOD_READINGS, no_temp_folder

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
    with pytest.raises(cpm.UsageError, match="^noise "):
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
    # What the commands promise (issue 63 item 4): the calibration's covariance turned into
    # each target's band; the nominal robot promises nothing.
    promise = c.predicted_error
    assert promise is not None and len(promise["targets"]) == len(c.targets)
    worst = promise["worst_target"]["ap_p_um"]
    assert worst == max(t["position_95_um"] for t in promise["targets"]) > 0
    assert cpm.compensate(HEX, c.targets).predicted_error is None


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


def _pose_csv(path, poses):
    """A pose list file of ``poses`` (labelled from 1, numbers exact)."""
    lines = ["pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg"]
    lines += [",".join([str(k + 1)] + [repr(float(v)) for v in row])
              for k, row in enumerate(poses)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_pose_arrays_go_to_the_jobs_in_memory(in_root, tmp_path, monkeypatch):
    """Issue 36: a plan (simulate, identifiability) and compensate's targets given as arrays
    reach the job in memory (no scratch file is written) and give what their file gives."""

    poses = cpm.simulate(HEX, random=8, truth=TRUTH, noise="none", seed=2).poses
    f = _pose_csv(tmp_path / "plan.csv", poses)
    text_robot = cpm.Robot.from_text(open(HEX).read(), "hexapod from text")
    on_file = (cpm.simulate(HEX, plan=f, truth=TRUTH, noise="gaussian:1", seed=3),
               cpm.identifiability(HEX, plan=f),
               cpm.compensate(TRUTH, f, from_home=True))

    with monkeypatch.context() as mp:
        no_temp_folder(mp)
        s = cpm.simulate(text_robot, plan=poses, truth=TRUTH, noise="gaussian:1", seed=3)
        i = cpm.identifiability(text_robot, plan=poses)
        c = cpm.compensate(TRUTH, poses, from_home=True)
        c_robot = cpm.compensate(cpm.Robot.from_toml(TRUTH), poses, from_home=True)
    np.testing.assert_array_equal(s.lengths_mm, on_file[0].lengths_mm)
    np.testing.assert_array_equal(s.poses, on_file[0].poses)
    assert i == on_file[1]
    assert c.csv == on_file[2].csv.replace(str(f), "poses")
    assert c_robot.csv == c.csv
    np.testing.assert_array_equal(c.readings, on_file[2].readings)


def test_a_job_without_out_makes_no_folder(tmp_path, monkeypatch):
    """Issue 59: a job without ``out`` makes nothing anywhere, not even an empty staging
    folder (the binding once made one in the temporary directory and removed it): with the
    temporary directory gone, calibrate, refine, validate and design still run, and the
    calibrated robot records where it came from, absolute."""
    gone = tmp_path / "gone"
    monkeypatch.setenv("TMPDIR", str(gone))
    cal = cpm.calibrate(HEXAPOD, HEXAPOD_READINGS)
    assert f'calibrated_from = "{HEXAPOD.resolve()}"' in cal.text("calibrated.toml")
    r = cpm.refine(HEXAPOD, HEXAPOD_READINGS, max_steps=1)
    assert "calibrated.toml" in r.files
    v = cpm.validate(cal.calibrated_robot, HEXAPOD, HEXAPOD_READINGS)
    assert v.calibrated_rms_um <= v.reference_rms_um
    d = cpm.design(HEXAPOD, readings=200, candidates=100)
    assert "design.json" in d.files
    assert not gone.exists()


def test_nothing_held_in_memory_is_written_for_an_option(in_root, monkeypatch):
    """Issue 59: no scratch folder. A robot or measurements held in memory only, given to an
    option that takes a file's path, is a UsageError naming the option (nothing is written
    to stand for them); the same robot read from its file goes by its path."""
    text_robot = cpm.Robot.from_text(open(HEX).read(), "hexapod from text")
    m = cpm.simulate(HEX, random=6, truth=TRUTH, noise="none", seed=2)
    with monkeypatch.context() as mp:
        no_temp_folder(mp)
        with pytest.raises(cpm.UsageError, match="sockets: the robot 'hexapod from text' "
                                                 "is held in memory only"):
            cpm.design(HEX, sockets=text_robot)
        with pytest.raises(cpm.UsageError, match="commands: the measurements "
                                                 r"\['simulated.csv'\] are held in memory"):
            cpm.validate(None, HEX, commands=m, truth=TRUTH)
        # A robot read from its file goes by its path: the file's own error, not ours.
        with pytest.raises(cpm.CpmError) as e:
            cpm.design(HEX, sockets=cpm.Robot.from_toml(HEX))
        assert "held in memory" not in str(e.value)


def test_a_bad_pose_array_names_its_row(in_root, tmp_path):
    """A bad pose of a plan or of the targets given as an array is the error of its file,
    named ``poses``, with the row of the array."""
    poses = cpm.simulate(HEX, random=5, truth=TRUTH, noise="none", seed=2).poses
    poses[3, 4] = 0.5 * np.pi * 1e3  # an angle out of range
    f = _pose_csv(tmp_path / "bad.csv", poses)
    with pytest.raises(cpm.InputError) as on_file:
        cpm.compensate(TRUTH, f)
    for run in (lambda: cpm.compensate(TRUTH, poses),
                lambda: cpm.simulate(HEX, plan=poses, truth=TRUTH),
                lambda: cpm.identifiability(HEX, plan=poses)):
        with pytest.raises(cpm.InputError) as e:
            run()
        assert (e.value.file, e.value.line, e.value.row, e.value.field) == \
            ("poses", 5, 3, "pitch_deg")
        assert str(e.value) == str(on_file.value).replace(str(f), "poses")
    with pytest.raises(cpm.UsageError, match="exactly one of"):
        cpm.simulate(HEX, plan=poses[:2], circle=True)


def test_robots_from_text_go_to_simulate_and_the_compensation_check_in_memory(
        in_root, tmp_path, monkeypatch):
    """Issue 36: a ``truth=`` made from text (simulate, a compensation check) and the
    reference of a compensation check reach the job as loaded (no scratch file is written),
    with the results of their files, named by their names."""

    truth = cpm.Robot.from_text(open(TRUTH).read(), "truth from text")
    ref = cpm.Robot.from_text(open(HEX).read(), "reference from text")
    commands = tmp_path / "commands.csv"
    cpm.compensate(TRUTH, "examples/targets.csv", out=commands)
    on_file = (cpm.simulate(HEX, random=6, truth=TRUTH, noise="gaussian:1", seed=3),
               cpm.validate(None, HEX, commands=commands, truth=TRUTH))
    fit = cpm.simulate(HEX, random=6, truth=TRUTH, noise="none", seed=1)

    with monkeypatch.context() as mp:
        no_temp_folder(mp)
        s = cpm.simulate(HEX, random=6, truth=truth, noise="gaussian:1", seed=3)
        v = cpm.validate(None, ref, fit, commands=commands, truth=truth)
    np.testing.assert_array_equal(s.lengths_mm, on_file[0].lengths_mm)
    assert v.summary["truth"] == "truth from text"
    assert v.summary["reference_robot"] == "reference from text"
    for key in ("compensated", "reference", "targets", "simulated"):
        assert v.summary[key] == on_file[1].summary[key], key
    with pytest.raises(cpm.UsageError, match="exclude each other"):
        cpm.simulate(HEX, random=3, truth=truth, paper_table2=True)
