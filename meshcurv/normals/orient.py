"""Orientation of unit normals: like reference normals (faces), towards a viewpoint, along a
direction (+z), or consistently along a minimum spanning tree of a k-nearest-neighbor graph
(Hoppe et al. 1992) with one global sign per connected piece.

Orientation decides the sign of every curvature (convex is positive under the outward normal),
so point-cloud normals are oriented consistently before any curvature is computed. Holds the
compiled kernels :func:`nearest_in_lists` and :func:`orient_spanning_tree`.

The global sign of a piece (:func:`piece_signs`)
-------------------------------------------------
The spanning tree makes the normals of a connected piece agree with each other; which of the
two sides is "outward" is a separate decision, taken per piece from three sums over its points,
each weighted by the share of the area the point stands for (:func:`sample_areas`), so that
uneven sampling does not change the decision:

- **closed pieces, outward.** By Gauss' theorem the area-weighted normals of a closed surface
  sum to zero, and ``sum (p - c) . n dA = 3 x volume > 0`` for outward normals whatever the
  point ``c`` and the shape (convex or not: torus, Goursat surface). A piece whose mean unit
  normal is shorter than :data:`CLOSED_MEAN_NORMAL` (0.25) is taken as closed and given the
  sign that makes ``sum (p - centroid) . n`` positive. A closed cloud of n points has a mean
  normal of about ``1 / sqrt(n)`` (0.006-0.011 measured at 10k points); a one-sided view has
  the ratio of its projected to its true area (hemisphere 0.5, top of a torus 0.64, terrain
  0.9 and more).
- **open pieces, towards +z.** An open sheet has no inside: its outward side is, by our
  contract, the side its viewer sees. Without a viewpoint the viewer is taken above, as aerial
  LiDAR, PDAL (``always_up``) and CloudCompare's preferred orientation do: the piece's mean
  normal is turned to point up (a dome, a terrain, the top of a torus, and the inside of a
  bowl seen from above).
- **open pieces facing sideways** (mean normal within about 6 degrees of horizontal,
  ``|m_z| < 0.1 |m|``: a wall) cannot be decided by "up"; they point away from their centroid
  (the convex side out). Give a viewpoint for such scans.

Pass a viewpoint (a scanner position) wherever it is known: it decides every point exactly.
"""

import math

import numpy as np
from numba import njit, prange
from scipy.spatial import cKDTree

from ..linalg import CHUNK
from ..neighbors import grid

__all__ = ["orient_like", "orient_towards", "orient_along", "orient_mst", "piece_signs",
           "sample_areas", "nearest_areas",
           "orientation_note", "CLOSED_MEAN_NORMAL", "SIDEWAYS_MEAN_NORMAL_Z", "PIECE_RULES",
           "nearest_in_lists", "orient_spanning_tree", "graph_pieces",
           "nearest_in_other_piece", "BRIDGE_TILT"]

# Largest angle (radians) between the tangent plane of either end and a bridge joining two
# pieces of the spanning tree's graph (:func:`nearest_in_other_piece`): gaps in the sampling
# of one surface are bridged along it (a curved surface's own points lie within about
# k |d| / 2 of it, under 30 degrees in balls that do not reach around); two surfaces stacked
# across a gap (an object above a floor) are not, so that each piece takes its own sign.
BRIDGE_TILT = math.radians(45.0)
BRIDGE_ACROSS = math.sin(BRIDGE_TILT)

# A connected piece whose mean unit normal |sum n| / count is shorter than this is closed:
# halfway (in ratio) between a closed cloud's sampling error (~1 / sqrt(n), 0.01 at 10k
# points) and the least one-sided of the views from one side (a hemisphere, 0.5).
CLOSED_MEAN_NORMAL = 0.25
# An open piece whose mean normal m has |m_z| < this x |m| (within ~6 degrees of horizontal)
# faces sideways: "up" does not decide its side.
SIDEWAYS_MEAN_NORMAL_Z = 0.1
# What each rule code of :func:`piece_signs` means: how the piece's normals point.
PIECE_RULES = ("outward (closed surface)", "towards +z (open surface)",
               "away from the centroid (open surface facing sideways)")

# Rows per piece of the whole-cloud steps of :func:`orient_mst` done piecewise to bound their
# temporaries (even: the pieces keep the whole arrays' alignment).
_ROWS = 1 << 16


def _plain(a):
    """Whether ``a`` is a C-contiguous float64 array (used as it is, without a copy)."""
    return isinstance(a, np.ndarray) and a.dtype == np.float64 and a.flags.c_contiguous


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


def orient_along(normals, direction):
    """Flip each normal to have a non-negative component along ``direction`` ((3,), e.g.
    (0, 0, 1): a viewpoint infinitely far that way); in place, returned."""
    flip = normals @ np.asarray(direction, dtype=np.float64) < 0
    normals[flip] *= -1.0
    return normals


def piece_signs(count, normal_sum, centroid_score):
    """The global sign of each connected piece of consistently oriented normals, and the rule
    that gave it (see the module docstring).

    Parameters
    ----------
    count : (c,) float, the area of each piece (the sum of :func:`sample_areas`, in any unit;
        or its points)
    normal_sum : (c, 3) float, the same-weighted sum of its unit normals
    centroid_score : (c,) float, the same-weighted sum over its points of
        ``(p - centroid) . n``, the centroid weighted alike

    Returns
    -------
    sign : (c,) float64, +1 or -1 to multiply the piece's normals by
    rule : (c,) int8, index into :data:`PIECE_RULES`: 0 closed (outward), 1 open (towards +z),
        2 open and facing sideways (away from the centroid)

    >>> sign, rule = piece_signs([100, 100], [[0, 0, 0.5], [0, 0, -60]], [-5.0, 3.0])
    >>> sign.tolist(), rule.tolist()
    ([-1.0, -1.0], [0, 1])
    """
    count = np.asarray(count, dtype=np.float64)
    normal_sum = np.asarray(normal_sum, dtype=np.float64).reshape(-1, 3)
    length = np.linalg.norm(normal_sum, axis=1)
    # a ratio of sums in the same units (areas or points): the same in metres and millimetres
    mean_length = np.divide(length, count, out=np.zeros_like(length), where=count > 0)
    open_piece = mean_length >= CLOSED_MEAN_NORMAL
    facing_up = np.abs(normal_sum[:, 2]) >= SIDEWAYS_MEAN_NORMAL_Z * np.linalg.norm(normal_sum,
                                                                                  axis=1)
    rule = np.where(open_piece, np.where(facing_up, 1, 2), 0).astype(np.int8)
    score = np.where(rule == 1, normal_sum[:, 2], np.asarray(centroid_score, dtype=np.float64))
    return np.where(score < 0, -1.0, 1.0), rule


def sample_areas(points, neighbors, scale=1.0):
    """Share of the surface each point stands for, up to a common factor: the squared distance
    to the farthest of its graph neighbors, measured on ``points * scale`` ((n,) float64; 0 for
    a point without neighbors). A ``scale`` near 1 / the extent keeps the squares of clouds
    at 1e300 or 1e-300 finite and nonzero.

    Weighting the sums of :func:`piece_signs` by it makes their decision independent of the
    sampling density: a closed cloud sampled ten times more densely on one side still has
    area-weighted normals summing to about zero.

    ``points`` (n, 3); ``neighbors`` (n, k) int, indices into ``points``, -1 for none.
    Numpy specification: :func:`meshcurv.normals.orient_spec.sample_area`.
    """
    nb = np.asarray(neighbors)
    if nb.ndim != 2 or len(nb) != len(points):
        raise ValueError(f"neighbors must be ({len(points)}, k), not {nb.shape}")
    return _farthest_neighbor_d2(np.ascontiguousarray(points, dtype=np.float64),
                                 np.ascontiguousarray(nb), float(scale))


@njit(parallel=True, cache=True)
def _farthest_neighbor_d2(points, neighbors, scale):
    """:func:`sample_areas`' kernel: one pass over the graph rows, without the (n, k, 3)
    offsets of the numpy specification (ten times faster)."""
    n, k = neighbors.shape
    out = np.zeros(n)
    nchunks = (n + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        for i in range(c * CHUNK, min(n, (c + 1) * CHUNK)):
            best = 0.0
            for a in range(k):
                j = neighbors[i, a]
                if j < 0:
                    continue
                d0 = (points[j, 0] - points[i, 0]) * scale
                d1 = (points[j, 1] - points[i, 1]) * scale
                d2 = (points[j, 2] - points[i, 2]) * scale
                # in the order numpy's einsum sums three products (x0 x0 + x2 x2) + x1 x1,
                # as the areas were first computed: the same bits
                dd = (d0 * d0 + d2 * d2) + d1 * d1
                if dd > best:
                    best = dd
            out[i] = best
    return out


def nearest_areas(points, query_points, radius, k, workers=1):
    """:func:`sample_areas` of ``query_points`` (m, 3) whose graph is their ``k`` nearest
    ``points`` (n, 3) within ``radius`` (coincident ones left out), as the spanning tree's graph
    from ball lists is: (m,) float64. ``workers``: the k-d tree query's threads (-1: all; the
    same result)."""
    if len(points) == 0 or len(query_points) == 0:
        return np.zeros(len(query_points))
    kk = min(len(points), k + 8)         # room for coincident points
    dist, _ = cKDTree(points).query(query_points, k=kk, distance_upper_bound=radius * (1 + 1e-12),
                                    workers=workers)
    dist = np.asarray(dist).reshape(len(query_points), -1)
    dist = np.where((dist > 0) & np.isfinite(dist), dist, np.inf)
    dist = np.sort(dist, axis=1)[:, :k]
    d2 = np.where(np.isfinite(dist), dist * dist, 0.0)
    return d2.max(axis=1, initial=0.0)


def orientation_note(rule, count):
    """One line saying how pieces with these rules ((c,) int, :func:`piece_signs`) and point
    counts ((c,)) were oriented, e.g. "oriented outward (closed surface)".

    >>> orientation_note([1, 1], [900, 80])
    'oriented towards +z (open surface)'
    >>> orientation_note([0, 2], [900, 80])[:50]
    'oriented by piece: outward (closed surface) on 1 p'
    """
    rule = np.asarray(rule)
    count = np.asarray(count)
    used = [r for r in range(len(PIECE_RULES)) if (count[rule == r] > 0).any()]
    if len(used) == 1:
        return f"oriented {PIECE_RULES[used[0]]}"
    if not used:
        return "not oriented (no normal)"
    parts = []
    for r in used:
        sel = (rule == r) & (count > 0)
        n = int(sel.sum())
        parts.append(f"{PIECE_RULES[r]} on {n} piece{'s' if n > 1 else ''} of "
                     f"{int(count[sel].sum())} points")
    return "oriented by piece: " + ", ".join(parts)


def orient_mst(points, normals, k=10, neighbors=None, note=False):
    """Consistent orientation by propagation over a minimum spanning tree, then one global
    sign per connected piece.

    The k-nearest-neighbor graph is weighted by ``1 - |n_i . n_j|`` (Hoppe et al. 1992), so the
    tree propagates signs along smooth paths first (weights rounded to 4096 steps of
    ``sqrt(w)``, see :func:`meshcurv.orient_spanning_tree`). Each connected piece is
    then flipped as a whole by :func:`piece_signs`: outward if it is closed, towards +z if it is
    open (the side a viewer above sees), away from its centroid if it is open and faces
    sideways.

    Parameters
    ----------
    points : (n, 3) float64; normals : (n, 3) float64 unit, NaN rows are left alone
    k : int, neighbors per point in the graph (when ``neighbors`` is not given)
    neighbors : (n, j) int, optional
        The graph, e.g. from :func:`nearest_in_lists` over lists already at
        hand: row i lists point indices joined to i, -1 for none. Default: the k nearest
        neighbors from a k-d tree.

    note : bool, also return :func:`orientation_note` of the rules the pieces took

    Returns
    -------
    (n, 3) float64, the same array, oriented in place (and the note, with ``note``).
    """
    ok = np.flatnonzero(np.isfinite(normals).all(axis=1) & np.isfinite(points).all(axis=1))
    if len(ok) == 0:
        return (normals, orientation_note([], [])) if note else normals
    # every row kept: the arrays themselves, not copies (``normals`` is oriented in place)
    whole = len(ok) == len(points)
    p = points if whole and _plain(points) else points[ok]
    nv = normals if whole and _plain(normals) else np.ascontiguousarray(normals[ok])
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
    for s in range(0, len(graph), _ROWS):
        # in pieces: on the whole graph numpy's take buffers it (80 bytes per point)
        np.take(rank, graph[s:s + _ROWS], out=graph[s:s + _ROWS], mode="wrap")
    nv_sorted = np.ascontiguousarray(nv[order])
    labels = orient_spanning_tree(nv_sorted, graph, 4096)
    del graph
    nv[order] = nv_sorted
    labels_input = np.empty_like(labels)
    labels_input[order] = order[labels]
    labels = labels_input
    # one global decision per connected piece, each point standing for its share of the area
    n_comp = len(ok)                       # labels are root rows: bins 0..len(ok) - 1
    count = np.bincount(labels, minlength=n_comp)
    # in a unit of a power of two above every |coordinate|: the same bits as in model units
    # wherever those neither overflow nor underflow (clouds at 1e300, 1e-300, or both)
    unit = math.ldexp(1.0, min(1000, -math.frexp(float(np.abs(p).max()))[1]))
    area = sample_areas(p, nb, unit)
    weight = np.bincount(labels, weights=area, minlength=n_comp)
    size = np.where(weight > 0, weight, 1.0)
    centroid = np.column_stack([np.bincount(labels, weights=area * (p[:, c] * unit),
                                            minlength=n_comp)
                                for c in range(3)]) / size[:, None]
    along = np.empty(len(p))
    for s in range(0, len(p), _ROWS):
        # in pieces: no (n, 3) offsets from the centroids
        e = s + _ROWS
        along[s:e] = area[s:e] * np.einsum("ij,ij->i", p[s:e] * unit - centroid[labels[s:e]],
                                           nv[s:e])
    score = np.bincount(labels, weights=along, minlength=n_comp)
    del along
    normal_sum = np.column_stack([np.bincount(labels, weights=area * nv[:, c],
                                              minlength=n_comp) for c in range(3)])
    sign, rule = piece_signs(weight, normal_sum, score)
    nv[sign[labels] < 0] *= -1.0
    if nv is not normals:
        normals[ok] = nv
    return (normals, orientation_note(rule, count)) if note else normals


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
def graph_pieces(neighbors):
    """(n,) int64 label of each point's connected piece of the graph ``neighbors`` ((n, k)
    int, -1 for none; edges undirected): the lowest point index in the piece."""
    n, k = neighbors.shape
    parent = np.arange(n)
    for i in range(n):
        for a in range(k):
            j = neighbors[i, a]
            if j >= 0:
                ri = _find_root(parent, i)
                rj = _find_root(parent, j)
                if ri != rj:
                    parent[max(ri, rj)] = min(ri, rj)
    labels = np.empty(n, dtype=np.int64)
    for i in range(n):
        labels[i] = _find_root(parent, i)
    return labels


@njit(parallel=True, cache=True)
def nearest_in_other_piece(points, query_points, indptr, indices, vertex, labels, own,
                           normals, query_normals):
    """For each query point, the vertex (``vertex[j]`` of list entry j, an index into
    ``labels``) nearest to it in its CSR list whose piece ``labels[...]`` differs from the
    query's ``own[q]``, where that vertex lies within :data:`BRIDGE_TILT` of the tangent
    plane of both (``query_normals`` (m, 3) and ``normals`` (n, 3) by vertex, unit, either
    sign; a NaN normal does not refuse); -1 where the list holds none or the nearest lies
    across a gap (the next nearest, slanting, would be no better). Points coinciding with
    the query point are left out (as :func:`nearest_in_lists` does). Returns (m,) int32."""
    m = query_points.shape[0]
    out = np.full(m, -1, dtype=np.int32)
    across2 = BRIDGE_ACROSS * BRIDGE_ACROSS
    for q in prange(m):
        best = np.inf
        e0 = e1 = e2 = 0.0                      # the offset to the nearest
        for e in range(indptr[q], indptr[q + 1]):
            i = indices[e]
            if labels[vertex[i]] == own[q]:
                continue
            d0 = points[i, 0] - query_points[q, 0]
            d1 = points[i, 1] - query_points[q, 1]
            d2 = points[i, 2] - query_points[q, 2]
            dd = d0 * d0 + d1 * d1 + d2 * d2
            if dd > 0.0 and dd < best:
                best = dd
                out[q] = vertex[i]
                e0, e1, e2 = d0, d1, d2
        j = out[q]
        if j >= 0:
            hq = e0 * query_normals[q, 0] + e1 * query_normals[q, 1] + e2 * query_normals[q, 2]
            hj = e0 * normals[j, 0] + e1 * normals[j, 1] + e2 * normals[j, 2]
            if hq * hq > across2 * best or hj * hj > across2 * best:
                out[q] = -1                 # stacked: across a gap between two surfaces
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
