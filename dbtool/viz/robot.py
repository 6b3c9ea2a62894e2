"""Pictures of robotized bodies: particles coloured by actuator group (Figure 8)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dbtool.sim.robot import Robot  # noqa: E402
from dbtool.viz.clouds import draw_cloud, save_figure  # noqa: E402
from dbtool.viz.render import BODY, GROUP_COLOURS  # noqa: E402


def draw_robot(ax, robot: Robot, workspace, title: str | None = None,
               max_points: int = 8000) -> None:
    """Active particles of ``robot`` (workspace coordinates, y up) coloured by group."""
    idx = np.flatnonzero(robot.active())
    if len(idx) > max_points:
        idx = idx[np.linspace(0, len(idx) - 1, max_points).astype(int)]
    p = robot.points[idx]
    if robot.actuators.shape[1]:
        cols = list(np.array(GROUP_COLOURS)[robot.actuators[idx].argmax(1)])
    else:
        cols = BODY
    ax.scatter(p[:, 0], p[:, 2], p[:, 1], c=cols, s=1.5, depthshade=False, linewidths=0)
    ws = np.asarray(workspace, float)
    ax.set_xlim(0, ws[0])
    ax.set_ylim(0, ws[2])
    ax.set_zlim(0, ws[1])
    ax.set_box_aspect((ws[0], ws[2], ws[1]))
    ax.view_init(elev=18, azim=-60)
    for set_ticks in (ax.set_xticks, ax.set_yticks, ax.set_zticks):
        set_ticks([])
    if title:
        ax.set_title(title, fontsize=8)


def robot_figure(panels: Sequence[tuple[str, object]], workspace, path: str | Path,
                 title: str | None = None, size: float = 2.8) -> Path:
    """One row of panels, each ``(title, cloud (N, 3) | Robot)``, saved atomically as PNG."""
    fig = plt.figure(figsize=(size * len(panels), size + 0.3))
    for k, (name, item) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d")
        if isinstance(item, Robot):
            draw_robot(ax, item, workspace, name)
        else:
            draw_cloud(ax, np.asarray(item), name)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    out = save_figure(fig, path, 110)
    plt.close(fig)
    return out
