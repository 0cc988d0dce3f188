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
the order scipy.sparse's products take (its ``csr_matmat``, ``multiply`` and row sums,
which :func:`meshcurv.ring_noise_spec.ring_noise` keeps as the specification): the same
bits, without the matrices (a 1M-vertex torus, one call: 2.46 -> 0.66 s, peak beyond the
input 666 -> 112 bytes per vertex).
"""

import numba
import numpy as np
from numba import njit, prange

from .neighbors import edge_adjacency
from .neighbors.kring import mean_edge_lengths
from .neighbors.csr import thread_ranges
from .normals import face_vertex_normals
from .normals.winding import coherent_faces

__all__ = ["ring_noise", "ring_means", "two_ring_sums"]


def ring_noise(v, f, adjacency=None):
    """``(noise, edge)``, (n,) each, of the mesh ``v`` (n, 3), ``f`` (m, 3): the noise sigma
    of each vertex along its normal (module docstring) and the mean length of its edges, model
    units. Noise NaN where a vertex within 3 rings has no normal (a vertex in no face) or is
    not finite, edge NaN at a vertex in no face. The normals are the area-weighted ones of the
    faces wound coherently (:func:`meshcurv.normals.winding.coherent_faces`): the faces'
    winding, and faces listed twice, do not matter. ``adjacency``: the mesh's
    :func:`meshcurv.neighbors.edge_adjacency`, if already made. The same bits as
    :func:`meshcurv.ring_noise_spec.ring_noise`."""
    v = np.ascontiguousarray(v, dtype=np.float64)
    n = len(v)
    indptr, indices = edge_adjacency(f, n) if adjacency is None else adjacency
    counts = np.diff(indptr)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        edge = mean_edge_lengths(v, indptr, indices)
        inverse = 1.0 / counts

        def ring_mean(x):
            return ring_means(indptr, indices, inverse, x)
        residual = _residual(v, f, ring_mean, indptr, indices, counts)
        spread, per_unit = two_ring_sums(indptr, indices, inverse, residual * residual)
        noise = np.sqrt(spread / per_unit)
    return noise, edge


def _residual(v, f, ring_mean, indptr, indices, counts):
    """``r = (I - P) h`` (n,) of the umbrella heights h along the normals; ``ring_mean(x)``
    is ``P x``."""
    normal = face_vertex_normals(v, coherent_faces(v, f, (indptr, indices))[0])
    normal[counts == 0] = np.nan
    height = np.einsum("ij,ij->i", ring_mean(v) - v, normal)
    return height - ring_mean(height)


@njit(cache=True)
def ring_means(indptr, indices, inverse, x):
    """``P x`` for ``x`` (n,) or (n, k): each row's mean over its neighbours (CSR adjacency;
    ``inverse`` (n,) one over each row's count), summed from 0 in the row's order, as
    scipy.sparse's ``csr_matvec(s)`` does."""
    out = np.zeros(x.shape)
    flat = out.reshape(x.shape[0], -1)
    values = x.reshape(x.shape[0], -1)
    for i in range(len(indptr) - 1):
        w = inverse[i]
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            for c in range(flat.shape[1]):
                flat[i, c] += w * values[j, c]
    return out


@njit(cache=True)
def _second_entry(indptr, indices, inverse, r, t, before):
    """Entry ``t`` (column, value) of row ``r`` of ``I - P`` as scipy.sparse's difference of
    two canonical matrices lists it: the row's columns in order, 1 on the diagonal (after the
    ``before`` neighbours of lower index), ``0 - 1 / count`` elsewhere."""
    if t == before:
        return r, 1.0
    e = indptr[r] + (t if t < before else t - 1)
    return indices[e], 0.0 - inverse[r]


@njit(cache=True)
def _lower(indptr, indices, r):
    """How many of row ``r``'s neighbours have a lower index."""
    count = 0
    for e in range(indptr[r], indptr[r + 1]):
        count += indices[e] < r
    return count


@njit(cache=True)
def _add(sums, following, k, value, head, length):
    """``sums[k] += value``, and column k linked in front of ``head`` where it is new (as
    scipy's ``csr_matmat`` does); returns the list's ``(head, length)``."""
    sums[k] += value
    if following[k] == -1:
        following[k] = head
        return k, length + 1
    return head, length


@njit(cache=True)
def _drain(head, length, sums, following, columns, values):
    """The entries of a product row as scipy's ``csr_matmat`` stores them: the columns
    linked from ``head`` (the last one first seen), those with a nonzero sum, into
    ``columns``, ``values``; ``sums`` and ``following`` reset; returns their count."""
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
def _second_row(indptr, indices, inverse, i, sums, following, columns, values):
    """Row ``i`` of ``(I - P)^2`` as scipy's ``csr_matmat`` forms it (each sum over the
    row of ``I - P`` in its order, from 0): its count of entries, into ``columns``,
    ``values`` (:func:`_drain`). ``sums`` (n,) 0 and ``following`` (n,) -1, as left."""
    head = -2
    length = 0
    before_i = _lower(indptr, indices, i)
    for t in range(indptr[i + 1] - indptr[i] + 1):
        j, a = _second_entry(indptr, indices, inverse, i, t, before_i)
        before_j = _lower(indptr, indices, j)
        for u in range(indptr[j + 1] - indptr[j] + 1):
            k, b = _second_entry(indptr, indices, inverse, j, u, before_j)
            head, length = _add(sums, following, k, a * b, head, length)
    return _drain(head, length, sums, following, columns, values)


@njit(cache=True)
def _two_ring_row(indptr, indices, inverse, i, sums, following, columns, values):
    """Row ``i`` of ``P^2`` as scipy's ``csr_matmat`` forms it (see :func:`_second_row`)."""
    head = -2
    length = 0
    for jj in range(indptr[i], indptr[i + 1]):
        j = indices[jj]
        a = inverse[i]
        for kk in range(indptr[j], indptr[j + 1]):
            head, length = _add(sums, following, indices[kk], a * inverse[j], head, length)
    return _drain(head, length, sums, following, columns, values)


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
    """Most entries a row of P^2 or (I - P)^2 can hold: the largest sum over a vertex and
    its neighbours of their counts plus one."""
    most = 1
    for i in range(len(indptr) - 1):
        total = indptr[i + 1] - indptr[i] + 1
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            total += indptr[j + 1] - indptr[j] + 1
        most = max(most, total)
    return most


@njit(cache=True)
def _row_scratch(n, most):
    """One thread's work arrays of the product rows: ``sums`` (n,) 0, ``following`` (n,) -1
    (:func:`_second_row`), ``columns`` and ``values`` (most,)."""
    return (np.zeros(n), np.full(n, -1, dtype=np.int64), np.empty(most, dtype=np.int64),
            np.empty(most))


@njit(parallel=True, cache=True)
def _per_unit(indptr, indices, inverse, nthreads):
    """``c_i``, the squared entries of row i of ``(I - P)^2`` summed as scipy.sparse's
    ``.multiply`` and ``.sum(axis=1)`` do: the products in reverse order of the row, the
    first plus numpy's pairwise sum of the others; 0 for an empty row."""
    n = len(indptr) - 1
    out = np.zeros(n)
    threads, per = thread_ranges(n, nthreads)
    most = _row_bound(indptr, indices)
    for t in prange(threads):
        sums, following, columns, values = _row_scratch(n, most)
        squares = np.empty(most)
        for i in range(t * per, min(n, (t + 1) * per)):
            count = _second_row(indptr, indices, inverse, i, sums, following, columns, values)
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
def _two_ring_means(indptr, indices, inverse, x, y, nthreads):
    """``(P^2 x, P^2 y)``: each row of ``P @ P`` formed as scipy's ``csr_matmat`` does and
    applied in its order from 0 (scipy's ``csr_matvec``)."""
    n = len(indptr) - 1
    px = np.zeros(n)
    py = np.zeros(n)
    threads, per = thread_ranges(n, nthreads)
    most = _row_bound(indptr, indices)
    for t in prange(threads):
        sums, following, columns, values = _row_scratch(n, most)
        for i in range(t * per, min(n, (t + 1) * per)):
            count = _two_ring_row(indptr, indices, inverse, i, sums, following, columns,
                                  values)
            sx = 0.0
            sy = 0.0
            for c in range(count):
                sx += values[c] * x[columns[c]]
                sy += values[c] * y[columns[c]]
            px[i] = sx
            py[i] = sy
    return px, py


def two_ring_sums(indptr, indices, inverse, squares):
    """``(P^2 squares, P^2 c)``, (n,) each: the 2-ring means of ``squares`` (n,) and of the
    variance factors ``c_i = sum_j ((I - P)^2)_ij^2``, with ``P`` the ring mean (CSR
    adjacency ``indptr, indices``, rows sorted; ``inverse`` (n,) one over each row's
    count); the same bits as scipy.sparse's products
    (:func:`meshcurv.ring_noise_spec.ring_noise`), a row at a time."""
    threads = numba.get_num_threads()
    per_unit = _per_unit(indptr, indices, inverse, threads)
    return _two_ring_means(indptr, indices, inverse, squares, per_unit, threads)
