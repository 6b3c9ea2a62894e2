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
# fingers. `dbtool export` automates that path. This notebook exports the reference gripper
# design committed in `exports/gripping-seed0/` (a seeded `dbtool design gripping` run) with
# tendon channels, renders the assembly with its tendon routing, prints the fabrication report
# and shows a cut through a Voronoi-infilled finger.
#
# Quick mode (`DBTOOL_QUICK=1`, used in CI) infills only a 20 mm slice of the finger (about
# 10 s); unset, it infills the whole finger (minutes and several GB of memory).

# %%
import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image, Markdown, display
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from dbtool.design import Design
from dbtool.export.assembly import ExportConfig, export_design, report_markdown
from dbtool.export.infill import InfillConfig, voronoi_infill

QUICK = os.environ.get("DBTOOL_QUICK", "0") == "1"
REFERENCE = Path("../exports/gripping-seed0")
design = Design.load(REFERENCE / "design.npz")
out = Path(tempfile.mkdtemp(prefix="fig14-")) / "gripping-seed0"
rep = export_design(design, out, ExportConfig(channels=True))
print(f"design metric (cube lift) {design.metrics[design.task]:.5f} m; files: {rep['files']}")

# %% [markdown]
# ## The assembly and its tendons
#
# The designed finger (orange), its mirror copy (olive) and the base plate with four mounting
# holes (grey). Each finger carries a flexion tendon along its inner actuator region (red: it
# curls the finger onto the object) and an extension tendon along the outer one (blue); dots are
# the four routing points, a cross the anchor at the tip, a triangle the tube's exit at the top
# of the base.

# %%
import manifold3d as m3  # noqa: E402
import trimesh  # noqa: E402

from dbtool.export.tendons import Tendon  # noqa: E402

COLOURS = {"finger": "tab:orange", "finger_mirror": "tab:olive", "base": "0.6"}
tendons = [Tendon(**t) for t in __import__("json").loads(
    (out / "tendons.json").read_text())["tendons"]]
fig = plt.figure(figsize=(9, 7))
ax = fig.add_subplot(projection="3d")
for name, colour in COLOURS.items():
    mesh = trimesh.load(out / f"{name}.stl")
    if len(mesh.faces) > 12000:  # draw a decimated copy: matplotlib is slow with many faces
        keep = np.random.default_rng(0).choice(len(mesh.faces), 12000, replace=False)
        faces = mesh.faces[keep]
    else:
        faces = mesh.faces
    tri = mesh.vertices[faces][:, :, [0, 2, 1]]  # plot with y (up) as the vertical axis
    ax.add_collection3d(Poly3DCollection(tri, facecolor=colour, alpha=0.25, linewidth=0))
for t in tendons:
    p = t.path()[:, [0, 2, 1]]
    c = "tab:red" if t.role == "flexion" else "tab:blue"
    ax.plot(*p.T, color=c, lw=2)
    pts = np.array(t.points)[:, [0, 2, 1]]
    ax.scatter(*pts.T, color=c, s=18)
ax.set(xlim=(0, 60), ylim=(0, 120), zlim=(0, 80), xlabel="x (mm)", ylabel="z (mm)",
       zlabel="y (mm)")
ax.set_box_aspect((60, 120, 80))
ax.view_init(elev=18, azim=-60)
fig.tight_layout()
fig.savefig("fig14_assembly.png", dpi=100)
plt.close(fig)
display(Image("fig14_assembly.png"))

# %%
display(Image(str(out / "tendons.png")))

# %% [markdown]
# ## Fabrication report
#
# Every part is checked as a printer would: watertight and a volume (trimesh), manifold3d's
# status, one body, its genus, volume and bounding box, and the thinnest wall (a ray cast from
# every face along its inward normal). The finger's volume is compared with the design's solid
# volume × scale³, and each tendon's routing points with the clearance the channel needs.

# %%
display(Markdown(report_markdown(rep)))

# %% [markdown]
# ## Voronoi lattice infill, cut open
#
# docs/method.md §8: the fingers were filled with a Voronoi lattice foam (2.5 mm seed spacing,
# 0.4 mm beams) inside a solid skin to soften them. `voronoi_infill` keeps the part one watertight
# body (a small drain hole joins the cavity to the outside, as resin printing needs) and reports
# its relative density. The cut below is the plane z = the finger's mid-depth.

# %%
finger = m3.Manifold(m3.Mesh(
    vert_properties=np.asarray(trimesh.load(out / "finger.stl").vertices, np.float32),
    tri_verts=np.asarray(trimesh.load(out / "finger.stl").faces, np.uint32)))
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
