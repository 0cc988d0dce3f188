"""meshcurv.tiled.grid: tiles own every finite point once and see exactly the points within their
halo; tile names and squares agree; the default tile size. Data built in code, no Dask."""

import numpy as np
import pytest

from meshcurv.tiled.grid import TileGrid, default_tile_size, tile_name


@pytest.fixture
def points():
    rng = np.random.default_rng(11)
    xyz = rng.uniform(-3.0, 7.0, size=(2000, 3))
    xyz[:50, :2] = np.round(xyz[:50, :2])  # points exactly on tile walls (tile_size 1)
    return xyz


def test_every_point_is_owned_by_exactly_one_tile_the_one_of_own_keys(points):
    grid = TileGrid.for_radius((-3.0, -3.0), 1.0, 0.3)
    point, keys, own = grid.memberships(points)
    assert np.array_equal(np.sort(point[own]), np.arange(len(points)))
    np.testing.assert_array_equal(keys[own][np.argsort(point[own])], grid.own_keys(points))


def test_a_tile_sees_exactly_the_points_within_its_halo(points):
    grid = TileGrid.for_radius((-3.0, -3.0), 1.0, 0.3)
    point, keys, _ = grid.memberships(points)
    members = set(zip(point.tolist(), map(tuple, keys.tolist())))
    for key in {tuple(k) for k in keys.tolist()}:
        lo = grid.tile_square(tile_name(key))
        xy = points[:, :2]
        inside = ((xy >= lo - grid.halo) & (xy < lo + grid.tile_size + grid.halo)).all(axis=1)
        expected = set(np.flatnonzero(inside).tolist())
        assert {p for p, k in members if k == key} == expected


def test_the_halo_covers_the_radius_and_tiles_narrower_than_it_are_refused():
    grid = TileGrid.for_radius((0.0, 0.0), 10.0, 2.0)
    assert grid.halo > 2.0 and grid.halo - 2.0 < 1e-5
    with pytest.raises(ValueError, match="at least the radius"):
        TileGrid.for_radius((0.0, 0.0), 1.0, 2.0)


def test_tile_names_give_back_their_square():
    grid = TileGrid.for_radius((5.0, -2.0), 3.0, 1.0)
    np.testing.assert_array_equal(grid.tile_square(tile_name((-2, 4))), [5.0 - 6.0, -2.0 + 12.0])


def test_default_tile_size_of_a_flat_cloud_is_a_few_radii_not_zero():
    # a line of points 100 long: one radius wide, 10^6 points per tile of 50 square units
    assert default_tile_size(10 ** 6, (100.0, 0.0), radius=0.5) == pytest.approx(50 ** 0.5)
    assert default_tile_size(10 ** 6, (1.0, 0.0), radius=0.5) == 2.0         # floor: 4 radii
    assert default_tile_size(4 * 10 ** 6, (400.0, 400.0), radius=0.5) == 200.0
