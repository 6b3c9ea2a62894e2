"""The export stage: a saved Design -> printable parts, an assembly and a report (mm)."""

from __future__ import annotations

from pathlib import Path

from dbtool.design import Design
from dbtool.export.mesh import MM_PER_UNIT, occupancy_solid, report, write_mesh
from dbtool.runs import write_json
from dbtool.sim.tasks import get_task
from dbtool.sim.tasks.base import SPACING
from dbtool.sim.tasks.gripping import BASE, FULL


def build_parts(design: Design, scale: float = MM_PER_UNIT) -> dict:
    """Manifolds (mm) of the design: ``body`` or, for the gripper, ``finger``, ``finger_mirror``,
    ``base`` and their boolean union ``assembly``."""
    import manifold3d as m3

    robot = design.robot
    body = occupancy_solid(robot.points, robot.active(), SPACING, scale)
    if design.task != "gripping":
        return {"body": body, "assembly": body}
    plane = FULL[2] / 2 * scale  # the finger lies in z < plane; its mirror in z > plane
    mirror = body.mirror([0.0, 0.0, 1.0]).translate([0.0, 0.0, 2 * plane])
    # the plate reaches one particle spacing down so the finger roots fuse with it
    base = m3.Manifold.cube([FULL[0] * scale, (BASE + SPACING) * scale, FULL[2] * scale])
    base = base.translate([0.0, (FULL[1] - BASE - SPACING) * scale, 0.0])
    assembly = m3.Manifold.batch_boolean([body, mirror, base], m3.OpType.Add)
    return {"finger": body, "finger_mirror": mirror, "base": base, "assembly": assembly}


def export_design(design: Design, out_dir: Path, formats=("stl",),
                  scale: float = MM_PER_UNIT) -> dict:
    """Write every part in each format plus ``report.json``; returns the report."""
    get_task(design.task)  # fail early on an unknown task
    out_dir = Path(out_dir)
    parts = build_parts(design, scale)
    files = []
    for name, solid in parts.items():
        for fmt in formats:
            files.append(str(write_mesh(solid, out_dir / f"{design.task}_{name}.{fmt}")))
    rep = {"task": design.task, "units": "mm", "mm_per_sim_unit": scale,
           "files": files, "parts": {name: report(solid) for name, solid in parts.items()}}
    write_json(out_dir / "report.json", rep)
    return rep
