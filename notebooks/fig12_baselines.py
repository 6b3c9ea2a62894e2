# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.7
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Figure 12 — the robots each baseline makes
#
# The paper's Figure 12 shows, per task, the final robot of every baseline next to DiffuseBot's.
# `dbtool compare` (docs/results.md) draws the same grid from a comparison folder: rows are the
# methods, columns the tasks, each panel the final design of the cell (the lowest seed) titled
# with its task metric. This notebook shows the grid of the committed comparison on the `quick`
# budget, then runs the methods itself and draws its own grid and each method's final episode.
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) runs crawling only; unset, crawling, gripping and
# hurdling. Both use the `smoke` budget (8-step episodes, a single gradient episode for the
# gradient baselines), so the fresh robots are barely moved from where each method starts: the
# run documents the pipeline and the starting points, not the paper's results.

# %%
import os
import tempfile
import time
from pathlib import Path

import matplotlib.pyplot as plt
from IPython.display import Image, Markdown, display

from dbtool.baselines.registry import REPRESENTATIONS, make
from dbtool.compare.methods import METHODS, TITLES
from dbtool.compare.report import cell_dir, grid_cells, read_results, robot_grid
from dbtool.compare.run import CompareConfig, compare
from dbtool.sim.tasks import get_task

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
if QUICK:
    TASKS, BUDGET = ("crawling",), "smoke"
else:
    TASKS, BUDGET = ("crawling", "gripping", "hurdling"), "smoke"
COMMITTED = Path("../docs/results/compare-quick")
print(f"tasks {', '.join(TASKS)}; budget {BUDGET!r}; seed 0")

# %% [markdown]
# ## The committed grid (`quick` budget)

# %%
if (COMMITTED / "robots.png").is_file():
    display(Image(str(COMMITTED / "robots.png")))
else:
    display(Markdown(f"*No committed comparison yet: `{COMMITTED / 'robots.png'}` does not "
                     "exist. Make it with `dbtool compare --preset quick --out "
                     "docs/results/compare-quick`.*"))

# %% [markdown]
# ## Where the gradient baselines start
#
# Every gradient baseline starts from the task's reference body (docs/method.md §7); they
# differ in how the design is parameterised, and so in how many parameters the gradient moves
# (counted here on the first task, the open-loop controller not included). The prior samples
# and DiffuseBot start from the diffusion model instead.

# %%
first = get_task(TASKS[0])
for name, cls in REPRESENTATIONS.items():
    n = make(name, first).n_parameters()
    print(f"{TITLES[name]} ({first.title}): {n:,} parameters\n  {cls.init_text}")

# %% [markdown]
# ## A fresh run of every method
#
# `compare` with all six methods, one seed, in this process; the grid is drawn from the run's
# folder with the same `robot_grid` that writes `robots.png`.

# %%
out = Path(tempfile.mkdtemp(prefix="fig12-")) / "compare"
t0 = time.perf_counter()
result = compare(CompareConfig(tasks=list(TASKS), methods=["all"], seeds=[0], budget=BUDGET),
                 out=out, executor="serial", echo=print)
print(f"{result['done']} cells done, {result['failed']} failed in "
      f"{time.perf_counter() - t0:.0f} s")
rows = read_results(out / "results.csv")
display(Image(str(robot_grid(out, rows, "fig12_baselines.png"))))

# %% [markdown]
# ## Each method's final episode on the first task
#
# The cell's `montage.png`: the final design with its controller over the episode.

# %%
pick = grid_cells(rows)
fig, axes = plt.subplots(len(METHODS), 1, figsize=(12, 2.1 * len(METHODS)))
for ax, m in zip(axes, METHODS, strict=True):
    ax.set_axis_off()
    row = pick.get((m, TASKS[0]))
    path = None if row is None else cell_dir(out, row) / "montage.png"
    if path is None or not path.is_file():
        ax.text(0.5, 0.5, f"{TITLES[m]}: no montage (cell failed)", ha="center",
                transform=ax.transAxes)
        continue
    ax.imshow(plt.imread(path))
    ax.set_title(TITLES[m], fontsize=10, loc="left")
fig.tight_layout()
fig.savefig("fig12_montages.png", dpi=100)
plt.close(fig)
display(Image("fig12_montages.png"))
assert result["done"] + result["failed"] == len(TASKS) * len(METHODS)
assert len(pick) == len(TASKS) * len(METHODS)
