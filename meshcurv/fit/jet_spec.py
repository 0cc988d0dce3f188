"""Numpy specification of the local jet (:mod:`meshcurv.fit.jet`): cubic and quadric height
fits around one point, for its noise level and refined normal."""

import numpy as np

__all__ = ["local_jet"]


def local_jet(x, n, neighbors, radius, point_weights=None):
    """Cubic and quadric height fits around x (:func:`meshcurv.fit.jet.local_jet` in numpy).

    Parameters
    ----------
    x, n : (3,) float, the point and its initial unit normal
    neighbors : (k, 3) float; points beyond ``radius`` and x itself are ignored
    radius : float, model units
    point_weights : (k,) float in [0, 1], optional, per neighbor: multiplies its weight;
        neighbors of weight 0 are left out (the outlier pass's weights)

    Returns
    -------
    normal : (3,) float, unit normal of the fitted quadric at x, on n's side; n itself when a
        fit is singular or the quadric would tilt it by more than 30 degrees
    noise : float, RMS height residual of the cubic fit, model units, corrected for its 10
        coefficients; NaN when the fit is singular
    """
    x = np.asarray(x, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    tu = np.cross(a, n)
    tu /= np.linalg.norm(tu)
    tv = np.cross(n, tu)
    q = np.asarray(neighbors, dtype=np.float64) - x
    d2 = np.einsum("ij,ij->i", q, q)
    pw = np.ones(len(q)) if point_weights is None else np.asarray(point_weights, float)
    use = (d2 > 0) & (d2 <= radius * radius) & (pw > 0)
    q = np.vstack([np.zeros(3), q[use] / radius])  # x included
    u, v, h = q @ tu, q @ tv, q @ n
    design = np.column_stack([u * u, u * v, v * v, u, v, np.ones_like(u),
                              u ** 3, u * u * v, u * v * v, v ** 3])
    w = (1 - np.einsum("ij,ij->i", q, q)) * np.concatenate([[1.0], pw[use]])
    w[0] = 1.0
    lhs = design.T @ (w[:, None] * design)
    if len(q) <= 10 or np.linalg.matrix_rank(lhs) < 10:
        return n, np.nan
    coef = np.linalg.solve(lhs, design.T @ (w * h))
    noise = np.sqrt(np.sum(w * (h - design @ coef) ** 2) / w.sum() * len(q) / (len(q) - 10))
    coef = np.linalg.solve(lhs[:6, :6], design[:, :6].T @ (w * h))   # the quadric
    if coef[3] ** 2 + coef[4] ** 2 > 1 / 3:
        return n, noise * radius
    g = n - coef[3] * tu - coef[4] * tv
    return g / np.linalg.norm(g), noise * radius
