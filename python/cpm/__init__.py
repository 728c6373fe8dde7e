"""cpm: calibration of parallel manipulators (six-link Gough-Stewart platforms), from Python.

The Python face of the ``cpm`` Rust crates: the same readers, fits, reports and files as the
``cpm`` command (``docs/cli.md``), with numpy arrays in and out.

>>> import cpm
>>> robot = cpm.Robot.from_toml("examples/hexapod_66.toml")             # doctest: +SKIP
>>> data = cpm.read_measurements("examples/hexapod_66_readings.csv", robot)  # doctest: +SKIP
>>> result = cpm.calibrate(robot, data, effects=["link_offset"])        # doctest: +SKIP
>>> result.estimates_um, result.std_um, result.identifiability.rank    # doctest: +SKIP
>>> result   # in Jupyter: the report.html of `cpm calibrate`, figures inline

``cpm.lm.least_squares`` is the cpm-lm solver with SciPy's calling convention.
Units: mm and degrees in poses, um for installation errors and residuals.
"""
from __future__ import annotations

from . import lm
from ._cpm import __version__
from ._commands import (
    CalibrationResult,
    CompensationResult,
    DesignResult,
    Identifiability,
    RefineResult,
    ValidationResult,
    calibrate,
    compensate,
    design,
    effect_names,
    export,
    identifiability,
    refine,
    simulate,
    validate,
)
from ._data import (
    Measurements,
    gauge_readings,
    measurements_from_frame,
    read_measurements,
    tracker_measurements,
)
from ._robot import Robot
from .errors import CpmError, CpmIOError, CpmWarning, InputError, SolverError, UsageError

__all__ = [
    "__version__",
    "Robot",
    "Measurements",
    "read_measurements",
    "gauge_readings",
    "tracker_measurements",
    "measurements_from_frame",
    "calibrate",
    "refine",
    "validate",
    "compensate",
    "design",
    "simulate",
    "identifiability",
    "export",
    "effect_names",
    "CalibrationResult",
    "RefineResult",
    "ValidationResult",
    "CompensationResult",
    "DesignResult",
    "Identifiability",
    "CpmError",
    "InputError",
    "UsageError",
    "SolverError",
    "CpmIOError",
    "CpmWarning",
    "lm",
]
