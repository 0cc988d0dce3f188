"""Numpy specification of the sphere-fit normals (:mod:`meshcurv.normals.sphere`): the
Pratt-normalised algebraic sphere/plane fit around one point, by the generalised eigenproblem
solved directly (``N^-1 M``, an unsymmetric 5x5 eigenproblem) instead of the kernel's two
symmetric ones."""

import numpy as np

__all__ = ["pratt_sphere", "sphere_normal"]

# Pratt's normalisation matrix: U^T N U = |u|^2 - 4 u0 u4 for U = (u0, u1, u2, u3, u4).
PRATT = np.array([[0, 0, 0, 0, -2], [0, 1, 0, 0, 0], [0, 0, 1, 0, 0], [0, 0, 0, 1, 0],
                  [-2, 0, 0, 0, 0]], dtype=np.float64)


def pratt_sphere(p, w):
    """The sphere/plane u0 + u.p + u4 |p|^2 = 0 minimising sum w (u0 + u.p + u4 |p|^2)^2 with
    |u|^2 - 4 u0 u4 = 1.

    Parameters
    ----------
    p : (k, 3) float, points; w : (k,) float, positive weights

    Returns
    -------
    (5,) float (u0, u1, u2, u3, u4), or None when no eigenvector has U^T N U > 0.
    """
    z = np.column_stack([np.ones(len(p)), p, np.einsum("ij,ij->i", p, p)])
    m = z.T @ (w[:, None] * z)
    lam, vec = np.linalg.eig(np.linalg.solve(PRATT, m))     # M U = lambda N U
    best = None
    for k in np.flatnonzero(np.abs(lam.imag) <= 1e-9 * max(1.0, np.abs(lam).max())):
        u = vec[:, k].real
        pratt = u @ PRATT @ u
        if pratt > 0:
            obj = max(u @ m @ u, 0.0) / pratt
            if best is None or obj < best[0]:
                best = (obj, u / np.sqrt(pratt))
    return None if best is None else best[1]


def sphere_normal(x, neighbors, radius, with_query=True):
    """Unit normal at x of the sphere/plane fitted to its neighbors
    (:func:`meshcurv.normals.sphere.sphere_normals` in numpy), sign arbitrary.

    Parameters
    ----------
    x : (3,) float; neighbors : (k, 3) float, points beyond ``radius`` and x itself ignored;
    radius : float, model units; with_query : bool, fit x itself too (weight 1)

    Returns
    -------
    (3,) float unit normal, the gradient u + 2 u4 p of the fitted function at x (p = 0) in
    coordinates relative to x in units of ``radius`` (weights 1 - r^2, x weighted 1); NaN with
    fewer than 6 points (x included when fitted) or no fit.
    """
    q = np.asarray(neighbors, dtype=np.float64) - np.asarray(x, dtype=np.float64)
    d2 = np.einsum("ij,ij->i", q, q)
    q = q[(d2 > 0) & (d2 <= radius * radius)] / radius
    if with_query:
        q = np.vstack([np.zeros(3), q])
    if len(q) < 6:
        return np.full(3, np.nan)
    w = 1.0 - np.einsum("ij,ij->i", q, q)
    if with_query:
        w[0] = 1.0
    u = pratt_sphere(q, w)
    if u is None or np.linalg.norm(u[1:4]) <= 1e-12:
        return np.full(3, np.nan)
    return u[1:4] / np.linalg.norm(u[1:4])
