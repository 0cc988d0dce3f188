"""Bias correction across scales: the shape operators fitted at radius R and at ``ratio * R``
extrapolated to radius 0 (Richardson).

Where the curvature varies inside the ball, the circle fits measure a weighted average of the
curvature around x whose error grows like R^2 (the surface's fourth-order terms; third-order
ones cancel between opposite half-sets). Two fits over the same neighbors, with the same
weight profile scaled to each radius, differ by that term, so ``S_0 = S_R + (S_r - S_R) /
(1 - ratio^2)`` removes it. The price is noise: the smaller fit has fewer points, so the
correction is mixed in by the measured noise (``gain``), as the weights are.
"""

import numpy as np

__all__ = ["BIAS_RATIO", "extrapolate_to_zero"]

# Radius of the second fit as a fraction of the first. Measured (Richardson on the clean
# Table 2 paraboloid and an ellipsoid): 1/2 and 1/sqrt(2) remove the same share of the bias;
# 1/sqrt(2) keeps twice the points in the smaller ball, so its correction amplifies position
# noise about half as much (the smaller fit's curvature noise grows like radius^-3).
BIAS_RATIO = 0.5 ** 0.5


def extrapolate_to_zero(large, small, normals, gain, ratio=BIAS_RATIO):
    """Principal curvatures and directions of ``S_R + gain (S_r - S_R) / (1 - ratio^2)``.

    Parameters
    ----------
    large, small : tuples ``(k1, k2, d1, d2)`` of the fits at radius R and ``ratio * R``
        about the same unit normals: k1 >= k2 (m,), 1 / model units, convex positive; d1, d2
        (m, 3) unit principal directions with d2 = n x d1; NaN rows where no estimate
    normals : (m, 3) unit normals both fits used
    gain : (m,) in [0, 1], how much of the correction to apply (0 keeps ``large``); rows where
        ``small`` has no estimate keep ``large``
    ratio : float in (0, 1)

    Returns
    -------
    ``(k1, k2, d1, d2)``, new arrays: k1 >= k2, d2 = n x d1.

    Examples
    --------
    >>> import numpy as np
    >>> e = np.eye(3)
    >>> large = (np.array([1.5]), np.array([0.5]), e[[0]], e[[1]])   # bias 0.5 at R in k1
    >>> small = (np.array([1.25]), np.array([0.5]), e[[0]], e[[1]])  # 0.25 at R / sqrt(2)
    >>> k1, k2, d1, d2 = extrapolate_to_zero(large, small, e[[2]], np.ones(1))
    >>> float(k1[0]), float(k2[0]), d1[0].tolist()
    (1.0, 0.5, [1.0, 0.0, 0.0])
    """
    k1, k2, d1, d2 = large
    s1, s2, e1, e2 = small
    g = np.where(np.isfinite(s1) & np.isfinite(s2), gain, 0.0) / (1.0 - ratio * ratio)
    # the small fit's operator in the large fit's frame (d1, d2): both lie in the tangent plane
    c = np.einsum("ij,ij->i", np.nan_to_num(e1), d1)
    s = np.einsum("ij,ij->i", np.nan_to_num(e1), d2)
    small11 = np.nan_to_num(s1 * c * c + s2 * s * s)
    small12 = np.nan_to_num((s1 - s2) * c * s)
    small22 = np.nan_to_num(s1 * s * s + s2 * c * c)
    a = k1 + g * (small11 - k1)
    b = g * small12
    d = k2 + g * (small22 - k2)
    mean = 0.5 * (a + d)
    amp = np.hypot(0.5 * (a - d), b)
    psi = 0.5 * np.arctan2(2.0 * b, a - d)
    cp, sp = np.cos(psi)[:, None], np.sin(psi)[:, None]
    new_d1 = cp * d1 + sp * d2
    return mean + amp, mean - amp, new_d1, np.cross(normals, new_d1)
