"""Common machinery of the six tasks (docs/method.md §3): scene, placement, objects, metric."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from dbtool.errors import InputError
from dbtool.sim.bodies import attached, lattice
from dbtool.sim.boundaries import BOUND
from dbtool.sim.kernels import MAX_GROUPS
from dbtool.sim.robot import Robot
from dbtool.sim.simulator import SUBSTEPS, Material, Particles, Scene  # noqa: F401 (re-exported)
from dbtool.sim.task_names import N_STEPS, TITLES  # noqa: F401 - N_STEPS re-exported

DX = 0.005  # grid spacing: the 0.08 workspace spans 16 cells
SPACING = DX / 2  # particle spacing: 8 particles per cell
GROUND = BOUND * DX  # the ground plane sits on top of the bottom wall
OBJECT_STIFFNESS = 1e5  # the cube / box is a stiff elastic body


class DetachedError(InputError):
    """A body that should hang from a clamped base has no material attached to it."""


@dataclass
class Episode:
    """A robot placed in a task scene: simulator particles plus the bookkeeping to map results
    back to the design. ``design_index[i]`` is the robot particle that simulator particle ``i``
    copies (-1 for the base, task objects and particles the task disables)."""

    task: Task
    scene: Scene
    particles: Particles
    design_index: np.ndarray
    robot_mask: np.ndarray
    object_mask: np.ndarray
    info: dict = field(default_factory=dict)


class Task:
    """One of the paper's six tasks. Subclasses set the class attributes and override the
    hooks (``scene``, ``origin``, ``controller``, ``metric``); ``title`` comes with the name
    from :data:`dbtool.sim.task_names.TITLES`."""

    name = ""
    title = ""
    setup = ""
    metric_text = ""
    controller_text = ""
    workspace: tuple[float, float, float] = (0.08, 0.08, 0.08)
    n_groups = 0
    cluster_axes: tuple[int, ...] = ()
    direction: tuple[float, float, float] = (0.0, 1.0, 0.0)
    initial_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    material = Material()
    # The designed body hangs from a clamped base (docs/method.md §3): it is placed against
    # the top of its workspace, only material attached to its clamp is scored, and
    # exports and the tendon bench mount it by that top face. Otherwise it stands on the ground.
    hangs = False
    object_stiffness = OBJECT_STIFFNESS  # Young's modulus of the task's cubes
    # the motion classes its rollouts are sorted into (dbtool.compare.motion): "gait", "leap"
    # (a gait with a flight phase over an obstacle), "grasp", or "" for none
    motion = ""
    damping = 0.0  # material damping rate of the robot's particles (1/time; docs/method.md §3)

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if cls.name:
            cls.title = TITLES[cls.name]

    def mirror_plane(self) -> tuple[int, float] | None:
        """``(axis, value)``: the scene holds the design and its mirror copy about the world
        plane ``x[axis] = value`` (the gripper's two fingers); ``None`` for a single body."""
        return None

    @property
    def gripper(self) -> bool:
        """A pair of mirrored bodies hanging from a clamped base: exported as a gripper
        (fingers, base, tendons) and measured on the tendon bench."""
        return self.hangs and self.mirror_plane() is not None

    # ------------------------------------------------------------------ hooks
    def scene(self) -> Scene:
        raise NotImplementedError

    def origin(self) -> np.ndarray:
        """World position of the workspace's min corner."""
        raise NotImplementedError

    def objects(self) -> list[tuple[np.ndarray, float]]:
        """Dynamic cubes ``(centre, side)`` simulated as stiff MPM bodies."""
        return []

    def controller(self, n_steps: int = N_STEPS) -> np.ndarray:
        """The prescribed open-loop actuation, shape ``(n_steps, n_groups)``."""
        return np.zeros((n_steps, self.n_groups))

    def metric(self, ep: Episode, x0: torch.Tensor, x: torch.Tensor, presence: torch.Tensor):
        """Differentiable task metric (higher is better) from initial and final positions."""
        raise NotImplementedError

    def group_order(self, centroid: np.ndarray) -> float:
        """Sort key of actuator groups (by centroid in centred local coordinates)."""
        return float(centroid[self.cluster_axes[0]]) if self.cluster_axes else 0.0

    # ------------------------------------------------------------------ robot
    def design_points(self) -> np.ndarray:
        """Particle lattice of the designed body (workspace coordinates)."""
        return lattice(self.workspace, SPACING)

    def design_workspace(self) -> tuple[float, float, float]:
        return self.workspace

    # ------------------------------------------------------------------ episode
    def place(self, robot: Robot) -> tuple[np.ndarray, np.ndarray]:
        """World positions of the robot particles and their design indices."""
        return robot.points + self.origin(), np.arange(robot.n)

    def episode(self, robot: Robot) -> Episode:
        """Assemble simulator particles: robot (placed), then task objects."""
        robot.validate()
        if robot.actuators.shape[1] != self.n_groups:
            raise InputError(f"task {self.name} needs {self.n_groups} actuator groups, "
                             f"the robot has {robot.actuators.shape[1]}")
        xr, idx = self.place(robot)
        presence = (robot.presence() * self.attachment(robot))[idx]
        actuators = np.zeros((len(idx), MAX_GROUPS))
        actuators[:, : self.n_groups] = robot.actuators[idx]
        direction = robot.particle_directions()[idx] if self.n_groups else np.tile(
            (0.0, 1.0, 0.0), (len(idx), 1))
        stiff = robot.stiffness[idx]
        glued = np.zeros(len(idx))
        parts = [(xr, presence, stiff, actuators, direction, glued, idx)]
        extra = self.extra_particles(robot)
        if extra is not None:
            parts.append(extra)
        n_robot = sum(len(p[0]) for p in parts)
        for centre, side in self.objects():
            xo = lattice((side, side, side), SPACING) + np.asarray(centre) - side / 2
            m = len(xo)
            parts.append((xo, np.ones(m), np.full(m, self.object_stiffness),
                          np.zeros((m, MAX_GROUPS)), np.tile((0.0, 1.0, 0.0), (m, 1)),
                          np.zeros(m), np.full(m, -1)))
        x0 = np.concatenate([p[0] for p in parts])
        v0 = np.zeros_like(x0)
        v0[:n_robot] = self.initial_velocity
        particles = Particles(
            x0=x0, presence=np.concatenate([p[1] for p in parts]),
            stiffness=np.concatenate([p[2] for p in parts]),
            actuators=np.concatenate([p[3] for p in parts]),
            direction=np.concatenate([p[4] for p in parts]),
            glued=np.concatenate([p[5] for p in parts]), v0=v0,
            damping=np.where(np.arange(len(x0)) < n_robot, self.damping, 0.0) if self.damping
            else None,
            field=(np.arange(len(x0)) >= n_robot).astype(float),
        )
        design_index = np.concatenate([p[6] for p in parts]).astype(int)
        robot_mask = np.zeros(len(x0), bool)
        robot_mask[:n_robot] = True
        ep = Episode(self, self.scene(), particles, design_index, robot_mask, ~robot_mask)
        self.finish_episode(ep)
        return ep

    def attachment(self, robot: Robot) -> np.ndarray:
        """1 for the design particles that are scored: all of them, or for a body that hangs
        from a clamped base only those attached to it through the lattice (the rest is
        dropped, docs/method.md §3 "Attachment"); :class:`DetachedError` when none is."""
        if not self.hangs:
            return np.ones(robot.n)
        keep = attached(robot.points, robot.active(), SPACING, self.design_workspace()[1])
        if not keep.any():
            raise DetachedError(
                f"the {self.name} design does not reach its clamped base: no material in the "
                "layers its clamp holds is connected to the body, so it would fall")
        return keep.astype(float)

    def extra_particles(self, robot: Robot):
        """Non-designed robot parts (the gripper's glued base)."""
        return None

    def finish_episode(self, ep: Episode) -> None:
        """Last task-specific adjustments (e.g. disable particles inside an object)."""

    def describe(self) -> dict:
        return {
            "name": self.name, "title": self.title, "setup": self.setup,
            "metric": self.metric_text, "controller": self.controller_text,
            "workspace": self.workspace, "groups": self.n_groups,
        }


# ---------------------------------------------------------------------- metric helpers
def centroid(x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Weighted centroid ``sum w x / sum w``."""
    return (w[:, None] * x).sum(0) / w.sum().clamp_min(1e-12)


def soft_occupancy(x: torch.Tensor, w: torch.Tensor, scene: Scene) -> torch.Tensor:
    """Voxel occupancy on the simulation grid: trilinear splat of particle presence,
    ``min(1, density / 4)`` (a full cell holds 8 particles; a surface node gets ~4)."""
    dims = scene.grid
    g = x / scene.dx
    base = torch.floor(g).long()
    f = g - base
    occ = torch.zeros(dims[0] * dims[1] * dims[2], dtype=x.dtype)
    for i in (0, 1):
        for j in (0, 1):
            for k in (0, 1):
                wt = ((f[:, 0] if i else 1 - f[:, 0]) * (f[:, 1] if j else 1 - f[:, 1])
                      * (f[:, 2] if k else 1 - f[:, 2]))
                idx = base + torch.tensor([i, j, k])
                for d in range(3):
                    idx[:, d] = idx[:, d].clamp(0, dims[d] - 1)
                flat = (idx[:, 0] * dims[1] + idx[:, 1]) * dims[2] + idx[:, 2]
                occ = occ.index_add(0, flat, wt * w)
    return (occ / 4.0).clamp(max=1.0)


def soft_iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.minimum(a, b).sum() / torch.maximum(a, b).sum().clamp_min(1e-12)


def ramp(start, end, frames: int) -> np.ndarray:
    """Linear ramp over ``frames`` control steps (first frame = start, last = end)."""
    return np.linspace(np.asarray(start, float), np.asarray(end, float), frames)
