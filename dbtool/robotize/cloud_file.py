"""A point-cloud file becomes a saved design (``.npz``) and its picture (``dbtool robotize``;
docs/method.md §2)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

from dbtool.atomic import check_own_file
from dbtool.design import Design
from dbtool.pointcloud import load_ply
from dbtool.prior.sampling.diffusion import T_TRAIN, noise_std
from dbtool.robotize.robotizer import RobotizeConfig, RobotizeError, robotize
from dbtool.sim.tasks import get_task
from dbtool.viz.robot import robot_figure


@dataclass
class RobotizedFile:
    """The design a cloud file became, where it was saved and its picture."""

    design: Design
    path: Path
    picture: Path


def _robotized(path: Path) -> bool:
    """Whether ``path`` is a design ``dbtool robotize`` wrote (its method is a robotizer's)."""
    return Design.load(path).meta.get("method") in ("dpsr", "direct_sdf")


def robotize_cloud_file(cloud: str | Path, task_name: str, out: str | Path,
                        method: str = "dpsr", noise: float | None = None, t: int | None = None,
                        cfg: RobotizeConfig | None = None) -> RobotizedFile:
    """Robotize the PLY ``cloud`` for ``task_name``; write the design to ``out`` and a PNG of
    the particles coloured by actuator group next to it. ``t`` (a diffusion step) sets the
    noise level from the cosine schedule; ``noise`` sets it directly."""
    task = get_task(task_name)
    if t is not None and noise is not None:
        raise RobotizeError("give either --t or --noise, not both")
    if t is not None:
        if not 0 <= t < T_TRAIN:
            raise RobotizeError(f"--t must be in [0, {T_TRAIN - 1}], got {t}")
        noise = noise_std(t)
    if noise is not None and not 0.0 <= noise <= 1.0:
        raise RobotizeError(f"--noise must be in [0, 1] (prior frame), got {noise}")
    out = Path(out)
    if out.suffix != ".npz":
        raise RobotizeError(f"the output must be a .npz file, got {out}")
    check_own_file(out, _robotized, "-o")
    check_own_file(out.with_suffix(".png"), lambda p: _robotized(out), "-o")
    x = load_ply(cloud)
    cfg = cfg or RobotizeConfig()
    rz = robotize(x, task, cfg, noise=noise, method=method)
    robot = rz.robot
    meta = {"source": str(cloud), "method": method, "noise": rz.noise,
            "config": asdict(cfg), "placement": {"centre": rz.placement.centre.tolist(),
                                                 "anchor": rz.placement.anchor.tolist(),
                                                 "scale": rz.placement.scale.tolist()}}
    design = Design(task.name, robot, task.controller(), x, {}, meta)
    path = design.save(out)
    counts = robot.actuators[robot.active()].sum(0).astype(int).tolist()
    title = (f"{task.title}: {int(robot.active().sum())} particles"
             + (f", groups {counts}" if counts else ""))
    png = robot_figure([("cloud", x), (f"robot ({method})", robot)], task.design_workspace(),
                       out.with_suffix(".png"), title)
    return RobotizedFile(design, path, png)
