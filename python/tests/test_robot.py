"""cpm.Robot: reading, properties, round trip, errors."""
import numpy as np
import pytest

import cpm
from conftest import CUBE, HEXAPOD, MALFORMED


def test_hexapod_properties():
    r = cpm.Robot.from_toml(HEXAPOD)
    assert r.num_links == 6
    assert r.base_joints_mm.shape == (6, 3) and r.platform_joints_mm.shape == (6, 3)
    assert r.base_joints_mm.dtype == np.float64
    # A hexapod's base joints lie off its centre, at distinct places.
    radii = np.linalg.norm(r.base_joints_mm[:, :2], axis=1)
    assert np.all(radii > 10) and len(np.unique(np.round(r.base_joints_mm, 6), axis=0)) == 6
    assert len(r.links) == 6 and set(r.links[0]) == {"base_mm", "platform_mm",
                                                     "length_at_zero_mm", "mm_per_unit"}
    assert r.sensor_names == [s["name"] for s in r.sensors] and len(r.sensor_names) >= 1
    assert r.home.shape == (6,) and r.home[2] > 0
    assert r.file == str(HEXAPOD) and r.path == HEXAPOD
    d = r.description
    assert len(d["link"]) == 6 and d["link"][0]["base_mm"] == list(r.links[0]["base_mm"])


def test_round_trip_through_text():
    r = cpm.Robot.from_toml(CUBE)
    text = r.to_toml()
    assert text == CUBE.read_text()
    r2 = cpm.Robot.from_text(text, "copy.toml")
    assert r2.file == "copy.toml" and r2.path is None
    np.testing.assert_array_equal(r.base_joints_mm, r2.base_joints_mm)
    np.testing.assert_array_equal(r.platform_joints_mm, r2.platform_joints_mm)


def test_to_toml_writes_a_file(tmp_path):
    r = cpm.Robot.from_toml(HEXAPOD)
    p = tmp_path / "h.toml"
    r.to_toml(p)
    assert cpm.Robot.from_toml(p).sensor_names == r.sensor_names


def test_bad_description_is_an_input_error_with_line_and_field():
    with pytest.raises(cpm.InputError) as e:
        cpm.Robot.from_toml(MALFORMED / "robot_duplicate_sensor.toml")
    assert isinstance(e.value, cpm.CpmError) and isinstance(e.value, ValueError)
    assert e.value.file == str(MALFORMED / "robot_duplicate_sensor.toml")
    assert str(e.value).startswith(e.value.file)


def test_missing_file_is_an_io_error(tmp_path):
    with pytest.raises(cpm.CpmIOError) as e:
        cpm.Robot.from_toml(tmp_path / "nope.toml")
    assert isinstance(e.value, OSError)


def test_text_error_names_the_given_name():
    with pytest.raises(cpm.InputError) as e:
        cpm.Robot.from_text("[[link]]\nbase_mm = [1, 2]\n", "mine.toml")
    assert e.value.file == "mine.toml" and str(e.value).startswith("mine.toml")
