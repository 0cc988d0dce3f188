"""Position noise of a triangle mesh measured over its 1-rings, free of its shape.

The local jet's residual (``CurvatureResult.noise``) measures noise plus what a quadric
leaves of the shape within the ball; on a mesh coarse for its shape the second dominates
(trimesh's clean 32 x 12 torus 1 / 0.3: 0.023, against 0.0005 here). Over the 1-rings the
shape is nearly constant, so its second difference cancels it and leaves the noise:

- ``P = D^-1 A``, the uniform average over each vertex's 1-ring (A the edge adjacency, D its
  degrees);
- ``h = n . (P v - v)``, the umbrella operator's displacement along the normal ``n``: a
  smooth surface's mean curvature times the squared edge length, plus noise;
- ``r = (I - P) h``: the shape's part cancels where the sampling is even, the noise's
  stays, ``r = M e`` with ``M = (I - P)^2`` applied to the noise ``e`` along the normals;
- ``sigma_i^2 = (P^2 r^2)_i / (P^2 c)_i`` with ``c_i = sum_j M_ij^2`` (the variance of
  ``r_i`` per unit noise variance), averaged over the 2-ring.

Measured against Gaussian noise along the normals (0.1 % of the diagonal) on six of
trimesh's tori (32 x 12 to 200 x 50) and MeshLab's decimations of a torus and an ellipsoid:
the RMS over the vertices within 5 % of its sigma. An uneven sampling reads as noise (its
``h`` differs from vertex to vertex), so the estimate is an upper bound of the noise where
the sampling is uneven, as at a sharp edge; callers take the smaller of it and the jet's.

:func:`meshcurv.normals.face_normal_error` measures the same noise from the first
differences of the umbrella heights with one calibration for a regular triangulation
(``UMBRELLA_NOISE``): on the meshes above, noisy, 0-16 % above this estimate; clean,
1.2-10x above it (trimesh's 32 x 12 torus 1 / 0.3: 0.0023 against 0.0007, RMS), still 10x
below the jet's there.

The second differences' matrices ``(I - P)^2`` and ``P^2`` hold ~20-40 entries per row; the
compiled kernels form one row at a time instead (:func:`two_ring_sums`), with the sums in
the order scipy.sparse's products take (its ``csr_matmat``, ``multiply`` and row sums, which
:func:`ring_noise_sparse` keeps as the specification): the same bits, without the matrices
(a 1M-vertex torus: 2.5 -> 0.5 s, 666 -> ~100 bytes per vertex at the peak).
"""

import math

import numba
import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from .neighbors import edge_adjacency
from .neighbors.csr import thread_ranges
from .normals import face_vertex_normals
from .normals.winding import coherent_faces

__all__ = ["ring_noise", "ring_noise_sparse", "mean_edges", "two_ring_sums"]


def ring_noise(v, f, adjacency=None):
    """``(noise, edge)``, (n,) each, of the mesh ``v`` (n, 3), ``f`` (m, 3): the noise sigma
    of each vertex along its normal (module docstring) and the mean length of its edges, model
    units. Noise NaN where a vertex within 3 rings has no normal (a vertex in no face) or is
    not finite, edge NaN at a vertex in no face. The normals are the area-weighted ones of the
    faces wound coherently (:func:`meshcurv.normals.winding.coherent_faces`): the faces'
    winding, and faces listed twice, do not matter. ``adjacency``: the mesh's
    :func:`meshcurv.neighbors.edge_adjacency`, if already made. The same bits as
    :func:`ring_noise_sparse`."""
    v = np.asarray(v, dtype=np.float64)
    n = len(v)
    indptr, indices = edge_adjacency(f, n) if adjacency is None else adjacency
    counts = np.diff(indptr)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        edge = mean_edges(v, indptr, indices)
        ring_mean = sp.csr_matrix((np.repeat(1.0 / counts, counts), indices, indptr),
                                  shape=(n, n))
        height, residual = _residuals(v, f, ring_mean, indptr, indices, counts)
        spread, per_unit = two_ring_sums(indptr, indices, ring_mean.data, residual * residual)
        noise = np.sqrt(spread / per_unit)
    return noise, edge


def ring_noise_sparse(v, f, adjacency=None):
    """:func:`ring_noise` with scipy.sparse's matrix products (the specification of its
    kernels; ~7x the memory)."""
    v = np.asarray(v, dtype=np.float64)
    n = len(v)
    indptr, indices = edge_adjacency(f, n) if adjacency is None else adjacency
    counts = np.diff(indptr)
    rows = np.repeat(np.arange(n), counts)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        edge = np.bincount(rows, np.linalg.norm(v[rows] - v[indices], axis=1), n) / counts
        ring_mean = sp.csr_matrix((1.0 / counts[rows], indices, indptr), shape=(n, n))
        height, residual = _residuals(v, f, ring_mean, indptr, indices, counts)
        second = sp.identity(n, format="csr") - ring_mean
        second = second @ second
        per_unit = np.asarray(second.multiply(second).sum(axis=1)).ravel()
        two_rings = ring_mean @ ring_mean
        noise = np.sqrt((two_rings @ (residual * residual)) / (two_rings @ per_unit))
    return noise, edge


def _residuals(v, f, ring_mean, indptr, indices, counts):
    """``(h, r)``: the umbrella heights h along the normals and ``r = (I - P) h``."""
    normal = face_vertex_normals(v, coherent_faces(v, f, (indptr, indices))[0])
    normal[counts == 0] = np.nan
    height = np.einsum("ij,ij->i", ring_mean @ v - v, normal)
    return height, height - ring_mean @ height


@njit(cache=True, error_model="numpy")
def mean_edges(v, indptr, indices):
    """Mean length (n,) of each vertex's edges (CSR adjacency), NaN where it has none (0 / 0,
    as numpy divides); summed in the adjacency's order (as ``np.bincount`` of the lengths)."""
    n = len(indptr) - 1
    edge = np.empty(n)
    for i in range(n):
        total = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            d0 = v[i, 0] - v[j, 0]
            d1 = v[i, 1] - v[j, 1]
            d2 = v[i, 2] - v[j, 2]
            total += math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        count = indptr[i + 1] - indptr[i]
        edge[i] = total / count
    return edge


@njit(cache=True)
def _product_row(ap, aj, ax, bp, bj, bx, i, sums, following, columns, values):
    """Row ``i`` of the CSR product A B as scipy's ``csr_matmat`` forms it: its nonzero
    entries into ``columns``, ``values`` in that order (the columns in reverse order of first
    appearance; each sum over A's row in its order, from 0); returns their count. ``sums``
    (n,) 0 and ``following`` (n,) -1 on entry, and again on return."""
    head = -2
    length = 0
    for jj in range(ap[i], ap[i + 1]):
        j = aj[jj]
        a = ax[jj]
        for kk in range(bp[j], bp[j + 1]):
            k = bj[kk]
            sums[k] += a * bx[kk]
            if following[k] == -1:
                following[k] = head
                head = k
                length += 1
    count = 0
    for _ in range(length):
        if sums[head] != 0.0:
            columns[count] = head
            values[count] = sums[head]
            count += 1
        last = head
        head = following[head]
        following[last] = -1
        sums[last] = 0.0
    return count


@njit(cache=True)
def _pairwise_block(a, lo, n):
    """``a[lo:lo + n]`` (n <= 128) summed as numpy's pairwise summation does: in order below
    8 terms, else 8 partial sums, combined pairwise, then the rest in order."""
    if n < 8:
        total = 0.0
        for i in range(lo, lo + n):
            total += a[i]
        return total
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        total += a[lo + i]
        i += 1
    return total


@njit(cache=True)
def _pairwise_sum(a, lo, n):
    """``a[lo:lo + n]`` summed as numpy's pairwise summation does: blocks of up to 128
    (:func:`_pairwise_block`), longer runs as the sum of their halves (the first a multiple
    of 8), evaluated with an explicit stack (numba's cache does not keep recursive
    functions)."""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    seg_lo = np.empty(64, dtype=np.int64)
    seg_n = np.empty(64, dtype=np.int64)
    stage = np.zeros(64, dtype=np.int64)
    partial = np.empty(64)
    top = 0
    done = 0
    seg_lo[0], seg_n[0], stage[0] = lo, n, 0
    while top >= 0:
        length = seg_n[top]
        half = length // 2
        half -= half % 8
        if length <= 128:
            partial[done] = _pairwise_block(a, seg_lo[top], length)
            done += 1
            top -= 1
        elif stage[top] < 2:
            start = seg_lo[top] + (half if stage[top] == 1 else 0)
            size = length - half if stage[top] == 1 else half
            stage[top] += 1
            top += 1
            seg_lo[top], seg_n[top], stage[top] = start, size, 0
        else:
            done -= 1
            partial[done - 1] = partial[done - 1] + partial[done]
            top -= 1
    return partial[0]


@njit(cache=True)
def _row_bound(indptr, indices):
    """Most entries a row of P^2 or (I - P)^2 can hold: the longest sum of the degrees of a
    row's vertex and its neighbors."""
    most = 1
    for i in range(len(indptr) - 1):
        total = indptr[i + 1] - indptr[i] + 1
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            total += indptr[j + 1] - indptr[j] + 1
        most = max(most, total)
    return most


@njit(parallel=True, cache=True)
def _per_unit(sp_, sj, sx, n, nthreads):
    """``c_i``, the squared entries of row i of ``(I - P)^2`` summed (``S = I - P`` in CSR
    ``sp_, sj, sx``) as ``S @ S`` then ``.multiply`` and ``.sum(axis=1)`` of scipy.sparse
    do: the products in reverse order of the product's row, the first plus numpy's pairwise
    sum of the others; 0 for an empty row."""
    out = np.zeros(n)
    threads, per = thread_ranges(n, nthreads)
    most = _row_bound(sp_, sj)
    for t in prange(threads):
        sums = np.zeros(n)
        following = np.full(n, -1, dtype=np.int64)
        columns = np.empty(most, dtype=np.int64)
        values = np.empty(most)
        squares = np.empty(most)
        for i in range(t * per, min(n, (t + 1) * per)):
            count = _product_row(sp_, sj, sx, sp_, sj, sx, i, sums, following, columns,
                                 values)
            kept = 0
            for c in range(count - 1, -1, -1):
                square = values[c] * values[c]
                if square != 0.0:
                    squares[kept] = square
                    kept += 1
            if kept:
                out[i] = squares[0] + _pairwise_sum(squares, 1, kept - 1)
    return out


@njit(parallel=True, cache=True)
def _two_ring_means(indptr, indices, weights, x, y, nthreads):
    """``(P^2 x, P^2 y)`` with ``P`` the CSR ``indptr, indices, weights``, each row of
    ``P @ P`` formed as scipy's ``csr_matmat`` does and then applied in its order (scipy's
    ``csr_matvec``: from 0, in the row's order)."""
    n = len(indptr) - 1
    px = np.zeros(n)
    py = np.zeros(n)
    threads, per = thread_ranges(n, nthreads)
    most = _row_bound(indptr, indices)
    for t in prange(threads):
        sums = np.zeros(n)
        following = np.full(n, -1, dtype=np.int64)
        columns = np.empty(most, dtype=np.int64)
        values = np.empty(most)
        for i in range(t * per, min(n, (t + 1) * per)):
            count = _product_row(indptr, indices, weights, indptr, indices, weights, i, sums,
                                 following, columns, values)
            sx = 0.0
            sy = 0.0
            for c in range(count):
                sx += values[c] * x[columns[c]]
                sy += values[c] * y[columns[c]]
            px[i] = sx
            py[i] = sy
    return px, py


def two_ring_sums(indptr, indices, weights, squares):
    """``(P^2 squares, P^2 c)``, (n,) each: the 2-ring means of ``squares`` (n,) and of the
    variance factors ``c_i = sum_j ((I - P)^2)_ij^2``, with ``P`` the ring mean (CSR
    ``indptr, indices, weights``, rows sorted); the same bits as scipy.sparse's products
    (:func:`ring_noise_sparse`)."""
    n = len(indptr) - 1
    second = sp.identity(n, format="csr") - sp.csr_matrix((weights, indices, indptr),
                                                          shape=(n, n))
    threads = numba.get_num_threads()
    per_unit = _per_unit(second.indptr, second.indices, second.data, n, threads)
    return _two_ring_means(indptr, indices, weights, squares, per_unit, threads)
