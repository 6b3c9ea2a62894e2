"""Mounting holes clear of the fingers, and alignment pins on the glue face (docs/export.md).

The gripper's frame is the export's: y up, the rigid base plate on top (its lower face, the
root, at ``root_mm``), the designed finger in z < ``mirror_z`` and its mirror image beyond.

- :func:`mount_holes` places four screw holes, symmetric about the mirror plane, on a rectangle
  of the largest area whose screw heads (and a margin) stay clear of every finger's shadow on
  the plate: a screw and its driver come from below, past the whole finger, not only its root.
- :func:`hole_clearance` is an independent check of a hole set: the volume of a vertical
  keep-out cylinder under each hole that lies inside a finger (0 is free).
- :func:`alignment_pins` picks pin positions in a finger's root section, far apart, with a wall
  around each pocket, and :func:`pin_solids` builds the pins (on the plate) and the pockets (in
  the finger).

Shadows and sections are rasterised at pixel centres after growing the obstacle by half a pixel
diagonal (a square join, which contains the round offset), so a raster distance minus that half
diagonal is a lower bound on the true distance: the placements are conservative.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from dbtool.export._manifold import manifold3d as m3

__all__ = ["alignment_pins", "hole_clearance", "mount_holes", "pin_solids", "root_section",
           "shadow"]

TOL = 0.02  # mm kept beyond every required distance, against float rounding of the checks
DOWN = [-90.0, 0.0, 0.0]  # rotates the frame so that (x, y, z) -> (x, z, -y)


def _xz(solid):
    """The solid turned so that its xz plane is the xy plane (x, z) and y points down."""
    return solid.rotate(DOWN)


def shadow(fingers: list):
    """The union of the fingers' projections onto the xz plane, as a CrossSection in (x, z)."""
    parts = [_xz(f).project() for f in fingers if not f.is_empty()]
    if not parts:
        return m3.CrossSection()
    return m3.CrossSection.batch_boolean(parts, m3.OpType.Add)


def root_section(finger, root_mm: float, below: float = 0.3, depth: float = 0.0,
                 step: float = 0.25):
    """The finger's cross-section ``below`` the root face, in (x, z); with ``depth`` > 0 the
    intersection of the sections from there down by ``depth`` (every ``step`` mm)."""
    turned = _xz(finger)
    ys = [root_mm - below]
    if depth > 0.0:
        n = max(1, math.ceil(depth / step))
        ys = list(root_mm - below - np.linspace(0.0, depth, n + 1))
    sections = [turned.slice(-y) for y in ys]
    out = sections[0]
    for s in sections[1:]:
        out = out ^ s
    return out


def _raster(polys: list, x0: float, nx: int, z0: float, nz: int, res: float) -> np.ndarray:
    """Pixel centres (x0 + i res, z0 + j res) inside the polygons (nonzero winding), (nz, nx)."""
    acc = np.zeros((nz, nx + 1), np.int32)
    for poly in polys:
        p = np.asarray(poly, np.float64)
        if len(p) < 3:
            continue
        a, b = p, np.roll(p, -1, axis=0)
        keep = a[:, 1] != b[:, 1]
        a, b = a[keep], b[keep]
        lo, hi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
        j0 = np.clip(np.ceil((lo - z0) / res), 0, nz).astype(np.int64)
        j1 = np.clip(np.ceil((hi - z0) / res), 0, nz).astype(np.int64)
        n = j1 - j0
        if n.sum() == 0:
            continue
        edge = np.repeat(np.arange(len(a)), n)
        rows = j0[edge] + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        zr = z0 + rows * res
        ae, be = a[edge], b[edge]
        xi = ae[:, 0] + (zr - ae[:, 1]) * (be[:, 0] - ae[:, 0]) / (be[:, 1] - ae[:, 1])
        cols = np.clip(np.floor((xi - x0) / res).astype(np.int64) + 1, 0, nx)
        np.add.at(acc, (rows, cols), np.where(be[:, 1] > ae[:, 1], 1, -1).astype(np.int32))
    return np.cumsum(acc, axis=1)[:, :nx] != 0


def _distance(obstacle: np.ndarray, res: float, grow: float) -> np.ndarray:
    """A lower bound of each pixel centre's distance to the obstacle grown by ``grow``."""
    if not obstacle.any():
        return np.full(obstacle.shape, np.inf)
    return ndimage.distance_transform_edt(~obstacle, sampling=res) - grow


def _avoid_ok(xx: np.ndarray, zz: np.ndarray, avoid, clear: float) -> np.ndarray:
    ok = np.ones(xx.shape, bool)
    for ax, az, ar in avoid:
        ok &= np.hypot(xx - ax, zz - az) >= clear + ar + TOL
    return ok


def mount_holes(fingers: list, plate=(0.0, 0.0, 60.0, 120.0), root_mm: float = 72.5,
                hole: float = 3.4, head: float = 6.0, margin: float = 1.0, edge: float = 5.0,
                avoid=(), mirror_z: float = 60.0, res: float = 0.25) -> dict:
    """Four holes (x1, z1), (x2, z1), (x1, z2), (x2, z2), z2 = 2 mirror_z - z1, on the feasible
    rectangle of the largest area (ties: the larger z spacing, then the smaller x1, z1).

    Feasible: each centre at least ``edge`` inside ``plate`` (x0, z0, x1, z1), at least
    ``head/2 + margin`` (the keep-out) from every finger's shadow on the plate and
    ``keep-out + r`` from each ``avoid`` circle (x, z, r); holes at least ``head`` apart.
    Without such a rectangle: the two holes (x, z1), (x, z2) farthest apart (ties: x nearest
    the plate's middle), ``count`` 2 and a ``note``; with none, ``ok`` False and a ``reason``.
    ``clearance_mm`` is a lower bound of the holes' distance to the shadows (raster at ``res``).
    ``root_mm`` is where the shadows start; the fingers hang below it (docs/export.md).
    """
    del root_mm  # the shadow is the whole finger's; kept for the callers' symmetry
    px0, pz0, px1, pz1 = (float(v) for v in plate)
    keep = 0.5 * head + margin
    grow = res * math.sqrt(0.5)
    pad = keep + 2.0 * res
    ia = math.floor((px0 - pad) / res)
    nx = math.ceil((px1 + pad) / res) - ia + 1
    x0 = ia * res
    half = math.ceil(max(mirror_z - pz0, pz1 - mirror_z, 0.0) / res + pad / res)
    nz, mid = 2 * half + 1, half  # rows mirror_z + (j - mid) res, symmetric about the plane
    z0 = mirror_z - half * res
    cs = shadow(fingers)
    polys = [] if cs.is_empty() else cs.offset(grow, m3.JoinType.Square).to_polygons()
    dist = _distance(_raster(polys, x0, nx, z0, nz, res), res, grow)
    xs, zs = x0 + res * np.arange(nx), z0 + res * np.arange(nz)
    zz, xx = np.meshgrid(zs, xs, indexing="ij")
    ok = dist >= keep + TOL
    ok &= (xx >= px0 + edge - 1e-9) & (xx <= px1 - edge + 1e-9)
    ok &= (zz >= pz0 + edge - 1e-9) & (zz <= pz1 - edge + 1e-9)
    ok &= _avoid_ok(xx, zz, avoid, keep)
    pair = ok[: mid + 1] & ok[::-1][: mid + 1]  # row j and its mirror row 2 mid - j
    gap = 2 * (mid - np.arange(mid + 1))  # z spacing in pixels
    need = math.ceil(head / res - 1e-9)
    out = {"diameter_mm": hole, "keepout_mm": keep, "resolution_mm": res,
           "shadow_mm2": round(cs.area(), 2)}
    best = None
    for j in np.flatnonzero(gap >= need):
        cols = np.flatnonzero(pair[j])
        if len(cols) and cols[-1] - cols[0] >= need:
            key = ((cols[-1] - cols[0]) * gap[j], gap[j], -cols[0])
            if best is None or key > best[0]:
                best = (key, j, cols[0], cols[-1])
    if best is not None:
        _, j, i1, i2 = best
        x1, x2, z1, z2 = xs[i1], xs[i2], zs[j], zs[2 * mid - j]
        holes = [[x1, z1], [x2, z1], [x1, z2], [x2, z2]]
        clear = min(dist[j, i1], dist[j, i2], dist[2 * mid - j, i1], dist[2 * mid - j, i2])
        return out | {"holes": _rounded(holes), "pattern_mm": _rounded([x2 - x1, z2 - z1]),
                      "area_mm2": round(float((x2 - x1) * (z2 - z1)), 3), "count": 4, "ok": True,
                      "clearance_mm": _clear(clear)}
    rows = np.flatnonzero((gap >= need) & pair.any(axis=1))
    if len(rows) == 0:
        return out | {"holes": [], "pattern_mm": [0.0, 0.0], "area_mm2": 0.0, "count": 0,
                      "ok": False, "reason": "no place for two holes symmetric about the mirror "
                      f"plane with a {keep:g} mm keep-out around each clear of the fingers' "
                      f"shadows, {edge:g} mm from the plate's edges"}
    j = rows[0]
    cols = np.flatnonzero(pair[j])
    i = cols[np.lexsort((cols, np.abs(xs[cols] - 0.5 * (px0 + px1))))[0]]
    z1, z2 = zs[j], zs[2 * mid - j]
    return out | {"holes": _rounded([[xs[i], z1], [xs[i], z2]]),
                  "pattern_mm": _rounded([0.0, z2 - z1]), "area_mm2": 0.0, "count": 2,
                  "ok": True, "clearance_mm": _clear(min(dist[j, i], dist[2 * mid - j, i])),
                  "note": "no four-hole rectangle fits; two holes on one line across the "
                  "mirror plane"}


def _rounded(values: list) -> list:
    return [_rounded(v) if isinstance(v, list) else round(float(v), 4) for v in values]


def _clear(d: float) -> float | None:
    return None if not np.isfinite(d) else round(float(d), 3)


def vertical_cylinder(x: float, z: float, radius: float, y_low: float, y_high: float,
                       segments: int, radius_low: float | None = None):
    """A cylinder (or frustum: ``radius_low`` at its bottom) along y from y_low to y_high."""
    low = radius if radius_low is None else radius_low
    c = m3.Manifold.cylinder(y_high - y_low, low, radius, segments)
    return c.rotate(DOWN).translate([x, y_low, z])  # local z -> y, local y -> -z


def hole_clearance(fingers: list, holes: list, radius: float, root_mm: float,
                   depth: float = 200.0, segments: int = 64) -> list[float]:
    """For each hole (x, z): the volume (mm^3) of a vertical cylinder of ``radius`` from
    ``root_mm`` down by ``depth`` inside the union of the fingers; 0 means free.

    The cylinder is the polygon around the circle (circumscribed), so a free hole is free for
    the true circle too (docs/export.md)."""
    body = m3.Manifold.batch_boolean(list(fingers), m3.OpType.Add)
    r = radius / math.cos(math.pi / segments)
    return [float((vertical_cylinder(x, z, r, root_mm - depth, root_mm, segments)
                   ^ body).volume()) for x, z in holes]


def alignment_pins(finger, root_mm: float = 72.5, pin: float = 3.0, clearance: float = 0.2,
                   wall: float = 1.0, avoid=(), count: int = 2, pocket_mm: float = 3.5,
                   res: float = 0.1) -> list[list[float]]:
    """Up to ``count`` pin axes (x, z) in the finger's root section, as far apart as possible.

    Each axis is at least ``pin/2 + clearance + wall`` from the section's outline (holes, such
    as tendon channels, included) over the pocket's depth ``pocket_mm`` plus ``wall`` below its
    floor, at least that plus r from each ``avoid`` circle (x, z, r), and two pockets keep a
    wall between them. Two pins are the section's farthest feasible pair; more are added
    farthest-first; one alone is the deepest point. [] when nothing fits (docs/export.md).
    """
    if count <= 0:
        return []
    need = 0.5 * pin + clearance + wall
    section = root_section(finger, root_mm, depth=pocket_mm + wall - 0.3)
    if section.is_empty():
        return []
    grow = res * math.sqrt(0.5)
    inner = section.offset(-grow, m3.JoinType.Square)
    if inner.is_empty():
        return []
    bx0, bz0, bx1, bz1 = inner.bounds()
    pad = 3.0 * res
    ia, ja = math.floor((bx0 - pad) / res), math.floor((bz0 - pad) / res)
    nx, nz = math.ceil((bx1 + pad) / res) - ia + 1, math.ceil((bz1 + pad) / res) - ja + 1
    inside = _raster(inner.to_polygons(), ia * res, nx, ja * res, nz, res)
    dist = _distance(~inside, res, grow)
    zz, xx = np.meshgrid(ja * res + res * np.arange(nz), ia * res + res * np.arange(nx),
                         indexing="ij")
    ok = (dist >= need + TOL) & _avoid_ok(xx, zz, avoid, need)
    if not ok.any():
        return []
    pts = np.column_stack([xx[ok], zz[ok]])
    deep = dist[ok]
    first = int(np.lexsort((pts[:, 1], pts[:, 0], -deep))[0])
    if count == 1:
        return _rounded([pts[first].tolist()])
    sep = pin + 2.0 * clearance + wall
    i, j = _farthest_pair(pts)
    if np.hypot(*(pts[i] - pts[j])) < sep - 1e-9:
        return _rounded([pts[first].tolist()])
    chosen = sorted([i, j], key=lambda k: (pts[k, 0], pts[k, 1]))
    gap = np.minimum(np.hypot(*(pts - pts[i]).T), np.hypot(*(pts - pts[j]).T))
    while len(chosen) < count:
        k = int(np.argmax(gap))
        if gap[k] < sep - 1e-9:
            break
        chosen.append(k)
        gap = np.minimum(gap, np.hypot(*(pts - pts[k]).T))
    return _rounded([pts[k].tolist() for k in chosen])


def _farthest_pair(pts: np.ndarray) -> tuple[int, int]:
    """Indices of the two points farthest apart (the first such pair in index order)."""
    cand = np.arange(len(pts))
    if len(pts) >= 3:
        try:
            cand = np.unique(ConvexHull(pts, qhull_options="QJ").vertices)
        except QhullError:  # all on a line: the extremes along it
            u = pts @ (pts[-1] - pts[0])
            cand = np.unique([int(np.argmin(u)), int(np.argmax(u))])
    p = pts[cand]
    d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
    a, b = np.unravel_index(int(np.argmax(d)), d.shape)
    return int(cand[a]), int(cand[b])


def pin_solids(pins: list, root_mm: float, pin: float = 3.0, length: float = 3.0,
               clearance: float = 0.2, depth_extra: float = 0.5, segments: int = 32):
    """(pins on the base, pockets in the finger) as Manifolds (empty without pins).

    A pin is a cylinder of diameter ``pin`` from 0.5 mm inside the plate (``root_mm`` + 0.5) down
    to ``root_mm - length``, its tip chamfered by 0.3 mm; a pocket is a cylinder of diameter
    ``pin + 2 clearance`` from ``root_mm`` + 0.01 down to ``root_mm - length - depth_extra``
    (docs/export.md)."""
    if not pins:
        return m3.Manifold(), m3.Manifold()
    r, tip = 0.5 * pin, 0.3 if 0.5 * pin > 0.6 else 0.0
    bottom = root_mm - length
    solids, pockets = [], []
    for x, z in pins:
        body = vertical_cylinder(x, z, r, bottom + tip, root_mm + 0.5, segments)
        if tip:
            body = m3.Manifold.batch_hull(
                [body, vertical_cylinder(x, z, r, bottom, bottom + tip, segments, r - tip)])
        solids.append(body)
        pockets.append(vertical_cylinder(x, z, r + clearance, bottom - depth_extra,
                                          root_mm + 0.01, segments))
    return (m3.Manifold.batch_boolean(solids, m3.OpType.Add),
            m3.Manifold.batch_boolean(pockets, m3.OpType.Add))
