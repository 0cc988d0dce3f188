"""Position noise of a triangle mesh measured over its 1-rings, free of its shape.

The local jet's residual (``CurvatureResult.noise``) measures noise plus what a quadric
leaves of the shape within the ball; on a mesh coarse for its shape the second dominates
(trimesh's clean 32 x 12 torus 1 / 0.3: 0.023, against 0.0005 here). Over the 1-rings the
shape is nearly constant, so its second difference cancels it and leaves the noise:

- ``P = D^-1 A``, the uniform average over each vertex's 1-ring (A the edge adjacency, D its
  degrees);
- ``h = n . (P v - v)``, the umbrella operator's displacement along the normal ``n``: a
  smooth surface's mean curvature times the squared edge length, plus noise;
- ``r = (I - P) h``: the shape's part cancels where the sampling is even, the noise's
  stays, ``r = M e`` with ``M = (I - P)^2`` applied to the noise ``e`` along the normals;
- ``sigma_i^2 = (P^2 r^2)_i / (P^2 c)_i`` with ``c_i = sum_j M_ij^2`` (the variance of
  ``r_i`` per unit noise variance), averaged over the 2-ring.

Measured against Gaussian noise along the normals (0.1 % of the diagonal) on six of
trimesh's tori (32 x 12 to 200 x 50) and MeshLab's decimations of a torus and an ellipsoid:
the RMS over the vertices within 5 % of its sigma. An uneven sampling reads as noise (its
``h`` differs from vertex to vertex), so the estimate is an upper bound of the noise where
the sampling is uneven, as at a sharp edge; callers take the smaller of it and the jet's.

:func:`meshcurv.normals.face_normal_error` measures the same noise from the first
differences of the umbrella heights with one calibration for a regular triangulation
(``UMBRELLA_NOISE``): on the meshes above, noisy, 0-16 % above this estimate; clean,
1.2-10x above it (trimesh's 32 x 12 torus 1 / 0.3: 0.0023 against 0.0007, RMS), still 10x
below the jet's there.
"""

import numpy as np
import scipy.sparse as sp

from .neighbors import edge_adjacency
from .normals import face_vertex_normals
from .normals.winding import coherent_faces

__all__ = ["ring_noise"]


def ring_noise(v, f, adjacency=None):
    """``(noise, edge)``, (n,) each, of the mesh ``v`` (n, 3), ``f`` (m, 3): the noise sigma
    of each vertex along its normal (module docstring) and the mean length of its edges, model
    units. Noise NaN where a vertex within 3 rings has no normal (a vertex in no face) or is
    not finite, edge NaN at a vertex in no face. The normals are the area-weighted ones of the
    faces wound coherently (:func:`meshcurv.normals.winding.coherent_faces`): the faces'
    winding, and faces listed twice, do not matter. ``adjacency``: the mesh's
    :func:`meshcurv.neighbors.edge_adjacency`, if already made."""
    v = np.asarray(v, dtype=np.float64)
    n = len(v)
    indptr, indices = edge_adjacency(f, n) if adjacency is None else adjacency
    counts = np.diff(indptr)
    rows = np.repeat(np.arange(n), counts)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        edge = np.bincount(rows, np.linalg.norm(v[rows] - v[indices], axis=1), n) / counts
        ring_mean = sp.csr_matrix((1.0 / counts[rows], indices, indptr), shape=(n, n))
        normal = face_vertex_normals(v, coherent_faces(v, f, (indptr, indices))[0])
        normal[counts == 0] = np.nan
        height = np.einsum("ij,ij->i", ring_mean @ v - v, normal)
        residual = height - ring_mean @ height
        second = sp.identity(n, format="csr") - ring_mean
        second = second @ second
        per_unit = np.asarray(second.multiply(second).sum(axis=1)).ravel()
        two_rings = ring_mean @ ring_mean
        noise = np.sqrt((two_rings @ (residual * residual)) / (two_rings @ per_unit))
    return noise, edge
