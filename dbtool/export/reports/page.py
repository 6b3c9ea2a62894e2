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

from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_write_text
from dbtool.errors import InputError
from dbtool.jsonfiles import (
    field,
    finite_or_none,
    integer,
    number,
    read_object,
    safe_name,
    vector,
)

ROLE_COLOURS = {"flexion": "#1f77b4", "extension": "#d62728"}


def is_export(folder: Path) -> bool:
    """Whether ``folder`` is a ``dbtool export`` folder (it holds the export's report)."""
    return (folder / "report.json").is_file() and (folder / "report.md").is_file()


MAX_MM = 1e5  # 100 m: no coordinate or size of an export comes near it


def read_export_report(folder: str | Path) -> dict:
    """The export's ``report.json``, checked for every entry that ``dbtool report``,
    ``dbtool view`` and ``dbtool realgap`` read (the one place they are checked): a JSON
    object; ``task`` and ``design`` texts; ``mm_per_sim_unit`` a positive number; ``parts``
    an object of part name (letters, digits, ``_``, ``-``: it names the part's STL) to an
    object whose ``watertight`` is true or false, ``bodies`` an integer, ``volume_mm3`` and
    ``min_wall_mm`` numbers, ``bbox_mm`` three numbers and ``print_pose.matrix`` an invertible
    4 x 4 matrix; ``tendons`` with ``count`` and ``all_ok``; ``mounting`` with lists of
    ``[x, z]`` holes and pins and positive diameters. Anything else is one
    :class:`~dbtool.errors.InputError` line naming the file and the entry."""
    path = Path(folder) / "report.json"
    report = read_object(path)
    for key in ("task", "design"):
        field(report, key, str, path)
    if "mm_per_sim_unit" in report:
        number(f"{path}: mm_per_sim_unit", report["mm_per_sim_unit"], 0, 1e6, positive=True)
    parts = field(report, "parts", dict, path, {})
    for name, part in parts.items():
        safe_name(f"{path}: the part name {name!r}", name)
        where = f"{path}: parts.{name}"
        if not isinstance(part, dict):
            raise InputError(f"{where} must be an object, not {type(part).__name__}")
        field(part, "watertight", bool, where)
        if "bodies" in part:
            integer(f"{where}.bodies", part["bodies"], 0)
        if "volume_mm3" in part:
            number(f"{where}.volume_mm3", part["volume_mm3"], 0, MAX_MM**3)
        if "min_wall_mm" in part:
            finite_or_none(f"{where}.min_wall_mm", part["min_wall_mm"])
        if "bbox_mm" in part:
            vector(f"{where}.bbox_mm", part["bbox_mm"], 3, MAX_MM)
        pose = part.get("print_pose")
        if pose is not None:
            if not isinstance(pose, dict) or "matrix" not in pose:
                raise InputError(f"{where}.print_pose must be an object with a matrix")
            _pose_matrix(f"{where}.print_pose.matrix", pose["matrix"])
    tendons = field(report, "tendons", dict, path)
    if tendons is not None:
        integer(f"{path}: tendons.count", tendons.get("count"), 0)
        field(tendons, "all_ok", bool, f"{path}: tendons", required=True)
    mounting = field(report, "mounting", dict, path)
    if mounting is not None:
        for key in ("holes", "pins", "pins_mirror"):
            for k, xz in enumerate(field(mounting, key, list, f"{path}: mounting", [])):
                vector(f"{path}: mounting.{key}[{k}]", xz, 2, MAX_MM)
        for key in ("diameter_mm", "pin_diameter_mm", "pin_length_mm"):
            if key in mounting:
                number(f"{path}: mounting.{key}", mounting[key], 0, 1000, positive=True)
    return report


def _pose_matrix(name: str, matrix: object) -> np.ndarray:
    rows = matrix if isinstance(matrix, list) and len(matrix) == 4 else None
    if rows is None:
        raise InputError(f"{name} must be a 4 x 4 matrix (a list of 4 rows)")
    m = np.array([vector(f"{name}[{i}]", r, 4, MAX_MM) for i, r in enumerate(rows)])
    if abs(np.linalg.det(m[:3, :3])) < 1e-9:
        raise InputError(f"{name} is not invertible")
    return m


def read_tendons(folder: str | Path) -> dict:
    """The export's ``tendons.json`` checked (``{}`` when the folder has none): a JSON object
    whose ``tendons`` is a list of objects, each with a ``name`` (letters, digits, ``_``,
    ``-``), ``finger`` and ``role`` texts, an actuator ``group`` (an integer >= 0), routing
    ``points``, ``anchor`` and ``exit`` (and ``entry``, ``lead``, ``tip`` if given) as
    ``[x, y, z]`` in mm; ``channel_diameter_mm`` and ``bend_radius_mm`` numbers >= 0."""
    path = Path(folder) / "tendons.json"
    if not path.is_file():
        return {}
    data = read_object(path)
    for key in ("channel_diameter_mm", "bend_radius_mm"):
        if key in data:
            number(f"{path}: {key}", data[key], 0, 1000)
    tendons = field(data, "tendons", list, path, [])
    names = set()
    for k, t in enumerate(tendons):
        where = f"{path}: tendons[{k}]"
        if not isinstance(t, dict):
            raise InputError(f"{where} must be an object, not {type(t).__name__}")
        name = safe_name(f"{where}.name", t.get("name"))
        if name in names:
            raise InputError(f"{where}: the name {name!r} appears twice")
        names.add(name)
        for key in ("finger", "role"):
            field(t, key, str, where, required=True)
        integer(f"{where}.group", t.get("group"), 0, 63)
        points = field(t, "points", list, where, required=True)
        if not points:
            raise InputError(f"{where}.points is empty")
        for i, p in enumerate(points):
            vector(f"{where}.points[{i}]", p, 3, MAX_MM)
        for key in ("anchor", "exit"):
            vector(f"{where}.{key}", t.get(key), 3, MAX_MM)
        for key in ("entry", "lead", "tip"):
            if t.get(key):
                vector(f"{where}.{key}", t[key], 3, MAX_MM)
    return data


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

    mesh_file = next((folder / n for n in ("assembly.stl", "body.stl")
                      if (folder / n).is_file()), None)
    if mesh_file is None:
        return None
    mesh = load_mesh(mesh_file)
    v, f = decimate(np.asarray(mesh.vertices), np.asarray(mesh.faces), max_faces)
    traces = [go.Mesh3d(x=v[:, 0], y=v[:, 2], z=v[:, 1], i=f[:, 0], j=f[:, 1], k=f[:, 2],
                        color="#ff9f1c", opacity=0.45, name=mesh_file.stem, flatshading=True,
                        hoverinfo="skip")]
    for t in read_tendons(folder).get("tendons", []):
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


def read_text(path: Path) -> str:
    """A text file of the export (its Markdown), or one line saying why it cannot be read."""
    try:
        return path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"cannot read {path}: not UTF-8 text") from None


def load_mesh(path: Path):
    """An STL of the export as a ``trimesh.Trimesh`` with at least one triangle, or one line
    saying why not."""
    import trimesh

    try:
        mesh = trimesh.load(path, force="mesh")
        faces = np.asarray(mesh.faces)
        vertices = np.asarray(mesh.vertices, float)
    except Exception as exc:  # noqa: BLE001 - any parser failure gets the same line
        raise InputError(f"{path} is not a readable STL mesh ({exc.__class__.__name__})"
                         ) from None
    if faces.ndim != 2 or len(faces) == 0:
        raise InputError(f"{path} holds no triangles")
    if not np.isfinite(vertices).all():
        raise InputError(f"{path} has NaN or infinite vertices")
    return mesh


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
    report = read_export_report(folder)
    read_tendons(folder)
    texts = {n: read_text(folder / n) for n in ("assembly.md", "report.md")
             if (folder / n).is_file()}
    fig = assembly_figure(folder)
    images = {name: (folder / name).read_bytes() for name in ("exploded.png", "tendons.png")
              if (folder / name).is_file()}
    page = render_html(f"dbtool export: {name or folder.name}", _part_rows(report),
                       {"assembly": fig} if fig is not None else {}, texts, images)
    out = atomic_write_text(folder / "report.html", page)
    add_to_marker(folder, "report.html")
    return out
