"""Fabrication checks of the exported parts and the export's report (docs/method.md §8):
``report.json`` and a short ``report.md``."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from dbtool.design import Design
from dbtool.export._manifold import mesh_arrays, to_trimesh
from dbtool.export.config import Assembly, ExportConfig
from dbtool.sim.tasks import get_task
from dbtool.sim.tasks.base import SPACING

WALL_CAP = 10.0  # mm: walls thicker than this are not measured


def design_volume(design: Design, scale: float, largest: bool = False) -> float:
    """The design's solid volume: active lattice sites x spacing^3, in mm^3; ``largest``: of
    its largest connected piece only (sites touching by a face, edge or corner), the piece the
    export keeps."""
    robot = design.robot
    active = robot.active()
    n = int(active.sum())
    if largest and n:
        from scipy.ndimage import label

        idx = np.round(robot.points[active] / SPACING - 0.5).astype(int)
        idx -= idx.min(0)
        grid = np.zeros(idx.max(0) + 1, bool)
        grid[tuple(idx.T)] = True
        lab, k = label(grid, structure=np.ones((3, 3, 3)))
        if k > 1:
            n = int(np.bincount(lab[grid]).max())
    return float(n) * (SPACING * scale) ** 3


def wall_thickness(solid, cap: float = WALL_CAP, eps: float = 1e-3,
                   cos_max: float = 0.5) -> np.ndarray:
    """Wall thickness (mm) at every triangle: the distance from its centroid along the inward
    normal to where the ray leaves the solid (manifold3d's ray cast). Counted only where the
    exit face is within 60 degrees of opposite (``cos_max``: a ray leaving through a fillet
    beside its start measures an edge, not a wall); ``inf`` there and where the wall is thicker
    than ``cap`` (short rays keep the cast cheap on large flat faces)."""
    v, t = mesh_arrays(solid)
    tri = v[t]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    n /= np.maximum(2 * area[:, None], 1e-30)
    c = tri.mean(1)
    start, end = (c - eps * n).tolist(), (c - cap * n).tolist()
    out = np.full(len(c), np.inf)
    for i in np.flatnonzero(area > 1e-4):  # a sliver triangle has no reliable normal
        hits = solid.ray_cast(start[i], end[i])
        if hits and -float(np.dot(hits[0].normal, n[i])) >= cos_max:
            out[i] = hits[0].distance * (cap - eps) + eps
    return out


SHARP_DEG = 30.0  # an edge where the surface turns more than this is a step (staircase)


def sharp_edges(solid, planes: tuple = (), angle: float = SHARP_DEG) -> float:
    """The lattice staircase, measured: length (mm) of the edges where the surface turns by more
    than ``angle`` degrees, per 100 mm^2 of surface. Edges of faces lying on one of ``planes``
    ((axis, value) in mm: the cut faces, a root glued flat) are not counted, nor their area."""
    tm = to_trimesh(solid, weld=True)
    on = np.zeros(len(tm.faces), bool)
    for axis, value in planes:
        on |= (np.abs(tm.triangles[:, :, axis] - value) < 0.02).all(1)
    adj = tm.face_adjacency
    keep = ~on[adj].any(1) & (tm.face_adjacency_angles > np.radians(angle))
    e = tm.face_adjacency_edges[keep]
    length = np.linalg.norm(tm.vertices[e[:, 0]] - tm.vertices[e[:, 1]], axis=1).sum()
    area = tm.area_faces[~on].sum()
    return float(100.0 * length / area) if area > 0 else 0.0


def mesh_report(solid, thickness: bool = True) -> dict:
    """Fabrication checks of one part: watertightness, bodies, genus, volume, bounding box and
    the thinnest wall (ray cast along the inward normal of every triangle).

    ``watertight`` and ``is_volume`` are trimesh's verdict on the part as an STL reader sees it:
    float32 vertices welded by position, so two vertices that only a double can tell apart
    (a pinch) count against it."""
    tm = to_trimesh(solid, weld=True)
    lo, hi = tm.bounds
    rep = {
        "watertight": bool(tm.is_watertight), "is_volume": bool(tm.is_volume),
        "manifold_status": str(solid.status()).split(".")[-1],
        "bodies": len(solid.decompose()), "genus": int(solid.genus()),
        "volume_mm3": float(solid.volume()), "triangles": int(solid.num_tri()),
        "bbox_mm": (hi - lo).round(3).tolist(), "bbox_min_mm": lo.round(3).tolist(),
    }
    if thickness:
        t = wall_thickness(solid)
        rep["min_wall_mm"] = round(float(t.min()), 3) if np.isfinite(t).any() else WALL_CAP
        rep["min_wall_capped"] = not np.isfinite(t).any()  # every wall thicker than the cap
    return rep


def report(design: Design, asm: Assembly, cfg: ExportConfig, name: str, files: list) -> dict:
    """``report.json``: per part the checks of :func:`mesh_report`, the volume against the
    design's solid volume x scale^3, and the tendons' clearances."""
    parts = {k: mesh_report(v) for k, v in asm.parts.items()}
    gripper = get_task(design.task).gripper
    if gripper:
        parts["assembly"] = mesh_report(asm.union, thickness=False)
    main = "finger" if gripper else "body"
    rep = {
        "design": name, "task": design.task, "units": "mm", "mm_per_sim_unit": cfg.scale_mm,
        "config": asdict(cfg), "files": files, "parts": parts,
        "volume_check": {
            "part": main, "design_solid_mm3": asm.design_volume_mm3,
            "mesh_mm3": asm.body_volume_mm3,
            # the gripper's root pillars fill empty cells on purpose: compare against both
            "ratio": asm.body_volume_mm3 / (asm.design_volume_mm3
                                            + asm.notes.get("root_pillar_fill_mm3", 0.0)),
            "design_total_mm3": design_volume(design, cfg.scale_mm),  # loose pieces included
        },
        "timings_s": {k: round(v, 3) for k, v in asm.timings.items()},
        **asm.notes,
        "metrics": design.metrics,
    }
    if asm.tendons:
        ts = asm.tendons
        rep["tendons"] = {
            "count": len(ts), "points_per_tendon": len(ts[0].points),
            "channel_diameter_mm": cfg.line_channel, "channel_radius_mm": cfg.channel_radius,
            "tube_seat_diameter_mm": 2 * cfg.seat_radius, "min_wall_mm": cfg.min_wall,
            "bend_radius_mm": cfg.bend_radius,
            "min_point_depth_mm": min(min(t.depth_mm) for t in ts),
            "channel_clearance_mm": min(t.clearance_mm for t in ts),
            "wall_samples": sum(t.wall_samples for t in ts),
            "min_bend_radius_mm": min((t.min_bend_radius_mm for t in ts
                                       if t.min_bend_radius_mm is not None), default=None),
            "through_holes": sum(bool(t.tip) for t in ts),
            "knot_pockets": sum(t.pocket_mm > 0 for t in ts),
            "pocket_mm": {t.name: t.pocket_mm for t in ts},
            "routes": sorted({t.route for t in ts}),
            "length_mm": {t.name: t.length_mm for t in ts},
            "failures": {t.name: t.failures for t in ts if t.failures},
            "all_ok": all(t.ok for t in ts),
        }
    if asm.mounting:
        m = asm.mounting
        rep["mounting"] = {**m, "holes_clear": all(v == 0 for v in m["clearance_mm3"])}
    if "finger" in asm.parts:
        from dbtool.sim.tasks.gripping import BASE, FULL

        s = cfg.scale_mm
        inset = 0.2
        planes = ((1, (FULL[1] - BASE) * s), (0, inset), (0, FULL[0] * s - inset), (2, inset))
        rep["staircase"] = {"part": "finger", "sharp_edges_mm_per_100mm2": round(
            sharp_edges(asm.parts["finger"], planes), 2), "angle_deg": SHARP_DEG}
    elif "body" in asm.parts:
        rep["staircase"] = {"part": "body", "sharp_edges_mm_per_100mm2": round(
            sharp_edges(asm.parts["body"]), 2), "angle_deg": SHARP_DEG}
    if asm.infill:
        rep["infill"] = asm.infill
    return rep


def report_markdown(rep: dict) -> str:
    """A short human-readable ``report.md``."""
    lines = _parts_lines(rep) + _volume_lines(rep) + _tendon_lines(rep) + _mounting_lines(rep)
    lines += _print_lines(rep)
    if "infill" in rep:
        i = rep["infill"]
        lines += ["", f"Voronoi infill: relative density {i['relative_density']:.3f} "
                      f"(seed spacing {i['spacing_mm']} mm, beams {i['beam_mm']} mm, shell "
                      f"{i['shell_mm']} mm), built in {i['seconds']:.1f} s."]
    return "\n".join(lines) + "\n"


def _parts_lines(rep: dict) -> list[str]:
    """The report's title and its table of parts."""
    lines = [f"# Fabrication report: {rep['design']}", "",
             f"Task {rep['task']}; units mm ({rep['mm_per_sim_unit']:g} mm per simulation unit).",
             "", "| part | watertight | volume | bodies | genus | volume (mm³) | "
                 "bounding box (mm) | thinnest wall (mm) |",
             "| --- | --- | --- | ---: | ---: | ---: | --- | ---: |"]
    for k, p in rep["parts"].items():
        wall = f"{p['min_wall_mm']:.2f}" if "min_wall_mm" in p else "–"
        box = " × ".join(f"{v:.1f}" for v in p["bbox_mm"])
        lines.append(f"| {k} | {p['watertight']} | {p['is_volume']} | {p['bodies']} | "
                     f"{p['genus']} | {p['volume_mm3']:.0f} | {box} | {wall} |")
    return lines


def _volume_lines(rep: dict) -> list[str]:
    """The volume check, what the root needed and the surface's staircase."""
    lines: list[str] = []
    v = rep["volume_check"]
    fill = rep.get("root_pillar_fill_mm3", 0.0)
    plus = f" plus {fill:.0f} mm³ of root cells the pillars fill" if fill > 0 else ""
    lines += ["", f"Meshed {v['part']} {v['mesh_mm3']:.0f} mm³ against the design's solid "
                  f"{v['design_solid_mm3']:.0f} mm³{plus} (ratio {v['ratio']:.3f}). The thinnest "
                  "wall is the shortest ray from a face, along its inward normal, through the "
                  "part."]
    if rep.get("root_gap_mm", 0) > 0:
        lines += ["", f"The design's top sites stop {rep['root_gap_mm']:.2f} mm below the base "
                      "(the simulator's grid joins them across it); the export fills that gap "
                      f"with {rep['root_bridge_mm3']:.0f} mm³ so the finger meets the base."]
    if rep.get("root_extension_mm", 0) > 0:
        lines += ["", f"**Root extended:** the finger's largest piece stopped "
                      f"{rep['root_extension_mm']:.1f} mm below the base (the design's top sites "
                      "hang from it by a thread the mesh does not keep); the export continues "
                      "its cross-section straight up to the base so it can be glued there."]
    dropped = v["design_total_mm3"] - v["design_solid_mm3"]
    if dropped > 0:
        lines += ["", f"**Loose pieces dropped:** {dropped:.0f} mm³ of the design "
                      f"({dropped / v['design_total_mm3']:.1%}) is not connected to its largest "
                      "piece and was left out."]
    if "staircase" in rep:
        st = rep["staircase"]
        lines += ["", f"Surface: {st['sharp_edges_mm_per_100mm2']:.2f} mm of edges turning more "
                      f"than {st['angle_deg']:g}° per 100 mm² of the {st['part']}'s surface (the "
                      "lattice's staircase; cut faces not counted)."]
    return lines


def _tendon_lines(rep: dict) -> list[str]:
    """The tendons: routes, channels, walls, bends and their verdict."""
    lines: list[str] = []
    if "tendons" in rep:
        t = rep["tendons"]
        verdict = "all clear" if t["all_ok"] else "**FAILING: " + "; ".join(
            f"{k}: {', '.join(v)}" for k, v in t["failures"].items()) + "**"
        bend = ("none: straight channels" if t["min_bend_radius_mm"] is None
                else f"{t['min_bend_radius_mm']:.2f} mm")
        lines += ["", f"Tendons: {t['count']} ({t['points_per_tendon']} routing points each, "
                      f"routes: {', '.join(t['routes'])}); line channel "
                      f"{t['channel_diameter_mm']:g} mm, tube seat "
                      f"{t['tube_seat_diameter_mm']:g} mm; thinnest wall along "
                      f"the paths {t['channel_clearance_mm']:.2f} mm (needed {t['min_wall_mm']:g}"
                      f", measured at {t['wall_samples']} points every 0.5 mm); smallest bend "
                      f"radius {bend} (needed {t['bend_radius_mm']:g} mm);"
                      f" through-holes at the tip {t['through_holes']}, knot pockets "
                      f"{t['knot_pockets']} (Ø "
                      f"{', '.join(f'{v:g}' for v in t['pocket_mm'].values())} mm); {verdict}. "
                      "Channels cut: "
                      f"{rep['config']['channels']}."]
    return lines


def _mounting_lines(rep: dict) -> list[str]:
    """The mounting holes and the alignment pins."""
    lines: list[str] = []
    if "mounting" in rep:
        m = rep["mounting"]
        holes = ", ".join(f"({x:.1f}, {z:.1f})" for x, z in m["holes"])
        lines += ["", f"Mounting: {len(m['holes'])} × Ø{m['diameter_mm']:g} mm holes at (x, z) "
                      f"{holes}; no finger within {m['keepout_mm']:.1f} mm of a hole's axis: "
                      f"{m['holes_clear']}. Alignment pins per finger: {len(m['pins'])} "
                      f"(Ø{m['pin_diameter_mm']:g} × {m['pin_length_mm']:g} mm)."]
    return lines


def _print_lines(rep: dict) -> list[str]:
    """Each part's print pose and PrusaSlicer's verdict."""
    lines: list[str] = []
    poses = [(k, p["print_pose"]) for k, p in rep["parts"].items() if "print_pose" in p]
    if poses:
        lines += ["", "| part | material | print: down | height (mm) | overhang (mm²) |",
                  "| --- | --- | --- | ---: | ---: |"]
        for k, p in poses:
            down = "(" + ", ".join(f"{v:g}" for v in np.round(p["down"], 3)) + ")"
            lines.append(f"| {k} | {rep['parts'][k].get('material', '')} | {down} | "
                         f"{p['height_mm']:.1f} | {p['overhang_mm2']:.0f} |")
    sl = rep.get("slicer", {})
    if "skipped" in sl:
        lines += ["", f"Slicer check skipped: {sl['skipped']}."]
    elif sl:
        lines += ["", "| part (PrusaSlicer, 0.2 mm layers) | profile | clean | layers | "
                      "time (h) | filament (g) | support (mm) |",
                  "| --- | --- | --- | ---: | ---: | ---: | ---: |"]
        for k, r in sl.items():
            lines.append(f"| {k} | {r['material']} | {r['ok']} | {r['layers']} | "
                         f"{r['print_time_s'] / 3600:.2f} | {r['filament_g']:.1f} | "
                         f"{r['support_mm']:.0f} |")
            lines += [f"  - {msg}" for msg in r["messages"]]
    return lines
