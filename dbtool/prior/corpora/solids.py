"""Solid primitives of the procedural corpora, built with manifold3d (z-up; docs/method.md §1)."""

from __future__ import annotations

import math

import numpy as np
import trimesh
from manifold3d import CrossSection, Manifold

SEG = 24  # circular segments of spheres and cylinders


def box(sx: float, sy: float, sz: float, at=(0.0, 0.0, 0.0)) -> Manifold:
    return Manifold.cube([sx, sy, sz], center=True).translate(list(at))


def ball(r: float, at=(0.0, 0.0, 0.0), scale=(1.0, 1.0, 1.0)) -> Manifold:
    return Manifold.sphere(r, SEG).scale(list(scale)).translate(list(at))


def rod(a, b, r: float, r_end: float | None = None) -> Manifold:
    """Cylinder (or frustum) from point ``a`` to point ``b``."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    h = float(np.linalg.norm(d))
    cyl = Manifold.cylinder(h, r, r if r_end is None else r_end, SEG)
    # rotate +z onto d: polar angle about y, then azimuth about z
    theta = math.degrees(math.acos(max(-1.0, min(1.0, d[2] / h))))
    phi = math.degrees(math.atan2(d[1], d[0]))
    return cyl.rotate([0.0, theta, 0.0]).rotate([0.0, 0.0, phi]).translate(a.tolist())


def union(parts: list[Manifold]) -> Manifold:
    out = parts[0]
    for p in parts[1:]:
        out = out + p
    return out


def extrude(poly: np.ndarray, h: float) -> Manifold:
    """Extrude a 2D polygon (xy, either winding) by ``h`` along z, centred on z = 0."""
    x, y = poly[:, 0], poly[:, 1]
    if np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)) < 0:  # clockwise: flip
        poly = poly[::-1]
    return Manifold.extrude(CrossSection([poly]), h).translate([0.0, 0.0, -h / 2])


def to_trimesh(solid: Manifold) -> trimesh.Trimesh:
    mesh = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3],
                           np.asarray(mesh.tri_verts), process=False)


def normalise(points: np.ndarray, reference: np.ndarray | None = None) -> np.ndarray:
    """Centre on the bounding box of ``reference`` (default: the points) and scale its largest
    side to 1."""
    ref = points if reference is None else reference
    lo, hi = ref.min(0), ref.max(0)
    return (points - (lo + hi) / 2) / max(float((hi - lo).max()), 1e-9)


def polyline(points, r: float) -> list[Manifold]:
    """Rods of radius ``r`` between consecutive points, with a ball at every point."""
    pts = [np.asarray(p, float) for p in points]
    return [rod(a, b, r) for a, b in zip(pts[:-1], pts[1:], strict=True)] + [
        ball(r, at=tuple(p)) for p in pts]
