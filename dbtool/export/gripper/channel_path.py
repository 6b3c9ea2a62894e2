"""Tendon channel paths: filleted polylines and exact wall distances (docs/export.md, "Tendon
routing").

A tendon channel runs as a polyline (mm) from where it enters the finger to its anchor. For a
line to be threaded, every bend needs a minimum radius: :func:`fillet` replaces each corner by a
circular arc tangent to both segments. The wall around the channel must keep a minimum along the
whole path: :class:`SurfaceDistance` gives the exact unsigned distance from points to a triangle
mesh's surface (not a voxel estimate), and :func:`wall_along` subtracts the channel radius.
Pure numpy/scipy.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

STRAIGHT_DEG = 0.5  # corners turning less than this keep their (tiny) kink, no arc
CHORD_ERROR_MM = 0.02  # as_polyline: largest gap between an arc and its chords
SLIVER_SIN2 = 1e-8  # triangles with sin(angle at a)^2 below this take the careful path

__all__ = ["FilletedPath", "SurfaceDistance", "closest_on_triangles", "fillet",
           "polyline_length", "wall_along"]


def polyline_length(points: np.ndarray) -> float:
    """Sum of the segment lengths of a polyline (k, 3)."""
    p = np.asarray(points, np.float64)
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0


# --- filleted paths ---------------------------------------------------------------------------


@dataclass
class _Piece:
    """A straight run a -> b, or an arc ``c + r (cos s u + sin s v)``, s in [0, angle]."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray | None = None
    u: np.ndarray | None = None
    v: np.ndarray | None = None
    r: float = 0.0
    angle: float = 0.0

    @property
    def length(self) -> float:
        return self.r * self.angle if self.c is not None else float(np.linalg.norm(self.b - self.a))

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points and unit tangents at fractions ``t`` (k,) of the piece."""
        t = np.asarray(t, np.float64)[:, None]
        if self.c is None:
            d = self.b - self.a
            n = np.linalg.norm(d)
            tan = np.broadcast_to(d / n if n > 0 else d, (len(t), 3))
            return self.a + t * d, np.array(tan)
        s = t * self.angle
        cos, sin = np.cos(s), np.sin(s)
        pts = self.c + self.r * (cos * self.u + sin * self.v)
        return pts, -sin * self.u + cos * self.v


@dataclass
class FilletedPath:
    """A polyline whose corners are rounded by circular arcs (see :func:`fillet`).

    ``corners`` are the input points (consecutive repeats dropped); ``radii``, ``turn_deg`` and
    ``centres`` have one entry per interior corner: the achieved arc radius (inf where the corner
    turns less than 0.5 degrees and stays as it is, 0 for a full reversal), the corner's turn, and
    the arc's centre (nan without an arc).
    """

    corners: np.ndarray
    radii: np.ndarray
    turn_deg: np.ndarray
    centres: np.ndarray
    pieces: list[_Piece] = field(default_factory=list, repr=False)

    @property
    def min_radius(self) -> float:
        """The smallest achieved radius over the corners; inf if none."""
        return float(self.radii.min()) if len(self.radii) else math.inf

    def length(self) -> float:
        """Exact length: the straight parts plus the arcs."""
        return float(sum(p.length for p in self.pieces))

    def _walk(self, step: float | None, chord: float | None) -> tuple[np.ndarray, np.ndarray]:
        if step is not None and step <= 0:
            raise ValueError("step must be positive")
        pts, tans = [self.corners[:1]], []
        first_tan = None
        for p in self.pieces:
            length = p.length
            if length <= 1e-9:  # a straight run a fillet used up, left over by rounding
                continue
            n = 1
            if step is not None:
                n = max(n, math.ceil(length / step - 1e-12))
            if chord is not None and p.c is not None and p.r > chord:
                n = max(n, math.ceil(p.angle / (2.0 * math.acos(1.0 - chord / p.r)) - 1e-12))
            elif chord is not None and p.c is not None:
                n = max(n, math.ceil(p.angle / (math.pi / 8)))
            x, t = p.at(np.arange(1, n + 1) / n)
            if first_tan is None:
                first_tan = p.at(np.zeros(1))[1]
            pts.append(x)
            tans.append(t)
        if first_tan is None:  # a single point
            return self.corners[:1].copy(), np.zeros((1, 3))
        # the last point of each piece is exactly where the next starts: pin the end point
        out = np.concatenate(pts)
        out[-1] = self.corners[-1]
        return out, np.concatenate([first_tan] + tans)

    def sample(self, step: float = 0.5) -> np.ndarray:
        """Points (k, 3) along the path, both ends included, at most ``step`` apart (along the
        path, hence also in a straight line)."""
        return self._walk(step, None)[0]

    def tangents(self, step: float = 0.5) -> np.ndarray:
        """Unit tangents (k, 3) at the points of :meth:`sample` with the same ``step``."""
        return self._walk(step, None)[1]

    def as_polyline(self, step: float | None = None,
                    chord_error: float = CHORD_ERROR_MM) -> np.ndarray:
        """A polyline for cutting: each arc split so that no chord strays more than
        ``chord_error`` (mm) from it; with ``step``, no point farther than that from the next."""
        return self._walk(step, chord_error)[0]


def _unit(d: np.ndarray) -> tuple[np.ndarray, float]:
    n = float(np.linalg.norm(d))
    return (d / n if n > 0 else d), n


def fillet(points: np.ndarray, radius: float) -> FilletedPath:
    """Round every interior corner of a polyline (k, 3) by an arc of ``radius`` tangent to both
    segments.

    A corner turning by θ needs a tangent length ``r tan(θ/2)`` on each of its segments. A
    segment gives at most half its length to each of its ends' corners (the first and the last
    segment their full length, as their other end is no corner); where that is too short the
    corner gets the largest radius that fits, and ``radii`` reports it. Corners turning less
    than 0.5 degrees stay as they are (radius inf).
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    if len(p) == 0:
        raise ValueError("a path needs at least one point")
    if radius < 0:
        raise ValueError("radius must be non-negative")
    keep = np.r_[True, np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-12]
    p = p[keep]
    k = len(p)
    seg = np.diff(p, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    dirs = seg / np.maximum(seg_len, 1e-300)[:, None]
    n_corner = max(k - 2, 0)
    radii = np.full(n_corner, math.inf)
    turn = np.zeros(n_corner)
    centres = np.full((n_corner, 3), np.nan)
    pieces: list[_Piece] = []
    start = p[0]
    for i in range(1, k - 1):
        d0, d1 = dirs[i - 1], dirs[i]
        cos_t = float(np.clip(d0 @ d1, -1.0, 1.0))
        theta = math.acos(cos_t)
        turn[i - 1] = math.degrees(theta)
        if turn[i - 1] < STRAIGHT_DEG:  # the corner stays: the path still passes through it
            pieces.append(_Piece(start, p[i]))
            start = p[i]
            continue
        room_in = seg_len[i - 1] * (1.0 if i == 1 else 0.5)
        room_out = seg_len[i] * (1.0 if i == k - 2 else 0.5)
        half_tan = math.tan(theta / 2.0)
        r = radius
        if r * half_tan > min(room_in, room_out):
            r = min(room_in, room_out) / half_tan
        n, n_len = _unit(d1 - cos_t * d0)  # in the plane of the corner, toward its inside
        if r <= 0 or n_len < 1e-12:  # no room, or a full reversal: a sharp corner
            radii[i - 1] = 0.0
            pieces.append(_Piece(start, p[i]))
            start = p[i]
            continue
        t = r * half_tan
        a = p[i] - t * d0
        c = a + r * n
        arc = _Piece(a, a, c=c, u=-n, v=d0, r=r, angle=theta)
        arc.b = arc.at(np.ones(1))[0][0]
        pieces += [_Piece(start, a), arc]
        radii[i - 1], centres[i - 1] = r, c
        start = arc.b
    if k > 1:
        pieces.append(_Piece(start, p[-1]))
    return FilletedPath(p, radii, turn, centres, pieces)


# --- exact distance to a triangle surface -------------------------------------------------------


def _safe_div(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    ok = den != 0
    return np.where(ok, num / np.where(ok, den, 1.0), 0.0)


def _closest_on_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(_safe_div(np.einsum("ij,ij->i", p - a, ab), np.einsum("ij,ij->i", ab, ab)), 0, 1)
    return a + t[:, None] * ab


def _closest_on_slivers(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                        c: np.ndarray) -> np.ndarray:
    cand = [_closest_on_segments(p, a, b), _closest_on_segments(p, b, c),
            _closest_on_segments(p, c, a)]
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    foot = p - _safe_div(np.einsum("ij,ij->i", p - a, n), nn)[:, None] * n
    inside = nn > 0
    for s, e in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(e - s, foot - s), n) >= 0
    cand.append(np.where(inside[:, None], foot, cand[0]))
    cand = np.stack(cand)
    best = np.argmin(np.linalg.norm(cand - p, axis=2), axis=0)
    return cand[best, np.arange(len(p))]


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                         c: np.ndarray) -> np.ndarray:
    """Closest points (k, 3) on triangles (a[i], b[i], c[i]) to points p[i]: Ericson's
    region test (Real-Time Collision Detection §5.1.5), vectorised. Slivers (an angle's sine
    below 1e-4) and degenerate triangles take the plane's foot where it falls inside, else
    the nearest of their three edges."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    v_in, w_in = _safe_div(vb, denom), _safe_div(vc, denom)
    out = a + v_in[:, None] * ab + w_in[:, None] * ac  # inside the face
    # the regions, tested last to first so that the first test that holds wins
    e_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    w = _safe_div(d4 - d3, (d4 - d3) + (d5 - d6))
    out = np.where(e_bc[:, None], b + w[:, None] * (c - b), out)
    e_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    out = np.where(e_ac[:, None], a + _safe_div(d2, d2 - d6)[:, None] * ac, out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, out)
    e_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    out = np.where(e_ab[:, None], a + _safe_div(d1, d1 - d3)[:, None] * ab, out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, out)
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, out)
    # slivers: the cancellation in va, vb, vc swamps the barycentric coordinates; take the
    # plane's foot if it lies inside (signs from cross products), else the nearest edge
    scale = np.maximum(np.einsum("ij,ij->i", ab, ab), np.einsum("ij,ij->i", ac, ac))
    flat = denom <= SLIVER_SIN2 * scale * scale
    if flat.any():
        out[flat] = _closest_on_slivers(p[flat], a[flat], b[flat], c[flat])
    return out


class SurfaceDistance:
    """Exact unsigned distance from points to a triangle mesh's surface.

    ``solid`` is a manifold3d Manifold or a ``(verts, tris)`` pair. ``exclude(centroids,
    normals) -> bool mask`` drops triangles from the surface (e.g. a face glued to another
    part). Triangles are grouped by size (the largest distance from their centroid to a
    vertex, R); each group has a k-d tree on its centroids. A point's distance is bounded
    above by the exact distance to the triangles of its nearest centroids, U; a triangle that
    could be closer has its centroid within U + R of the point, so only those are measured
    exactly.
    """

    def __init__(self, solid, exclude: Callable[[np.ndarray, np.ndarray], np.ndarray] | None
                 = None, neighbours: int = 8, max_pairs: int = 2_000_000):
        if isinstance(solid, tuple):
            verts, tris = solid
        else:
            from dbtool.export._manifold import mesh_arrays

            verts, tris = mesh_arrays(solid, double=True)
        verts = np.asarray(verts, np.float64)
        tris = np.asarray(tris, np.int64).reshape(-1, 3)
        a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
        centroids = (a + b + c) / 3.0
        if exclude is not None:
            normals = np.cross(b - a, c - a)
            length = np.linalg.norm(normals, axis=1, keepdims=True)
            normals = np.where(length > 0, normals / np.where(length > 0, length, 1.0), 0.0)
            keep = ~np.asarray(exclude(centroids, normals), bool)
            a, b, c, centroids = a[keep], b[keep], c[keep], centroids[keep]
            self.kept = np.flatnonzero(keep)
        else:
            self.kept = np.arange(len(tris))
        if len(a) == 0:
            raise ValueError("no triangles left to measure against")
        self.a, self.b, self.c, self.centroids = a, b, c, centroids
        rad = np.sqrt(np.max([np.einsum("ij,ij->i", x - centroids, x - centroids)
                              for x in (a, b, c)], axis=0))
        self.max_radius = float(rad.max())
        self._tree = cKDTree(centroids)
        self._k = min(neighbours, len(a))
        self._max_pairs = max_pairs
        size = np.abs(np.asarray(verts)).max() if len(verts) else 1.0
        self._eps = 1e-9 * max(size, 1.0)
        # size classes by powers of two of R: a few trees, each queried with its own R
        cls = np.floor(np.log2(np.maximum(rad, 1e-12 * max(size, 1.0)))).astype(np.int64)
        self._groups: list[tuple[float, np.ndarray, cKDTree]] = []
        for value in np.unique(cls):
            ids = np.flatnonzero(cls == value)
            self._groups.append((float(rad[ids].max()), ids, cKDTree(centroids[ids])))

    def _exact(self, pts: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = closest_on_triangles(pts, self.a[tri], self.b[tri], self.c[tri])
        return np.linalg.norm(q - pts, axis=1), q

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distances (k,), closest surface points (k, 3), and the index of the closest
        triangle (k,) in the input mesh's numbering."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        m = len(p)
        if m == 0:
            return np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64)
        _, near = self._tree.query(p, k=self._k)
        near = np.asarray(near).reshape(m, -1)
        rows = np.repeat(np.arange(m), near.shape[1])
        d, q = self._exact(p[rows], near.ravel())
        best_d = np.full(m, np.inf)
        best_q = np.zeros((m, 3))
        best_t = np.zeros(m, np.int64)
        self._update(rows, near.ravel(), d, q, best_d, best_q, best_t)
        upper = best_d.copy()
        for r_max, ids, tree in self._groups:
            lists = tree.query_ball_point(p, upper + r_max + self._eps, return_sorted=False)
            counts = np.fromiter((len(x) for x in lists), np.int64, m)
            if counts.sum() == 0:
                continue
            rows = np.repeat(np.arange(m), counts)
            cand = ids[np.concatenate([np.asarray(x, np.int64) for x in lists if len(x)])]
            for s in range(0, len(rows), self._max_pairs):
                r_s, t_s = rows[s:s + self._max_pairs], cand[s:s + self._max_pairs]
                d, q = self._exact(p[r_s], t_s)
                self._update(r_s, t_s, d, q, best_d, best_q, best_t)
        return best_d, best_q, self.kept[best_t]

    @staticmethod
    def _update(rows, tri, d, q, best_d, best_q, best_t) -> None:
        order = np.lexsort((d, rows))
        r_sorted = rows[order]
        first = order[np.r_[True, r_sorted[1:] != r_sorted[:-1]]]
        better = d[first] < best_d[rows[first]]
        sel, at = first[better], rows[first[better]]
        best_d[at], best_q[at], best_t[at] = d[sel], q[sel], tri[sel]

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Exact unsigned distance (k,) from each point to the surface."""
        return self.query(points)[0]

    def closest(self, points: np.ndarray) -> np.ndarray:
        """The closest surface point (k, 3) to each point."""
        return self.query(points)[1]


def wall_along(path_samples: np.ndarray, surface: SurfaceDistance, radius: float) -> np.ndarray:
    """Wall (k,) around a channel of ``radius`` at each sample of its centre line: the distance
    from the sample to the surface less the radius. Meaningful for samples inside the part
    (the distance is unsigned)."""
    return surface.distance(path_samples) - float(radius)
