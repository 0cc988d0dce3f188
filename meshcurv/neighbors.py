"""Neighbourhoods N(x): radius-limited k-rings over mesh edges, ball queries in point clouds.

Both return CSR lists ``(indptr, indices)``: the neighbours of query ``i`` are
``indices[indptr[i]:indptr[i + 1]]``, indices into the full vertex array. Points with NaN or
infinite coordinates are never anyone's neighbour and have no neighbours themselves.
"""

from typing import NamedTuple

import numba
import numpy as np
from scipy.spatial import cKDTree

from . import kernels

__all__ = ["edge_adjacency", "kring_neighbors", "kring_counts", "KringWork", "BallGrid",
           "ball_grid", "spatial_order", "ball_neighbors", "ball_counts", "default_radius",
           "power_of_two_scale"]


def edge_adjacency(faces, n_vertices):
    """Undirected edge graph of a triangle mesh as CSR ``(indptr, indices)`` over vertices.

    Parameters
    ----------
    faces : (m, 3) int, vertex indices (validated by the caller)
    n_vertices : int

    Degenerate faces contribute only their distinct edges; non-manifold edges are fine.
    Each row is sorted and holds every neighbour once. ``indptr`` (n + 1,) int64, ``indices``
    int32.
    """
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    return kernels.edge_adjacency_csr(faces, int(n_vertices))


class KringWork:
    """Reusable work arrays of :func:`kring_neighbors` for repeated calls on one mesh.

    ``threads x n`` int32 visited stamps and queues (8 bytes per vertex and thread), allocated
    once instead of per call; each call takes fresh stamp values from ``next_tag`` (three per
    query vertex), and the stamps are cleared when those would pass ``2**31``.
    """

    def __init__(self, n_vertices, n_threads=None):
        t = numba.get_num_threads() if n_threads is None else int(n_threads)
        self.stamp = np.full((max(1, t), n_vertices), -1, dtype=np.int32)
        self.queue = np.empty((max(1, t), n_vertices), dtype=np.int32)
        self.next_tag = 0

    def take_tags(self, count):
        """First of ``count`` fresh query tags (stamp values ``3 * tag + {0, 1, 2}``)."""
        if 3 * (self.next_tag + count) + 3 >= 2 ** 31:
            self.stamp.fill(-1)
            self.next_tag = 0
        tag0 = self.next_tag
        self.next_tag += count
        return tag0


def kring_neighbors(points, adjacency, radius, query, work=None):
    """Connected, radius-limited k-ring of each query vertex.

    Breadth-first over mesh edges from the query vertex, keeping (and expanding through) only
    vertices within Euclidean distance ``radius``: the part of the ball that is reachable on the
    surface, so the other side of a thin sheet is never reached.

    Parameters
    ----------
    points : (n, 3) float64
    adjacency : CSR ``(indptr, indices)`` from :func:`edge_adjacency`
    radius : float, model units
    query : (m,) int64, vertices to collect neighbourhoods for
    work : KringWork, optional
        Work arrays to reuse across calls on the same mesh (saves an O(n) allocation per call).

    Returns
    -------
    indptr : (m + 1,) int64; indices : (nnz,) int64 (query vertex excluded, breadth-first order)
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    query = np.ascontiguousarray(query, dtype=np.int64)
    if work is None:
        work = KringWork(len(points))
    tag0 = work.take_tags(len(query))
    return kernels.kring_ball_csr(adjacency[0], adjacency[1], points, query, float(radius),
                                       work.stamp, work.queue, tag0)


def kring_counts(points, adjacency, radius, query, work=None):
    """(m,) int64 size of each query vertex's neighbourhood in :func:`kring_neighbors`,
    without storing the lists (to size the work first)."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    query = np.ascontiguousarray(query, dtype=np.int64)
    if work is None:
        work = KringWork(len(points))
    tag0 = work.take_tags(len(query))
    return kernels.kring_counts(adjacency[0], adjacency[1], points, query, float(radius),
                                work.stamp, work.queue, tag0)


class BallGrid(NamedTuple):
    """Uniform grid over the finite points of a cloud for ball queries of one radius.

    Built by :func:`ball_grid`. Cells are those of the lattice ``floor(coordinate / cell)``
    (:func:`meshcurv.kernels.lattice_cells`). ``order`` lists point indices cell by cell
    (ascending within a cell) and ``sorted_points`` their coordinates in that order. Dense form
    (``table_keys`` empty): the block of ``dims`` cells from lattice cell ``base``, numbered
    x-major, z fastest, cell ``c`` starting at ``cell_start[c]``. Hashed form (sparse extents;
    ``base``, ``dims`` unused): ``cell_start`` over the occupied cells only, found from their
    packed keys through ``table_keys``/``table_cells``. Both give the same lists.
    """

    radius: float
    base: np.ndarray
    cell: float
    order: np.ndarray
    sorted_points: np.ndarray
    cell_start: np.ndarray
    dims: np.ndarray
    table_keys: np.ndarray
    table_cells: np.ndarray


# Dense grids hold up to this many cells per point (int64 each); sparser extents are hashed.
_DENSE_CELLS_PER_POINT = 4


def _dense_block(cells, n_points):
    """``(base, dims)`` of the block of lattice cells holding ``cells`` ((k, 3) int64), or None
    if it would hold more than ``4 n + 2**20`` cells (then a hashed grid is used)."""
    if len(cells) == 0:
        return None
    base = cells.min(axis=0)
    dims = cells.max(axis=0) - base + 1          # clamped cell numbers: no overflow
    if float(np.prod(dims.astype(np.float64))) > _DENSE_CELLS_PER_POINT * n_points + 2 ** 20:
        return None
    return base, dims


def ball_grid(points, radius):
    """Grid index for :func:`ball_neighbors` over the finite rows of ``points``.

    Cells are a little wider than ``radius``, so a ball lies within the 27 cells around its
    centre's cell. Returns None if ``radius`` is not a positive finite number.

    Parameters
    ----------
    points : (n, 3) float64; radius : float, model units

    Memory: 56 bytes per point (cell numbers, sorted copy and order) plus 8 per cell; at most
    ``4 * n + 2**20`` cells are allocated densely, beyond that only occupied cells are hashed:
    bounded by the number of points whatever the coordinates (a point at 1e30 gets a cell of
    its own; beyond 2**61 cells from the origin points share the outermost cell).
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0):
        return None
    finite = np.flatnonzero(np.isfinite(p).all(axis=1)).astype(np.int64)
    # a relative margin keeps |p - x| <= radius within one cell step despite rounding
    cell = radius * (1.0 + 1e-6)
    cells = kernels.lattice_cells(p, finite, cell)
    block = _dense_block(cells, len(finite))
    if block is not None:
        base, dims = block
        order, sorted_points, cell_start = kernels.dense_grid_build(p, finite, cells, base, dims)
        none = np.zeros(0, dtype=np.int64)
        return BallGrid(radius, base, cell, order, sorted_points, cell_start, dims, none, none)
    order, sorted_points, cell_start, keys, table = kernels.hashed_grid_build(p, finite, cells)
    zero = np.zeros(3, dtype=np.int64)
    return BallGrid(radius, zero, cell, order, sorted_points, cell_start, zero, keys, table)


def ball_neighbors(tree, finite_index, query_points, radius, ascending=True, positions=False):
    """All points within ``radius`` of each query point (the query point itself included).

    Parameters
    ----------
    tree : BallGrid from :func:`ball_grid` (fast; ``finite_index`` is then unused and the grid's
        own radius must equal ``radius``), or a scipy.spatial.cKDTree over the finite points
    finite_index : (k,) int64, the vertex index of each point in the tree
    query_points : (m, 3) float64 (rows with NaN get no neighbours)
    radius : float, model units
    ascending : bool, default True
        Sort each list. False leaves a grid's lists in grid order (about twice as fast;
        for consumers that do not depend on the order, like the curvature kernel).
    positions : bool, default False
        With a grid: return rows of ``tree.sorted_points`` (the points in grid order,
        ``tree.order`` their vertex indices) instead of vertex indices. Kernels that read the
        neighbours' coordinates from ``tree.sorted_points`` then find them close together in
        memory, which on a large cloud in random order is several times faster. Ignored (vertex
        indices) with a cKDTree.

    Returns
    -------
    indptr : (m + 1,) int64; indices : (nnz,) int64 vertex indices (grid rows with
    ``positions``), ascending per query point unless ``ascending`` is False (both searches
    return the same sets)
    """
    if isinstance(tree, BallGrid):
        if float(radius) != tree.radius:
            raise ValueError(f"the grid was built for radius {tree.radius}, not {radius}")
        q = np.ascontiguousarray(query_points, dtype=np.float64)
        return kernels.cell_ball_csr(tree.order, tree.sorted_points, tree.cell_start,
                                     tree.base, tree.cell, tree.dims, tree.table_keys,
                                     tree.table_cells, q, tree.radius, numba.get_num_threads(),
                                     bool(ascending), bool(positions))
    ok = np.isfinite(query_points).all(axis=1)
    lists = np.empty(len(query_points), dtype=object)
    lists[:] = [[] for _ in range(len(query_points))]
    if ok.any():
        lists[ok] = tree.query_ball_point(query_points[ok], radius, workers=-1, return_sorted=True)
    counts = np.fromiter((len(a) for a in lists), dtype=np.int64, count=len(lists))
    indptr = np.zeros(len(lists) + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    flat = np.fromiter((j for a in lists for j in a), dtype=np.int64, count=int(indptr[-1]))
    return indptr, finite_index[flat]


def ball_counts(tree, query_points, radius):
    """(m,) int64 number of points :func:`ball_neighbors` would list for each query point,
    without storing the lists (to size the work first). ``tree`` as there."""
    q = np.ascontiguousarray(query_points, dtype=np.float64)
    if isinstance(tree, BallGrid):
        return kernels.cell_ball_counts(tree.order, tree.sorted_points, tree.cell_start,
                                        tree.base, tree.cell, tree.dims, tree.table_keys,
                                        tree.table_cells, q, tree.radius)
    out = np.zeros(len(q), dtype=np.int64)
    ok = np.isfinite(q).all(axis=1)
    if ok.any():
        out[ok] = tree.query_ball_point(q[ok], radius, workers=-1, return_length=True)
    return out


def spatial_order(points, cell):
    """Order that visits the points grid cell by grid cell, so that neighbours are near in it.

    Lattice cells of edge ``cell`` (enlarged where a filled extent would need more than
    ``4 n + 2**20`` cells; hashed where even that does not fit, e.g. with far outliers),
    numbered x-major and z fastest; points with NaN coordinates come last. Processing queries
    in this order keeps the points their neighbourhoods touch in cache. Memory is bounded by
    the number of points whatever the coordinates.

    Parameters
    ----------
    points : (m, 3) float64; cell : float, model units

    Returns
    -------
    (m,) int64 permutation of ``range(m)``
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    finite = np.flatnonzero(np.isfinite(p).all(axis=1)).astype(np.int64)
    cell = float(cell)
    if len(finite) < 2 or not (np.isfinite(cell) and cell > 0):
        return np.arange(len(p), dtype=np.int64)
    cells = kernels.lattice_cells(p, finite, cell)
    block = _dense_block(cells, len(finite))
    if block is None:
        # coarser cells, as many as a dense grid may hold if the extent were filled
        dims = (cells.max(axis=0) - cells.min(axis=0) + 1).astype(np.float64)
        limit = _DENSE_CELLS_PER_POINT * len(finite) + 2.0 ** 20
        coarse = cell * (float(np.prod(dims)) / limit) ** (1.0 / 3.0) * 1.01
        if np.isfinite(coarse):
            coarse_cells = kernels.lattice_cells(p, finite, coarse)
            block = _dense_block(coarse_cells, len(finite))
            if block is not None:
                cells = coarse_cells
    if block is not None:
        order = kernels.dense_grid_build(p, finite, cells, *block)[0]
    else:
        # a sparse extent (far outliers): only the occupied cells, sorted by key
        order = kernels.hashed_grid_build(p, finite, cells)[0]
    if len(finite) == len(p):
        return order
    rest = np.setdiff1d(np.arange(len(p)), finite, assume_unique=True)
    return np.concatenate([order, rest])


# Lengths outside [2**-200, 2**200] are computed on coordinates scaled by a power of two
# (exact): their squares would overflow or lose precision in float64.
_SCALE_RANGE = (2.0 ** -200, 2.0 ** 200)


def power_of_two_scale(length):
    """1.0 if ``length`` (model units) squares safely in float64, else the power of two ``s``
    with ``length * s`` in [0.5, 1) (at most 2**1000): computing on ``points * s`` is then
    exact and safe."""
    length = float(length)
    if not (np.isfinite(length) and length > 0) or _SCALE_RANGE[0] <= length <= _SCALE_RANGE[1]:
        return 1.0
    # below 2**-1000 (subnormal lengths) the exact power would overflow: 2**1000 suffices
    return float(np.ldexp(1.0, min(-int(np.frexp(length)[1]), 1000)))


def typical_extent(points, sample=20000, seed=0):
    """Median distance (max norm) of the finite points from their coordinate-wise median, on
    up to ``sample`` of them: the size of the bulk of a cloud, unmoved by a few far points."""
    p = np.asarray(points, dtype=np.float64)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) > sample:
        p = p[np.random.default_rng(seed).choice(len(p), sample, replace=False)]
    if len(p) == 0:
        return float("nan")
    with np.errstate(over="ignore", invalid="ignore"):     # +-1e308: inf, NaN (ignored)
        return float(np.median(np.abs(p - np.median(p, axis=0)).max(axis=1)))


def default_radius(points, target_neighbors=100, sample=20000, seed=0):
    """Radius (model units) whose ball holds about ``target_neighbors`` points of the sampling.

    The local area density is estimated from the distance d16 to the 16th nearest neighbour,
    ``rho = 16 / (pi d16^2)``, on up to ``sample`` points; the radius is
    ``sqrt(target / (pi rho))`` with the median of d16^2. For a regular grid of spacing h this
    is about 5.6 h; for a mesh about 5 mean edge lengths. A few far-away points do not move it
    (a median); duplicated points count once where most points are duplicates; clouds of any
    scale (1e-300 ... 1e300) are measured on coordinates scaled by a power of two.

    Parameters
    ----------
    points : (n, 3) float, NaN rows ignored

    Returns
    -------
    float (NaN if there are fewer than 2 distinct finite points)
    """
    p = np.asarray(points, dtype=np.float64)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < 2:
        return float("nan")
    s = power_of_two_scale(typical_extent(p, sample, seed))
    if s != 1.0:
        with np.errstate(over="ignore"):
            scaled = p * s
        return default_radius(scaled, target_neighbors, sample, seed) / s
    radius = _default_radius(p, target_neighbors, sample, seed)
    if not np.isfinite(radius):
        # most points duplicated (coincident points are nobody's neighbour): distinct ones
        p = np.unique(p, axis=0)
        radius = _default_radius(p, target_neighbors, sample, seed) if len(p) > 1 else radius
    return radius


def _default_radius(p, target_neighbors, sample, seed):
    k = min(16, len(p) - 1)
    rng = np.random.default_rng(seed)
    probe = p if len(p) <= sample else p[rng.choice(len(p), sample, replace=False)]
    d, _ = cKDTree(p).query(probe, k=k + 1, workers=-1)
    with np.errstate(over="ignore"):
        dk2 = np.median(d[:, k] ** 2)
    if not (np.isfinite(dk2) and dk2 > 0):
        return float("nan")
    return float(np.sqrt(target_neighbors / k * dk2))
