"""3MF with materials and a plate layout (dbtool.export.printing.threemf, docs/export.md): read
back by trimesh, by xml.etree, and by PrusaSlicer where it is installed."""

from __future__ import annotations

import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
import trimesh

from dbtool.export._manifold import manifold3d as m3
from dbtool.export.printing.orient import apply_pose, choose_pose
from dbtool.export.printing.threemf import NS, model_xml, plate_layout, transform_attr, write_3mf

Q = f"{{{NS}}}"
MATERIALS = {"finger": ("TPU 95A", "#1f77b4"), "mirror": ("TPU 95A", "#1f77b4"),
             "base": ("PLA", "#FF7F0E")}


def _parts() -> dict:
    """Three posed parts (min at the origin), each in its own pose."""
    raw = {"finger": m3.Manifold.cube([12, 30, 8]) + m3.Manifold.cube([12, 4, 25]),
           "mirror": m3.Manifold.sphere(9, 48).translate([40, -5, 3]),
           "base": m3.Manifold.cube([60, 7.5, 120])}
    return {n: apply_pose(s, choose_pose(s)) for n, s in raw.items()}


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    parts = _parts()
    layout = plate_layout(parts, gap=10.0)
    path = write_3mf(parts, tmp_path_factory.mktemp("plate") / "plate.3mf", MATERIALS, layout)
    return parts, layout, path


def _model(path) -> ET.Element:
    with zipfile.ZipFile(path) as z:
        return ET.fromstring(z.read("3D/3dmodel.model"))


def test_transform_attribute_is_3mf_row_vector_order():
    a = np.eye(4)
    a[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # quarter turn about z
    a[:3, 3] = [5, 6, 7]
    vals = np.array(transform_attr(a).split(), float)
    m = vals.reshape(4, 3)  # 3MF: p' = [x y z 1] M
    p = np.array([1.0, 2.0, 3.0])
    assert np.allclose(np.append(p, 1) @ m, a[:3, :3] @ p + a[:3, 3])
    assert np.allclose(vals[9:], [5, 6, 7])  # m30 m31 m32: the translation
    assert np.allclose(vals[:3], [0, 1, 0])  # m00 m01 m02: the image of x
    with pytest.raises(ValueError):
        transform_attr(np.diag([1.0, 1.0, 0.0, 1.0]))


def test_plate_layout_puts_parts_in_a_row_on_z0():
    parts = _parts()
    layout = plate_layout(parts, gap=10.0)
    boxes = [np.array(parts[n].transform(layout[n][:3, :4]).bounding_box()) for n in parts]
    for box in boxes:
        assert box[2] == pytest.approx(0.0, abs=1e-9) and box[1] == pytest.approx(0.0, abs=1e-9)
    assert boxes[0][0] == pytest.approx(0.0, abs=1e-9)
    for prev, nxt in zip(boxes[:-1], boxes[1:], strict=True):
        assert nxt[0] - prev[3] == pytest.approx(10.0, abs=1e-9)
    assert all(np.allclose(m[:3, :3], np.eye(3)) for m in layout.values())


def test_trimesh_reads_volumes_and_placement(plate):
    parts, layout, path = plate
    scene = trimesh.load(path)
    assert isinstance(scene, trimesh.Scene) and len(scene.geometry) == 3
    vols = sorted(g.volume for g in scene.geometry.values())
    assert np.allclose(vols, sorted(s.volume() for s in parts.values()), rtol=1e-5)
    placed = sorted((m.bounds for m in scene.dump()), key=lambda b: b[0][0])
    assert [lo[2] for lo, _ in placed] == pytest.approx([0.0] * 3, abs=1e-4)
    gaps = [b[0][0] - a[1][0] for a, b in zip(placed[:-1], placed[1:], strict=True)]
    assert gaps == pytest.approx([10.0, 10.0], abs=1e-4)
    want = [np.array(parts[n].transform(layout[n][:3, :4]).bounding_box()) for n in parts]
    assert np.allclose([np.ravel(b) for b in placed], sorted(want, key=lambda b: b[0]),
                       atol=1e-4)


def _turned(path):
    """A 10 x 20 x 30 box placed by a quarter turn about z (x -> y) and a shift."""
    a = np.eye(4)
    a[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    a[:3, 3] = [100, 50, 0]
    return write_3mf({"box": m3.Manifold.cube([10, 20, 30])}, path, transforms={"box": a})


def test_trimesh_applies_a_rotation_the_same_way(tmp_path):
    (lo, hi), = [m.bounds for m in trimesh.load(_turned(tmp_path / "turned.3mf")).dump()]
    assert np.allclose(lo, [80, 50, 0], atol=1e-5) and np.allclose(hi, [100, 60, 30], atol=1e-5)


def test_materials_and_property_references(plate):
    _, _, path = plate
    root = _model(path)
    res = root.find(f"{Q}resources")
    groups = res.findall(f"{Q}basematerials")
    assert len(groups) == 1 and list(res)[0] is groups[0]  # defined before it is referenced
    bases = [(b.get("name"), b.get("displaycolor")) for b in groups[0].findall(f"{Q}base")]
    assert bases == [("TPU 95A", "#1F77B4FF"), ("PLA", "#FF7F0EFF")]
    objs = {o.get("name"): o for o in res.findall(f"{Q}object")}
    ids = [o.get("id") for o in res.findall(f"{Q}object")] + [groups[0].get("id")]
    assert len(set(ids)) == len(ids)
    for name, (mat, _) in MATERIALS.items():
        assert objs[name].get("pid") == groups[0].get("id")
        assert bases[int(objs[name].get("pindex"))][0] == mat
    items = root.find(f"{Q}build").findall(f"{Q}item")
    assert len(items) == 3 and all(len(i.get("transform").split()) == 12 for i in items)


def test_without_options_the_file_is_the_plain_one(tmp_path):
    parts = {"a": m3.Manifold.cube([1, 2, 3]), "b": m3.Manifold.sphere(2, 12)}
    xml = model_xml(parts)
    assert "basematerials" not in xml and "transform" not in xml and "pid" not in xml
    assert len(re.findall(r'<item objectid="\d+"/>', xml)) == 2
    root = _model(write_3mf(parts, tmp_path / "plain.3mf"))
    assert [o.get("id") for o in root.iter(f"{Q}object")] == ["1", "2"]
    with pytest.raises(ValueError):
        write_3mf(parts, tmp_path / "bad.3mf", materials={"c": ("PLA", "#000000")})
    with pytest.raises(ValueError):
        write_3mf(parts, tmp_path / "bad.3mf", materials={"a": ("PLA", "red")})
    assert not (tmp_path / "bad.3mf").exists()


@pytest.mark.skipif(shutil.which("prusa-slicer") is None, reason="prusa-slicer is not installed")
def test_prusaslicer_reads_the_plate(plate):
    parts, layout, path = plate
    run = subprocess.run(["prusa-slicer", "--info", str(path)], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    manifold = re.findall(r"^manifold = (\w+)", run.stdout, re.M)
    assert manifold == ["yes"] * len(parts)
    vols = sorted(float(v) for v in re.findall(r"^volume = ([\d.]+)", run.stdout, re.M))
    assert np.allclose(vols, sorted(s.volume() for s in parts.values()), rtol=1e-4)
    min_z = [float(v) for v in re.findall(r"^min_z = ([-\d.]+)", run.stdout, re.M)]
    assert np.allclose(min_z, 0.0, atol=1e-3)


@pytest.mark.skipif(shutil.which("prusa-slicer") is None, reason="prusa-slicer is not installed")
def test_prusaslicer_applies_a_rotation_the_same_way(tmp_path):
    run = subprocess.run(["prusa-slicer", "--info", str(_turned(tmp_path / "turned.3mf"))],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    got = {k: float(v) for k, v in re.findall(r"^(size_[xyz]|m(?:in|ax)_[xyz]) = ([-\d.]+)",
                                                run.stdout, re.M)}
    assert [got["size_x"], got["size_y"], got["size_z"]] == pytest.approx([20, 10, 30], abs=1e-3)
    assert [got["min_x"], got["min_y"]] == pytest.approx([80, 50], abs=1e-3)
