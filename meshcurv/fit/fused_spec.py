"""Numpy specification of the fused estimator, one point at a time.

Slow and readable: the paper's steps for a single point, built from the other specifications
(:mod:`~meshcurv.fit.frame_spec`, :mod:`~meshcurv.fit.circle_spec`,
:mod:`~meshcurv.fit.euler_spec`). It exists to check the compiled kernel
(:func:`meshcurv.fit.fused.curvature_cga`), which must agree with it to round-off.
"""

import numpy as np

from .circle_spec import fit_normal_circle, normal_row_weight, normal_turn_rows, sample_mix
from .constants import MIN_DIRECTION_SPREAD, PLANE_OFFSET, WEIGHT_POWER
from .euler_spec import direction_spread, fit_euler
from .frame_spec import tangent_u

__all__ = ["curvature_at_point"]


def curvature_at_point(x, n, neighbors, radius, n_directions=8, slab=0.25, min_points=3,
                       min_spread=0.25, blend=1.0, circle_normalization="tangent",
                       section_blend=True, half_frequency=False, robust=True,
                       neighbor_normals=None, noise=np.nan, normal_gain=1.0,
                       point_weights=None, row_weight=None, taper=None):
    """Principal curvatures at one point from its neighbors (the kernel's contract, in numpy).

    Parameters
    ----------
    x : (3,) float, the point; n : (3,) float, its unit normal (outward)
    neighbors : (k, 3) float, candidate neighbors sorted by vertex index (x itself and points
        beyond ``radius`` are ignored); the first one at least 30 degrees off the normal sets
        the tangent frame, as the lowest-index one does in the kernel
    radius : float, model units; ``slab`` and ``min_spread`` are fractions of it
    blend : float in [0, 1], weights ``(1 - blend) + blend (1 - r^2 / radius^2)^WEIGHT_POWER``
        (see :func:`meshcurv.pipeline.weight_blend`), in each slab times its taper
        ``(1 - taper) + taper (1 - (s / slab)^2)^2`` at the distance s from the plane
    taper : float in [0, 1] or None (``blend``), the blend of the slabs' taper
    point_weights : (k,) float in [0, 1], optional, per neighbor: multiplies its weight;
        neighbors of weight 0 join no half-set and set no frame (the outlier pass's weights)
    other parameters : as in :func:`meshcurv.principal_curvatures`
    neighbor_normals : (k, 3) float, optional, unit normals of ``neighbors`` (NaN: unknown):
        normal-aware circle fits, each half-set's normal rows
        (:func:`~meshcurv.fit.circle_spec.normal_turn_rows`, relative to the ball's weighted
        mean position and normal) weighted by
        :func:`~meshcurv.fit.circle_spec.normal_row_weight` from ``noise`` (model units, the
        local cubic fit's RMS height residual), times ``normal_gain``; or ``row_weight``
        (float) when given

    Returns
    -------
    dict with k1, k2 (float, NaN if undefined, 1 / model units), d1 ((3,) unit), n_samples
    (int, circle fits kept), residual (float, RMS of the Euler fit, 1 / model units) and
    row_weight (float, the normal rows' weight used; 0 without them)
    """
    x = np.asarray(x, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    n = n / np.linalg.norm(n)
    q = np.asarray(neighbors, dtype=np.float64) - x
    d2 = np.einsum("ij,ij->i", q, q)
    ball = (d2 > 0) & (d2 <= radius * radius)
    pw = np.ones(len(q)) if point_weights is None else np.asarray(point_weights, float)
    q, pw = q[ball], pw[ball]
    tu = tangent_u(q[pw > 0], n)
    tv = np.cross(n, tu)
    q = q / radius  # all fits in units of the radius
    u, v = q @ tu, q @ tv
    keep = (u * u + v * v > 0) & (pw > 0)
    q, u, v, pw = q[keep], u[keep], v[keep], pw[keep]
    r2 = np.einsum("ij,ij->i", q, q)
    phi = np.arctan2(v, u)
    w = ((1 - blend) + blend * (1 - r2) ** WEIGHT_POWER) * pw
    turn_uv = None
    if neighbor_normals is not None:
        nb = np.asarray(neighbor_normals, dtype=np.float64)[ball][keep]
        nb = np.where((nb @ n < 0)[:, None], -nb, nb)     # turned round to face like n
        turn_uv = np.column_stack([nb @ tu, nb @ tv])
        has = np.isfinite(turn_uv).all(axis=1)
        uv = np.column_stack([u, v])
        if has.any():    # relative to the ball's weighted mean position and normal
            uv = uv - np.average(uv[has], axis=0, weights=w[has])
            turn_uv = turn_uv - np.average(turn_uv[has], axis=0, weights=w[has])

    halves = []
    for i in range(n_directions):
        alpha = (i + PLANE_OFFSET) * np.pi / n_directions
        dist = -np.sin(alpha) * u + np.cos(alpha) * v    # distance to plane i (through x)
        along = np.cos(alpha) * u + np.sin(alpha) * v    # coordinate along the plane's tangent
        in_slab = np.abs(dist) <= slab
        # the slab's weight tapers to 0 at its edges where the data are clean (like the
        # distance weights), so points entering or leaving it move the fit smoothly
        tb = blend if taper is None else taper
        in_taper = (1 - tb) + tb * np.clip(1 - (dist / slab) ** 2, 0, None) ** 2
        for side, half in enumerate([in_slab & (along >= 0), in_slab & (along < 0)]):
            if half.sum() < min_points or np.abs(along[half]).max(initial=0) < min_spread:
                continue
            theta = alpha + side * np.pi
            nrows = (np.zeros(half.sum()), np.zeros(half.sum()), np.full(half.sum(), np.nan))
            if turn_uv is not None:
                nrows = normal_turn_rows(uv[half], turn_uv[half], theta)
            halves.append((i, theta, half, (w * in_taper)[half], nrows))
    # x itself is in every half-set: position row (0, -1, 0), no normal row
    mu = 0.0
    if turn_uv is not None:
        mu = row_weight if row_weight is not None else normal_gain * normal_row_weight(
            [(wh,) + nrows for _, _, _, wh, nrows in halves], (noise / radius) ** 2)

    kappas, rows, mixes, planes = [], [], [], set()
    for i, theta, half, wh, nrows in halves:
        pts = np.vstack([np.zeros(3), q[half]])
        wt = np.concatenate([[1.0], wh])
        kappa, _ = fit_normal_circle(pts, n, wt, circle_normalization,
                                     np.concatenate([[0.0], nrows[0]]),
                                     np.concatenate([[np.nan], nrows[2]]), mu)
        if not np.isfinite(kappa):
            continue
        mix = sample_mix(r2[half], phi[half], wt, theta, *nrows, mu)
        c, s = mix if section_blend else (np.cos(2 * theta), np.sin(2 * theta))
        row = [1.0, c, s] + ([np.cos(theta), np.sin(theta)] if half_frequency else [])
        kappas.append(kappa)
        rows.append(row)
        mixes.append(mix)
        planes.add(i)
    out = dict(k1=np.nan, k2=np.nan, d1=np.full(3, np.nan), n_samples=len(kappas),
               residual=np.nan, row_weight=mu)
    if len(planes) < 3 or len(kappas) < 5:
        return out
    k1, k2, theta1, rms, used = fit_euler(np.array(rows), np.array(kappas), robust=robust)
    if not np.isfinite(k1):
        return out
    # the measured directions must span the Euler model (not all along one curve)
    if direction_spread(np.array(mixes)[used]) < MIN_DIRECTION_SPREAD:
        return out
    out.update(k1=k1 / radius, k2=k2 / radius, d1=np.cos(theta1) * tu + np.sin(theta1) * tv,
               n_samples=int(used.sum()), residual=rms / radius)
    return out
