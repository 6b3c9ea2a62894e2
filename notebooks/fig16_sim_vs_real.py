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
# # Figure 16 — sim vs real: the tendon protocol
#
# The paper pulls the flexion tendon of its printed gripper, then the extension tendon, in 2 mm
# increments and releases it, measuring the distance between the fingertips after each step;
# simulation and the real robot both give log-shaped curves, and the real one shows hysteresis
# and a fast change on release from full contraction (docs/realgap.md). This notebook runs that
# protocol on the reference gripper (`exports/gripping-seed0`): it simulates it, replays the
# example log shipped beside the design, fits the tendon map to the log through the
# differentiable simulator, and replays the log again with the fitted parameters.
#
# **The example log is illustrative, not a measurement.** It was made by
# `python scripts/realgap_example_log.py` from the simulator with hidden parameters, a fast change
# on release and noise added (its `notes` metadata says which). With a log measured on a
# printed gripper, the same calls apply.
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) uses the flexion tendon's readings at 0, 6 and
# 10 mm only (5 mm steps in simulation) and fits the gain alone in at most 3 gradient
# evaluations; unset, both tendons at every 2 mm step, the stiffness scale too, and up to 20
# evaluations.

# %%
import os
import tempfile
from pathlib import Path

import numpy as np
from IPython.display import Image, Markdown, display

from dbtool.realgap.calibrate import calibrate
from dbtool.realgap.fingertips import mesh_tip_distance
from dbtool.realgap.log import Curve, TipLog, check_design, read_log
from dbtool.realgap.protocol import TendonParams, simulate_log, standard_schedule
from dbtool.realgap.report import compare, plot, write_report
from dbtool.realgap.run import open_bench, summary

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
TENDONS = ("flexion",) if QUICK else ("flexion", "extension")
FIT = ("gain",) if QUICK else ("gain", "stiffness_scale", "friction_mm")
MAX_EVALS = 3 if QUICK else 20
STEP_MM = 5.0 if QUICK else 2.0  # the simulated protocol's increments
LEVELS = (0.0, 6.0, 10.0) if QUICK else None  # the log's readings kept (None: all)
REFERENCE = Path("../exports/gripping-seed0")
out = Path(tempfile.mkdtemp(prefix="fig16-"))
bench, meta = open_bench(REFERENCE)
print(f"design {meta['design']} (sha {meta['design_sha']}); tendon groups {bench.groups}; "
      f"strip lengths {bench.length_mm} mm")

# %% [markdown]
# ## The protocol in simulation
#
# Default tendon map (gain 1, the design's stiffness, no channel friction, no slack),
# `STEP_MM` steps to 10 mm. At zero displacement the simulated tip distance should match the
# exported parts' fingertips (the lowest 15 % of each finger's material).

# %%
sim = simulate_log(bench, standard_schedule(STEP_MM, 10.0, TENDONS), TendonParams(), meta)
for t, c in sim.curves.items():
    print(f"{t:9s} tip distance (mm):", np.round(c.tip, 2))
print(sim.meta["settling"])
print(f"rest: simulated {sim.curves['flexion'].tip[0]:.2f} mm, exported meshes "
      f"{mesh_tip_distance(REFERENCE):.2f} mm")
plot(sim, None, out / "sim.png", "simulated protocol, default tendon map")
display(Image(str(out / "sim.png")))

# %% [markdown]
# ## Replaying the example log
#
# The simulator replays the log's own schedule; the report gives the RMSE per tendon and
# branch, the largest deviation, each curve's hysteresis loop area and the release slope ratio
# at full contraction.

# %%
full = read_log(REFERENCE / "tip_distance_illustrative.csv")
print("source:", full.meta["source"], "|", full.meta["notes"][:120], "...")
check_design(full, meta["design"], meta["design_sha"])
print("warnings:", full.warnings or "none")


def kept(c: Curve) -> Curve:
    """The readings of ``c`` at ``LEVELS`` (all of them when ``LEVELS`` is None)."""
    m = np.isin(c.displacement, LEVELS) if LEVELS else np.ones(len(c.phase), bool)
    phase = [p for p, k in zip(c.phase, m, strict=True) if k]
    return Curve(c.tendon, phase, c.displacement[m], c.tip[m])


logged = TipLog({t: kept(full.curves[t]) for t in TENDONS}, full.meta)
before = simulate_log(bench, logged.schedule(), TendonParams(), meta)
report = compare(logged, before)
print(summary(report))
plot(logged, before, out / "before.png", "example log (illustrative) vs default map")
display(Image(str(out / "before.png")))

# %% [markdown]
# ## Calibrating the tendon map
#
# The parameters in `FIT` are fitted from their defaults by L-BFGS-B on the mean squared
# tip-distance error; each gradient is one adjoint pass of the whole protocol (docs/realgap.md,
# "Calibration"). The standard errors are Gauss-Newton ones at the optimum.

# %%
cal = calibrate(bench, logged, TendonParams(), FIT, max_evals=MAX_EVALS)
for name, err in cal.stderr.items():
    shown = f" ± {err:.3g}" if err is not None else ""
    print(f"{name:16s} {getattr(cal.params, name):.4g}{shown}")
print(f"RMSE {cal.rmse_before_mm:.3f} -> {cal.rmse_after_mm:.3f} mm in {cal.evaluations} "
      f"evaluations ({cal.wall_s:.0f} s)")

# %% [markdown]
# ## Replaying again with the fitted parameters

# %%
after = simulate_log(bench, logged.schedule(), cal.params, meta, hold=cal.hold)
report = compare(logged, after)
write_report(report, out)
print(summary(report))
plot(logged, after, out / "after.png", "example log (illustrative) vs calibrated map")
display(Image(str(out / "after.png")))
display(Markdown((out / "report.md").read_text()))
