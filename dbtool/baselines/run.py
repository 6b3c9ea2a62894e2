"""The particle-based baseline as a run (``dbtool design --method particle``; docs/method.md
§7): a reference body whose per-particle geometry, softness and actuator logits, and the
open-loop controller, follow the simulator's gradients; the run directory gets the metrics per
iteration, ``design.npz`` and a montage PNG.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from dbtool.baselines.features import DEFAULT_BODY
from dbtool.choices import DESIGN_METHODS
from dbtool.errors import InputError
from dbtool.robotize.actuators import reference_robot
from dbtool.sim.tasks import N_STEPS, get_task


def check_method(method: str) -> str:
    """``method`` if it names a design method, else ``ValueError``."""
    if method not in DESIGN_METHODS:
        raise InputError(f"unknown method {method!r}; choose {' or '.join(DESIGN_METHODS)}")
    return method


@dataclass
class ParticleRunConfig:
    """Settings of one particle-baseline run; invalid ones raise ``ValueError``."""

    task: str
    iterations: int = 4
    steps: int = N_STEPS
    seed: int = 0
    arch: str = "cpu"

    def __post_init__(self) -> None:
        self.task = get_task(self.task).name
        if self.iterations < 0:
            raise InputError(f"iterations must be at least 0, got {self.iterations}")
        if self.steps < 1:
            raise InputError(f"steps must be at least 1, got {self.steps}")

    @property
    def shape(self) -> str:
        return DEFAULT_BODY.get(self.task, "box")

    def resolved(self) -> dict:
        """The run's ``config.json``."""
        return {"command": "design", "task": self.task, "method": "particle-baseline",
                "start_shape": self.shape, "iterations": self.iterations, "steps": self.steps,
                "seed": self.seed, "arch": self.arch}


@dataclass
class ParticleRunResult:
    """The final metric and the files a particle-baseline run wrote."""

    task: str
    metric: float
    run_dir: Path
    design: Path
    montage: Path


def particle_run(cfg: ParticleRunConfig, out: str | Path | None = None,
                 on_iteration: Callable[[int, float], object] | None = None
                 ) -> ParticleRunResult:
    """Optimise the particle baseline in the run directory ``out`` (default
    ``runs/design-TASK-TIME``) and score the result with a fresh episode.

    ``on_iteration(k, metric)`` is called as iteration ``k`` finishes."""
    from dbtool.baselines.particle import optimise
    from dbtool.design import Design
    from dbtool.runs import RunDir, default_run_dir, seed_everything
    from dbtool.sim import runtime
    from dbtool.sim.rollout import simulate
    from dbtool.viz.render import montage

    task = get_task(cfg.task)
    runtime.init(arch=cfg.arch)
    seed_everything(cfg.seed)
    run = RunDir(out or default_run_dir("design", task.name), cfg.resolved(), cfg.seed,
                 runtime.device(), kind="design", option="--out", own=False)
    with run:
        def log(k: int, metric: float, _design) -> None:
            run.log(iteration=k, metric=metric)
            if on_iteration is not None:
                on_iteration(k, metric)

        d = optimise(task, reference_robot(task, cfg.shape), cfg.iterations, n_steps=cfg.steps,
                     callback=log)
        robot, actions = d.robot(), d.actions
        ro = simulate(task, robot.compact(), actions, n_steps=cfg.steps)
        run.log(iteration=cfg.iterations, metric=ro.metric, final=True)
        result = Design(task.name, robot, actions, metrics={task.name: ro.metric},
                        meta={"method": "particle-baseline", "seed": cfg.seed,
                              "iterations": cfg.iterations, "start_shape": cfg.shape})
        path = result.save(run.file("design.npz"))
        png = montage(ro.episode, ro.positions, run.file("montage.png"),
                      title=f"{task.title}: metric {ro.metric:.4f}")
    return ParticleRunResult(task.name, ro.metric, run.path, path, png)
