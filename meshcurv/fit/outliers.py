"""Point outliers: each point's residual from a robust cubic fit of its neighborhood, over the
neighborhood's robust noise scale, and the Tukey weight that follows. Compiled kernel
:func:`point_residuals`; its numpy specification is
:func:`meshcurv.fit.outliers_spec.point_residual`.

A stray point (a scanner spike) lies far from the surface its neighbors describe; with it
down-weighted in the later fits (normals, jet, circle fits) it no longer moves its neighbors'
curvature, and it is flagged itself instead of getting a curvature of its own.
"""

import math

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK, ball_offset, smallest_eigvec_jacobi3, solve_sym
from .constants import OUTLIER_ITERATIONS, OUTLIER_SCALE_FLOOR, TUKEY_C
from .jet import _JET_U, _JET_V, _add_monomials

__all__ = ["point_residuals", "outlier_weight", "MAD_SIGMA"]

# Standard deviations per median absolute deviation of Gaussian data.
MAD_SIGMA = 1.4826


@njit(cache=True)
def _pca_frame(q, k, frame, cov, ev):
    """Rows of ``frame`` (3, 3): tangent axes and normal of the least-squares plane of the
    ``k`` offsets ``q[:k]`` (units of the radius) and the origin (the point itself)."""
    c = k + 1.0
    m0 = m1 = m2 = 0.0
    for i in range(k):
        m0 += q[i, 0]
        m1 += q[i, 1]
        m2 += q[i, 2]
    m0 /= c
    m1 /= c
    m2 /= c
    for a in range(3):
        for b in range(3):
            cov[a, b] = 0.0
    for i in range(k):
        d0 = q[i, 0] - m0
        d1 = q[i, 1] - m1
        d2 = q[i, 2] - m2
        cov[0, 0] += d0 * d0
        cov[0, 1] += d0 * d1
        cov[0, 2] += d0 * d2
        cov[1, 1] += d1 * d1
        cov[1, 2] += d1 * d2
        cov[2, 2] += d2 * d2
    cov[0, 0] += m0 * m0       # the origin's own deviation from the centroid
    cov[0, 1] += m0 * m1
    cov[0, 2] += m0 * m2
    cov[1, 1] += m1 * m1
    cov[1, 2] += m1 * m2
    cov[2, 2] += m2 * m2
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]
    smallest_eigvec_jacobi3(cov, ev)
    n0, n1, n2 = ev[0], ev[1], ev[2]
    if abs(n0) < 0.9:
        t0, t1, t2 = 0.0, -n2, n1
    else:
        t0, t1, t2 = n2, 0.0, -n0
    s = 1.0 / math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    frame[0, 0], frame[0, 1], frame[0, 2] = t0 * s, t1 * s, t2 * s
    frame[1, 0] = n1 * frame[0, 2] - n2 * frame[0, 1]
    frame[1, 1] = n2 * frame[0, 0] - n0 * frame[0, 2]
    frame[1, 2] = n0 * frame[0, 1] - n1 * frame[0, 0]
    frame[2, 0], frame[2, 1], frame[2, 2] = n0, n1, n2


@njit(cache=True)
def _cubic(sol, u, v):
    """The cubic height model with coefficients ``sol`` (order of ``_JET_U``) at (u, v)."""
    return (sol[0] * u * u + sol[1] * u * v + sol[2] * v * v + sol[3] * u + sol[4] * v + sol[5]
            + sol[6] * u * u * u + sol[7] * u * u * v + sol[8] * u * v * v + sol[9] * v * v * v)


@njit(parallel=True, cache=True)
def point_residuals(points, query_points, indptr, indices, radius, residual, scale,
                    iterations=OUTLIER_ITERATIONS):
    """Residual of each query point from a robust cubic fit of its neighbors, and their scale.

    In the frame of the neighbors' PCA plane, the heights of the neighbors within ``radius``
    (x itself left out) are fitted by a cubic in (u, v) (10 coefficients, weights
    ``1 - r^2 / radius^2``), first by least squares, then ``iterations`` times reweighted by
    Tukey's biweight ``(1 - (e / (TUKEY_C s))^2)^2`` of each neighbor's residual e, with s
    ``MAD_SIGMA`` times the median |e| of the last fit, at least ``OUTLIER_SCALE_FLOOR *
    radius``. The residual of x is its height above the final fit at x.

    Parameters
    ----------
    points : (n, 3) float64; query_points : (m, 3) float64
    indptr, indices : CSR neighbor lists into ``points``; radius : float, model units
    residual : (m,) float64 output, |height of x - fitted height at x|, model units
    scale : (m,) float64 output, the robust scale s of the final fit, model units
    iterations : int, reweighting rounds

    Both are NaN where the fit is singular (fewer than 11 well-spread neighbors) or x is not
    finite.
    """
    m = query_points.shape[0]
    r2max = radius * radius
    inv_r = 1.0 / radius
    most = 0
    for q in range(m):
        most = max(most, indptr[q + 1] - indptr[q])
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        q3 = np.empty((most, 3))
        uvh = np.empty((most, 3))
        wd = np.empty(most)
        wr = np.empty(most)
        res = np.empty(most)
        mat = np.empty((10, 10))
        rhs = np.empty(10)
        sol = np.empty(10)
        mom = np.empty((7, 7))
        hmom = np.empty((7, 7))
        frame = np.empty((3, 3))
        cov = np.empty((3, 3))
        ev = np.empty(3)
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            residual[q] = np.nan
            scale[q] = np.nan
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            if not np.isfinite(x0 + x1 + x2):
                continue
            k = 0
            for j in range(indptr[q], indptr[q + 1]):
                inside, qx, qy, qz, r2 = ball_offset(points, indices[j], x0, x1, x2, r2max,
                                                      inv_r)
                if not inside:
                    continue
                q3[k, 0] = qx
                q3[k, 1] = qy
                q3[k, 2] = qz
                wd[k] = 1.0 - r2
                wr[k] = 1.0
                k += 1
            if k <= 10:
                continue
            _pca_frame(q3, k, frame, cov, ev)
            for i in range(k):
                for a in range(3):
                    uvh[i, a] = (q3[i, 0] * frame[a, 0] + q3[i, 1] * frame[a, 1]
                                 + q3[i, 2] * frame[a, 2])
            ok = True
            s = 0.0
            for it in range(iterations + 1):
                for a in range(7):
                    for b in range(7):
                        mom[a, b] = 0.0
                        hmom[a, b] = 0.0
                for i in range(k):
                    w = wd[i] * wr[i]
                    if w > 0.0:
                        _add_monomials(mom, w, uvh[i, 0], uvh[i, 1], 6)
                        _add_monomials(hmom, w * uvh[i, 2], uvh[i, 0], uvh[i, 1], 3)
                for a in range(10):
                    rhs[a] = hmom[_JET_U[a], _JET_V[a]]
                    for cc in range(a + 1):
                        mat[a, cc] = mom[_JET_U[a] + _JET_U[cc], _JET_V[a] + _JET_V[cc]]
                if not solve_sym(mat, rhs, 10, sol):
                    ok = False
                    break
                for i in range(k):
                    res[i] = abs(uvh[i, 2] - _cubic(sol, uvh[i, 0], uvh[i, 1]))
                s = max(MAD_SIGMA * np.median(res[:k]), OUTLIER_SCALE_FLOOR)
                if it == iterations:
                    break
                for i in range(k):
                    z = res[i] / (TUKEY_C * s)
                    wr[i] = (1.0 - z * z) ** 2 if z < 1.0 else 0.0
            if not ok:
                continue
            residual[q] = abs(sol[5]) * radius
            scale[q] = s * radius


def outlier_weight(score):
    """Tukey's biweight ``(1 - (score / TUKEY_C)^2)^2`` of outlier scores (|residual| / robust
    scale, :func:`point_residuals`), in [0, 1]: 0 from ``TUKEY_C`` on, 1 where the score is NaN
    (no fit: nothing to judge by)."""
    z = np.asarray(score, dtype=np.float64) / TUKEY_C
    with np.errstate(invalid="ignore"):
        w = np.where(z < 1.0, (1.0 - z * z) ** 2, 0.0)
    return np.where(np.isfinite(z), w, 1.0)
