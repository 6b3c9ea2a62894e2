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
# # Figure 3 — the six tasks
#
# Each task of the paper (docs/method.md §3) with a simple reference body: the scene at the first
# and the last control step, and the task metric. Bodies are reference shapes (no design yet);
# gripping uses a finger-shaped plate and its mirror copy. Actuated tasks run their prescribed
# open-loop controller; colours mark actuator groups (grey: the task's cube).
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) runs 30 control steps instead of the paper's 100.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image

from dbtool.robotize.actuators import reference_robot
from dbtool.sim import runtime
from dbtool.sim.rollout import simulate
from dbtool.sim.tasks import TASKS, get_task
from dbtool.viz.render import draw_frame, particle_colours

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
STEPS = 30 if QUICK else 100
runtime.init("cpu")
BODIES = {"balancing": "box", "landing": "sphere", "crawling": "box", "hurdling": "box",
          "gripping": "finger", "box": "box"}

# %%
results = {}
for name in TASKS:
    task = get_task(name)
    robot = reference_robot(task, BODIES[name]).compact()
    ro = simulate(task, robot, task.controller(STEPS), n_steps=STEPS)
    results[name] = ro
    print(f"{task.title:13s} body={BODIES[name]:7s} particles={len(ro.episode.particles.x0):6d} "
          f"metric={ro.metric: .5f}   ({task.metric_text})")

# %%
fig = plt.figure(figsize=(12, 4.6))
for k, (name, ro) in enumerate(results.items()):
    cols = particle_colours(ro.episode)
    for row, t in enumerate((0, len(ro.positions) - 1)):
        ax = fig.add_subplot(2, 6, 1 + k + 6 * row, projection="3d")
        label = f"{get_task(name).title}\n{'start' if t == 0 else f'step {t}'}"
        draw_frame(ax, ro.episode, ro.positions[t], cols, 3000, label)
fig.tight_layout()
fig.savefig("fig03_tasks.png", dpi=110)
plt.close(fig)
Image("fig03_tasks.png")

# %% [markdown]
# The metric of each task, as printed above, is the quantity the co-design maximises.
# Balancing: IoU of the occupied space at the first and last step; landing:
# exp(-distance to the target); crawling and hurdling: x travel of the centre; gripping: lift
# of the cube; moving a box: +x travel of the cube (the direction dbtool fixes for both goal and
# metric).

# %%
summary = {name: round(ro.metric, 5) for name, ro in results.items()}
assert all(np.isfinite(v) for v in summary.values())
summary
