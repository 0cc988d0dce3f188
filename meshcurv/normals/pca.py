"""PCA normals: the normal of the least-squares plane through each point's neighborhood.
Compiled kernel :func:`pca_normals_csr` and its wrapper :func:`pca_normals`.
"""

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK, ball_offset, normal_frame, smallest_eigvec_jacobi3, solve_sym

__all__ = ["pca_normals", "pca_normals_csr", "plane_agreement", "split_disagreement"]


@njit(cache=True)
def _neighbor(points, indices, j, x0, x1, x2, r2max, inv_r, point_weights):
    """``(w, a, b, d)``: the weight of the neighbor ``indices[j]`` (``point_weights``, default
    1) and its offset from (x0, x1, x2) in units of the radius; w = 0 where it is outside the
    ball, coincident with the point or weighted 0 (:func:`meshcurv.linalg.ball_offset`)."""
    inside, a, b, d, _ = ball_offset(points, indices[j], x0, x1, x2, r2max, inv_r)
    w = 0.0
    if inside:
        w = 1.0 if point_weights is None else max(point_weights[indices[j]], 0.0)
    return w, a, b, d


@njit(cache=True)
def _plane_normal(points, indices, lo, hi, x0, x1, x2, r2max, inv_r, point_weights, cov, ev):
    """Unit normal of the least-squares plane through (x0, x1, x2) and the neighbors
    ``indices[lo:hi]`` within the ball (``r2max`` squared radius, ``inv_r`` its inverse;
    see :func:`pca_normals_csr`) into ``ev``; False where it has none (fewer than 3 points, a
    covariance that is not finite). ``cov`` (3, 3) is scratch; with True it holds the
    covariance's eigenvalues (units of the radius squared) on its diagonal."""
    s0 = s1 = s2 = 0.0
    s00 = s01 = s02 = s11 = s12 = s22 = 0.0
    c = 1.0
    k = 1
    for j in range(lo, hi):
        w, a, b, d = _neighbor(points, indices, j, x0, x1, x2, r2max, inv_r, point_weights)
        if w == 0.0:
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


@njit(cache=True)
def _sorted_eigenvalues(cov):
    """``(l1, l2, l3)``, ascending: the eigenvalues :func:`_plane_normal` leaves on the
    diagonal of ``cov``."""
    a, b, c = cov[0, 0], cov[1, 1], cov[2, 2]
    return min(a, b, c), max(min(a, b), min(max(a, b), c)), max(a, b, c)


@njit(cache=True)
def _ball_plane(points, indices, indptr, q, query_points, r2max, inv_r, point_weights, cov,
                nrm):
    """:func:`_plane_normal` of the ball of query point q (its list ``indices[indptr[q]:
    indptr[q + 1]]``) into ``nrm``, with its covariance's eigenvalues ascending: ``(ok, l1,
    l2, l3)`` (units of the radius squared; NaN where not ok)."""
    if not _plane_normal(points, indices, indptr[q], indptr[q + 1], query_points[q, 0],
                         query_points[q, 1], query_points[q, 2], r2max, inv_r, point_weights,
                         cov, nrm):
        return False, np.nan, np.nan, np.nan
    l1, l2, l3 = _sorted_eigenvalues(cov)
    return True, l1, l2, l3


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
            if _plane_normal(points, indices, indptr[q], indptr[q + 1], query_points[q, 0],
                             query_points[q, 1], query_points[q, 2], r2max, inv_r,
                             point_weights, cov, ev):
                out[q, 0] = ev[0]
                out[q, 1] = ev[1]
                out[q, 2] = ev[2]
    return out


@njit(parallel=True, cache=True)
def plane_agreement(points, query_points, normals, indptr, indices, radius, flatness,
                    point_weights=None):
    """``|cos|`` (m,) of the angle between each query point's unit normal ``normals[q]`` and
    the normal of the least-squares plane through its neighborhood (:func:`pca_normals_csr`'s),
    whatever their signs: 1 where they agree, 0 where the normal lies in that plane. NaN where
    the plane fit has none, the normal is not finite, or the ball is no patch of surface:
    its covariance's smallest eigenvalue above ``flatness`` times the middle one (a blob of
    noise), or the middle one below 1e-6 times the largest (one line of points: a spread
    across it under a thousandth of its length), where the plane's normal is arbitrary.
    Its numpy specification: ``agreement_spec`` in tests/test_normals_pca.py."""
    m = query_points.shape[0]
    out = np.full(m, np.nan)
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        cov = np.empty((3, 3))
        nrm = np.empty(3)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            ok, l1, l2, l3 = _ball_plane(points, indices, indptr, q, query_points, r2max,
                                         inv_r, point_weights, cov, nrm)
            if not (ok and l1 <= flatness * l2 and l2 > 1e-6 * l3):
                continue
            cos = abs(normals[q, 0] * nrm[0] + normals[q, 1] * nrm[1] + normals[q, 2] * nrm[2])
            if np.isfinite(cos):
                out[q] = cos
    return out


@njit(parallel=True, cache=True)
def ball_spread(points, query_points, indptr, indices, radius, point_weights=None):
    """The eigenvalues (m, 3), ascending, of the covariance of each query point's ball (the
    query point and its neighbors within ``radius``, weighted as in
    :func:`pca_normals_csr`), in units of ``radius`` squared; NaN rows where the plane fit has
    none (fewer than 3 points, a covariance that is not finite).

    The smallest over the middle one is the ball's flatness: 0 for a flat patch; a
    spherical cap whose rim lies at angle T from its centre, evenly sampled, gives
    ``(1 - cos T) / (2 (2 + cos T))`` (1/4 at 90 degrees, 1/2 at 120); near 1 for a ball
    holding a tube's whole section, or a blob."""
    m = query_points.shape[0]
    out = np.full((m, 3), np.nan)
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        cov = np.empty((3, 3))
        nrm = np.empty(3)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            _, out[q, 0], out[q, 1], out[q, 2] = _ball_plane(
                points, indices, indptr, q, query_points, r2max, inv_r, point_weights, cov, nrm)
    return out


# Terms of the height models of :func:`split_disagreement` in the ball's tangent frame (u, v):
# the whole ball's quadric (u, v, 1, u^2, u v, v^2) and each half's plane (the first three).
_QUADRIC_TERMS = 6
_PLANE_TERMS = 3


@njit(cache=True)
def _height_fit(points, indices, lo, hi, stride, x0, x1, x2, r2max, inv_r, point_weights,
                frame, terms, bend, phi, mat, rhs, sol):
    """Weighted least-squares fit of the heights ``h - bend . (u^2, u v, v^2)`` of (x0, x1, x2)
    (u = v = h = 0, weight 1) and the neighbors ``indices[lo:hi:stride]`` within the ball, in
    the frame ``frame`` (rows t1, t2, normal; offsets in units of the radius), by the first
    ``terms`` of (u, v, 1, u^2, u v, v^2); coefficients into ``sol``. False where it has
    none (fewer points than terms, a singular system). ``phi``, ``rhs`` (6,), ``mat`` (6, 6):
    scratch."""
    for a in range(terms):
        rhs[a] = 0.0
        for b in range(terms):
            mat[a, b] = 0.0
    mat[2, 2] = 1.0
    k = 1
    for j in range(lo, hi, stride):
        w, qx, qy, qz = _neighbor(points, indices, j, x0, x1, x2, r2max, inv_r, point_weights)
        if w == 0.0:
            continue
        k += 1
        u = qx * frame[0, 0] + qy * frame[0, 1] + qz * frame[0, 2]
        v = qx * frame[1, 0] + qy * frame[1, 1] + qz * frame[1, 2]
        h = qx * frame[2, 0] + qy * frame[2, 1] + qz * frame[2, 2]
        phi[0] = u
        phi[1] = v
        phi[2] = 1.0
        phi[3] = u * u
        phi[4] = u * v
        phi[5] = v * v
        h -= bend[0] * phi[3] + bend[1] * phi[4] + bend[2] * phi[5]
        for a in range(terms):
            wa = w * phi[a]
            rhs[a] += wa * h
            for b in range(a + 1):
                mat[a, b] += wa * phi[b]
    return k >= terms and solve_sym(mat, rhs, terms, sol)


@njit(parallel=True, cache=True)
def split_disagreement(points, query_points, indptr, indices, radius, point_weights=None):
    """How far noise alone moves a plane fit of half of each ball: ``sin^2`` (m,) of the
    angle between the tangent planes at each query point of the two halves of its list (its
    entries at even and at odd positions, the query point in both), times
    ``(l2 / (l2 - l1))^2``; NaN where there is none.

    Each half's plane is a least-squares height fit in the frame of the whole ball's plane fit
    (:func:`pca_normals_csr`: covariance eigenvalues l1 <= l2 <= l3) after the whole ball's
    quadric part is taken off its heights: where the surface bends, a plane fit of an uneven
    half (every other point of a regular sampling) tilts with the curvature, which is not
    noise (clean icosphere of 10242 vertices, radius 0.3: sin^2 2e-4 with plain plane fits of
    the halves, 1e-8 with this). The factor is how much more a plane fit's normal (the
    covariance's smallest eigenvector) tilts under noise than a height fit's: it grows as the
    noise's variance l1 approaches the ball's spread l2 (measured on noisy planes, noise 2-26
    % of the radius: the ratio of the plane fits' disagreement over the radius and twice it
    to this stays within 0.39-0.52; without the factor it doubles). Its numpy specification:
    ``split_spec`` in tests/test_normals_pca.py."""
    m = query_points.shape[0]
    out = np.full(m, np.nan)
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        cov = np.empty((3, 3))
        nrm = np.empty(3)
        frame = np.empty((3, 3))
        flat = np.zeros(3)
        bend = np.empty(3)
        phi = np.empty(_QUADRIC_TERMS)
        mat = np.empty((_QUADRIC_TERMS, _QUADRIC_TERMS))
        rhs = np.empty(_QUADRIC_TERMS)
        sol = np.empty(_QUADRIC_TERMS)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            lo, hi = indptr[q], indptr[q + 1]
            if not _plane_normal(points, indices, lo, hi, x0, x1, x2, r2max, inv_r,
                                 point_weights, cov, nrm):
                continue
            l1, l2, _ = _sorted_eigenvalues(cov)
            normal_frame(nrm[0], nrm[1], nrm[2], frame)
            if not _height_fit(points, indices, lo, hi, 1, x0, x1, x2, r2max, inv_r,
                               point_weights, frame, _QUADRIC_TERMS, flat, phi, mat, rhs, sol):
                continue
            bend[0], bend[1], bend[2] = sol[3], sol[4], sol[5]
            if not _height_fit(points, indices, lo, hi, 2, x0, x1, x2, r2max, inv_r,
                               point_weights, frame, _PLANE_TERMS, bend, phi, mat, rhs, sol):
                continue
            a0, a1 = sol[0], sol[1]
            if not _height_fit(points, indices, lo + 1, hi, 2, x0, x1, x2, r2max, inv_r,
                               point_weights, frame, _PLANE_TERMS, bend, phi, mat, rhs, sol):
                continue
            b0, b1 = sol[0], sol[1]
            cos = (a0 * b0 + a1 * b1 + 1.0) / np.sqrt((1.0 + a0 * a0 + a1 * a1)
                                                     * (1.0 + b0 * b0 + b1 * b1))
            gap = l2 / (l2 - l1) if l2 > l1 else np.inf
            out[q] = max(0.0, 1.0 - cos * cos) * gap * gap
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
