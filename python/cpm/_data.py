"""Measurements: files read by the readers of ``cpm`` (``docs/formats.md``); gauge readings
and tracker measurements from numpy arrays read as values with the checks and errors of the
file readers (no text); pandas tables written as their file formats and read by the same
readers. Every route gets the same checks (units, reachability, consistency, the
registration of tracker sets) and the same errors."""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, List, Optional, Sequence, Union

import numpy as np

from . import _cpm
from ._robot import PathLike, Robot
from .errors import InputError, UsageError, _warn

__all__ = [
    "Measurements",
    "read_measurements",
    "gauge_readings",
    "tracker_measurements",
    "measurements_from_frame",
]


class _Info(dict):  # type: ignore[type-arg]
    """The dict of measurements read from text or arrays: ``file``, ``kind``, ``simulated``
    and ``handle`` at once, the arrays (the handle's ``summary()``) when first asked for."""

    def __init__(self, brief: Dict[str, Any]) -> None:
        super().__init__(brief)
        self._full = "handle" not in brief

    def _fill(self) -> None:
        if not self._full:
            self._full = True
            self.update(dict.__getitem__(self, "handle").summary())

    def __missing__(self, key: str) -> Any:
        if self._full:
            raise KeyError(key)
        self._fill()
        return self[key]

    def get(self, key: str, default: Any = None) -> Any:
        try:
            return self[key]
        except KeyError:
            return default


def _filled(name: str) -> Any:
    """``dict``'s method ``name``, on the dict filled first (a whole view of an ``_Info``)."""
    method = getattr(dict, name)

    def call(self: "_Info", *args: Any) -> Any:
        self._fill()
        return method(self, *args)

    call.__name__ = name
    return call


for _name in ("__contains__", "__iter__", "__len__", "keys", "items", "values"):
    setattr(_Info, _name, _filled(_name))
del _name


@dataclass
class _Source:
    name: str
    path: Optional[str]
    text: Optional[str]
    info: Dict[str, Any]
    arrays: bool = False


@dataclass
class Measurements:
    """One or more measurement files (gauge readings, tracker poses) for one robot.

    Add two with ``+`` to fit them together (``cpm calibrate --data a.csv --data b.csv``).
    The arrays give what was read: per reading (``reading_pose``, ``reading_sensor``,
    ``lengths_mm``), per pose (``poses``: x, y, z mm, roll, pitch, yaw deg) and per tracker
    measurement (``measured_poses``: x, y, z mm, qw, qx, qy, qz).
    """

    sources: List[_Source] = field(default_factory=list)

    def __add__(self, other: "Measurements") -> "Measurements":
        if not isinstance(other, Measurements):
            return NotImplemented
        return Measurements(self.sources + other.sources)

    @property
    def files(self) -> List[str]:
        """The files (or array sources) by name."""
        return [s.name for s in self.sources]

    @property
    def simulated(self) -> bool:
        """True when any source is simulated (labelled so in the file)."""
        return any(bool(s.info["simulated"]) for s in self.sources)

    @property
    def kinds(self) -> List[str]:
        """``"gauge"`` or ``"tracker"`` per source."""
        return [s.info["kind"] for s in self.sources]

    def _cat(self, key: str) -> np.ndarray:
        parts = [np.asarray(s.info[key]) for s in self.sources]
        return np.concatenate(parts) if parts else np.zeros(0)

    @property
    def poses(self) -> np.ndarray:
        """Commanded (gauge) or measured (tracker) poses, ``(poses, 6)``: x, y, z mm; roll,
        pitch, yaw deg (all sources one after the other)."""
        return np.concatenate([s.info["poses"] for s in self.sources]) if self.sources \
            else np.zeros((0, 6))

    @property
    def lengths_mm(self) -> np.ndarray:
        """The gauge readings, mm."""
        return self._cat("lengths_mm")

    @property
    def reading_sensor(self) -> List[str]:
        """The sensor of each gauge reading."""
        return [n for s in self.sources for n in s.info["reading_sensor"]]

    @property
    def measured_poses(self) -> np.ndarray:
        """Tracker measurements, ``(n, 7)``: x, y, z mm; qw, qx, qy, qz."""
        return np.concatenate([s.info["measured_poses"] for s in self.sources]) \
            if self.sources else np.zeros((0, 7))

    @property
    def num_readings(self) -> int:
        return int(sum(len(s.info["lengths_mm"]) for s in self.sources))

    @property
    def num_poses(self) -> int:
        return int(sum(len(s.info["poses"]) for s in self.sources))

    def to_pandas(self) -> Any:
        """The gauge readings as a pandas DataFrame (one row per reading: file, line, pose,
        sensor, x_mm .. yaw_deg, length_mm)."""
        import pandas as pd

        frames = []
        for s in self.sources:
            i = s.info
            k = np.asarray(i["reading_pose"], dtype=int)
            p = np.asarray(i["poses"])[k] if len(k) else np.zeros((0, 6))
            labels = [i["pose_labels"][j] for j in k]
            frames.append(pd.DataFrame({
                "file": s.name, "line": i["reading_lines"], "pose": labels,
                "sensor": i["reading_sensor"], "x_mm": p[:, 0], "y_mm": p[:, 1],
                "z_mm": p[:, 2], "roll_deg": p[:, 3], "pitch_deg": p[:, 4],
                "yaw_deg": p[:, 5], "length_mm": i["lengths_mm"]}))
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    def _option_paths(self, key: str) -> List[str]:
        """The files these measurements were read from, for an option that takes paths
        (measurements the job takes in memory go as ``data``)."""
        held = [s.name for s in self.sources if s.path is None]
        if held:
            raise UsageError(f"{key}: the measurements {held} are held in memory only; this "
                             "option takes the paths of measurement files")
        return [s.path for s in self.sources if s.path is not None]

    def __repr__(self) -> str:
        sim = ", SIMULATED" if self.simulated else ""
        return (f"Measurements({self.files}, {self.num_readings} gauge readings, "
                f"{len(self.measured_poses)} tracker poses{sim})")


def _as_robot(robot: Any) -> Robot:
    """``robot`` as a :class:`Robot`: itself, or the description read from its path."""
    if isinstance(robot, Robot):
        return robot
    if isinstance(robot, (str, os.PathLike)):
        return Robot.from_toml(robot)
    raise TypeError("robot: expected a cpm.Robot or the path of a robot description (.toml), "
                    f"got {type(robot).__name__}")


def _is_frame(data: Any) -> bool:
    """True for a pandas DataFrame (pandas not imported for it)."""
    pd = sys.modules.get("pandas")
    return pd is not None and isinstance(data, pd.DataFrame)


def _warn_excluded(info: Any) -> None:
    """The command's warning for each pose left out while reading (unreachable)."""
    for message in info.get("excluded") or ():
        _warn(message)


def read_measurements(path: PathLike, robot: Union[Robot, PathLike]) -> Measurements:
    """Reads a measurement file (gauge readings or tracker poses, told from its header)
    against ``robot`` (a :class:`Robot` or the path of its description), with the checks of
    ``cpm calibrate --data``; errors are :class:`cpm.InputError` naming the file, line and
    field. A pose found unreachable is left out with the command's warning (a
    :class:`cpm.CpmWarning`)."""
    if _is_frame(path):
        raise TypeError("path: a DataFrame is not a file: cpm.measurements_from_frame(frame, "
                        "robot) reads it (cpm.calibrate takes it as it is)")
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError("path: expected the path of a measurement file (str or os.PathLike), "
                        f"got {type(path).__name__}")
    r = _as_robot(robot)
    p = os.fspath(path)
    info = dict(_cpm.read_file(p, r._h))
    _warn_excluded(info)
    return Measurements([_Source(p, p, None, info)])


def _row_error(e: InputError) -> InputError:
    """An error of measurements made from arrays, with the row of the arrays (line 2 is row
    0) when it names a line."""
    if e.line is not None and e.line >= 2:
        row = e.line - 2
        return InputError(f"{e} (row {row} of the arrays)", e.file, e.line, e.field, row)
    return e


def _from_text(text: str, name: str, robot: Robot, arrays: bool) -> Measurements:
    try:
        info = _cpm.read_text(text, name, robot._h)
    except InputError as e:
        if arrays:
            raise _row_error(e) from None
        raise
    _warn_excluded(info)
    return Measurements([_Source(name, None, text, _Info(info), arrays)])


def _from_arrays(read: Any, name: str) -> Measurements:
    """Measurements read from arrays as values by ``read()`` (no text), errors naming the
    row of the arrays."""
    try:
        info = read()
    except InputError as e:
        raise _row_error(e) from None
    _warn_excluded(info)
    return Measurements([_Source(name, None, None, _Info(info), True)])


def _real(x: Any, name: str) -> None:
    """Refuses complex numbers (numpy would drop their imaginary part with a warning)."""
    if np.iscomplexobj(x):
        raise UsageError(f"{name}: complex numbers; expected real numbers (give .real if the "
                         "imaginary part is to be dropped)")


def _float_array(x: Any, name: str, ndim: int, cols: Optional[int] = None) -> np.ndarray:
    """``x`` as float64 (float32, integers and non-contiguous arrays are converted), checked
    for its number of dimensions and columns; complex numbers are refused."""
    _real(x, name)
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise UsageError(f"{name}: not an array of numbers ({e})") from None
    if a.ndim != ndim or (cols is not None and a.shape[1] != cols):
        want = f"(n, {cols})" if cols is not None else ("(n,)" if ndim == 1 else f"{ndim}-D")
        raise UsageError(f"{name} has shape {a.shape}, expected {want}")
    return a


def gauge_readings(
    robot: Union[Robot, PathLike],
    poses: Any,
    sensors: Union[Sequence[str], str],
    lengths_mm: Any,
    *,
    pose_labels: Optional[Sequence[Any]] = None,
    time_s: Any = None,
    simulated: bool = False,
    name: str = "gauge readings",
) -> Measurements:
    """Gauge readings from arrays: commanded ``poses`` ``(n, 6)`` (x, y, z mm; roll, pitch,
    yaw deg), the ``sensors`` read (``n`` names, or one name for all), ``lengths_mm``
    ``(n,)``. Rows with the same ``pose_labels`` share a pose (default: every row its own
    pose). ``simulated=True`` labels simulated data (every result then says so).

    Read as values with the checks of the file reader of ``cpm`` and its errors (no text is
    made); an error's ``row`` is the row of the arrays. ``robot`` is a :class:`Robot` or the
    path of its description."""
    robot = _as_robot(robot)
    p = _float_array(poses, "poses", 2, 6)
    n = p.shape[0]
    lengths = _float_array(lengths_mm, "lengths_mm", 1)
    names = [sensors] * n if isinstance(sensors, str) else sensors
    t = None if time_s is None else _float_array(time_s, "time_s", 1)
    return _from_arrays(lambda: _cpm.gauge_rows(p, names, lengths, robot._h, name,
                                                pose_labels, t, bool(simulated)),
                        name)


def tracker_measurements(
    robot: Union[Robot, PathLike],
    readings: Any,
    poses: Any,
    *,
    pose_labels: Optional[Sequence[Any]] = None,
    time_s: Any = None,
    simulated: bool = False,
    name: str = "tracker measurements",
) -> Measurements:
    """Tracker measurements from arrays: the commanded link ``readings`` ``(n, links)`` (in
    the links' units) and the measured ``poses`` ``(n, 7)`` (x, y, z mm in the tracker's
    frame; unit quaternion qw, qx, qy, qz) or ``(n, 6)`` (x, y, z mm; roll, pitch, yaw deg,
    R = Rz(yaw) Ry(pitch) Rx(roll)). Rows with the same ``pose_labels`` are refused (one row
    per pose; default: the rows numbered from 1). ``simulated=True`` labels simulated data.

    Read as values with the checks of the file reader of ``cpm`` and its errors (no text is
    made; an error's ``row`` is the row of the arrays), registered and checked as ``cpm`` does
    a tracker file: the same numbers as a file give the same fit. ``robot`` is a
    :class:`Robot` or the path of its description."""
    robot = _as_robot(robot)
    r = _float_array(readings, "readings", 2, robot.num_links)
    p = _float_array(poses, "poses", 2)
    if p.shape[1] not in (6, 7):
        raise UsageError(f"poses has shape {p.shape}, expected (n, 7) (x, y, z mm, qw, qx, qy, "
                         "qz) or (n, 6) (x, y, z mm, roll, pitch, yaw deg)")
    t = None if time_s is None else _float_array(time_s, "time_s", 1)
    return _from_arrays(lambda: _cpm.tracker_rows(r, p, robot._h, name, pose_labels,
                                                  t, bool(simulated)),
                        name)


def measurements_from_frame(frame: Any, robot: Union[Robot, PathLike], name: str = "DataFrame") -> Measurements:
    """Measurements from a pandas DataFrame whose columns are those of a measurement file
    (``docs/formats.md``: e.g. ``pose, sensor, x_mm, .., yaw_deg, length_mm``); ``robot``
    a :class:`Robot` or the path of its description."""
    text = frame.to_csv(index=False)
    return _from_text(text, name, _as_robot(robot), arrays=True)


def as_measurements(data: Any, robot: Robot) -> Measurements:
    """``data`` as measurements: :class:`Measurements`, a path, a pandas DataFrame
    (:func:`measurements_from_frame`), or a list of them."""
    if isinstance(data, Measurements):
        return data
    if isinstance(data, (str, os.PathLike)):
        return read_measurements(data, robot)
    if _is_frame(data):
        return measurements_from_frame(data, robot)
    if isinstance(data, Iterable):
        out = Measurements()
        for d in data:
            out = out + as_measurements(d, robot)
        return out
    raise UsageError("data: expected Measurements, a path, a DataFrame or a list of them, got "
                     f"{type(data).__name__}")
