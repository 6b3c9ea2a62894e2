"""The assembly sheet and its drawings (docs/export.md), on a small synthetic gripper."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dbtool.export._manifold import manifold3d as m3
from dbtool.export.reports import sheet as S

HOLES = [[8.0, 8.0], [52.0, 8.0], [8.0, 112.0], [52.0, 112.0]]
CHANNEL_R = 0.75


def _box() -> object:
    """A 40 x 30 x 40 mm finger under the base's lower face (y = 72.5)."""
    return m3.Manifold.cube([40.0, 30.0, 40.0]).translate([5.0, 42.5, 2.0])


def _channelled() -> object:
    """The box with a blind channel along x at y = 57, z = 20, from x = 10 to x = 40."""
    rod = m3.Manifold.cylinder(30.0, CHANNEL_R, circular_segments=24).rotate([0.0, 90.0, 0.0])
    return _box() - rod.translate([10.0, 57.0, 20.0])


def _tendon(finger: str, role: str, z: float, length: float, ok: bool = True) -> dict:
    pts = [[15.0, 57.0, z], [20.0, 57.0, z], [30.0, 57.0, z], [38.0, 57.0, z]]
    return {"finger": finger, "name": f"{finger}-{role}", "role": role,
            "exit": [12.0, 80.0, z], "entry": [12.0, 72.5, z], "points": pts,
            "anchor": pts[-1], "tip": [45.0, 57.0, z], "length_mm": length,
            "clearance_mm": 1.1, "min_bend_radius_mm": 5.0, "ok": ok}


def _sheet(ok: bool = True, slicer_ok: bool = True) -> dict:
    finger = _channelled()
    mirror = finger.mirror([0.0, 0.0, 1.0]).translate([0.0, 0.0, 120.0])
    base = m3.Manifold.cube([60.0, 7.5, 120.0]).translate([0.0, 72.5, 0.0])
    sliced = {"ok": slicer_ok, "layers": 247, "print_time_s": 14228, "filament_g": 24.1,
              "filament_m": 8.29}
    prints = {k: {"down": d, "height_mm": h, "overhang_mm2": 759.5, "file": f"{k}.stl",
                  "slicer": s}
              for k, d, h, s in (("finger", [0, 0, -1], 40.0, sliced),
                                 ("finger_mirror", [0, 0, 1], 40.0, sliced),
                                 ("base", [0, -1, 0], 7.5, None))}
    tpu, pla = ("TPU 95A (soft)", "#E07020"), ("PLA (rigid)", "#808080")
    return {"name": "synthetic", "parts": {"finger": finger, "finger_mirror": mirror,
                                           "base": base},
            "materials": {"finger": tpu, "finger_mirror": tpu, "base": pla}, "print": prints,
            "holes": {"holes": HOLES, "diameter_mm": 3.4, "keepout_mm": 4.0},
            "pins": [[20.0, 15.0], [30.0, 30.0], [20.0, 105.0], [30.0, 90.0]],
            "pin": {"diameter_mm": 3.0, "length_mm": 3.0},
            "tendons": [_tendon("finger", "flexion", 20.0, 61.3, ok),
                        _tendon("finger", "extension", 8.0, 55.04)],
            "hardware": {"line_diameter_mm": 0.5, "tube_od_mm": 2.0, "tube_id_mm": 1.0,
                         "tube_length_mm": 300, "screw": "M3 x 12 socket head",
                         "knot_pocket_mm": 3.0},
            "glue_mm2": 321.0}


def test_assembly_md_lists_parts_lengths_and_steps(tmp_path: Path) -> None:
    sheet = _sheet()
    text = S.write_assembly_md(sheet, tmp_path / "assembly.md").read_text()
    # the line to buy: (61.3 + 300 + 150) + (55.04 + 300 + 150) = 1016.34 -> 1020 mm
    total = math.ceil(sum(t["length_mm"] + 300 + 150 for t in sheet["tendons"]) / 10) * 10
    assert total == 1020
    assert f"| {total} mm |" in text
    assert "| M3 x 12 socket head screw | 4 |" in text
    assert "| 2 × 300 mm |" in text  # PTFE tubes: one per line
    assert "| alignment pins Ø 3.0 × 3.0 mm | 4 | printed on the base" in text
    assert "321.0 mm² per finger" in text
    assert "| finger | `finger.stl` | TPU 95A (soft) | 1 | lying on its side, outer side (-z)" \
        in text
    assert "outer side (+z) down" in text  # the mirror finger lies on its own outer side
    assert "| base | `base.stl` | PLA (rigid) | 1 | lying flat, lower face down |" in text
    assert "3 h 57 min, 247 layers | 24.1 g (8.29 m)" in text
    assert "| finger-flexion | flexion | 61.3 | 511.3 | 1.10 | 5.0 | yes |" in text
    assert "| finger-extension | extension | 55.0 | 505.0 |" in text
    for i, step in enumerate(S.STEPS, 1):
        assert f"### {i}. {step}" in text
    assert "pattern 44.0 × 104.0 mm (dx × dz)" in text
    assert "0.6 mm wire" in text and "double overhand" in text
    assert "WARNING" not in text


@pytest.mark.parametrize(("ok", "slicer_ok", "needle"),
                         [(False, True, "tendon finger-flexion fails its check"),
                          (True, False, "finger.stl (finger) failed the slicer check")])
def test_assembly_md_warns_at_the_top(tmp_path: Path, ok: bool, slicer_ok: bool,
                                      needle: str) -> None:
    text = S.write_assembly_md(_sheet(ok, slicer_ok), tmp_path / "a.md").read_text()
    first = text.split("## Parts list")[0]
    assert "> **WARNING:**" in first and needle in first
    assert text.count("> **WARNING:**") == (1 if not ok else 2)  # both fingers' files


def test_orientation_words() -> None:
    assert S.orientation_words("finger", [0, 1, 0]) == "root face down"
    assert S.orientation_words("finger", [0, -1, 0]) == "fingertip down"
    assert S.orientation_words("finger", [0, 0, 1], side=-1.0).startswith(
        "lying on its side, inner (gripping) side (+z)")
    assert S.orientation_words("base", [0, 1, 0]) == "lying flat, top face down"
    assert S.orientation_words("base", [0.6, 0.8, 0]).startswith("tilted")


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_drawings_are_pngs(tmp_path: Path) -> None:
    sheet = _sheet()
    out = S.draw_exploded(sheet, tmp_path / "exploded.png")
    w, h = _png_size(out)
    assert 600 <= w <= 2000 and 500 <= h <= 2000 and out.stat().st_size > 20_000
    res = S.draw_section(sheet["parts"]["finger"], sheet["tendons"], tmp_path / "section.png")
    w, h = _png_size(tmp_path / "section.png")
    assert 400 <= w <= 2000 and 300 <= h <= 2000
    assert res["plane"] == ("x", pytest.approx(25.75))  # mean x of the first routing points
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exploded.png", "section.png"]


def test_section_shows_the_channel_as_a_hole(tmp_path: Path) -> None:
    tendons = _sheet()["tendons"]
    plain = S.draw_section(_box(), tendons, tmp_path / "plain.png")
    cut = S.draw_section(_channelled(), tendons, tmp_path / "cut.png")
    assert (len(plain["polygons"]), plain["holes"]) == (1, 0)
    assert (len(cut["polygons"]), cut["holes"]) == (2, 1)
    assert plain["area_mm2"] == pytest.approx(30.0 * 40.0, rel=1e-6)
    hole = np.pi * CHANNEL_R**2
    assert plain["area_mm2"] - cut["area_mm2"] == pytest.approx(hole, rel=0.02)
    # the hole is where the channel is: centred on (z, y) = (20, 57)
    inner = next(p for p in cut["polygons"] if S._signed_area(p) < 0)
    assert np.allclose(inner.mean(axis=0), [20.0, 57.0], atol=0.05)
    # a plane past the channel's end cuts solid material only
    beyond = S.draw_section(_channelled(), tendons, tmp_path / "end.png", plane=42.0)
    assert beyond["holes"] == 0 and beyond["plane"] == ("x", 42.0)


def test_writes_are_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import matplotlib.figure

    sheet = _sheet()
    (tmp_path / "assembly.md").write_text("old")

    def broken_text(self, *a, **k):
        Path.write_bytes(self, b"half")
        raise OSError("disk full")

    def broken_png(self, fname, *a, **k):
        Path(fname).write_bytes(b"\x89PNG half")
        raise OSError("disk full")

    monkeypatch.setattr(Path, "write_text", broken_text)
    with pytest.raises(OSError, match="disk full"):
        S.write_assembly_md(sheet, tmp_path / "assembly.md")
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", broken_png)
    with pytest.raises(OSError, match="disk full"):
        S.draw_exploded(sheet, tmp_path / "exploded.png")
    with pytest.raises(OSError, match="disk full"):
        S.draw_section(sheet["parts"]["finger"], sheet["tendons"], tmp_path / "section.png")
    assert [p.name for p in tmp_path.iterdir()] == ["assembly.md"]  # no temp files left
    assert Path.read_text(tmp_path / "assembly.md") == "old"
