"""The commands of ``cpm`` (``docs/cli.md``) as functions.

Keyword arguments are the command's options with ``_`` for ``-`` (``sigma_um=1`` is
``--sigma-um 1``, ``from_home=True`` is ``--from-home``, a list repeats an option); the
command's own parser reads them, so names, defaults and errors are the command's. Robots and
measurements may be objects or paths. ``out=`` writes the command's outputs where the command
would (all or nothing); without it they are made in a scratch directory and kept in memory.

Interrupting (Ctrl-C) raises ``KeyboardInterrupt`` at once, but the command's work cannot be
stopped from outside: it finishes in the background, and a command given ``out=`` still
commits its outputs there when it finishes (all or nothing), as the command would have;
:func:`calibrate` is the exception and writes nothing once interrupted.

:func:`calibrate` runs the workflow's job on the campaign in memory
(``cpm_workflow::memory``): the robot as loaded, measurements made from arrays or tables as
they were read (read again from memory only when the fit needs other read options), files by
their paths; no scratch file, no argument vector. Two or more tracker sets of which some were
made in memory are registered together only when read from files: such a campaign goes
through scratch files and the command's parser, as every campaign did before. For the other
commands, measurements made from arrays or tables (and robots made from text) reach the
command as files in a scratch directory; errors name them by their names (and rows), and the
outputs name the scratch file.
"""
from __future__ import annotations

import csv
import html as _html
import io
import json
import os
import warnings as _warnings
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _cpm
from ._data import Measurements, _Source, as_measurements
from ._robot import PathLike, Robot, Scratch
from .errors import CpmError, CpmWarning, InputError, UsageError

__all__ = [
    "calibrate", "refine", "validate", "compensate", "design", "simulate",
    "identifiability", "export", "effect_names",
    "CalibrationResult", "RefineResult", "ValidationResult", "CompensationResult",
    "DesignResult", "Identifiability",
]

# Options whose value is one comma-separated list (a Python list is joined).
_JOINED = {"effects", "candidates"}


def effect_names() -> List[str]:
    """The effects ``effects=[...]`` knows (besides the pose map terms ``pose_map_*``)."""
    return list(_cpm.effect_names())


def _robot(r: Union[Robot, PathLike]) -> Robot:
    return r if isinstance(r, Robot) else Robot.from_toml(r)


def _argv(command: str, scratch: Scratch, options: Dict[str, Any]) -> List[str]:
    """``--option value`` for each keyword argument (None and False left out)."""
    argv = [command]
    for key, value in options.items():
        if value is None or value is False:
            continue
        flag = "--" + key.replace("_", "-")
        if value is True:
            argv.append(flag)
            continue
        if isinstance(value, Robot):
            argv += [flag, value._cli_path(scratch)]
            continue
        if isinstance(value, Measurements):
            for p in value._cli_paths(scratch):
                argv += [flag, p]
            continue
        if key == "tolerances" and isinstance(value, dict):
            # {"link_scale": 20000, "installation_errors": float("inf")} -> --tolerance G=V
            flag = "--tolerance"
            value = [f"{k}={'inf' if np.isinf(v) else repr(float(v))}" for k, v in value.items()]
        if key == "truth_effect" and isinstance(value, dict):
            value = [f"{k}=" + ",".join(repr(float(v)) for v in np.atleast_1d(vs))
                     for k, vs in value.items()]
        if isinstance(value, (list, tuple, np.ndarray)):
            items = []
            for v in value:
                if isinstance(v, Measurements):
                    items += v._cli_paths(scratch)
                else:
                    items.append(_text(v))
            if key in _JOINED:
                argv += [flag, ",".join(items) if items else "none"]
            else:
                for v in items:
                    argv += [flag, v]
            continue
        argv += [flag, _text(value)]
    return argv


def _text(v: Any) -> str:
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, os.PathLike):
        return os.fspath(v)
    return str(v)


def _data(data: Any, robot: Robot) -> Any:
    """Measurements for ``--data``: paths go to the command as they are (it reads them, with
    its checks and errors); arrays and tables were read into :class:`Measurements`."""
    if isinstance(data, (str, os.PathLike, Measurements)):
        return [data]
    if isinstance(data, (list, tuple)):
        if not data:
            raise UsageError("data: no measurements")
        return list(data)
    return [as_measurements(data, robot)]


def _run(argv: List[str], scratch: Scratch) -> Tuple[str, Optional[str]]:
    try:
        out, trouble = _cpm.run_command(argv)
    except CpmError as e:
        raise scratch.fix(e) from None
    if trouble:
        _warnings.warn(trouble, CpmWarning, stacklevel=3)
    return out, trouble


def _read_dir(d: Path) -> Dict[str, bytes]:
    files: Dict[str, bytes] = {}
    for p in sorted(d.rglob("*")):
        if p.is_file() and not p.name.startswith(".cpm-"):
            files[p.relative_to(d).as_posix()] = p.read_bytes()
    return files


def _out_dir(out: Optional[PathLike], scratch: Scratch, name: str) -> Path:
    return Path(out) if out is not None else scratch.path / name


def _csv_rows(text: str) -> Tuple[List[str], List[List[str]]]:
    """Header and rows of a CSV file written by cpm (``#`` comments skipped)."""
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    return (rows[0], rows[1:]) if rows else ([], [])


def _columns(text: str, names: Sequence[str]) -> np.ndarray:
    header, rows = _csv_rows(text)
    idx = [header.index(n) for n in names]
    return np.array([[float(r[i]) for i in idx] for r in rows], dtype=float).reshape(
        len(rows), len(names))


def _poses_file(poses: Any, scratch: Scratch) -> str:
    """A pose list file for ``poses``: a path, or an array ``(n, 6)`` (x, y, z mm; roll,
    pitch, yaw deg)."""
    if isinstance(poses, (str, os.PathLike)):
        return os.fspath(poses)
    a = np.asarray(poses, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 6:
        raise UsageError(f"poses has shape {a.shape}, expected (n, 6)")
    lines = ["pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg"]
    lines += [",".join([str(k + 1)] + [repr(float(v)) for v in row]) for k, row in enumerate(a)]
    return scratch.write("poses.csv", "\n".join(lines) + "\n", "poses", arrays=True)


def _iframe(page: str, height: int = 720) -> str:
    """A full HTML page shown in a notebook cell (its styles kept to itself)."""
    return (f'<iframe srcdoc="{_html.escape(page, quote=True)}" '
            f'style="width:100%;height:{height}px;border:1px solid #ddd" '
            f'sandbox="allow-same-origin"></iframe>')


class _Files:
    """A result made of the files a command wrote (``files``: name -> bytes)."""

    files: Dict[str, bytes]
    _title = "cpm"

    def text(self, name: str) -> str:
        """One output file as text."""
        return self.files[name].decode("utf-8")

    @property
    def figures(self) -> Dict[str, str]:
        """The SVG figures by file name."""
        return {k: v.decode("utf-8") for k, v in self.files.items() if k.endswith(".svg")}

    @property
    def markdown(self) -> str:
        """``report.md``."""
        return self.text("report.md")

    @property
    def html(self) -> str:
        """``report.html``: the report with its figures inline (self-contained page)."""
        return self.text("report.html")

    def _repr_html_(self) -> str:
        return _iframe(self.html)

    def save(self, directory: PathLike) -> List[Path]:
        """Writes the output files into ``directory`` (created)."""
        d = Path(directory)
        written = []
        for name, data in self.files.items():
            p = d / name
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes(data)
            written.append(p)
        return written


class Identifiability:
    """What the data identify: rank, singular values, the parameters determined on their
    own, and the blind directions in words."""

    def __init__(self, d: Dict[str, Any]) -> None:
        self.rank: int = d["rank"]
        self.num_params: int = d["num_params"]
        self.singular_values: np.ndarray = d["singular_values"]
        self.determined: np.ndarray = np.asarray(d["determined"], dtype=bool)
        self.blind_directions: List[Tuple[str, int]] = list(d["blind_directions"])
        self.unexplained_null_dimensions: int = d["unexplained_null_dimensions"]
        self.rank_rtol: float = d["rank_rtol"]
        self.summary: str = d["identifiability_summary"]

    def __repr__(self) -> str:
        return self.summary


class CalibrationResult(_Files):
    """The result of :func:`calibrate`: the numbers of ``calibration.json`` as arrays (um),
    the covariance, what the data identify, and every output of ``cpm calibrate``
    (``files``; ``to_json()`` is ``calibration.json``, ``_repr_html_`` is ``report.html``)."""

    def __init__(self, d: Dict[str, Any]) -> None:
        self._d = d
        self.files = dict(d["files"])
        self.parameter_names: List[str] = list(d["parameter_names"])
        self.estimates_um: np.ndarray = d["estimates_um"]
        self.std_um: np.ndarray = d["std_um"]
        self.minimum_norm_um: np.ndarray = d["minimum_norm_um"]
        self.covariance: np.ndarray = d["covariance"]
        self.identifiability = Identifiability(d)
        self.residuals_um: np.ndarray = d["residuals_um"]
        self.outliers: List[int] = list(d["outliers"])
        self.sigma_um: float = d["sigma_um"]
        self.sigma_estimated: bool = d["sigma_estimated"]
        self.residual_rms_um: float = d["residual_rms_um"]
        self.initial_rms_um: float = d["initial_rms_um"]
        self.simulated: bool = d["simulated"]
        self.converged: bool = d["converged"]
        self.termination: str = d["termination"]
        self.solver: str = d["solver"]
        self.warnings: List[str] = list(d["warnings"])
        self.trouble: Optional[str] = d["trouble"]
        self.written: List[str] = list(d["written"])
        #: Seconds spent by part, for a calibration from memory: ``job`` (reading what was
        #: not read yet, the fit and its outputs), ``solver`` (the final least-squares
        #: solve), ``total`` (the job and the results made ready for Python).
        self.timings: Dict[str, float] = dict(d.get("timings") or {})

    @property
    def determined(self) -> np.ndarray:
        return self.identifiability.determined

    @property
    def registration(self) -> Optional[Dict[str, Any]]:
        """The automatic registration of tracker files (``calibration.json``
        ``registration``), or None."""
        return json.loads(self.to_json()).get("registration")

    @property
    def noise_by_kind(self) -> List[Dict[str, Any]]:
        """The noise of each kind of observation (each gauge, tracker positions and
        orientations, point targets, inclinometer angles): the one the fit weighed it with
        (``assumed``) and the one its own residual shows (``estimated``), in ``unit``
        (``calibration.json`` ``noise_by_kind``; ``noise_per_kind=True`` weighs by the
        estimates)."""
        return list(json.loads(self.to_json())["noise_by_kind"])

    @property
    def calibrated_robot(self) -> Robot:
        """``calibrated.toml``: the calibrated machine as a robot description."""
        return Robot.from_text(self.text("calibrated.toml"), "calibrated.toml")

    def to_json(self) -> str:
        """``calibration.json``, as ``cpm calibrate`` writes it."""
        return self.text("calibration.json")

    def observation_origin(self, k: int) -> Optional[Tuple[str, int, str]]:
        """Where observation ``k`` (of ``residuals_um``) came from: file, line, what."""
        o = self._d["observation_origin"][k]
        return None if o is None else tuple(o)

    def to_pandas(self) -> Any:
        """Estimates and standard deviations per parameter as a DataFrame."""
        import pandas as pd

        return pd.DataFrame({"estimate_um": self.estimates_um, "std_um": self.std_um,
                             "determined": self.determined,
                             "minimum_norm_um": self.minimum_norm_um},
                            index=pd.Index(self.parameter_names, name="parameter"))

    def __repr__(self) -> str:
        sim = "SIMULATED data: " if self.simulated else ""
        return (f"<CalibrationResult {sim}rank {self.identifiability.rank} of "
                f"{self.identifiability.num_params}, residual RMS {self.residual_rms_um:.3f} um;"
                f" {self.termination}>")


def calibrate(
    robot: Union[Robot, PathLike],
    data: Any,
    effects: Optional[Union[Sequence[str], str]] = None,
    robust: Optional[str] = None,
    sigma_um: Optional[float] = None,
    *,
    out: Optional[PathLike] = None,
    **options: Any,
) -> CalibrationResult:
    """``cpm calibrate``: fits the 36 installation errors and the effects (``effects``: a list
    or ``"a,b"``; ``[]`` for none; default the description's) to the measurements.

    ``robust="huber:K"`` (``cauchy:K``, ``tukey:K``), ``sigma_um`` (the sensor noise), and the
    other options of the command by name (``pose_sigma_um``, ``orientation_sigma_urad``,
    ``minimum_norm``, ``max_iterations``, ``formulation``). The estimator's prior:
    ``tolerances={"installation_errors": 2000, "link_scale": 50000}`` (each group's a-priori
    standard deviation in its unit, ``float("inf")`` frees it), ``hold=["installation_errors"]``
    (groups kept at nominal), ``tolerance_limit=3`` (tolerances an undetermined parameter may
    reach before it is held there; default the description's, else 1), ``no_prior=True``
    (plain least squares);
    ``tracker_residuals="auto"|"pose"|"legs"`` for 6-D tracker poses (docs/estimation.md). With ``out`` the outputs are written
    there as the command writes them. The GIL is released during the fit; Ctrl-C raises
    ``KeyboardInterrupt`` at once (the fit itself finishes in the background and is dropped;
    nothing is written).

    A fit that did not converge (or a robust fit that failed) is returned with ``trouble`` set
    and a :class:`cpm.CpmWarning` (the command's exit code 1)."""
    r = _robot(robot)
    items = _data(data, r)
    d = _calibrate_in_memory(r, items, effects, robust, sigma_um, out, options)
    if d is None:
        d = _calibrate_from_files(r, items, effects, robust, sigma_um, out, options)
    result = CalibrationResult(dict(d))
    if result.trouble:
        _warnings.warn(result.trouble, CpmWarning, stacklevel=2)
    return result


# Options of `cpm calibrate` whose values are numbers of um, urad (floats) or counts (ints).
_FLOATS = {"sigma_um", "pose_sigma_um", "orientation_sigma_urad", "tolerance_limit"}
_INTS = {"max_iterations"}


def _memory_options(effects: Any, robust: Any, sigma_um: Any,
                    options: Dict[str, Any]) -> Dict[str, Any]:
    """The options of :func:`calibrate` as the workflow's (``--option`` by name, values of
    their types): what the command's parser would have made of the argument vector."""
    given: Dict[str, Any] = dict(effects=effects, sigma_um=sigma_um, robust=robust)
    given.update(options)
    out: Dict[str, Any] = {}
    for key, value in given.items():
        if value is None or value is False:
            continue
        flag = "--" + key.replace("_", "-")
        if key == "effects":
            if isinstance(value, str):
                out[key] = value
            else:
                names = [str(v) for v in value]
                out[key] = ",".join(names) if names else "none"
        elif key == "tolerances" and isinstance(value, dict):
            out.setdefault("tolerance", [])
            out["tolerance"] += [f"{k}={'inf' if np.isinf(v) else repr(float(v))}"
                                 for k, v in value.items()]
        elif key in ("tolerance", "hold"):
            items = [value] if isinstance(value, str) else list(value)
            out.setdefault(key, [])
            out[key] += [_text(v) for v in items]
        elif key == "noise_per_kind" and value is True:
            out[key] = "on"
        elif key in _FLOATS or key in _INTS:
            try:
                out[key] = int(value) if key in _INTS else float(value)
            except (TypeError, ValueError):
                raise UsageError(f"invalid value {value!r} for '{flag}'") from None
            if key in _INTS and out[key] < 0:
                raise UsageError(f"invalid value {value!r} for '{flag}'")
        elif value is True:
            out[key] = True
        elif isinstance(value, (list, tuple, np.ndarray)):
            raise UsageError(f"{flag}: one value expected, got {value!r}")
        else:
            out[key] = _text(value)
    return out


def _calibrate_in_memory(r: Robot, items: List[Any], effects: Any, robust: Any, sigma_um: Any,
                         out: Optional[PathLike], options: Dict[str, Any]) -> Optional[Any]:
    """:func:`calibrate` on the campaign in memory (the workflow's job, no files, no argument
    vector): measurements from arrays as read, files by their paths. ``None`` when the
    campaign must be read from files (several tracker sets, some made in memory)."""
    sources: List[Any] = []
    arrays: set = set()
    for item in items:
        if isinstance(item, Measurements):
            for s in item.sources:
                handle = s.info.get("handle")
                if s.path is not None:
                    sources.append(s.path)
                elif handle is not None:
                    sources.append(handle)
                    if s.arrays:
                        arrays.add(s.name)
                else:
                    return None
        elif isinstance(item, (str, os.PathLike)):
            sources.append(os.fspath(item))
        else:
            return None
    opts = _memory_options(effects, robust, sigma_um, options)
    target = os.fspath(out) if out is not None else None
    try:
        return _cpm.calibrate_memory(r._h, sources, opts, target, out is not None)
    except InputError as e:
        if e.file in arrays and e.line is not None and e.line >= 2 and e.row is None:
            raise InputError(str(e), e.file, e.line, e.field, e.line - 2) from None
        raise


def _calibrate_from_files(r: Robot, items: List[Any], effects: Any, robust: Any, sigma_um: Any,
                          out: Optional[PathLike], options: Dict[str, Any]) -> Any:
    """:func:`calibrate` through the command's parser, the measurements made in memory
    written to a scratch directory (a campaign :func:`_calibrate_in_memory` does not take)."""
    with Scratch() as scratch:
        opts: Dict[str, Any] = dict(robot=r, data=items, effects=effects, sigma_um=sigma_um,
                                    robust=robust)
        opts.update(options)
        commit = out is not None
        opts["out"] = os.fspath(out) if commit else os.fspath(scratch.path / "cal")
        if effects is not None and not isinstance(effects, str) and len(effects) == 0:
            opts["effects"] = "none"
        argv = _argv("calibrate", scratch, opts)
        try:
            return _cpm.calibrate(argv, commit, dict(scratch.names))
        except CpmError as e:
            raise scratch.fix(e) from None


class RefineResult(_Files):
    """The result of :func:`refine`: ``refine.json`` (``doc``, ``steps``), the final fit's
    ``calibration.json`` (``calibration``), ``calibrated.toml`` (``calibrated_robot``) and the
    figures, among them ``residuals_before_after.svg``."""

    def __init__(self, files: Dict[str, bytes], trouble: Optional[str]) -> None:
        self.files = files
        self.trouble = trouble
        self.doc: Dict[str, Any] = json.loads(self.text("refine.json"))
        self.calibration: Dict[str, Any] = json.loads(self.text("calibration.json"))

    @property
    def steps(self) -> List[Dict[str, Any]]:
        """The effects added, one per step, with their tests."""
        return list(self.doc.get("steps", []))

    @property
    def calibrated_robot(self) -> Robot:
        return Robot.from_text(self.text("calibrated.toml"), "calibrated.toml")

    def to_json(self) -> str:
        return self.text("refine.json")

    def __repr__(self) -> str:
        names = [s.get("effect") for s in self.steps]
        return f"<RefineResult added {names}>"


def refine(robot: Union[Robot, PathLike], data: Any, *, out: Optional[PathLike] = None,
           **options: Any) -> RefineResult:
    """``cpm refine``: calibrates, then adds the effects the residual asks for, one at a time
    (options by name: ``effects``, ``candidates``, ``max_steps``, ``alpha``, ``folds``,
    ``pose_map_degree``, ``sigma_um``, ``robust``, ...)."""
    r = _robot(robot)
    with Scratch() as scratch:
        d = _out_dir(out, scratch, "refined")
        _, trouble = _run(_argv("refine", scratch, dict(robot=r, data=_data(data, r), out=d, json=True,
                                                         **options)), scratch)
        files = _read_dir(d)
    return RefineResult(files, trouble)


class ValidationResult(_Files):
    """The result of :func:`validate`: ``summary`` (the command's ``--json``), and the
    per-group errors; ``_repr_html_`` renders ``validation.md`` with its figure."""

    def __init__(self, summary: Dict[str, Any], files: Dict[str, bytes]) -> None:
        self.summary = summary
        self.files = files

    @property
    def calibrated_rms_um(self) -> float:
        return float(self.summary["calibrated"]["rms_um"])

    @property
    def reference_rms_um(self) -> float:
        return float(self.summary["reference"]["rms_um"])

    @property
    def groups(self) -> List[Dict[str, Any]]:
        return list(self.summary.get("groups", []))

    @property
    def markdown(self) -> str:
        return self.text("report.md")

    @property
    def html(self) -> str:
        return _cpm.render_html("cpm validation", self.markdown, self.figures)

    def __repr__(self) -> str:
        if "calibrated" in self.summary:
            return (f"<ValidationResult held-out RMS {self.calibrated_rms_um:.3f} um "
                    f"(reference {self.reference_rms_um:.3f} um)>")
        return f"<ValidationResult {self.summary.get('compensated')}>"


def validate(robot: Optional[Union[Robot, PathLike]], reference: Union[Robot, PathLike],
             data: Any = None, *, out: Optional[PathLike] = None, **options: Any
             ) -> ValidationResult:
    """``cpm validate``: the calibrated ``robot`` against ``reference`` on held-out
    ``data``; or, with ``commands=`` and ``truth=`` (and ``robot=None``), a compensation
    checked end to end on a simulated machine."""
    ref = _robot(reference)
    rob = None if robot is None else _robot(robot)
    with Scratch() as scratch:
        m = None if data is None else _data(data, rob if rob is not None else ref)
        d = _out_dir(out, scratch, "validation")
        opts: Dict[str, Any] = dict(robot=rob, reference=ref, data=m, out=d, json=True)
        opts.update(options)
        text, _ = _run(_argv("validate", scratch, opts), scratch)
        files = _read_dir(d)
        doc = scratch.named(json.loads(text))
    return ValidationResult(doc, files)


class CompensationResult:
    """The result of :func:`compensate`: the commands (``readings`` per target, in the links'
    units; ``targets``), the CSV as written, and the command's ``--json`` summary."""

    def __init__(self, csv_text: str, summary: Dict[str, Any], num_links: int) -> None:
        self.csv = csv_text
        self.summary = summary
        header, rows = _csv_rows(csv_text)
        self.labels = [r[header.index("pose")] for r in rows] if "pose" in header else []
        self.targets = _columns(csv_text, ["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg",
                                           "yaw_deg"])
        self.readings = _columns(csv_text, [f"reading_{k}" for k in range(1, num_links + 1)])

    def to_pandas(self) -> Any:
        import pandas as pd

        return pd.read_csv(io.StringIO(self.csv), comment="#")

    def __repr__(self) -> str:
        return f"<CompensationResult {len(self.readings)} targets>"


def compensate(robot: Union[Robot, PathLike], poses: Any, *, out: Optional[PathLike] = None,
               **options: Any) -> CompensationResult:
    """``cpm compensate``: the link readings to command for target ``poses`` (a pose list
    file, or an array ``(n, 6)``: x, y, z mm; roll, pitch, yaw deg); options
    ``temperature_c``, ``from_home``."""
    r = _robot(robot)
    with Scratch() as scratch:
        target = Path(out) if out is not None else scratch.path / "commands.csv"
        text, _ = _run(_argv("compensate", scratch, dict(
            robot=r, poses=_poses_file(poses, scratch), out=target, json=True, **options)),
            scratch)
        csv_text = target.read_text(encoding="utf-8")
    return CompensationResult(csv_text, json.loads(text) if text.strip() else {}, r.num_links)


class DesignResult(_Files):
    """The result of :func:`design`: ``design.json`` (``doc``), the designed robot
    (``robot``, ``robot.toml``: the chosen sensors), the poses (``poses``), the report."""

    def __init__(self, files: Dict[str, bytes], directory: Optional[Path]) -> None:
        self.files = files
        self.directory = directory
        self.doc: Dict[str, Any] = json.loads(self.text("design.json"))

    @property
    def robot(self) -> Robot:
        """The description with the chosen sensors (``robot.toml``)."""
        if self.directory is not None:
            return Robot.from_toml(self.directory / "robot.toml")
        return Robot.from_text(self.text("robot.toml"), "robot.toml")

    @property
    def poses(self) -> np.ndarray:
        """The poses to drive, ``(n, 6)`` (``poses.csv``; with setups, every plan's)."""
        names = ["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"]
        if "poses.csv" in self.files:
            return _columns(self.text("poses.csv"), names)
        plans = [k for k in self.files if k.startswith("plans/")]
        return np.concatenate([_columns(self.text(k), names) for k in sorted(plans)]) \
            if plans else np.zeros((0, 6))

    def __repr__(self) -> str:
        return f"<DesignResult {sorted(self.files)}>"


def design(robot: Union[Robot, PathLike], *, out: Optional[PathLike] = None,
           **options: Any) -> DesignResult:
    """``cpm design``: sensor sockets and poses for a campaign (options by name:
    ``readings``, ``base_sockets``, ``platform_sockets``, ``criterion``, ``stroke_mm``, ...).
    Without ``out`` the design lives in memory (``result.robot`` is read from its text)."""
    r = _robot(robot)
    with Scratch() as scratch:
        d = _out_dir(out, scratch, "design")
        _run(_argv("design", scratch, dict(robot=r, out=d, json=True, **options)), scratch)
        files = _read_dir(d)
    return DesignResult(files, Path(out) if out is not None else None)


def simulate(robot: Union[Robot, PathLike], *, out: Optional[PathLike] = None,
             **options: Any) -> Measurements:
    """``cpm simulate``: a simulated campaign, labelled simulated (options by name: ``plan``,
    ``circle``, ``random``, ``truth``, ``paper_table2``, ``truth_effect`` (a list of
    ``"effect=v1,v2"`` or a dict), ``noise``, ``seed``, ``measure``, ``sensors``, ...).
    ``plan`` may be a pose array ``(n, 6)``. Returns the measurements (read back against
    ``robot``); with ``out`` the file is written there."""
    r = _robot(robot)
    with Scratch() as scratch:
        if "plan" in options and options["plan"] is not None:
            options["plan"] = _poses_file(options["plan"], scratch)
        for key in ("truth",):
            if isinstance(options.get(key), Robot):
                options[key] = options[key]._cli_path(scratch)
        target = Path(out) if out is not None else scratch.path / "simulated.csv"
        _run(_argv("simulate", scratch, dict(robot=r, out=target, **options)), scratch)
        if out is not None:
            from ._data import read_measurements

            return read_measurements(target, r)
        text = target.read_text(encoding="utf-8")
    info = _cpm.read_text(text, "simulated.csv", r._h)
    return Measurements([_Source("simulated.csv", None, text, dict(info))])


def identifiability(robot: Union[Robot, PathLike], data: Any = None,
                    **options: Any) -> Dict[str, Any]:
    """``cpm identifiability --json``: rank, singular values, blind directions in words,
    Cramér-Rao bounds, for measurements (``data``) or a plan (``plan``, ``circle``,
    ``random``)."""
    r = _robot(robot)
    with Scratch() as scratch:
        m = None if data is None else _data(data, r)
        if options.get("plan") is not None:
            options["plan"] = _poses_file(options["plan"], scratch)
        text, _ = _run(_argv("identifiability", scratch, dict(robot=r, data=m, json=True,
                                                               **options)), scratch)
        return scratch.named(json.loads(text))


def export(robot: Union[Robot, PathLike], format: str = "linuxcnc", **options: Any) -> str:
    """``cpm export``: the joints for a machine controller (LinuxCNC genhexkins HAL text)."""
    r = _robot(robot)
    with Scratch() as scratch:
        text, _ = _run(_argv("export", scratch, dict(format=format, robot=r, **options)),
                       scratch)
    return text
