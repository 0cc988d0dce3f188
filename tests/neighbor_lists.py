"""Neighbor lists for the kernels' tests, built with scipy's k-d tree: the independent
reference for what meshcurv's own searches give."""

import numpy as np
from scipy.spatial import cKDTree


def ball_csr(points, radius, centres=None):
    """CSR lists ``(indptr, indices)`` (int64) of the rows of ``points`` within ``radius`` of
    each of ``centres`` (default: the points themselves), each list sorted ascending."""
    centres = points if centres is None else centres
    lists = cKDTree(points).query_ball_point(centres, radius, return_sorted=True)
    indptr = np.concatenate([[0], np.cumsum([len(lst) for lst in lists])]).astype(np.int64)
    return indptr, np.concatenate(lists).astype(np.int64)
