"""Numpy specification of :mod:`meshcurv.fit.wrap`: the folding in one neighborhood."""

import numpy as np

from .wrap import TURN

__all__ = ["folding_weight"]


def folding_weight(x, n, neighbors, neighbor_normals, radius, point_weights=None):
    """The smaller of the counts (or weights) of the ``neighbors`` (k, 3) within ``radius``
    of x on the far side - unit normals (k, 3) turned from the unit normal n by more than
    ``TURN``, lying across their own tangent plane from x by more than ``sin(TURN / 2)`` of
    their distance - and on the bend - normals turned by between ``180 degrees - TURN`` and
    ``TURN`` (:func:`meshcurv.fit.wrap.folding_weight` at one point)."""
    x, n = np.asarray(x, float), np.asarray(n, float)
    if not np.all(np.isfinite(np.concatenate([x, n]))):
        return 0.0
    d = x - np.asarray(neighbors, float)
    a = np.asarray(neighbor_normals, float)
    w = np.ones(len(d)) if point_weights is None else np.asarray(point_weights, float)
    with np.errstate(invalid="ignore"):
        cos = a @ n
        inside = np.einsum("ij,ij->i", d, d) <= radius * radius
        across = (np.abs(np.einsum("ij,ij->i", d, a))
                  > np.sin(TURN / 2) * np.linalg.norm(d, axis=1))
        far = inside & (cos < np.cos(TURN)) & across
        bend = inside & (cos >= np.cos(TURN)) & (cos < -np.cos(TURN))
    return float(min(np.sum(w[far]), np.sum(w[bend])))
