"""Unit normals: from mesh faces, from a local fit, and a global orientation step.

Orientation decides the sign of every curvature (convex is positive under the outward normal),
so point-cloud normals are oriented consistently before any curvature is computed.
"""

import numpy as np
from scipy.spatial import cKDTree

from . import kernels

__all__ = ["face_vertex_normals", "pca_normals", "orient_like", "orient_towards", "orient_mst"]


def _unit(v):
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
    return _unit(acc)


def pca_normals(points, query_points, indptr, indices, radius):
    """Normals of the least-squares plane through each query point's neighbourhood (PCA).

    Parameters
    ----------
    points : (n, 3) float64; query_points : (m, 3) float64
    indptr, indices : CSR neighbour lists into ``points``; radius : float, model units

    Returns
    -------
    (m, 3) float64 unit normals with arbitrary sign; NaN with fewer than 3 points in the ball.
    """
    # covariance and its smallest eigenvector (Jacobi, to machine precision) in one kernel
    return kernels.pca_normals_csr(np.ascontiguousarray(points, dtype=np.float64),
                                   np.ascontiguousarray(query_points, dtype=np.float64),
                                   indptr, indices, float(radius))


def orient_like(normals, reference):
    """Flip each normal to agree with a reference (e.g. face normals); in place, returned."""
    flip = np.einsum("ij,ij->i", normals, reference) < 0
    normals[flip] *= -1.0
    return normals


def orient_towards(normals, points, viewpoint):
    """Flip each normal to face ``viewpoint`` (a (3,) scanner position); in place, returned."""
    flip = np.einsum("ij,ij->i", normals, np.asarray(viewpoint, dtype=np.float64) - points) < 0
    normals[flip] *= -1.0
    return normals


def orient_mst(points, normals, k=10, neighbors=None):
    """Consistent orientation by propagation over a minimum spanning tree, then outward.

    The k-nearest-neighbour graph is weighted by ``1 - |n_i . n_j|`` (Hoppe et al. 1992), so the
    tree propagates signs along smooth paths first (weights rounded to 4096 steps of
    ``sqrt(w)``, see :func:`meshcurv.kernels.orient_spanning_tree`). Each connected piece is
    then flipped as a whole so that its normals point away from its centroid on average -
    outward for a closed surface, away from the concave side for an open one.

    Parameters
    ----------
    points : (n, 3) float64; normals : (n, 3) float64 unit, NaN rows are left alone
    k : int, neighbours per point in the graph (when ``neighbors`` is not given)
    neighbors : (n, j) int, optional
        The graph, e.g. from :func:`meshcurv.kernels.nearest_in_lists` over lists already at
        hand: row i lists point indices joined to i, -1 for none. Default: the k nearest
        neighbours from a k-d tree.

    Returns
    -------
    (n, 3) float64, the same array, oriented in place.
    """
    ok = np.flatnonzero(np.isfinite(normals).all(axis=1) & np.isfinite(points).all(axis=1))
    if len(ok) == 0:
        return normals
    p = points[ok]
    nv = np.ascontiguousarray(normals[ok])
    if neighbors is None:
        kk = min(k, len(ok) - 1)
        if kk >= 1:
            dist, nb = cKDTree(p).query(p, k=kk + 1, workers=-1)
            nb = np.where(np.isfinite(dist[:, 1:]), nb[:, 1:], -1).astype(np.int32)
        else:
            nb = np.full((len(ok), 1), -1, dtype=np.int32)
    elif len(ok) == len(points):
        nb = np.asarray(neighbors)
    else:
        # renumber the graph to the rows kept
        local = np.full(len(points) + 1, -1, dtype=np.int32)
        local[ok] = np.arange(len(ok), dtype=np.int32)
        nb = local[np.asarray(neighbors)[ok]]
    # traverse in a spatially coherent order (points sorted by grid cell): the tree's random
    # accesses then stay in cache (twice as fast on a 1M cloud in random order)
    span = np.maximum(np.ptp(p, axis=0), 1e-300)
    s1, s2, s3 = np.sort(span)[::-1]
    # about one point per cell for volumes, a few per occupied cell for surfaces
    with np.errstate(over="ignore"):
        cell = max(2.0 * np.sqrt(s1 * s2 / len(p)), np.cbrt(s1 * s2 * s3 / len(p)), 1e-300)
    dims = np.floor(span / cell) + 3
    if np.isfinite(cell) and float(np.prod(dims)) <= 4.0 * len(p) + 2.0 ** 20:
        order = kernels.cell_grid_build(p, np.arange(len(p)), p.min(axis=0) - cell, cell,
                                        dims.astype(np.int64))[0]
    else:
        # far outliers stretch the extent: lattice cells, hashed (memory bounded by n)
        from .neighbors import spatial_order

        order = spatial_order(p, cell)
    rank = np.empty(len(p) + 1, dtype=np.int32)
    rank[order] = np.arange(len(p), dtype=np.int32)
    rank[-1] = -1                          # "no neighbour" stays -1 (index -1 wraps to it)
    graph = np.ascontiguousarray(nb[order], dtype=np.int32)
    np.take(rank, graph, out=graph, mode="wrap")
    nv_sorted = np.ascontiguousarray(nv[order])
    labels = kernels.orient_spanning_tree(nv_sorted, graph, 4096)
    del graph
    nv[order] = nv_sorted
    labels_input = np.empty_like(labels)
    labels_input[order] = order[labels]
    labels = labels_input
    # one global decision per connected piece: point away from its centroid
    n_comp = len(ok)                       # labels are root rows: bins 0..len(ok) - 1
    size = np.maximum(np.bincount(labels, minlength=n_comp), 1)
    centroid = np.column_stack([np.bincount(labels, weights=p[:, c], minlength=n_comp)
                                for c in range(3)]) / size[:, None]
    score = np.bincount(labels, weights=np.einsum("ij,ij->i", p - centroid[labels], nv),
                        minlength=n_comp)
    nv[score[labels] < 0] *= -1.0
    normals[ok] = nv
    return normals
