"""The export stage (docs/method.md §8): a saved Design -> printable parts, an assembly, tendon
routing and a fabrication report, all in millimetres.

Gripping: the designed finger, its mirror copy (``Manifold.mirror``, so winding stays right) about
the gripper's mirror plane and the rigid base plate with four mounting holes, placed as in the
simulated gripper; one tendon per actuator group and finger (:mod:`dbtool.export.tendons`),
optionally cut as channels. Other tasks: the body and its actuator regions as separate parts.
The checks and the report are in :mod:`dbtool.export.report`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_folder
from dbtool.design import Design
from dbtool.export._manifold import manifold3d as m3
from dbtool.export.config import Assembly, ExportConfig
from dbtool.export.mesh import OccupancyField, finish, largest_component, write_stl
from dbtool.export.report import design_volume, report, report_markdown
from dbtool.export.tendons import channel_solid, mirror_tendon, route_finger
from dbtool.export.threemf import write_3mf
from dbtool.export.voxels import Voxels
from dbtool.runs import write_json
from dbtool.sim.tasks import get_task
from dbtool.sim.tasks.base import DX, SPACING
from dbtool.sim.tasks.gripping import BASE, FULL

__all__ = ["Assembly", "ExportConfig", "build", "design_volume", "export_design",
           "report_markdown"]

INSET = 0.2  # mm between a finger and the sides of the workspace (and base)
GLUE = 0.05  # mm of overlap that fuses the fingers to the plate in ``assembly``


def _fields(design: Design, scale: float, extrude_top: int = 0
            ) -> tuple[OccupancyField, dict[int, OccupancyField], float]:
    """Fields of the body and of each actuator group's particles, and the root gap (mm).

    ``extrude_top``: the topmost layer of active sites is continued upward to the top of the
    design lattice and ``extrude_top`` layers beyond, so a finger trimmed at its root keeps
    straight walls and meets the base. The simulator's grid (cells of two sites) joins a finger
    to the base across a gap below one cell, so such a gap is printed solid; its size is
    returned (0 when the finger reaches the lattice's top).
    """
    robot = design.robot
    points, active = robot.points, robot.active()
    if not active.any():
        raise ValueError("the design has no active particles: nothing to export")
    w = robot.actuators
    label = np.where(w.max(1) > 0, w.argmax(1), -1) if w.size else np.full(robot.n, -1)
    gap = 0.0
    if extrude_top:
        y = points[:, 1]
        top_active = y[active].max()
        gap = float(y.max() - top_active) * scale
        layer = active & np.isclose(y, top_active)
        n_up = int(round((y.max() - top_active) / SPACING)) + extrude_top
        extra = [points[layer] + [0.0, k * SPACING, 0.0] for k in range(1, n_up + 1)]
        points = np.vstack([points, *extra])
        active = np.concatenate([active, np.ones(n_up * int(layer.sum()), bool)])
        label = np.concatenate([label, np.tile(label[layer], n_up)])
    body = OccupancyField.from_sites(points, active, SPACING, scale)
    # every lattice site takes the group of its nearest active, actuated site, so the surfaces
    # between regions run on through the body's surface instead of along it (no slivers)
    owned = active & (label >= 0)
    regions = {}
    if owned.any():
        from scipy.spatial import cKDTree

        _, near = cKDTree(points[owned]).query(points)
        filled = label[owned][near]
        regions = {int(g): OccupancyField.from_sites(points, filled == g, SPACING, scale,
                                                     frame=points, edge_pad=True)
                   for g in np.unique(filled)}
    return body, regions, gap


def _root_pillars(design: Design, scale: float, root: float) -> np.ndarray | None:
    """Square pillars (one lattice cell wide) from every active site within one simulator grid
    cell (``DX``, two sites) of the base up into it: the sites the simulation's grid couples to
    the glued base. Smoothing would thin a narrow root away; these keep it as designed.
    Returns their (k, 2, 3) box corners in mm (united with the finger's field)."""
    r = design.robot
    a = r.active()
    y = r.points[:, 1]
    sel = a & (y >= y.max() - (DX / SPACING - 0.5) * SPACING)
    if not sel.any():
        return None
    w = SPACING * scale  # one cell: neighbours meet (united in the field, no boolean)
    c = r.points[sel] * scale
    lo = np.stack([c[:, 0] - w / 2, c[:, 1] - 0.5 * SPACING * scale, c[:, 2] - w / 2], 1)
    hi = np.stack([c[:, 0] + w / 2, np.full(len(c), root + 1.0), c[:, 2] + w / 2], 1)
    return np.stack([lo, hi], 1)


def _pillar_fill(design: Design, scale: float, boxes: np.ndarray | None, top: float) -> float:
    """Volume (mm^3) of the empty lattice cells below ``top`` (mm) that the root pillars fill:
    what the export adds to the design on purpose, where the simulator glues sites to the base
    across an empty cell."""
    if boxes is None:
        return 0.0
    cell = SPACING * scale
    r = design.robot
    active = {tuple(v) for v in np.round(r.points[r.active()] / SPACING - 0.5).astype(int)}
    filled = set()
    for lo, hi in boxes:
        i, k = int(round(lo[0] / cell)), int(round(lo[2] / cell))
        for j in range(int(round(lo[1] / cell)), int(np.floor(min(hi[1], top) / cell + 1e-6))):
            filled.add((i, j, k))
    return len(filled - active) * cell**3


def build_gripper(design: Design, cfg: ExportConfig) -> Assembly:
    s = cfg.scale_mm
    t0 = time.perf_counter()
    body, regions, gap = _fields(design, s, extrude_top=3)
    root = (FULL[1] - BASE) * s  # the base's lower face; the finger hangs below it
    # the finger stays INSET inside its workspace's sides: a finger face nearly coplanar with
    # the base's side face leaves edges of 1e-6 mm in the fused assembly (an STL cannot keep them)
    ws = np.array([[INSET, -1.0, INSET], [FULL[0] * s - INSET, root + 2.0, FULL[2] * s - INSET]])
    pillars = _root_pillars(design, s, root)
    finger = body.solid(keep_largest=False, boxes=pillars, clip=ws)
    finger = finger.trim_by_plane([0.0, -1.0, 0.0], -root)  # keep y <= root
    finger = largest_component(finger)
    plane = FULL[2] / 2 * s  # the finger lies in z < plane, its mirror in z > plane
    base = m3.Manifold.cube([FULL[0] * s, BASE * s, FULL[2] * s]).translate([0.0, root, 0.0])
    t_mesh = time.perf_counter()
    vox = Voxels.of(finger, cfg.pitch)
    tendons = route_finger(finger, regions, "finger", FULL[1] * s, root, cfg.radius, cfg.min_wall,
                           {0: -1.0, 1: +1.0}, cfg.pitch, voxels=vox,
                           base_xz=(0.0, 0.0, FULL[0] * s, FULL[2] * s))
    tendons += [mirror_tendon(t, plane, "finger_mirror") for t in tendons]
    t_route = time.perf_counter()
    # the volume check compares the part of the finger the design holds (below its top sites)
    design_top = (design.robot.points[design.robot.active(), 1].max() + SPACING / 2) * s
    body_volume = finger.trim_by_plane([0.0, -1.0, 0.0], -design_top).volume()
    fill = _pillar_fill(design, s, pillars, design_top)
    bridge = finger.volume() - body_volume
    info: dict = {}
    if cfg.infill == "voronoi":
        from dbtool.export.infill import InfillConfig, voronoi_infill

        foam, info = voronoi_infill(finger, InfillConfig(shell=cfg.shell))
        if cfg.channels:  # a solid sleeve keeps each channel a closed tube through the foam
            sleeves = [channel_solid(t, cfg.radius + cfg.min_wall, root) for t in tendons
                       if t.finger == "finger"]
            foam = foam + (m3.Manifold.batch_boolean(sleeves, m3.OpType.Add) ^ finger)
        finger = foam
    t_infill = time.perf_counter()
    # four mounting holes through the plate, 8 mm in from its corners
    r = 0.5 * cfg.mount_hole
    holes = []
    for x in (8.0, FULL[0] * s - 8.0):
        for z in (8.0, FULL[2] * s - 8.0):
            hole = m3.Manifold.cylinder(BASE * s + 2.0, r, r, 24)
            holes.append(hole.rotate([-90.0, 0.0, 0.0]).translate([x, root - 1.0, z]))
    # the fingers only touch the plate's lower face; in the fused assembly the plate reaches
    # GLUE lower so fingers and plate overlap and join into one body (one box, cut once: a
    # separate glue slab shares the holes' walls with the plate, which leaves slivers)
    plate = m3.Manifold.cube([FULL[0] * s, BASE * s + GLUE, FULL[2] * s])
    plate = plate.translate([0.0, root - GLUE, 0.0])
    cut = m3.Manifold.batch_boolean(holes, m3.OpType.Add)
    if cfg.channels:  # cut the designed finger; its mirror copy stays its exact reflection
        tubes = m3.Manifold.batch_boolean([channel_solid(t, cfg.radius, root) for t in tendons
                                           if t.finger == "finger"], m3.OpType.Add)
        finger = finger - tubes
        cut = cut + tubes + tubes.mirror([0.0, 0.0, 1.0]).translate([0.0, 0.0, 2 * plane])
    base, plate = finish(base - cut), plate - cut
    finger = finish(finger)
    mirror = finger.mirror([0.0, 0.0, 1.0]).translate([0.0, 0.0, 2 * plane])
    t_channels = time.perf_counter()
    parts = {"finger": finger, "finger_mirror": mirror, "base": base}
    union = finish(m3.Manifold.batch_boolean([finger, mirror, plate], m3.OpType.Add))
    timings = {"mesh_s": t_mesh - t0, "routing_s": t_route - t_mesh,
               "infill_s": t_infill - t_route, "channels_s": t_channels - t_infill,
               "assembly_s": time.perf_counter() - t_channels}
    notes = {"root_gap_mm": round(gap, 3), "root_bridge_mm3": round(bridge, 1),
             "root_pillar_fill_mm3": round(fill, 1)}
    return Assembly(parts, union, tendons, design_volume(design, s, largest=True),
                    body_volume, timings, info, notes)


def build_body(design: Design, cfg: ExportConfig) -> Assembly:
    """Any other task: the body, and the actuator regions as parts inside it."""
    s = cfg.scale_mm
    t0 = time.perf_counter()
    body_field, regions, _ = _fields(design, s)
    body = body_field.solid()
    parts: dict = {"body": body}
    for g, f in sorted(regions.items()):
        others = [o for k, o in regions.items() if k != g]
        if others:  # the part of the body where group g outweighs every other group
            stack = np.max([o.grid for o in others], axis=0)
            rival = OccupancyField(stack, f.origin, f.spacing, f.scale)
            region = f.solid(other=rival, keep_largest=False, within=body_field)
        else:
            region = body
        pieces = sorted(region.decompose(), key=lambda m: -m.volume())
        pieces = [p for p in pieces if p.volume() > 0.005 * body.volume()]
        for i, p in enumerate(pieces):
            parts[f"actuator_{g}" + (f"_{i}" if len(pieces) > 1 else "")] = p
    t1 = time.perf_counter()
    info: dict = {}
    if cfg.infill == "voronoi":
        from dbtool.export.infill import InfillConfig, voronoi_infill

        parts["body"], info = voronoi_infill(body, InfillConfig(shell=cfg.shell))
    parts = {k: finish(v) for k, v in parts.items()}
    return Assembly(parts, parts["body"], [], design_volume(design, s, largest=True), body.volume(),
                    {"mesh_s": t1 - t0, "infill_s": time.perf_counter() - t1}, info)


def build(design: Design, cfg: ExportConfig | None = None) -> Assembly:
    cfg = cfg or ExportConfig()
    if cfg.infill not in ("none", "voronoi"):
        raise ValueError(f"unknown infill {cfg.infill!r}: choose none or voronoi")
    get_task(design.task)  # fail early on an unknown task
    if design.robot.n == 0:
        raise ValueError("the design has no robot fields (points, occupancy, actuators)")
    if design.task == "gripping":
        return build_gripper(design, cfg)
    return build_body(design, cfg)


def export_design(design: Design, out_dir: Path, cfg: ExportConfig | None = None,
                  name: str | None = None) -> dict:
    """Write the parts (STL and/or 3MF), ``tendons.json``, ``tendons.png``, ``report.json`` and
    ``report.md`` into ``out_dir``; returns the report.

    Everything is written into a hidden sibling folder first and renamed into place at the end,
    so an interrupted export never leaves a folder that looks complete.
    """
    cfg = cfg or ExportConfig()
    out_dir = Path(out_dir)
    name = name or out_dir.name
    asm = build(design, cfg)
    with atomic_folder(out_dir) as tmp:
        files = []
        t0 = time.perf_counter()
        for part, solid in asm.parts.items():
            if cfg.stl:
                files.append(write_stl(solid, tmp / f"{part}.stl").name)
        if cfg.stl and design.task == "gripping":
            files.append(write_stl(asm.union, tmp / "assembly.stl").name)
        if cfg.threemf:
            objs = {k: v for k, v in asm.parts.items() if not (k == "body" and len(asm.parts) > 1)}
            files.append(write_3mf(objs, tmp / "assembly.3mf").name)
        t_write = time.perf_counter() - t0
        rep = report(design, asm, cfg, name, files)
        rep["timings_s"]["write_s"] = round(t_write, 3)
        write_json(tmp / "report.json", rep)
        (tmp / "report.md").write_text(report_markdown(rep))
        if design.task == "gripping":
            tj = {"units": "mm", "frame": "gripper workspace, y up, base on top",
                  "channel_diameter_mm": cfg.channel_diameter, "min_wall_mm": cfg.min_wall,
                  "channels_cut": cfg.channels, "tendons": [t.as_json() for t in asm.tendons]}
            write_json(tmp / "tendons.json", tj)
            from dbtool.export.drawing import draw_tendons

            draw_tendons(asm, tmp / "tendons.png", title=name)
    return rep
