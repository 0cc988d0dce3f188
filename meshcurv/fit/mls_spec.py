"""Numpy specification of the MLS curvature (:mod:`meshcurv.fit.mls`): the potential of the
oriented algebraic sphere fitted about a point, and the curvature of its zero set."""

import numpy as np

from ..surfaces import implicit_curvature

__all__ = ["potential", "mls_curvature_at", "mls_normal_at", "STEP"]

# Central-difference step, a fraction of the support h: F is smooth on the scale h, so the
# truncation error is ~STEP^2 relative, and its values near the surface are ~|grad F| times
# the step, so the rounding error of the second differences is ~1e-16 / STEP^2 relative; 1e-4
# balances the two at ~1e-8. The kernels' derivatives are exact (second-order jets): this
# specification checks them by another route.
STEP = 1e-4


def potential(x, points, normals, support, point_weights=None):
    """The MLS potential F(x) (model units; 0 on the surface, growing along the normals):
    the algebraic sphere ``u0 + u . y + u4 |y|^2`` fitted to the points and their unit normals
    with the weights ``(1 - |p - x|^2 / support^2)^4`` about x (times ``point_weights``),
    evaluated at x. NaN where the weights vanish or the fit is singular.

    The fit (Guennebaud & Gross 2007, the oriented sphere fit), with sums over the weights w
    of offsets q = p - x: ``u4 = (A W - P.N) / (2 (B W - |P|^2))``, ``u = (N - 2 u4 P) / W``,
    ``u0 = -(u . P + u4 B) / W`` (W = sum w, P = sum w q, N = sum w n, A = sum w q.n,
    B = sum w |q|^2); F(x) = u0.
    """
    q = np.asarray(points, dtype=np.float64) - np.asarray(x, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    w = np.clip(1.0 - np.einsum("ij,ij->i", q, q) / (support * support), 0.0, None) ** 4
    if point_weights is not None:
        w = w * np.asarray(point_weights, dtype=np.float64)
    keep = (w > 0) & np.isfinite(n).all(axis=1)
    q, n, w = q[keep], n[keep], w[keep]
    big_w = w.sum()
    p_sum, n_sum = w @ q, w @ n
    a_sum, b_sum = w @ np.einsum("ij,ij->i", q, n), w @ np.einsum("ij,ij->i", q, q)
    den = b_sum * big_w - p_sum @ p_sum
    if not (big_w > 0 and den > 0):
        return np.nan
    u4 = 0.5 * (a_sum * big_w - p_sum @ n_sum) / den
    u = (n_sum - 2.0 * u4 * p_sum) / big_w
    return -(u @ p_sum + u4 * b_sum) / big_w


def _local(points, x):
    """``points`` (m, 3) as offsets from x: the stencil's steps are taken about 0, not added
    to x, whose rounding would change them (x ~ 5e6 in UTM coordinates: by 1e-9)."""
    return np.asarray(points, dtype=np.float64) - np.asarray(x, dtype=np.float64)


def mls_curvature_at(x, normal, points, normals, support, point_weights=None):
    """Curvature of the MLS surface F = 0 (:func:`potential`) at x, by central differences of
    F with the step ``STEP * support`` (13 evaluations: x, the axis steps and the diagonal
    steps ``+-(e_i + e_j)``, about x in coordinates relative to it).

    Returns ``(k1, k2, d1, d2, n)``: curvatures (1 / model units, k1 >= k2, convex positive
    about ``n``), unit directions and the unit normal grad F / |grad F| turned to ``normal``'s
    side (:func:`meshcurv.surfaces.implicit_curvature`, whose directions are NaN at
    umbilics); NaNs where F is undefined at a stencil point.
    """
    step = STEP * support
    e = np.eye(3) * step
    local = _local(points, x)

    def f(d):
        return potential(d, local, normals, support, point_weights)

    f0 = f(np.zeros(3))
    ahead, behind = np.array([f(e[i]) for i in range(3)]), np.array([f(-e[i]) for i in range(3)])
    grad = (ahead - behind) / (2 * step)
    hess = np.empty((3, 3))
    for i in range(3):
        hess[i, i] = (ahead[i] - 2 * f0 + behind[i]) / (step * step)
        for j in range(i + 1, 3):
            # F along the diagonal less along the axes: (H_ii + 2 H_ij + H_jj) - H_ii - H_jj
            hess[i, j] = hess[j, i] = (f(e[i] + e[j]) + f(-e[i] - e[j]) - ahead[i] - behind[i]
                                       - ahead[j] - behind[j] + 2 * f0) / (2 * step * step)
    nan = np.full(3, np.nan)
    if not (np.isfinite(grad).all() and np.isfinite(hess).all()) or not grad.any():
        return np.nan, np.nan, nan, nan, nan
    if grad @ np.asarray(normal, dtype=np.float64) < 0:
        grad, hess = -grad, -hess
    n, k1, k2, d1, d2 = implicit_curvature(grad, hess)
    return k1[0], k2[0], d1[0], d2[0], n[0]


def mls_normal_at(x, normal, points, normals, support, point_weights=None):
    """The unit normal grad F / |grad F| of the MLS surface at x, turned to ``normal``'s side,
    by central differences over the axis steps ``+-STEP * support`` alone (the gradient of
    :func:`mls_curvature_at`); NaNs where F is undefined there or its gradient vanishes."""
    step = STEP * support
    e = np.eye(3) * step
    local = _local(points, x)
    grad = np.array([potential(e[i], local, normals, support, point_weights)
                     - potential(-e[i], local, normals, support, point_weights)
                     for i in range(3)]) / (2 * step)
    length = np.linalg.norm(grad)
    if not (np.isfinite(length) and length > 0):
        return np.full(3, np.nan)
    return grad / length * (1.0 if grad @ np.asarray(normal, dtype=np.float64) >= 0 else -1.0)
