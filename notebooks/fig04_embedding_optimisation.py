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

# %%

# %% [markdown]
# # Figures 4 and 10 — embedding optimisation across epochs
#
# Algorithm 1 (docs/method.md §4, Table 4): the conditioning embedding c is trained, with the
# diffusion model frozen, on the best designs it produced. Each epoch samples designs from c,
# robotizes and simulates them (forward only), adds them to a FIFO buffer and takes Adam steps
# of the diffusion loss on the buffer's top-k. dbtool's c is a mixture over the conditions the
# prior was trained on (the null embedding and one caption per corpus family): each design is
# sampled from one of them, and training moves weight onto the conditions the top-k came from
# (`docs/codesign.md` explains why). From the null embedding the mixture starts uniform.
#
# For every task the notebook shows the best robot of each epoch and the mean and best
# performance per epoch. Quick mode (`DBTOOL_QUICK=1`, used in CI) runs crawling and gripping
# only, 2 epochs of 4 samples with 20-step episodes and 16 sampler steps: it documents the
# mechanics, and its numbers are too small a sample to show improvement. Unset, it runs all six
# tasks on the quick preset (4 epochs of 12 samples, top-3, 100-step episodes).

# %%
import os
from dataclasses import replace

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image, display

from dbtool.codesign.config import preset
from dbtool.codesign.embedding import EmbeddingOptimiser, caption_atoms
from dbtool.prior.sampling.pipeline import Prior
from dbtool.prior.sampling.text import null
from dbtool.robotize import robotize
from dbtool.sim.tasks import TASKS, get_task
from dbtool.viz.robot import robot_figure

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
N_STEPS = 20 if QUICK else 100
RUN = ("crawling", "gripping") if QUICK else tuple(TASKS)
prior = Prior.load(with_upsampler=False)
names, _ = caption_atoms()


def settings(task_name):
    emb, _ = preset("quick", task_name)
    if QUICK:
        emb = replace(emb, epochs=2, samples_per_epoch=4, min_buffer=4, top_k=2, batch_size=2,
                      sample_steps=16)
    return emb


# %% [markdown]
# ## Epochs of each task
#
# The best design of every epoch (its robot, coloured by actuator group, its metric and the
# condition it was sampled from) and the condition that holds the most weight in c at the end.

# %%
curves = {}
for task_name in RUN:
    task = get_task(task_name)
    emb = settings(task_name)
    opt = EmbeddingOptimiser(prior, task, emb, null(), seed=0, n_steps=N_STEPS)
    panels = []
    for _ in range(emb.epochs):
        row = opt.step()
        mine = [e for e in opt.buffer.entries if e.epoch == row["epoch"]]
        if mine:
            best = max(mine, key=lambda e: e.metric)
            panels.append((f"epoch {row['epoch']}: {best.metric:.4f}\n"
                           f"{(['null'] + list(names))[best.atom]}",
                           robotize(best.cloud, task).robot))
    curves[task_name] = opt.history
    w = opt.embedding.weights()
    atoms = ["null"] + list(names)  # start = null, so the atoms are null + the captions
    top = int(w.argmax())
    robot_figure(panels, task.design_workspace(), f"fig04_{task_name}.png",
                 f"{task.title}: heaviest condition {atoms[top]!r} ({float(w[top]):.2f})")
    display(Image(filename=f"fig04_{task_name}.png"))

# %% [markdown]
# ## Performance per epoch
#
# Mean (line) and best (dots) performance of each epoch's samples. Designs that could not be
# robotized or simulated count as failures and are left out of both.

# %%
fig, axes = plt.subplots(1, len(curves), figsize=(2.6 * len(curves), 2.6))
for ax, (task_name, hist) in zip(axes, curves.items(), strict=True):
    ep = [h["epoch"] for h in hist]
    ax.plot(ep, [h["mean"] for h in hist], "o-", label="mean")
    ax.plot(ep, [h["max"] for h in hist], "s", label="best")
    ax.set(title=task_name, xlabel="epoch", xticks=ep)
axes[0].set_ylabel("performance")
axes[0].legend(fontsize=7)
fig.tight_layout()
fig.savefig("fig04_curves.png", dpi=100)
plt.close(fig)
display(Image(filename="fig04_curves.png"))
for task_name, hist in curves.items():
    print(task_name, "means", np.round([h["mean"] for h in hist], 5).tolist(),
          "failed", [h["failed"] for h in hist])
