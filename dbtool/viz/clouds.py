"""Point-cloud grids: samples of the prior, x_t across diffusion time (Figure 11).

Headless (Agg); files are written atomically. Clouds are in the prior's frame
(``[-0.5, 0.5]^3``, y up) and drawn with y pointing up the page.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dbtool.atomic import atomic_write  # noqa: E402
from dbtool.errors import InputError


def draw_cloud(ax, cloud: np.ndarray, title: str | None = None, lim: float = 0.55,
               colour: str = "#1f77b4", size: float = 1.5) -> None:
    """Scatter one ``(n, 3)`` cloud on a 3-D axis, y up, fixed limits, no ticks."""
    c = np.asarray(cloud)
    ax.scatter(c[:, 0], c[:, 2], c[:, 1], s=size, c=colour, depthshade=True, linewidths=0)
    for setter in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        setter(-lim, lim)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=20, azim=-60)
    ax.set_axis_off()
    if title:
        ax.set_title(title, fontsize=8)


def cloud_grid(clouds: Sequence[np.ndarray], path: str | Path, titles: Sequence[str] | None = None,
               cols: int | None = None, lim: float = 0.55, cell: float = 2.0,
               suptitle: str | None = None, dpi: int = 100) -> Path:
    """A grid PNG of clouds (row-major, ``cols`` per row) written atomically to ``path``."""
    n = len(clouds)
    if n == 0:
        raise InputError("no clouds to draw")
    cols = cols or min(n, 8)
    rows = -(-n // cols)
    fig = plt.figure(figsize=(cell * cols, cell * rows + (0.4 if suptitle else 0)))
    for k, cloud in enumerate(clouds):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        draw_cloud(ax, cloud, titles[k] if titles else None, lim)
    if suptitle:
        fig.suptitle(suptitle, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi)


def save_figure(fig, path: str | Path, dpi: int = 100) -> Path:
    """Save a matplotlib figure atomically (temp file in the same folder, then rename)."""
    try:
        return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi))
    finally:
        plt.close(fig)
