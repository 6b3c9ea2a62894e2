"""One simulated episode as a run (``dbtool simulate``): a body on a task, its metric, a run
directory with the resolved config, a montage PNG and an animated GIF (docs/method.md §3).

A top-level module because it draws (:mod:`dbtool.viz`) as well as simulates; the simulator
itself never imports the pictures.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dbtool.choices import CONTROLLERS
from dbtool.errors import InputError
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.bodies import SHAPES
from dbtool.sim.tasks import N_STEPS, SUBSTEPS, Task, get_task


@dataclass
class SimulateConfig:
    """What ``dbtool simulate`` runs; invalid settings raise ``ValueError`` on creation.

    ``design`` (a saved ``.npz``) replaces the reference body ``shape``; ``controller`` is the
    task's prescribed one, ``none`` (zero actuation) or the design's own."""

    task: str
    shape: str = "box"
    design: Path | None = None
    controller: str = "prescribed"
    steps: int = N_STEPS
    seed: int = 0
    arch: str = "cpu"
    gif: bool = True

    def __post_init__(self) -> None:
        self.task = get_task(self.task).name
        if self.controller not in CONTROLLERS:
            raise InputError(f"unknown controller {self.controller!r}; choose prescribed, none "
                             "or design")
        if self.steps < 1:
            raise InputError(f"steps must be at least 1, got {self.steps}")
        if self.design is None and self.shape not in SHAPES:
            raise InputError(f"unknown shape {self.shape!r}; choose one of {', '.join(SHAPES)}")

    def resolved(self) -> dict:
        """The run's ``config.json``."""
        return {"command": "simulate", "task": self.task,
                "shape": None if self.design else self.shape,
                "design": str(self.design) if self.design else None,
                "controller": self.controller, "steps": self.steps, "substeps": SUBSTEPS,
                "seed": self.seed, "arch": self.arch}


@dataclass
class SimulateResult:
    """What one simulate run measured and wrote."""

    task: Task
    metric: float
    particles: int
    seconds: float
    run_dir: Path
    montage: Path
    animation: Path | None


def simulate_run(cfg: SimulateConfig, out: str | Path | None = None,
                 progress: Callable[[int], object] | None = None) -> SimulateResult:
    """Simulate ``cfg`` in the run directory ``out`` (default ``runs/simulate-TASK-TIME``).

    ``progress(n)`` is called as each control step finishes (``n = 1``). Bad input (an unknown
    arch, an unreadable or empty design, a design for another task or whose controller is too
    short) raises ``ValueError`` before anything is written; a diverging episode raises
    :class:`~dbtool.sim.simulator.SimulationError`."""
    from dbtool.design import Design
    from dbtool.runs import RunDir, default_run_dir, seed_everything
    from dbtool.sim import runtime
    from dbtool.sim.rollout import simulate
    from dbtool.viz.render import animation, montage

    task = get_task(cfg.task)
    runtime.init(arch=cfg.arch)
    design = None
    if cfg.design is not None:
        design = Design.load(cfg.design)
        if design.task != task.name:
            raise InputError(f"design {cfg.design} was made for task {design.task!r}, not "
                             f"{task.name!r}")
        robot = design.robot.compact()
    else:
        robot = reference_robot(task, cfg.shape).compact()
    seed_everything(cfg.seed)
    actions = _actions(cfg, task, design)
    with RunDir(out or default_run_dir("simulate", task.name), cfg.resolved(), cfg.seed,
                runtime.device(), kind="simulate") as run:
        start = time.perf_counter()
        ro = simulate(task, robot, actions, n_steps=cfg.steps, progress=progress)
        seconds = time.perf_counter() - start
        particles = len(ro.episode.particles.x0)
        run.log(task=task.name, metric=ro.metric, particles=particles, seconds=seconds)
        png = montage(ro.episode, ro.positions, run.file("montage.png"),
                      title=f"{task.title}: metric {ro.metric:.4f}")
        gif = animation(ro.episode, ro.positions, run.file("rollout.gif")) if cfg.gif else None
    return SimulateResult(task, ro.metric, particles, seconds, run.path, png, gif)


def _actions(cfg: SimulateConfig, task: Task, design) -> np.ndarray:
    if cfg.controller == "prescribed":
        return task.controller(cfg.steps)
    if cfg.controller == "design":
        if design is None or len(design.controller) < cfg.steps:
            raise InputError("--controller design needs a --design whose controller covers "
                             "the steps")
        return design.controller[: cfg.steps]
    return task.controller(cfg.steps) * 0.0
