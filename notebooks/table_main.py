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
# # Main table — DiffuseBot against the baselines
#
# The paper's main comparison: six methods on the six tasks, each given the same simulator
# budget per cell (one method on one task with one seed), the table listing the task metric of
# each method's final design (higher is better on every task). `dbtool compare` runs it
# (docs/results.md); this notebook explains the budget, shows the committed tables on the
# `quick` and `standard` budgets and runs a small comparison of its own through the same
# library call.
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) runs gripping with one seed on the `smoke` budget
# (fig12_baselines runs crawling); unset, all six tasks with two seeds, still on `smoke` (the
# `quick` budget's full-length episodes take hours for the whole table: `dbtool compare
# --preset quick`).

# %%
import csv
import json
import os
import tempfile
import time
from pathlib import Path

from IPython.display import Image, Markdown, display

from dbtool.compare.budget import BUDGETS, GRAD_COST, get_budget, gradient_iterations
from dbtool.compare.methods import METHODS, TITLES, diffusebot_plan
from dbtool.compare.report import bar_chart, read_results, table_markdown
from dbtool.compare.run import CompareConfig, compare
from dbtool.sim.tasks import TASKS as ALL_TASKS

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
if QUICK:
    TASKS, SEEDS, BUDGET = ("gripping",), (0,), "smoke"
else:
    TASKS, SEEDS, BUDGET = tuple(ALL_TASKS), (0, 1), "smoke"
COMMITTED = (Path("../docs/results/compare-quick"), Path("../docs/results/compare-standard"))
print(f"tasks {', '.join(TASKS)}; seeds {SEEDS}; budget {BUDGET!r}")

# %% [markdown]
# ## What is compared, and how the budget is counted
#
# - **particle, voxel, implicit fn, diff-CPPN**: the gradient baselines (docs/method.md §7),
#   four design representations started from the task's reference body and ascended by the
#   shared gradient loop (Adam on the design parameters and the open-loop controller);
# - **prior samples**: plain samples of the shipped diffusion prior from the null embedding,
#   each robotized and scored with the task's prescribed controller, the best kept;
# - **DiffuseBot**: embedding optimisation, then diffusion as co-design (docs/method.md §4-§5).
#
# The budget is simulator cost, counted in **forward-episode units**: one unit is one forward
# episode of the task. A gradient episode (the forward pass with checkpoints, then the backward
# pass) counts `GRAD_COST` units, the measured cost ratio of a backward pass. What a cell spends
# is counted from the simulator's episode counters, not planned, and every method ends with one
# forward evaluation of its final design. The diffusion model's own cost (sampling,
# robotizing) is outside the budget; its wall time is in `results.csv`. The budgets, and how each
# method splits the one used here:

# %%
print(f"GRAD_COST = {GRAD_COST:g} units per gradient episode")
lines = ["| budget | units per cell | control steps | sampler steps | use |",
         "|---|---:|---:|---:|---|"]
lines += [f"| `{b.name}` | {b.units} | {b.n_steps} | {b.sample_steps} | {b.text} |"
          for b in BUDGETS.values()]
display(Markdown("\n".join(lines)))
budget = get_budget(BUDGET)
plan = diffusebot_plan(TASKS[0], budget)
print(f"{BUDGET!r} budget, {budget.units} units per cell:")
print(f"  gradient baselines: {gradient_iterations(budget.units)} gradient episode(s), then the "
      "final evaluation")
print(f"  prior samples: {max(1, budget.units - 1)} samples scored, then the final evaluation")
print(f"  DiffuseBot on {TASKS[0]}: {plan['epochs']} embedding epoch(s) of "
      f"{plan['samples_per_epoch']} design(s), then {plan['refine_steps']} refinement step(s) "
      f"of the elite, each a gradient episode and {plan['line_search']} line-search "
      f"episode(s); planned {plan['planned_units']:g} units")

# %% [markdown]
# ## The committed tables (`quick` and `standard` budgets)
#
# `docs/results/compare-quick/` holds the comparison on the `quick` budget (20 units per cell)
# and `docs/results/compare-standard/` the one on the `standard` budget (100 units per cell,
# seeds 0, 1, 2), as `dbtool compare` wrote them: `results.csv`, the table, the bar chart and,
# for `standard`, the paired differences DiffuseBot − each method with their verdicts and the
# anytime curves (best metric found against units spent).

# %%
for folder in COMMITTED:
    committed_csv = folder / "results.csv"
    display(Markdown(f"### `{folder.name}`"))
    if not committed_csv.is_file():
        display(Markdown(f"*No committed comparison: `{committed_csv}` does not exist. Make it "
                         f"with `dbtool compare --out docs/results/{folder.name}`.*"))
        continue
    display(Markdown(table_markdown(read_results(committed_csv))))
    for name in ("bars.png", "anytime.png"):
        if (folder / name).is_file():
            display(Image(str(folder / name)))
    if (folder / "paired.md").is_file():
        display(Markdown((folder / "paired.md").read_text()))

# %% [markdown]
# ## A fresh comparison
#
# The same library call as `dbtool compare`, run here in this process (`executor="serial"`)
# into a temporary folder. On the `smoke` budget the gradient baselines get a single gradient
# episode and the episodes are short, so the table shows that the pipeline works end to end,
# not how the methods rank at a real budget.

# %%
out = Path(tempfile.mkdtemp(prefix="table-main-")) / "compare"
t0 = time.perf_counter()
result = compare(CompareConfig(tasks=list(TASKS), methods=["all"], seeds=list(SEEDS),
                               budget=BUDGET), out=out, executor="serial", echo=print)
print(f"{result['done']} cells done, {result['failed']} failed in "
      f"{time.perf_counter() - t0:.0f} s")
rows = read_results(out / "results.csv")
display(Markdown(table_markdown(rows)))
display(Image(str(bar_chart(rows, "table_main_bars.png"))))

# %% [markdown]
# ## Budget used per cell
#
# From the run's `results.csv`: the units each cell was given and what it spent
# (`forward + (GRAD_COST - 1) * gradient` episodes), and its wall time (including work outside
# the budget, such as sampling the prior).

# %%
with open(out / "results.csv", newline="") as fh:
    raw = list(csv.DictReader(fh))
cols = ("method", "task", "seed", "status", "budget_units", "budget_used", "forward_episodes",
        "gradient_episodes", "wall_s")
lines = ["| " + " | ".join(cols) + " |", "|---|---|---:|---|" + "---:|" * (len(cols) - 4)]
lines += ["| " + " | ".join(r[c] for c in cols) + " |" for r in raw]
display(Markdown("\n".join(lines)))
over = [r for r in rows if r["budget_used"] > r["budget_units"]]
for m in METHODS:
    mine = [r for r in rows if r["method"] == m]
    used = sorted({r["budget_used"] for r in mine})
    print(f"{TITLES[m]:14s} used {', '.join(f'{u:g}' for u in used)} of {budget.units} units; "
          f"wall {sum(r['wall_s'] for r in mine):.0f} s over {len(mine)} cells")
print(f"{len(over)} of {len(rows)} cells spent more than their budget"
      + (f": {', '.join(sorted({r['method'] for r in over}))}" if over else ""))
assert result["done"] + result["failed"] == len(TASKS) * len(METHODS) * len(SEEDS)
assert all(r["budget_used"] > 0 for r in rows)

# %% [markdown]
# ## Anytime curves
#
# Every progress row of a cell records the units spent when it was written, so the report also
# draws, per task, the best metric each method had found against the units it had spent (mean
# over seeds, min to max as a band): `anytime.png` and one `anytime-TASK.png` per task in the
# comparison folder (`dbtool/compare/anytime.py`). On `smoke` the curves have a few points
# each; on `standard` they show whether a method was still improving when its budget ran out.

# %%
display(Image(str(out / "anytime.png")))
anytime = json.loads((out / "anytime.json").read_text())
for task, per in anytime.items():
    ends = {m: c["mean"][-1] for m, c in per.items()}
    print(task, {TITLES[m]: None if v is None else round(v, 4) for m, v in ends.items()})
assert anytime and set(anytime) <= set(TASKS)
