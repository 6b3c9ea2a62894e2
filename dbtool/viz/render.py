"""Motion montages and animations of a rollout (the notebooks of Figures 3, 5 and 9).

Headless: the Agg backend, nothing is shown on screen; files are written atomically.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dbtool.atomic import atomic_write  # noqa: E402

GROUP_COLOURS = ("#d62728", "#1f77b4", "#2ca02c", "#9467bd")
BODY, OBJECT, INACTIVE = "#ff9f1c", "#7f7f7f", None


def particle_colours(ep) -> np.ndarray:
    """Colour per simulator particle: actuator group, passive body, or task object."""
    p = ep.particles
    cols = np.array([BODY] * len(p.x0), dtype=object)
    groups = p.actuators.sum(1) > 0
    cols[groups] = np.array(GROUP_COLOURS)[p.actuators[groups].argmax(1)]
    cols[ep.object_mask] = OBJECT
    return cols


def shown_particles(ep, max_points: int) -> np.ndarray:
    """Indices of at most ``max_points`` active particles (presence > 0), evenly spaced: the
    ones every figure, report and viewer of a rollout draws."""
    idx = np.flatnonzero(ep.particles.presence > 0)
    if len(idx) > max_points:
        idx = idx[np.linspace(0, len(idx) - 1, max_points).astype(int)]
    return idx


def box_edges(c: np.ndarray, h: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 12 edges of the axis-aligned box of centre ``c`` and half-size ``h``."""
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    pts = np.asarray(c) + corners * np.asarray(h)
    return [(pts[i], pts[j]) for i in range(8) for j in range(i + 1, 8)
            if np.sum(corners[i] != corners[j]) == 1]


def draw_frame(ax, ep, x: np.ndarray, cols, max_points: int, title: str | None) -> None:
    """Draw one frame of a rollout (active particles, colliders, ground) on a 3-D axis."""
    idx = shown_particles(ep, max_points)
    # the simulator's y is up: plot (x, z, y) so gravity points down the page
    ax.scatter(x[idx, 0], x[idx, 2], x[idx, 1], c=list(cols[idx]), s=1.5, depthshade=False,
               linewidths=0)
    for c, h in ep.scene.boxes:
        for a, b in box_edges(c, h):
            ax.plot([a[0], b[0]], [a[2], b[2]], [a[1], b[1]], color="k", lw=0.6)
    size = ep.scene.size
    ax.set_xlim(0, size[0])
    ax.set_ylim(0, size[2])
    ax.set_zlim(0, size[1])
    ax.set_box_aspect((size[0], size[2], size[1]))
    ax.view_init(elev=18, azim=-60)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_zticks([])
    g = ep.scene.ground_y
    xx, zz = np.meshgrid([0, size[0]], [0, size[2]])
    ax.plot_surface(xx, zz, np.full_like(xx, g), color="#dddddd", alpha=0.4, linewidth=0)
    if title:
        ax.set_title(title, fontsize=8)


def _atomic_save(fig_or_writer, path: Path, save) -> Path:
    return atomic_write(path, save)


def montage(ep, positions: np.ndarray, path, frames: int = 6, max_points: int = 6000,
            title: str | None = None) -> Path:
    """A row of ``frames`` snapshots evenly spaced over the rollout, saved as PNG."""
    steps = np.linspace(0, len(positions) - 1, frames).astype(int)
    fig = plt.figure(figsize=(2.2 * frames, 2.6))
    cols = particle_colours(ep)
    for k, t in enumerate(steps):
        ax = fig.add_subplot(1, frames, k + 1, projection="3d")
        draw_frame(ax, ep, positions[t], cols, max_points, f"step {t}")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    out = _atomic_save(fig, path, lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)
    return out


def animation(ep, positions: np.ndarray, path, every: int = 4, max_points: int = 4000,
              fps: int = 12) -> Path:
    """An animated GIF of the rollout (every ``every``-th control step)."""
    import imageio.v2 as imageio

    cols = particle_colours(ep)
    images = []
    fig = plt.figure(figsize=(3.6, 3.0))
    for t in range(0, len(positions), every):
        fig.clf()
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        draw_frame(ax, ep, positions[t], cols, max_points, f"step {t}")
        fig.canvas.draw()
        images.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)
    return _atomic_save(None, path, lambda p: imageio.mimsave(p, images, format="GIF",
                                                              duration=1.0 / fps, loop=0))
