"""Numpy specification of the ring jets (:mod:`meshcurv.fit.ring_jet`): quartic height fits
over a small and a larger support around one vertex."""

import numpy as np

from .jet_spec import tangent_frame
from .ring_jet import MIN_ROWS, ROUNDING

__all__ = ["ring_jet", "shape_operator"]

# Exponents (of u, of v) of the quartic's terms, in the kernel's order: u^2, uv, v^2, u, v, 1,
# then the cubic's and the quartic's.
_U = np.array([2, 1, 0, 1, 0, 0, 3, 2, 1, 0, 4, 3, 2, 1, 0])
_V = np.array([0, 1, 2, 0, 1, 0, 0, 1, 2, 3, 0, 1, 2, 3, 4])


def shape_operator(coefficients):
    """(2, 2) shape operator at u = v = 0 of the height function with these quartic
    coefficients (kernel order), in the orthonormal basis of its tangent plane that is
    (tu, tv) tilted onto it: ``-I^(-1/2) H I^(-1/2) / sqrt(1 + |g|^2)`` (g the gradient, H
    the Hessian, I = 1 + g g^T); convex positive."""
    c = np.asarray(coefficients, dtype=np.float64)
    g = c[3:5]
    hess = np.array([[2.0 * c[0], c[1]], [c[1], 2.0 * c[2]]])
    first = np.eye(2) + np.outer(g, g)
    w, vecs = np.linalg.eigh(first)
    root_inv = vecs @ np.diag(1.0 / np.sqrt(w)) @ vecs.T
    return -root_inv @ hess @ root_inv / np.sqrt(1.0 + g @ g)


def ring_jet(x, n, neighbors, inner):
    """The quartic fits of :func:`meshcurv.fit.ring_jet.ring_jet` at one vertex, in numpy.

    Parameters
    ----------
    x, n : (3,) float, the vertex and its unit normal
    neighbors : (k, 3) float, its neighbours (x itself and non-finite rows are skipped)
    inner : int, how many leading rows form the small support

    Returns
    -------
    small, large : (3,) float, ``(S_uu, S_uv, S_vv)`` of the small and the larger support's
        fit (NaN where fewer than MIN_ROWS points, x included, or singular)
    error : float, the small fit's misfit bound on those entries (the largest):
        ``sqrt(RSS * (A^T A)^-1_kk)``, times 2 for S_uu and S_vv, each residual at least
        ``ROUNDING * max|x_i|``
    tu : (3,) float, the frame's first tangent (e_x x n, or e_y x n where |n_x| >= 0.9)
    rows : int, the points of the small fit (x included; 0 where it is not fitted)
    """
    x = np.asarray(x, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    tu, tv = tangent_frame(n)
    d = np.asarray(neighbors, dtype=np.float64) - x
    keep = np.isfinite(d).all(axis=1) & (np.abs(d).sum(axis=1) > 0)
    first = keep & (np.arange(len(d)) < inner)
    small = large = np.full(3, np.nan)
    error = np.nan
    rows = 0
    if first.sum() + 1 < MIN_ROWS:
        return small, large, error, tu, rows
    scale = np.sqrt(np.mean(np.sum(d[first] ** 2, axis=1)))
    for support in (first, keep):
        p = np.vstack([np.zeros(3), d[support] / scale])
        u, v, h = p @ tu, p @ tv, p @ n
        design = u[:, None] ** _U * v[:, None] ** _V
        gram = design.T @ design
        if len(p) < MIN_ROWS or np.linalg.cond(gram) > 1e12:
            break
        coef = np.linalg.solve(gram, design.T @ h)
        s = shape_operator(coef) / scale
        entries = np.array([s[0, 0], s[0, 1], s[1, 1]])
        if support is keep:
            large = entries
            continue
        small = entries
        rounding = ROUNDING * np.abs(x).max() / scale
        rss = np.sum((h - design @ coef) ** 2) + len(p) * rounding ** 2
        factor = np.linalg.inv(gram).diagonal()[:3] * np.array([4.0, 1.0, 4.0])
        error = np.sqrt(rss * factor.max()) / scale
        rows = len(p)
    return small, large, error, tu, rows
