"""Numpy specifications of the face normals (:func:`meshcurv.normals.faces.face_vertex_normals`)
and of their expected error (:func:`meshcurv.normals.faces.face_normal_error`: the umbrella
heights and their spread over each vertex's edges, by gathering every edge at once)."""

import numpy as np

from ..neighbors.kring import edge_adjacency
from .faces import UMBRELLA_NOISE, unit_rows

__all__ = ["face_vertex_normals", "face_normal_error"]


def face_vertex_normals(vertices, faces):
    """:func:`meshcurv.normals.faces.face_vertex_normals` in numpy: each face's edges' cross
    product (twice its area times its unit normal; 0 where not finite) summed at its corners
    by ``np.bincount``, then scaled to unit length
    (:func:`meshcurv.normals.faces.unit_rows`)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = len(v)
    if len(f) == 0:
        return np.full((n, 3), np.nan)
    # twice the area times the unit normal: the cross product of two edges
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    fn[~np.isfinite(fn).all(axis=1)] = 0.0
    acc = np.column_stack([
        np.bincount(f.ravel(), weights=np.repeat(fn[:, c], 3), minlength=n) for c in range(3)
    ])
    return unit_rows(acc)


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
