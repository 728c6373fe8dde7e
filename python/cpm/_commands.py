"""The commands of ``cpm`` (``docs/cli.md``) as functions.

Keyword arguments are the command's options with ``_`` for ``-`` (``sigma_um=1`` is
``--sigma-um 1``, ``from_home=True`` is ``--from-home``, a list gives an option several
values). Each command runs as the workflow's job (``cpm_workflow``), not through the command
line: the options go by name to the job's options struct, whose names and defaults are the
command's (``tests/workflow.rs`` checks that), and an unknown option or a value of the wrong
type is a :class:`cpm.UsageError` naming it. Robots and measurements may be objects or paths.
``out=`` writes the command's outputs where the command would (all or nothing); without it
they are made in memory.

Interrupting (Ctrl-C) raises ``KeyboardInterrupt`` at once and cancels the job: a fit stops
inside its iterations, and nothing is written.

:func:`calibrate`, :func:`refine`, :func:`validate` and :func:`identifiability` run on the
campaign in memory (``cpm_workflow::memory``): robots as loaded (from a file or from text),
measurements made from arrays or tables as they were read, files by their paths; every
command takes its robot as loaded. Pose arrays given as a plan (``plan=`` of
:func:`simulate` and :func:`identifiability`) or as :func:`compensate`'s targets go to the
job in memory too, named ``poses`` and read with the checks of a pose list file (an error's
``row`` is the row of the array). A ``truth=`` robot made from text, and the robots of a
compensation check (``validate(None, ...)``, which reads no measurements: of ``data`` only
the files are passed on), go as loaded. Nothing is written to a scratch folder: an option
that takes a file (``truth=`` as a robot read from its file, ``sockets=``, ``commands=``,
...) gets the path of one, and a robot or measurements held in memory only, given to such an
option, is a :class:`cpm.UsageError` naming it. Errors and reports name the inputs by their
names (and rows).
"""
from __future__ import annotations

import csv
import html as _html
import io
import json
import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _cpm
from ._data import Measurements, _Info, _Source, _float_array, _real, as_measurements
from ._robot import PathLike, Robot
from .errors import CpmError, InputError, UsageError, _in_keywords, _warn

__all__ = [
    "calibrate", "refine", "validate", "compensate", "design", "simulate",
    "identifiability", "export", "effect_names",
    "CalibrationResult", "RefineResult", "ValidationResult", "CompensationResult",
    "DesignResult", "Identifiability",
]

def effect_names() -> List[str]:
    """The effects ``effects=[...]`` knows (besides the pose map terms ``pose_map_*``)."""
    return list(_cpm.effect_names())


def _robot(r: Union[Robot, PathLike]) -> Robot:
    return r if isinstance(r, Robot) else Robot.from_toml(r)


def _renamed(options: Dict[str, Any]) -> Dict[str, str]:
    """The jobs' option names that the Python keywords given spell otherwise (messages name
    the keyword): ``tolerances={...}`` is the job's ``tolerance``."""
    return {"tolerance": "tolerances"} if "tolerances" in options else {}


def _said(d: Dict[str, Any], renamed: Dict[str, str]) -> None:
    """The job's warnings (the command's ``warning:`` lines: a pose left out, ...) and its
    trouble (the command's exit code 1, outputs written) as :class:`cpm.CpmWarning`."""
    for message in d.get("warned") or ():
        _warn(message, renamed)
    if d.get("trouble"):
        _warn(d["trouble"], renamed)


def _data(data: Any, robot: Optional[Robot]) -> Any:
    """Measurements for ``data``: paths go to the job as they are (it reads them, with its
    checks and errors); arrays and tables were read into :class:`Measurements` (a pandas
    DataFrame read as :func:`cpm.measurements_from_frame` reads it)."""
    if isinstance(data, (str, os.PathLike, Measurements)):
        return [data]
    if isinstance(data, (list, tuple)):
        if not data:
            raise UsageError("data: no measurements")
        return list(data)
    if robot is None:
        raise UsageError("data: measurements other than files are read against a robot: give "
                         "robot or reference")
    return [as_measurements(data, robot)]


def _sources(r: Robot, items: List[Any]) -> Tuple[List[Any], set]:
    """The measurements for a job on ``r`` in memory: read ones by their handles (as read),
    files by their paths; and the names of those made from arrays."""
    sources: List[Any] = []
    arrays: set = set()
    for item in items:
        if isinstance(item, Measurements):
            for s in item.sources:
                handle = s.info.get("handle")
                if s.path is not None:
                    sources.append(s.path)
                    continue
                if handle is None:
                    handle = _cpm.read_text(s.text, s.name, r._h)["handle"]
                sources.append(handle)
                if s.arrays:
                    arrays.add(s.name)
        else:
            sources.append(os.fspath(item))
    return sources, arrays


def _row_of(e: InputError, arrays: set) -> InputError:
    """An error in measurements made from arrays also says the row of the arrays."""
    if e.file in arrays and e.line is not None and e.line >= 2 and e.row is None:
        return InputError(str(e), e.file, e.line, e.field, e.line - 2)
    return e


def _value(key: str, value: Any) -> Any:
    """One option's value as the job takes it by name (JSON): robots and measurements as
    the paths of their files (the ones a job takes in memory are not options), paths as text,
    numpy numbers as numbers, lists as lists."""
    if isinstance(value, Robot):
        return value._option_path(key)
    if isinstance(value, Measurements):
        return value._option_paths(key)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, (complex, np.complexfloating)):
        _real(value, key)
    if isinstance(value, float) and not np.isfinite(value):
        raise UsageError(f"invalid value {value!r} for '{key}': not a finite number")
    if isinstance(value, (list, tuple, np.ndarray)):
        items: List[Any] = []
        for v in value:
            v = _value(key, v)
            items += v if isinstance(v, list) else [v]
        return items
    return value


def _tolerance_value(v: Any) -> Any:
    """A tolerance's value as JSON holds it: a number, or "inf" (any infinity frees the
    group) and "nan" (refused by the job as no tolerance > 0)."""
    v = float(v)
    return v if np.isfinite(v) else ("inf" if np.isinf(v) else "nan")


def _by_name(options: Dict[str, Any]) -> str:
    """The options of a command by name, as JSON text for the job (None and False left
    out: the command's defaults)."""
    out: Dict[str, Any] = {}
    for key, value in options.items():
        if value is None or value is False:
            continue
        if key == "tolerances" and isinstance(value, dict):
            # {"link_scale": 20000, "installation_errors": float("inf")} -> the typed
            # tolerances, {"group": G, "value": V} (JSON has no infinity: "inf").
            key = "tolerance"
            value = [{"group": str(k), "value": _tolerance_value(v)} for k, v in value.items()]
        elif key == "truth_effect" and isinstance(value, dict):
            value = [f"{k}=" + ",".join(repr(float(v)) for v in np.atleast_1d(vs))
                     for k, vs in value.items()]
        elif key == "noise_per_kind" and value is True:
            value = "on"
        elif key in ("tolerance", "hold", "truth_effect", "data") and isinstance(value, str):
            value = [value]
        value = _value(key, value)
        if key in out and isinstance(out[key], list) and isinstance(value, list):
            out[key] += value
        else:
            out[key] = value
    return json.dumps(out)


def _job(command: str, options: Dict[str, Any],
         out: Optional[PathLike] = None, robot: Optional[Robot] = None,
         data: Optional[List[Any]] = None, reference: Optional[Robot] = None,
         poses: Optional[np.ndarray] = None, truth: Optional[Robot] = None) -> Dict[str, Any]:
    """Runs ``command`` as the workflow's job with ``options`` by name; its outputs are
    committed to ``out`` when given (all or nothing). ``robot``, ``data``, ``reference``,
    ``truth`` and ``poses`` (a plan's or compensate's targets, an array ``(n, 6)``) go to the
    job in memory, not as files. The job's warnings and its trouble (the command's exit code
    1, outputs written) are :class:`cpm.CpmWarning`; errors name the Python keywords."""
    renamed = _renamed(options)
    try:
        text = _by_name(options)
    except CpmError as e:
        raise _in_keywords(e, renamed) from None
    target = os.fspath(out) if out is not None else None
    arrays: set = set()
    held: Dict[str, Any] = {}
    if robot is not None:
        held["robot"] = robot._h
        if data is not None:
            held["data"], arrays = _sources(robot, data)
    if reference is not None:
        held["reference"] = reference._h
    if truth is not None:
        held["truth"] = truth._h
    if poses is not None:
        held["poses"] = poses
        arrays.add("poses")
    try:
        d = dict(_cpm.job(command, text, target, out is not None, **held))
    except InputError as e:
        raise _row_of(e, arrays) from None
    except CpmError as e:
        raise _in_keywords(e, renamed) from None
    _said(d, renamed)
    d["files"] = dict(d["files"])
    return d


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


def _pose_list(poses: Any, name: str = "poses") -> Union[str, np.ndarray]:
    """A pose list: the path of its file, or an array ``(n, 6)`` (x, y, z mm; roll, pitch,
    yaw deg) that goes to the job in memory (named ``poses``, labelled from 1, read with the
    checks of a pose list file; an error's ``row`` is the row of the array); ``name`` is the
    argument's, for errors."""
    if isinstance(poses, (str, os.PathLike)):
        return os.fspath(poses)
    return _float_array(poses, name, 2, 6)


def _held_truth(options: Dict[str, Any]) -> Optional[Robot]:
    """A ``truth=`` robot that no file holds (made from text, or its file changed since),
    taken out of ``options``: it goes to the job in memory (a robot read from its file goes
    by its path)."""
    t = options.get("truth")
    if isinstance(t, Robot) and t._file() is None:
        del options["truth"]
        return t
    return None


def _files_of(items: Optional[List[Any]]) -> Optional[List[Any]]:
    """The files among measurements (paths, and the sources read from files): what a
    compensation check, which reads no measurements, keeps of them (an output may not
    replace them)."""
    if items is None:
        return None
    files: List[Any] = []
    for item in items:
        if isinstance(item, Measurements):
            files += [s.path for s in item.sources if s.path is not None]
        else:
            files.append(item)
    return files or None


def _plan(options: Dict[str, Any]) -> Optional[np.ndarray]:
    """A plan given as an array, taken out of ``options`` (it goes to the job in memory); a
    plan file stays in them by its path."""
    if options.get("plan") is None:
        return None
    plan = _pose_list(options["plan"], "plan")
    if isinstance(plan, str):
        options["plan"] = plan
        return None
    del options["plan"]
    return plan


def _iframe(page: str, height: int = 720) -> str:
    """A full HTML page shown in a notebook cell (its styles kept to itself)."""
    return (f'<iframe srcdoc="{_html.escape(page, quote=True)}" '
            f'style="width:100%;height:{height}px;border:1px solid #ddd" '
            f'sandbox="allow-same-origin"></iframe>')


class _Files:
    """A result made of the files a command wrote (``files``: name -> bytes)."""

    files: Dict[str, bytes]
    _title = "cpm"
    #: The folder the files were written to (``out``), whose paths they record relative to
    #: it (``calibrated.toml``'s ``calibrated_from``); None when they live in memory only.
    _dir: Optional[Path] = None

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
        """Writes the output files into ``directory`` (created). ``calibrated.toml`` records
        the description it was calibrated from as ``cpm calibrate --out directory`` does (a
        path from ``directory``), so that ``cpm validate`` finds it there."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        written = []
        for name, data in self.files.items():
            p = d / name
            p.parent.mkdir(parents=True, exist_ok=True)
            if name == "calibrated.toml":
                here = None if self._dir is None else os.fspath(self._dir)
                data = _cpm.calibrated_from_at(data.decode("utf-8"), here,
                                               os.fspath(d)).encode("utf-8")
            p.write_bytes(data)
            written.append(p)
        return written

    def _calibrated(self) -> Robot:
        """``calibrated.toml`` as a robot, named by where it was written (its recorded
        origin resolves from there, for :func:`validate`'s default reference)."""
        name = "calibrated.toml" if self._dir is None else os.fspath(self._dir / "calibrated.toml")
        return Robot.from_text(self.text("calibrated.toml"), name)


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

    def __init__(self, d: Dict[str, Any], directory: Optional[Path] = None) -> None:
        self._d = d
        self._dir = directory
        self.files = dict(d["files"])
        self.parameter_names: List[str] = list(d["parameter_names"])
        self.estimates_um: np.ndarray = d["estimates_um"]
        self.std_um: np.ndarray = d["std_um"]
        self.minimum_norm_um: np.ndarray = d["minimum_norm_um"]
        self.covariance: np.ndarray = d["covariance"]
        self.identifiability = Identifiability(d)
        # The fit's residuals, predicted minus measured, um: None when the residual is
        # weighted (kinds of different units or noise). Every observation's residual in its
        # own unit, measured minus predicted as residuals.csv, is ``residuals``, with its unit
        # in ``residual_units`` (``um``, ``urad``, an instrument's own).
        self.residuals_um: Optional[np.ndarray] = d["residuals_um"]
        self.residuals: np.ndarray = d["residuals"]
        self.residual_units: np.ndarray = np.asarray(
            d["residual_unit_names"] or [""], dtype=str)[d["residual_unit_codes"]]
        self.outliers: List[int] = list(d["outliers"])
        # A residual that mixes kinds weighed differently (angles beside lengths, or lengths
        # of different noise) has no one unit: its RMS and noise in um are then None, as
        # calibration.json's null, and the weighted figures are in sigma. Each kind's RMS in
        # its own unit is calibration.json's noise_by_kind.
        self.residual_weighted: bool = d["residual_weighted"]
        self.sigma_um: Optional[float] = d["sigma_um"]
        self.sigma_estimated: bool = d["sigma_estimated"]
        self.residual_rms_um: Optional[float] = d["residual_rms_um"]
        self.initial_rms_um: Optional[float] = d["initial_rms_um"]
        self.weighted_rms_in_sigma: float = d["weighted_rms_in_sigma"]
        self.initial_weighted_rms_in_sigma: float = d["initial_weighted_rms_in_sigma"]
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
        return self._calibrated()

    def to_json(self) -> str:
        """``calibration.json``, as ``cpm calibrate`` writes it."""
        return self.text("calibration.json")

    def observation_origin(self, k: int) -> Optional[Tuple[str, int, str]]:
        """Where observation ``k`` (of ``residuals``) came from: file, line, what."""
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
        rms = (f"weighted residual RMS {self.weighted_rms_in_sigma:.3f} in sigma"
               if self.residual_rms_um is None
               else f"residual RMS {self.residual_rms_um:.3f} um")
        return (f"<CalibrationResult {sim}rank {self.identifiability.rank} of "
                f"{self.identifiability.num_params}, {rms}; {self.termination}>")


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
    sources, arrays = _sources(r, _data(data, r))
    given: Dict[str, Any] = dict(effects=effects, sigma_um=sigma_um, robust=robust)
    given.update(options)
    renamed = _renamed(given)
    target = os.fspath(out) if out is not None else None
    try:
        opts = _by_name(given)
        d = dict(_cpm.calibrate_memory(r._h, sources, opts, target, out is not None))
    except InputError as e:
        raise _row_of(e, arrays) from None
    except CpmError as e:
        raise _in_keywords(e, renamed) from None
    _said(d, renamed)
    return CalibrationResult(d, None if out is None else Path(os.path.abspath(out)))


class RefineResult(_Files):
    """The result of :func:`refine`: ``refine.json`` (``doc``, ``steps``), the final fit's
    ``calibration.json`` (``calibration``), ``calibrated.toml`` (``calibrated_robot``) and the
    figures, among them ``residuals_before_after.svg``."""

    def __init__(self, files: Dict[str, bytes], trouble: Optional[str],
                 directory: Optional[Path] = None) -> None:
        self.files = files
        self.trouble = trouble
        self._dir = directory
        self.doc: Dict[str, Any] = json.loads(self.text("refine.json"))
        self.calibration: Dict[str, Any] = json.loads(self.text("calibration.json"))

    @property
    def steps(self) -> List[Dict[str, Any]]:
        """The effects added, one per step, with their tests."""
        return list(self.doc.get("steps", []))

    @property
    def calibrated_robot(self) -> Robot:
        """``calibrated.toml``: the final fit's calibrated machine."""
        return self._calibrated()

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
    d = _job("refine", dict(options), out, robot=r, data=_data(data, r))
    return RefineResult(d["files"], d["trouble"],
                        None if out is None else Path(os.path.abspath(out)))


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


def validate(robot: Optional[Union[Robot, PathLike]],
             reference: Optional[Union[Robot, PathLike]] = None, data: Any = None, *,
             out: Optional[PathLike] = None, **options: Any) -> ValidationResult:
    """``cpm validate``: the calibrated ``robot`` against ``reference`` on held-out
    ``data``; or, with ``commands=`` and ``truth=`` (and ``robot=None``), a compensation
    checked end to end on a simulated machine. Without ``reference``, as the command: the
    description the calibrated robot records it was calibrated from
    (``[calibration] calibrated_from``)."""
    ref = None if reference is None else _robot(reference)
    rob = None if robot is None else _robot(robot)
    reader = rob if rob is not None else ref
    m = None if data is None else _data(data, reader)
    if rob is None:
        # A compensation checked on a simulated machine: the reference and the truth as
        # loaded; of the measurements (it reads none) only their files.
        opts: Dict[str, Any] = dict(data=_files_of(m))
        opts.update(options)
        truth = _held_truth(opts)
        d = _job("validate", opts, out, reference=ref, truth=truth)
    else:
        d = _job("validate", dict(options), out, robot=rob, data=m, reference=ref)
    return ValidationResult(json.loads(d["summary"]), d["files"])


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

    @property
    def predicted_error(self) -> Optional[Dict[str, Any]]:
        """The pose error predicted after compensation from the calibration's covariance
        (``--json``'s ``predicted_error``: per target ``position_std_um``,
        ``orientation_std_urad``, ``position_95_um``, ``orientation_95_urad``; the worst
        target's ISO 9283 bands in ``worst_target``); None when the robot carries no
        covariance (no accuracy is promised)."""
        return self.summary.get("predicted_error")

    def __repr__(self) -> str:
        return f"<CompensationResult {len(self.readings)} targets>"


def compensate(robot: Union[Robot, PathLike], poses: Any, *, out: Optional[PathLike] = None,
               **options: Any) -> CompensationResult:
    """``cpm compensate``: the link readings to command for target ``poses`` (a pose list
    file, or an array ``(n, 6)``: x, y, z mm; roll, pitch, yaw deg); options
    ``temperature_c``, ``from_home``."""
    r = _robot(robot)
    targets = _pose_list(poses)
    if isinstance(targets, str):
        d = _job("compensate", dict(poses=targets, **options), out, robot=r)
    else:
        d = _job("compensate", dict(options), out, robot=r, poses=targets)
    return CompensationResult(d["text"], json.loads(d["summary"]), r.num_links)


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
    d = _job("design", dict(options), out, robot=r)
    return DesignResult(d["files"], Path(out) if out is not None else None)


def simulate(robot: Union[Robot, PathLike], *, out: Optional[PathLike] = None,
             **options: Any) -> Measurements:
    """``cpm simulate``: a simulated campaign, labelled simulated (options by name: ``plan``,
    ``circle``, ``random``, ``truth``, ``paper_table2``, ``truth_effect`` (a list of
    ``"effect=v1,v2"`` or a dict), ``noise``, ``seed``, ``measure``, ``sensors``, ...).
    ``plan`` may be a pose array ``(n, 6)``. Returns the measurements (read back against
    ``robot``); with ``out`` the file is written there."""
    r = _robot(robot)
    plan = _plan(options)
    truth = _held_truth(options)
    d = _job("simulate", dict(options), out, robot=r, poses=plan, truth=truth)
    if out is not None:
        from ._data import read_measurements

        return read_measurements(out, r)
    text = d["text"]
    info = _cpm.read_text(text, "simulated.csv", r._h)
    return Measurements([_Source("simulated.csv", None, text, _Info(info))])


def identifiability(robot: Union[Robot, PathLike], data: Any = None,
                    **options: Any) -> Dict[str, Any]:
    """``cpm identifiability --json``: rank, singular values, blind directions in words,
    Cramér-Rao bounds, for measurements (``data``) or a plan (``plan``, ``circle``,
    ``random``)."""
    r = _robot(robot)
    plan = _plan(options)
    m = None if data is None else _data(data, r)
    d = _job("identifiability", dict(options), robot=r, data=m, poses=plan)
    return json.loads(d["summary"])


def export(robot: Union[Robot, PathLike], format: str = "linuxcnc", *,
           out: Optional[PathLike] = None, **options: Any) -> str:
    """``cpm export``: the joints for a machine controller (LinuxCNC genhexkins HAL text),
    written to ``out`` too when given (options ``units``, ``ini``)."""
    r = _robot(robot)
    d = _job("export", dict(format=format, **options), out, robot=r)
    return d["text"]
