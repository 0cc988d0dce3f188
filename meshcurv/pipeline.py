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

from .fit import fused, jet
from .neighbors import (MAX_BALL_FRACTION, BallGrid, KringWork, ball_counts, ball_grid,
                        ball_neighbors, edge_adjacency, kring_counts, kring_neighbors,
                        spatial_order)
from .normals import face_vertex_normals, orient, orient_like, orient_mst, orient_towards, \
    pca_normals
from .result import CurvatureResult, Status

__all__ = ["run", "estimate_normals", "weight_blend", "Search", "ball_search", "kring_search",
           "block_size", "blocks", "mst_normals", "retry_sparse", "BLOCK", "BLOCK_ENTRIES",
           "MAX_PAIRS", "NOISE_SCALE", "SPARSE_FACTORS", "MAX_BALL_FRACTION"]

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

# Radii, as multiples of the call's, at which :func:`retry_sparse` re-estimates the vertices
# whose ball held too few points, each at the smallest that serves (the larger the ball, the
# more the curvature varies inside it): up to 16 times the area, so a patch sampled 16 times
# more sparsely than the default radius' target still gets its ~100 points.
SPARSE_FACTORS = (1.5, 2.0, 3.0, 4.0)
# Fewest neighbors of a half-set in the last resort of :func:`retry_sparse`.
SPARSE_MIN_POINTS = 1
# Statuses of fits that failed for lack of points.
SPARSE_STATUSES = (Status.TOO_FEW_NEIGHBORS, Status.TOO_FEW_HALF_SETS, Status.ILL_POSED_FIT,
                   Status.DEGENERATE_DIRECTIONS)

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


def mst_normals(v, radius, search, progress, block=BLOCK):
    """PCA normals of every point, oriented along a spanning tree whose graph joins each point
    to its nearest neighbors, taken from the search's lists (see :func:`ball_search`)."""
    n = len(v)
    nv = np.full((n, 3), np.nan)
    graph = np.full((n, _TREE_NEIGHBORS), -1, dtype=np.int32)
    # the grid's own cell order (``rank``) when there is one, else one made for the purpose
    rank = search.rank
    order = rank if rank is not None else spatial_order(v, radius)
    for pos in blocks(order, progress, "normals", block):
        indptr, indices = search.neighbors(pos)
        nv[pos] = pca_normals(search.points, v[pos], indptr, indices, radius)
        near = orient.nearest_in_lists(search.points, v[pos], indptr, indices, _TREE_NEIGHBORS)
        graph[pos] = near if rank is None else np.where(near >= 0, rank[near], -1)
    return orient_mst(v, nv, neighbors=graph)


def estimate_normals(v, radius, progress=False):
    """Oriented PCA normals (n, 3) of the cloud ``v`` ((n, 3) float64, contiguous; radius in
    model units, squaring safely): the "mst" normals of :func:`run`."""
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    return _spanning_tree_normals(v, radius, ball_search(v, finite, radius), finite, progress)


def _spanning_tree_normals(v, radius, search, finite, progress):
    """:func:`mst_normals` of the ``finite`` (k,) rows of ``v`` over the ball ``search``, in
    blocks sized for their neighbor lists."""
    return mst_normals(v, radius, search, progress, block_size(search, finite, radius, "points"))


def _start_normals(v, f, given, radius, search, finite, plan, progress):
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
        return _spanning_tree_normals(v, radius, search, finite, progress), None
    return (face_normals if plan.normals == "faces" else None), face_normals


def _block_normals(nv, face_normals, idx, xb, indptr, indices, radius, search, plan):
    """Unit normals of one block: taken from ``nv``, or PCA plane fits oriented like the face
    normals or towards the viewpoint."""
    if nv is not None:
        qb = nv[idx]
    else:
        qb = pca_normals(search.points, xb, indptr, indices, radius)
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

    def result(self, radius):
        return CurvatureResult(k1=self.k1, k2=self.k2, d1=self.d1, d2=self.d2,
                               normals=self.normals, valid=np.isfinite(self.k1),
                               n_neighbors=self.n_neighbors, n_samples=self.n_samples,
                               residual=self.residual, noise=self.noise, radius=radius,
                               status=self.status)


def _fit_block(out, pos, xb, qb, indptr, indices, radius, search, plan):
    """Local jet (noise, refined normal) and the fused fits of one block, into ``out[pos]``."""
    b = len(xb)
    noise = np.empty(b)
    start = qb.copy() if plan.refine else None
    jet.local_jet(search.points, xb, qb, indptr, indices, radius, plan.refine, noise)
    beta = weight_blend(noise, radius, "auto")
    if plan.refine:
        qb = _mix_normals(start, qb, beta)
    k1, k2, residual, samples, nbrs = (np.empty(b) for _ in range(5))
    d1, d2 = np.empty((b, 3)), np.empty((b, 3))
    status = np.empty(b, dtype=np.int8)
    blend = beta if plan.weighting == "auto" else weight_blend(noise, radius, plan.weighting)
    fused.curvature_cga(search.points, xb, qb, indptr, indices, radius, blend, plan.fit,
                        (k1, k2, d1, d2, samples, residual, nbrs, status), search.rank)
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
        qb = _block_normals(nv, face_normals, idx, xb, indptr, indices, radius, search, plan)
        _fit_block(out, pos, xb, qb, indptr, indices, radius, search, plan)
        del indptr, indices
    if plan.sparse_retry:
        retry_sparse(out, v, f, nv, face_normals, radius, query, plan, search)
    return out.result(radius)


def _needs_support(out, plan):
    """Rows of ``out`` estimated from too few points: fits that failed for lack of them (and,
    for estimated normals, plane fits that had no 3 points), and estimates whose local cubic
    fit had no 11 points (noise NaN: no noise measured, normal not refined)."""
    lacking = np.isin(out.status, SPARSE_STATUSES)
    if plan.normals != "given":
        lacking |= out.status == Status.NO_NORMAL
    thin = (out.status == Status.OK) & ~np.isfinite(out.noise)
    return np.flatnonzero(lacking | thin)


def _reference_normals(nv, trusted, rank, indptr, indices):
    """A sign reference per neighbor list: the sum of the normals ``nv`` (vertex order) of its
    ``trusted`` vertices ((n,) bool, finite normals), zero where it has none (``rank`` maps
    list entries to vertices, None if they are vertices)."""
    rows = indices if rank is None else rank[indices]
    nb = np.where(trusted[rows, None], nv[rows], 0.0)
    owner = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    ref = np.zeros((len(indptr) - 1, 3))
    np.add.at(ref, owner, nb)
    return ref


def _refit(v, idx, nv, face_normals, r, search, plan, own_normals, trusted=None):
    """:class:`_Outputs` of the vertices ``idx`` at radius ``r`` over ``search``. Normals: the
    given or face ones (``nv``); else plane fits over the ball of ``r``, oriented like the
    faces, the viewpoint or, for spanning-tree normals (``own_normals`` False), the
    spanning-tree normals ``nv`` of the ``trusted`` vertices in the ball (see
    :func:`_reference_normals`; none where the ball holds none of them)."""
    sub = _Outputs(len(idx))
    for pos in blocks(len(idx), False, "", block_size(search, idx, r, "points")):
        xb = v[idx[pos]]
        indptr, indices = search.neighbors(idx[pos])
        if plan.normals == "mst" and not own_normals:
            qb = pca_normals(search.points, xb, indptr, indices, r)
            ref = _reference_normals(nv, trusted, search.rank, indptr, indices)
            orient_like(qb, ref)
            qb[~np.any(ref != 0.0, axis=1)] = np.nan     # no side to take: no normal
            with np.errstate(invalid="ignore", divide="ignore"):
                qb /= np.linalg.norm(qb, axis=1, keepdims=True)
        else:
            qb = _block_normals(nv, face_normals, idx[pos], xb, indptr, indices, r, search,
                                plan)
        _fit_block(sub, pos, xb, qb, indptr, indices, r, search, plan)
    return sub


def _take(out, rows, sub, done):
    """Copy the rows ``done`` of ``sub`` into rows ``rows[done]`` of ``out``."""
    for name in ("k1", "k2", "d1", "d2", "normals", "n_samples", "residual", "noise",
                 "n_neighbors", "status"):
        getattr(out, name)[rows[done]] = getattr(sub, name)[done]


def retry_sparse(out, v, f, nv, face_normals, radius, query, plan, search):
    """Re-estimate, in place, the rows of ``out`` that had too few points (:func:`_needs_support`).

    First at ``SPARSE_FACTORS`` times ``radius``, each row at the first factor whose fit
    succeeds with a ball of at most ``MAX_BALL_FRACTION`` of the finite points. The fits that
    still fail then at ``radius`` and at those factors again with half-sets of
    ``SPARSE_MIN_POINTS`` point: a coarse ring (a low-poly mesh's 1-ring) puts one or two points
    in each half-set, and the circle through x and one point p centred on the normal line is
    the classic ``2 h / |p - x|^2`` estimate of the normal curvature towards p (exact on
    spheres), 5 or more of them averaged by the Euler fit. ``search`` is the search of
    ``radius``. Rows nothing serves keep their estimate, except on clouds with estimated
    normals, where an estimate from fewer than 11 points has no checked normal and is dropped.
    """
    rows = _needs_support(out, plan)
    if not len(rows):
        return
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    most = MAX_BALL_FRACTION * len(finite)
    sparse = plan._replace(fit=plan.fit[:2] + (float(SPARSE_MIN_POINTS),) + plan.fit[3:])
    wide = {1.0: search}       # the searches of the larger radii, made when first needed

    def search_at(factor):
        if factor not in wide:
            r = radius * factor
            wide[factor] = kring_search(v, f, r) if plan.use_kring else ball_search(v, finite, r)
        return wide[factor]
    passes = [(factor, plan) for factor in SPARSE_FACTORS]
    if plan.fit[2] > SPARSE_MIN_POINTS:
        passes += [(factor, sparse) for factor in (1.0,) + SPARSE_FACTORS]
    # sign references of the spanning-tree normals: points with 11 neighbors (a sparse clump's
    # tree may be a piece of its own, turned away from its own centroid), and those oriented
    # by a pass
    trusted = np.zeros(len(v), dtype=bool)
    trusted[query] = np.isfinite(out.noise) & np.isfinite(out.normals).all(axis=1)
    reference = nv.copy() if plan.normals == "mst" else None
    for factor, how in passes:
        rows = rows[(out.status[rows] != Status.OK) |
                    (~np.isfinite(out.noise[rows]) & (how is plan))]
        if not len(rows):
            break
        local = rows[search_at(factor).counts(query[rows]) <= most] if factor > 1.0 else rows
        if not len(local):
            continue
        sub = _refit(v, query[local], reference if reference is not None else nv,
                     face_normals, radius * factor, search_at(factor), how,
                     how is sparse and factor == 1.0, trusted)
        done = (sub.status == Status.OK) & ((sub.n_neighbors <= most) | (factor == 1.0))
        if how is sparse and not plan.use_kring:
            # one-point half-sets of a cloud only where the cubic fit checked the normal; a
            # mesh's rings are its own neighborhoods (an icosahedron's 1-ring: 5 points)
            done &= np.isfinite(sub.noise)
        _take(out, local, sub, done)
        if reference is not None:
            oriented = done & np.isfinite(sub.noise)
            trusted[query[local[oriented]]] = True
            reference[query[local[oriented]]] = sub.normals[oriented]
    if plan.normals in ("mst", "pca") and not plan.use_kring:
        # a plane fit through fewer than 11 points of a clumpy cloud may be tilted by 90
        # degrees, and no larger ball served: no estimate
        thin = (out.status == Status.OK) & ~np.isfinite(out.noise)
        for name in ("k1", "k2", "d1", "d2", "residual"):
            getattr(out, name)[thin] = np.nan
        out.status[thin] = Status.TOO_FEW_NEIGHBORS
