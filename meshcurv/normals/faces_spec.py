"""Numpy specification of the face normals' expected error
(:func:`meshcurv.normals.faces.face_normal_error`): the umbrella heights and their spread over
each vertex's edges, by gathering every edge at once."""

import numpy as np

from ..neighbors.kring import edge_adjacency
from .faces import UMBRELLA_NOISE

__all__ = ["face_normal_error"]


def face_normal_error(vertices, faces, normals):
    """(n,) float64: ``RMS (h_k - h_j) / UMBRELLA_NOISE / mean_j |v_j - v_i|``, the RMS over
    the edges jk of each vertex i and of its neighbors j, ``h_i = mean_j (v_j - v_i) . n_i``
    the umbrella height of i."""
    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    indptr, b = edge_adjacency(faces, n)
    a = np.repeat(np.arange(n), np.diff(indptr))
    count = np.diff(indptr).astype(np.float64)
    offset = v[b] - v[a]
    with np.errstate(invalid="ignore", divide="ignore"):
        height = np.bincount(a, np.einsum("ij,ij->i", offset, normals[a]), n) / count
        edge = np.bincount(a, np.linalg.norm(offset, axis=1), n) / count
        square = np.bincount(a, (height[b] - height[a]) ** 2, n)     # per vertex's edges
        ring = (square + np.bincount(a, square[b], n)) / (count + np.bincount(a, count[b], n))
        return np.sqrt(ring) / UMBRELLA_NOISE / edge
