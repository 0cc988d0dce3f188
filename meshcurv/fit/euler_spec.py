"""Numpy specification of the Euler model fit (:mod:`meshcurv.fit.euler`): principal
curvatures from normal-section curvatures sampled around a point.

Euler's theorem gives the normal curvature in tangent direction theta as
``kappa(theta) = k1 cos^2(theta - theta1) + k2 sin^2(theta - theta1)
               = A + B cos 2theta + C sin 2theta`` with ``A = (k1 + k2) / 2`` and
``sqrt(B^2 + C^2) = (k1 - k2) / 2``. This is the paper's three-parameter sine fit written as a
linear least-squares problem (the paper's phase formula is wrong; this form needs none).
"""

import numpy as np

__all__ = ["euler_design", "fit_euler", "direction_spread"]


def euler_design(theta, half_frequency=False):
    """Design matrix of the Euler model at sample directions ``theta`` (radians, shape (m,)).

    Columns ``(1, cos 2theta, sin 2theta)``, plus ``(cos theta, sin theta)`` with
    ``half_frequency``: the linear form of the paper's optional half-frequency second fit, which
    absorbs the difference between opposite directions (a curvature gradient).
    """
    theta = np.asarray(theta, dtype=np.float64)
    cols = [np.ones_like(theta), np.cos(2 * theta), np.sin(2 * theta)]
    if half_frequency:
        cols += [np.cos(theta), np.sin(theta)]
    return np.column_stack(cols)


def fit_euler(design, kappa, robust=False):
    """Least-squares Euler model fit, optionally with one round of outlier rejection.

    Parameters
    ----------
    design : (m, 3) or (m, 5) float
        Rows ``(1, c, s[, cos theta, sin theta])`` where (c, s) is the (cos 2theta, sin 2theta)
        mix a sample measured; see :func:`euler_design`.
    kappa : (m,) float
        Normal-section curvatures, 1 / length units.
    robust : bool
        Drop samples further than 3 robust sigmas (1.4826 * median absolute residual) from the
        first fit, then refit.

    Returns
    -------
    k1, k2 : float, k1 >= k2
    theta1 : float, direction of k1 in the (c, s) angle frame, radians in (-pi/2, pi/2]
    residual : float, RMS residual of the samples kept
    used : (m,) bool, samples kept

    All four numbers are NaN when fewer than ``n_params + 2`` samples remain.

    Examples
    --------
    >>> th = np.arange(16) * np.pi / 8
    >>> k = 0.3 + 0.1 * np.cos(2 * (th - 0.2))
    >>> [round(v, 12) for v in fit_euler(euler_design(th), k)[:3]]
    [0.4, 0.2, 0.2]
    """
    design = np.asarray(design, dtype=np.float64)
    kappa = np.asarray(kappa, dtype=np.float64)
    used = np.ones(len(kappa), dtype=bool)
    nan = (np.nan, np.nan, np.nan, np.nan, used)
    if len(kappa) < design.shape[1] + 2:
        return nan
    sol = np.linalg.lstsq(design, kappa, rcond=None)[0]
    if robust:
        r = np.abs(kappa - design @ sol)
        cut = 3.0 * 1.4826 * np.median(r)
        if cut > 0 and np.any(r > cut):
            used = r <= cut
            if used.sum() < design.shape[1] + 2:
                return nan
            sol = np.linalg.lstsq(design[used], kappa[used], rcond=None)[0]
    amp = np.hypot(sol[1], sol[2])
    rms = np.sqrt(np.mean((kappa[used] - design[used] @ sol) ** 2))
    return float(sol[0] + amp), float(sol[0] - amp), float(0.5 * np.arctan2(sol[2], sol[1])), float(rms), used


def direction_spread(mix):
    """Spread of the measured directions: the smaller eigenvalue of the covariance of the
    (k, 2) (cos 2phi, sin 2phi) mixes of the circle fits kept (0 when they lie on a line)."""
    return np.linalg.eigvalsh(np.cov(np.asarray(mix).T, bias=True))[0]
