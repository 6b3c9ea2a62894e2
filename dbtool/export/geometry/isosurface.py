"""Level set of a sampled scalar field -> manifold solid, by marching tetrahedra
(docs/method.md §8).

Each grid cube is split into the six Kuhn tetrahedra around its main diagonal (the same split in
every cube, so neighbouring cubes' faces match). Inside a tetrahedron the trilinear field is
replaced by the linear interpolant of its four corner values, whose level set is a plane: one
triangle (one corner on its own side) or a convex quad (two and two) whose vertices lie on the
tetrahedron's edges. A vertex is identified by its grid edge, so neighbouring tetrahedra share
it, and the piecewise-linear level set of a generic field on a triangulated grid is a closed
2-manifold: the result is watertight and consistently oriented by construction, and
manifold3d's constructor checks it again.

This replaces ``Manifold.level_set``: manifold3d 3.5.4 crashes (SIGSEGV inside
``CreateLevelSet``) on some of our fields, and a mesher in numpy never calls back into Python.
One such field is kept in ``tests/data/level_set_crash.npz``; ``tests/test_isosurface.py`` runs
``level_set`` on it in a subprocess and says when a manifold3d release meshes it.
"""

from __future__ import annotations

from itertools import permutations

import numpy as np

from dbtool.export._manifold import manifold3d as m3

_CORNERS = np.array([(i, j, k) for i in (0, 1) for j in (0, 1) for k in (0, 1)])
SIMPLIFY = 0.01  # collapse edges shorter than this fraction of the pitch (slivers near nodes)
_T_EPS = 1e-4  # crossing points stay this fraction of an edge away from its grid nodes


def _kuhn_tets() -> np.ndarray:
    """(6, 4) cube-corner indices (into ``_CORNERS``) of the Kuhn tetrahedra: paths 000 -> 111."""
    tets = []
    for axes in permutations(range(3)):
        p = np.zeros(3, int)
        path = [p.copy()]
        for a in axes:
            p[a] = 1
            path.append(p.copy())
        tets.append([int(np.flatnonzero((_CORNERS == q).all(1))[0]) for q in path])
    return np.array(tets)


def _case_table(tets: np.ndarray) -> list[list[np.ndarray]]:
    """For each tetrahedron and each of the 16 inside/outside patterns of its corners, the
    triangles as (n, 3, 2) corner pairs (the edges their vertices lie on), wound so the normal
    points from the inside corners to the outside ones (counter-clockwise seen from outside)."""
    table = []
    for tet in tets:
        pos = _CORNERS[tet].astype(float)
        rows = []
        for case in range(16):
            inside = [c for c in range(4) if case >> c & 1]
            outside = [c for c in range(4) if not case >> c & 1]
            if len(inside) in (0, 4):
                rows.append(np.zeros((0, 3, 2), int))
                continue
            if len(inside) == 1 or len(outside) == 1:
                lone, rest = (inside[0], outside) if len(inside) == 1 else (outside[0], inside)
                polys = [[(lone, r) for r in rest]]
            else:
                (p, q), (r, s) = inside, outside
                quad = [(p, r), (p, s), (q, s), (q, r)]  # a cycle: neighbours share a face
                polys = [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
            out_dir = pos[outside].mean(0) - pos[inside].mean(0)
            tris = []
            for tri in polys:
                m = np.array([(pos[a] + pos[b]) / 2 for a, b in tri])
                if np.dot(np.cross(m[1] - m[0], m[2] - m[0]), out_dir) < 0:
                    tri = [tri[0], tri[2], tri[1]]
                tris.append(tri)
            rows.append(np.array(tris, int))
        table.append(rows)
    return table


_TETS = _kuhn_tets()
_TABLE = _case_table(_TETS)


def marching_tetrahedra(values: np.ndarray, origin, pitch: float):
    """Manifold (mm) of ``values > 0``, ``values`` sampled at ``origin + pitch * index``.

    The outermost layer of the grid is treated as outside, so the surface is always closed.
    Returns an empty Manifold when nothing is inside.
    """
    v = np.asarray(values, np.float64).copy()
    if v.ndim != 3 or min(v.shape) < 3:
        raise ValueError(f"need a 3-d grid of at least 3 samples per axis, got {v.shape}")
    for ax in range(3):  # close the surface at the grid's border
        sl = [slice(None)] * 3
        for end in (0, -1):
            sl[ax] = end
            v[tuple(sl)] = np.minimum(v[tuple(sl)], -1.0)
    inside = v > 0
    if not inside.any():
        return m3.Manifold()
    nx, ny, nz = v.shape
    # cubes whose 8 corners are not all on one side
    cube_in = np.stack([inside[i:nx - 1 + i, j:ny - 1 + j, k:nz - 1 + k] for i, j, k in _CORNERS])
    n_in = cube_in.sum(0)
    cubes = np.argwhere((n_in > 0) & (n_in < 8))
    strides = np.array([ny * nz, nz, 1])
    corner_off = _CORNERS @ strides
    node = cubes @ strides  # flat index of each cube's corner 000
    flat_in = inside.ravel()
    tri_edges = []  # (m, 3, 2) global node pairs
    for t, tet in enumerate(_TETS):
        nodes = node[:, None] + corner_off[tet][None, :]  # (c, 4)
        case = (flat_in[nodes] * (1 << np.arange(4))).sum(1)
        for c in range(1, 15):
            tris = _TABLE[t][c]
            sel = nodes[case == c]
            if len(sel) == 0:
                continue
            tri_edges.append(sel[:, tris].reshape(-1, 3, 2))
    pairs = np.concatenate(tri_edges)  # (T, 3, 2)
    a = np.minimum(pairs[..., 0], pairs[..., 1])
    b = np.maximum(pairs[..., 0], pairs[..., 1])
    key = a.astype(np.int64) * v.size + b
    uniq, tri = np.unique(key.ravel(), return_inverse=True)
    ea, eb = uniq // v.size, uniq % v.size
    fa, fb = v.ravel()[ea], v.ravel()[eb]
    t = np.clip(fa / (fa - fb), _T_EPS, 1 - _T_EPS)
    pa = np.stack(np.unravel_index(ea, v.shape), 1).astype(float)
    pb = np.stack(np.unravel_index(eb, v.shape), 1).astype(float)
    verts = np.asarray(origin, float) + pitch * (pa + t[:, None] * (pb - pa))
    mesh = m3.Mesh(vert_properties=verts.astype(np.float32),
                   tri_verts=tri.reshape(-1, 3).astype(np.uint32))
    solid = m3.Manifold(mesh)
    status = solid.status()
    if status != m3.Error.NoError:  # pragma: no cover - a bug, not bad input
        raise RuntimeError(f"marching tetrahedra produced an invalid mesh: {status}")
    return solid.simplify(SIMPLIFY * pitch)
