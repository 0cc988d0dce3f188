"""Numpy specification of the area weights of the spanning-tree orientation
(:func:`meshcurv.normals.orient.sample_areas`): the squared distance from each point to the
farthest of its graph neighbors, by gathering every neighbor's offset at once."""

import numpy as np

__all__ = ["sample_area"]


def sample_area(points, neighbors, scale=1.0):
    """(n,) float64: ``max_j |(points[j] - points[i]) * scale|^2`` over the graph neighbors j
    of each point i (``neighbors`` (n, k) int, -1 for none); 0 for a point without neighbors."""
    nb = np.asarray(neighbors)
    d = (points[np.where(nb >= 0, nb, 0)] - points[:, None, :]) * scale
    # summed as (x0 x0 + x2 x2) + x1 x1, the order numpy's einsum("ijk,ijk->ij") takes
    d2 = np.where(nb >= 0, (d[..., 0] * d[..., 0] + d[..., 2] * d[..., 2])
                  + d[..., 1] * d[..., 1], 0.0)
    return d2.max(axis=1, initial=0.0)
