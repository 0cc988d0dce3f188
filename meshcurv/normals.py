"""Unit normals: from mesh faces, from a local fit, and a global orientation step.

Orientation decides the sign of every curvature (convex is positive under the outward normal),
so point-cloud normals are oriented consistently before any curvature is computed.
"""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
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


def orient_mst(points, normals, k=10):
    """Consistent orientation by propagation over a minimum spanning tree, then outward.

    The k-nearest-neighbour graph is weighted by ``1 - |n_i . n_j|`` (Hoppe et al. 1992), so the
    tree propagates signs along smooth paths first. Each connected piece is then flipped as a
    whole so that its normals point away from its centroid on average - outward for a closed
    surface, away from the concave side for an open one.

    Parameters
    ----------
    points : (n, 3) float64; normals : (n, 3) float64 unit, NaN rows are left alone
    k : int, neighbours per point in the graph

    Returns
    -------
    (n, 3) float64, the same array, oriented in place.
    """
    ok = np.flatnonzero(np.isfinite(normals).all(axis=1) & np.isfinite(points).all(axis=1))
    if len(ok) == 0:
        return normals
    p = points[ok]
    nv = normals[ok].copy()
    kk = min(k, len(ok) - 1)
    if kk >= 1:
        dist, nb = cKDTree(p).query(p, k=kk + 1, workers=-1)
        rows = np.repeat(np.arange(len(ok)), kk)
        cols = nb[:, 1:].ravel()
        keep = np.isfinite(dist[:, 1:].ravel())
        rows, cols = rows[keep], cols[keep]
        # small floor: scipy treats explicit zero weights as missing edges
        w = 1.0 - np.abs(np.einsum("ij,ij->i", nv[rows], nv[cols])) + 1e-9
        graph = coo_matrix((w, (rows, cols)), shape=(len(ok), len(ok))).tocsr()
        tree = minimum_spanning_tree(graph)
        tree = tree + tree.T
        n_comp, labels = connected_components(tree, directed=False)
    else:
        n_comp, labels = 1, np.zeros(len(ok), dtype=np.int64)
    roots, sizes = np.unique(labels, return_index=True, return_counts=True)[1:]
    for root in roots[sizes > 1]:
        order, pred = breadth_first_order(tree, root, directed=False, return_predecessors=True)
        kernels.propagate_signs(order, pred, nv)
    # one global decision per connected piece: point away from its centroid
    sums = np.zeros((n_comp, 3))
    np.add.at(sums, labels, p)
    centroid = sums / np.bincount(labels, minlength=n_comp)[:, None]
    score = np.bincount(labels, weights=np.einsum("ij,ij->i", p - centroid[labels], nv), minlength=n_comp)
    nv[score[labels] < 0] *= -1.0
    normals[ok] = nv
    return normals
