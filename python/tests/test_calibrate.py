"""cpm.calibrate: the same numbers as `cpm calibrate`, the result's fields, the report in
HTML, the GIL released during the fit."""
import json
import re
import math
import subprocess
import threading
import time

import numpy as np
import pytest

import cpm
from conftest import HEXAPOD, HEXAPOD_READINGS

GOOD = "tests/data/malformed/good.csv"
CUBE = "examples/paper_cubic.toml"


def _numbers(a, b, path=""):
    """Every number of two JSON documents, pairwise (the documents must have the same shape
    apart from timings)."""
    if isinstance(a, dict):
        assert set(a) == set(b), f"{path}: keys {set(a) ^ set(b)}"
        for k in a:
            if "elapsed" in k or k.endswith("_seconds"):
                continue
            yield from _numbers(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            yield from _numbers(x, y, f"{path}[{i}]")
    elif isinstance(a, (int, float)) and not isinstance(a, bool):
        yield path, float(a), float(b)
    elif isinstance(a, str) and isinstance(b, str):
        assert _untimed(a) == _untimed(b), f"{path}: {a!r} != {b!r}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def _untimed(text):
    """Text with the solver's wall-clock times (``5.46ms``) left out: they differ run to
    run."""
    return re.sub(r"\d+(\.\d+)?\s?(ms|µs|us|ns|s)\b", "<time>", text)


CASES = [
    ("hexapod", "examples/hexapod_66.toml", "examples/hexapod_66_readings.csv", []),
    ("hexapod_link_offset", "examples/hexapod_66.toml", "examples/hexapod_66_readings.csv",
     ["--effects", "link_offset"]),
    ("hexapod_huber", "examples/hexapod_66.toml", "examples/hexapod_66_readings.csv",
     ["--robust", "huber:3", "--sigma-um", "1"]),
    ("cube", CUBE, GOOD, []),
]


@pytest.mark.parametrize("name,robot,data,extra", CASES, ids=[c[0] for c in CASES])
def test_python_calibrate_equals_cpm_calibrate(in_root, tmp_path, cpm_bin, name, robot, data,
                                               extra):
    out = tmp_path / "cli"
    subprocess.run([str(cpm_bin), "calibrate", "--robot", robot, "--data", data, "--out",
                    str(out), "-q", *extra], check=True)
    cli = json.loads((out / "calibration.json").read_text())
    kwargs = {}
    for flag, value in zip(extra[::2], extra[1::2]):
        kwargs[flag[2:].replace("-", "_")] = value
    if "sigma_um" in kwargs:
        kwargs["sigma_um"] = float(kwargs["sigma_um"])
    if "effects" in kwargs:
        kwargs["effects"] = kwargs["effects"].split(",")
    res = cpm.calibrate(robot, data, **kwargs)
    py = json.loads(res.to_json())
    count = 0
    for path, x, y in _numbers(cli, py):
        count += 1
        if math.isnan(x):
            assert math.isnan(y), path
        else:
            assert abs(x - y) <= 1e-12 * max(1.0, abs(x)), f"{path}: {x} vs {y}"
    assert count > 50, count  # the comparison saw the estimates, not an empty document
    # The calibrated description and the report are the command's, byte for byte: saved
    # beside the command's folder, calibrated.toml records its origin as the command did.
    res.save(tmp_path / "py")
    assert (tmp_path / "py" / "calibrated.toml").read_text() == \
        (out / "calibrated.toml").read_text()
    assert _untimed(res.markdown) == _untimed((out / "report.md").read_text())
    # The arrays say what calibration.json says: the parameters not determined.
    assert len(cli["not_determined"]) == int((~res.determined).sum())
    assert np.all(np.isnan(res.estimates_um[~res.determined]))


@pytest.fixture(scope="module")
def result():
    robot = cpm.Robot.from_toml(HEXAPOD)
    return cpm.calibrate(robot, cpm.read_measurements(HEXAPOD_READINGS, robot),
                         effects=["link_offset"])


def test_result_fields(result):
    n = result.identifiability.num_params
    assert n == 36 + 6  # installation errors + one link offset per link
    assert result.estimates_um.shape == (n,) == result.std_um.shape
    assert result.covariance.shape == (n, n)
    assert len(result.parameter_names) == n
    det = result.determined
    # The covariance's diagonal is the standard deviations squared; it is symmetric.
    np.testing.assert_allclose(np.sqrt(np.diag(result.covariance)[det]), result.std_um[det],
                               rtol=1e-9)
    c = result.covariance[np.ix_(det, det)]
    np.testing.assert_allclose(c, c.T, rtol=1e-12, atol=0)
    assert np.all(np.isnan(result.estimates_um[~det])) and np.all(np.isnan(result.std_um[~det]))
    ident = result.identifiability
    assert ident.rank == len([s for s in ident.singular_values
                              if s > ident.rank_rtol * ident.singular_values[0]])
    assert result.residuals_um.ndim == 1 and result.residuals_um.size > 0
    rms = float(np.sqrt(np.mean(result.residuals_um ** 2)))
    assert rms == pytest.approx(result.residual_rms_um, rel=1e-9)
    assert result.simulated and result.converged
    assert result.registration is None  # gauge readings only
    f, line, what = result.observation_origin(0)
    assert f.endswith("hexapod_66_readings.csv") and line == 3 and "sensor" in what
    cal = result.calibrated_robot
    assert isinstance(cal, cpm.Robot) and cal.num_links == 6
    # The calibrated link offsets are known effects of the calibrated robot; its link reading
    # models stay the description's.
    base = cpm.Robot.from_toml(HEXAPOD)
    assert np.array_equal(cal.length_at_zero_mm, base.length_at_zero_mm)
    assert "link_offset = [" in cal.to_toml()
    df = result.to_pandas()
    assert list(df.index) == result.parameter_names


def test_rank_deficient_fit_names_blind_directions(in_root):
    # The paper's design (one sensor on a circle) cannot see every installation error.
    data = cpm.simulate(CUBE, circle=True, paper_table2=True, noise="uniform:10", seed=1)
    assert data.simulated
    r = cpm.calibrate(CUBE, data, effects=[])
    ident = r.identifiability
    assert ident.rank < ident.num_params == 36
    assert ident.blind_directions and all(isinstance(w, str) and d >= 1
                                          for w, d in ident.blind_directions)
    assert sum(d for _, d in ident.blind_directions) + ident.unexplained_null_dimensions \
        == 36 - ident.rank
    assert any("Rank-deficient" in w for w in r.warnings)
    assert not r.determined.all()


def test_repr_html_is_the_report(result):
    page = result.html
    assert page.startswith("<!DOCTYPE html>") and "<svg" in page and "<table>" in page
    frame = result._repr_html_()
    assert frame.startswith("<iframe srcdoc=") and "&lt;svg" in frame
    assert "SIMULATED" in page


def test_out_writes_the_command_outputs(in_root, tmp_path):
    out = tmp_path / "cal"
    r = cpm.calibrate("examples/hexapod_66.toml", "examples/hexapod_66_readings.csv", out=out)
    for name in ("calibration.json", "report.md", "report.html", "calibrated.toml"):
        assert (out / name).read_bytes() == r.files[name]
    assert r.written


def test_sigma_and_robust_reach_the_fit(in_root):
    a = cpm.calibrate(CUBE, GOOD, sigma_um=5.0)
    assert a.sigma_um == 5.0 and not a.sigma_estimated
    b = cpm.calibrate(CUBE, GOOD)
    assert b.sigma_estimated
    c = cpm.calibrate(CUBE, GOOD, robust="huber:30", sigma_um=5.0)
    assert "Huber" in c.to_json()


def test_gil_is_released_during_the_fit(in_root, tmp_path):
    # A campaign big enough that the fit takes a while (simulated).
    data = cpm.simulate("examples/hexapod_66.toml", random=3000, truth=
                        "examples/hexapod_66_truth.toml", noise="gaussian:1", seed=5)
    stamps = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            stamps.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=count)
    t.start()
    try:
        time.sleep(0.05)
        t0 = time.perf_counter()
        cpm.calibrate("examples/hexapod_66.toml", data, effects=["link_offset", "link_scale"])
        t1 = time.perf_counter()
    finally:
        stop.set()
        t.join()
    inside = [s for s in stamps if t0 <= s <= t1]
    assert t1 - t0 > 0.05, f"the fit took only {t1 - t0:.3f} s: too short to tell"
    gaps = np.diff([t0] + inside + [t1])
    # Held, the GIL would stop the counting thread for the whole fit; released, it counts on.
    assert gaps.max() < 0.5 * (t1 - t0), (gaps.max(), t1 - t0)
    assert len(inside) > 10


def test_ctrl_c_interrupts_a_long_command(in_root, tmp_path):
    import signal

    data = cpm.simulate("examples/hexapod_66.toml", random=1000,
                        truth="examples/hexapod_66_truth.toml", noise="gaussian:1", seed=5)
    t0 = time.perf_counter()
    cpm.refine("examples/hexapod_66.toml", data)
    whole = time.perf_counter() - t0
    assert whole > 0.4, f"refine took only {whole:.2f} s: too short to tell"
    out = tmp_path / "refined"
    timer = threading.Timer(0.1, lambda: signal.raise_signal(signal.SIGINT))
    timer.start()
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        cpm.refine("examples/hexapod_66.toml", data, out=out)
    interrupted = time.perf_counter() - t0
    timer.cancel()
    # Back at once, long before the command would have finished.
    assert interrupted < 0.1 + 0.5 * (whole - 0.1), (interrupted, whole)
    # The job is cancelled (through its progress, inside the fit too) and writes nothing,
    # not even once the time the whole refinement takes has passed.
    time.sleep(2 * whole + 0.5)
    assert not out.exists(), sorted(p.name for p in out.iterdir())


def test_noise_per_kind_reaches_the_fit(in_root, tmp_path):
    """A simulated tracker with orientations 25 times noisier than the default: weighed by
    the defaults (``noise_per_kind="off"``) the result says so; by default (two kinds, no
    declared noise) each kind is weighed by its own residual."""
    data = tmp_path / "tracker.csv"
    cpm.simulate(HEXAPOD, random=60, truth="examples/hexapod_66_truth.toml", measure="poses",
                 noise="gaussian:2", orientation_noise_urad=500, seed=3, out=data)
    plain = cpm.calibrate(HEXAPOD, data, noise_per_kind="off")
    kinds = {k["kind"]: k for k in plain.noise_by_kind}
    assert set(kinds) == {"tracker positions", "tracker orientations"}
    assert kinds["tracker orientations"]["estimated"] > 10 * kinds["tracker orientations"]["assumed"]
    assert any(w.startswith("Noise not as weighed") for w in plain.warnings)
    weighed = cpm.calibrate(HEXAPOD, data)
    kinds = {k["kind"]: k for k in weighed.noise_by_kind}
    assert abs(kinds["tracker positions"]["estimated"] / 2.0 - 1.0) < 0.15
    assert abs(kinds["tracker orientations"]["estimated"] / 500.0 - 1.0) < 0.15
    assert not any(w.startswith("Noise not as weighed") for w in weighed.warnings)


def test_tolerances_and_hold_reach_the_fit(in_root):
    """The estimator's prior from Python: a held group stays at nominal, a tolerance is the
    one the report lists, and a group the model does not have is refused by name."""
    robot = cpm.Robot.from_toml(HEXAPOD)
    data = cpm.read_measurements(HEXAPOD_READINGS, robot)
    held = cpm.calibrate(robot, data, effects=["link_offset"], hold=["installation_errors"])
    assert np.all(held.minimum_norm_um[:36] == 0.0)
    assert np.any(held.minimum_norm_um[36:] != 0.0)
    tight = cpm.calibrate(robot, data, effects=["link_offset"],
                          tolerances={"link_offset": 123.0})
    groups = {g["group"]: g for g in json.loads(tight.text("calibration.json"))["prior"]["groups"]}
    assert groups["link_offset"]["tolerance"] == 123.0
    assert groups["link_offset"]["treatment"] == "prior"
    with pytest.raises(cpm.CpmError, match="not_a_group"):
        cpm.calibrate(robot, data, tolerances={"not_a_group": 1.0})
    # The limit reaches the fit and its report; one that is no number of tolerances is a
    # usage error.
    limited = cpm.calibrate(robot, data, effects=["link_offset"], tolerance_limit=2.0)
    prior = json.loads(limited.text("calibration.json"))["prior"]
    assert prior["limit_in_tolerances"] == 2.0
    assert isinstance(prior["held_at_limit"], list)
    with pytest.raises(cpm.UsageError, match="^tolerance_limit must be > 0"):
        cpm.calibrate(robot, data, tolerance_limit=0.0)
