# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Figure 8 — robotizing noisy samples: DPSR (Psi) against Direct SDF
#
# During co-design the robotizer Psi turns intermediate diffusion samples x_t into robots and
# carries the simulator's gradients back to the points (docs/method.md §2). x_t is a surface cloud
# plus Gaussian noise: `x_t = sqrt(abar_t) x_0 + sqrt(1 - abar_t) eps` (cosine schedule, in the
# prior's model space). This notebook makes x_t at t = 300 from corpus shapes, robotizes it with
# Psi (oriented normals, robust reweighting, differentiable Poisson reconstruction, largest
# component) and with the Direct SDF baseline (signed distance to the nearest oriented point,
# interior filled by rejection sampling), and then runs a short gradient ascent of the crawling
# metric on the points through each robotizer.
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) uses two shapes, 10-step episodes and two ascent
# steps instead of three shapes, 100-step episodes and five steps.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image

from dbtool.prior.corpora.shapes import make_shape
from dbtool.prior.sampling.diffusion import noise_std
from dbtool.robotize.cloud_metric import evaluate
from dbtool.robotize.quality import iou, noisy
from dbtool.robotize.robotizer import lattice_dims, robotize
from dbtool.robotize.solid import components
from dbtool.sim.tasks import get_task
from dbtool.viz.robot import robot_figure

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
FAMILIES = ["quadruped", "hook"] if QUICK else ["quadruped", "hook", "star"]
T = 300
task = get_task("crawling")
dims = lattice_dims(task)

# %% [markdown]
# ## The two robotizers on x_0 and on x_t
#
# Each row: the noisy cloud, the robot Psi makes of the clean x_0 (the reference), Psi's robot
# of x_t, and Direct SDF's robot of x_t. Colours are the four crawling actuator groups.

# %%
pictures, scores = [], []
for k, family in enumerate(FAMILIES):
    x0 = make_shape(family, 0, "test", 0, 1024).points
    xt = noisy(x0, T, seed=k)
    ref = robotize(x0, task).robot
    ours = robotize(xt, task, noise=noise_std(T)).robot
    direct = robotize(xt, task, noise=noise_std(T), method="direct_sdf").robot
    ref_direct = robotize(x0, task, method="direct_sdf").robot
    scores.append({
        "family": family,
        "ours_iou": iou(ref.active(), ours.active()),
        "direct_iou": iou(ref_direct.active(), direct.active()),
        "ours_parts": components(ours.active().reshape(dims)),
        "direct_parts": components(direct.active().reshape(dims)),
    })
    path = f"fig08_{family}.png"
    robot_figure([(f"{family}: x_t, t = {T}", xt), ("Psi(x_0)", ref), ("Psi(x_t)", ours),
                  ("Direct SDF(x_t)", direct)], task.design_workspace(), path)
    pictures.append(path)

for s in scores:
    print(f"{s['family']:10s} IoU with the x_0 robot: Psi {s['ours_iou']:.2f} "
          f"({s['ours_parts']} part), Direct SDF {s['direct_iou']:.2f} "
          f"({s['direct_parts']} parts)")
Image(pictures[0])

# %%
Image(pictures[1])

# %% [markdown]
# Psi smooths the noise away and keeps the largest connected component. Direct SDF takes the
# sign of the distance from the nearest noisy point, which flips from point to point inside the
# noise, so its robot is ragged: holes and loose particles. The IoU printed above compares each
# method's x_t robot with the same method's x_0 robot; `benchmarks/robotize.py` measures it over
# 20 shapes of 10 families at t = 150 and 300 (`benchmarks/results/legacy/robotize.json`).
#
# ## A short co-optimisation through each robotizer
#
# Gradient ascent of the crawling distance on the points of x_t:
# `x <- x + eta * g / rms(g)` with `g = d metric / d x` from `evaluate(x, task, noise=...)`,
# eta = 0.01 (prior frame), the prescribed sine controller fixed. The same start, the same
# steps; only the robotizer differs.

# %%
STEPS = 10 if QUICK else 100
ITERS = 2 if QUICK else 5
ETA = 0.01
x_start = noisy(make_shape("quadruped", 0, "test", 0, 1024).points, T, seed=0)
curves = {}
for method in ("dpsr", "direct_sdf"):
    x = x_start.copy()
    curve = []
    for _ in range(ITERS + 1):
        metric, g = evaluate(x, task, noise=noise_std(T), method=method, n_steps=STEPS)
        curve.append(metric)
        x = x + ETA * g / max(np.sqrt(np.mean(g**2)), 1e-12)
    curves[method] = curve
    print(f"{method:10s} crawling distance per step: " + ", ".join(f"{m:.5f}" for m in curve))

fig, ax = plt.subplots(figsize=(4.5, 3))
for method, curve in curves.items():
    ax.plot(range(len(curve)), curve, marker="o", label={"dpsr": "Psi (DPSR)",
                                                         "direct_sdf": "Direct SDF"}[method])
ax.set_xlabel("ascent step")
ax.set_ylabel(f"crawling distance ({STEPS} control steps)")
ax.legend()
fig.tight_layout()
fig.savefig("fig08_curves.png", dpi=110)
plt.close(fig)
Image("fig08_curves.png")
