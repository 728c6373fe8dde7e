"""The exceptions of cpm.

Every error of the library is a :class:`CpmError`; the subclasses follow the exit codes of
the ``cpm`` command (``docs/cli.md``):

- :class:`UsageError` (exit code 2): a bad option or argument value; also a ``ValueError``;
- :class:`InputError` (exit code 3): a bad input file or array, with ``file``, ``line`` and
  ``field`` where the problem is (for measurements given as arrays, ``row`` is the 0-based
  row of the arrays); also a ``ValueError``;
- :class:`SolverError` (exit code 1): the computation failed (forward kinematics at a pose,
  a fit that determines nothing, a solver failure); also a ``RuntimeError``;
- :class:`CpmIOError` (exit code 4): a file could not be read or written; also an ``OSError``.
"""
from __future__ import annotations

import os
import re
import sys
import warnings
from typing import Dict, Optional

__all__ = ["CpmError", "UsageError", "InputError", "SolverError", "CpmIOError", "CpmWarning"]


class CpmError(Exception):
    """Base class of every cpm error."""


class UsageError(CpmError, ValueError):
    """A bad option or argument (the ``cpm`` command's exit code 2)."""


class InputError(CpmError, ValueError):
    """A bad input file or array (exit code 3): ``file``, ``line`` (1-based) and ``field``
    say where, when known; ``row`` is the 0-based row for measurements made from arrays."""

    def __init__(
        self,
        message: str,
        file: Optional[str] = None,
        line: Optional[int] = None,
        field: Optional[str] = None,
        row: Optional[int] = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.file = file
        self.line = line
        self.field = field
        self.row = row

    def __reduce__(self):  # picklable with its attributes
        return (type(self), (self.message, self.file, self.line, self.field, self.row))


class SolverError(CpmError, RuntimeError):
    """The computation failed or reports trouble (exit code 1)."""


class CpmIOError(CpmError, OSError):
    """A file could not be read or written (exit code 4)."""


class CpmWarning(UserWarning):
    """A result that is returned but says something is wrong (e.g. the solver did not
    converge, the fit is rank-deficient, the model does not fit the declared noise)."""


_FLAG = re.compile(r"(?<![\w-])--([a-z][a-z0-9]*(?:-[a-z0-9]+)*)")


def _keywords(message: str, renamed: Optional[Dict[str, str]] = None) -> str:
    """``message`` with the command's flags named as the Python keywords (``--sigma-um`` is
    ``sigma_um``); ``renamed`` maps a job's option name to the keyword it was given as
    (``tolerance`` to ``tolerances``)."""
    renamed = renamed or {}

    def keyword(m: "re.Match[str]") -> str:
        name = m.group(1).replace("-", "_")
        return renamed.get(name, name)

    return _FLAG.sub(keyword, message)


def _in_keywords(err: CpmError, renamed: Optional[Dict[str, str]] = None) -> CpmError:
    """A usage or solver error with the command's flags named as the Python keywords (an
    input or I/O error names files, left as it is)."""
    if isinstance(err, (InputError, CpmIOError)):
        return err
    msg = _keywords(str(err), renamed)
    if msg == str(err):
        return err
    try:
        return type(err)(msg)
    except Exception:  # pragma: no cover - an exception type with another signature
        return err


def _warn(message: str, renamed: Optional[Dict[str, str]] = None) -> None:
    """A :class:`CpmWarning`, shown at the first caller outside the package (the user's
    line), with the command's flags named as the Python keywords."""
    here = os.path.dirname(os.path.abspath(__file__))
    frame = sys._getframe(1)
    level = 2
    while frame is not None and os.path.dirname(
            os.path.abspath(frame.f_code.co_filename)) == here:
        frame = frame.f_back
        level += 1
    warnings.warn(_keywords(message, renamed), CpmWarning, stacklevel=level)
