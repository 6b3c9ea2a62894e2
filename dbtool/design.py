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
    def load(cls, path: str | Path, task: str | None = None) -> Design:
        """Read a design and check it (:func:`check_design_file`: types, shapes, finite
        values, the header, the task); raises :class:`DesignFileError` with a one-line reason.
        ``task``: the task the caller needs (another task is an error)."""
        return check_design_file(path, task)


# designs from the prior carry its surface
PRIOR_METHODS = ("diffusebot", "prior", "dpsr", "embedding", "codesign", "diffusebot-paper")


def _header(raw: np.ndarray, where: str) -> dict:
    if raw.dtype.kind not in "US" or raw.ndim != 0:
        raise DesignFileError(f"{where} has a header that is not a text")
    try:
        header = json.loads(str(raw))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DesignFileError(f"{where} has a corrupt header: {exc}") from None
    if not isinstance(header, dict):
        raise DesignFileError(f"{where} has a header that is not a JSON object")
    if header.get("format") != FORMAT:
        raise DesignFileError(f"{where} has format {header.get('format')!r}, expected "
                              f"{FORMAT!r}")
    if not isinstance(header.get("task"), str):
        raise DesignFileError(f"{where}: the header names no task")
    metrics = header.get("metrics", {})
    if not isinstance(metrics, dict) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in metrics.values()):
        raise DesignFileError(f"{where}: the header's metrics must map names to numbers")
    if not isinstance(header.get("meta", {}), dict):
        raise DesignFileError(f"{where}: the header's meta must be a JSON object")
    return header


def _real(arrays: dict[str, np.ndarray], where: str) -> dict[str, np.ndarray]:
    out = {}
    for k in _ARRAYS:
        a = arrays[k]
        if a.dtype.kind not in "fiub":
            raise DesignFileError(f"{where}: {k} must hold real numbers, not {a.dtype}")
        a = a.astype(float)
        if not np.all(np.isfinite(a)):
            raise DesignFileError(f"{where}: {k} contains NaN or inf")
        out[k] = a
    return out


def check_design_file(path: str | Path, task: str | None = None) -> Design:
    """Load and check the design file ``path`` (the one place every command reads designs):
    a ``.npz`` archive with a JSON header (format, a known task, numeric metrics) and real,
    finite arrays of consistent shapes; the robot's actuator groups, directions and
    controller match its task, its particles lie in the task's workspace, and a design from
    the prior carries its surface cloud. ``task``: the task the caller needs.

    Example::

        design = check_design_file("exports/gripping-seed0/design.npz", task="gripping")
    """
    from dbtool.sim.tasks import get_task
    from dbtool.sim.tasks.base import SPACING

    path = Path(path)
    where = f"design file {path}"
    if not path.is_file():
        raise DesignFileError(f"design file not found: {path}")
    if not zipfile.is_zipfile(path):
        raise DesignFileError(f"{path} is not a design file (.npz archive)")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as exc:
        raise DesignFileError(f"cannot read {where}: {exc}") from None
    missing = [k for k in ("header", *_ARRAYS) if k not in arrays]
    if missing:
        raise DesignFileError(f"{where} lacks {', '.join(missing)}")
    header = _header(arrays["header"], where)
    try:
        spec = get_task(header["task"])
    except InputError:
        raise DesignFileError(f"{where} names an unknown task {header['task']!r}") from None
    arrays = _real(arrays, where)
    surface, controller, directions = arrays["surface"], arrays["controller"], \
        arrays["directions"]
    if surface.ndim != 2 or surface.shape[1] != 3:
        raise DesignFileError(f"{where}: surface must have shape (N, 3), got {surface.shape}")
    method = header.get("meta", {}).get("method")
    if len(surface) == 0 and method in PRIOR_METHODS:
        raise DesignFileError(f"{where}: a {method} design must carry its surface cloud; the "
                              "surface is empty")
    if directions.ndim != 2 or directions.shape[1] != 3:
        raise DesignFileError(f"{where}: directions must have shape (groups, 3), got "
                              f"{directions.shape}")
    robot = Robot(arrays["points"], arrays["occupancy"], arrays["stiffness"],
                  arrays["actuators"], directions)
    try:
        robot.validate()
    except ValueError as exc:
        raise DesignFileError(f"{where}: {exc}") from None
    groups = directions.shape[0]
    if groups != spec.n_groups:
        raise DesignFileError(f"{where}: task {spec.name} has {spec.n_groups} actuator "
                              f"groups, the design {groups} (is the header's task right?)")
    if groups and np.any(np.linalg.norm(directions, axis=1) < 1e-9):
        raise DesignFileError(f"{where}: an actuator group has no muscle direction (all "
                              "zero)")
    lo, hi = robot.points.min(0), robot.points.max(0)
    ws = np.asarray(spec.design_workspace(), float)
    if np.any(lo < -SPACING) or np.any(hi > ws + SPACING):
        raise DesignFileError(f"{where}: its particles span {np.round(lo, 4).tolist()} .. "
                              f"{np.round(hi, 4).tolist()}, outside the {spec.name} workspace "
                              f"{ws.tolist()} (is the header's task right?)")
    if controller.ndim != 2 or controller.shape[1] != groups or len(controller) == 0:
        raise DesignFileError(f"{where}: controller shape {controller.shape} does not match "
                              f"{groups} actuator groups and at least one step")
    if task is not None and get_task(task).name != spec.name:
        raise DesignFileError(f"{path} was made for task {spec.name!r}, not {task!r}")
    return Design(spec.name, robot, controller, surface, dict(header.get("metrics", {})),
                  dict(header.get("meta", {})))
