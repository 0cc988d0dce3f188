"""Vertex normals of a triangle mesh from its faces (area-weighted), and their expected error
from the mesh's roughness (compiled kernel :func:`umbrella_spread`; its numpy specification
is :func:`meshcurv.normals.faces_spec.face_normal_error`)."""

import math

import numpy as np
from numba import njit, prange

from ..neighbors.kring import edge_adjacency

__all__ = ["face_vertex_normals", "face_normal_error", "unit_rows"]

# Standard deviation of the difference of two neighbors' umbrella heights per unit of
# Gaussian noise along the normals, on a regular triangulation (6 neighbors, 2 shared by
# neighbors): each height has variance 1 + 1/6, two neighbors' heights covariance
# -1/6 - 1/6 + 2/36, so their difference has variance 26/9.
UMBRELLA_NOISE = (26.0 / 9.0) ** 0.5


def unit_rows(v):
    """Rows scaled to unit length; zero or non-finite rows become NaN."""
    nrm = np.linalg.norm(v, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = v / nrm
    out[~(np.isfinite(nrm[:, 0]) & (nrm[:, 0] > 0))] = np.nan
    return out


def face_vertex_normals(vertices, faces):
    """Area-weighted vertex normals of a triangle mesh.

    Parameters
    ----------
    vertices : (n, 3) float; faces : (m, 3) int, counter-clockwise seen from outside

    Returns
    -------
    (n, 3) float64 unit normals; NaN for vertices in no (non-degenerate, finite) face.
    """
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


def face_normal_error(vertices, faces, normals, adjacency=None):
    """Expected tilt (radians, (n,)) of the face normals ``normals`` of a mesh from its own
    roughness: ``sigma / h`` with h the mean length of a vertex's edges and sigma the noise
    of the positions along the normal, measured as the RMS difference of the umbrella heights
    (the mean offset of a vertex's 1-ring along its normal) across the edges of the vertex
    and of its neighbors (~36 edges), divided by ``UMBRELLA_NOISE``.

    A smooth mesh, however coarse, gives ~0 (the umbrella height, about the mean curvature
    times h^2 / 2, changes little from vertex to vertex): its face normals are exact to
    within h^2 terms, border vertices included. Noise of sigma along the normals gives about
    sigma / h, the scale of the tilt it gives the face normals (measured, torus 240 x 60
    with 0.1 % / 0.3 % noise: median 0.10 / 0.26 against actual tilts of 0.09 / 0.26).

    Parameters
    ----------
    vertices : (n, 3) float; faces : (m, 3) int, validated; normals : (n, 3) unit normals
    adjacency : the faces' edge graph (:func:`meshcurv.neighbors.edge_adjacency`) if already
        made, else None

    Returns
    -------
    (n,) float64, NaN at vertices in no face or with no finite normal
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    indptr, indices = edge_adjacency(faces, len(v)) if adjacency is None else adjacency
    spread, edge = np.empty(len(v)), np.empty(len(v))
    umbrella_spread(v, np.ascontiguousarray(normals, dtype=np.float64), indptr, indices,
                    spread, edge)
    with np.errstate(invalid="ignore", divide="ignore"):
        return spread / UMBRELLA_NOISE / edge


@njit(parallel=True, cache=True)
def umbrella_spread(points, normals, indptr, indices, spread, edge):
    """Over the edge graph ``(indptr, indices)`` (CSR, each edge once each way), per vertex
    i, with ``h_i`` the mean of ``(points[j] - points[i]) . normals[i]`` over its neighbors
    j (its umbrella height): ``edge[i]`` the neighbors' mean distance and ``spread[i]`` the
    RMS of ``h_j - h_i`` over the edges of i and of its neighbors (both (n,) float64
    outputs; NaN without neighbors)."""
    n = points.shape[0]
    height = np.empty(n)
    square = np.empty(n)
    for i in prange(n):
        k = indptr[i + 1] - indptr[i]
        h = 0.0
        d = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            o0 = points[j, 0] - points[i, 0]
            o1 = points[j, 1] - points[i, 1]
            o2 = points[j, 2] - points[i, 2]
            h += o0 * normals[i, 0] + o1 * normals[i, 1] + o2 * normals[i, 2]
            d += math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
        height[i] = h / k if k > 0 else np.nan
        edge[i] = d / k if k > 0 else np.nan
    for i in prange(n):
        s = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            g = height[indices[e]] - height[i]
            s += g * g
        square[i] = s
    for i in prange(n):
        s = square[i]
        k = indptr[i + 1] - indptr[i]
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            s += square[j]
            k += indptr[j + 1] - indptr[j]
        spread[i] = math.sqrt(s / k) if k > 0 else np.nan
