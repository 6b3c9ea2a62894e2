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
# # Figure 11 — samples across diffusion time
#
# The prior (docs/method.md §1) denoises a Gaussian cloud into a body in 1,024 training steps;
# dbtool samples it with strided DDIM and classifier-free guidance (scale 3). The denoising loop
# is a generator that hands back control at chosen timesteps, so the intermediate clouds x_t at
# t = 600, 400, 200 and the final x_0 come out of one run. These intermediate x_t are what the
# co-design chain robotizes and simulates at t = 400, 350, ... (docs/method.md §5); the last
# cell shows their robotized views.
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) draws one sample per prompt with 32 steps instead of
# two with 64.

# %%
import os

import numpy as np
import torch
from IPython.display import Image

from dbtool.prior.sampling.pipeline import Prior
from dbtool.prior.training.metrics import chamfer_matrix
from dbtool.viz.clouds import cloud_grid

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
N = 1 if QUICK else 2
STEPS = 32 if QUICK else 64
TIMES = (600, 400, 200, 0)
PROMPTS = ["a star", "a table", "a pair of wings", "a ball"]
prior = Prior.load(with_upsampler=False)

# %%
rows = []
for k, prompt in enumerate(PROMPTS):
    res = prior.sample(prompt, n=N, guidance=3.0, steps=STEPS, seed=k, return_at=TIMES)
    for i in range(N):
        rows.append((prompt, [res.intermediates[t][i] for t in TIMES]))

clouds = [c for _, cs in rows for c in cs]
titles = [f"{p}\nt = {t}" for p, _ in rows for t in TIMES]
cloud_grid(clouds, "fig11_diffusion_process.png", titles, cols=len(TIMES), lim=1.0, cell=2.2)
Image("fig11_diffusion_process.png")

# %% [markdown]
# How far each x_t still is from the sample it becomes: the Chamfer distance (mean squared
# nearest-neighbour distance, both ways, in the unit-cube frame) between x_t and x_0. It falls
# monotonically as t goes to 0; most of the shape is decided by t = 200.

# %%
table = {}
for prompt, cs in rows:
    final = torch.from_numpy(np.asarray(cs[-1], np.float32))[None]
    d = [float(chamfer_matrix(torch.from_numpy(np.asarray(c, np.float32))[None], final))
         for c in cs]
    table.setdefault(prompt, []).append(d)
for prompt, ds in table.items():
    mean = np.mean(ds, 0)
    print(f"{prompt:16s} " + "  ".join(f"t={t}: {v:.4f}" for t, v in zip(TIMES, mean, strict=True)))
    assert np.all(np.diff(mean) <= 1e-9), "x_t should approach x_0 as t decreases"

# %% [markdown]
# ## Interpolating between two prompts
#
# The conditioning space is continuous, which is what embedding optimisation (docs/method.md §4)
# moves through. Spherical interpolation from the embedding of "a ball" to that of "a star",
# sampled from the same initial noise at every point of the path, morphs one family into the
# other. `dbtool prior evaluate` measures the same paths (share of samples nearest to each
# family); the numbers are in the model card.

# %%
from dbtool.prior.sampling.text import interpolate

a, b = prior.embed(["a ball", "a star"])
US = np.linspace(0, 1, 4 if QUICK else 6)
path = [prior.sample(embedding=interpolate(a, b, float(u)), n=1, steps=STEPS, seed=0).clouds[0]
        for u in US]
cloud_grid(path, "fig11_interpolation.png", [f"u = {u:.2f}" for u in US], cols=len(US))
Image("fig11_interpolation.png")

# %% [markdown]
# ## What the robotizer makes of x_t
#
# The co-design chain robotizes x_t, not x_0. Psi (`dbtool.robotize`, Figure 8) is told the
# noise level of each x_t (its std in the cloud's frame, from the cosine schedule) and turns the
# samples of the first prompt into crawling robots (colours: the four actuator groups).

# %%
from dbtool.prior.sampling.diffusion import noise_std
from dbtool.robotize.robotizer import robotize
from dbtool.sim.tasks import get_task
from dbtool.viz.robot import robot_figure

crawl = get_task("crawling")
prompt, cs = rows[0]
panels = [(f"t = {t}", robotize(c, crawl, noise=noise_std(t) if t else None).robot)
          for t, c in zip(TIMES, cs, strict=True)]
robot_figure(panels, crawl.design_workspace(), "fig11_robotized.png", title=prompt)
Image("fig11_robotized.png")
