"""Numpy specification of the local jet (:mod:`meshcurv.fit.jet`): quartic (cubic) and
quadric height fits around one point, for its noise level and refined normal."""

import numpy as np

from .constants import NOISE_SCALE

__all__ = ["local_jet", "tangent_frame"]


def tangent_frame(n):
    """``(tu, tv)``: unit tangents at the unit normal n (3,), tu = e_x x n (e_y x n where
    |n_x| >= 0.9) normalised, tv = n x tu (the kernels' :func:`meshcurv.linalg.normal_frame`)."""
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    tu = np.cross(a, n)
    tu /= np.linalg.norm(tu)
    return tu, np.cross(n, tu)


def local_jet(x, n, neighbors, radius, point_weights=None):
    """Quartic (cubic) and quadric height fits around x (:func:`meshcurv.fit.jet.local_jet` in
    numpy).

    Parameters
    ----------
    x, n : (3,) float, the point and its initial unit normal
    neighbors : (k, 3) float; points beyond ``radius`` and x itself are ignored
    radius : float, model units
    point_weights : (k,) float in [0, 1], optional, per neighbor: multiplies its weight;
        neighbors of weight 0 are left out (the outlier pass's weights)

    Returns
    -------
    normal : (3,) float, unit normal at x, on n's side, of the quartic's (cubic's) gradient
        (the cubic's where its standard error is the smaller) where the noise is low and the
        quadric's where it is high, mixed by
        ``1 / (1 + (noise / (NOISE_SCALE radius))^4)``; n itself when a fit is singular or
        the normal would tilt by more than 30 degrees (the kernel's refined normal, in place
        or in its ``refined`` output)
    noise : float, RMS height residual of the quartic fit (15 coefficients), or of the cubic
        (10) where the quartic is singular or 15 points are all there is, model units,
        corrected for the coefficients; NaN when both are singular
    """
    x = np.asarray(x, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    tu, tv = tangent_frame(n)
    q = np.asarray(neighbors, dtype=np.float64) - x
    d2 = np.einsum("ij,ij->i", q, q)
    pw = np.ones(len(q)) if point_weights is None else np.asarray(point_weights, float)
    use = (d2 > 0) & (d2 <= radius * radius) & (pw > 0)
    q = np.vstack([np.zeros(3), q[use] / radius])  # x included
    u, v, h = q @ tu, q @ tv, q @ n
    design = np.column_stack([u * u, u * v, v * v, u, v, np.ones_like(u),
                              u ** 3, u * u * v, u * v * v, v ** 3,
                              u ** 4, u ** 3 * v, u * u * v * v, u * v ** 3, v ** 4])
    w = (1 - np.einsum("ij,ij->i", q, q)) * np.concatenate([[1.0], pw[use]])
    w[0] = 1.0
    lhs = design.T @ (w[:, None] * design)
    for npar in (15, 10):
        if len(q) > npar and _solvable(lhs[:npar, :npar]):
            break
    else:
        return n, np.nan
    coef = np.linalg.solve(lhs[:npar, :npar], design[:, :npar].T @ (w * h))
    noise = np.sqrt(np.sum(w * (h - design[:, :npar] @ coef) ** 2) / w.sum() * len(q)
                    / (len(q) - npar))
    if npar == 15 and _solvable(lhs[:10, :10]):
        # the cubic's gradient where its standard error is the smaller
        cubic = np.linalg.solve(lhs[:10, :10], design[:, :10].T @ (w * h))
        se = [max(np.sum(w * (h - design[:, :p] @ c) ** 2), 0.0) / (len(q) - p)
              * np.trace(np.linalg.inv(lhs[:p, :p])[3:5, 3:5])
              for p, c in ((10, cubic), (15, coef))]
        if se[0] < se[1]:
            coef = np.concatenate([cubic, np.zeros(5)])
    quadric = np.linalg.solve(lhs[:6, :6], design[:, :6].T @ (w * h))
    clean = 1 / (1 + (noise / NOISE_SCALE) ** 4)
    gu, gv = quadric[3:5] + clean * (coef[3:5] - quadric[3:5])
    if gu ** 2 + gv ** 2 > 1 / 3:
        return n, noise * radius
    g = n - gu * tu - gv * tv
    return g / np.linalg.norm(g), noise * radius


def _solvable(lhs):
    """Whether the kernel's Cholesky solves the normal equations ``lhs``: every pivot above
    1e-12 of its diagonal entry, and above 1e-12 (:func:`meshcurv.linalg.solve_sym`)."""
    try:
        pivots = np.diag(np.linalg.cholesky(lhs)) ** 2
    except np.linalg.LinAlgError:
        return False
    return bool(np.all(pivots > 1e-12 * np.maximum(1.0, np.abs(np.diag(lhs)))))
