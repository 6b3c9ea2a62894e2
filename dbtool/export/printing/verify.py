"""A maker's checks of a gripper export folder, from its files alone
(docs/export-checks.md).

Reads the part STLs (in their print orientation), ``report.json`` (each part's print pose) and
``tendons.json``, turns the parts back into the gripper's frame, and checks with booleans of its
own rather than the exporter's measurements:

- every part is one watertight volume as an STL reader sees it (trimesh, vertices welded);
- every part rests on the bed (min z = 0) in its print pose, the base lying flat;
- no mounting hole is covered: a vertical cylinder of the screw head's keep-out around each
  hole's axis holds no finger material;
- the wall along every channel: a tube of radius channel radius + minimum wall (less 0.05 mm)
  around the centreline inside the finger (root face to anchor) lies within the finger with its
  own channel filled (only at the channel's mouth may it cross the glued root face);
- every bend of every channel's centreline has at least the bend radius;
- every tendon ends in a through-hole at the fingertip (a probe just inside the mouth finds no
  material) and, where the report says so, in a knot pocket;
- optionally, PrusaSlicer slices every part clean with the flexible-filament profile.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dbtool.export._manifold import manifold3d as m3
from dbtool.export.gripper.channel_path import fillet
from dbtool.export.gripper.channels import along_axis

PROBE = 0.05  # mm: radius of the probe balls
WALL_SLACK = 0.05  # mm: the tubes' polygons against the exact wall


def load_part(folder: Path, name: str, rep: dict):
    """A part's STL as a manifold in the gripper's frame (its print pose undone)."""
    import trimesh

    mesh = trimesh.load(folder / f"{name}.stl", process=True)
    pose = rep["parts"][name].get("print_pose")
    if pose is not None:
        mesh.apply_transform(np.linalg.inv(np.array(pose["matrix"], float)))
    return m3.Manifold(m3.Mesh(vert_properties=np.asarray(mesh.vertices, np.float32),
                               tri_verts=np.asarray(mesh.faces, np.uint32)))


def _stl_ok(path: Path) -> dict:
    import trimesh

    mesh = trimesh.load(path, process=True)
    return {"watertight": bool(mesh.is_watertight and mesh.is_volume),
            "bodies": len(mesh.split(only_watertight=False)),
            "min_z": float(mesh.bounds[0, 2]), "height_mm": float(np.ptp(mesh.bounds[:, 2]))}


def _capsules(path: np.ndarray, radius: float, segments: int = 24):
    ball = m3.Manifold.sphere(radius, segments)
    pieces = [m3.Manifold.batch_hull([ball.translate(list(a)), ball.translate(list(b))])
              for a, b in zip(path[:-1], path[1:], strict=True) if np.linalg.norm(b - a) > 1e-9]
    return m3.Manifold.batch_boolean(pieces, m3.OpType.Add)


def _empty(solid, at: np.ndarray) -> bool:
    """No material of ``solid`` within ``PROBE`` of ``at``."""
    ball = m3.Manifold.sphere(PROBE, 12).translate(list(at))
    return (ball ^ solid).volume() < 1e-9


def tendon_wall(finger, t: dict, tj: dict, root: float) -> dict:
    """Does a tube of channel radius + wall around ``t``'s path inside the finger stay in it?"""
    r, wall = 0.5 * tj["channel_diameter_mm"], tj["min_wall_mm"]
    down = t.get("lead") or t["entry"]
    corners = np.array([t["exit"], down, *t["points"], t["tip"]], float)
    path = fillet(corners, tj["bend_radius_mm"])
    radii = path.radii[np.isfinite(path.radii)]
    bend_ok = bool(np.all(radii >= tj["bend_radius_mm"] - 1e-6))
    line = path.as_polyline(step=0.5)
    k = int(np.argmin(np.linalg.norm(line - np.array(t["anchor"]), axis=1)))
    inner = line[: k + 1]
    inner = inner[inner[:, 1] <= root + r + wall]
    own = _capsules(line, r + 0.02)  # the tendon's own channel and knot pocket, filled back
    n = np.asarray(t["tip_normal"] or list(corners[-1] - corners[-2]), float)
    n = n / np.linalg.norm(n)
    pocket = t.get("pocket_mm", 0.0)
    if pocket:
        depth = tj["knot_depth_mm"]
        cyl = m3.Manifold.cylinder(depth + 1.02, 0.5 * pocket + 0.02, 0.5 * pocket + 0.02, 48)
        own = own + along_axis(cyl, n).translate(list(np.array(t["tip"]) - n * (depth + 0.02)))
    # the channel goes through the glued root face at its mouth (channel radius + wall + 1 mm
    # around the entry); elsewhere the root face is surface like any other
    mouth = r + wall + 1.0
    gate = m3.Manifold.cylinder(10.0, mouth, mouth, 64).rotate([-90.0, 0.0, 0.0])
    gate = gate.translate([t["entry"][0], root, t["entry"][2]])
    thick = _capsules(inner, r + wall - WALL_SLACK).trim_by_plane([0.0, -1.0, 0.0], -root - 5.0)
    outside = (thick - (finger + own + gate)).volume()
    mouth = np.array(t["tip"]) - 0.3 * n
    side = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    in_pocket = np.array(t["tip"]) - 1.0 * n + 0.35 * pocket * side
    return {"name": t["name"], "outside_mm3": round(float(outside), 4),
            "wall_ok": bool(outside < 1e-3), "bend_ok": bend_ok,
            "min_bend_mm": round(float(radii.min()), 3) if len(radii) else None,
            "through_hole": _empty(finger, mouth),
            "pocket_mm": pocket, "pocket_open": bool(pocket == 0 or _empty(finger, in_pocket))}


def verify_export(folder: Path, slice_flex: bool = False) -> dict:
    """Every check above on one gripper export folder; ``ok`` when all pass."""
    folder = Path(folder)
    rep = json.loads((folder / "report.json").read_text())
    tj = json.loads((folder / "tendons.json").read_text())
    names = ("finger", "finger_mirror", "base")
    out: dict = {"parts": {n: _stl_ok(folder / f"{n}.stl") for n in names}}
    parts = {n: load_part(folder, n, rep) for n in names}
    root = float(tj["tendons"][0]["entry"][1])  # the base's lower face: the fingers' roots
    m = rep["mounting"]
    keep = m["keepout_mm"]
    fingers = parts["finger"] + parts["finger_mirror"]
    covered = []
    for x, z in m["holes"]:
        cyl = m3.Manifold.cylinder(200.0, keep, keep, 64).rotate([90.0, 0.0, 0.0])
        covered.append(float((cyl.translate([x, root, z]) ^ fingers).volume()))
    out["holes"] = {"count": len(m["holes"]), "covered_mm3": covered,
                    "clear": all(v < 1e-6 for v in covered)}
    out["tendons"] = [tendon_wall(parts[t["finger"]], t, tj, root) for t in tj["tendons"]]
    out["oriented"] = all(abs(p["min_z"]) < 1e-3 for p in out["parts"].values())
    out["base_flat"] = out["parts"]["base"]["height_mm"] <= (
        rep["parts"]["base"]["bbox_mm"][1] + 1e-3) and out["parts"]["base"]["height_mm"] < 15.0
    if slice_flex:
        from dbtool.export.printing.slicer import slice_part

        out["slicer_flex"] = {n: slice_part(folder / f"{n}.stl", "flex").as_json()
                              for n in names}
    sl = rep.get("slicer", {})
    out["slicer"] = {k: v["ok"] for k, v in sl.items() if isinstance(v, dict)}
    out["ok"] = bool(
        all(p["watertight"] and p["bodies"] == 1 for p in out["parts"].values())
        and out["holes"]["clear"] and out["oriented"] and out["base_flat"]
        and all(t["wall_ok"] and t["bend_ok"] and t["through_hole"] and t["pocket_open"]
                for t in out["tendons"])
        and all(out["slicer"].values())
        and all(v["ok"] for v in out.get("slicer_flex", {}).values()))
    return out
