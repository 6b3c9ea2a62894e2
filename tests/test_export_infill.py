"""Voronoi lattice foam infill (docs/method.md §8, appendix G): one watertight body inside the
part."""

import dataclasses

import manifold3d as m3
import numpy as np
import pytest

from dbtool.errors import InputError
from dbtool.export._manifold import to_trimesh as _trimesh
from dbtool.export.geometry.infill import InfillConfig, voronoi_infill
from dbtool.export.geometry.voxels import inside_layer


def _inside(solid, pts: np.ndarray) -> np.ndarray:
    """Point-in-solid by the winding number of cross-sections (trimesh.contains needs rtree)."""
    out = np.zeros(len(pts), bool)
    for z in np.unique(pts[:, 2]):
        sel = np.flatnonzero(pts[:, 2] == z)
        xs, ix = np.unique(pts[sel, 0], return_inverse=True)
        ys, iy = np.unique(pts[sel, 1], return_inverse=True)
        out[sel] = inside_layer(solid, z, xs, ys)[ix, iy]
    return out


@pytest.fixture(scope="module")
def cube():
    return m3.Manifold.cube([12.0, 12.0, 12.0])


@pytest.fixture(scope="module")
def cube_infill(cube):
    return voronoi_infill(cube)


@pytest.fixture(scope="module")
def sphere():
    return m3.Manifold.sphere(7.0, 48)


@pytest.fixture(scope="module")
def sphere_infill(sphere):
    return voronoi_infill(sphere, InfillConfig(spacing=3.0))


def test_default_config_is_the_papers_foam():
    cfg = InfillConfig()
    assert cfg.spacing == 2.5 and cfg.beam == 0.4  # the paper's foam
    assert cfg.shell > 0 and cfg.segments >= 3


@pytest.mark.parametrize("case", ["cube", "sphere"])
def test_one_watertight_body_inside_the_part(case, request):
    solid = request.getfixturevalue(case)
    result, info = request.getfixturevalue(f"{case}_infill")
    assert result.status() == m3.Error.NoError
    assert len(result.decompose()) == 1, "foam, skin and drain must form one connected body"
    mesh = _trimesh(result)
    assert mesh.is_watertight and mesh.is_volume
    assert abs(mesh.volume - result.volume()) < 1e-6 * result.volume()
    assert result.volume() < solid.volume()
    assert (result - solid).volume() < 1e-6 * solid.volume(), "nothing may stick out"
    lo, hi = np.array(result.bounding_box()).reshape(2, 3)
    slo, shi = np.array(solid.bounding_box()).reshape(2, 3)
    # the skin keeps the part's outside (the 2 mm drain clips a sphere's pole by 0.07 mm)
    assert np.allclose(lo, slo, atol=0.1) and np.allclose(hi, shi, atol=0.1), "skin kept"
    assert result.genus() > 20, "an open-cell foam has many handles"
    assert info["volume_mm3"] == pytest.approx(result.volume())
    assert info["surfaces"] == 1


@pytest.mark.parametrize("case", ["cube", "sphere"])
def test_density_between_skin_and_solid(case, request):
    solid = request.getfixturevalue(case)
    result, info = request.getfixturevalue(f"{case}_infill")
    rd = info["relative_density"]
    assert rd == pytest.approx(result.volume() / solid.volume())
    assert info["shell_fraction"] < rd < 1.0, "the foam adds material to the skin, not all"
    assert rd - info["shell_fraction"] > 0.02
    assert 0.03 < info["foam_relative_density"] < 0.4
    assert info["seeds"] > 10 and info["beams"] > info["seeds"]


def test_skin_is_solid_and_foam_is_open(cube, cube_infill):
    """Points in the skin are material, the foam region is mostly void, the cavity drains."""
    result, info = cube_infill
    skin = np.array([[0.5, 6.0, 6.0], [6.0, 11.5, 6.0], [6.0, 6.0, 11.6], [11.4, 3.0, 9.0]])
    assert _inside(result, skin).all()
    assert not _inside(result, np.array([[6.0, 6.0, 13.0], [-1.0, 6.0, 6.0]])).any()
    rng = np.random.default_rng(1)
    core = rng.uniform(3.0, 9.0, (500, 3))
    core[:, 2] = np.round(core[:, 2])  # a few cross-sections
    filled = _inside(result, core).mean()
    assert filled == pytest.approx(info["foam_relative_density"], abs=0.08)
    assert filled < 0.35


def test_info_reports_settings(cube_infill):
    _, info = cube_infill
    assert info["spacing_mm"] == 2.5 and info["beam_mm"] == 0.4 and info["shell_mm"] == 1.2
    assert info["seconds"] > 0
    assert 0.0 < info["stitched"] <= 1.0


def test_reproducible_with_seed_and_different_with_another(cube, cube_infill):
    result, info = cube_infill
    again, info2 = voronoi_infill(cube, InfillConfig(seed=0))
    assert again.volume() == pytest.approx(result.volume(), rel=1e-12)
    assert info2["beams"] == info["beams"]
    other, _ = voronoi_infill(cube, InfillConfig(seed=1))
    assert abs(other.volume() - result.volume()) > 1e-6 * result.volume()


def test_sealed_skin_without_drain(cube, cube_infill):
    result, info = voronoi_infill(cube, InfillConfig(drain=0.0))
    parts = sorted(p.volume() for p in result.decompose())
    assert len(parts) == 2 and parts[0] < 0 < parts[1], "outer surface and the cavity's"
    assert info["surfaces"] == 2
    assert _trimesh(result).is_watertight
    drained, _ = cube_infill
    assert result.volume() > drained.volume(), "the drain hole removes skin"


def test_larger_spacing_gives_lighter_foam(cube, cube_infill):
    _, dense = cube_infill
    _, sparse = voronoi_infill(cube, InfillConfig(spacing=3.5))
    assert sparse["foam_relative_density"] < dense["foam_relative_density"]
    assert sparse["beams"] < dense["beams"]


def test_empty_solid_raises():
    with pytest.raises(InputError, match="empty"):
        voronoi_infill(m3.Manifold())


def test_too_thin_for_the_shell_raises():
    plate = m3.Manifold.cube([20.0, 20.0, 2.0])  # thinner than 2 x 1.2 mm
    with pytest.raises(InputError, match="thinner than 2 x shell"):
        voronoi_infill(plate)


@pytest.mark.parametrize("field,value", [("spacing", 0.0), ("spacing", -2.5), ("beam", 0.0),
                                         ("beam", -0.4), ("shell", 0.0), ("segments", 2)])
def test_bad_settings_raise(cube, field, value):
    cfg = dataclasses.replace(InfillConfig(), **{field: value})
    with pytest.raises(ValueError):
        voronoi_infill(cube, cfg)
