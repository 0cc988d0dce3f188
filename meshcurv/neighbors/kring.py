"""Radius-limited k-rings over mesh edges: the connected part of the ball reachable on the
surface (never across a thin sheet); and plain k-rings, every vertex within k hops (the ring
jets' supports, :func:`hop_rings`). Compiled kernels (edge adjacency, breadth-first search,
the CSR lists through :mod:`meshcurv.neighbors.csr`) and their wrappers.
"""

import math

import numba
import numpy as np
from numba import njit, prange

from ..linalg import insertion_sort
from .csr import gather_streams, overflowed, sample_step, stream_capacity, thread_ranges

__all__ = ["edge_adjacency", "mean_edge_lengths", "kring_neighbors", "kring_counts",
           "KringWork", "edge_adjacency_csr", "kring_ball_csr", "kring_ball_counts", "hop_rings"]

def edge_adjacency(faces, n_vertices):
    """Undirected edge graph of a triangle mesh as CSR ``(indptr, indices)`` over vertices.

    Parameters
    ----------
    faces : (m, 3) int, vertex indices (validated by the caller)
    n_vertices : int

    Degenerate faces contribute only their distinct edges; non-manifold edges are fine.
    Each row is sorted and holds every neighbor once. ``indptr`` (n + 1,) int64, ``indices``
    int32.
    """
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    return edge_adjacency_csr(faces, int(n_vertices))


@njit(parallel=True, cache=True, error_model="numpy")
def mean_edge_lengths(points, indptr, indices):
    """Mean length (n,) of each vertex's edges over the edge graph ``(indptr, indices)``
    (:func:`edge_adjacency`), summed in the row's order (as ``np.bincount`` of the lengths
    sums them); NaN where a vertex has none (0 / 0, as numpy divides)."""
    n = len(indptr) - 1
    edge = np.empty(n)
    for i in prange(n):
        total = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            d0 = points[i, 0] - points[j, 0]
            d1 = points[i, 1] - points[j, 1]
            d2 = points[i, 2] - points[j, 2]
            total += math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        edge[i] = total / (indptr[i + 1] - indptr[i])
    return edge


class KringWork:
    """Reusable work arrays of :func:`kring_neighbors` for repeated calls on one mesh.

    ``threads x n`` int32 visited stamps and queues (8 bytes per vertex and thread), allocated
    once instead of per call; each call takes fresh stamp values from ``next_tag`` (three per
    query vertex), and the stamps are cleared when those would pass ``2**31``.
    """

    def __init__(self, n_vertices, n_threads=None):
        t = numba.get_num_threads() if n_threads is None else int(n_threads)
        self.stamp = np.full((max(1, t), n_vertices), -1, dtype=np.int32)
        self.queue = np.empty((max(1, t), n_vertices), dtype=np.int32)
        self.next_tag = 0

    def take_tags(self, count):
        """First of ``count`` fresh query tags (stamp values ``3 * tag + {0, 1, 2}``)."""
        if 3 * (self.next_tag + count) + 3 >= 2 ** 31:
            self.stamp.fill(-1)
            self.next_tag = 0
        tag0 = self.next_tag
        self.next_tag += count
        return tag0


def kring_neighbors(points, adjacency, radius, query, work=None):
    """Connected, radius-limited k-ring of each query vertex.

    Breadth-first over mesh edges from the query vertex, keeping (and expanding through) only
    vertices within Euclidean distance ``radius``: the part of the ball that is reachable on the
    surface, so the other side of a thin sheet is never reached.

    Parameters
    ----------
    points : (n, 3) float64
    adjacency : CSR ``(indptr, indices)`` from :func:`edge_adjacency`
    radius : float, model units
    query : (m,) int64, vertices to collect neighborhoods for
    work : KringWork, optional
        Work arrays to reuse across calls on the same mesh (saves an O(n) allocation per call).

    Returns
    -------
    indptr : (m + 1,) int64; indices : (nnz,) int64 (query vertex excluded, breadth-first order)
    """
    return _run_kring(kring_ball_csr, points, adjacency, radius, query, work)


def kring_counts(points, adjacency, radius, query, work=None):
    """(m,) int64 size of each query vertex's neighborhood in :func:`kring_neighbors`,
    without storing the lists (to size the work first)."""
    return _run_kring(kring_ball_counts, points, adjacency, radius, query, work)


def _run_kring(kernel, points, adjacency, radius, query, work):
    """Call a k-ring kernel with converted inputs and fresh stamps of ``work`` (made if None)."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    query = np.ascontiguousarray(query, dtype=np.int64)
    if work is None:
        work = KringWork(len(points))
    tag0 = work.take_tags(len(query))
    return kernel(adjacency[0], adjacency[1], points, query, float(radius), work.stamp,
                  work.queue, tag0)


@njit(cache=True)
def edge_adjacency_csr(faces, n):
    """Undirected edge graph of a triangle mesh as CSR ``(indptr, indices)``, sorted, unique.

    ``indptr`` is int64, ``indices`` int32 (vertex numbers below 2**31; half the memory).

    Every face contributes its three edges in both directions (self-loops of degenerate faces
    are dropped); each vertex's row is then sorted and deduplicated in place.
    """
    m = faces.shape[0]
    start = np.zeros(n + 1, dtype=np.int64)
    for f in range(m):
        for c in range(3):
            a = faces[f, c]
            b = faces[f, (c + 1) % 3]
            if a != b:
                start[a + 1] += 1
                start[b + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start[:n].copy()
    idx = np.empty(start[n], dtype=np.int32)
    for f in range(m):
        for c in range(3):
            a = faces[f, c]
            b = faces[f, (c + 1) % 3]
            if a != b:
                idx[fill[a]] = b
                fill[a] += 1
                idx[fill[b]] = a
                fill[b] += 1
    indptr = np.zeros(n + 1, dtype=np.int64)
    out = 0
    for i in range(n):
        lo = start[i]
        hi = start[i + 1]
        insertion_sort(idx, lo, hi)     # rows hold ~12 entries
        # compaction never overtakes the unsorted rows ahead: out <= lo
        prev = -1
        for j in range(lo, hi):
            if idx[j] != prev:
                prev = idx[j]
                idx[out] = prev
                out += 1
        indptr[i + 1] = out
    return indptr, idx[:out].copy()


@njit(cache=True)
def _kring_one(adj_ptr, adj_idx, points, s, tag, r2max, stamp, queue, out, base, limit):
    """Breadth-first, radius-limited k-ring of vertex ``s``; the connected, radius-limited
    neighborhood that cannot jump across a thin sheet.

    Writes the neighbors found to ``out[base:]`` as long as they fit below ``limit`` and returns
    how many there are (so a caller can detect an overflow). ``stamp`` marks visited vertices
    with ``tag``, a value unique to this search.
    """
    x0 = points[s, 0]
    x1 = points[s, 1]
    x2 = points[s, 2]
    if not np.isfinite(x0 + x1 + x2):
        return 0
    stamp[s] = tag
    head = 0
    tail = 1
    queue[0] = s
    found = 0
    while head < tail:
        a = queue[head]
        head += 1
        for e in range(adj_ptr[a], adj_ptr[a + 1]):
            b = adj_idx[e]
            if stamp[b] == tag:
                continue
            stamp[b] = tag
            d0 = points[b, 0] - x0
            d1 = points[b, 1] - x1
            d2 = points[b, 2] - x2
            if d0 * d0 + d1 * d1 + d2 * d2 <= r2max:
                queue[tail] = b
                tail += 1
                if base + found < limit:
                    out[base + found] = b
                found += 1
    return found


@njit(parallel=True, cache=True)
def kring_ball_csr(adj_ptr, adj_idx, points, query, radius, stamp, queue, tag0):
    """Radius-limited k-ring CSR lists, one breadth-first search per query vertex.

    Lists exclude the query vertex and are in breadth-first order. Each thread streams its
    results into an int32 scratch sized from a sample of 64 queries, copied once; a thread
    whose stream overflows searches its range again.
    ``stamp`` (threads, n) int32 or int64 and ``queue`` (threads, n) int32 are reusable work
    arrays (``stamp`` starts at -1); ``tag0`` is an offset that makes this call's stamps
    unique: pass a different ``tag0`` per call (e.g. the position of the block), with
    ``3 * (tag0 + len(query)) + 2`` representable in ``stamp``'s type.
    """
    m = query.shape[0]
    r2max = radius * radius
    counts = np.zeros(m + 1, dtype=np.int64)
    nthreads, per = thread_ranges(m, stamp.shape[0])
    # stamps 3 * (tag0 + qi) + {0: sample, 1: stream, 2: repeat} are unique across uses
    dummy = np.empty(0, dtype=np.int32)
    tot = 0
    cnt = 0
    for qi in range(0, m, sample_step(m)):
        tot += _kring_one(adj_ptr, adj_idx, points, query[qi], 3 * (tag0 + qi), r2max,
                          stamp[0], queue[0], dummy, 0, 0)
        cnt += 1
    cap = stream_capacity(tot, cnt)
    buf = np.empty(nthreads * per * cap, dtype=np.int32)
    used = np.zeros(nthreads, dtype=np.int64)
    for t in prange(nthreads):
        lo = t * per * cap
        pos = lo
        for qi in range(t * per, min(m, (t + 1) * per)):
            f = _kring_one(adj_ptr, adj_idx, points, query[qi], 3 * (tag0 + qi) + 1, r2max,
                           stamp[t], queue[t], buf, pos, lo + per * cap)
            counts[qi + 1] = f
            pos += f
        used[t] = pos - lo
    indices = gather_streams(counts, buf, used, nthreads, per, cap)
    for t in prange(nthreads):
        if overflowed(used, t, per, cap):
            for qi in range(t * per, min(m, (t + 1) * per)):
                _kring_one(adj_ptr, adj_idx, points, query[qi], 3 * (tag0 + qi) + 2, r2max,
                           stamp[t], queue[t], indices, counts[qi], counts[qi + 1])
    return counts, indices


@njit(parallel=True, cache=True)
def kring_ball_counts(adj_ptr, adj_idx, points, query, radius, stamp, queue, tag0):
    """(m,) int64 size of each query vertex's radius-limited k-ring (what
    :func:`kring_ball_csr` would list, nothing stored: to size the work before doing it).
    Work arrays and ``tag0`` as there."""
    m = query.shape[0]
    r2max = radius * radius
    out = np.zeros(m, dtype=np.int64)
    nthreads, per = thread_ranges(m, stamp.shape[0])
    dummy = np.empty(0, dtype=np.int32)
    for t in prange(nthreads):
        for qi in range(t * per, min(m, (t + 1) * per)):
            out[qi] = _kring_one(adj_ptr, adj_idx, points, query[qi], 3 * (tag0 + qi), r2max,
                                 stamp[t], queue[t], dummy, 0, 0)
    return out


@njit(cache=True)
def _hop_ring_one(adj_ptr, adj_idx, s, depth, tag, stamp, queue, out, base, limit):
    """Breadth-first over mesh edges from vertex ``s`` to ``depth`` hops: the vertices found
    (``s`` excluded, by hop count, then in the search's order) written to ``out[base:]`` when
    ``out`` holds them (a counting pass passes an empty one); returns ``(found, inner)``,
    their number and how many lie within ``depth - 1`` hops; ``(0, 0)`` where more than
    ``limit`` are found (a hub of a fan reaches the whole fan). ``stamp`` marks visited
    vertices with ``tag``, a value unique to this search."""
    stamp[s] = tag
    queue[0] = s
    head = 0
    tail = 1
    inner = 0
    for hop in range(depth):
        level_end = tail
        if hop == depth - 1:
            inner = tail - 1
        while head < level_end:
            a = queue[head]
            head += 1
            for e in range(adj_ptr[a], adj_ptr[a + 1]):
                b = adj_idx[e]
                if stamp[b] == tag:
                    continue
                if tail > limit:
                    return 0, 0
                stamp[b] = tag
                queue[tail] = b
                tail += 1
    if out.shape[0] > 0:
        for i in range(1, tail):
            out[base + i - 1] = queue[i]
    return tail - 1, inner


@njit(parallel=True, cache=True)
def hop_rings(adj_ptr, adj_idx, query, depth, stamp, queue, tag0, limit):
    """The ``depth``-ring of each query vertex over mesh edges (every vertex within ``depth``
    hops, however far): CSR ``(indptr, indices, inner)``, each row by hop count (the query
    vertex excluded) and ``inner`` (m,) int64 the entries of each row within ``depth - 1``
    hops; an empty row where the ring holds more than ``limit`` vertices (which bounds the
    lists' memory by ``limit`` entries a query). Work arrays as :func:`kring_ball_csr`'s
    (stamps ``3 * (tag0 + qi) + {0, 1}``)."""
    m = query.shape[0]
    counts = np.zeros(m + 1, dtype=np.int64)
    inner = np.zeros(m, dtype=np.int64)
    nthreads, per = thread_ranges(m, stamp.shape[0])
    dummy = np.empty(0, dtype=np.int32)
    for t in prange(nthreads):
        for qi in range(t * per, min(m, (t + 1) * per)):
            counts[qi + 1], inner[qi] = _hop_ring_one(adj_ptr, adj_idx, query[qi], depth,
                                                      3 * (tag0 + qi), stamp[t], queue[t],
                                                      dummy, 0, limit)
    indptr = np.cumsum(counts)
    indices = np.empty(indptr[m], dtype=np.int32)
    for t in prange(nthreads):
        for qi in range(t * per, min(m, (t + 1) * per)):
            _hop_ring_one(adj_ptr, adj_idx, query[qi], depth, 3 * (tag0 + qi) + 1, stamp[t],
                          queue[t], indices, indptr[qi], limit)
    return indptr, indices, inner
