"""Where DiffuseBot wins or loses a task of the comparison, and why (docs/results.md): the
verdict per task, and a figure of each method's metric against the budget it had spent, next
to the final designs in motion."""

from __future__ import annotations

import json
from pathlib import Path

from dbtool.atomic import atomic_write
from dbtool.choices import METHODS
from dbtool.compare.budget import GRAD_COST
from dbtool.compare.labels import method_name
from dbtool.compare.report import TASKS, cell_dir


def verdicts(rows: list[dict], method: str = "diffusebot") -> list[dict]:
    """Per task: ``method``'s mean, the best other method and its mean, and whether
    ``method`` has the best mean (ties count as a win)."""
    out = []
    for task in TASKS:
        means = {m: _mean(rows, m, task) for m in METHODS}
        means = {m: v for m, v in means.items() if v is not None}
        if method not in means or len(means) < 2:
            continue
        others = {m: v for m, v in means.items() if m != method}
        best = max(others, key=others.get)
        out.append({"task": task, "mean": means[method], "best_other": best,
                    "best_other_mean": others[best], "wins": means[method] >= others[best]})
    return out


def _mean(rows: list[dict], method: str, task: str) -> float | None:
    vals = [r["metric"] for r in rows if r["method"] == method and r["task"] == task
            and r["status"] == "done"]
    return sum(vals) / len(vals) if vals else None


def spending(folder: Path) -> list[tuple[float, float]]:
    """``(units spent, metric)`` of every design a cell evaluated, in order, from its
    ``metrics.jsonl`` and ``cell.json``."""
    rec = json.loads((folder / "cell.json").read_text())
    info = rec.get("info") or {}
    rows = [json.loads(line) for line in (folder / "metrics.jsonl").read_text().splitlines()]
    pts: list[tuple[float, float]] = []
    spent = 0.0
    per_epoch = info.get("samples_per_epoch", 1)
    for r in rows:
        phase = r.get("phase")
        if phase == "gradient" and "metric" in r:
            spent += GRAD_COST
        elif phase == "sample":
            spent += 1
        elif phase == "embedding":
            spent += per_epoch
            r = {**r, "metric": r.get("max")}
        elif phase == "codesign":
            spent += 1 if r.get("final") else GRAD_COST
            if r.get("metric") is not None:
                pts.append((spent, float(r["metric"])))
            for m in r.get("search") or []:  # the line search's forward episodes
                spent += 1
                if m is not None:
                    pts.append((spent, float(m)))
            continue
        elif phase == "final":
            spent += 1
        else:
            continue
        if r.get("metric") is not None:
            pts.append((spent, float(r["metric"])))
    return pts


def why_figure(out_dir: str | Path, task: str, methods: list[str], path: str | Path,
               seed: int = 0) -> Path:
    """Metric against units spent for ``methods`` on ``task`` (left: each evaluated design as a
    dot, the best so far as a line; for DiffuseBot's embedding epochs the best design of the
    epoch), and their final designs in motion (the cells' montages, right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    fig = plt.figure(figsize=(13, 2.6 * len(methods)))
    grid = fig.add_gridspec(len(methods), 3)
    ax = fig.add_subplot(grid[:, 0])
    for i, m in enumerate(methods):
        folder = cell_dir(out_dir, {"method": m, "task": task, "seed": seed})
        pts = spending(folder)
        if pts:
            x, y = zip(*pts, strict=True)
            best = [max(y[: k + 1]) for k in range(len(y))]
            line = ax.step(x, best, where="post", label=f"{method_name(m)} (best so far)")
            ax.plot(x, y, "o", ms=3, alpha=0.5, color=line[0].get_color())
        img = fig.add_subplot(grid[i, 1:])
        if (folder / "montage.png").is_file():
            img.imshow(mpimg.imread(folder / "montage.png"))
        else:  # a comparison folder kept without its cells' montages
            img.text(0.5, 0.5, f"no montage.png in {folder.name}", ha="center", va="center")
        img.set_axis_off()
        img.set_title(f"{method_name(m)}: final design", fontsize=9)
    ax.set(xlabel="budget spent (forward-episode units)", ylabel="metric",
           title=f"{task}, seed {seed}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    res = atomic_write(Path(path), lambda p: fig.savefig(p, dpi=90, format="png"))
    plt.close(fig)
    return res
