"""PCA normals: the normal of the least-squares plane through each point's neighborhood.
Compiled kernel :func:`pca_normals_csr` and its wrapper :func:`pca_normals`.
"""

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK, ball_offset, smallest_eigvec_jacobi3

__all__ = ["pca_normals", "pca_normals_csr", "split_plane_disagreement"]


@njit(cache=True)
def _plane_normal(points, indices, lo, hi, stride, x0, x1, x2, r2max, inv_r, point_weights,
                  cov, ev):
    """Unit normal of the least-squares plane through (x0, x1, x2) and the neighbors
    ``indices[lo:hi:stride]`` within the ball (``r2max`` squared radius, ``inv_r`` its inverse;
    see :func:`pca_normals_csr`) into ``ev``; False where it has none (fewer than 3 points, a
    covariance that is not finite). ``cov`` (3, 3) is scratch."""
    s0 = s1 = s2 = 0.0
    s00 = s01 = s02 = s11 = s12 = s22 = 0.0
    c = 1.0
    k = 1
    for j in range(lo, hi, stride):
        inside, a, b, d, _ = ball_offset(points, indices[j], x0, x1, x2, r2max, inv_r)
        if not inside:
            continue
        w = 1.0 if point_weights is None else point_weights[indices[j]]
        if w <= 0.0:
            continue
        k += 1
        c += w
        s0 += w * a
        s1 += w * b
        s2 += w * d
        s00 += w * a * a
        s01 += w * a * b
        s02 += w * a * d
        s11 += w * b * b
        s12 += w * b * d
        s22 += w * d * d
    if k < 3:
        return False
    m0 = s0 / c
    m1 = s1 / c
    m2 = s2 / c
    cov[0, 0] = s00 / c - m0 * m0
    cov[0, 1] = s01 / c - m0 * m1
    cov[0, 2] = s02 / c - m0 * m2
    cov[1, 1] = s11 / c - m1 * m1
    cov[1, 2] = s12 / c - m1 * m2
    cov[2, 2] = s22 / c - m2 * m2
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]
    for i in range(3):
        for j in range(3):
            if not np.isfinite(cov[i, j]):
                return False
    smallest_eigvec_jacobi3(cov, ev)
    return True


@njit(parallel=True, cache=True)
def pca_normals_csr(points, query_points, indptr, indices, radius, point_weights=None):
    """Unit normals (m, 3) of the least-squares plane through each query point's neighbors.

    The covariance of the neighbors within ``radius`` (the point included) is accumulated
    about the query point in units of ``radius`` (precise at large offsets) and corrected to
    the centroid; its smallest eigenvector comes from Jacobi rotations. NaN rows
    where fewer than 3 points lie in the ball or the covariance is not finite. Signs are
    arbitrary (the orientation step fixes them). ``point_weights`` (n,) in [0, 1], optional:
    each neighbor's weight in the covariance (the outlier pass's; the query point's is 1).
    """
    m = query_points.shape[0]
    out = np.full((m, 3), np.nan)
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        cov = np.empty((3, 3))
        ev = np.empty(3)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            if _plane_normal(points, indices, indptr[q], indptr[q + 1], 1, query_points[q, 0],
                             query_points[q, 1], query_points[q, 2], r2max, inv_r,
                             point_weights, cov, ev):
                out[q, 0] = ev[0]
                out[q, 1] = ev[1]
                out[q, 2] = ev[2]
    return out


@njit(parallel=True, cache=True)
def split_plane_disagreement(points, query_points, indptr, indices, radius, point_weights=None):
    """``sin^2`` (m,) of the angle between the plane fits (:func:`pca_normals_csr`) of the two
    halves of each list - its entries at even and at odd positions, the query point in
    both - NaN where either half has none: how far the fit's noise alone (the positions',
    and a random sampling's) moves a plane fit of half the points. Its numpy specification:
    :func:`pca_normals_csr` of the two halves' lists."""
    m = query_points.shape[0]
    out = np.full(m, np.nan)
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        cov = np.empty((3, 3))
        ev = np.empty(3)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            lo, hi = indptr[q], indptr[q + 1]
            if not _plane_normal(points, indices, lo, hi, 2, x0, x1, x2, r2max, inv_r,
                                 point_weights, cov, ev):
                continue
            e0, e1, e2 = ev[0], ev[1], ev[2]
            if not _plane_normal(points, indices, lo + 1, hi, 2, x0, x1, x2, r2max, inv_r,
                                 point_weights, cov, ev):
                continue
            cos = e0 * ev[0] + e1 * ev[1] + e2 * ev[2]
            out[q] = max(0.0, 1.0 - cos * cos)
    return out


def pca_normals(points, query_points, indptr, indices, radius, point_weights=None):
    """Normals of the least-squares plane through each query point's neighborhood (PCA).

    Parameters
    ----------
    points : (n, 3) float64; query_points : (m, 3) float64
    indptr, indices : CSR neighbor lists into ``points``; radius : float, model units
    point_weights : (n,) float64 in [0, 1], optional, the neighbors' weights (default 1)

    Returns
    -------
    (m, 3) float64 unit normals with arbitrary sign; NaN with fewer than 3 points in the ball.
    """
    # covariance and its smallest eigenvector (Jacobi, to machine precision) in one kernel
    return pca_normals_csr(np.ascontiguousarray(points, dtype=np.float64),
                                   np.ascontiguousarray(query_points, dtype=np.float64),
                                   indptr, indices, float(radius), point_weights)
