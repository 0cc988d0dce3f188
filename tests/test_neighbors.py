"""Ball queries: dense grid, hashed grid and k-d tree give the same neighbour lists."""

import numpy as np
from scipy.spatial import cKDTree

import meshcurv
from meshcurv import surfaces
from meshcurv.neighbors import ball_grid, ball_neighbors


def kdtree_lists(points, query, radius):
    lists = cKDTree(points).query_ball_point(query, radius, return_sorted=True)
    return [np.asarray(a, dtype=np.int64) for a in lists]


def csr_lists(indptr, indices):
    return [indices[indptr[i]:indptr[i + 1]] for i in range(len(indptr) - 1)]


def two_far_clouds(rng):
    """A noisy sphere and a copy 1e7 radii away: the extent is too sparse for a dense grid."""
    s = surfaces.sphere(subdivisions=4)
    near = s.vertices + rng.normal(scale=1e-3, size=s.vertices.shape)
    return near, np.vstack([near, near + [1e6, -3e5, 2e5]])


def test_dense_and_hashed_grids_list_the_kdtree_neighbours():
    rng = np.random.default_rng(5)
    near, both = two_far_clouds(rng)
    radius = 0.3
    dense, hashed = ball_grid(near, radius), ball_grid(both, radius)
    assert len(dense.table_keys) == 0 and len(hashed.table_keys) > 0   # both forms are tested
    query = np.vstack([both, rng.uniform(-1.2, 1.2, size=(200, 3)), [[np.nan, 0, 0]]])
    truth = kdtree_lists(both[np.isfinite(both).all(axis=1)], query[:-1], radius) + [[]]
    got = csr_lists(*ball_neighbors(hashed, None, query, radius))
    assert all(np.array_equal(g, t) for g, t in zip(got, truth, strict=True))
    truth_near = kdtree_lists(near, query[:len(near)], radius)
    got_near = csr_lists(*ball_neighbors(dense, None, query[:len(near)], radius))
    assert all(np.array_equal(g, t) for g, t in zip(got_near, truth_near, strict=True))


def test_grid_order_is_the_same_dense_and_hashed():
    """Unsorted lists come in the same order from both forms, so results are the same bits
    whichever form a cloud (or a tile of it) gets."""
    rng = np.random.default_rng(6)
    near, both = two_far_clouds(rng)
    radius = 0.3
    q = near[:500]
    dense = ball_neighbors(ball_grid(near, radius), None, q, radius, ascending=False)
    hashed = ball_neighbors(ball_grid(both, radius), None, q, radius, ascending=False)
    assert np.array_equal(dense[0], hashed[0]) and np.array_equal(dense[1], hashed[1])
    assert not np.all(np.diff(dense[1][dense[0][0]:dense[0][1]]) > 0)  # really unsorted

    alone = meshcurv.principal_curvatures(near, radius=radius)
    with_far_copy = meshcurv.principal_curvatures(both, radius=radius)
    n = len(near)
    for name in ("k1", "k2", "normals", "d1"):
        a, b = getattr(alone, name), getattr(with_far_copy, name)[:n]
        assert np.array_equal(a, b, equal_nan=True), name
    assert np.all(alone.valid) and abs(np.median(alone.k1) - 1.0) < 0.05
