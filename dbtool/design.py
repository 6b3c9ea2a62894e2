"""The ``Design`` record: what the method outputs and every later stage consumes.

A design holds the surface point cloud (from the prior), the robot's particle fields
(geometry, softness, actuators), the open-loop controller, the task and its metrics. It is saved
as one ``.npz`` (arrays plus a JSON header) written atomically, and loads back identically.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write
from dbtool.errors import InputError
from dbtool.sim.robot import Robot

FORMAT = "dbtool.design/1"
_ARRAYS = ("surface", "points", "occupancy", "stiffness", "actuators", "directions", "controller")


class DesignFileError(InputError):
    """A design file is missing, unreadable or malformed."""


@dataclass
class Design:
    """A designed robot for ``task``; ``controller`` has shape (n_steps, n_groups)."""

    task: str
    robot: Robot
    controller: np.ndarray
    surface: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    metrics: dict[str, float] = field(default_factory=dict)
    meta: dict = field(default_factory=dict)

    def arrays(self) -> dict[str, np.ndarray]:
        r = self.robot
        return {
            "surface": np.asarray(self.surface, float), "points": r.points,
            "occupancy": r.occupancy, "stiffness": r.stiffness, "actuators": r.actuators,
            "directions": r.directions, "controller": np.asarray(self.controller, float),
        }

    def save(self, path: str | Path) -> Path:
        """Write ``path`` (``.npz``) atomically: a temp file in the same folder, then rename."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        header = {"format": FORMAT, "task": self.task, "metrics": self.metrics, "meta": self.meta}
        arrays = self.arrays()

        def save(tmp: str) -> None:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, header=np.array(json.dumps(header)), **arrays)

        return atomic_write(path, save)

    @classmethod
    def load(cls, path: str | Path) -> Design:
        """Read a design; raises :class:`DesignFileError` with a one-line reason."""
        path = Path(path)
        if not path.is_file():
            raise DesignFileError(f"design file not found: {path}")
        if not zipfile.is_zipfile(path):
            raise DesignFileError(f"{path} is not a design file (.npz archive)")
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            raise DesignFileError(f"cannot read design file {path}: {exc}") from None
        missing = [k for k in ("header", *_ARRAYS) if k not in arrays]
        if missing:
            raise DesignFileError(f"design file {path} lacks {', '.join(missing)}")
        try:
            header = json.loads(str(arrays["header"]))
        except json.JSONDecodeError as exc:
            raise DesignFileError(f"design file {path} has a corrupt header: {exc}") from None
        if header.get("format") != FORMAT:
            raise DesignFileError(f"design file {path} has format {header.get('format')!r}, "
                                  f"expected {FORMAT!r}")
        robot = Robot(arrays["points"], arrays["occupancy"], arrays["stiffness"],
                      arrays["actuators"], arrays["directions"])
        try:
            robot.validate()
        except ValueError as exc:
            raise DesignFileError(f"design file {path}: {exc}") from None
        controller = arrays["controller"]
        if controller.ndim != 2 or controller.shape[1] != robot.actuators.shape[1]:
            raise DesignFileError(f"design file {path}: controller shape {controller.shape} does "
                                  f"not match {robot.actuators.shape[1]} actuator groups")
        return cls(header["task"], robot, controller, arrays["surface"],
                   header.get("metrics", {}), header.get("meta", {}))
