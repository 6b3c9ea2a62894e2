"""``dbtool view EXPORT_FOLDER``: an export folder in the viser viewer (docs/viewing.md).

The scene is the assembly in the export's frame (mm, y up, the base on top): every part's
mesh in its own colour with a checkbox (a gripper's ``finger``, ``finger_mirror`` and
``base``; a body export's ``body`` and actuator regions), the tendon paths of
``tendons.json`` as polylines coloured by role (from the tube seat at the base's top down
through the channel's rounded bends to the knot pocket), the channels as translucent solids
built as the export cuts them, and the mounting holes and alignment pins of ``report.json``
as small cylinders.

The part files are stored in their print pose: the inverse of ``report.json``'s
``parts[name].print_pose.matrix`` puts each back into the assembly. The cut plane really cuts
every solid (manifold3d's ``trim_by_plane``, about 0.1 s for the finger), so a cut part stays
closed and the channels show as holes in its cut face. The tendons' corners, their fillet,
the channel tube and the cylinders are the export's own (:mod:`dbtool.export.gripper`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dbtool.errors import InputError
from dbtool.export._manifold import from_arrays, manifold3d, mesh_arrays
from dbtool.export.gripper.channel_path import fillet
from dbtool.export.gripper.channels import tube
from dbtool.export.gripper.mounting import vertical_cylinder
from dbtool.export.gripper.tendons import Tendon
from dbtool.export.reports.page import (
    ROLE_COLOURS,
    load_mesh,
    read_export_report,
    read_tendons,
)
from dbtool.viz.viewer import aim_camera, open_server, rgb, url_of

PART_COLOURS = {"finger": (224, 112, 32), "finger_mirror": (238, 176, 60),
                "base": (140, 140, 140), "body": (224, 112, 32), "assembly": (224, 112, 32)}
OTHER_COLOURS = ((214, 39, 40), (31, 119, 180), (44, 160, 44), (148, 103, 189),
                 (255, 127, 14), (140, 86, 75))  # actuator regions, by group
HOLE_COLOUR, PIN_COLOUR = (30, 30, 30), (40, 170, 70)
AXES = ("x", "y", "z")
TOWARD = (0.65, 0.55, -0.85)  # the initial camera's direction from the assembly
CHANNEL_SHOWN = 0.97  # the channel tubes are drawn this much thinner than the channel, so
# their surface does not fight the channel's wall in the depth buffer


def load_parts(folder: Path, report: dict) -> dict:
    """Each part's STL (``trimesh.Trimesh``) in the assembly's frame, its print pose undone;
    ``assembly.stl`` alone when no part has an STL (an export with ``--3mf`` only has none)."""
    out = {}
    for name, part in report.get("parts", {}).items():
        file = folder / f"{name}.stl"
        if name == "assembly" or not file.is_file():
            continue
        mesh = load_mesh(file)
        pose = part.get("print_pose")
        if pose is not None:
            mesh.apply_transform(np.linalg.inv(np.asarray(pose["matrix"], float)))
        out[name] = mesh
    if not out and (folder / "assembly.stl").is_file():
        out["assembly"] = load_mesh(folder / "assembly.stl")
    return out


def to_manifold(vertices: np.ndarray, faces: np.ndarray):
    """A manifold3d solid of a closed mesh, or None when the mesh is not a manifold."""
    solid = from_arrays(np.asarray(vertices)[:, :3], faces)
    return solid if solid.status() == manifold3d.Error.NoError and not solid.is_empty() \
        else None


def corners(tendon: dict) -> np.ndarray:
    """A tendon's centreline corners from its ``tendons.json`` entry (:meth:`Tendon.corners`:
    the exit at the base's top, down past the root face, the routing points, the knot pocket)."""
    known = Tendon.__dataclass_fields__
    return Tendon(**{k: v for k, v in tendon.items() if k in known}).corners()


def centreline(tendon: dict, bend_radius: float) -> np.ndarray:
    """A tendon's path (mm), its corners rounded by ``bend_radius`` as the channel's are,
    sampled every 0.5 mm."""
    return fillet(corners(tendon), bend_radius).sample(0.5)


def channel(tendon: dict, bend_radius: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The channel's solid around the tendon's path, built as the export cuts it
    (:func:`dbtool.export.gripper.channels.tube`), as vertices and triangles."""
    return mesh_arrays(tube(fillet(corners(tendon), bend_radius).as_polyline(), radius))


def root_and_top(base, mounting: dict) -> tuple[float, float]:
    """The base plate's lower face (the fingers' root face) and its top (mm): the base mesh's
    top, and its bottom less the pins that stand below the plate."""
    lo, hi = base.bounds[:, 1]
    pins = mounting.get("pins", []) + mounting.get("pins_mirror", [])
    return float(lo + (mounting.get("pin_length_mm", 0.0) if pins else 0.0)), float(hi)


def _own_cap(v: np.ndarray, f: np.ndarray, plane) -> tuple[np.ndarray, np.ndarray]:
    """The cut face's triangles on their own copies of the vertices, so the browser's smooth
    normals do not bend across the sharp edge around it."""
    on = np.abs(v @ np.asarray(plane[0], v.dtype) - plane[1]) < 1e-4
    cap = on[f].all(1)
    if not cap.any():
        return v, f
    idx = f[cap].reshape(-1)
    f = f.copy()
    f[cap] = (len(v) + np.arange(len(idx))).reshape(-1, 3)
    return np.concatenate([v, v[idx]]), f


class _Shown:
    """One solid in the scene, cut with the others: its manifold (None: drawn uncut), its
    colour and opacity, whether its checkbox shows it, and its current handle."""

    def __init__(self, server, name: str, vertices, faces, colour, opacity=None) -> None:
        self.server, self.name, self.colour, self.opacity = server, name, colour, opacity
        self.whole = (np.asarray(vertices, np.float32), np.asarray(faces, np.uint32))
        self.solid = to_manifold(*self.whole)
        self.on, self.empty, self.handle = True, False, None
        self.draw(None)

    def draw(self, plane) -> None:
        """Draw what is left on the kept side of ``plane`` (normal, offset: keeps
        normal . p >= offset; None: all of it); hide it when nothing is."""
        geometry = self.cut(plane)
        self.empty = geometry is None
        if self.empty:
            if self.handle is not None:
                self.handle.visible = False
        else:
            self.handle = self.add(geometry)

    def cut(self, plane):
        v, f = self.whole
        if plane is not None and self.solid is not None:
            v, f = _own_cap(*mesh_arrays(self.solid.trim_by_plane(*plane)), plane)
        return (v, f) if len(f) else None

    def add(self, geometry):
        v, f = geometry
        return self.server.scene.add_mesh_simple(
            self.name, v.astype(np.float32), f.astype(np.uint32), color=self.colour,
            opacity=self.opacity, side="front", visible=self.on)

    def show(self, on: bool) -> None:
        self.on = on
        if self.handle is not None:
            self.handle.visible = on and not self.empty


class _Path(_Shown):
    """A tendon's path as a polyline, cut with the solids: the segments on the kept side."""

    def __init__(self, server, name: str, path: np.ndarray, colour) -> None:
        self.server, self.name, self.colour = server, name, colour
        self.segments = np.stack([path[:-1], path[1:]], 1).astype(np.float32)
        self.solid, self.on, self.empty, self.handle = None, True, False, None
        self.draw(None)

    def cut(self, plane):
        seg = self.segments
        if plane is not None:  # the segments on the kept side, those across it cut short
            d = seg @ np.asarray(plane[0], np.float32) - np.float32(plane[1])  # (n, 2)
            seg = seg[(d >= 0).any(1)].copy()
            d = d[(d >= 0).any(1)]
            for end in (0, 1):
                out = d[:, end] < 0
                f = (d[out, 1 - end] / (d[out, 1 - end] - d[out, end]))[:, None]
                seg[out, end] = seg[out, 1 - end] + f * (seg[out, end] - seg[out, 1 - end])
        return seg if len(seg) else None

    def add(self, geometry):
        return self.server.scene.add_line_segments(
            self.name, geometry, self.colour, thickness=4.0, thickness_units="screen",
            visible=self.on)


@dataclass
class ExportView:
    """A running viewer of an export folder: its server, the URL, the GUI handles the tests
    move and the scene's objects (docs/viewing.md)."""

    server: object
    url: str
    cut: object  # the cut checkbox
    cut_axis: object  # the dropdown x / y / z
    cut_at: object  # the plane's position along the axis (mm)
    flip: object  # keep the other side of the plane
    opacity: object  # the parts' opacity slider
    visible: dict  # part name -> its checkbox
    shown: dict = field(default_factory=dict)  # scene name -> _Shown
    lock: threading.Lock = field(default_factory=threading.Lock)
    drawn: tuple | None = None  # the plane the solids are cut by now

    def _group(self, prefix: str) -> dict:
        return {k.removeprefix(prefix): s.handle for k, s in self.shown.items()
                if k.startswith(prefix)}

    @property
    def parts(self) -> dict:
        """Part name -> its mesh handle (a new one after each cut)."""
        return self._group("/parts/")

    @property
    def tendons(self) -> dict:
        """Tendon name -> its polyline's handle."""
        return self._group("/tendons/")

    @property
    def channels(self) -> dict:
        return self._group("/channels/")

    @property
    def holes(self) -> list:
        return list(self._group("/mounting/hole").values())

    @property
    def pins(self) -> list:
        return list(self._group("/mounting/pin").values())

    @property
    def solids(self) -> dict:
        """Part name -> its manifold3d solid in the assembly's frame (None: not a manifold)."""
        return {k.removeprefix("/parts/"): s.solid for k, s in self.shown.items()
                if k.startswith("/parts/")}

    def plane(self) -> tuple[list[float], float] | None:
        """The cut plane (normal, offset) the controls set, or None when the cut is off; the
        side kept is the one away from the initial camera (or the other one, flipped)."""
        if not self.cut.value:
            return None
        i = AXES.index(self.cut_axis.value)
        sign = (-1.0 if TOWARD[i] > 0 else 1.0) * (-1.0 if self.flip.value else 1.0)
        normal = [0.0, 0.0, 0.0]
        normal[i] = sign
        return normal, sign * float(self.cut_at.value)

    def recut(self) -> None:
        """Cut every solid by the current plane (the latest controls win)."""
        with self.lock:
            plane = self.plane()
            if plane == self.drawn:
                return
            self.drawn = plane
            for s in self.shown.values():
                s.draw(plane)

    def stop(self) -> None:
        self.server.stop()


def _summary(folder: Path, report: dict, meshes: dict, tendons: list, mounting: dict) -> str:
    lines = [f"**dbtool export: {folder.name}**",
             f"task {report.get('task', '?')}, design {report.get('design', '?')}; mm, y up"
             + (", the base on top" if "base" in meshes else "")]
    for name, mesh in meshes.items():
        part = report.get("parts", {}).get(name, {})
        vol = part.get("volume_mm3", float(mesh.volume))
        lines.append(f"- {name}: watertight {part.get('watertight', mesh.is_watertight)}, "
                     f"{vol:,.0f} mm³, {len(mesh.faces):,} triangles")
    if tendons:
        lines.append(f"- tendons: {len(tendons)} (flexion blue, extension red)")
    if mounting:
        pins = len(mounting.get("pins", [])) + len(mounting.get("pins_mirror", []))
        lines.append(f"- mounting holes: {len(mounting.get('holes', []))} of "
                     f"{mounting.get('diameter_mm', '?')} mm; pins: {pins} of "
                     f"{mounting.get('pin_diameter_mm', '?')} mm")
    return "  \n".join(lines)


def _colour(name: str, k: int) -> tuple[int, int, int]:
    if name in PART_COLOURS:
        return PART_COLOURS[name]
    group = name.split("_")[1] if name.startswith("actuator_") else str(k)
    return OTHER_COLOURS[int(group) % len(OTHER_COLOURS)] if group.isdigit() else (
        OTHER_COLOURS[k % len(OTHER_COLOURS)])


def serve_export(folder: Path, host: str = "127.0.0.1", port: int = 8080) -> ExportView:
    """Start the viewer of an export folder and return at once; :meth:`ExportView.stop`
    ends it (docs/viewing.md)."""
    folder = Path(folder)
    report = read_export_report(folder)
    tj = read_tendons(folder)
    meshes = load_parts(folder, report)
    if not meshes:
        raise InputError(f"{folder} has no STL of its parts to show (an export with --3mf only)")
    tendons, mounting = tj.get("tendons", []), report.get("mounting", {})

    server = open_server(host, port, f"export {folder.name}")
    first = next(iter(meshes.values())).bounds  # the finger, or the body
    corners = np.concatenate([m.bounds for m in meshes.values()])
    lo, hi = corners.min(0), corners.max(0)
    aim_camera(server, np.array([lo, hi]), TOWARD)
    server.gui.add_markdown(_summary(folder, report, meshes, tendons, mounting))

    shown: dict[str, _Shown] = {}
    with server.gui.add_folder("parts"):
        opacity = server.gui.add_slider("opacity", min=0.1, max=1.0, step=0.05,
                                        initial_value=0.5)
        # a body's actuator regions tile it: they are shown, the body hidden at first
        regions = any(name.startswith("actuator_") for name in meshes)
        visible = {name: server.gui.add_checkbox(name, initial_value=not (
            regions and name == "body")) for name in meshes}
    for k, (name, mesh) in enumerate(meshes.items()):
        s = _Shown(server, f"/parts/{name}", mesh.vertices, mesh.faces, _colour(name, k),
                   opacity.value)
        s.show(visible[name].value)
        shown[s.name] = s

    radius = 0.5 * tj.get("channel_diameter_mm", 0.0) * CHANNEL_SHOWN
    bend = tj.get("bend_radius_mm", 0.0)
    for t in tendons:
        colour = tuple(int(c) for c in rgb([ROLE_COLOURS.get(t.get("role"), "#000000")])[0])
        shown[f"/tendons/{t['name']}"] = _Path(server, f"/tendons/{t['name']}",
                                               centreline(t, bend), colour)
        if radius > 0:
            shown[f"/channels/{t['name']}"] = _Shown(server, f"/channels/{t['name']}",
                                                     *channel(t, bend, radius), colour, 0.35)
    if mounting and "base" in meshes:
        root, top = root_and_top(meshes["base"], mounting)
        r = 0.5 * mounting.get("diameter_mm", 3.4)
        for k, (x, z) in enumerate(mounting.get("holes", [])):
            m = vertical_cylinder(x, z, 0.9 * r, root - 0.5, top + 0.5, 24)
            shown[f"/mounting/hole{k}"] = _Shown(server, f"/mounting/hole{k}",
                                                 *mesh_arrays(m), HOLE_COLOUR)
        r, length = 0.5 * mounting.get("pin_diameter_mm", 3.0) + 0.05, mounting.get(
            "pin_length_mm", 3.0)
        pins = mounting.get("pins", []) + mounting.get("pins_mirror", [])
        for k, (x, z) in enumerate(pins):
            m = vertical_cylinder(x, z, r, root - length - 0.05, root + 0.05, 24)
            shown[f"/mounting/pin{k}"] = _Shown(server, f"/mounting/pin{k}",
                                                *mesh_arrays(m), PIN_COLOUR)

    with server.gui.add_folder("show"):
        groups = {g: server.gui.add_checkbox(g, initial_value=True)
                  for g, present in (("tendons", tendons), ("channels", radius > 0 and tendons),
                                     ("holes and pins", mounting and "base" in meshes))
                  if present}
    with server.gui.add_folder("cut plane"):
        cut = server.gui.add_checkbox("cut", initial_value=False)
        axis = server.gui.add_dropdown("cut axis", AXES, initial_value="y")
        at = server.gui.add_slider("cut at (mm)", min=round(float(lo[1]), 1),
                                   max=round(float(hi[1]), 1), step=0.1,
                                   initial_value=round(float(first[:, 1].mean()), 1))
        flip = server.gui.add_checkbox("keep the other side", initial_value=False)
    view = ExportView(server, url_of(server, host), cut, axis, at, flip, opacity, visible,
                      shown)
    _wire(view, groups, lo, hi, first.mean(0))
    return view


def _wire(view: ExportView, groups: dict, lo: np.ndarray, hi: np.ndarray,
          centre: np.ndarray) -> None:
    """The controls' callbacks."""
    for name, box in view.visible.items():
        box.on_update(lambda _e, name=name, box=box: view.shown[f"/parts/{name}"].show(
            box.value))
    prefixes = {"tendons": "/tendons/", "channels": "/channels/", "holes and pins": "/mounting/"}

    def show_group(g: str) -> None:
        for k, s in view.shown.items():
            if k.startswith(prefixes[g]):
                s.show(groups[g].value)

    for g, box in groups.items():
        box.on_update(lambda _e, g=g: show_group(g))

    @view.opacity.on_update
    def _(_e) -> None:
        with view.lock:
            for k, s in view.shown.items():
                if k.startswith("/parts/"):
                    s.opacity = float(view.opacity.value)
                    if s.handle is not None:
                        s.handle.opacity = s.opacity

    @view.cut_axis.on_update
    def _(_e) -> None:
        i = AXES.index(view.cut_axis.value)
        a, b = round(float(lo[i]), 1), round(float(hi[i]), 1)
        view.cut_at.min, view.cut_at.max = min(a, view.cut_at.min), max(b, view.cut_at.max)
        view.cut_at.value = round(float(centre[i]), 1)  # through the first part
        view.cut_at.min, view.cut_at.max = a, b
        view.recut()

    for control in (view.cut, view.cut_at, view.flip):
        control.on_update(lambda _e: view.recut())
