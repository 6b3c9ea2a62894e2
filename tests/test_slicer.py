"""Printability by a real slicer, PrusaSlicer (docs/export.md): clean parts slice with plausible
numbers, a holed mesh fails with a reason, an overhang gets supports, a missing slicer is a clear
error. Tests that run the slicer skip when it is not installed."""

import os
import re
import stat
import subprocess

import numpy as np
import pytest

from dbtool.errors import RunError
from dbtool.export._manifold import manifold3d as m3
from dbtool.export.geometry.mesh import write_stl
from dbtool.export.printing import slicer

SKIP_REASON = "PrusaSlicer not installed: apt-get install prusa-slicer"
CUBE_MM = 20.0
CYL_H = 10.0


@pytest.fixture(scope="module")
def prusa():
    """The slicer's path, or a skip."""
    found = slicer.find_slicer()
    if found is None:
        pytest.skip(SKIP_REASON)
    return found


@pytest.fixture(scope="module")
def parts(tmp_path_factory):
    """STL files: a 20 mm cube, a cylinder, a T (a wide plate on a thin stem), a holed sphere."""
    import trimesh

    d = tmp_path_factory.mktemp("slicer")
    stem = m3.Manifold.cube([4.0, 4.0, 15.0]).translate([13.0, 13.0, 0.0])
    plate = m3.Manifold.cube([30.0, 30.0, 3.0]).translate([0.0, 0.0, 14.5])
    out = {
        "cube": write_stl(m3.Manifold.cube([CUBE_MM] * 3), d / "cube.stl"),
        "cylinder": write_stl(m3.Manifold.cylinder(CYL_H, 8.0, circular_segments=64),
                              d / "cylinder.stl"),
        "tee": write_stl(stem + plate, d / "tee.stl"),
    }
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    sphere.apply_translation([0.0, 0.0, 10.0])
    keep = np.ones(len(sphere.faces), bool)
    keep[np.random.default_rng(0).choice(len(keep), 50, replace=False)] = False
    sphere.update_faces(keep)
    sphere.export(d / "holed.stl")
    out["holed"] = d / "holed.stl"
    return out


@pytest.fixture(scope="module")
def results(prusa, parts):
    """Every part sliced with both profiles."""
    return {(name, mat): slicer.slice_part(path, mat, slicer=prusa)
            for name, path in parts.items() for mat in ("flex", "pla")}


# -- without a slicer ----------------------------------------------------------------------

def _script(path, body: str):
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return str(path)


def test_a_missing_slicer_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv(slicer.ENV_VAR, str(tmp_path / "no-such-slicer"))
    assert slicer.find_slicer() is None
    with pytest.raises(slicer.SlicerMissing, match="prusa-slicer") as err:
        slicer.slice_part(tmp_path / "x.stl")
    assert isinstance(err.value, RunError)  # the command line prints it as one error line
    assert "$DBTOOL_SLICER" in str(err.value)
    (tmp_path / "not-executable").write_text("")
    monkeypatch.setenv(slicer.ENV_VAR, str(tmp_path / "not-executable"))
    assert slicer.find_slicer() is None
    fake = _script(tmp_path / "fake-slicer", "exit 0")
    monkeypatch.setenv(slicer.ENV_VAR, fake)
    assert slicer.find_slicer() == str((tmp_path / "fake-slicer").resolve())


def test_a_failing_or_hanging_slicer_is_not_ok(tmp_path):
    fail = _script(tmp_path / "fail", "echo 'Loading of a model file failed.' >&2; exit 3")
    res = slicer.slice_part(tmp_path / "x.stl", slicer=fail)
    assert not res.ok and res.messages == ["--info exited with 3: Loading of a model file failed."]
    hang = _script(tmp_path / "hang", "exec sleep 30")
    res = slicer.slice_part(tmp_path / "x.stl", slicer=hang, timeout=0.5)
    assert not res.ok and res.messages == ["--info timed out after 0.5 s"]
    assert res.seconds < 5


def test_profiles_are_0_2_mm_with_automatic_supports(tmp_path):
    for mat, kind, density in (("flex", "FLEX", 1.21), ("pla", "PLA", 1.24)):
        text = slicer.write_profile(mat, tmp_path / f"{mat}.ini").read_text()
        keys = dict(re.findall(r"^(\w+) = (.*)$", text, re.M))
        assert keys["filament_type"] == kind and float(keys["filament_density"]) == density
        assert float(keys["layer_height"]) == float(keys["first_layer_height"]) == 0.2
        assert keys["support_material"] == keys["support_material_auto"] == "1"
        assert keys["bed_shape"] == "0x0,250x0,250x210,0x210"
        assert float(keys["max_print_height"]) == 210
    flex, pla = slicer.PROFILES["flex"], slicer.PROFILES["pla"]
    assert flex["filament_max_volumetric_speed"] < pla["filament_max_volumetric_speed"]
    with pytest.raises(ValueError, match="unknown material"):
        slicer.write_profile("abs", tmp_path / "abs.ini")


def test_readers_of_slicer_output():
    assert slicer.parse_time("1h 20m 37s") == 4837
    assert slicer.parse_time("1d 0h 0m 5s") == 86405
    info = slicer.parse_info("[2026-01-01] [0x1] [trace]   Initializing StaticPrintConfigs\n"
                             "[a.stl]\nsize_x = 20.5\nmanifold = no\nopen_edges = 36\n"
                             "number_of_parts =  2\n")
    assert info == {"size_x": 20.5, "manifold": "no", "open_edges": 36, "number_of_parts": 2}
    # absolute E with a reset, a retraction and its undoing (E only: not extrusion)
    absolute = ("M82\n;TYPE:Perimeter\nG1 X1 Y1 E1.0\nG1 E0.2 F2400\nG1 E1.0\n"
                "G1 X2 E1.5 ; comment\nG92 E0\n;TYPE:Support material\nG1 X3 Y3 E0.25\n"
                "G1 X4 E0.75\n;TYPE:Support material interface\nG1 Y5 E1.0\n")
    assert slicer.extrusion_by_type(absolute) == pytest.approx(
        {"Perimeter": 1.5, "Support material": 0.75, "Support material interface": 0.25})
    relative = "M83\n;TYPE:Support material\nG1 E-0.8\nG1 E0.8\nG1 X1 Y1 E0.3\nG1 X2 E0.2\n"
    assert slicer.extrusion_by_type(relative) == pytest.approx({"Support material": 0.5})


# -- with PrusaSlicer ----------------------------------------------------------------------

@pytest.mark.parametrize("mat", ["flex", "pla"])
def test_clean_parts_slice_with_plausible_numbers(results, mat):
    cube, cyl = results["cube", mat], results["cylinder", mat]
    for res in (cube, cyl):
        assert res.ok and res.messages == [] and res.material == mat
        assert res.info["manifold"] == "yes" and res.info["number_of_parts"] == 1
        assert res.print_time_s > 0 and res.filament_mm > 0 and res.support_mm == 0
        density = slicer.PROFILES[mat]["filament_density"]
        assert res.filament_g == pytest.approx(res.filament_cm3 * density, abs=0.02)
    assert abs(cube.layers - CUBE_MM / 0.2) <= 1 and abs(cyl.layers - CYL_H / 0.2) <= 1
    volume_cm3 = CUBE_MM**3 / 1000
    assert 0.5 * volume_cm3 <= cube.filament_cm3 <= 1.1 * volume_cm3
    assert cube.name == "cube" and cube.as_json()["layers"] == cube.layers


def test_a_holed_mesh_is_not_printable(results):
    for mat in ("flex", "pla"):
        res = results["holed", mat]
        assert not res.ok and res.info["manifold"] == "no" and res.info["open_edges"] > 0
        assert any("open_edges" in m for m in res.messages)


def test_an_overhang_is_printed_on_supports(results):
    for mat in ("flex", "pla"):
        tee = results["tee", mat]
        assert tee.ok and tee.messages == []
        assert tee.support_mm > 0.05 * tee.filament_mm
        assert results["cube", mat].support_mm == 0


@pytest.mark.parametrize("mat", ["flex", "pla"])
def test_the_gcode_reader_adds_up_to_the_slicers_total(prusa, parts, tmp_path, mat):
    """Relative E (flex) and absolute E (pla) both sum to the slicer's own filament total."""
    ini = slicer.write_profile(mat, tmp_path / "p.ini")
    out = tmp_path / "tee.gcode"
    subprocess.run([prusa, "--export-gcode", "--loglevel", "1", "--load", str(ini),
                    "--output", str(out), str(parts["tee"])], check=True, capture_output=True)
    gcode = out.read_text()
    assert ("M83" if mat == "flex" else "M82") in gcode
    total = float(re.search(r"; filament used \[mm\] = ([\d.]+)", gcode).group(1))
    by_type = slicer.extrusion_by_type(gcode)
    assert sum(by_type.values()) == pytest.approx(total, rel=2e-3)
    assert by_type["Support material"] > 0


def test_slice_parts_uses_each_parts_material_and_keeps_no_gcode(prusa, parts, tmp_path):
    out = slicer.slice_parts({"finger": parts["cylinder"], "base": parts["cube"]},
                             {"base": "pla"}, slicer=prusa, workdir=tmp_path)
    assert [(k, r.material, r.ok, r.layers) for k, r in out.items()] == [
        ("finger", "flex", True, 50), ("base", "pla", True, 100)]
    assert os.listdir(tmp_path) == []
