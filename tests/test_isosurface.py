"""Marching tetrahedra (dbtool.export.isosurface): closed, outward-oriented manifolds whose
volume converges to the level set's, on fields that crashed manifold3d's level_set."""

import numpy as np
import pytest
import trimesh

from dbtool.export.isosurface import marching_tetrahedra
from dbtool.export.mesh import to_trimesh


def _grid(n: int, half: float = 1.2):
    x = np.linspace(-half, half, n)
    return np.meshgrid(x, x, x, indexing="ij"), x[1] - x[0]


@pytest.mark.parametrize("n", [25, 49])
def test_sphere_is_a_closed_outward_volume_converging_to_the_ball(n):
    (X, Y, Z), h = _grid(n)
    s = marching_tetrahedra(1 - np.sqrt(X**2 + Y**2 + Z**2), [-1.2] * 3, h)
    assert s.status().name == "NoError" and s.genus() == 0 and len(s.decompose()) == 1
    mesh = to_trimesh(s)
    assert mesh.is_watertight and mesh.is_volume and mesh.volume > 0  # outward normals
    err = abs(s.volume() - 4 / 3 * np.pi) / (4 / 3 * np.pi)
    assert err < (0.02 if n == 25 else 0.005), err  # an inscribed surface: O(h^2) error


def test_torus_and_two_pieces_keep_their_topology():
    (X, Y, Z), h = _grid(61, 1.5)
    r = np.sqrt(X**2 + Y**2)
    torus = 0.3 - np.sqrt((r - 0.9) ** 2 + Z**2)
    s = marching_tetrahedra(torus, [-1.5] * 3, h)
    assert s.genus() == 1 and s.volume() == pytest.approx(2 * np.pi**2 * 0.9 * 0.09, rel=0.02)
    balls = np.maximum(0.4 - np.sqrt((X - 0.7) ** 2 + Y**2 + Z**2),
                       0.4 - np.sqrt((X + 0.7) ** 2 + Y**2 + Z**2))
    assert len(marching_tetrahedra(balls, [-1.5] * 3, h).decompose()) == 2


def test_a_full_grid_is_closed_at_its_border_and_an_empty_one_is_empty():
    s = marching_tetrahedra(np.ones((5, 6, 7)), [0, 0, 0], 1.0)
    assert s.status().name == "NoError" and len(s.decompose()) == 1
    assert to_trimesh(s).is_volume
    assert marching_tetrahedra(-np.ones((5, 5, 5)), [0, 0, 0], 1.0).is_empty()
    with pytest.raises(ValueError, match="3-d grid"):
        marching_tetrahedra(np.ones((5, 5)), [0, 0], 1.0)


def test_rough_random_fields_and_exact_ties_stay_manifold():
    """Noise with many tiny components, and values exactly at the level (grid-node ties)."""
    rng = np.random.default_rng(0)
    from scipy.ndimage import gaussian_filter

    for k in range(3):
        v = gaussian_filter(rng.normal(size=(40, 40, 40)), 1.0 + k)
        v[rng.random(v.shape) < 0.05] = 0.0  # ties: a node on the level belongs outside
        s = marching_tetrahedra(v, [0, 0, 0], 0.5)
        assert s.status().name == "NoError"
        mesh = to_trimesh(s)
        assert mesh.is_watertight and mesh.is_volume
        assert isinstance(mesh, trimesh.Trimesh) and s.volume() > 0
