"""The gripper's parts (docs/export.md, "Gripper"; docs/method.md §8): the designed finger, its
mirror copy (``Manifold.mirror``, so winding stays right) about the gripper's mirror plane, and
the rigid base plate, placed as in the simulated gripper.

The base carries four M3 mounting holes where no finger covers them, a seat for each tendon's
PTFE tube and the alignment pins that locate each finger in the pockets of its root face; each
finger carries its tendons' channels (:mod:`dbtool.export.gripper.channels`) with a knot pocket
at the fingertip.
"""

from __future__ import annotations

import time

import numpy as np

from dbtool.design import Design
from dbtool.export._manifold import manifold3d as m3
from dbtool.export.config import Assembly, ExportConfig
from dbtool.export.geometry.fields import design_fields
from dbtool.export.geometry.mesh import finish, largest_component
from dbtool.export.geometry.voxels import Voxels
from dbtool.export.gripper.channels import base_cut, finger_cut, route_finger
from dbtool.export.gripper.channels import check as check_walls
from dbtool.export.gripper.mounting import alignment_pins, hole_clearance, mount_holes, pin_solids
from dbtool.export.gripper.tendons import mirror_tendon
from dbtool.export.reports.report import design_volume
from dbtool.sim.tasks.base import DX, SPACING
from dbtool.sim.tasks.gripping import BASE, FULL

INSET = 0.2  # mm between a finger and the sides of the workspace (and base)
GLUE = 0.05  # mm of overlap that fuses the fingers to the plate in ``assembly``
SIDES = {0: -1.0, 1: +1.0}  # the extension tendon sits toward -z, the flexion one toward +z


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


def _near_root(t, cfg: ExportConfig, root: float, depth: float) -> np.ndarray:
    """Points (every 0.25 mm) of ``t``'s centreline within ``depth`` below the root face."""
    from dbtool.export.gripper.channel_path import fillet

    path = fillet(t.corners(), cfg.bend_radius).sample(0.25)
    return path[(path[:, 1] <= root + 1e-6) & (path[:, 1] >= root - depth)]


def _union(solids: list):
    solids = [s for s in solids if s is not None and not s.is_empty()]
    return m3.Manifold.batch_boolean(solids, m3.OpType.Add) if solids else m3.Manifold()


def _mirror(solid, plane: float):
    return solid.mirror([0.0, 0.0, 1.0]).translate([0.0, 0.0, 2 * plane])


def reach_root(finger, root: float, depth: float = 1.5) -> tuple[object, float]:
    """The finger continued straight up to the base's lower face (``root``, mm) when its top
    stops below it, and how far it stopped (mm; 0 when it reaches the base).

    That happens when the design's top sites hang from the body by a thread of single sites:
    the simulator's grid glues the thread to the base, but the mesh's largest piece does not
    include it. The continuation is the finger's own cross-section ``depth`` mm below its top,
    extruded up to the base (0.3 mm inside its surface), so the printed finger can be glued
    where the simulated one is."""
    top = finger.bounding_box()[4]
    if top >= root - 1e-3:
        return finger, 0.0
    y0 = top - depth
    # y becomes z: a horizontal section, kept 0.3 mm inside the surface so the column's walls
    # cross the finger's instead of touching it (touching faces leave slivers an STL loses)
    section = finger.rotate([90.0, 0.0, 0.0]).slice(y0).offset(-0.3, m3.JoinType.Round)
    column = section.extrude(root + 1.0 - y0).translate([0.0, 0.0, y0]).rotate([-90.0, 0.0, 0.0])
    joined = (finger + column).trim_by_plane([0.0, -1.0, 0.0], -root)
    return joined, float(root - top)


def build_gripper(design: Design, cfg: ExportConfig) -> Assembly:
    s = cfg.scale_mm
    t0 = time.perf_counter()
    root, top = (FULL[1] - BASE) * s, FULL[1] * s  # the base's lower and upper faces
    finger, regions, pillars, gap, short = _finger(design, s, root)
    plane = FULL[2] / 2 * s  # the finger lies in z < plane, its mirror in z > plane
    t_mesh = time.perf_counter()
    tendons, pins, pin_base, pockets = _route(finger, regions, cfg, top, root, plane)
    t_route = time.perf_counter()
    body_volume, fill, bridge = _volumes(design, finger, s, pillars)
    solid_finger = finger
    own = [t for t in tendons if t.finger == "finger"]
    finger, info = _infill(finger, own, pins, cfg, root)
    t_infill = time.perf_counter()
    mounting = _mounting(solid_finger, tendons, pins, cfg, s, root, plane)
    cut = _hole_cut(mounting["holes"], cfg, s, root)
    if cfg.channels:  # cut the designed finger; its mirror copy stays its exact reflection
        tubes = _union([finger_cut(t, cfg, root) for t in own])
        finger = finger - tubes
        cut = cut + _union([base_cut(t, cfg, top, root) for t in tendons])
    plain = finish(finger)  # without pin pockets: the fused assembly fills them with the pins
    finger = finish(finger - pockets) if pins else plain
    base, plate = _base(cut, pins, pin_base, s, root, plane)
    mirror = _mirror(finger, plane)
    t_channels = time.perf_counter()
    parts = {"finger": finger, "finger_mirror": mirror, "base": base}
    union = finish(_union([plain, _mirror(plain, plane), plate]))
    timings = {"mesh_s": t_mesh - t0, "routing_s": t_route - t_mesh,
               "infill_s": t_infill - t_route, "channels_s": t_channels - t_infill,
               "assembly_s": time.perf_counter() - t_channels}
    notes = {"root_gap_mm": round(gap, 3), "root_extension_mm": round(short, 3),
             "root_bridge_mm3": round(bridge, 1),
             "root_pillar_fill_mm3": round(fill, 1),
             "glue_face_mm2": round(_root_area(solid_finger, root), 1)}
    return Assembly(parts, union, tendons, design_volume(design, s, largest=True),
                    body_volume, timings, info, notes, mounting)


def _finger(design: Design, s: float, root: float) -> tuple:
    """The designed finger (mm), kept below the base's lower face ``root`` and reaching it;
    also the actuator groups' fields, the root pillars, the field's root gap and how far the
    finger was continued up to the base."""
    body, regions, gap = design_fields(design, s, extrude_top=3)
    # the finger stays INSET inside its workspace's sides: a finger face nearly coplanar with
    # the base's side face leaves edges of 1e-6 mm in the fused assembly (an STL cannot keep them)
    ws = np.array([[INSET, -1.0, INSET], [FULL[0] * s - INSET, root + 2.0, FULL[2] * s - INSET]])
    pillars = _root_pillars(design, s, root)
    finger = body.solid(keep_largest=False, boxes=pillars, clip=ws)
    finger = finger.trim_by_plane([0.0, -1.0, 0.0], -root)  # keep y <= root
    finger, short = reach_root(largest_component(finger), root)
    return finger, regions, pillars, gap, short


def _route(finger, regions, cfg: ExportConfig, top: float, root: float, plane: float) -> tuple:
    """Both fingers' tendons, the alignment pins (x, z) and their solids: the pins on the base
    and the pockets in the finger's root face."""
    vox = Voxels.of(finger, cfg.pitch)
    tendons = route_finger(finger, regions, cfg, "finger", top, root, SIDES, voxels=vox)
    # alignment pins in the root face, clear of the channels where they run within a pocket's
    # depth (and a wall) of it; the walls are measured again with the pockets cut
    avoid = [(x, z, cfg.channel_radius) for t in tendons
             for x, _, z in _near_root(t, cfg, root, cfg.pin_length + 0.5 + cfg.min_wall
                                       + cfg.channel_radius + 0.5 * cfg.pin_diameter)]
    pins = alignment_pins(finger, root, cfg.pin_diameter, cfg.pin_clearance, cfg.min_wall, avoid)
    pin_base, pockets = pin_solids(pins, root, cfg.pin_diameter, cfg.pin_length,
                                   cfg.pin_clearance)
    if pins:
        check_walls(tendons, finger, cfg, root, pockets)
    tendons += [mirror_tendon(t, plane, "finger_mirror") for t in tendons]
    return tendons, pins, pin_base, pockets


def _volumes(design: Design, finger, s: float, pillars) -> tuple[float, float, float]:
    """The finger's volume below the design's top sites (what the volume check compares), the
    empty cells the root pillars fill and what the finger holds above those sites (mm^3)."""
    design_top = (design.robot.points[design.robot.active(), 1].max() + SPACING / 2) * s
    body_volume = finger.trim_by_plane([0.0, -1.0, 0.0], -design_top).volume()
    fill = _pillar_fill(design, s, pillars, design_top)
    bridge = finger.volume() - body_volume
    return body_volume, fill, bridge


def _infill(finger, own: list, pins: list, cfg: ExportConfig, root: float) -> tuple[object, dict]:
    """The finger with its Voronoi infill (``--infill voronoi``), and the infill's numbers."""
    if cfg.infill != "voronoi":
        return finger, {}
    from dbtool.export.geometry.infill import InfillConfig, voronoi_infill
    from dbtool.export.gripper.channels import centreline, tube

    foam, info = voronoi_infill(finger, InfillConfig(shell=cfg.shell))
    # solid sleeves keep each channel and pin pocket a closed hole through the foam
    sleeves = [tube(centreline(t, cfg), cfg.channel_radius + cfg.min_wall) for t in own
               if cfg.channels]
    if pins:
        sleeves += [pin_solids(pins, root, cfg.pin_diameter + 2 * cfg.min_wall,
                               cfg.pin_length, cfg.pin_clearance)[1]]
    if sleeves:
        foam = foam + (_union(sleeves) ^ finger)
    return foam, info


def _mounting(solid_finger, tendons: list, pins: list, cfg: ExportConfig, s: float, root: float,
              plane: float) -> dict:
    """The mounting holes, where neither finger's shadow nor a tube seat is in the way, and
    the alignment pins, as the report and the assembly sheet give them."""
    seats = [(t.exit[0], t.exit[2], cfg.seat_radius) for t in tendons]
    mirrored = _mirror(solid_finger, plane)
    mounting = mount_holes([solid_finger, mirrored], (0.0, 0.0, FULL[0] * s, FULL[2] * s),
                           root, cfg.mount_hole, cfg.screw_head, avoid=seats, mirror_z=plane)
    mounting["clearance_mm3"] = [round(v, 3) for v in hole_clearance(
        [solid_finger, mirrored], mounting["holes"], 0.5 * cfg.screw_head, root)]
    mounting["pins"] = [[round(float(x), 3), round(float(z), 3)] for x, z in pins]
    mounting["pins_mirror"] = [[x, round(2 * plane - z, 3)] for x, z in mounting["pins"]]
    mounting["pin_diameter_mm"] = cfg.pin_diameter
    mounting["pin_length_mm"] = cfg.pin_length
    return mounting


def _hole_cut(holes: list, cfg: ExportConfig, s: float, root: float):
    """The mounting holes' cylinders, through the base from below."""
    r = 0.5 * cfg.mount_hole
    cylinders = []
    for x, z in holes:
        hole = m3.Manifold.cylinder(BASE * s + 2.0, r, r, 24)
        cylinders.append(hole.rotate([-90.0, 0.0, 0.0]).translate([x, root - 1.0, z]))
    return _union(cylinders)


def _base(cut, pins: list, pin_base, s: float, root: float, plane: float) -> tuple:
    """The base plate with ``cut`` taken out and the pins on, and the plate of the fused
    assembly."""
    base = m3.Manifold.cube([FULL[0] * s, BASE * s, FULL[2] * s]).translate([0.0, root, 0.0])
    # the fingers only touch the plate's lower face; in the fused assembly the plate reaches
    # GLUE lower so fingers and plate overlap and join into one body (one box, cut once: a
    # separate glue slab shares the holes' walls with the plate, which leaves slivers)
    plate = m3.Manifold.cube([FULL[0] * s, BASE * s + GLUE, FULL[2] * s])
    plate = finish(plate.translate([0.0, root - GLUE, 0.0]) - cut)
    base = base - cut
    if pins:
        base = base + pin_base + _mirror(pin_base, plane)
    base = finish(base)
    return base, plate


def _root_area(finger, root: float) -> float:
    """Area (mm^2) of the finger's root face: what is glued to the base."""
    v = finger.trim_by_plane([0.0, 1.0, 0.0], root - 0.05)  # the last 0.05 mm below the face
    return v.volume() / 0.05 if not v.is_empty() else 0.0
