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

# %%

# %% [markdown]
# # Figures 5 and 9 — the final robot of each task in motion
#
# `dbtool design TASK` (DiffuseBot, docs/method.md §4-§5) breeds a robot per task: embedding
# optimisation (Algorithm 1) and then co-design from the elite (the best design of the epochs
# refined by the Langevin steps of the last co-design stop, whose drift is the simulator's
# gradient, with the controller co-optimised on active tasks). This notebook runs
# the library call behind the CLI (`DesignRun`) for each of the six tasks on the `quick` preset
# and shows the final robot in motion.
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) runs crawling and gripping only, with one
# embedding epoch of 4 designs, 16 sampler steps, 5 refinement steps and 10-step episodes
# per task, and skips the upsampler (the
# final design keeps its 1,024-point cloud; the figures show the robot's particles), so the
# robots are barely optimised: the notebook then documents the pipeline, not the paper's
# performance. Unset, it runs the full quick preset (4 epochs of 12 samples, 32 sampler steps,
# 10 refinement steps, 100-step episodes; about 10 minutes per task here).

# %%
import os
import tempfile
from pathlib import Path

from IPython.display import Image, display

from dbtool.codesign.design_run import DesignRun, Settings
from dbtool.prior.sampling.pipeline import Prior
from dbtool.sim.tasks import TASKS

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
SIZES = dict(epochs=1, samples_per_epoch=4, sample_steps=16, refine=5,
             n_steps=10) if QUICK else {}
UPSAMPLE = not QUICK  # the final design's 4,096-point surface
RUN = ("crawling", "gripping") if QUICK else tuple(TASKS)
prior = Prior.load(with_upsampler=UPSAMPLE)
root = Path(tempfile.mkdtemp(prefix="fig05-"))

# %% [markdown]
# ## One design run per task
#
# Each run writes its run directory (config, manifest, metrics, checkpoint, `design.npz`, the
# performance curve and the montage). The table lists the final metric (the task's metric of
# the final robot with its co-optimised controller) and the epoch means.

# %%
def design(name: str) -> None:
    """One `quick` design run of task ``name`` into ``results`` when ``name`` is in ``RUN``
    (one cell per task keeps each cell short)."""
    if name not in RUN:
        return
    run = DesignRun(root / name, Settings(name, "quick", seed=0, **SIZES), prior)
    run.start("cpu")
    final = run.run(show_progress=False)
    epochs = [r for r in run.state.rows if r["phase"] == "embedding"]
    results[name] = final, run.path, [round(r["mean"], 5) for r in epochs]


results = {}

# %%
design("balancing")

# %%
design("landing")

# %%
design("crawling")

# %%
design("hurdling")

# %%
design("gripping")

# %%
design("box")

# %%
assert list(results) == list(RUN)
print(f"{'task':<10} {'final metric':>13}  epoch means")
for name, (final, _, means) in results.items():
    print(f"{name:<10} {final.metrics[name]:>13.5f}  {means}")

# %% [markdown]
# ## The robots in motion
#
# Six frames evenly spaced over each episode; particles are coloured by actuator group (passive
# tasks in one colour) and the task's objects (walls, the cube, the box) are drawn with them.

# %%
for _name, (_, path, _) in results.items():
    display(Image(filename=str(path / "montage.png")))

# %% [markdown]
# ## Performance along the run
#
# Left: mean and best performance of each epoch's samples. Right: the performance of the
# design before each refinement step of co-design from the elite.

# %%
for _name, (_, path, _) in results.items():
    display(Image(filename=str(path / "performance.png")))
