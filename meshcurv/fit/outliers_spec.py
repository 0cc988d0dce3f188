"""Numpy specification of the point-outlier pass (:mod:`meshcurv.fit.outliers`): the residual
of one point from a robust (Tukey-reweighted) height fit of its neighbors, and its scale."""

import numpy as np

from .constants import OUTLIER_ITERATIONS, OUTLIER_MAX_REJECTED, OUTLIER_SCALE_FLOOR, TUKEY_C

__all__ = ["point_residual"]

MAD_SIGMA = 1.4826


def point_residual(x, neighbors, radius, iterations=OUTLIER_ITERATIONS):
    """``(residual, scale, dof)`` of x (:func:`meshcurv.fit.outliers.point_residuals` in numpy).

    Parameters
    ----------
    x : (3,) float; neighbors : (k, 3) float, points beyond ``radius`` and x itself ignored
    radius : float, model units; iterations : int, most Tukey reweighting rounds (none
        more once no residual reaches ``TUKEY_C`` scales)

    Returns
    -------
    residual : float, |height of x above the robust fit at x| (a cubic from 30 neighbors, a
        quadric from 18, a plane from 6), model units
    scale : float, the robust scale of that residual (biweight midvariance of the fit's
        residuals, the reweighting itself by their MAD; corrected
        for its p coefficients, floored, times ``sqrt(1 + c)`` with c the fitted height's
        variance at x per unit noise), model units; both NaN with fewer than 6 neighbors or
        a singular fit, or a fit whose robust weights left out more than
        ``OUTLIER_MAX_REJECTED`` of the neighbors
    dof : int, k - p, the neighbors less the fitted coefficients (0 where no fit)
    """
    x = np.asarray(x, dtype=np.float64)
    q = np.asarray(neighbors, dtype=np.float64) - x
    d2 = np.einsum("ij,ij->i", q, q)
    q = q[(d2 > 0) & (d2 <= radius * radius)] / radius
    k = len(q)
    p = 10 if k >= 30 else 6 if k >= 18 else 3 if k >= 6 else 0   # 3 points per coefficient
    if p == 0:
        return np.nan, np.nan, 0
    wd = 1.0 - np.einsum("ij,ij->i", q, q)
    wr = np.ones(len(q))
    for it in range(iterations + 1):
        # the plane of the neighbors (x left out), weighted by the robust weights so far
        mean = wr @ q / wr.sum()
        n = np.linalg.eigh((wr[:, None] * (q - mean)).T @ (q - mean))[1][:, 0]
        a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        tu = np.cross(a, n)
        tu /= np.linalg.norm(tu)
        tv = np.cross(n, tu)
        u, v, h = q @ tu, q @ tv, q @ n
        design = np.column_stack([u, v, np.ones_like(u), u * u, u * v, v * v,
                                  u ** 3, u * u * v, u * v * v, v ** 3])[:, :p]
        w = wd * wr
        lhs = design.T @ (w[:, None] * design)
        if np.linalg.matrix_rank(lhs) < p:
            return np.nan, np.nan, 0
        coef = np.linalg.solve(lhs, design.T @ (w * h))
        res = np.abs(h - design @ coef)
        s = max(MAD_SIGMA * np.median(res) * np.sqrt(k / (k - p)),
                OUTLIER_SCALE_FLOOR)
        if it == iterations:
            break
        if res.max() <= TUKEY_C * s:
            break                   # no neighbor to down-weight
        z = res / (TUKEY_C * s)
        wr = np.where(z < 1.0, (1.0 - z * z) ** 2, 0.0)
    if np.count_nonzero(wr == 0.0) > OUTLIER_MAX_REJECTED * k:
        return np.nan, np.nan, 0
    # biweight midvariance of the final residuals
    u = res / (9.0 * np.median(res))
    inner = u < 1.0
    bi = np.sqrt(k * np.sum(res[inner] ** 2 * (1 - u[inner] ** 2) ** 4)) / abs(
        np.sum((1 - u[inner] ** 2) * (1 - 5 * u[inner] ** 2))) if np.median(res) > 0 else 0.0
    s = max(bi * np.sqrt(k / (k - p)), OUTLIER_SCALE_FLOOR)
    # variance of the fitted height at x per unit noise, plus x's own noise
    e = np.linalg.solve(lhs, np.eye(p)[2])
    spread = e @ (design.T @ ((w * w)[:, None] * design)) @ e
    return abs(coef[2]) * radius, s * np.sqrt(1.0 + spread) * radius, k - p
