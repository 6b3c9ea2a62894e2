"""``tendons.png``: the gripper's tendon routing drawn over its parts (two orthographic views)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write
from dbtool.export._manifold import mesh_arrays

COLOURS = {"flexion": "tab:red", "extension": "tab:blue"}
PART_COLOURS = {"base": "0.55", "finger": "tab:orange", "finger_mirror": "tab:olive"}


def _silhouette(ax, solid, axes: tuple[int, int], colour) -> None:
    """Fill the projection of a part's triangles onto ``axes`` (front faces only)."""
    from matplotlib.collections import PolyCollection

    v, t = mesh_arrays(solid)
    tri = v[t][:, :, list(axes)]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    front = (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) > 0
    ax.add_collection(PolyCollection(tri[front], facecolors=colour, edgecolors="none",
                                     alpha=0.35))


def draw_tendons(asm, path: Path, title: str = "") -> Path:
    """Side view (z, y: the closing axis) and front view (x, y) with every tendon's path,
    routing points (dots), anchor (cross) and tube exit (triangle)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(10, 5.2))
    for ax, (a, b), label in ((axs[0], (2, 1), "z (mm), closing axis"),
                              (axs[1], (0, 1), "x (mm)")):
        for name, solid in asm.parts.items():
            _silhouette(ax, solid, (a, b), PART_COLOURS.get(name, "0.6"))
        for t in asm.tendons:
            p = t.path()
            c = COLOURS.get(t.role, "k")
            ax.plot(p[:, a], p[:, b], "-", color=c, lw=1.5)
            pts = np.array(t.points)
            ax.plot(pts[:, a], pts[:, b], "o", color=c, ms=4)
            ax.plot(t.anchor[a], t.anchor[b], "x", color="k", ms=7)
            ax.plot(t.exit[a], t.exit[b], "^", color=c, ms=7)
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel(label)
        ax.set_ylabel("y (mm), up")
    handles = [plt.Line2D([], [], color=c, label=f"{r} tendon") for r, c in COLOURS.items()]
    handles += [plt.Line2D([], [], color="k", marker="x", ls="", label="anchor"),
                plt.Line2D([], [], color="0.3", marker="^", ls="", label="tube exit")]
    axs[1].legend(handles=handles, loc="lower right", fontsize=8)
    fig.suptitle(f"tendon routing {title}".strip())
    fig.tight_layout()
    out = atomic_write(Path(path), lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    return out
