"""The export stage (docs/method.md §8): a saved Design -> printable parts, an assembly, tendon
routing and a fabrication report, all in millimetres.

Gripping: the designed finger, its mirror copy (``Manifold.mirror``, so winding stays right) about
the gripper's mirror plane and the rigid base plate with four mounting holes, placed as in the
simulated gripper; one tendon per actuator group and finger (:mod:`dbtool.export.gripper.tendons`),
optionally cut as channels. Other tasks: the body and its actuator regions as separate parts.
The checks and the report are in :mod:`dbtool.export.reports.report`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from dbtool.atomic import atomic_folder
from dbtool.design import Design
from dbtool.errors import InputError
from dbtool.export.complete import mark_complete
from dbtool.export.config import INFILLS, Assembly, ExportConfig
from dbtool.export.geometry.fields import design_fields
from dbtool.export.geometry.mesh import OccupancyField, finish, write_stl
from dbtool.export.gripper.parts import build_gripper
from dbtool.export.printing.threemf import write_3mf
from dbtool.export.reports.report import design_volume, report, report_markdown
from dbtool.runs import write_json
from dbtool.sim.tasks import get_task

__all__ = ["Assembly", "ExportConfig", "build", "design_volume", "export_design",
           "report_markdown"]

def build_body(design: Design, cfg: ExportConfig) -> Assembly:
    """Any other task: the body, and the actuator regions as parts inside it."""
    s = cfg.scale_mm
    t0 = time.perf_counter()
    body_field, regions, _ = design_fields(design, s)
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
        from dbtool.export.geometry.infill import InfillConfig, voronoi_infill

        parts["body"], info = voronoi_infill(body, InfillConfig(shell=cfg.shell))
    parts = {k: finish(v) for k, v in parts.items()}
    return Assembly(parts, parts["body"], [], design_volume(design, s, largest=True), body.volume(),
                    {"mesh_s": t1 - t0, "infill_s": time.perf_counter() - t1}, info)


def build(design: Design, cfg: ExportConfig | None = None) -> Assembly:
    cfg = cfg or ExportConfig()
    if cfg.infill not in INFILLS:  # the config was changed after it was checked
        raise InputError(f"unknown infill {cfg.infill!r}: choose {' or '.join(INFILLS)}")
    task = get_task(design.task)  # fail early on an unknown task
    if design.robot.n == 0:
        raise InputError("the design has no robot fields (points, occupancy, actuators)")
    if task.gripper:
        return build_gripper(design, cfg)
    return build_body(design, cfg)


SOFT = ("TPU 95A (soft)", "#E07020")
RIGID = ("PLA (rigid)", "#8C8C8C")
SLICE_AS = {"TPU 95A (soft)": "flex", "PLA (rigid)": "pla"}
ACTUATOR_COLOURS = ("#D62728", "#1F77B4", "#2CA02C", "#9467BD", "#FF7F0E", "#8C564B")


def materials(parts: dict) -> dict[str, tuple[str, str]]:
    """Material and colour per part: soft fingers and bodies, a rigid base; actuator regions in
    the soft material, one colour per group."""
    out = {}
    for k in parts:
        if k == "base":
            out[k] = RIGID
        elif k.startswith("actuator_"):
            g = int(k.split("_")[1])
            out[k] = (SOFT[0], ACTUATOR_COLOURS[g % len(ACTUATOR_COLOURS)])
        else:
            out[k] = SOFT
    return out


def poses(asm: Assembly, cfg: ExportConfig) -> dict:
    """Print pose per part (docs/export.md, "Print orientation"): each gripper part its own;
    a body's actuator regions share the body's, so they still tile it."""
    from dbtool.export.printing.orient import PrintPose, choose_pose

    if not cfg.orient:  # the parts stay in the design's frame
        return {k: PrintPose(np.array([0.0, 0.0, -1.0]), np.eye(4), 0.0, 0.0,
                             float(np.ptp(np.reshape(v.bounding_box(), (2, 3))[:, 2])), [])
                for k, v in asm.parts.items()}
    if "body" in asm.parts:
        pose = choose_pose(asm.parts["body"])
        return {k: pose for k in asm.parts}
    return {k: choose_pose(v) for k, v in asm.parts.items()}


def export_design(design: Design, out_dir: Path, cfg: ExportConfig | None = None,
                  name: str | None = None, page: bool = False) -> dict:
    """Write the parts (STL and/or 3MF, in their print orientation), ``assembly.stl`` (the
    gripper fused, in its own frame), ``tendons.json``, ``tendons.png``, ``assembly.md``,
    ``exploded.png``, ``report.json`` and ``report.md`` into ``out_dir``; returns the report.

    ``page``: also ``report.html`` (:func:`dbtool.export.reports.page.write_export_page`).
    Everything is written into a hidden sibling folder first, the completion marker last
    (:mod:`dbtool.export.complete`), and the folder is renamed into place as a whole, so an
    interrupted export never leaves a folder that looks complete.
    """
    from dbtool.export.printing.orient import apply_pose
    from dbtool.export.printing.threemf import plate_layout

    cfg = cfg or ExportConfig()
    out_dir = Path(out_dir)
    name = name or out_dir.name
    asm = build(design, cfg)
    gripper = get_task(design.task).gripper
    mats = materials(asm.parts)
    pose = poses(asm, cfg)
    posed = {k: apply_pose(v, pose[k]) for k, v in asm.parts.items()}
    with atomic_folder(out_dir) as tmp:
        files = []
        t0 = time.perf_counter()
        for part, solid in posed.items():
            if cfg.stl:
                files.append(write_stl(solid, tmp / f"{part}.stl").name)
        if cfg.stl and gripper:
            files.append(write_stl(asm.union, tmp / "assembly.stl").name)
        if cfg.threemf:
            if "body" in posed and len(posed) > 1:  # the regions, which together are the body
                objs = {k: v for k, v in posed.items() if k != "body"}
                layout = None
            else:
                objs, layout = posed, plate_layout(posed)
            files.append(write_3mf(objs, tmp / "assembly.3mf", {k: mats[k] for k in objs},
                                   layout).name)
        t_write = time.perf_counter() - t0
        sliced = _slice(posed, mats, tmp, cfg)
        rep = report(design, asm, cfg, name, files)
        rep["timings_s"]["write_s"] = round(t_write, 3)
        rep["timings_s"]["slice_s"] = round(time.perf_counter() - t0 - t_write, 3)
        for k, p in pose.items():
            rep["parts"][k]["material"] = mats[k][0]
            rep["parts"][k]["print_pose"] = p.as_json()
        rep["slicer"] = sliced
        if gripper:
            _gripper_files(design, asm, cfg, rep, tmp, name)
        write_json(tmp / "report.json", rep)
        (tmp / "report.md").write_text(report_markdown(rep))
        if page:
            from dbtool.export.reports.page import write_export_page

            write_export_page(tmp, name)
        mark_complete(tmp)
    return rep


def _slice(posed: dict, mats: dict, tmp: Path, cfg: ExportConfig) -> dict:
    """PrusaSlicer's verdict on each printable part (docs/export.md, "Printability"), or why
    there is none."""
    from dbtool.export.printing.slicer import find_slicer, slice_parts

    if not cfg.slice:
        return {"skipped": "--no-slice"}
    if find_slicer() is None:
        return {"skipped": "PrusaSlicer not installed (apt-get install prusa-slicer, or set "
                           "DBTOOL_SLICER)"}
    printable = {k: v for k, v in posed.items() if not k.startswith("actuator_")}
    stls = {}
    for k, v in printable.items():
        path = tmp / f"{k}.stl"
        if not path.exists():  # 3MF only: slice a temporary STL
            path = write_stl(v, tmp / f".slice-{k}.stl")
        stls[k] = path
    results = slice_parts(stls, {k: SLICE_AS[mats[k][0]] for k in stls})
    for p in tmp.glob(".slice-*.stl"):
        p.unlink()
    return {k: r.as_json() for k, r in results.items()}


def _gripper_files(design: Design, asm: Assembly, cfg: ExportConfig, rep: dict, tmp: Path,
                   name: str) -> None:
    """``tendons.json``, ``tendons.png``, ``assembly.md`` and ``exploded.png``."""
    from dbtool.export.reports.drawing import draw_tendons
    from dbtool.export.reports.sheet import draw_exploded, write_assembly_md

    tj = {"units": "mm", "frame": "gripper workspace, y up, base on top",
          "channel_diameter_mm": cfg.line_channel, "tube_seat_diameter_mm": 2 * cfg.seat_radius,
          "min_wall_mm": cfg.min_wall, "bend_radius_mm": cfg.bend_radius,
          "knot_depth_mm": cfg.knot_depth,
          "channels_cut": cfg.channels, "tendons": [t.as_json() for t in asm.tendons]}
    write_json(tmp / "tendons.json", tj)
    draw_tendons(asm, tmp / "tendons.png", title=name)
    sheet = assembly_sheet(asm, cfg, rep, name)
    write_assembly_md(sheet, tmp / "assembly.md")
    draw_exploded(sheet, tmp / "exploded.png")


def assembly_sheet(asm: Assembly, cfg: ExportConfig, rep: dict, name: str) -> dict:
    """What the assembly sheet needs (:mod:`dbtool.export.reports.sheet`), from an export's
    report."""
    mats = materials(asm.parts)
    sliced = rep.get("slicer", {})
    prints = {}
    for k in asm.parts:
        pose = rep["parts"][k]["print_pose"]
        s = sliced.get(k) if isinstance(sliced.get(k), dict) else None
        prints[k] = {"down": pose["down"], "height_mm": pose["height_mm"],
                     "overhang_mm2": pose["overhang_mm2"], "file": f"{k}.stl",
                     "slicer": None if s is None else {
                         "ok": s["ok"], "layers": s["layers"], "print_time_s": s["print_time_s"],
                         "filament_g": s["filament_g"], "filament_m": s["filament_mm"] / 1000}}
    m = asm.mounting
    return {
        "name": name, "parts": asm.parts, "materials": mats, "print": prints,
        "holes": {"holes": m["holes"], "diameter_mm": m["diameter_mm"],
                  "keepout_mm": m["keepout_mm"], "pattern_mm": m.get("pattern_mm")},
        "pins": m["pins"] + m["pins_mirror"],
        "pin": {"diameter_mm": cfg.pin_diameter, "length_mm": cfg.pin_length},
        "tendons": [t.as_json() for t in asm.tendons],
        "hardware": {"line_diameter_mm": cfg.tendon_diameter, "tube_od_mm": cfg.tube_diameter,
                     "tube_id_mm": cfg.tube_diameter / 2, "tube_length_mm": cfg.tube_length,
                     "screw": "M3 x 12 socket head", "knot_pocket_mm": cfg.knot_pocket},
        "glue_mm2": asm.notes.get("glue_face_mm2", 0.0),
    }
