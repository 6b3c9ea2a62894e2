"""The export's ``report.html``: one self-contained page per export folder (docs/viewing.md).

It shows the assembled gripper (or the body) in rotatable 3D, in mm, with the tendon paths
through its channels; each part's checks from ``report.json`` (watertight, bodies, volume,
size, thinnest wall); the assembly sheet (``assembly.md``) with its exploded view and tendon
drawing embedded as images; and the export report (``report.md``). Like the design report
(:mod:`dbtool.viz.report`) it embeds plotly.js and needs no network.

The displayed mesh is decimated by vertex clustering to about ``max_faces`` triangles (the
printed files keep every triangle): the finger alone has about 115,000.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write_text
from dbtool.errors import InputError

ROLE_COLOURS = {"flexion": "#1f77b4", "extension": "#d62728"}


def is_export(folder: Path) -> bool:
    """Whether ``folder`` is a ``dbtool export`` folder (it holds the export's report)."""
    return (folder / "report.json").is_file() and (folder / "report.md").is_file()


def _cluster(vertices: np.ndarray, faces: np.ndarray, cell: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """Merge the vertices in each grid cell of size ``cell`` (at their mean) and keep the
    triangles that still have three distinct corners, once each."""
    keys = np.floor(vertices / cell).astype(np.int64)
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    f = inverse[faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
    v = np.zeros((len(uniq), 3))
    np.add.at(v, inverse, vertices)
    v /= np.bincount(inverse, minlength=len(uniq))[:, None]
    return v, f[np.sort(first)]


def decimate(vertices: np.ndarray, faces: np.ndarray, max_faces: int
             ) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering for display: the finest grid (from 1/400 of the mesh's extent,
    coarsening by 1.25) that leaves at most ``max_faces`` triangles."""
    if len(faces) <= max_faces:
        return vertices, faces
    cell = float(np.ptp(vertices, axis=0).max()) / 400
    while True:
        v, f = _cluster(vertices, faces, cell)
        if len(f) <= max_faces:
            return v, f
        cell *= 1.25


def assembly_figure(folder: Path, max_faces: int = 40_000):
    """The assembled part (``assembly.stl``, else ``body.stl``) and the tendon paths, in mm,
    y up; None when the folder has no STL of it (an export with ``--3mf`` only)."""
    import plotly.graph_objects as go
    import trimesh

    mesh_file = next((folder / n for n in ("assembly.stl", "body.stl")
                      if (folder / n).is_file()), None)
    if mesh_file is None:
        return None
    mesh = trimesh.load(mesh_file, force="mesh")
    v, f = decimate(np.asarray(mesh.vertices), np.asarray(mesh.faces), max_faces)
    traces = [go.Mesh3d(x=v[:, 0], y=v[:, 2], z=v[:, 1], i=f[:, 0], j=f[:, 1], k=f[:, 2],
                        color="#ff9f1c", opacity=0.45, name=mesh_file.stem, flatshading=True,
                        hoverinfo="skip")]
    tendons = folder / "tendons.json"
    if tendons.is_file():
        for t in json.loads(tendons.read_text())["tendons"]:
            p = np.asarray(t["points"], float)
            traces.append(go.Scatter3d(x=p[:, 0], y=p[:, 2], z=p[:, 1], mode="lines+markers",
                                       name=t["name"], marker={"size": 2},
                                       line={"color": ROLE_COLOURS.get(t["role"], "black"),
                                             "width": 5}))
    axis = {"title": ""}
    fig = go.Figure(traces)
    fig.update_layout(title=f"{mesh_file.name} ({len(f):,} of {len(mesh.faces):,} triangles "
                            "shown), tendon paths (mm, drag to rotate)",
                      height=620, margin={"l": 0, "r": 0, "t": 40, "b": 0},
                      scene={"aspectmode": "data", "xaxis": axis, "yaxis": axis,
                             "zaxis": {**axis, "title": "up"}})
    return fig


def _part_rows(report: dict) -> dict:
    rows = {"task": report.get("task"), "design": report.get("design"),
            "mm per simulation unit": report.get("mm_per_sim_unit")}
    for name, part in report.get("parts", {}).items():
        wall = part.get("min_wall_mm")
        rows[name] = (f"watertight {part.get('watertight')}, {part.get('bodies')} body, "
                      f"{part.get('volume_mm3', float('nan')):.0f} mm^3, "
                      f"{' x '.join(f'{b:.1f}' for b in part.get('bbox_mm', []))} mm"
                      + (f", thinnest wall {wall:.2f} mm" if wall is not None else ""))
    t = report.get("tendons")
    if t:
        rows["tendons"] = f"{t['count']}, all checks passed: {t['all_ok']}"
    return rows


def write_export_page(folder: str | Path, name: str | None = None) -> Path:
    """Write ``folder/report.html`` for an export folder (atomically; ``name``: the export's
    name in the title, default the folder's); returns its path. A finished export's marker
    then lists the page (:func:`dbtool.export.complete.add_to_marker`)."""
    from dbtool.export.complete import add_to_marker
    from dbtool.viz.report import render_html

    folder = Path(folder)
    if not is_export(folder):
        raise InputError(f"{folder} is not an export folder (no report.json and report.md)")
    report = json.loads((folder / "report.json").read_text())
    fig = assembly_figure(folder)
    texts = {name: (folder / name).read_text() for name in ("assembly.md", "report.md")
             if (folder / name).is_file()}
    images = {name: (folder / name).read_bytes() for name in ("exploded.png", "tendons.png")
              if (folder / name).is_file()}
    page = render_html(f"dbtool export: {name or folder.name}", _part_rows(report),
                       {"assembly": fig} if fig is not None else {}, texts, images)
    out = atomic_write_text(folder / "report.html", page)
    add_to_marker(folder, "report.html")
    return out
