"""The block loop of the estimator: neighborhoods -> normals -> local jet (noise, refined
normal) -> fused circle and Euler fits -> :class:`~meshcurv.result.CurvatureResult`.

:func:`run` takes validated arrays, a numeric radius and a :class:`~meshcurv.options.Plan`
(input checks, radius policy and options are :mod:`meshcurv.api`'s). Query points go through
the compiled kernels in blocks, which bounds the memory of the neighbor lists.
"""

from typing import Callable, NamedTuple

import numpy as np
from scipy.spatial import cKDTree
from tqdm.auto import tqdm

from .fit import fused, jet, outliers
from .fit.constants import TUKEY_C
from .neighbors import (BallGrid, KringWork, ball_counts, ball_grid, ball_neighbors,
                        edge_adjacency, kring_counts, kring_neighbors, spatial_order)
from .normals import face_vertex_normals, orient, orient_like, orient_mst, orient_towards, \
    pca_normals
from .result import CurvatureResult, Status

__all__ = ["run", "estimate_normals", "weight_blend", "Search", "ball_search", "kring_search",
           "block_size", "blocks", "mst_normals", "outlier_scores", "BLOCK", "BLOCK_ENTRIES", "MAX_PAIRS",
           "NOISE_SCALE"]

# Query points per call into the kernels: bounds the memory of the neighbor lists (about
# 0.8 kB per query point at 100 neighbors) at no measurable cost in speed.
BLOCK = 16384
# Neighbor list entries per block (int64): blocks shrink where the balls hold more than
# 1024 points (a radius much larger than the sampling), so their lists stay within ~128 MB.
BLOCK_ENTRIES = 2 ** 24
# Most neighbor pairs (query points x neighbors) a call takes on: hours of work beyond.
MAX_PAIRS = 1e11

# Noise level (RMS height residual of the local cubic fit, as a fraction of the radius) at
# which weighting="auto" mixes equal and distance weights half and half. Measured: clean
# samples of the test surfaces stay below 0.09 % of the radius (Table 2 paraboloid 0.02 %,
# torus 0.08 %), normal noise of 0.03 % of the bounding-box diagonal already gives 0.6-0.9 %,
# and from there on equal weights are the more accurate.
NOISE_SCALE = 2e-3

# Neighbors per point in the graph of the spanning-tree orientation.
_TREE_NEIGHBORS = 10


class Search(NamedTuple):
    """Neighborhoods of one radius: ``neighbors(idx)`` the CSR lists of the points ``v[idx]``
    (unsorted: the kernels do not depend on the order within a list), ``counts(idx)`` their
    lengths (nothing stored), ``points`` the coordinates the lists index (the grid's copy in
    grid order, or ``v``) and ``rank`` their vertex indices (None when ``points`` is ``v``)."""

    neighbors: Callable
    counts: Callable
    points: np.ndarray
    rank: object


def _mix_normals(start, refined, beta):
    """``start + beta (refined - start)``, normalised, row by row.

    With beta from the measured noise: the quadric's normal on clean data (no tilt from
    irregular sampling), the starting one (usually the plane fit's, which averages the most
    points) under noise.
    """
    mixed = start + beta[:, None] * (refined - start)
    with np.errstate(invalid="ignore", divide="ignore"):
        return mixed / np.linalg.norm(mixed, axis=1, keepdims=True)


def weight_blend(noise, radius, weighting="auto"):
    """Per-vertex mix of the circle fits' weight functions, in [0, 1] (1 = distance weights).

    "auto": ``1 / (1 + (noise / (NOISE_SCALE * radius))^4)``, i.e. distance weights where the
    local cubic fit explains the points (clean data: less bias), equal weights where it leaves
    noise (less variance); NaN noise (too few points for the fit) gives equal weights.
    """
    noise = np.asarray(noise, dtype=np.float64)
    if weighting == "distance":
        return np.ones_like(noise)
    if weighting == "none":
        return np.zeros_like(noise)
    with np.errstate(invalid="ignore"):
        beta = 1.0 / (1.0 + (noise / (NOISE_SCALE * radius)) ** 4)
    return np.where(np.isfinite(beta), beta, 0.0)


def blocks(order, progress, desc, size=BLOCK):
    """Blocks of ``size`` positions, with a progress bar when asked.

    ``order`` is an index array (blocks are its pieces) or a count m (blocks are slices of
    ``range(m)``, which index without copies).
    """
    m = order if isinstance(order, (int, np.integer)) else len(order)
    bar = tqdm(total=m, desc=desc, unit="pt", disable=not progress, leave=False)
    for s in range(0, m, size):
        e = min(s + size, m)
        yield slice(s, e) if isinstance(order, (int, np.integer)) else order[s:e]
        bar.update(e - s)
    bar.close()


def _sample_queries(m, size=64):
    """Up to ``size`` positions spread over ``range(m)``."""
    return np.unique(np.linspace(0, m - 1, min(m, size)).astype(np.int64)) if m else \
        np.zeros(0, dtype=np.int64)


def block_size(search, queries, radius, what):
    """Queries per block for the neighbor lists of ``queries`` (their mean length from a
    sample), raising ValueError where they are more work than :data:`MAX_PAIRS`."""
    counts = search.counts(queries[_sample_queries(len(queries))])
    per = max(float(np.mean(counts)) if len(counts) else 0.0, 1.0)
    if per * len(queries) > MAX_PAIRS:
        raise ValueError(
            f"radius {radius:.6g} is too large for these {what}: each neighborhood would hold "
            f"about {per:.3g} points ({per * len(queries):.3g} neighbor pairs in all, far too "
            f"many to compute); use a smaller radius")
    return int(min(BLOCK, max(1, BLOCK_ENTRIES // per)))


def ball_search(v, finite, radius):
    """:class:`Search` by ball queries over the finite rows ``finite`` of ``v``.

    With a uniform grid (when one fits; the same lists as a k-d tree, several times faster)
    the lists hold rows of the grid's copy of the points, where a neighborhood lies together
    in memory however the input is ordered; else a k-d tree over ``v[finite]``.
    """
    tree = ball_grid(v, radius) if len(finite) else None
    if tree is None and len(finite):
        tree = cKDTree(v[finite])
    in_grid = isinstance(tree, BallGrid)

    def neighbors(idx):
        if tree is None:
            return np.zeros(len(idx) + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return ball_neighbors(tree, finite, v[idx], radius, ascending=False, positions=in_grid)

    def counts(idx):
        if tree is None:
            return np.zeros(len(idx), dtype=np.int64)
        return ball_counts(tree, v[idx], radius)

    return Search(neighbors, counts, tree.sorted_points if in_grid else v,
                  tree.order if in_grid else None)


def kring_search(v, f, radius):
    """:class:`Search` by connected k-rings over the mesh edges of faces ``f``, limited to the
    ball of ``radius``."""
    adjacency = edge_adjacency(f, len(v))
    work = KringWork(len(v))

    def neighbors(idx):
        return kring_neighbors(v, adjacency, radius, idx, work)

    def counts(idx):
        return kring_counts(v, adjacency, radius, idx, work)
    return Search(neighbors, counts, v, None)


def outlier_scores(v, radius, search, rows, progress, block=BLOCK):
    """Outlier scores (n,) of the points ``v[rows]`` (NaN elsewhere): each one's residual from
    a robust height fit of its neighborhood over its robust scale, as a Gaussian deviate
    (:func:`meshcurv.fit.outliers.point_residuals`, :func:`~meshcurv.fit.outliers.outlier_score`)."""
    score = np.full(len(v), np.nan)
    for pos in blocks(rows, progress, "outliers", block):
        indptr, indices = search.neighbors(pos)
        residual, scale, dof = (np.empty(len(pos)) for _ in range(3))
        outliers.point_residuals(search.points, v[pos], indptr, indices, radius, residual, scale,
                                 dof)
        score[pos] = outliers.outlier_score(residual, scale, dof)
    return score


def _scored_rows(v, search, query, finite, block):
    """The vertices whose outlier scores the estimates at ``query`` use: every finite one, or,
    for a few queries, those and their neighbors."""
    if finite is None:
        finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    if len(query) >= len(finite) // 4:
        return finite
    parts = [query]
    for s in range(0, len(query), block):
        rows = np.unique(search.neighbors(query[s:s + block])[1])
        parts.append(rows if search.rank is None else search.rank[rows])
    rows = np.unique(np.concatenate(parts))
    return rows[np.isfinite(v[rows]).all(axis=1)]


def mst_normals(v, radius, search, progress, block=BLOCK, point_weights=None):
    """PCA normals of every point, oriented along a spanning tree whose graph joins each point
    to its nearest neighbors, taken from the search's lists (see :func:`ball_search`);
    ``point_weights`` (per row of ``search.points``) weight the plane fits."""
    n = len(v)
    nv = np.full((n, 3), np.nan)
    graph = np.full((n, _TREE_NEIGHBORS), -1, dtype=np.int32)
    # the grid's own cell order (``rank``) when there is one, else one made for the purpose
    rank = search.rank
    order = rank if rank is not None else spatial_order(v, radius)
    for pos in blocks(order, progress, "normals", block):
        indptr, indices = search.neighbors(pos)
        nv[pos] = pca_normals(search.points, v[pos], indptr, indices, radius, point_weights)
        near = orient.nearest_in_lists(search.points, v[pos], indptr, indices, _TREE_NEIGHBORS)
        graph[pos] = near if rank is None else np.where(near >= 0, rank[near], -1)
    return orient_mst(v, nv, neighbors=graph)


def estimate_normals(v, radius, progress=False):
    """Oriented PCA normals (n, 3) of the cloud ``v`` ((n, 3) float64, contiguous; radius in
    model units, squaring safely): the "mst" normals of :func:`run`."""
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    return _spanning_tree_normals(v, radius, ball_search(v, finite, radius), finite, progress)


def _spanning_tree_normals(v, radius, search, finite, progress, point_weights=None):
    """:func:`mst_normals` of the ``finite`` (k,) rows of ``v`` over the ball ``search``, in
    blocks sized for their neighbor lists."""
    return mst_normals(v, radius, search, progress, block_size(search, finite, radius, "points"),
                       point_weights)


def _start_normals(v, f, given, radius, search, finite, plan, progress, point_weights=None):
    """``(normals, face_normals)`` before the blocks: the given ones, the faces', or the
    spanning tree's (which needs every normal first); None where blocks estimate their own.
    ``finite``: the finite rows of ``v`` (ball searches only)."""
    if plan.normals == "given":
        return given, None
    face_normals = None
    if f is not None:
        with np.errstate(invalid="ignore"):       # NaN vertices give NaN normals
            face_normals = face_vertex_normals(v, f)
    if plan.normals == "mst":
        return _spanning_tree_normals(v, radius, search, finite, progress, point_weights), None
    return (face_normals if plan.normals == "faces" else None), face_normals


def _block_normals(nv, face_normals, idx, xb, indptr, indices, radius, search, plan,
                   point_weights=None):
    """Unit normals of one block: taken from ``nv``, or PCA plane fits oriented like the face
    normals or towards the viewpoint."""
    if nv is not None:
        qb = nv[idx]
    else:
        qb = pca_normals(search.points, xb, indptr, indices, radius, point_weights)
        if face_normals is not None:
            orient_like(qb, face_normals[idx])
        else:
            orient_towards(qb, xb, plan.viewpoint)
    with np.errstate(invalid="ignore", divide="ignore"):
        return qb / np.linalg.norm(qb, axis=1, keepdims=True)


class _Outputs:
    """The result arrays of :func:`run`, filled block by block."""

    def __init__(self, m):
        self.k1, self.k2, self.residual, self.noise = (np.full(m, np.nan) for _ in range(4))
        self.d1, self.d2, self.normals = (np.full((m, 3), np.nan) for _ in range(3))
        self.n_samples = np.zeros(m, dtype=np.int32)
        self.n_neighbors = np.zeros(m, dtype=np.int32)
        self.status = np.zeros(m, dtype=np.int8)
        self.outlier_score = np.full(m, np.nan)

    def flag_outliers(self):
        """No curvature, status OUTLIER, where the outlier score reaches the Tukey cutoff (the
        points of weight 0 in their neighbors' fits) - unless the point's own position or
        normal already gave a reason."""
        with np.errstate(invalid="ignore"):
            out = (self.outlier_score >= TUKEY_C) & (self.status != Status.NO_POSITION) & \
                (self.status != Status.NO_NORMAL)
        for a in (self.k1, self.k2, self.d1, self.d2, self.residual):
            a[out] = np.nan
        self.status[out] = Status.OUTLIER

    def result(self, radius):
        return CurvatureResult(k1=self.k1, k2=self.k2, d1=self.d1, d2=self.d2,
                               normals=self.normals, valid=np.isfinite(self.k1),
                               n_neighbors=self.n_neighbors, n_samples=self.n_samples,
                               residual=self.residual, noise=self.noise, radius=radius,
                               status=self.status, outlier_score=self.outlier_score)


def _fit_block(out, pos, xb, qb, indptr, indices, radius, search, plan, point_weights=None):
    """Local jet (noise, refined normal) and the fused fits of one block, into ``out[pos]``;
    ``point_weights`` (per row of ``search.points``) weight the neighbors in both."""
    b = len(xb)
    noise = np.empty(b)
    start = qb.copy() if plan.refine else None
    jet.local_jet(search.points, xb, qb, indptr, indices, radius, plan.refine, noise,
                  point_weights)
    beta = weight_blend(noise, radius, "auto")
    if plan.refine:
        qb = _mix_normals(start, qb, beta)
    k1, k2, residual, samples, nbrs = (np.empty(b) for _ in range(5))
    d1, d2 = np.empty((b, 3)), np.empty((b, 3))
    status = np.empty(b, dtype=np.int8)
    blend = beta if plan.weighting == "auto" else weight_blend(noise, radius, plan.weighting)
    fused.curvature_cga(search.points, xb, qb, indptr, indices, radius, blend, plan.fit,
                        (k1, k2, d1, d2, samples, residual, nbrs, status), search.rank,
                        point_weights)
    out.k1[pos], out.k2[pos], out.d1[pos], out.d2[pos] = k1, k2, d1, d2
    out.normals[pos], out.n_samples[pos], out.residual[pos] = qb, samples, residual
    out.n_neighbors[pos], out.noise[pos], out.status[pos] = nbrs, noise, status


def run(v, f, given_normals, radius, query, plan, progress=False):
    """Principal curvatures at the vertices ``query`` of ``v``: the estimator's block loop.

    Parameters
    ----------
    v : (n, 3) float64, contiguous; f : (m, 3) int64 or None, validated faces
    given_normals : (n, 3) float64 or None; radius : float, model units, squaring safely
    query : (q,) int64 vertex indices; plan : :class:`meshcurv.options.Plan`
    progress : bool, progress bars

    Returns
    -------
    CurvatureResult with q rows
    """
    if plan.use_kring:
        finite, search = None, kring_search(v, f, radius)
    else:
        finite = np.flatnonzero(np.isfinite(v).all(axis=1))
        search = ball_search(v, finite, radius)
    # work per query from a sample: smaller blocks for large balls, an error for infeasible ones
    block = block_size(search, query, radius, "vertices" if f is not None else "points")
    score = point_weights = None
    if plan.robust_points:
        # scores by vertex; weights by row of search.points (the grid's order where it has one)
        score = outlier_scores(v, radius, search, _scored_rows(v, search, query, finite, block),
                               progress, block)
        weight = outliers.outlier_weight(score)
        point_weights = weight if search.rank is None else weight[search.rank]
    # the spanning tree's normals unweighted: they are estimate_normals', which tiled runs
    # share between tiles (the weighted local jet refines them)
    nv, face_normals = _start_normals(v, f, given_normals, radius, search, finite, plan,
                                      progress)
    out = _Outputs(len(query))
    # queries by grid cell for ball queries (the points a block touches then stay in cache);
    # as given for k-rings, whose memory accesses follow the mesh's own numbering
    order = len(query) if plan.use_kring else spatial_order(v[query], radius)
    for pos in blocks(order, progress, "curvature", block):
        idx = query[pos]
        xb = v[idx]
        indptr, indices = search.neighbors(idx)
        qb = _block_normals(nv, face_normals, idx, xb, indptr, indices, radius, search, plan,
                            point_weights)
        _fit_block(out, pos, xb, qb, indptr, indices, radius, search, plan, point_weights)
        del indptr, indices
    if score is not None:
        out.outlier_score[:] = score[query]
        out.flag_outliers()
    return out.result(radius)
