"""Orientation of unit normals: like reference normals (faces), towards a viewpoint, or
consistently along a minimum spanning tree of a k-nearest-neighbor graph (Hoppe et al. 1992).

Orientation decides the sign of every curvature (convex is positive under the outward normal),
so point-cloud normals are oriented consistently before any curvature is computed. Holds the
compiled kernels :func:`nearest_in_lists` and :func:`orient_spanning_tree`.
"""

import math

import numpy as np
from numba import njit, prange
from scipy.spatial import cKDTree

from ..linalg import CHUNK
from ..neighbors import grid

__all__ = ["orient_like", "orient_towards", "orient_mst", "nearest_in_lists",
           "orient_spanning_tree"]

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

    The k-nearest-neighbor graph is weighted by ``1 - |n_i . n_j|`` (Hoppe et al. 1992), so the
    tree propagates signs along smooth paths first (weights rounded to 4096 steps of
    ``sqrt(w)``, see :func:`meshcurv.orient_spanning_tree`). Each connected piece is
    then flipped as a whole so that its normals point away from its centroid on average -
    outward for a closed surface, away from the concave side for an open one.

    Parameters
    ----------
    points : (n, 3) float64; normals : (n, 3) float64 unit, NaN rows are left alone
    k : int, neighbors per point in the graph (when ``neighbors`` is not given)
    neighbors : (n, j) int, optional
        The graph, e.g. from :func:`nearest_in_lists` over lists already at
        hand: row i lists point indices joined to i, -1 for none. Default: the k nearest
        neighbors from a k-d tree.

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
        order = grid.cell_grid_build(p, np.arange(len(p)), p.min(axis=0) - cell, cell,
                                        dims.astype(np.int64))[0]
    else:
        # far outliers stretch the extent: lattice cells, hashed (memory bounded by n)
        order = grid.spatial_order(p, cell)
    rank = np.empty(len(p) + 1, dtype=np.int32)
    rank[order] = np.arange(len(p), dtype=np.int32)
    rank[-1] = -1                          # "no neighbor" stays -1 (index -1 wraps to it)
    graph = np.ascontiguousarray(nb[order], dtype=np.int32)
    np.take(rank, graph, out=graph, mode="wrap")
    nv_sorted = np.ascontiguousarray(nv[order])
    labels = orient_spanning_tree(nv_sorted, graph, 4096)
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


@njit(parallel=True, cache=True)
def nearest_in_lists(points, query_points, indptr, indices, k):
    """The ``k`` nearest neighbors of each query point among its CSR neighbor list.

    Returns (m, k) int64 point indices, nearest first, padded with -1; points coinciding with
    the query point (the point itself) are left out.
    """
    m = query_points.shape[0]
    out = np.full((m, k), -1, dtype=np.int64)
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        best = np.empty(k)
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            have = 0
            for j in range(indptr[q], indptr[q + 1]):
                i = indices[j]
                d0 = points[i, 0] - x0
                d1 = points[i, 1] - x1
                d2 = points[i, 2] - x2
                dd = d0 * d0 + d1 * d1 + d2 * d2
                if not dd > 0.0 or (have == k and dd >= best[k - 1]):
                    continue
                # insert into the sorted list of the best so far
                s = min(have, k - 1)
                while s > 0 and best[s - 1] > dd:
                    best[s] = best[s - 1]
                    out[q, s] = out[q, s - 1]
                    s -= 1
                best[s] = dd
                out[q, s] = i
                have = min(have + 1, k)
    return out


@njit(cache=True)
def _find_root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def orient_spanning_tree(normals, neighbors, levels):
    """Consistent signs of unit normals along a minimum spanning tree of a neighbor graph.

    The graph joins each point i to ``neighbors[i]`` ((n, k) int, -1 = none) with weight
    ``1 - |n_i . n_j|`` (Hoppe et al. 1992). Kruskal's algorithm runs on the weights rounded to
    ``levels`` steps of ``sqrt(w)`` (a counting sort instead of a comparison sort; ties go to the
    lower edge number), then each tree is traversed breadth-first from its lowest vertex and
    every normal is flipped to agree with its parent. Points with NaN normals stay alone.
    ``n * k`` must stay below 2**31 (edge numbers are int32).
    ``normals`` (n, 3) is modified in place. Returns (n,) int64 labels: the root of each
    point's tree.
    """
    n, k = neighbors.shape
    ne = n * k
    level = np.full(ne, -1, dtype=np.int32)
    count = np.zeros(levels + 1, dtype=np.int64)
    for i in range(n):
        for a in range(k):
            j = neighbors[i, a]
            if j < 0:
                continue
            if j < i:
                # an edge listed from both ends is sorted once
                dup = False
                for b in range(k):
                    if neighbors[j, b] == i:
                        dup = True
                if dup:
                    continue
            c = abs(normals[i, 0] * normals[j, 0] + normals[i, 1] * normals[j, 1]
                    + normals[i, 2] * normals[j, 2])
            if not np.isfinite(c):
                continue
            lv = np.int32(math.sqrt(max(1.0 - c, 0.0)) * (levels - 1))
            level[i * k + a] = lv
            count[lv + 1] += 1
    for b in range(levels):
        count[b + 1] += count[b]
    sorted_edges = np.empty(count[levels], dtype=np.int32)
    for e in range(ne):
        if level[e] >= 0:
            sorted_edges[count[level[e]]] = e
            count[level[e]] += 1
    # Kruskal: tree edges as (i, j) pairs
    parent = np.arange(n)
    tree_a = np.empty(n, dtype=np.int64)
    tree_b = np.empty(n, dtype=np.int64)
    nt = 0
    for e in sorted_edges:
        i = e // k
        j = neighbors[i, e % k]
        ri = _find_root(parent, i)
        rj = _find_root(parent, j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
            tree_a[nt] = i
            tree_b[nt] = j
            nt += 1
    # tree adjacency (CSR) and breadth-first sign propagation from each root
    start = np.zeros(n + 1, dtype=np.int64)
    for t in range(nt):
        start[tree_a[t] + 1] += 1
        start[tree_b[t] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start[:n].copy()
    adj = np.empty(2 * nt, dtype=np.int64)
    for t in range(nt):
        adj[fill[tree_a[t]]] = tree_b[t]
        fill[tree_a[t]] += 1
        adj[fill[tree_b[t]]] = tree_a[t]
        fill[tree_b[t]] += 1
    labels = np.empty(n, dtype=np.int64)
    seen = np.zeros(n, dtype=np.bool_)
    queue = np.empty(n, dtype=np.int64)
    for r in range(n):
        if seen[r]:
            continue
        seen[r] = True
        labels[r] = r
        head = 0
        tail = 1
        queue[0] = r
        while head < tail:
            a = queue[head]
            head += 1
            for e in range(start[a], start[a + 1]):
                b = adj[e]
                if seen[b]:
                    continue
                seen[b] = True
                labels[b] = r
                if (normals[a, 0] * normals[b, 0] + normals[a, 1] * normals[b, 1]
                        + normals[a, 2] * normals[b, 2]) < 0.0:
                    normals[b, 0] = -normals[b, 0]
                    normals[b, 1] = -normals[b, 1]
                    normals[b, 2] = -normals[b, 2]
                queue[tail] = b
                tail += 1
    return labels
