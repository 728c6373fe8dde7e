"""Issue 61, "Python as Python users expect": a saved result resolves where it is saved, from a
clone at any depth; inputs are refused or taken as a Python user expects (complex arrays, an
unreachable pose, a DataFrame, a robot given by its path, validate's default reference);
error messages name the Python keywords, not the command-line flags."""
import re
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

import cpm
from conftest import HEXAPOD, HEXAPOD_READINGS

LATER = HEXAPOD.parent / "hexapod_66_later.csv"


@pytest.fixture(scope="module")
def hexapod():
    return cpm.Robot.from_toml(HEXAPOD)


@pytest.fixture
def near_tmp():
    """A copy of the hexapod and its readings two folders below the temporary directory
    (where the issue's clone was: /tmp/newcomer5/cpm): a scratch folder there is as near."""
    d = Path(tempfile.mkdtemp(prefix="cpm-clone-")) / "cpm"
    d.mkdir()
    shutil.copy(HEXAPOD, d / "hexapod_66.toml")
    shutil.copy(HEXAPOD_READINGS, d / "readings.csv")
    yield d
    shutil.rmtree(d.parent)


def _recorded(text):
    m = re.search(r'^calibrated_from = "(.*)"$', text, re.M)
    assert m, text
    return m.group(1)


# Item 4: a saved result points at a file that exists.

def test_a_saved_result_validates_where_it_is_saved(near_tmp, tmp_path, cpm_bin):
    robot = cpm.Robot.from_toml(near_tmp / "hexapod_66.toml")
    result = cpm.calibrate(robot, near_tmp / "readings.csv")
    # In memory, the result records the description it came from as a path that exists.
    assert Path(_recorded(result.text("calibrated.toml"))).resolve() == \
        (near_tmp / "hexapod_66.toml").resolve()
    saved = tmp_path / "deep" / "er" / "saved"
    result.save(saved)
    recorded = _recorded((saved / "calibrated.toml").read_text())
    assert (saved / recorded).resolve() == (near_tmp / "hexapod_66.toml").resolve()
    # The command validates it with its default reference (the recorded description).
    run = subprocess.run([str(cpm_bin), "validate", "--robot", str(saved / "calibrated.toml"),
                          "--data", str(LATER), "--out", str(tmp_path / "v"), "-q"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    # So does Python, from the saved file and from the result in memory.
    from_file = cpm.validate(saved / "calibrated.toml", data=LATER)
    in_memory = cpm.validate(result.calibrated_robot, data=LATER)
    assert from_file.reference_rms_um == in_memory.reference_rms_um > 0


def test_a_result_written_with_out_saves_elsewhere(near_tmp, tmp_path):
    """With ``out`` the files record the description relative to ``out`` (as the command
    does); saved elsewhere they record it from there."""
    robot = cpm.Robot.from_toml(near_tmp / "hexapod_66.toml")
    out = near_tmp / "cal"
    result = cpm.calibrate(robot, near_tmp / "readings.csv", out=out)
    assert _recorded((out / "calibrated.toml").read_text()) == "../hexapod_66.toml"
    assert result.text("calibrated.toml") == (out / "calibrated.toml").read_text()
    result.save(tmp_path / "copy")
    recorded = _recorded((tmp_path / "copy" / "calibrated.toml").read_text())
    assert (tmp_path / "copy" / recorded).resolve() == (near_tmp / "hexapod_66.toml").resolve()
    v = cpm.validate(result.calibrated_robot, data=LATER)
    assert v.calibrated_rms_um < v.reference_rms_um


def test_a_refined_result_records_a_path_that_exists(near_tmp, tmp_path):
    """refine's calibrated.toml, made in memory, records its origin where it exists too."""
    robot = cpm.Robot.from_toml(near_tmp / "hexapod_66.toml")
    refined = cpm.refine(robot, near_tmp / "readings.csv", max_steps=1)
    assert Path(_recorded(refined.text("calibrated.toml"))).resolve() == \
        (near_tmp / "hexapod_66.toml").resolve()
    refined.save(tmp_path / "refined")
    v = cpm.validate(tmp_path / "refined" / "calibrated.toml", data=LATER)
    assert v.calibrated_rms_um < v.reference_rms_um


# Item 5: inputs.

def test_complex_arrays_are_refused_naming_the_argument(hexapod):
    m = cpm.read_measurements(HEXAPOD_READINGS, hexapod)
    frame = m.to_pandas()
    p = frame[["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"]].to_numpy()
    lengths = frame["length_mm"].to_numpy()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning, an error
        with pytest.raises(cpm.UsageError, match=r"^poses: complex"):
            cpm.gauge_readings(hexapod, p + 1000j, list(frame["sensor"]), lengths)
        with pytest.raises(cpm.UsageError, match=r"^lengths_mm: complex"):
            cpm.gauge_readings(hexapod, p, list(frame["sensor"]), lengths + 1000j)
        with pytest.raises(cpm.UsageError, match=r"^poses: complex"):
            cpm.compensate(hexapod, np.array([[0, 0, 250, 0, 0, 0]]) + 1000j)
        with pytest.raises(cpm.UsageError, match=r"^sigma_um: complex"):
            cpm.calibrate(hexapod, m, sigma_um=1 + 1000j)
        with pytest.raises(ValueError, match=r"x0.*complex"):
            cpm.lm.least_squares(lambda x: x - 1, np.array([1 + 1000j]))


def test_an_unreachable_pose_is_left_out_with_the_commands_warning(hexapod, tmp_path, cpm_bin):
    frame = cpm.read_measurements(HEXAPOD_READINGS, hexapod).to_pandas()
    frame.loc[0, "z_mm"] = 5000.0
    p = frame[["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"]].to_numpy()
    with pytest.warns(cpm.CpmWarning, match=r'^gauge readings:2: pose "1" excluded: .*z 5000 mm.* '
                                                r'is not reachable') as w:
        m = cpm.gauge_readings(hexapod, p, list(frame["sensor"]), frame["length_mm"].to_numpy())
    assert m.num_readings == len(frame) - 1
    assert len([x for x in w if issubclass(x.category, cpm.CpmWarning)]) == 1
    # The fit says it too (the command warns there).
    with pytest.warns(cpm.CpmWarning, match=r'pose "1" excluded'):
        cpm.calibrate(hexapod, m)
    # The same words as the command's warning, for the same readings in a file (each row
    # its own pose, as the arrays without labels).
    f = tmp_path / "far.csv"
    frame["pose"] = np.arange(1, len(frame) + 1)
    frame.drop(columns=["file", "line"]).to_csv(f, index=False)
    run = subprocess.run([str(cpm_bin), "calibrate", "--robot", str(HEXAPOD), "--data", str(f),
                          "--out", str(tmp_path / "cal")], capture_output=True, text=True)
    said = [ln[len("warning: "):] for ln in run.stderr.splitlines()
            if ln.startswith("warning: ") and "excluded" in ln]
    assert len(said) == 1, run.stderr
    with pytest.warns(cpm.CpmWarning) as w:
        cpm.read_measurements(f, hexapod)
    assert [str(x.message) for x in w if issubclass(x.category, cpm.CpmWarning)] == said


def test_calibrate_takes_a_dataframe(hexapod):
    pd = pytest.importorskip("pandas")
    frame = pd.read_csv(HEXAPOD_READINGS, comment="#")
    from_frame = cpm.calibrate(hexapod, frame, effects=["link_offset"])
    from_file = cpm.calibrate(hexapod, HEXAPOD_READINGS, effects=["link_offset"])
    np.testing.assert_allclose(from_frame.estimates_um, from_file.estimates_um, rtol=1e-12,
                               atol=1e-9, equal_nan=True)
    with pytest.raises(TypeError, match="measurements_from_frame"):
        cpm.read_measurements(frame, hexapod)


def test_a_robot_may_be_given_by_its_path(hexapod):
    by_path = cpm.read_measurements(HEXAPOD_READINGS, str(HEXAPOD))
    by_object = cpm.read_measurements(HEXAPOD_READINGS, hexapod)
    np.testing.assert_array_equal(by_path.lengths_mm, by_object.lengths_mm)
    frame = by_object.to_pandas()
    g = cpm.gauge_readings(HEXAPOD, frame[["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg",
                                          "yaw_deg"]].to_numpy(),
                           list(frame["sensor"]), frame["length_mm"].to_numpy())
    assert g.num_readings == by_object.num_readings
    with pytest.raises(TypeError, match=r"robot: expected a cpm\.Robot or the path of a robot "
                                        r"description \(\.toml\), got int"):
        cpm.read_measurements(HEXAPOD_READINGS, 42)


def test_validate_defaults_its_reference_as_the_command_does(hexapod, tmp_path, cpm_bin):
    cal = cpm.calibrate(hexapod, HEXAPOD_READINGS, out=tmp_path / "cal")
    given = cpm.validate(tmp_path / "cal" / "calibrated.toml", HEXAPOD, LATER)
    default = cpm.validate(tmp_path / "cal" / "calibrated.toml", data=LATER)
    assert default.reference_rms_um == given.reference_rms_um
    assert default.calibrated_rms_um == given.calibrated_rms_um < given.reference_rms_um
    # A description that records no origin: the error names the keyword.
    with pytest.raises(cpm.UsageError, match=r"^reference is required") as e:
        cpm.validate(hexapod, data=LATER)
    assert "--" not in str(e.value)
    assert cal.calibrated_robot.num_links == 6


def test_errors_name_the_python_keywords(hexapod):
    with pytest.raises(cpm.UsageError) as e:
        cpm.calibrate(hexapod, HEXAPOD_READINGS, sigma=1)
    assert "'sigma'" in str(e.value) and "--" not in str(e.value), e.value
    with pytest.raises(cpm.UsageError) as e:
        cpm.calibrate(hexapod, HEXAPOD_READINGS, tolerances={"link_scale": -1})
    assert str(e.value).startswith("tolerances "), e.value
    assert "--" not in str(e.value)
    with pytest.raises(cpm.UsageError) as e:
        cpm.calibrate(hexapod, HEXAPOD_READINGS, robust="pink:3")
    assert str(e.value).startswith("robust "), e.value
    with pytest.raises(cpm.UsageError) as e:
        cpm.calibrate(hexapod, HEXAPOD_READINGS, sigma_um=float("nan"))
    assert "'sigma_um'" in str(e.value) and "--" not in str(e.value), e.value
    with pytest.raises(cpm.UsageError) as e:
        cpm.simulate(hexapod, random=12, measure="sound")
    assert "'measure'" in str(e.value) and "--" not in str(e.value), e.value


def test_a_weighted_residual_has_no_figure_in_um():
    """Issue 60 item 10: the real inclinometer session (angles alone, in urad) has no
    residual RMS or noise in um: they are None, as calibration.json's null; the weighted
    figure is in sigma and the angles' RMS in urad is calibration.json's noise_by_kind."""
    import json

    tilt = Path(__file__).resolve().parents[2] / "tests" / "data" / "jugglebot_tilt"
    r = cpm.calibrate(tilt / "robot.toml", tilt / "session_1.csv")
    assert r.residual_weighted
    assert r.residual_rms_um is None and r.initial_rms_um is None and r.sigma_um is None
    assert 0 < r.weighted_rms_in_sigma < r.initial_weighted_rms_in_sigma
    assert "in sigma" in repr(r) and " um;" not in repr(r)
    doc = json.loads(r.files["calibration.json"])
    assert doc["residual_rms_um"] is None
    (angles,) = [k for k in doc["noise_by_kind"] if k["kind"] == "inclinometer angles"]
    assert angles["unit"] == "urad" and angles["rms"] > 0
    # The residuals: none in um; each in its own unit, as residuals.csv writes them.
    assert r.residuals_um is None
    assert r.residuals.shape == (570,) and set(r.residual_units) == {"urad"}
    rows = r.files["residuals.csv"].decode().splitlines()[1:]
    csv = np.array([float(row.rsplit(",", 1)[1]) for row in rows])
    np.testing.assert_allclose(r.residuals, csv, rtol=1e-8, atol=1e-6)
    rms = float(np.sqrt(np.mean(r.residuals ** 2)))
    assert rms == pytest.approx(angles["rms"], rel=1e-9)


def test_gauge_residuals_are_in_um_both_ways(hexapod):
    """A gauge-only fit: residuals_um (predicted minus measured) is the opposite of
    residuals (measured minus predicted), all in um."""
    r = cpm.calibrate(hexapod, HEXAPOD_READINGS)
    assert not r.residual_weighted and r.residual_rms_um is not None
    assert set(r.residual_units) == {"um"}
    np.testing.assert_allclose(r.residuals, -r.residuals_um, rtol=1e-12, atol=1e-12)
