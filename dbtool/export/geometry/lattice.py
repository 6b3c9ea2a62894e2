"""Beams and nodes of the Voronoi lattice foam as manifold3d meshes (used by
:mod:`dbtool.export.geometry.infill`; docs/method.md §8).

The interface: :class:`Lattice` (``Lattice.build``), :func:`foam_pieces`, and the geometry
helpers :func:`frames`, :func:`segment_distance`, :func:`sample_segments` and ``EPS``.
:func:`foam_pieces` turns the foam's graph (Voronoi vertices as nodes, the edges between them as
beams, built into a :class:`Lattice`) into watertight pieces:

1. Each beam is a prism of ``segments`` facets whose width across flats is ``beam`` (no section
   is thinner); each Voronoi vertex a node, the convex hull of its beams' end rings, set far
   enough out (``beam/2 cot(angle/2)``) that every ring is a face of the hull and a plane
   separates any two of its beams.
2. Where that holds and nothing else comes near, the ring face is cut out and the beam's side
   walls are stitched to it, so most of the foam is one mesh built from numpy arrays, with no
   boolean at all.
3. The rest (tangled joints, pieces near the skin) are closed pieces that reach into their
   neighbours; a greedy colouring of their conflict graph (exact capsule / ball distances)
   splits them into groups of disjoint pieces, one manifold each, for the caller to unite with
   ``Manifold.batch_boolean`` (hundreds of thousands of small overlapping unions would take far
   longer).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dbtool.export._manifold import from_arrays, mesh_arrays
from dbtool.export._manifold import manifold3d as m3

EPS = 1e-3  # mm: pieces closer than this are treated as touching (united, never composed)


# --------------------------------------------------------------------------- lattice geometry


def frames(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors p, q with (p, q, u) a right-handed orthonormal frame, per row of u."""
    h = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    p = np.cross(u, h)
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return p, np.cross(u, p)


def segment_distance(p1, q1, p2, q2) -> np.ndarray:
    """Distance between segments [p1, q1] and [p2, q2], row by row (Ericson's closest points;
    a zero-length segment is a point)."""
    d1, d2, w = q1 - p1, q2 - p2, p1 - p2
    a, e = (d1 * d1).sum(1), (d2 * d2).sum(1)
    b, c, f = (d1 * d2).sum(1), (d1 * w).sum(1), (d2 * w).sum(1)
    sa, se = np.maximum(a, 1e-18), np.maximum(e, 1e-18)
    den = a * e - b * b
    s = np.where(den > 1e-12 * np.maximum(a * e, 1e-18), (b * f - c * e) / np.maximum(den, 1e-30),
                 0.0)
    s = np.clip(s, 0.0, 1.0)
    t = (b * s + f) / se
    s = np.where(t < 0.0, np.clip(-c / sa, 0.0, 1.0),
                 np.where(t > 1.0, np.clip((b - c) / sa, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    s = np.where(a < 1e-18, 0.0, s)
    t = np.where(e < 1e-18, 0.0, np.where(a < 1e-18, np.clip(f / se, 0.0, 1.0), t))
    return np.linalg.norm(p1 + d1 * s[:, None] - p2 - d2 * t[:, None], axis=1)


def sample_segments(p0: np.ndarray, p1: np.ndarray, step: float):
    """Points at most ``step`` apart along each segment, ends included; (points, owner)."""
    n = np.ceil(np.linalg.norm(p1 - p0, axis=1) / step).astype(int) + 1
    owner = np.repeat(np.arange(len(p0)), n)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n)
    t = k / np.repeat(np.maximum(n - 1, 1), n)
    return p0[owner] + (p1 - p0)[owner] * t[:, None], owner


@dataclass
class Lattice:
    """Beams (edges e of nodes) as prisms of circumradius ``big_r`` (so the flat-to-flat width is
    the beam diameter) and nodes as convex hulls of the beams' end rings.

    Half-edge ``h = 2 * edge + end`` starts at node ``he_node[h]`` along ``he_dir[h]``; its ring
    (``seg`` points, counter-clockwise about the edge direction) lies ``t[h]`` from the node.
    Points: ring point k of half-edge h is ``h * seg + k``, then 6 small octahedron points per
    node (so every hull is solid), then each beam's own end rings (radius ``0.9 big_r``,
    ``delta`` inside the node hull) used where a beam is united with its node by a boolean.
    """

    nodes: np.ndarray  # (nn, 3)
    e: np.ndarray  # (ne, 2)
    seg: int
    big_r: float
    delta: float
    t: np.ndarray  # (2 ne,) ring distance per half-edge
    he_node: np.ndarray
    he_dir: np.ndarray
    points: np.ndarray  # (2 ne seg + 6 nn + 2 ne seg, 3)
    node_ids: list  # per node: its hull's input point ids
    seg_a: np.ndarray  # beam capsules (radius big_r): from ... (ne, 3)
    seg_b: np.ndarray  # ... to (ne, 3), delta inside the hulls
    rho: np.ndarray  # (nn,) node hull bounding radius about the node
    ext: np.ndarray  # (2 ne,) how far node he_node[h]'s hull reaches along he_dir[h]

    @property
    def own_base(self) -> int:
        return 2 * len(self.e) * self.seg + 6 * len(self.nodes)

    @classmethod
    def build(cls, nodes: np.ndarray, e: np.ndarray, r: float, seg: int) -> Lattice:
        big_r = r / math.cos(math.pi / seg)
        delta = 0.3 * r
        nn, ne = len(nodes), len(e)
        a, b = nodes[e[:, 0]], nodes[e[:, 1]]
        length = np.linalg.norm(b - a, axis=1)
        u = (b - a) / length[:, None]
        p, q = frames(u)
        he_node = e.ravel()
        he_dir = np.stack([u, -u], 1).reshape(-1, 3)
        # ring distance: beyond t = big_r cot(angle / 2) (every pair of beams at the node) the
        # rings are faces of the hull and a bisecting plane separates any two of its beams
        deg = np.bincount(he_node, minlength=nn)
        order = np.argsort(he_node, kind="stable")
        first = np.cumsum(deg) - deg
        slot = np.empty(2 * ne, int)
        slot[order] = np.arange(2 * ne) - np.repeat(first, deg)
        md = int(deg.max())
        dirs = np.zeros((nn, md, 3))
        dirs[he_node, slot] = he_dir
        has = np.zeros((nn, md), bool)
        has[he_node, slot] = True
        cos = np.clip(np.einsum("nik,njk->nij", dirs, dirs), -1.0, 1.0)
        pair = has[:, :, None] & has[:, None, :] & ~np.eye(md, dtype=bool)
        half = 0.5 * np.arccos(np.where(pair, cos, -1.0))  # angle / 2 in (0, pi / 2]
        cot = np.cos(half) / np.maximum(np.sin(half), 1e-6)
        t_node = 1.05 * big_r * np.maximum(cot.max((1, 2)), 0.6) + delta
        t = np.minimum(t_node[he_node], 0.45 * np.repeat(length, 2))
        ph = 2 * np.pi * np.arange(seg) / seg
        circle = np.cos(ph)[None, :, None] * p[:, None] + np.sin(ph)[None, :, None] * q[:, None]
        he_circle = np.repeat(circle, 2, axis=0)  # (2 ne, seg, 3)
        centre = nodes[he_node] + t[:, None] * he_dir
        rings = centre[:, None] + big_r * he_circle
        octa = 0.5 * big_r * np.vstack([np.eye(3), -np.eye(3)])
        own_c = centre - delta * he_dir
        own = own_c[:, None] + 0.9 * big_r * he_circle
        points = np.concatenate([rings.reshape(-1, 3), (nodes[:, None] + octa).reshape(-1, 3),
                                 own.reshape(-1, 3)])
        # per node: ring ids of its half-edges (slot order) then its octahedron
        hs = np.full((nn, md), -1)
        hs[he_node, slot] = np.arange(2 * ne)
        node_ids = []
        octa_base = 2 * ne * seg
        ks = np.arange(seg)
        for i in range(nn):
            h = hs[i, :deg[i]]
            node_ids.append(np.concatenate([(h[:, None] * seg + ks).ravel(),
                                            octa_base + 6 * i + np.arange(6)]))
        # bounding radius and reach along each of the node's beams
        rel = np.zeros((nn, md * seg + 6, 3))
        valid = np.zeros((nn, md * seg + 6), bool)
        rel[:, md * seg:] = octa
        valid[:, md * seg:] = True
        rr = (rings - nodes[he_node][:, None]).reshape(-1, 3)
        pos = (slot[:, None] * seg + ks).ravel()
        rel[np.repeat(he_node, seg), pos] = rr
        valid[np.repeat(he_node, seg), pos] = True
        rho = np.sqrt(np.where(valid, (rel * rel).sum(2), 0.0).max(1))
        ext = np.empty(2 * ne)
        for s in range(md):
            sel = np.flatnonzero(deg > s)
            proj = np.einsum("nmk,nk->nm", rel[sel], dirs[sel, s])
            ext_s = np.where(valid[sel], proj, -np.inf).max(1)
            ext[hs[sel, s]] = ext_s
        seg_a = own_c[0::2]
        seg_b = own_c[1::2]
        return cls(nodes, e, seg, big_r, delta, t, he_node, he_dir, points, node_ids, seg_a,
                   seg_b, rho, ext)


def _hulls(lat: Lattice) -> tuple[list, np.ndarray, dict]:
    """Each node's convex hull as triangles of point ids, which half-edge rings are exact hull
    faces (the hull triangles with all corners on the ring tile the ring polygon, facing out), and
    the hulls whose vertices could not be matched to point ids (kept as manifolds)."""
    seg, ne = lat.seg, len(lat.e)
    tris, bad = [], {}
    for i, ids in enumerate(lat.node_ids):
        pts = lat.points[ids]
        hull = m3.Manifold.hull_points(pts)
        vo, hull_tris = mesh_arrays(hull, double=True)
        eq = (vo[:, None, :] == pts[None]).all(2)
        if not eq.any(1).all():  # pragma: no cover - a hull vertex that is not an input point
            bad[i] = hull
            tris.append(np.zeros((0, 3), np.int64))
            continue
        tris.append(ids[eq.argmax(1)][np.asarray(hull_tris, np.int64)])
    label = np.full(len(lat.points), -1)
    label[:2 * ne * seg] = np.repeat(np.arange(2 * ne), seg)
    allt = np.concatenate(tris)
    lt = label[allt]
    face = (lt[:, 0] >= 0) & (lt[:, 0] == lt[:, 1]) & (lt[:, 1] == lt[:, 2])
    ft, fh = allt[face], lt[face, 0]
    x = lat.points[ft]
    n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    norm = np.linalg.norm(n, axis=1)
    outward = (n * lat.he_dir[fh]).sum(1) > (1 - 1e-6) * norm
    count = np.bincount(fh, minlength=2 * ne)
    area = np.bincount(fh, 0.5 * norm, minlength=2 * ne)
    wrong = np.bincount(fh, ~outward, minlength=2 * ne)
    hexagon = 0.5 * seg * lat.big_r**2 * math.sin(2 * math.pi / seg)
    ring_ok = (count == seg - 2) & (wrong == 0) & (np.abs(area - hexagon) <= 1e-6 * hexagon)
    ring_ok[np.isin(lat.he_node, list(bad))] = False
    return tris, ring_ok, bad


def _conflicts(lat: Lattice, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of pieces (nodes 0..nn-1, then beams) that may overlap: (accidental, designed).

    Designed: a node and its own beams (they overlap by construction, or are stitched).
    Accidental: anything else whose bounding balls (nodes) / capsules (beams) come closer than
    EPS, unless a plane separates them: two beams of one node beyond ``big_r cot(angle / 2)``
    (the bisecting plane), two neighbouring nodes whose hulls end before meeting."""
    from scipy.spatial import cKDTree

    nodes, rho, big_r = lat.nodes, lat.rho, lat.big_r
    sa, sb, e = lat.seg_a, lat.seg_b, lat.e
    nn, ne = len(nodes), len(e)
    pts, owner = sample_segments(sa, sb, step)
    tree = cKDTree(pts)
    acc = []
    # beam - beam: the nearest samples lie within step of the closest points
    pr = tree.query_pairs(2 * big_r + step + EPS, output_type="ndarray")
    pr = np.unique(np.sort(owner[pr], 1), axis=0)
    pr = pr[pr[:, 0] != pr[:, 1]]
    close = (segment_distance(sa[pr[:, 0]], sb[pr[:, 0]], sa[pr[:, 1]], sb[pr[:, 1]])
             < 2 * big_r + EPS)
    pr = pr[close]
    sep = np.zeros(len(pr), bool)
    for i_end in (0, 1):
        for j_end in (0, 1):
            shared = e[pr[:, 0], i_end] == e[pr[:, 1], j_end]
            hi, hj = 2 * pr[shared, 0] + i_end, 2 * pr[shared, 1] + j_end
            cos = np.clip((lat.he_dir[hi] * lat.he_dir[hj]).sum(1), -1.0, 1.0)
            half = 0.5 * np.arccos(cos)
            need = big_r * np.cos(half) / np.maximum(np.sin(half), 1e-9) + EPS
            sep[shared] = (lat.t[hi] - lat.delta > need) & (lat.t[hj] - lat.delta > need)
    acc.append(pr[~sep] + nn)
    # node - beam (not its own)
    hits = tree.query_ball_point(nodes, rho + big_r + 0.5 * step + EPS)
    cnt = np.fromiter((len(h) for h in hits), int, nn)
    ns = np.stack([np.repeat(np.arange(nn), cnt),
                   owner[np.fromiter((s for h in hits for s in h), int, int(cnt.sum()))]], 1)
    ns = np.unique(ns, axis=0)
    ns = ns[(e[ns[:, 1], 0] != ns[:, 0]) & (e[ns[:, 1], 1] != ns[:, 0])]
    d = segment_distance(nodes[ns[:, 0]], nodes[ns[:, 0]], sa[ns[:, 1]], sb[ns[:, 1]])
    ns = ns[d < rho[ns[:, 0]] + big_r + EPS]
    acc.append(np.stack([ns[:, 0], ns[:, 1] + nn], 1))
    # node - node: a conflicting pair is found from the node with the larger ball
    hits = cKDTree(nodes).query_ball_point(nodes, 2 * rho + EPS)
    cnt = np.fromiter((len(h) for h in hits), int, nn)
    nd = np.stack([np.repeat(np.arange(nn), cnt),
                   np.fromiter((s for h in hits for s in h), int, int(cnt.sum()))], 1)
    nd = np.unique(np.sort(nd, 1), axis=0)
    nd = nd[nd[:, 0] != nd[:, 1]]
    d = np.linalg.norm(nodes[nd[:, 0]] - nodes[nd[:, 1]], axis=1)
    nd = nd[d < rho[nd[:, 0]] + rho[nd[:, 1]] + EPS]
    # neighbours (one beam apart) are apart if their hulls end before meeting along the beam
    key = e[:, 0] * nn + e[:, 1]
    k = nd[:, 0] * nn + nd[:, 1]
    srt = np.argsort(key)
    pos = np.clip(np.searchsorted(key[srt], k), 0, ne - 1)
    edge = srt[pos]
    nb = key[edge] == k
    length = np.linalg.norm(nodes[e[edge, 1]] - nodes[e[edge, 0]], axis=1)
    apart = nb & (lat.ext[2 * edge] + lat.ext[2 * edge + 1] < length - EPS)
    acc.append(nd[~apart])
    designed = np.stack([np.concatenate([e[:, 0], e[:, 1]]),
                         np.tile(np.arange(ne), 2) + nn], 1)
    return np.concatenate(acc), designed


def _colour(n: int, pairs: np.ndarray) -> np.ndarray:
    """Greedy colouring (in index order) so that no conflicting pair shares a colour."""
    from scipy.sparse import coo_matrix

    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    g = (g + g.T).tocsr()
    indptr, indices = g.indptr.tolist(), g.indices.tolist()
    col = [-1] * n
    for i in range(n):
        taken = {col[j] for j in indices[indptr[i]:indptr[i + 1]]}
        c = 0
        while c in taken:
            c += 1
        col[i] = c
    return np.asarray(col, int)


def _beam_triangles(lat: Lattice, beams: np.ndarray, stitched: np.ndarray) -> np.ndarray:
    """Point-id triangles of the given beams: side walls between the end rings (the node's ring
    where that end is stitched, else the beam's own ring, closed by a cap), outward facing."""
    seg = lat.seg
    if len(beams) == 0:
        return np.zeros((0, 3), np.int64)
    ks = np.arange(seg)
    ring = np.empty((len(beams), 2, seg), np.int64)
    for end in (0, 1):
        h = 2 * beams + end
        node_ring = h[:, None] * seg + ks
        own_ring = lat.own_base + h[:, None] * seg + ks
        ring[:, end] = np.where(stitched[h][:, None], node_ring, own_ring)
    s, f = ring[:, 0], ring[:, 1]
    j = (ks + 1) % seg
    side = np.concatenate([np.stack([s[:, ks], s[:, j], f[:, j]], 2),
                           np.stack([s[:, ks], f[:, j], f[:, ks]], 2)], 1).reshape(-1, 3)
    out = [side]
    fan = np.arange(1, seg - 1)
    for end in (0, 1):
        capped = np.flatnonzero(~stitched[2 * beams + end])
        if len(capped) == 0:
            continue
        rr = ring[capped, end]
        if end == 0:  # faces -u: clockwise about u
            cap = np.stack([rr[:, np.zeros_like(fan)], rr[:, fan + 1], rr[:, fan]], 2)
        else:
            cap = np.stack([rr[:, np.zeros_like(fan)], rr[:, fan], rr[:, fan + 1]], 2)
        out.append(cap.reshape(-1, 3))
    return np.concatenate(out)


def _manifold(points: np.ndarray, tris: np.ndarray):
    """A manifold from point-id triangles (closed, non-overlapping pieces), or None."""
    if len(tris) == 0:
        return None
    used, inv = np.unique(tris, return_inverse=True)
    out = from_arrays(points[used], inv.reshape(-1, 3))
    if out.status() != m3.Error.NoError:  # pragma: no cover - a construction bug
        raise RuntimeError(f"infill: lattice pieces do not form a manifold ({out.status()})")
    return out


# --------------------------------------------------------------------------- the pieces


def foam_pieces(lat: Lattice, node_safe: np.ndarray, beam_safe: np.ndarray,
            step: float) -> tuple[object | None, dict[bool, list], np.ndarray]:
    """The foam as manifolds: (stitched, groups, beam_ok).

    ``stitched`` (None if empty) is one mesh of the node hulls whose rings are all faces and the
    beams whose ends replace those faces, built without booleans; ``beam_ok`` says which beams
    are in it. Every other piece is in one of ``groups[safe]``, each a manifold of disjoint
    pieces (a greedy colouring of the conflict graph, beams sampled ``step`` apart), with
    ``safe`` from ``node_safe`` / ``beam_safe`` (pieces that stay inside the part; the others
    are to be clipped by it)."""
    seg = lat.seg
    nn, ne = len(lat.nodes), len(lat.e)
    tris, ring_ok, bad = _hulls(lat)
    accidental, designed = _conflicts(lat, step)
    tangled = np.zeros(nn + ne, bool)
    tangled[accidental.ravel()] = True
    node_ok = node_safe & ~tangled[:nn]
    node_ok[lat.he_node[~ring_ok]] = False
    beam_ok = beam_safe & ~tangled[nn:]
    stitched = beam_ok[np.repeat(np.arange(ne), 2)] & node_ok[lat.he_node]  # per half-edge
    label = np.full(len(lat.points), -1)
    label[:2 * ne * seg] = np.repeat(np.arange(2 * ne), seg)
    hull_tris = []
    for i in np.flatnonzero(node_ok):
        lt = label[tris[i]]
        cut = (lt[:, 0] >= 0) & (lt[:, 0] == lt[:, 1]) & (lt[:, 1] == lt[:, 2])
        cut[cut] = stitched[lt[cut, 0]]
        hull_tris.append(tris[i][~cut])
    beam_tris = _beam_triangles(lat, np.flatnonzero(beam_ok), stitched)
    stitched_mesh = _manifold(lat.points, np.concatenate([*hull_tris, beam_tris]))

    loose = np.concatenate([~node_ok, ~beam_ok])
    index = np.cumsum(loose) - 1
    pairs = np.concatenate([accidental, designed])
    pairs = index[pairs[loose[pairs].all(1)]]
    colour = np.full(nn + ne, -1)
    if loose.any():
        colour[loose] = _colour(int(loose.sum()), pairs)
    safe = np.concatenate([node_safe, beam_safe])
    groups: dict[bool, list] = {True: [], False: []}
    none = np.zeros(2 * ne, bool)
    for c in range(int(colour.max()) + 1):
        for s in (True, False):
            members = np.flatnonzero((colour == c) & (safe == s))
            ns, bs = members[members < nn], members[members >= nn] - nn
            t_c = [tris[i] for i in ns] + [_beam_triangles(lat, bs, none)]
            piece = _manifold(lat.points, np.concatenate(t_c))
            if piece is not None:
                groups[s].append(piece)
            groups[s] += [bad[i] for i in ns if i in bad]
    return stitched_mesh, groups, beam_ok
