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

    def _option_path(self, key: str) -> str:
        """The file holding this description, for an option that takes a robot's path (a
        robot the job takes in memory goes as ``robot``, ``reference`` or ``truth``)."""
        from .errors import UsageError

        p = self._file()
        if p is None:
            raise UsageError(f"{key}: the robot '{self.file}' is held in memory only; this "
                             "option takes the path of a robot file")
        return p

    def __repr__(self) -> str:
        return (f"Robot({self.file!r}, {self.num_links} links, "
                f"sensors {self.sensor_names})")
