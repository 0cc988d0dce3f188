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
