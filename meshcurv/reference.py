"""Plain numpy reference of the estimator, one point at a time.

Slow and readable: the paper's steps for a single point, built from :mod:`meshcurv.cga` and
:mod:`meshcurv.sinefit`. It exists to check the compiled kernel
(:func:`meshcurv.kernels.curvature_cga`), which must agree with it to round-off.
"""

import numpy as np

from .cga import fit_normal_circle
from .kernels import MIN_DIRECTION_SPREAD, PLANE_OFFSET, WEIGHT_POWER
from .sinefit import fit_euler

__all__ = ["curvature_at_point", "local_jet"]


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
                       min_spread=0.25, blend=1.0, circle_normalization="tangent",
                       section_blend=True, half_frequency=False, robust=True):
    """Principal curvatures at one point from its neighbours (the kernel's contract, in numpy).

    Parameters
    ----------
    x : (3,) float, the point; n : (3,) float, its unit normal (outward)
    neighbours : (k, 3) float, candidate neighbours sorted by vertex index (x itself and points
        beyond ``radius`` are ignored); the first one at least 30 degrees off the normal sets
        the tangent frame, as the lowest-index one does in the kernel
    radius : float, model units; ``slab`` and ``min_spread`` are fractions of it
    blend : float in [0, 1], weights ``(1 - blend) + blend (1 - r^2 / radius^2)^WEIGHT_POWER``
        (see :func:`meshcurv.api.weight_blend`)
    other parameters : as in :func:`meshcurv.principal_curvatures`

    Returns
    -------
    dict with k1, k2 (float, NaN if undefined, 1 / model units), d1 ((3,) unit), n_samples
    (int, circle fits kept) and residual (float, RMS of the Euler fit, 1 / model units)
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
    u, v = q @ tu, q @ tv
    keep = u * u + v * v > 0
    q, u, v = q[keep], u[keep], v[keep]
    r2 = np.einsum("ij,ij->i", q, q)
    phi = np.arctan2(v, u)
    w = (1 - blend) + blend * (1 - r2) ** WEIGHT_POWER

    kappas, rows, mixes, planes = [], [], [], set()
    for i in range(n_directions):
        alpha = (i + PLANE_OFFSET) * np.pi / n_directions
        dist = -np.sin(alpha) * u + np.cos(alpha) * v    # distance to plane i (through x)
        along = np.cos(alpha) * u + np.sin(alpha) * v    # coordinate along the plane's tangent
        in_slab = np.abs(dist) <= slab
        for side, half in enumerate([in_slab & (along >= 0), in_slab & (along < 0)]):
            if half.sum() < min_points or np.abs(along[half]).max(initial=0) < min_spread:
                continue
            pts = np.vstack([np.zeros(3), q[half]])          # x itself is in every half-set
            wt = np.concatenate([[1.0], w[half]])
            kappa, _ = fit_normal_circle(pts, n, wt, circle_normalization)
            if not np.isfinite(kappa):
                continue
            theta = alpha + side * np.pi
            # the blend of directions this half-set measured (see kernels._sample_design)
            rr = np.concatenate([[0.0], r2[half]])
            wp = wt * rr * (rr - np.sum(wt * rr) / wt.sum())
            if wp.sum() > 0:
                mix = (np.sum(wp[1:] * np.cos(2 * phi[half])) / wp.sum(),
                       np.sum(wp[1:] * np.sin(2 * phi[half])) / wp.sum())
            else:
                mix = (np.cos(2 * theta), np.sin(2 * theta))
            c, s = mix if section_blend else (np.cos(2 * theta), np.sin(2 * theta))
            row = [1.0, c, s] + ([np.cos(theta), np.sin(theta)] if half_frequency else [])
            kappas.append(kappa)
            rows.append(row)
            mixes.append(mix)
            planes.add(i)
    out = dict(k1=np.nan, k2=np.nan, d1=np.full(3, np.nan), n_samples=len(kappas),
               residual=np.nan)
    if len(planes) < 3 or len(kappas) < 5:
        return out
    k1, k2, theta1, rms, used = fit_euler(np.array(rows), np.array(kappas), robust=robust)
    if not np.isfinite(k1):
        return out
    # the measured directions must span the Euler model (not all along one curve)
    if np.linalg.eigvalsh(np.cov(np.array(mixes)[used].T, bias=True))[0] < MIN_DIRECTION_SPREAD:
        return out
    out.update(k1=k1 / radius, k2=k2 / radius, d1=np.cos(theta1) * tu + np.sin(theta1) * tv,
               n_samples=int(used.sum()), residual=rms / radius)
    return out


def local_jet(x, n, neighbours, radius):
    """Cubic and quadric height fits around x (:func:`meshcurv.kernels.local_jet` in numpy).

    Parameters
    ----------
    x, n : (3,) float, the point and its initial unit normal
    neighbours : (k, 3) float; points beyond ``radius`` and x itself are ignored
    radius : float, model units

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
    q = np.asarray(neighbours, dtype=np.float64) - x
    d2 = np.einsum("ij,ij->i", q, q)
    q = np.vstack([np.zeros(3), q[(d2 > 0) & (d2 <= radius * radius)] / radius])  # x included
    u, v, h = q @ tu, q @ tv, q @ n
    design = np.column_stack([u * u, u * v, v * v, u, v, np.ones_like(u),
                              u ** 3, u * u * v, u * v * v, v ** 3])
    w = 1 - np.einsum("ij,ij->i", q, q)
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
