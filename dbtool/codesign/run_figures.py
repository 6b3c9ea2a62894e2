"""A design run's figures: the performance per embedding epoch and along each co-designed
sample's chain (``performance.png``) and the run's ``report.html`` (docs/method.md §4-5)."""

from __future__ import annotations

import json
from pathlib import Path

from dbtool.atomic import atomic_write


def write_run_report(folder: Path, design, ro, rows: list[dict]) -> Path:
    """``folder/report.html`` (:mod:`dbtool.viz.report`): the run's performance curves, the
    design and its rollout ``ro``, the folder's config and manifest."""
    from dbtool.sim.tasks import get_task
    from dbtool.viz.report import write_report

    def read(name: str) -> dict | None:
        f = folder / name
        return json.loads(f.read_text()) if f.is_file() else None

    task = get_task(design.task)
    summary = {"task": task.title, **{k: design.meta[k] for k in ("method", "preset", "seed",
                                                                   "source", "prompt")
                                      if design.meta.get(k) is not None}}
    return write_report(folder / "report.html", f"dbtool: {task.title}, {folder.name}",
                        ro.episode, ro.positions, ro.metric, performance_panels(rows),
                        summary, read("config.json"), read("manifest.json"))


def performance_panels(rows: list[dict]) -> list:
    """The run's two performance plots from its logged rows: mean and max per embedding
    epoch, and the metric of x_t along each co-designed sample's chain."""
    from dbtool.viz.report import Curve, Panel

    ep = [r for r in rows if r.get("phase") == "embedding"]
    epochs = [r["epoch"] for r in ep]
    emb = Panel("embedding optimisation", "epoch", "performance",
                [Curve("mean", epochs, [r["mean"] for r in ep]),
                 Curve("max", epochs, [r["max"] for r in ep])] if ep else [])
    cd = [r for r in rows if r.get("phase") == "codesign" and "metric" in r
          and not r.get("final")]
    chain = Panel("diffusion as co-design", "Langevin step", "performance of x_t")
    for s in sorted({r["sample"] for r in cd}):
        pts = [r["metric"] for r in cd if r["sample"] == s]
        chain.curves.append(Curve(f"sample {s}", list(range(len(pts))), pts))
    ref = [r["metric"] for r in rows if r.get("phase") == "refine" and "metric" in r
           and not r.get("final")]
    if ref:  # co-design from the elite: the design's metric before each refinement step
        chain.curves.append(Curve("from the elite", list(range(len(ref))), ref))
    return [emb, chain]


def performance_figure(rows: list[dict], path: Path, title: str) -> Path:
    """Mean and max performance per epoch, and the metric of x_t along co-design."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    styles, fonts = (("o-", "s--"), ("o-",)), (None, 7)  # the epochs' panel, the chains'
    for ax, panel, style, font in zip(axes, performance_panels(rows), styles, fonts,
                                      strict=True):
        for i, c in enumerate(panel.curves):
            ax.plot(c.x, c.y, style[min(i, len(style) - 1)], label=c.label)
        if panel.curves:
            ax.legend(fontsize=font)
        ax.set(xlabel=panel.xlabel, ylabel=panel.ylabel, title=panel.title)
    fig.suptitle(title)
    fig.tight_layout()
    out = atomic_write(path, lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)
    return out
