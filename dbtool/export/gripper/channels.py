"""Tendon channels a maker can thread (docs/export.md, "Tendon routing"; docs/method.md §8).

Each tendon's centreline runs from the top of the base (where its PTFE tube sits in a seat bored
into the base) straight down to the finger's root face, through the four routing points of
:mod:`dbtool.export.gripper.tendons`, and on from the anchor to the finger's surface, where the
line's knot sits in a pocket. Every corner is rounded to at least the bend radius
(:func:`dbtool.export.gripper.channel_path.fillet`). The wall is measured exactly along the
whole path inside the finger, every 0.5 mm: the distance from the centreline to the surface of
the finger with everything else cut from it (the other channels, the pin pockets; of the glued
root face, all but the channel's own mouth), less the channel's radius. A path that keeps less
than the minimum is re-routed (the straightest run within 2.5 mm of the largest moment arm, then
the deepest routing points, then a straight run from the root face to the deepest route's
anchor); if no route keeps it, the tendon is reported as failing with where and by how much.
"""

from __future__ import annotations

import numpy as np

from dbtool.export._manifold import manifold3d as m3
from dbtool.export.config import ExportConfig
from dbtool.export.geometry.voxels import Voxels
from dbtool.export.gripper.channel_path import SurfaceDistance, fillet, wall_along
from dbtool.export.gripper.tendons import ROLES, Tendon, root_entry, routing_points

STEP = 0.5  # mm between the wall's samples along a path
ROUTES = ("moment", "straight", "depth", "direct")  # routing preferences tried in turn
TIP_MAX = 20.0  # mm: a straight run past the anchor longer than this turns to a shorter exit
SEAT_WALL = 0.4  # mm of the base between two tube seats, at least
LEAD = 1.0  # share of the first bend's tangent run kept straight below the root face


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-12)


def _pocket(d: np.ndarray, tip: np.ndarray, radius: float, top: float, bottom: float):
    """A cylinder of ``radius`` on the axis through ``tip`` along the outward ``d``, from
    ``bottom`` below the surface up to ``top`` (negative: below it too)."""
    c = m3.Manifold.cylinder(bottom - top, radius, radius, 32)
    return along_axis(c, d).translate(list(tip - d * bottom))


def _pocket_fits(finger, tip: np.ndarray, d: np.ndarray, radius: float, depth: float,
                 wall: float) -> bool:
    """The pocket with ``wall`` of material around it and under it lies inside the finger
    (from 0.3 mm below the mouth on): no thin lip at its rim."""
    probe = _pocket(d, tip, radius + wall, 0.3, depth + wall)
    return (probe - finger).volume() <= 1e-3 * probe.volume()


def tip_exit(finger, before: np.ndarray, anchor: np.ndarray, cfg: ExportConfig,
             side: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Where the line leaves the finger past its anchor, and its knot pocket (square to the
    surface, with the minimum wall around it). In order: straight on along the last run (no
    bend to thread; unless that runs longer than ``TIP_MAX``) with the full pocket, then with
    pockets 0.5 mm narrower down to 2 mm; then the shortest way out along -y, +-x or the
    tendon's own side (``side``: +-1 along z, never across the other tendon) that has room for
    the bend and the full pocket; else straight on with no pocket (the knot sits on the
    surface). Returns the mouth (mm), the surface's outward normal there and the pocket's
    diameter (0: none)."""
    ahead = _unit(anchor - before)
    dirs = [ahead] + [np.array(d, float) for d in
                      ((0, -1, 0), (1, 0, 0), (-1, 0, 0), (0, 0, side))]
    run = float(np.linalg.norm(anchor - before))
    found = []
    for k, d in enumerate(dirs):
        hits = finger.ray_cast(anchor.tolist(), (anchor + 200.0 * d).tolist())
        if not hits:
            continue
        dist = hits[0].distance * 200.0
        # a turn needs room for its bend: tangent lengths R tan(turn / 2) on both sides
        turn = np.arccos(np.clip(float(np.dot(d, ahead)), -1.0, 1.0))
        if k and cfg.bend_radius * np.tan(turn / 2) > min(dist - cfg.knot_depth, 0.5 * run):
            continue
        if k == 0 and dist > TIP_MAX:
            continue
        found.append((k == 0, dist, anchor + dist * d, _unit(np.asarray(hits[0].normal, float))))
    if not found:
        return anchor + 5.0 * ahead, ahead, 0.0
    straight = [f for f in found if f[0]]
    sizes = np.arange(cfg.knot_pocket, min(2.0, cfg.knot_pocket) - 1e-9, -0.5)
    for _, _, tip, n in straight:
        for dia in sizes:
            if _pocket_fits(finger, tip, n, 0.5 * dia, cfg.knot_depth, cfg.min_wall):
                return tip, n, float(dia)
    for _, _, tip, n in sorted((f for f in found if not f[0]), key=lambda f: f[1]):
        if _pocket_fits(finger, tip, n, 0.5 * cfg.knot_pocket, cfg.knot_depth, cfg.min_wall):
            return tip, n, cfg.knot_pocket
    _, _, tip, n = straight[0] if straight else min(found, key=lambda f: f[1])
    return tip, n, 0.0


def plan(vox: Voxels, depth: np.ndarray, regions: dict, finger, cfg: ExportConfig,
         finger_name: str, top_mm: float, root_mm: float, side_sign: dict[int, float],
         prefer: str = "moment") -> list[Tendon]:
    """The tendons of one finger for one routing preference (no wall check yet). ``direct``
    takes the deepest route's anchor and runs straight to it from the root face, the routing
    points spread over the run's second half (no bend between them)."""
    # half a voxel of margin for the fillets
    need = cfg.channel_radius + cfg.min_wall + 0.5 * vox.pitch
    routes = routing_points(vox, depth, regions, need, side_sign,
                            "depth" if prefer == "direct" else prefer,
                            sep=2 * cfg.channel_radius + cfg.min_wall + vox.pitch)
    out, entries, runs = [], [], []
    # entries keep two channels and a wall apart, and two tube seats 0.4 mm (the seats are in
    # the rigid base; a narrow root has no room for more)
    sep = max(2 * cfg.channel_radius + cfg.min_wall + 0.5, 2 * cfg.seat_radius + SEAT_WALL)
    for g, (pts, depths, ok) in routes.items():
        target = pts[-1] if prefer == "direct" else pts[0]
        x, z = root_entry(vox, depth, root_mm, target, need, entries, sep, runs)
        entries.append((x, z))
        entry = np.array([x, root_mm, z])
        runs.append((entry, np.asarray(target, float)))
        if prefer == "direct":
            pts = entry + np.array([0.55, 0.7, 0.85, 1.0])[:, None] * (pts[-1] - entry)
            depths = vox.depth_at(pts, depth).tolist()
            ok = bool(min(depths) >= need - 0.5 * vox.pitch)
            before = entry
        else:
            before = pts[-2]
        tip, normal, pocket = tip_exit(finger, before, pts[-1], cfg, side_sign[g])
        # the channel goes straight down through the glued root face and bends only below it,
        # so that it leaves the face square with its wall all round
        turn = np.arccos(np.clip(-_unit(pts[0] - entry)[1], -1.0, 1.0))
        drop = min(LEAD * cfg.bend_radius * np.tan(turn / 2),
                   0.5 * (root_mm - pts[0][1]))
        lead = (entry - [0.0, drop, 0.0]).round(3).tolist() if turn > np.radians(1) else []
        t = Tendon(finger_name, f"{finger_name}-{ROLES.get(g, f'group{g}')}",
                   ROLES.get(g, f"group {g}"), int(g), pts.round(3).tolist(),
                   pts[-1].round(3).tolist(), [round(x, 3), top_mm, round(z, 3)],
                   entry=[round(x, 3), root_mm, round(z, 3)], lead=lead,
                   tip=tip.round(3).tolist(),
                   tip_normal=normal.round(4).tolist(), pocket_mm=pocket,
                   depth_mm=[round(v, 3) for v in depths], route=prefer, ok=ok)
        out.append(t)
    return out


def _root_face(root_mm: float):
    def exclude(centroids: np.ndarray, normals: np.ndarray) -> np.ndarray:
        return (np.abs(centroids[:, 1] - root_mm) < 1e-3) & (normals[:, 1] > 0.99)
    return exclude


def _to_glue_face(pts: np.ndarray, root_mm: float, entry: list, mouth: float) -> np.ndarray:
    """Distance (mm) from points inside the finger to its glued root face (y = ``root_mm``,
    taken to cover the finger's section) outside the channel's mouth, the disk of radius
    ``mouth`` around the entry where the channel goes through the face on purpose."""
    h = root_mm - pts[:, 1]
    rho = np.hypot(pts[:, 0] - entry[0], pts[:, 2] - entry[2])
    return np.where(rho >= mouth, h, np.hypot(h, mouth - rho))


def check(tendons: list[Tendon], finger, cfg: ExportConfig, root_mm: float,
          pockets=None) -> None:
    """Measure each tendon's bends and its wall along the whole path inside the finger (every
    ``STEP`` mm from the root face to the anchor) and set ``clearance_mm``, ``ok`` and
    ``failures``."""
    tubes = {id(t): finger_cut(t, cfg, root_mm) for t in tendons}
    for t in tendons:
        others = [tubes[id(o)] for o in tendons if o is not t]
        if pockets is not None and not pockets.is_empty():
            others.append(pockets)
        solid = finger - m3.Manifold.batch_boolean(others, m3.OpType.Add) if others else finger
        path = fillet(t.corners(), cfg.bend_radius)
        samples = path.sample(STEP)
        # inside the finger: below the root face, up to the anchor (past it, the line leaves
        # the finger on purpose through the knot pocket)
        k_anchor = int(np.argmin(np.linalg.norm(samples - np.array(t.anchor), axis=1)))
        inside = np.arange(len(samples)) <= k_anchor
        inside &= samples[:, 1] <= root_mm - 1e-6
        pts = samples[inside]
        # the glued root face counts as surface too, but for the channel's own mouth
        mouth = cfg.channel_radius + cfg.min_wall + 1.0
        wall = wall_along(pts, SurfaceDistance(solid, exclude=_root_face(root_mm)),
                          cfg.channel_radius)
        wall = np.minimum(wall, _to_glue_face(pts, root_mm, t.entry, mouth) - cfg.channel_radius)
        finite = path.radii[np.isfinite(path.radii)]
        t.bend_radii_mm = [round(float(r), 3) for r in finite]
        t.min_bend_radius_mm = round(float(finite.min()), 3) if len(finite) else None
        t.clearance_mm = round(float(wall.min()), 3) if len(wall) else 0.0
        t.wall_samples = int(len(wall))
        t.length_mm = round(path.length(), 2)
        failures = []
        thin = wall < cfg.min_wall - 1e-6
        if thin.any():
            ys = pts[thin, 1]
            failures.append(f"wall {wall.min():.2f} mm (< {cfg.min_wall:g}) along "
                            f"{thin.sum() * STEP:.1f} of {len(wall) * STEP:.1f} mm, "
                            f"y {ys.min():.1f}-{ys.max():.1f} mm")
        if len(finite) and finite.min() < cfg.bend_radius - 1e-6:
            failures.append(f"bend radius {finite.min():.2f} mm (< {cfg.bend_radius:g}): the "
                            "routing points are too close for the bend")
        t.failures = failures
        t.ok = not failures


def route_finger(finger, regions: dict, cfg: ExportConfig, finger_name: str, top_mm: float,
                 root_mm: float, side_sign: dict[int, float], voxels: Voxels | None = None,
                 pockets=None) -> list[Tendon]:
    """Plan, check and, where the wall is too thin, re-route the tendons of one finger."""
    vox = voxels or Voxels.of(finger, cfg.pitch)
    depth = vox.depth()
    best: dict[int, Tendon] = {}
    current: list[Tendon] = []
    for prefer in ROUTES:
        trial = plan(vox, depth, regions, finger, cfg, finger_name, top_mm, root_mm, side_sign,
                     prefer)
        # keep the tendons that already pass; try the new route for the others
        mixed = [best[t.group] if t.group in best and best[t.group].ok else t for t in trial]
        check(mixed, finger, cfg, root_mm, pockets)
        for t in mixed:
            old = best.get(t.group)
            if old is None or (not old.ok and t.clearance_mm > old.clearance_mm) or t.ok:
                best[t.group] = t
        current = [best[g] for g in sorted(best)]
        if all(t.ok for t in current):
            break
    check(current, finger, cfg, root_mm, pockets)  # the final set, measured together
    if all(t.ok for t in current):
        return current
    for prefer in ROUTES:  # tendons from different routes may crowd each other: one route each
        trial = plan(vox, depth, regions, finger, cfg, finger_name, top_mm, root_mm, side_sign,
                     prefer)
        check(trial, finger, cfg, root_mm, pockets)
        if all(t.ok for t in trial):
            return trial
    return current


def tube(path: np.ndarray, radius: float, segments: int = 16):
    """A tube of ``radius`` along a polyline: hulls of consecutive balls, each capsule's balls
    turned differently so that no two share vertices (an STL reader would weld them)."""
    pieces = []
    for k, (a, b) in enumerate(zip(path[:-1], path[1:], strict=True)):
        if np.linalg.norm(b - a) < 1e-9:
            continue
        ball = m3.Manifold.sphere(radius, segments).rotate([23.0 * k + 7.0, 37.0 * k + 11.0,
                                                            0.0])
        pieces.append(m3.Manifold.batch_hull([ball.translate(list(a)), ball.translate(list(b))]))
    return m3.Manifold.batch_boolean(pieces, m3.OpType.Add)


def centreline(t: Tendon, cfg: ExportConfig) -> np.ndarray:
    """The filleted centreline, from 2 radii above the base's top to 1 mm past the surface."""
    c = t.corners()
    c[0] = c[0] + [0.0, 2 * cfg.seat_radius, 0.0]
    c[-1] = c[-1] + _unit(c[-1] - c[-2]) * 1.0
    return fillet(c, cfg.bend_radius).as_polyline()


def finger_cut(t: Tendon, cfg: ExportConfig, root_mm: float):
    """What is cut from the finger for ``t``: the line's channel and the knot pocket."""
    line = tube(centreline(t, cfg), cfg.channel_radius)
    # the pocket is a counterbore square to the surface, so its rim is a clean edge (a pocket
    # along an oblique line would leave a feather edge where it breaks out)
    tip = np.array(t.tip)
    d = _unit(np.array(t.tip_normal, float))
    if t.pocket_mm:
        pocket = _pocket(d, tip, 0.5 * t.pocket_mm, -1.0, cfg.knot_depth)
    else:  # no room for a knot pocket: a shallow counterbore still squares the mouth
        pocket = _pocket(d, tip, cfg.channel_radius + 0.5, -1.0, 1.0)
    return line + pocket


def base_cut(t: Tendon, cfg: ExportConfig, top_mm: float, root_mm: float):
    """What is cut from the base for ``t``: the tube's seat from the top down to 1.5 mm above
    the root face (a shoulder the tube stops on) and the line's channel through the rest."""
    line = tube(centreline(t, cfg), cfg.channel_radius)
    r = cfg.seat_radius
    depth = top_mm - root_mm - 1.5
    seat = m3.Manifold.cylinder(depth + 1.0, r, r, 32).rotate([-90.0, 0.0, 0.0])
    seat = seat.translate([t.exit[0], top_mm - depth, t.exit[2]])
    return line + seat


def along_axis(solid, d: np.ndarray):
    """Turn a solid built along +z so that +z points along ``d``."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s, c = np.linalg.norm(axis), float(np.dot(z, d))
    if s < 1e-9:
        return solid if c > 0 else solid.mirror([0.0, 0.0, 1.0])
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    rot = np.eye(3) + s * kx + (1 - c) * kx @ kx
    return solid.transform(np.hstack([rot, np.zeros((3, 1))]).tolist())
