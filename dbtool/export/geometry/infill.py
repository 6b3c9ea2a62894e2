"""Voronoi lattice foam infill of a printable part (docs/method.md §8, the paper's appendix G).

The paper's physical gripper fingers were infilled with a Voronoi lattice foam (seed point
spacing 2.5 mm, beam thickness 0.4 mm) to soften them. :func:`voronoi_infill` rebuilds a part as
a solid skin (``shell`` mm thick) around such a foam and returns one watertight manifold:

1. The inner region (the part eroded by ``shell``) is the ``shell`` level set, meshed by
   marching tetrahedra (:mod:`dbtool.export.geometry.isosurface`), of a signed distance field:
   the part is voxelised slice by slice (:mod:`dbtool.export.geometry.voxels`: winding numbers
   of its cross-sections, no ray casting) and
   ``scipy.ndimage.distance_transform_edt`` gives the distance. skin = part - inner region.
2. Seeds on a body-centred cubic grid jittered by +-10 % of its cell (one seed per
   ``spacing**3``, reproducible from ``seed``; a near-Kelvin foam with few very short edges).
   The finite edges of their ``scipy.spatial.Voronoi`` diagram with an end (or the middle) in
   the slightly enlarged inner region become the beams; edges under 1.25 beam diameters are
   contracted (their ends merged).
3. The lattice (:mod:`dbtool.export.geometry.lattice`): each beam is a prism of ``segments``
   facets whose width across flats is ``beam`` (no section is thinner), each Voronoi vertex a node,
   the convex hull of its beams' end rings. Most of the foam is stitched into one mesh with no
   boolean at all; the rest (tangled joints, pieces near the skin) are groups of disjoint
   pieces united by ``Manifold.batch_boolean``.
4. Pieces that might stick out of the part are intersected with it; the foam is united with the
   skin, foam islands not joined to it are dropped and pockets closed off between beams and
   the skin are filled.
5. A drain hole (``drain`` mm wide) is drilled through the skin at the cavity's lowest point
   (-z), along the shortest way out. A DLP print (docs/method.md §8: EPU 40) must let uncured
   resin out of the foam, and only the hole joins the outer skin's surface to the foam's, so
   that the part is one connected surface (``len(decompose()) == 1``). With ``drain=0`` the
   skin is sealed and the outer surface and the cavity's are two surfaces of one solid.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from dbtool.errors import InputError
from dbtool.export._manifold import from_arrays, mesh_arrays
from dbtool.export._manifold import manifold3d as m3
from dbtool.export.geometry.isosurface import marching_tetrahedra
from dbtool.export.geometry.lattice import (
    EPS,
    Lattice,
    foam_pieces,
    frames,
    sample_segments,
    segment_distance,
)
from dbtool.export.geometry.voxels import Voxels

_JITTER = 0.1  # seed displacement, fraction of the body-centred cubic cell (each axis, +-)


@dataclass
class InfillConfig:
    """Voronoi foam settings in mm; spacing and beam are the paper's values (docs/method.md §8)."""

    spacing: float = 2.5  # mm between Voronoi seeds: one seed per spacing**3
    beam: float = 0.4  # mm beam thickness: the prisms' width across flats
    shell: float = 1.2  # mm solid skin kept around the foam (a setting, not from the paper)
    seed: int = 0  # RNG seed of the seed points (reproducible)
    segments: int = 6  # facets of each beam's cross-section
    drain: float = 2.0  # mm diameter of a resin drain hole through the skin (0: sealed skin)


# --------------------------------------------------------------------------- distance field


@dataclass
class _Field:
    """Signed distance to the part's surface (mm, positive inside) sampled on a grid."""

    sdf: np.ndarray  # (nx, ny, nz)
    origin: np.ndarray  # position (mm) of voxel (0, 0, 0)'s centre
    pitch: float

    def sample(self, p: np.ndarray) -> np.ndarray:
        """Trilinear interpolation at points (n, 3) in mm; far outside beyond the grid."""
        from scipy.ndimage import map_coordinates

        u = (np.atleast_2d(p) - self.origin) / self.pitch
        return map_coordinates(self.sdf, u.T, order=1, mode="constant", cval=-1e3)


def _distance_field(solid, pitch: float, pad: int = 3) -> _Field:
    """Signed distance (voxel estimate, error below about one ``pitch``) of a manifold."""
    vox = Voxels.of(solid, pitch, pad)
    return _Field(vox.signed_distance().astype(np.float64), vox.origin, pitch)


def _inner_region(field: _Field, shell: float):
    """The part eroded by ``shell``: the ``shell`` level set of the distance field."""
    keep = np.argwhere(field.sdf > shell)
    if len(keep) == 0:
        return m3.Manifold()
    a = np.maximum(keep.min(0) - 2, 0)
    b = np.minimum(keep.max(0) + 3, field.sdf.shape)
    box = field.sdf[a[0]:b[0], a[1]:b[1], a[2]:b[2]] - shell
    return marching_tetrahedra(box, field.origin + a * field.pitch, field.pitch)


# --------------------------------------------------------------------------- seeds and edges


def _seeds(lo: np.ndarray, hi: np.ndarray, spacing: float, rng) -> np.ndarray:
    """Jittered body-centred cubic grid covering [lo, hi] plus two cells, one seed per
    ``spacing**3``; the jitter keeps the seeds well spread (no two nearly coincide)."""
    a = spacing * 2.0 ** (1.0 / 3.0)  # two seeds per cubic cell
    start = lo - 2 * a
    n = np.ceil((hi + 2 * a - start) / a).astype(int) + 1
    g = np.stack(np.meshgrid(*(np.arange(k) for k in n), indexing="ij"), -1).reshape(-1, 3)
    cells = np.vstack([g, g + 0.5]).astype(float)
    cells += rng.uniform(-_JITTER, _JITTER, cells.shape)
    return start + a * cells


def _voronoi_edges(seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Voronoi vertices (m, 3) and the unique finite ridge edges (k, 2) between them."""
    from scipy.spatial import Voronoi

    vor = Voronoi(seeds)
    ridges = vor.ridge_vertices  # in 3-D each ridge is a polygon with its vertices in order
    sizes = np.fromiter((len(r) for r in ridges), int, len(ridges))
    flat = np.fromiter((v for r in ridges for v in r), int, int(sizes.sum()))
    start = np.repeat(np.cumsum(sizes) - sizes, sizes)
    pos = np.arange(len(flat)) - start
    nxt = flat[start + (pos + 1) % np.repeat(sizes, sizes)]
    e = np.stack([flat, nxt], 1)
    e = e[(e >= 0).all(1)]
    e = np.unique(np.sort(e, 1), axis=0)
    return vor.vertices, e


def _contract_short(verts: np.ndarray, edges: np.ndarray, min_len: float):
    """Merge the ends of edges shorter than ``min_len`` (mean position); drop loops/duplicates.
    Returns node positions (k, 3) and edges (m, 2) indexing them (only nodes that are used)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    used, e = np.unique(edges, return_inverse=True)
    e = e.reshape(-1, 2)
    p = verts[used]
    short = np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1) < min_len
    n = len(used)
    graph = coo_matrix((np.ones(short.sum()), (e[short, 0], e[short, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    count = np.bincount(label)
    pos = np.stack([np.bincount(label, p[:, k]) for k in range(3)], 1) / count[:, None]
    e = label[e]
    e = e[e[:, 0] != e[:, 1]]
    e = np.unique(np.sort(e, 1), axis=0)
    keep, e = np.unique(e, return_inverse=True)
    return pos[keep], e.reshape(-1, 2)


# --------------------------------------------------------------------------- drain and clean-up


def _drain_hole(inner, field: _Field, diameter: float, reach: float):
    """A cylinder through the skin from the cavity's lowest point (-z) along the distance
    field's steepest descent (the shortest way out), ``reach`` mm into the cavity."""
    v = np.asarray(mesh_arrays(inner)[0], float)
    low = v[v[:, 2] <= v[:, 2].min() + field.pitch]
    c = low[np.argmin(np.linalg.norm(low - low.mean(0), axis=1))]
    h = field.pitch
    grad = np.array([field.sample(c + h * d)[0] - field.sample(c - h * d)[0]
                     for d in np.eye(3)])
    d = -grad / np.linalg.norm(grad) if np.linalg.norm(grad) > 1e-12 else np.array([0, 0, -1.0])
    out = float(field.sample(c)[0]) + 2 * field.pitch + 0.5 * diameter  # past the outer surface
    a, b = c - reach * d, c + out * d
    return _cylinder(a, b, 0.5 * diameter, 24), (a, b)


def _cylinder(a: np.ndarray, b: np.ndarray, radius: float, segments: int):
    """A cylinder from a to b (manifold3d's run along +z from the origin)."""
    v = b - a
    length = float(np.linalg.norm(v))
    p, q = frames((v / length)[None])
    rot = np.column_stack([p[0], q[0], v / length, a])  # (p, q, u) right-handed: a rotation
    return m3.Manifold.cylinder(length, radius, radius, segments).transform(rot.tolist())


def _clean(body, cavity: float):
    """Keep the skin's surface only, and the number of surfaces kept. ``decompose`` splits a
    body into its connected surfaces: foam islands (positive volume) and pockets closed off
    between beams and the skin (inverted, negative volume; they would trap resin) are separate
    ones. Dropping a pocket's surface fills it. An inverted surface enclosing more than
    ``cavity`` mm3 is a foam cavity (a sealed skin, or a drain that missed it) and stays."""
    parts = body.decompose()
    if len(parts) == 1:
        return body, 1
    vols = np.array([m.volume() for m in parts])
    keep = [parts[int(np.argmax(vols))]] + [parts[i] for i in np.flatnonzero(vols < -cavity)]
    if len(keep) == 1:
        return keep[0], 1
    verts, tris, nv = [], [], 0
    for m in keep:
        v, t = mesh_arrays(m, double=True)
        verts.append(v)
        tris.append(t + nv)
        nv += len(v)
    return from_arrays(np.vstack(verts), np.vstack(tris)), len(keep)


# --------------------------------------------------------------------------- the infill


def _check(solid, cfg: InfillConfig) -> None:
    if not (cfg.spacing > 0 and math.isfinite(cfg.spacing)):
        raise InputError(f"infill spacing must be a positive number of mm, got {cfg.spacing}")
    if not (cfg.beam > 0 and math.isfinite(cfg.beam)):
        raise InputError(f"infill beam diameter must be a positive number of mm, got {cfg.beam}")
    if cfg.beam >= 0.5 * cfg.spacing:
        raise InputError(f"infill beam ({cfg.beam} mm) must be under half the seed spacing "
                         f"({cfg.spacing} mm)")
    if not (cfg.shell > 0 and math.isfinite(cfg.shell)):
        raise InputError(f"infill shell must be a positive thickness in mm, got {cfg.shell}")
    if not (cfg.drain >= 0 and math.isfinite(cfg.drain)):
        raise InputError(f"infill drain must be a diameter >= 0 mm, got {cfg.drain}")
    if int(cfg.segments) < 3:
        raise InputError(f"infill beams need at least 3 segments, got {cfg.segments}")
    if solid is None or solid.is_empty() or solid.volume() <= 0:
        raise InputError("infill: the solid is empty")
    if len(solid.decompose()) != 1:
        raise InputError("infill: the solid must be one connected body")


def _thin(cfg: InfillConfig) -> InputError:
    return InputError(f"infill: the part is thinner than 2 x shell ({2 * cfg.shell:g} mm), "
                      "no room for foam")


def _skin(solid, cfg: InfillConfig, pitch: float) -> tuple:
    """Stage 1 of :func:`voronoi_infill`: the part's distance field, the inner region, the skin
    (drained), what the foam is clipped to, and the drain hole's axis (or None)."""
    field = _distance_field(solid, pitch)
    if field.sdf.max() <= cfg.shell + 0.5 * pitch:
        raise _thin(cfg)
    inner = _inner_region(field, cfg.shell)
    if inner.is_empty() or inner.volume() <= 0:
        raise _thin(cfg)
    shell, keep_in = solid - inner, solid
    hole = None
    if cfg.drain > 0:
        cyl, hole = _drain_hole(inner, field, cfg.drain, cfg.beam + pitch)
        shell, keep_in = shell - cyl, solid - cyl
    return field, inner, shell, keep_in, hole


def _foam_lattice(inner, field: _Field, cfg: InfillConfig, r: float, seg: int) -> tuple:
    """Stage 2 of :func:`voronoi_infill`: the seeds, and the lattice of the Voronoi edges near
    the inner region (its nodes, edges and :class:`Lattice`)."""
    box = np.asarray(inner.bounding_box(), float)
    seeds = _seeds(box[:3], box[3:], cfg.spacing, np.random.default_rng(cfg.seed))
    verts, edges = _voronoi_edges(seeds)
    a, b = verts[edges[:, 0]], verts[edges[:, 1]]
    near = cfg.shell - cfg.beam  # "inside the slightly enlarged inner region"
    keep = ((field.sample(a) >= near) | (field.sample(b) >= near)
            | (field.sample(0.5 * (a + b)) >= near))
    if not keep.any():  # pragma: no cover - the inner region exists, so some edge crosses it
        raise _thin(cfg)
    nodes, e = _contract_short(verts, edges[keep], 2.5 * r)
    lat = Lattice.build(nodes, e, r, seg)
    return seeds, nodes, e, lat


def _safe(lat: Lattice, nodes: np.ndarray, ne: int, field: _Field, hole, cfg: InfillConfig,
          step: float, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Stage 3 of :func:`voronoi_infill`: the beams and the nodes that stay inside the part and
    clear of the drain hole (the others are clipped by a boolean)."""
    pts, owner = sample_segments(lat.seg_a, lat.seg_b, step)
    margin = 1.5 * pitch + 0.5 * step + EPS  # the field's error plus the sampling gap
    low = np.full(ne, np.inf)
    np.minimum.at(low, owner, field.sample(pts))
    beam_safe = low >= lat.big_r + margin
    node_safe = field.sample(nodes) >= lat.rho + margin
    if hole is not None:
        ha, hb = hole
        reach = 0.5 * cfg.drain + EPS
        d = segment_distance(pts, pts, np.broadcast_to(ha, pts.shape),
                             np.broadcast_to(hb, pts.shape))
        near_hole = np.zeros(ne, bool)
        near_hole[owner[d < reach + lat.big_r + 0.5 * step]] = True
        beam_safe &= ~near_hole
        d = segment_distance(nodes, nodes, np.broadcast_to(ha, nodes.shape),
                             np.broadcast_to(hb, nodes.shape))
        node_safe &= d >= reach + lat.rho
    return beam_safe, node_safe


def voronoi_infill(solid, cfg: InfillConfig | None = None) -> tuple[object, dict]:
    """Replace the inside of ``solid`` (a ``manifold3d.Manifold`` in mm) by a Voronoi lattice
    foam (docs/method.md §8 / appendix G: seed spacing 2.5 mm, beams 0.4 mm) inside a skin of
    thickness ``cfg.shell``; returns (one watertight body, info).

    info: relative_density (result / solid volume), foam_relative_density (foam volume in the
    inner region / its volume), shell_fraction (skin / solid volume), seeds (in the foam
    region), beams, nodes, stitched (share of beams joined without booleans), surfaces (1, or 2
    for a sealed skin: outer and cavity surfaces), shell_mm, spacing_mm, beam_mm, drain_mm,
    seconds, volume_mm3. Raises InputError (a ValueError) on an empty solid,
    bad settings, or a part thinner than 2 x shell (no room for foam).
    """
    cfg = InfillConfig() if cfg is None else cfg
    t0 = time.perf_counter()
    _check(solid, cfg)
    seg = int(cfg.segments)
    r = 0.5 * cfg.beam

    # 1. skin, inner region, drain hole
    pitch = min(cfg.shell / 3.0, 0.5)
    field, inner, shell, keep_in, hole = _skin(solid, cfg, pitch)
    solid_vol, inner_vol, shell_vol = solid.volume(), inner.volume(), shell.volume()

    # 2. seeds and the Voronoi edges near the inner region
    seeds, nodes, e, lat = _foam_lattice(inner, field, cfg, r, seg)
    nn, ne = len(nodes), len(e)

    # 3. pieces that may leave the part (or enter the drain) are clipped by a boolean
    step = r
    beam_safe, node_safe = _safe(lat, nodes, ne, field, hole, cfg, step, pitch)

    # 4. stitch what is clean into one mesh: node hulls whose rings are all faces, beams whose
    #    ends replace those faces; everything else is fused by booleans (groups of disjoint
    #    pieces from a greedy colouring of the conflict graph)
    stitched_mesh, groups, beam_ok = foam_pieces(lat, node_safe, beam_safe, step)
    parts = [shell] + ([stitched_mesh] if stitched_mesh is not None else []) + groups[True]
    if groups[False]:
        parts.append(m3.Manifold.batch_boolean(groups[False], m3.OpType.Add) ^ keep_in)
    result = m3.Manifold.batch_boolean(parts, m3.OpType.Add)

    # 5. keep the skin's surface: drop foam islands, fill enclosed pockets
    result, surfaces = _clean(result, cavity=0.05 * inner_vol)
    if result.status() != m3.Error.NoError or result.volume() < shell_vol * (1 - 1e-6):
        raise RuntimeError("infill: the foam and skin did not fuse")  # pragma: no cover
    vol = result.volume()
    info = {
        "relative_density": vol / solid_vol,
        "foam_relative_density": max(vol - shell_vol, 0.0) / inner_vol,
        "shell_fraction": shell_vol / solid_vol,
        "seeds": int(np.count_nonzero(field.sample(seeds) >= cfg.shell)),
        "beams": ne,
        "nodes": nn,
        "stitched": float(beam_ok.mean() if ne else 0.0),
        "surfaces": surfaces,  # 1: one connected surface (drained); 2: sealed skin + cavity
        "shell_mm": cfg.shell,
        "spacing_mm": cfg.spacing,
        "beam_mm": cfg.beam,
        "drain_mm": cfg.drain,
        "seconds": time.perf_counter() - t0,
        "volume_mm3": vol,
    }
    return result, info
