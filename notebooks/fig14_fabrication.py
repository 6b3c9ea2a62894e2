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
# # Figure 14 — fabricating the gripper
#
# The paper's physical gripper (appendix G, docs/method.md §8) is one designed finger and its mirror
# copy under a rigid base, closed by underactuated tendons with four routing points per finger,
# the tendons in Teflon tubes, printed in an elastomer with a Voronoi lattice foam inside the
# fingers. `dbtool export` automates that path and checks it as a maker would (docs/export.md).
# This notebook exports the reference gripper design committed in `exports/gripping-seed0/` (a
# seeded `dbtool design gripping` run) with the defaults: smooth parts, tendon channels sized for
# a 0.5 mm braided line and a 1/2 mm PTFE tube, round bends, knot pockets, mounting holes clear of
# the fingers, alignment pins, each part in its print orientation, and PrusaSlicer's verdict when
# it is installed. It shows the exploded assembly, a cut through a channel, the report, the
# assembly sheet and a cut through a Voronoi-infilled finger.
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) shows the committed export (`exports/gripping-seed0`,
# which `tests/test_export_maker.py` re-exports and compares on every CI run) instead of
# exporting afresh, and infills only a 20 mm slice of the finger (about 10 s); unset, it exports
# the design (about two minutes with the slicer) and infills the whole finger (minutes and
# several GB of memory).

# %%
import json
import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image, Markdown, display

from dbtool.design import Design
from dbtool.export.assembly import ExportConfig, export_design, report_markdown
from dbtool.export.geometry.infill import InfillConfig, voronoi_infill
from dbtool.export.printing.verify import load_part, verify_export
from dbtool.export.reports.sheet import draw_section

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
REFERENCE = Path("../exports/gripping-seed0")
design = Design.load(REFERENCE / "design.npz")
EXPORT_AFRESH = not QUICK
if EXPORT_AFRESH:
    out = Path(tempfile.mkdtemp(prefix="fig14-")) / "gripping-seed0"
    rep = export_design(design, out, ExportConfig())
else:
    out = REFERENCE
    rep = json.loads((out / "report.json").read_text())
print(f"design metric (cube lift) {design.metrics[design.task]:.5f} m; files: {rep['files']}")

# %% [markdown]
# ## The assembly, exploded
#
# The base (rigid, grey) with its four M3 holes where no finger is in the way and two alignment
# pins per finger on its lower face; the designed finger and its mirror copy (soft, orange),
# glued to the base with the pins in the pockets of their root faces. Each finger carries a
# flexion tendon along its inner actuator region (red: it curls the finger onto the object) and
# an extension tendon along the outer one (blue), from the tube seat at the top of the base
# through the four routing points to the fingertip, where the knot sits in a pocket when the
# tip has room for one (the reference finger's strand tips do not: its knots sit on the surface).

# %%
display(Image(str(out / "exploded.png")))

# %%
display(Image(str(out / "tendons.png")))

# %% [markdown]
# ## A cut through a channel
#
# The finger cut by the plane x = const through its tendons' routing points, in the gripper's
# frame: the channels are the holes; the lines are the tendons' centrelines (round bends of at
# least the bend radius). The wall around each channel is measured every 0.5 mm along its whole
# path, and checked again from the files alone by `verify_export`.

# %%
rep_json = json.loads((out / "report.json").read_text())
finger = load_part(out, "finger", rep_json)
tendons = [t for t in json.loads((out / "tendons.json").read_text())["tendons"]
           if t["finger"] == "finger"]
cut = draw_section(finger, tendons, Path("fig14_channel_cut.png"))
print(f"plane {cut['plane']}: {cut['holes']} channel holes in the cut")
display(Image("fig14_channel_cut.png"))
check = verify_export(out)
print("maker checks from the files:", "all pass" if check["ok"] else check)
for t in check["tendons"]:
    print(f"  {t['name']}: wall kept {t['wall_ok']}, through-hole {t['through_hole']}, "
          f"knot pocket {t['pocket_mm']:g} mm")
print(f"  mounting holes clear: {check['holes']['clear']}; parts on the bed: {check['oriented']}")

# %% [markdown]
# ## Fabrication report
#
# Every part is checked as a printer would: watertight and a volume (trimesh), manifold3d's
# status, one body, its genus, volume and bounding box, and the thinnest wall (a ray cast from
# every face along its inward normal). The finger's volume is compared with the design's solid
# volume × scale³; the tendons with the wall and bend they need; the print pose of each part
# with its overhang; PrusaSlicer's verdict with layers, time and filament.

# %%
display(Markdown(report_markdown(rep)))

# %% [markdown]
# ## The assembly sheet
#
# `assembly.md`, written with the parts: the parts list, the tendon lengths and the steps.

# %%
display(Markdown((out / "assembly.md").read_text()))

# %% [markdown]
# ## Voronoi lattice infill, cut open
#
# docs/method.md §8: the fingers were filled with a Voronoi lattice foam (2.5 mm seed spacing,
# 0.4 mm beams) inside a solid skin to soften them. `voronoi_infill` keeps the part one watertight
# body (a small drain hole joins the cavity to the outside, as resin printing needs) and reports
# its relative density. The cut below is the plane z = the finger's mid-depth.

# %%
import manifold3d as m3  # noqa: E402

finger = load_part(out, "finger", rep_json)
lo, hi = np.array(finger.bounding_box()[:3]), np.array(finger.bounding_box()[3:])
if QUICK:  # a 20 mm slice around the finger's middle
    mid = 0.5 * (lo[1] + hi[1])
    box = m3.Manifold.cube([hi[0] - lo[0] + 2, 20.0, hi[2] - lo[2] + 2]).translate(
        [lo[0] - 1, mid - 10.0, lo[2] - 1])
    finger = finger ^ box
foam, info = voronoi_infill(finger, InfillConfig())
print(f"relative density {info['relative_density']:.3f} (foam {info['foam_relative_density']:.3f}),"
      f" {info['seeds']} seeds, {info['beams']} beams, one body: {len(foam.decompose()) == 1}, "
      f"built in {info['seconds']:.1f} s")
zc = 0.5 * (lo[2] + hi[2])
from matplotlib.patches import PathPatch  # noqa: E402
from matplotlib.path import Path as MplPath  # noqa: E402

section = [np.asarray(p) for p in foam.slice(zc).to_polygons()]
verts = np.concatenate([np.vstack([p, p[:1]]) for p in section])
codes = np.concatenate([[MplPath.MOVETO] + [MplPath.LINETO] * (len(p) - 1) + [MplPath.CLOSEPOLY]
                        for p in section])
fig, ax = plt.subplots(figsize=(6, 6))
ax.add_patch(PathPatch(MplPath(verts, codes), facecolor="tab:orange", lw=0))
ax.autoscale_view()
ax.set_aspect("equal")
ax.set(xlabel="x (mm)", ylabel="y (mm)", title=f"cut at z = {zc:.1f} mm")
fig.savefig("fig14_infill_cut.png", dpi=110)
plt.close(fig)
display(Image("fig14_infill_cut.png"))
