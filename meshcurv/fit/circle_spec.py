"""Numpy specification of the circle fits (:mod:`meshcurv.fit.circle`): the conformal
geometric algebra (CGA) point embedding, the osculating-circle fit of one normal section and
the blend of directions a half-set measures.

A Euclidean point p is embedded as the conformal vector ``P = p + 1/2 |p|^2 e_inf + e_0``; a
sphere with centre m and radius r is ``S = m + 1/2 (|m|^2 - r^2) e_inf + e_0``; the inner product
``P . S = -1/2 (|p - m|^2 - r^2)`` is linear in S and vanishes exactly on the sphere, which is
what turns circle fitting into a small eigenvalue problem.
"""

import numpy as np

__all__ = ["conformal_embed", "conformal_inner", "circle_fit_rows", "fit_normal_circle", "sample_mix",
           "normal_turn_rows", "normal_row_weight"]


def conformal_embed(points):
    """Conformal embedding of Euclidean points.

    Parameters
    ----------
    points : (n, 3) float

    Returns
    -------
    (n, 5) float
        Coefficients on (e1, e2, e3, e_inf, e_0): ``(p, |p|^2 / 2, 1)``.

    Examples
    --------
    >>> conformal_embed(np.array([[1.0, 2.0, 2.0]]))
    array([[1. , 2. , 2. , 4.5, 1. ]])
    """
    p = np.asarray(points, dtype=np.float64)
    return np.column_stack([p, 0.5 * np.einsum("ij,ij->i", p, p), np.ones(len(p))])


def conformal_inner(a, b):
    """Inner product of conformal vectors given on (e1, e2, e3, e_inf, e_0), shape (..., 5).

    The metric has e_inf . e_0 = -1 and e_inf^2 = e_0^2 = 0, so for two embedded points
    ``P . Q = -|p - q|^2 / 2``.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return (a[..., :3] * b[..., :3]).sum(-1) - a[..., 3] * b[..., 4] - a[..., 4] * b[..., 3]


def circle_fit_rows(q, normal):
    """Rows ``w = (q . n, -1, -|q|^2 / 2)`` of the circle-fit matrix, for points relative to x.

    A sphere whose centre lies on the normal line, ``S = t3 (x + c n) + t3 e_0 + t2 e_inf`` with
    ``t1 = t3 c``, has ``P . S = t1 (q . n) - t2 - t3 |q|^2 / 2`` once x is moved to the origin,
    i.e. ``P . S = w . t``. Centring at x is what keeps the fit precise at large coordinates.

    Parameters
    ----------
    q : (k, 3) float, points relative to the estimation point x
    normal : (3,) float, unit normal at x

    Returns
    -------
    (k, 3) float
    """
    q = np.asarray(q, dtype=np.float64)
    return np.column_stack([q @ normal, -np.ones(len(q)), -0.5 * np.einsum("ij,ij->i", q, q)])


def fit_normal_circle(q, normal, weights=None, normalization="tangent", along=None, turn=None,
                      mu=0.0):
    """Signed curvature of the best sphere centred on the normal line through x (at the origin).

    Minimises ``sum_j w_j (P_j . S)^2 = t^T B t`` with ``B = W^T diag(w) W`` (rows W from
    :func:`circle_fit_rows`). The sphere's centre is at ``x + (t1 / t3) n``, so the curvature is
    ``kappa = -t3 / t1``: positive where the points bend away from the normal (a convex cap under
    an outward normal), zero for a straight line.

    Parameters
    ----------
    q : (k, 3) float, points relative to x (x itself contributes the row (0, -1, 0))
    normal : (3,) float, unit normal at x
    weights : (k,) float, optional
    normalization : {"tangent", "unit"}
        "unit": ``|t| = 1``, t is the eigenvector of the smallest eigenvalue of B (the paper).
        "tangent": ``t1 = 1``, the generalised eigenproblem ``B t = lambda diag(1, 0, 0) t``,
        solved as the 2x2 system ``B[1:, 1:] t[1:] = -B[1:, 0]``. Both give the same sphere on
        exact data; with noise the unit form can drift towards spheres centred at x (t1 -> 0,
        unbounded kappa), the tangent form cannot.
    along, turn : (k,) float, optional, the normal rows ``turn = kappa along`` of the points
        (see :func:`normal_turn_rows`; NaN ``turn``: no normal row), with the points' weights
        times ``mu``. In t a row reads ``turn t1 + along t3 = 0``: B gains
        ``mu sum w [[turn^2, 0, turn along], [0, 0, 0], [turn along, 0, along^2]]``.

    Returns
    -------
    kappa : float, 1 / length units of q
    residual : float, ``t^T B t / t1^2``: the weighted sum of squared height residuals

    Examples
    --------
    >>> a = np.linspace(-0.5, 0.5, 11)
    >>> q = np.column_stack([np.sin(a), np.zeros(11), np.cos(a) - 1.0])   # unit circle below x
    >>> float(round(fit_normal_circle(q, np.array([0.0, 0.0, 1.0]))[0], 12))
    1.0
    """
    w = circle_fit_rows(q, normal)
    wt = np.ones(len(w)) if weights is None else np.asarray(weights, dtype=np.float64)
    b = (w * wt[:, None]).T @ w
    if mu > 0 and along is not None:
        has = np.isfinite(turn)
        nrow = np.column_stack([turn[has], np.zeros(has.sum()), along[has]])
        b = b + mu * (nrow * wt[has, None]).T @ nrow
    if normalization == "unit":
        vals, vecs = np.linalg.eigh(b)
        t = vecs[:, 0]
        return -t[2] / t[0], max(vals[0], 0.0) / t[0] ** 2
    if normalization != "tangent":
        raise ValueError(f"normalization must be 'tangent' or 'unit', got {normalization!r}")
    if not np.linalg.det(b[1:, 1:]) > 1e-14 * b[1, 1] * b[2, 2]:
        return np.nan, np.nan     # all points at one distance from x: no circle is defined
    t = np.concatenate([[1.0], np.linalg.solve(b[1:, 1:], -b[1:, 0])])
    return -t[2], max(float(t @ b @ t), 0.0)


def sample_mix(r2, phi, weights, theta, along=None, across=None, turn=None, mu=0.0):
    """The blend of directions (cos 2phi, sin 2phi) a half-set's circle fit measured
    (specification of :func:`meshcurv.fit.circle.sample_design`).

    To first order in the heights the fitted curvature is ``sum_p w_p k(phi_p) / sum_p w_p``
    with ``w_p = wt_p r2_p (r2_p - mean r2)`` (the mean weighted by ``wt``), so the Euler model
    is fitted to that blend of directions rather than to the plane's nominal one.

    Parameters
    ----------
    r2 : (k,) float, squared distances of the half-set's points from x (units of the radius)
    phi : (k,) float, their angles in the tangent plane, radians
    weights : (k + 1,) float, the circle fit's weights, x itself (at r2 = 0) first
    theta : float, the half-set's direction: the fallback where the blend is undefined
    along, across, turn, mu : the half-set's normal rows (:func:`normal_turn_rows`, without
        x) and their weight: the fitted curvature is then the mean of the position rows' (weight
        ``sum w_p / 4``) and the normal rows' (weight ``mu sum w along^2``), and the normal
        rows measure ``kappa(theta) + delta S(e_perp, e)``, i.e. the direction mix
        ``(cos 2theta - delta sin 2theta, sin 2theta + delta cos 2theta)`` with
        ``delta = sum w along across / sum w along^2``.

    Returns
    -------
    (c, s) float: the weighted means of cos 2phi and sin 2phi
    """
    rr = np.concatenate([[0.0], r2])
    wp = weights * rr * (rr - np.sum(weights * rr) / weights.sum())
    c2, s2 = np.cos(2 * theta), np.sin(2 * theta)
    parts = []
    if wp.sum() > 0:
        parts.append((wp.sum() / 4, np.sum(wp[1:] * np.cos(2 * phi)) / wp.sum(),
                      np.sum(wp[1:] * np.sin(2 * phi)) / wp.sum()))
    if mu > 0 and along is not None:
        has = np.isfinite(turn)
        w = weights[1:][has]
        saa = np.sum(w * along[has] ** 2)
        if saa > 0:
            delta = np.sum(w * along[has] * across[has]) / saa
            parts.append((mu * saa, c2 - delta * s2, s2 + delta * c2))
    if not parts:
        return (c2, s2)
    tot = sum(p[0] for p in parts)
    return (sum(p[0] * p[1] for p in parts) / tot, sum(p[0] * p[2] for p in parts) / tot)


def normal_turn_rows(uv, turn_uv, theta):
    """Normal rows of a half-set of direction theta: ``(along, across, turn)``, each (k,).

    ``along = p . e`` and ``across = p . e_perp`` for the unit direction e at angle theta in the
    tangent frame and ``e_perp`` a quarter turn from it, and ``turn = n_p . e`` the normal's turn
    along e, p and n_p relative to a reference point and normal of the same field (meshcurv:
    the ball's weighted means). For a shape operator S (convex positive, outward normals)
    ``n_p - n_ref = S (p - p_ref)`` to first order, so
    ``turn = kappa(theta) along + S(e_perp, e) across``.

    Parameters
    ----------
    uv : (k, 2) float, the points' tangent coordinates (u, v) relative to the reference
    turn_uv : (k, 2) float, the tangent components of ``n_p - n_ref`` (NaN: no normal)
    theta : float, radians
    """
    c, s = np.cos(theta), np.sin(theta)
    along = c * uv[:, 0] + s * uv[:, 1]
    across = -s * uv[:, 0] + c * uv[:, 1]
    turn = c * turn_uv[:, 0] + s * turn_uv[:, 1]
    return along, across, turn


def normal_row_weight(half_sets, height_var):
    """Weight of the normal rows relative to the position rows of one point's circle fits
    (specification of :func:`meshcurv.fit.circle.normal_row_weight`).

    The ratio of the two kinds of rows' noise variances: ``height_var`` for the positions (the
    local cubic fit's, units of the radius; NaN gives 0), for the normals their residual of
    ``turn = kappa along + gamma across`` (the turn across the slab is modelled, not noise)
    pooled over the half-sets, ``sum SSE / sum W (cnt - 2) / cnt`` with W the rows' total weight
    and cnt their number; both floored by 1e-12.

    Parameters
    ----------
    half_sets : list of ``(weights, along, across, turn)``, each (k,): every half-set's normal
        rows and their weights (NaN turn: none)
    height_var : float

    Returns
    -------
    float, 0 where there are no normal rows
    """
    if not np.isfinite(height_var):
        return 0.0
    sse_n = dof_n = 0.0
    for wt, along, across, turn in half_sets:
        has = np.isfinite(turn)
        x = np.column_stack([along[has], across[has]])
        g = (x * wt[has, None]).T @ x
        if has.sum() > 2 and np.linalg.det(g) > 1e-14 * g[0, 0] * g[1, 1]:
            coef = np.linalg.solve(g, (x * wt[has, None]).T @ turn[has])
            sse_n += max(np.sum(wt[has] * (turn[has] - x @ coef) ** 2), 0.0)
            dof_n += wt[has].sum() * (has.sum() - 2) / has.sum()
    if not dof_n > 0:
        return 0.0
    return (height_var + 1e-12) / (sse_n / dof_n + 1e-12)
