"""Export: watertight manifold meshes in millimetres; the gripper assembly is one solid."""

import trimesh

from dbtool.design import Design
from dbtool.export.assembly import export_design
from dbtool.sim.tasks import get_task


def test_gripper_assembly_is_one_watertight_solid(tmp_path):
    task = get_task("gripping")
    d = Design("gripping", task.reference_robot("finger"), task.controller())
    rep = export_design(d, tmp_path)
    a = rep["parts"]["assembly"]
    assert a["watertight"] and a["is_volume"]
    assert a["genus"] == 0, "fingers and base must fuse into one connected solid"
    assert a["bbox_mm"] == [60.0, 80.0, 120.0]
    f, m = rep["parts"]["finger"], rep["parts"]["finger_mirror"]
    assert abs(f["volume_mm3"] - m["volume_mm3"]) < 1e-6 * f["volume_mm3"]
    mesh = trimesh.load(tmp_path / "gripping_assembly.stl")
    assert mesh.is_watertight and abs(mesh.volume - a["volume_mm3"]) < 1e-3 * a["volume_mm3"]
    assert (tmp_path / "report.json").exists()


def test_body_export_volume_matches_occupancy(tmp_path):
    task = get_task("crawling")
    robot = task.reference_robot("box")
    rep = export_design(Design("crawling", robot, task.controller()), tmp_path)
    body = rep["parts"]["body"]
    assert body["watertight"]
    expected = 80.0**3  # the full 0.08 workspace at 1000 mm per unit
    assert abs(body["volume_mm3"] - expected) / expected < 0.1
