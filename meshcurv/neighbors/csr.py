"""The CSR streaming driver every neighbor search shares (compiled kernels).

A search that lists each query's neighbors ``(indptr, indices)`` runs in three passes: a sample
of 64 queries sizes a scratch buffer (:func:`stream_capacity`); each of the threads
(:func:`thread_ranges`) streams its contiguous range of queries into its own slice of it; then
:func:`gather_streams` turns the counts into ``indptr`` and copies every slice that fitted into
``indices``. A thread whose slice overflowed (:func:`overflowed`) searches its range again
straight into ``indices``. The searches themselves (k-ring, grid ball) live in
:mod:`meshcurv.neighbors.kring` and :mod:`meshcurv.neighbors.grid`.
"""

import numpy as np
from numba import njit, prange

# Queries whose neighbor counts size the scratch buffer.
SAMPLE = 64


@njit(cache=True)
def thread_ranges(m, nthreads):
    """``(nthreads, per)``: threads to use for ``m`` queries (1 .. m) and queries per thread;
    thread t takes queries ``t * per .. min(m, (t + 1) * per) - 1``."""
    nthreads = max(1, min(m, nthreads))
    return nthreads, (m + nthreads - 1) // nthreads


@njit(cache=True)
def sample_step(m):
    """Stride of the sample queries ``range(0, m, step)`` (about :data:`SAMPLE` of them)."""
    return max(1, m // SAMPLE)


@njit(cache=True)
def stream_capacity(total, count):
    """Scratch entries per query: 1.5 times the mean of ``count`` sampled list lengths that sum
    to ``total``, plus 16."""
    return 16 + (3 * total) // (2 * max(count, 1))


@njit(cache=True)
def overflowed(used, t, per, cap):
    """Whether thread ``t``'s stream of ``used[t]`` entries overflowed its slice."""
    return used[t] > per * cap


@njit(parallel=True, cache=True)
def gather_streams(counts, buf, used, nthreads, per, cap):
    """CSR ``indices`` from the threads' streams.

    ``counts`` (m + 1,) int64 holds each query's list length at ``counts[q + 1]`` (and 0 at
    ``counts[0]``); it becomes ``indptr`` in place. ``buf`` holds thread t's stream at
    ``t * per * cap``, ``used[t]`` entries long. Returns (nnz,) int64 ``indices`` with every
    stream that fitted copied in; the ranges of overflowed threads are left for the caller.
    """
    m = counts.shape[0] - 1
    for i in range(m):
        counts[i + 1] += counts[i]
    indices = np.empty(counts[m], dtype=np.int64)
    for t in prange(nthreads):
        q0 = t * per
        if q0 >= m or overflowed(used, t, per, cap):
            continue
        lo = t * per * cap
        o = counts[q0]
        for j in range(used[t]):
            indices[o + j] = buf[lo + j]
    return indices


@njit(parallel=True, cache=True)
def csr_rows(indptr, indices, rows):
    """The CSR lists ``(sub_indptr, sub_indices)`` of the queries ``rows`` ((k,) int, each in
    0 .. m - 1) only, in that order: list i of the result is list ``rows[i]`` of ``(indptr,
    indices)``, same dtypes."""
    k = rows.shape[0]
    sub_ptr = np.zeros(k + 1, dtype=indptr.dtype)
    for i in range(k):
        sub_ptr[i + 1] = sub_ptr[i] + indptr[rows[i] + 1] - indptr[rows[i]]
    sub_idx = np.empty(sub_ptr[k], dtype=indices.dtype)
    for i in prange(k):
        lo = indptr[rows[i]]
        for j in range(sub_ptr[i + 1] - sub_ptr[i]):
            sub_idx[sub_ptr[i] + j] = indices[lo + j]
    return sub_ptr, sub_idx


@njit(cache=True)
def _in_ball(points, j, centres, i, r2max):
    """Whether ``points[j]`` lies within the ball of squared radius ``r2max`` about
    ``centres[i]``, the centre itself (and points coincident with it) left out."""
    dx = points[j, 0] - centres[i, 0]
    dy = points[j, 1] - centres[i, 1]
    dz = points[j, 2] - centres[i, 2]
    d2 = dx * dx + dy * dy + dz * dz
    return d2 > 0.0 and d2 <= r2max


@njit(parallel=True, cache=True)
def count_within(points, centres, indptr, indices, r2max):
    """Entries of each list within a ball: ``out[i]`` (int64) counts the j in list i with
    ``0 < |points[j] - centres[i]|^2 <= r2max`` (model units squared; the centre itself and
    coincident points are not counted)."""
    m = centres.shape[0]
    out = np.zeros(m, dtype=np.int64)
    for i in prange(m):
        c = 0
        for e in range(indptr[i], indptr[i + 1]):
            if _in_ball(points, indices[e], centres, i, r2max):
                c += 1
        out[i] = c
    return out


@njit(parallel=True, cache=True)
def ball_mean(points, centres, indptr, indices, r2max, values, mean, weights=None):
    """Means of ``values`` ((n, c), per row of ``points``) over the entries of each list within
    a ball, as :func:`count_within` counts them, into ``mean`` ((m, c); NaN where the ball
    holds none). ``weights`` ((n,) >= 0, per row of ``points``, optional): weighted means
    ``sum w values / sum w`` (NaN where the weights in the ball sum to 0); default 1."""
    m = centres.shape[0]
    c = values.shape[1]
    for i in prange(m):
        total = 0.0
        for a in range(c):
            mean[i, a] = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            if _in_ball(points, j, centres, i, r2max):
                w = 1.0 if weights is None else weights[j]
                if w > 0.0:
                    total += w
                    for a in range(c):
                        mean[i, a] += w * values[j, a]
        for a in range(c):
            mean[i, a] = mean[i, a] / total if total > 0.0 else np.nan


@njit(parallel=True, cache=True)
def ball_max(points, centres, indptr, indices, r2max, values, out):
    """Largest finite entry of ``values`` ((n,), per row of ``points``) over the entries of
    each list within its own ball, as :func:`count_within` counts them but with a squared
    radius per list (``r2max`` (m,), model units squared), into ``out`` ((m,); NaN where the
    ball holds no finite value)."""
    m = centres.shape[0]
    for i in prange(m):
        top = -np.inf
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            if values[j] > top and _in_ball(points, j, centres, i, r2max[i]):
                top = values[j]
        out[i] = top if top > -np.inf else np.nan
