"""Plain numpy reference of the estimator, one point at a time.

Slow and readable: the paper's steps for a single point, built from :mod:`meshcurv.cga` and
:mod:`meshcurv.sinefit`. It exists to check the compiled kernel
(:func:`meshcurv.kernels.curvature_cga`), which must agree with it to round-off.
"""

import numpy as np

from .cga import fit_normal_circle
from .sinefit import fit_euler

__all__ = ["curvature_at_point"]


def _tangent_u(q, n):
    """First neighbour offset at least 30 degrees off the normal, made tangential and unit."""
    for qj in q:
        t = qj - (qj @ n) * n
        if t @ t > 0.25 * (qj @ qj) and t @ t > 0:
            return t / np.linalg.norm(t)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = a - (a @ n) * n
    return t / np.linalg.norm(t)


def curvature_at_point(x, n, neighbours, radius, n_directions=8, slab=0.25, min_points=3,
                       min_spread=0.25, weighted=False, corrected=True, half_frequency=False,
                       robust=True):
    """Principal curvatures at one point from its neighbours (the kernel's contract, in numpy).

    Parameters
    ----------
    x : (3,) float, the point; n : (3,) float, its unit normal (outward)
    neighbours : (k, 3) float, candidate neighbours in list order (x itself and points beyond
        ``radius`` are ignored)
    radius : float, model units; ``slab`` and ``min_spread`` are fractions of it
    other parameters : as in :func:`meshcurv.principal_curvatures`

    Returns
    -------
    k1, k2 : float (NaN if undefined); d1 : (3,) float; n_samples : int; residual : float
    """
    x = np.asarray(x, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    n = n / np.linalg.norm(n)
    q = np.asarray(neighbours, dtype=np.float64) - x
    d2 = np.einsum("ij,ij->i", q, q)
    q = q[(d2 > 0) & (d2 <= radius * radius)]
    tu = _tangent_u(q, n)
    tv = np.cross(n, tu)
    q = q / radius  # all fits in units of the radius
    u, v, h = q @ tu, q @ tv, q @ n
    keep = u * u + v * v > 0
    q, u, v = q[keep], u[keep], v[keep]
    r2 = np.einsum("ij,ij->i", q, q)
    phi = np.arctan2(v, u)
    w = (1 - r2) ** 2 if weighted else np.ones(len(q))

    kappas, rows, planes = [], [], set()
    for i in range(n_directions):
        alpha = i * np.pi / n_directions
        dist = -np.sin(alpha) * u + np.cos(alpha) * v    # distance to plane i (through x)
        along = np.cos(alpha) * u + np.sin(alpha) * v    # coordinate along the plane's tangent
        in_slab = np.abs(dist) <= slab
        for side, half in enumerate([in_slab & (along >= 0), in_slab & (along < 0)]):
            if half.sum() < min_points or np.abs(along[half]).max(initial=0) < min_spread:
                continue
            pts = np.vstack([np.zeros(3), q[half]])          # x itself is in every half-set
            wt = np.concatenate([[1.0], w[half]])
            kappa, _ = fit_normal_circle(pts, n, wt)
            theta = alpha + side * np.pi
            if corrected:
                # the blend of directions this half-set measured (see kernels._sample_design)
                rr = np.concatenate([[0.0], r2[half]])
                wp = wt * rr * (rr - np.sum(wt * rr) / wt.sum())
                c = np.sum(wp[1:] * np.cos(2 * phi[half])) / wp.sum()
                s = np.sum(wp[1:] * np.sin(2 * phi[half])) / wp.sum()
            else:
                c, s = np.cos(2 * theta), np.sin(2 * theta)
            row = [1.0, c, s] + ([np.cos(theta), np.sin(theta)] if half_frequency else [])
            kappas.append(kappa)
            rows.append(row)
            planes.add(i)
    if len(planes) < 3 or len(kappas) < 5:
        return np.nan, np.nan, np.full(3, np.nan), len(kappas), np.nan
    k1, k2, theta1, rms, used = fit_euler(np.array(rows), np.array(kappas), robust=robust)
    if not np.isfinite(k1):
        return np.nan, np.nan, np.full(3, np.nan), len(kappas), np.nan
    d1 = np.cos(theta1) * tu + np.sin(theta1) * tv
    return k1 / radius, k2 / radius, d1, int(used.sum()), rms / radius
