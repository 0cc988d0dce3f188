"""Numpy specification of the point-outlier pass (:mod:`meshcurv.fit.outliers`): the residual
of one point from a robust (Tukey-reweighted) cubic fit of its neighbors, and their scale."""

import numpy as np

from .constants import OUTLIER_ITERATIONS, OUTLIER_SCALE_FLOOR, TUKEY_C

__all__ = ["point_residual"]

MAD_SIGMA = 1.4826


def point_residual(x, neighbors, radius, iterations=OUTLIER_ITERATIONS):
    """``(residual, scale)`` of x (:func:`meshcurv.fit.outliers.point_residuals` in numpy).

    Parameters
    ----------
    x : (3,) float; neighbors : (k, 3) float, points beyond ``radius`` and x itself ignored
    radius : float, model units; iterations : int, Tukey reweighting rounds

    Returns
    -------
    residual : float, |height of x above the robust cubic fit at x|, model units
    scale : float, the fit's robust scale (MAD of the residuals, floored), model units;
        both NaN with 10 or fewer neighbors or a singular fit
    """
    x = np.asarray(x, dtype=np.float64)
    q = np.asarray(neighbors, dtype=np.float64) - x
    d2 = np.einsum("ij,ij->i", q, q)
    q = q[(d2 > 0) & (d2 <= radius * radius)] / radius
    if len(q) <= 10:
        return np.nan, np.nan
    centred = np.vstack([q, np.zeros(3)])         # x takes part in the plane fit only
    centred = centred - centred.mean(axis=0)
    n = np.linalg.eigh(centred.T @ centred)[1][:, 0]
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    tu = np.cross(a, n)
    tu /= np.linalg.norm(tu)
    tv = np.cross(n, tu)
    u, v, h = q @ tu, q @ tv, q @ n
    design = np.column_stack([u * u, u * v, v * v, u, v, np.ones_like(u),
                              u ** 3, u * u * v, u * v * v, v ** 3])
    wd = 1.0 - np.einsum("ij,ij->i", q, q)
    wr = np.ones(len(q))
    for it in range(iterations + 1):
        w = wd * wr
        lhs = design.T @ (w[:, None] * design)
        if np.linalg.matrix_rank(lhs) < 10:
            return np.nan, np.nan
        coef = np.linalg.solve(lhs, design.T @ (w * h))
        res = np.abs(h - design @ coef)
        s = max(MAD_SIGMA * np.median(res), OUTLIER_SCALE_FLOOR)
        z = res / (TUKEY_C * s)
        wr = np.where(z < 1.0, (1.0 - z * z) ** 2, 0.0)
    return abs(coef[5]) * radius, s * radius
