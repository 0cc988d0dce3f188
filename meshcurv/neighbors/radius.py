"""Default radius from the sampling density, and the power-of-two scaling that keeps squared
lengths of any size representable in float64."""

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["default_radius", "power_of_two_scale", "typical_extent"]

# Lengths outside [2**-200, 2**200] are computed on coordinates scaled by a power of two
# (exact): their squares would overflow or lose precision in float64.
_SCALE_RANGE = (2.0 ** -200, 2.0 ** 200)


def power_of_two_scale(length):
    """1.0 if ``length`` (model units) squares safely in float64, else the power of two ``s``
    with ``length * s`` in [0.5, 1) (at most 2**1000): computing on ``points * s`` is then
    exact and safe."""
    length = float(length)
    if not (np.isfinite(length) and length > 0) or _SCALE_RANGE[0] <= length <= _SCALE_RANGE[1]:
        return 1.0
    # below 2**-1000 (subnormal lengths) the exact power would overflow: 2**1000 suffices
    return float(np.ldexp(1.0, min(-int(np.frexp(length)[1]), 1000)))


def typical_extent(points, sample=20000, seed=0):
    """Median distance (max norm) of the finite points from their coordinate-wise median, on
    up to ``sample`` of them: the size of the bulk of a cloud, unmoved by a few far points."""
    p = np.asarray(points, dtype=np.float64)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) > sample:
        p = p[np.random.default_rng(seed).choice(len(p), sample, replace=False)]
    if len(p) == 0:
        return float("nan")
    with np.errstate(over="ignore", invalid="ignore"):     # +-1e308: inf, NaN (ignored)
        return float(np.median(np.abs(p - np.median(p, axis=0)).max(axis=1)))


def default_radius(points, target_neighbors=100, sample=20000, seed=0):
    """Radius (model units) whose ball holds about ``target_neighbors`` points of the sampling.

    The local area density is estimated from the distance d16 to the 16th nearest neighbor,
    ``rho = 16 / (pi d16^2)``, on up to ``sample`` points; the radius is
    ``sqrt(target / (pi rho))`` with the median of d16^2. For a regular grid of spacing h this
    is about 5.6 h; for a mesh about 5 mean edge lengths. A few far-away points do not move it
    (a median); duplicated points count once where most points are duplicates; clouds of any
    scale (1e-300 ... 1e300) are measured on coordinates scaled by a power of two.

    Parameters
    ----------
    points : (n, 3) float, NaN rows ignored

    Returns
    -------
    float (NaN if there are fewer than 2 distinct finite points)
    """
    p = np.asarray(points, dtype=np.float64)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < 2:
        return float("nan")
    s = power_of_two_scale(typical_extent(p, sample, seed))
    if s != 1.0:
        with np.errstate(over="ignore"):
            scaled = p * s
        return default_radius(scaled, target_neighbors, sample, seed) / s
    radius = _default_radius(p, target_neighbors, sample, seed)
    if not np.isfinite(radius):
        # most points duplicated (coincident points are nobody's neighbor): distinct ones
        p = np.unique(p, axis=0)
        radius = _default_radius(p, target_neighbors, sample, seed) if len(p) > 1 else radius
    return radius


def _default_radius(p, target_neighbors, sample, seed):
    k = min(16, len(p) - 1)
    rng = np.random.default_rng(seed)
    probe = p if len(p) <= sample else p[rng.choice(len(p), sample, replace=False)]
    d, _ = cKDTree(p).query(probe, k=k + 1, workers=-1)
    with np.errstate(over="ignore"):
        dk2 = np.median(d[:, k] ** 2)
    if not (np.isfinite(dk2) and dk2 > 0):
        return float("nan")
    return float(np.sqrt(target_neighbors / k * dk2))
