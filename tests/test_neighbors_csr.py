"""The CSR streaming driver (meshcurv.neighbors.csr): lists are right whether each thread's
stream fits its scratch slice or overflows it (then the range is searched again)."""

import numpy as np
from scipy.spatial import cKDTree

from meshcurv.neighbors import ball_grid, ball_neighbors, csr


def test_gather_copies_the_streams_that_fit_and_leaves_overflowed_ranges():
    """4 queries, 2 threads of 2 queries, slices of per * cap = 4 entries: thread 0's stream
    (3 entries) fits and is copied, thread 1's (5 entries) overflowed."""
    counts = np.array([0, 2, 1, 3, 2], dtype=np.int64)
    buf = np.array([5, 6, 7, -1, 8, 9, 10, 11], dtype=np.int64)
    used = np.array([3, 5], dtype=np.int64)
    indices = csr.gather_streams(counts, buf, used, 2, 2, 2)
    assert list(counts) == [0, 2, 3, 6, 8]
    assert list(indices[:3]) == [5, 6, 7]
    assert csr.overflowed(used, 1, 2, 2) and not csr.overflowed(used, 0, 2, 2)


def test_ball_lists_survive_an_underestimated_scratch():
    """The sampled queries (every m // 64-th) see empty space, the others a dense cluster:
    the scratch is sized for empty balls and every thread overflows."""
    rng = np.random.default_rng(0)
    cluster = rng.normal(scale=0.05, size=(2000, 3))
    m = 640
    query = np.tile([0.0, 0.0, 0.0], (m, 1))
    query[::m // 64] = [10.0, 10.0, 10.0]
    grid = ball_grid(cluster, 0.1)
    indptr, indices = ball_neighbors(grid, None, query, 0.1)
    tree = cKDTree(cluster)
    for q in (0, 1, 5, m - 1):
        expected = sorted(tree.query_ball_point(query[q], 0.1))
        assert list(indices[indptr[q]:indptr[q + 1]]) == expected


def _random_lists(seed, m=50, longest=6, n=1000):
    rng = np.random.default_rng(seed)
    indptr = np.concatenate([[0], np.cumsum(rng.integers(0, longest, m))]).astype(np.int64)
    return rng, indptr, rng.integers(0, n, indptr[-1])


def test_csr_rows_are_the_lists_of_those_rows():
    rng, indptr, indices = _random_lists(2)
    rows = np.flatnonzero(rng.uniform(size=50) < 0.4)
    sub_ptr, sub = csr.csr_rows(indptr, indices, rows)
    assert len(sub_ptr) == len(rows) + 1
    for k, i in enumerate(rows):
        np.testing.assert_array_equal(sub[sub_ptr[k]:sub_ptr[k + 1]],
                                      indices[indptr[i]:indptr[i + 1]])
    empty_ptr, empty = csr.csr_rows(indptr, indices, rows[:0])
    assert empty_ptr.tolist() == [0] and len(empty) == 0


def test_count_within_counts_the_entries_inside_the_ball_as_numpy_does():
    """The kernel against its numpy specification: entries whose squared distance from the
    list's centre is in (0, r2max]; a point listed at the centre itself is not counted."""
    rng, indptr, indices = _random_lists(3, longest=40, n=300)
    points = rng.uniform(-1.0, 1.0, (300, 3))
    centres = points[rng.integers(0, 300, len(indptr) - 1)]
    owner = np.repeat(np.arange(len(centres)), np.diff(indptr))
    d2 = np.sum((points[indices] - centres[owner]) ** 2, axis=1)
    for r2max in (0.0, 0.3, 1.0, 12.0):
        expected = np.bincount(owner[(d2 > 0.0) & (d2 <= r2max)], minlength=len(centres))
        np.testing.assert_array_equal(csr.count_within(points, centres, indptr, indices, r2max),
                                      expected)
    assert 0 < csr.count_within(points, centres, indptr, indices, 0.3).sum() < len(indices)


def test_ball_mean_averages_the_entries_inside_the_ball_as_numpy_does():
    """The kernel against its numpy specification: the mean of each column over the entries
    :func:`count_within` counts, NaN for a list with none of them; with weights (some 0),
    the weighted mean, NaN where the weights in the ball sum to 0."""
    rng, indptr, indices = _random_lists(4, longest=40, n=300)
    points = rng.uniform(-1.0, 1.0, (300, 3))
    values = rng.normal(size=(300, 2))
    weights = np.where(rng.uniform(size=300) < 0.2, 0.0, rng.uniform(size=300))
    centres = points[rng.integers(0, 300, len(indptr) - 1)]
    owner = np.repeat(np.arange(len(centres)), np.diff(indptr))
    d2 = np.sum((points[indices] - centres[owner]) ** 2, axis=1)
    for r2max in (0.0, 0.3, 12.0):
        inside = (d2 > 0.0) & (d2 <= r2max)
        for w in (None, weights):
            wj = np.ones(len(indices)) if w is None else w[indices]
            total = np.bincount(owner[inside], wj[inside], minlength=len(centres)).astype(float)
            expected = np.column_stack([
                np.bincount(owner[inside], wj[inside] * values[indices[inside], a],
                            minlength=len(centres)) for a in range(2)]).astype(np.float64)
            with np.errstate(invalid="ignore", divide="ignore"):
                expected /= total[:, None]
            mean = np.empty((len(centres), 2))
            csr.ball_mean(points, centres, indptr, indices, r2max, values, mean, w)
            np.testing.assert_allclose(mean, expected, rtol=1e-12, atol=1e-15)
            assert np.isnan(mean[total == 0]).all() and np.isfinite(mean[total > 0]).all()
            if r2max == 0.3 and w is not None:
                assert np.any((total == 0) & (np.bincount(owner[inside],
                                                          minlength=len(centres)) > 0))


def test_ball_lists_of_serving_points_are_the_lists_filtered_as_numpy_does():
    """A dense clump in a sparse cloud, queries arranged so that the sampled ones (which size
    the scratch) see empty balls: the clump's lists overflow and are searched again. With a
    ``serving`` mask every list is the unmasked one without the points it leaves out, in both
    orders and both kinds of entry."""
    from meshcurv.neighbors import ball_counts
    rng = np.random.default_rng(4)
    sparse = rng.uniform(-1.0, 1.0, (3000, 3))
    clump = rng.normal(scale=0.02, size=(1500, 3))
    points = np.concatenate([sparse, clump])
    grid = ball_grid(points, 0.15)
    query = clump[:640].copy()
    sampled = np.arange(0, 640, 640 // 64)
    query[sampled] = sparse[sampled] + [5.0, 0.0, 0.0]
    query[::3] = sparse[:640:3]
    serving = rng.uniform(size=len(points)) < 0.3
    for ascending in (True, False):
        for positions in (True, False):
            full = ball_neighbors(grid, None, query, 0.15, ascending, positions)
            indptr, indices = ball_neighbors(grid, None, query, 0.15, ascending, positions,
                                             serving=serving)
            rows_served = serving if positions else serving[np.argsort(grid.order)]
            for q in range(len(query)):
                entries = full[1][full[0][q]:full[0][q + 1]]
                np.testing.assert_array_equal(indices[indptr[q]:indptr[q + 1]],
                                              entries[rows_served[entries]])
    lengths = np.diff(ball_neighbors(grid, None, query, 0.15)[0])
    assert (lengths > 400).sum() > 300 and (lengths < 7).sum() > 100   # both kinds of list
    np.testing.assert_array_equal(ball_counts(grid, query, 0.15, serving),
                                  np.diff(ball_neighbors(grid, None, query, 0.15,
                                                         serving=serving)[0]))


def test_crowd_thinning_keeps_the_thin_surface_and_limits_each_small_cell_of_a_clump():
    from meshcurv.neighbors import crowd_thinning
    from meshcurv.neighbors.grid import CROWD_FACTOR, CROWD_FINE
    rng = np.random.default_rng(5)
    plane = np.column_stack([rng.uniform(0, 10, (40000, 2)), np.zeros(40000)])
    assert crowd_thinning(ball_grid(plane, 0.3)) is None          # even density: untouched
    clump = np.column_stack([rng.uniform(3.0, 3.1, (8000, 2)), np.zeros(8000)])
    grid = ball_grid(np.concatenate([plane, clump]), 0.3)
    serving = crowd_thinning(grid)
    kept = serving[np.argsort(grid.order)]                         # by input point
    counts = np.diff(grid.cell_start)
    typical = np.median(np.repeat(counts, counts))
    limit = max(1, int(CROWD_FACTOR * typical / CROWD_FINE ** 2))
    keys = np.floor(np.concatenate([plane, clump]) * (CROWD_FINE / grid.cell)).astype(np.int64)
    _, small, size = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    small = small.ravel()
    served = np.bincount(small, weights=kept, minlength=len(size))
    crowded = size > limit
    assert crowded.any() and (served[crowded] == limit).all()
    assert kept[:40000][~crowded[small[:40000]]].all()            # the thin surface serves


def test_ball_max_takes_the_largest_finite_value_inside_each_ball_as_numpy_does():
    """The kernel against its numpy specification: the largest of ``values`` over the entries
    :func:`count_within` would count with each list's own squared radius, NaN values left
    out, NaN for a list with no finite value inside its ball."""
    rng, indptr, indices = _random_lists(5, longest=40, n=300)
    points = rng.uniform(-1.0, 1.0, (300, 3))
    values = np.where(rng.uniform(size=300) < 0.2, np.nan, rng.normal(size=300))
    centres = points[rng.integers(0, 300, len(indptr) - 1)]
    owner = np.repeat(np.arange(len(centres)), np.diff(indptr))
    d2 = np.sum((points[indices] - centres[owner]) ** 2, axis=1)
    r2max = rng.choice([0.0, 0.1, 0.5, 12.0], size=len(centres))
    inside = (d2 > 0.0) & (d2 <= r2max[owner]) & np.isfinite(values[indices])
    expected = np.full(len(centres), -np.inf)
    np.maximum.at(expected, owner[inside], values[indices[inside]])
    expected[np.isneginf(expected)] = np.nan
    out = np.empty(len(centres))
    csr.ball_max(points, centres, indptr, indices, r2max, values, out)
    np.testing.assert_array_equal(out, expected)
    assert np.isnan(out).any() and np.isfinite(out).sum() > len(out) // 2
