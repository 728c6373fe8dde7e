"""Measurements from files, numpy arrays and pandas tables: the same reader, the same checks;
dtype and shape handling."""
import numpy as np
import pytest

import cpm
from conftest import CUBE, HEXAPOD, HEXAPOD_READINGS, MALFORMED, no_temp_folder


@pytest.fixture(scope="module")
def hexapod():
    return cpm.Robot.from_toml(HEXAPOD)


@pytest.fixture(scope="module")
def readings(hexapod):
    return cpm.read_measurements(HEXAPOD_READINGS, hexapod)


def _rows(path):
    lines = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]
    return lines[0].split(","), [ln.split(",") for ln in lines[1:]]


def test_read_file_gives_what_the_file_holds(readings):
    header, rows = _rows(HEXAPOD_READINGS)
    assert readings.num_readings == len(rows)
    assert readings.simulated  # the example file is labelled simulated
    assert readings.kinds == ["gauge"]
    i = header.index("length_mm")
    np.testing.assert_array_equal(readings.lengths_mm, [float(r[i]) for r in rows])
    assert readings.reading_sensor == [r[header.index("sensor")] for r in rows]
    assert readings.num_poses == len({r[0] for r in rows})


def _arrays(m):
    """The file's own columns as arrays: poses (x..yaw), sensors, lengths, pose labels."""
    header, rows = _rows(HEXAPOD_READINGS)
    col = {c: header.index(c) for c in header}
    poses = np.array([[float(r[col[c]]) for c in ("x_mm", "y_mm", "z_mm", "roll_deg",
                                                   "pitch_deg", "yaw_deg")] for r in rows])
    return (poses, [r[col["sensor"]] for r in rows],
            np.array([float(r[col["length_mm"]]) for r in rows]), [r[col["pose"]] for r in rows])


def test_arrays_go_through_the_same_reader(hexapod, readings):
    poses, sensors, lengths, labels = _arrays(readings)
    m = cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels,
                           simulated=True)
    np.testing.assert_array_equal(m.lengths_mm, readings.lengths_mm)
    np.testing.assert_array_equal(m.poses, readings.poses)
    assert m.simulated and m.num_poses == readings.num_poses
    a = cpm.calibrate(hexapod, readings)
    b = cpm.calibrate(hexapod, m)
    np.testing.assert_array_equal(a.estimates_um, b.estimates_um)
    np.testing.assert_array_equal(a.std_um, b.std_um)


def test_the_arrays_of_measurements_from_arrays_are_made_when_asked(hexapod, readings):
    """Measurements from arrays hold their file, kind and handle at once; the arrays of a
    file's summary come when first asked for, the same as the file's."""
    poses, sensors, lengths, labels = _arrays(readings)
    m = cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels,
                           simulated=True)
    info = m.sources[0].info
    assert dict.__contains__(info, "handle") and not dict.__contains__(info, "lengths_mm")
    assert info["kind"] == "gauge" and info["simulated"] is True
    assert "reading_lines" in info and set(info) >= set(readings.sources[0].info)
    np.testing.assert_array_equal(info["reading_pose"], readings.sources[0].info["reading_pose"])
    assert info["pose_labels"] == readings.sources[0].info["pose_labels"]
    assert info.get("no such key") is None
    with pytest.raises(KeyError):
        info["no such key"]


def test_unlabelled_arrays_are_not_marked_simulated(hexapod, readings):
    poses, sensors, lengths, labels = _arrays(readings)
    m = cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels)
    assert not m.simulated


def test_float32_and_non_contiguous_input(hexapod, readings):
    poses, sensors, lengths, labels = _arrays(readings)
    p32 = poses.astype(np.float32)
    m = cpm.gauge_readings(hexapod, p32, sensors, lengths.astype(np.float32),
                           pose_labels=labels)
    # float32 values are converted to float64 exactly as numpy converts them.
    np.testing.assert_array_equal(m.lengths_mm, lengths.astype(np.float32).astype(np.float64))
    assert m.lengths_mm.dtype == np.float64
    # A strided view (every other column of a wider array) and a Fortran-ordered copy give
    # the same measurements as the contiguous array.
    wide = np.zeros((poses.shape[0], 12))
    wide[:, ::2] = poses
    view = wide[:, ::2]
    assert not view.flags["C_CONTIGUOUS"]
    m1 = cpm.gauge_readings(hexapod, view, sensors, lengths[::1], pose_labels=labels)
    m2 = cpm.gauge_readings(hexapod, np.asfortranarray(poses), sensors, lengths,
                            pose_labels=labels)
    m3 = cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels)
    np.testing.assert_array_equal(m1.poses, m3.poses)
    np.testing.assert_array_equal(m2.poses, m3.poses)
    # Reversed (negative strides) lengths.
    rev = lengths[::-1]
    m4 = cpm.gauge_readings(hexapod, poses[::-1], sensors[::-1], rev, pose_labels=labels[::-1])
    np.testing.assert_array_equal(m4.lengths_mm, rev)


def test_labels_and_sensors_are_taken_as_their_str(hexapod, readings):
    """Labels and sensor names of any sequence are their items' ``str()``: numpy arrays,
    integers, a generator, one object shared by many rows or a new object per row give the
    same measurements as lists of ``str``."""
    poses, sensors, lengths, labels = _arrays(readings)
    ref = cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels)
    as_int = [int(v) for v in labels]
    assert all(str(v) == t for v, t in zip(as_int, labels))  # the file's labels are integers

    class Named:
        def __init__(self, text):
            self.text = text

        def __str__(self):
            return self.text

    shared = {t: t for t in set(labels)}
    variants = [
        (np.array(sensors), np.array(as_int)),
        (tuple(sensors), (v for v in as_int)),
        ([Named(t) for t in sensors], [shared[t] for t in labels]),
        ([(t + ".")[:-1] for t in sensors], [np.int64(v) for v in as_int]),
    ]
    for names, labs in variants:
        m = cpm.gauge_readings(hexapod, poses, names, lengths, pose_labels=labs)
        assert m.reading_sensor == ref.reading_sensor
        assert m.sources[0].info["pose_labels"] == ref.sources[0].info["pose_labels"]
        np.testing.assert_array_equal(m.sources[0].info["reading_pose"],
                                      ref.sources[0].info["reading_pose"])
        np.testing.assert_array_equal(m.poses, ref.poses)

    class Tagged(str):
        def __str__(self):
            return "x" + str.__str__(self)

    # A subclass of str is its str() too, as str(v) in Python gives it.
    m = cpm.gauge_readings(hexapod, poses, sensors, lengths,
                           pose_labels=[Tagged(t) for t in labels])
    assert m.sources[0].info["pose_labels"] == [
        "x" + t for t in ref.sources[0].info["pose_labels"]]

    class Broken:
        def __str__(self):
            raise ValueError("no text for this label")

    with pytest.raises(ValueError, match="no text for this label"):
        cpm.gauge_readings(hexapod, poses, sensors, lengths,
                           pose_labels=[Broken()] * len(labels))


@pytest.mark.parametrize("bad,match", [
    ("poses5", r"poses has shape \(\d+, 5\), expected \(n, 6\)"),
    ("poses1d", r"poses has shape \(\d+,\), expected \(n, 6\)"),
    ("lengths", r"lengths_mm has shape"),
    ("sensors", r"sensors has shape"),
    ("text", r"poses: not an array of numbers"),
])
def test_wrong_shapes_are_usage_errors(hexapod, readings, bad, match):
    poses, sensors, lengths, _ = _arrays(readings)
    args = dict(poses=poses, sensors=sensors, lengths_mm=lengths)
    if bad == "poses5":
        args["poses"] = poses[:, :5]
    elif bad == "poses1d":
        args["poses"] = poses[:, 0]
    elif bad == "lengths":
        args["lengths_mm"] = lengths[:-1]
    elif bad == "sensors":
        args["sensors"] = sensors[:-1]
    elif bad == "text":
        args["poses"] = [["a"] * 6] * len(lengths)
    with pytest.raises(cpm.UsageError, match=match) as e:
        cpm.gauge_readings(hexapod, **args)
    assert isinstance(e.value, ValueError)


def test_a_bad_row_names_its_row(hexapod, readings):
    poses, sensors, lengths, labels = _arrays(readings)
    lengths = lengths.copy()
    lengths[7] /= 1000.0  # metres, not millimetres
    with pytest.raises(cpm.InputError) as e:
        cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels)
    assert e.value.row == 7 and e.value.field == "length_mm"
    assert e.value.file == "gauge readings" and "row 7" in str(e.value)
    sensors = list(sensors)
    sensors[3] = "nosuch"
    with pytest.raises(cpm.InputError) as e:
        cpm.gauge_readings(hexapod, poses, sensors, readings.lengths_mm, pose_labels=labels)
    assert e.value.row == 3 and e.value.field == "sensor"


def test_pandas_frame(hexapod, readings):
    pd = pytest.importorskip("pandas")
    import warnings

    with warnings.catch_warnings():
        # pandas 3 deprecates the option (its default parser is exact there); older pandas
        # need it to read every number back exactly.
        warnings.simplefilter("ignore")
        df = pd.read_csv(HEXAPOD_READINGS, comment="#", float_precision="round_trip")
    m = cpm.measurements_from_frame(df, hexapod)
    np.testing.assert_array_equal(m.lengths_mm, readings.lengths_mm)
    np.testing.assert_array_equal(m.poses, readings.poses)
    t = readings.to_pandas()
    assert list(t["sensor"]) == list(df["sensor"])
    np.testing.assert_array_equal(t["length_mm"].to_numpy(), df["length_mm"].to_numpy())
    assert t["line"].iloc[0] == 3  # after the simulated-by comment and the header


def _quat(rpy_deg):
    """Quaternion (w, x, y, z) of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = np.radians(rpy_deg).T
    cr, sr, cp, sp, cy, sy = (np.cos(r / 2), np.sin(r / 2), np.cos(p / 2), np.sin(p / 2),
                              np.cos(y / 2), np.sin(y / 2))
    return np.stack([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy], 1)


def test_tracker_arrays(hexapod, tmp_path):
    f = tmp_path / "tracker.csv"
    sim = cpm.simulate(hexapod, random=12, truth=str(HEXAPOD.parent / "hexapod_66_truth.toml"),
                       measure="poses", noise="gaussian:1", seed=3, out=f)
    assert sim.kinds == ["tracker"] and sim.simulated
    header, rows = _rows(f)
    readings = np.array([[float(r[header.index(f"reading_{k}")]) for k in range(1, 7)]
                         for r in rows])
    if "qw" in header:
        q = np.array([[float(r[header.index(c)]) for c in ("qw", "qx", "qy", "qz")]
                      for r in rows])
    else:
        q = _quat(np.array([[float(r[header.index(c)]) for c in
                             ("roll_deg", "pitch_deg", "yaw_deg")] for r in rows]))
    xyz = np.array([[float(r[header.index(c)]) for c in ("x_mm", "y_mm", "z_mm")]
                    for r in rows])
    # The file's own numbers as arrays (its angles, roll pitch yaw deg): the same fit, to 1e-12.
    rpy = np.array([[float(r[header.index(c)]) for c in ("roll_deg", "pitch_deg", "yaw_deg")]
                    for r in rows])
    same = cpm.tracker_measurements(hexapod, readings, np.hstack([xyz, rpy]), simulated=True)
    exact = cpm.calibrate(hexapod, same)
    m = cpm.tracker_measurements(hexapod, readings, np.hstack([xyz, q]), simulated=True)
    assert m.kinds == ["tracker"] and len(m.measured_poses) == len(rows)
    # Issue 36: tracker arrays are read as values (no CSV text is made); a command that reads
    # files gets their CSV, every number exact, and reads what the arrays gave.
    assert m.sources[0].text is None and same.sources[0].text is None
    again = tmp_path / "again.csv"
    again.write_text(same.sources[0].info["handle"].csv())
    back = cpm.read_measurements(again, hexapod)
    np.testing.assert_array_equal(back.measured_poses, same.measured_poses)
    np.testing.assert_array_equal(back.poses, same.poses)
    assert back.simulated and back.kinds == ["tracker"]
    np.testing.assert_allclose(m.measured_poses[:, :3], sim.measured_poses[:, :3], atol=1e-9)
    a = cpm.calibrate(hexapod, sim)
    b = cpm.calibrate(hexapod, m)
    np.testing.assert_allclose(exact.estimates_um, a.estimates_um, rtol=1e-12, atol=1e-12,
                               equal_nan=True)
    # Tracker files are registered (a frame per file): the result says how.
    assert a.registration is not None and len(a.registration["sessions"]) == 1
    assert b.registration is not None and b.registration["sessions"][0]["file"] == \
        "tracker measurements"
    # Quaternions converted from the file's angles differ from them in the last bits: the
    # fits agree to a relative 1e-6 (the solver's tolerance), not to the last digit.
    np.testing.assert_allclose(b.estimates_um, a.estimates_um, rtol=1e-6, atol=1e-6,
                               equal_nan=True)
    with pytest.raises(cpm.UsageError, match=r"poses has shape \(12, 5\), expected \(n, 7\)"):
        cpm.tracker_measurements(hexapod, readings, np.hstack([xyz, q[:, :2]]))
    with pytest.raises(cpm.UsageError, match=r"readings has shape \(12, 5\)"):
        cpm.tracker_measurements(hexapod, readings[:, :5], np.hstack([xyz, q]))


def test_measurements_add_and_read_errors(hexapod, readings):
    both = readings + readings
    assert both.num_readings == 2 * readings.num_readings and len(both.files) == 2
    with pytest.raises(cpm.InputError) as e:
        cpm.read_measurements(MALFORMED / "not_a_number.csv", cpm.Robot.from_toml(CUBE))
    assert e.value.line is not None and e.value.field is not None


def _max_difference(a, b):
    """The largest difference between two calibrations' numbers, relative to max(1, |x|)
    (NaN where both are NaN: parameters the data do not determine)."""
    worst = 0.0
    for x, y in ((a.estimates_um, b.estimates_um), (a.std_um, b.std_um),
                 (a.minimum_norm_um, b.minimum_norm_um), (a.residuals_um, b.residuals_um),
                 (a.covariance, b.covariance)):
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        assert x.shape == y.shape
        assert np.array_equal(np.isnan(x), np.isnan(y))
        ok = ~np.isnan(x)
        d = np.abs(x[ok] - y[ok]) / np.maximum(1.0, np.abs(x[ok]))
        worst = max(worst, float(d.max()) if d.size else 0.0)
    return worst


def test_arrays_and_file_agree_to_1e_12(hexapod, readings, monkeypatch):
    """Issue 36: the same calibration from arrays and from the file agree to 1e-12; the
    arrays reach the fit in memory (no scratch file, no argument vector)."""
    poses, sensors, lengths, labels = _arrays(readings)
    m = cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels,
                           simulated=True)

    for effects in (None, ["link_offset"], ["sensor_offset"]):
        a = cpm.calibrate(hexapod, HEXAPOD_READINGS, effects=effects)
        with monkeypatch.context() as mp:
            no_temp_folder(mp)
            b = cpm.calibrate(hexapod, m, effects=effects)
        worst = _max_difference(a, b)
        print(f"effects {effects}: largest difference file vs arrays {worst:.3g}")
        assert worst <= 1e-12, worst
        assert b.timings["solver"] > 0.0 and b.timings["total"] >= b.timings["job"]
    # The arrays name themselves in the outputs.
    assert b.observation_origin(0)[0] == "gauge readings"


def test_gauge_arrays_are_read_as_values(hexapod, readings, tmp_path):
    """Issue 36: gauge arrays are read as values (no CSV text is made); a command that reads
    files gets their CSV, every number exact, and finds what the file gives."""
    poses, sensors, lengths, labels = _arrays(readings)
    m = cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels,
                           simulated=True)
    assert m.sources[0].text is None
    f = tmp_path / "again.csv"
    f.write_text(m.sources[0].info["handle"].csv())
    back = cpm.read_measurements(f, hexapod)
    np.testing.assert_array_equal(back.poses, m.poses)
    np.testing.assert_array_equal(back.lengths_mm, m.lengths_mm)
    assert back.reading_sensor == m.reading_sensor and back.simulated
    # identifiability reads files: the arrays' text gives the file's answer.
    a = cpm.identifiability(hexapod, m)
    b = cpm.identifiability(hexapod, HEXAPOD_READINGS)
    # The report names the arrays, not a scratch file.
    assert a.pop("source") == "gauge readings"
    b.pop("source")
    assert a == b


def test_refine_and_identifiability_take_arrays_in_memory(hexapod, readings, monkeypatch):
    """Issue 36: ``refine`` and ``identifiability`` run on a robot made from text and
    measurements made from arrays in memory (no scratch file is written), and give what the
    files give."""
    poses, sensors, lengths, labels = _arrays(readings)
    m = cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels,
                           simulated=True)
    text_robot = cpm.Robot.from_text(HEXAPOD.read_text(), "hexapod from text")

    a = cpm.identifiability(HEXAPOD, HEXAPOD_READINGS)
    with monkeypatch.context() as mp:
        no_temp_folder(mp)
        b = cpm.identifiability(text_robot, m)
        r = cpm.refine(text_robot, m, max_steps=1)
    np.testing.assert_allclose(b["singular_values"],
                               a["singular_values"], rtol=1e-12)
    assert b["source"] == "gauge readings" and a["source"] == str(HEXAPOD_READINGS)
    ref = cpm.refine(HEXAPOD, HEXAPOD_READINGS, max_steps=1)
    assert r.doc["steps"] == ref.doc["steps"]
    np.testing.assert_allclose(r.calibration["residual_rms_um"],
                               ref.calibration["residual_rms_um"], rtol=1e-12)


def test_two_tracker_sets_from_arrays_are_registered_together(hexapod, tmp_path, monkeypatch):
    """Issue 36: two tracker sessions given as arrays calibrate in memory (no scratch file),
    registered together as two files are (a frame each): the same fit as from the files."""
    files = []
    for k, seed in enumerate((3, 4)):
        f = tmp_path / f"tracker{k}.csv"
        cpm.simulate(hexapod, random=20, truth=str(HEXAPOD.parent / "hexapod_66_truth.toml"),
                     measure="poses", noise="gaussian:1", seed=seed, out=f,
                     tracker_frame=f"{500 * k},{-300 * k},10,0.2,-0.1,{40 * k}")
        files.append(f)
    arrays = []
    for f in files:
        header, rows = _rows(f)
        col = lambda c: np.array([float(r[header.index(c)]) for r in rows])  # noqa: E731
        readings = np.stack([col(f"reading_{k}") for k in range(1, 7)], axis=1)
        pose = np.stack([col(c) for c in ("x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg",
                                          "yaw_deg")], axis=1)
        arrays.append(cpm.tracker_measurements(hexapod, readings, pose, simulated=True))
        assert arrays[-1].sources[0].text is None
    a = cpm.calibrate(hexapod, [str(f) for f in files])

    with monkeypatch.context() as mp:
        no_temp_folder(mp)
        b = cpm.calibrate(hexapod, arrays)
    assert len(a.registration["sessions"]) == 2 and len(b.registration["sessions"]) == 2
    np.testing.assert_allclose(b.estimates_um, a.estimates_um, rtol=1e-9, atol=1e-9,
                               equal_nan=True)


def test_validate_takes_robots_and_arrays_in_memory(hexapod, tmp_path, monkeypatch):
    """Issue 36: ``validate`` runs on a calibrated robot made from text, its reference and
    held-out measurements made from arrays, in memory (no scratch file), and gives what the
    files give."""
    later = HEXAPOD.parent / "hexapod_66_later.csv"
    cal = cpm.calibrate(hexapod, HEXAPOD_READINGS, out=tmp_path / "cal")
    from_files = cpm.validate(tmp_path / "cal" / "calibrated.toml", HEXAPOD, later)
    header, rows = _rows(later)
    col = {c: header.index(c) for c in header}
    poses = np.array([[float(r[col[c]]) for c in ("x_mm", "y_mm", "z_mm", "roll_deg",
                                                   "pitch_deg", "yaw_deg")] for r in rows])
    m = cpm.gauge_readings(hexapod, poses, [r[col["sensor"]] for r in rows],
                           np.array([float(r[col["length_mm"]]) for r in rows]),
                           pose_labels=[r[col["pose"]] for r in rows], simulated=True,
                           name="later readings")
    text_robot = cal.calibrated_robot
    assert text_robot.path is None

    with monkeypatch.context() as mp:
        no_temp_folder(mp)
        in_memory = cpm.validate(text_robot, hexapod, m)
    assert in_memory.calibrated_rms_um == from_files.calibrated_rms_um
    assert in_memory.reference_rms_um == from_files.reference_rms_um
    assert in_memory.calibrated_rms_um < in_memory.reference_rms_um / 5
    assert in_memory.summary["data"] == ["later readings"]
    assert "residuals.csv" in in_memory.files and "later readings" in in_memory.text(
        "residuals.csv")


def test_a_label_longer_than_a_line_is_refused_as_in_a_file(hexapod, readings):
    """Issue 36: a pose label (or a sensor name) that makes its row longer than the CSV
    reader takes (1 MiB) is refused from arrays as in a file, naming its row."""
    poses, sensors, lengths, labels = _arrays(readings)
    labels = list(labels)
    labels[4] = "x" * (1 << 20)
    with pytest.raises(cpm.InputError) as e:
        cpm.gauge_readings(hexapod, poses, sensors, lengths, pose_labels=labels)
    assert e.value.row == 4 and e.value.line == 6
    assert "the line is longer than 1048576 bytes" in str(e.value)
    sensors = list(sensors)
    sensors[2] = "s" * (1 << 20)
    with pytest.raises(cpm.InputError, match="line is longer") as e:
        cpm.gauge_readings(hexapod, poses, sensors, lengths)
    assert e.value.row == 2
    with pytest.raises(cpm.InputError, match="line is longer") as e:
        cpm.tracker_measurements(hexapod, np.zeros((2, 6)), np.tile([0, 0, 300, 1, 0, 0, 0],
                                 (2, 1)), pose_labels=["a", "b" * (1 << 20)])
    assert e.value.row == 1
