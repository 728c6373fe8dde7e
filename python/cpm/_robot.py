"""Robot descriptions (``docs/robot-description.md``) read by the readers of ``cpm``."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Dict, List, Optional, Union

import numpy as np

from . import _cpm

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["Robot"]


class Robot:
    """A robot description: a six-link Gough-Stewart platform with its joints, link reading
    models, sensors and calibration settings.

    Read one with :meth:`from_toml` (a file) or :meth:`from_text`; a calibration gives the
    calibrated one (:attr:`CalibrationResult.calibrated_robot`). The checks and error messages
    are those of ``cpm --robot`` (:class:`cpm.InputError` with ``file``, ``line``, ``field``).
    """

    __slots__ = ("_h",)

    def __init__(self, handle: Any) -> None:
        self._h = handle

    @classmethod
    def from_toml(cls, path: PathLike) -> "Robot":
        """Reads a robot description file."""
        return cls(_cpm.robot_load(os.fspath(path)))

    @classmethod
    def from_text(cls, text: str, name: str = "<robot>") -> "Robot":
        """Reads a robot description from TOML text; ``name`` stands for the file in
        messages."""
        return cls(_cpm.robot_from_text(text, name))

    def to_toml(self, path: Optional[PathLike] = None) -> str:
        """The description's TOML text (as read); written to ``path`` when given."""
        text: str = self._h.text
        if path is not None:
            Path(path).write_text(text, encoding="utf-8")
        return text

    # Where it came from.
    @property
    def file(self) -> str:
        """The name it goes by in messages (the file as given)."""
        return self._h.file

    @property
    def path(self) -> Optional[Path]:
        """The file it was read from (``None`` when made from text)."""
        p = self._h.path
        return None if p is None else Path(p)

    @property
    def name(self) -> Optional[str]:
        """The description's ``name``."""
        return self._h.name

    # Geometry.
    @property
    def num_links(self) -> int:
        return self._h.num_links

    @property
    def base_joints_mm(self) -> np.ndarray:
        """Base joints in {B}, mm, ``(links, 3)`` (``[installation_errors_um]`` applied)."""
        return self._h.base_joints_mm

    @property
    def platform_joints_mm(self) -> np.ndarray:
        """Platform joints in {P}, mm, ``(links, 3)``."""
        return self._h.platform_joints_mm

    @property
    def joints(self) -> Dict[str, np.ndarray]:
        """``{"base_mm": (links, 3), "platform_mm": (links, 3)}``."""
        return {"base_mm": self.base_joints_mm, "platform_mm": self.platform_joints_mm}

    @property
    def length_at_zero_mm(self) -> np.ndarray:
        """Each link's length at reading 0, mm."""
        return self._h.length_at_zero_mm

    @property
    def mm_per_unit(self) -> np.ndarray:
        """Each link's millimetres per reading unit."""
        return self._h.mm_per_unit

    @property
    def links(self) -> List[Dict[str, Any]]:
        """One dict per link: ``base_mm``, ``platform_mm``, ``length_at_zero_mm``,
        ``mm_per_unit``."""
        b, p = self.base_joints_mm, self.platform_joints_mm
        z, u = self.length_at_zero_mm, self.mm_per_unit
        return [
            {"base_mm": b[i], "platform_mm": p[i], "length_at_zero_mm": float(z[i]),
             "mm_per_unit": float(u[i])}
            for i in range(self.num_links)
        ]

    @property
    def sensor_names(self) -> List[str]:
        """Sensor names in the order of ``[[sensor]]``."""
        return list(self._h.sensor_names)

    @property
    def sensors(self) -> List[Dict[str, Any]]:
        """One dict per sensor: ``name``, ``base_mm`` ({B}), ``platform_mm`` ({P})."""
        b, p = self._h.sensor_base_mm, self._h.sensor_platform_mm
        return [{"name": n, "base_mm": b[i], "platform_mm": p[i]}
                for i, n in enumerate(self.sensor_names)]

    @property
    def home(self) -> np.ndarray:
        """Home pose: x, y, z (mm), roll, pitch, yaw (deg)."""
        return self._h.home

    @property
    def declared_effects(self) -> List[str]:
        """The effects of ``[calibration] effects``."""
        return list(self._h.declared_effects)

    @property
    def sensor_noise_um(self) -> Optional[float]:
        """``[calibration] sensor_noise_um``."""
        return self._h.sensor_noise_um

    @property
    def description(self) -> Dict[str, Any]:
        """The whole description as a dict (every table and key)."""
        return json.loads(self._h.description_json())

    def _file(self) -> Optional[str]:
        """The file it was read from when that still holds the same text, else None."""
        p = self.path
        if p is not None:
            try:
                if p.read_text(encoding="utf-8-sig") == self._h.text or \
                        p.read_bytes().decode("utf-8", "replace") == self._h.text:
                    return os.fspath(p)
            except OSError:
                pass
        return None

    def _cli_path(self, scratch: "Scratch") -> str:
        """A file holding this description for a command: the file it was read from when
        that still holds the same text, else a copy in the scratch directory."""
        p = self._file()
        if p is not None:
            return p
        base = Path(self.file).name or "robot.toml"
        if not base.endswith(".toml"):
            base += ".toml"
        return scratch.write(base, self._h.text, self.file)

    def __repr__(self) -> str:
        return (f"Robot({self.file!r}, {self.num_links} links, "
                f"sensors {self.sensor_names})")


class Scratch:
    """A scratch directory for the files a command reads or writes, and the names the
    files stand for (to put back in error messages)."""

    def __init__(self) -> None:
        import tempfile

        self._dir = tempfile.TemporaryDirectory(prefix="cpm-py-")
        self.path = Path(self._dir.name)
        self.names: Dict[str, str] = {}
        self.array_sources: set = set()

    def write(self, base: str, text: str, stands_for: str, arrays: bool = False) -> str:
        safe = "".join(c if c.isalnum() or c in "._-" else "_" for c in base) or "file"
        target = self.path / safe
        k = 1
        while target.exists():
            k += 1
            target = self.path / f"{k}_{safe}"
        target.write_text(text, encoding="utf-8")
        self.names[os.fspath(target)] = stands_for
        if arrays:
            self.array_sources.add(stands_for)
        return os.fspath(target)

    def named(self, value: Any) -> Any:
        """``value`` (parsed JSON) with every scratch file's path replaced by the name it
        stands for (a command's report names its inputs)."""
        if isinstance(value, str):
            return self.names.get(value, value)
        if isinstance(value, list):
            return [self.named(v) for v in value]
        if isinstance(value, dict):
            return {k: self.named(v) for k, v in value.items()}
        return value

    def fix(self, err: BaseException) -> BaseException:
        """Puts the names the scratch files stand for back into an error."""
        from .errors import InputError

        msg = str(err)
        for tmp, name in self.names.items():
            msg = msg.replace(tmp, name)
        msg = msg.replace(os.fspath(self.path) + os.sep, "")
        if isinstance(err, InputError):
            file = self.names.get(err.file or "", err.file)
            row = err.row
            if file in self.array_sources and err.line is not None and err.line >= 2:
                row = err.line - 2
            new = InputError(msg, file, err.line, err.field, row)
            return new
        try:
            new_err = type(err)(msg)
        except Exception:  # pragma: no cover - an exception type with another signature
            return err
        return new_err

    def cleanup(self) -> None:
        self._dir.cleanup()

    def __enter__(self) -> "Scratch":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.cleanup()
