"""Ball queries in point clouds over a uniform grid (dense, or hashed for sparse extents), and
a spatially coherent order of points. Compiled kernels (lattice, counting sort, hash table,
ball search, the CSR lists through :mod:`meshcurv.neighbors.csr`) and their wrappers.
"""

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from ..linalg import CHUNK
from .csr import gather_streams, overflowed, sample_step, stream_capacity, thread_ranges

__all__ = ["BallGrid", "ball_grid", "ball_neighbors", "ball_counts", "spatial_order",
           "lattice_cells", "cell_grid_build", "dense_grid_build", "hashed_grid_build",
           "cell_ball_counts", "cell_ball_csr"]

class BallGrid(NamedTuple):
    """Uniform grid over the finite points of a cloud for ball queries of one radius.

    Built by :func:`ball_grid`. Cells are those of the lattice ``floor(coordinate / cell)``
    (:func:`meshcurv.lattice_cells`). ``order`` lists point indices cell by cell
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


# Crowded parts of a cloud (:func:`crowd_thinning`): a grid cell holding more than CROWD_FACTOR
# times the typical count is thinned in cells CROWD_FINE times smaller.
CROWD_FACTOR = 8
CROWD_FINE = 4

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
    cells = lattice_cells(p, finite, cell)
    block = _dense_block(cells, len(finite))
    if block is not None:
        base, dims = block
        order, sorted_points, cell_start = dense_grid_build(p, finite, cells, base, dims)
        none = np.zeros(0, dtype=np.int64)
        return BallGrid(radius, base, cell, order, sorted_points, cell_start, dims, none, none)
    order, sorted_points, cell_start, keys, table = hashed_grid_build(p, finite, cells)
    zero = np.zeros(3, dtype=np.int64)
    return BallGrid(radius, zero, cell, order, sorted_points, cell_start, zero, keys, table)


def ball_neighbors(tree, finite_index, query_points, radius, ascending=True, positions=False,
                   serving=None):
    """All points within ``radius`` of each query point (the query point itself included).

    Parameters
    ----------
    tree : BallGrid from :func:`ball_grid` (fast; ``finite_index`` is then unused and the grid's
        own radius must equal ``radius``), or a scipy.spatial.cKDTree over the finite points
    finite_index : (k,) int64, the vertex index of each point in the tree
    query_points : (m, 3) float64 (rows with NaN get no neighbors)
    radius : float, model units
    ascending : bool, default True
        Sort each list. False leaves a grid's lists in grid order (about twice as fast;
        for consumers that do not depend on the order, like the curvature kernel).
    positions : bool, default False
        With a grid: return rows of ``tree.sorted_points`` (the points in grid order,
        ``tree.order`` their vertex indices) instead of vertex indices. Kernels that read the
        neighbors' coordinates from ``tree.sorted_points`` then find them close together in
        memory, which on a large cloud in random order is several times faster. Ignored (vertex
        indices) with a cKDTree.
    serving : (k,) bool per row of ``tree.sorted_points``, optional
        With a grid: list only the points it marks (:func:`crowd_thinning`). Ignored with a
        cKDTree.

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
        return cell_ball_csr(tree.order, tree.sorted_points, tree.cell_start,
                                     tree.base, tree.cell, tree.dims, tree.table_keys,
                                     tree.table_cells, q, tree.radius, numba.get_num_threads(),
                                     bool(ascending), bool(positions), _serving(serving))
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


def ball_counts(tree, query_points, radius, serving=None):
    """(m,) int64 number of points :func:`ball_neighbors` would list for each query point
    (with the same ``serving``), without storing the lists (to size the work first). ``tree``
    as there."""
    q = np.ascontiguousarray(query_points, dtype=np.float64)
    if isinstance(tree, BallGrid):
        return cell_ball_counts(tree.order, tree.sorted_points, tree.cell_start,
                                tree.base, tree.cell, tree.dims, tree.table_keys,
                                tree.table_cells, q, tree.radius, _serving(serving))
    out = np.zeros(len(q), dtype=np.int64)
    ok = np.isfinite(q).all(axis=1)
    if ok.any():
        out[ok] = tree.query_ball_point(q[ok], radius, workers=-1, return_length=True)
    return out


def _serving(serving):
    """``serving`` as the kernels take it: a contiguous bool array, empty for "every point"."""
    return np.zeros(0, dtype=np.bool_) if serving is None else np.ascontiguousarray(
        serving, dtype=np.bool_)


def crowd_thinning(grid, fine=CROWD_FINE, factor=CROWD_FACTOR):
    """Which points of ``grid`` (bool per row of its ``sorted_points``) serve as anyone's
    neighbor where part of the cloud is crowded; None where none is.

    A grid cell is crowded when it holds more than ``factor`` times the median over the points
    of their own cell's count. Its points are then counted again in cells ``fine`` times
    smaller, and each such cell keeps ``limit = factor * median / fine^2`` points (its share of
    a typical cell, ``factor`` times over), evenly spread over its points in grid order; cells
    holding fewer keep all. So the thin surface around a dense clump keeps every point, and a
    ball over the clump lists at most ``limit`` of its points per small cell: without this, a
    clump cost the square of its size (each of its points' balls holds all of it). Every point
    is still estimated, from the points that serve.
    """
    counts = np.diff(grid.cell_start)
    typical = float(np.median(np.repeat(counts, counts))) if len(grid.order) else 0.0
    crowded = np.repeat(counts > factor * max(typical, 1.0), counts)
    if not crowded.any():
        return None
    rows = np.flatnonzero(crowded)
    # coordinates beyond 2^63 small cells (a cloud near float64's limits) cast to one key: such
    # a crowd is thinned as one small cell (fewer of its points serve; each is still estimated)
    with np.errstate(invalid="ignore", over="ignore"):
        keys = np.floor(grid.sorted_points[rows] * (fine / grid.cell)).astype(np.int64)
    _, cell, size = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    cell = cell.ravel()
    # each point's rank within its small cell, in grid order
    by_cell = np.argsort(cell, kind="stable")
    rank = np.empty(len(rows), dtype=np.int64)
    rank[by_cell] = np.arange(len(rows)) - np.repeat(np.cumsum(size) - size, size)
    limit = max(1, int(factor * typical / fine ** 2))
    n = size[cell]
    keep = (n <= limit) | ((rank * limit) // n != ((rank - 1) * limit) // n)
    serving = np.ones(len(grid.order), dtype=bool)
    serving[rows] = keep
    return serving


def spatial_order(points, cell):
    """Order that visits the points grid cell by grid cell, so that neighbors are near in it.

    Lattice cells of edge ``cell`` (enlarged where a filled extent would need more than
    ``4 n + 2**20`` cells; hashed where even that does not fit, e.g. with far outliers),
    numbered x-major and z fastest; points with NaN coordinates come last. Processing queries
    in this order keeps the points their neighborhoods touch in cache. Memory is bounded by
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
    cells = lattice_cells(p, finite, cell)
    block = _dense_block(cells, len(finite))
    if block is None:
        # coarser cells, as many as a dense grid may hold if the extent were filled
        dims = (cells.max(axis=0) - cells.min(axis=0) + 1).astype(np.float64)
        limit = _DENSE_CELLS_PER_POINT * len(finite) + 2.0 ** 20
        coarse = cell * (float(np.prod(dims)) / limit) ** (1.0 / 3.0) * 1.01
        if np.isfinite(coarse):
            coarse_cells = lattice_cells(p, finite, coarse)
            block = _dense_block(coarse_cells, len(finite))
            if block is not None:
                cells = coarse_cells
    if block is not None:
        order = dense_grid_build(p, finite, cells, *block)[0]
    else:
        # a sparse extent (far outliers): only the occupied cells, sorted by key
        order = hashed_grid_build(p, finite, cells)[0]
    if len(finite) == len(p):
        return order
    rest = np.setdiff1d(np.arange(len(p)), finite, assume_unique=True)
    return np.concatenate([order, rest])


@njit(cache=True)
def _cell_coord(value, origin, inv, size):
    c = math.floor((value - origin) * inv)
    return np.int64(min(max(c, -1.0), float(size)))


@njit(cache=True)
def cell_grid_build(points, finite_index, origin, cell, dims):
    """Counting sort of ``points[finite_index]`` into a dense grid of ``dims`` cells of edge ``cell``.

    Returns ``(order, sorted_points, cell_start)``: ``order`` (k,) int64 lists point indices cell
    by cell (ascending within a cell), ``sorted_points`` (k, 3) their coordinates in that order,
    and cell ``(cx * ny + cy) * nz + cz`` holds positions ``cell_start[c]:cell_start[c + 1]``.
    Every point must lie inside the grid (``origin`` at least one cell below the minimum).
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    k = finite_index.shape[0]
    inv = 1.0 / cell
    keys = np.empty(k, dtype=np.int64)
    cell_start = np.zeros(nx * ny * nz + 1, dtype=np.int64)
    for j in range(k):
        i = finite_index[j]
        cx = _cell_coord(points[i, 0], origin[0], inv, nx)
        cy = _cell_coord(points[i, 1], origin[1], inv, ny)
        cz = _cell_coord(points[i, 2], origin[2], inv, nz)
        key = (cx * ny + cy) * nz + cz
        keys[j] = key
        cell_start[key + 1] += 1
    return _scatter_by_key(points, finite_index, keys, cell_start)


@njit(cache=True)
def _scatter_by_key(points, finite_index, keys, cell_start):
    """Counting sort's second half: ``cell_start`` holds the counts of each key shifted by one."""
    k = finite_index.shape[0]
    for c in range(cell_start.shape[0] - 1):
        cell_start[c + 1] += cell_start[c]
    fill = cell_start[:-1].copy()
    order = np.empty(k, dtype=np.int64)
    sorted_points = np.empty((k, 3))
    for j in range(k):
        pos = fill[keys[j]]
        fill[keys[j]] += 1
        i = finite_index[j]
        order[pos] = i
        sorted_points[pos, 0] = points[i, 0]
        sorted_points[pos, 1] = points[i, 1]
        sorted_points[pos, 2] = points[i, 2]
    return order, sorted_points, cell_start


LATTICE_LIMIT = float(2 ** 61)


@njit(cache=True)
def _lattice_index(value, inv):
    """Lattice cell number floor(value * inv), clamped to +-2**61 (NaN to the lower end)."""
    c = value * inv
    if not c > -LATTICE_LIMIT:
        return np.int64(-LATTICE_LIMIT)
    if c > LATTICE_LIMIT:
        return np.int64(LATTICE_LIMIT)
    return np.int64(math.floor(c))


@njit(parallel=True, cache=True)
def lattice_cells(points, finite_index, cell):
    """(k, 3) int64 lattice cell numbers of ``points[finite_index]`` for cells of edge ``cell``."""
    k = finite_index.shape[0]
    inv = 1.0 / cell
    out = np.empty((k, 3), dtype=np.int64)
    for j in prange(k):
        for a in range(3):
            out[j, a] = _lattice_index(points[finite_index[j], a], inv)
    return out


@njit(cache=True)
def dense_grid_build(points, finite_index, cells, base, dims):
    """Counting sort of ``points[finite_index]`` by their lattice ``cells`` (from
    :func:`lattice_cells`) into the dense block of ``dims`` cells starting at cell ``base``.

    Returns ``(order, sorted_points, cell_start)`` as :func:`cell_grid_build`; cell
    ``((cx - bx) * ny + cy - by) * nz + cz - bz`` holds positions ``cell_start[c]:cell_start[c + 1]``.
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    k = finite_index.shape[0]
    keys = np.empty(k, dtype=np.int64)
    cell_start = np.zeros(nx * ny * nz + 1, dtype=np.int64)
    for j in range(k):
        # clamped only as a guard: the caller's block holds every cell
        cx = min(max(cells[j, 0] - base[0], 0), nx - 1)
        cy = min(max(cells[j, 1] - base[1], 0), ny - 1)
        cz = min(max(cells[j, 2] - base[2], 0), nz - 1)
        key = (cx * ny + cy) * nz + cz
        keys[j] = key
        cell_start[key + 1] += 1
    return _scatter_by_key(points, finite_index, keys, cell_start)


# Grid keys pack three cell coordinates modulo 2**21; a hash table maps keys to cells. Cells a
# multiple of 2**21 apart share a key: they merge into one bucket, which costs a few distance
# tests where it happens (a far outlier) but loses nothing.
_GRID_BITS = 21


_GRID_MASK = (1 << _GRID_BITS) - 1


@njit(cache=True)
def _grid_key(cx, cy, cz):
    return (((cx & _GRID_MASK) << (2 * _GRID_BITS)) | ((cy & _GRID_MASK) << _GRID_BITS)
            | (cz & _GRID_MASK))


@njit(cache=True)
def _hash_slot(key, mask):
    h = (key * 0x9E3779B97F4A7C15) & 0x7FFFFFFFFFFFFFFF
    return (h >> 17) & mask


@njit(cache=True)
def hashed_grid_build(points, finite_index, cells):
    """Uniform grid over ``points[finite_index]`` by their lattice ``cells`` (from
    :func:`lattice_cells`), only the occupied cells stored: memory in the number of points
    whatever the extent.

    The sparse counterpart of :func:`dense_grid_build`, for extents where a dense grid would
    hold too many empty cells. Returns ``(order, sorted_points, cell_start, table_keys,
    table_cells)``: ``order`` lists the point indices cell by cell (ascending within a cell),
    ``sorted_points`` their coordinates in that order, occupied cell ``c`` holds positions
    ``cell_start[c]:cell_start[c + 1]``, and the open-addressing hash table
    ``table_keys``/``table_cells`` (-1 = empty) maps packed cell keys to cells.
    """
    k = finite_index.shape[0]
    keys = np.empty(k, dtype=np.int64)
    for j in range(k):
        keys[j] = _grid_key(cells[j, 0], cells[j, 1], cells[j, 2])
    srt = np.argsort(keys, kind="mergesort")  # stable: ascending point index within a cell
    order = finite_index[srt]
    sorted_points = np.empty((k, 3))
    for j in range(k):
        sorted_points[j, 0] = points[order[j], 0]
        sorted_points[j, 1] = points[order[j], 1]
        sorted_points[j, 2] = points[order[j], 2]
    ncell = 0
    for j in range(k):
        if j == 0 or keys[srt[j]] != keys[srt[j - 1]]:
            ncell += 1
    cell_start = np.empty(ncell + 1, dtype=np.int64)
    size = 16
    while size < 2 * ncell:
        size *= 2
    mask = size - 1
    table_keys = np.full(size, -1, dtype=np.int64)
    table_cells = np.full(size, -1, dtype=np.int64)
    c = -1
    for j in range(k):
        key = keys[srt[j]]
        if j == 0 or key != keys[srt[j - 1]]:
            c += 1
            cell_start[c] = j
            slot = _hash_slot(key, mask)
            while table_keys[slot] != -1:
                slot = (slot + 1) & mask
            table_keys[slot] = key
            table_cells[slot] = c
    cell_start[ncell] = k
    return order, sorted_points, cell_start, table_keys, table_cells


# Most cell numbers one axis of a ball query visits (see _axis_window).
WINDOW = 64


@njit(cache=True)
def _axis_window(x, cell, inv, out):
    """Lattice cell numbers, ascending, of every float within ``cell`` of ``x`` along one axis;
    their count.

    The numbers of ``x - cell`` and ``x + cell`` bound them (rounding is monotone, so no float
    between the two gets a number outside), and are adjacent to ``x``'s own but where
    ``|x| / cell`` exceeds ~2**50 and rounding makes the numbers jump: there the few floats in
    the window are enumerated, so that a query never visits more than a few cells.
    """
    lo = _lattice_index(x - cell, inv)
    hi = _lattice_index(x + cell, inv)
    if hi - lo <= 3:
        for a in range(hi - lo + 1):
            out[a] = lo + a
        return hi - lo + 1
    count = 0
    p = x - cell
    end = x + cell
    for _ in range(out.shape[0]):
        if not p <= end:
            break
        c = _lattice_index(p, inv)
        if count == 0 or c != out[count - 1]:
            out[count] = c
            count += 1
        p = np.nextafter(p, np.inf)
    return count


@njit(cache=True)
def _scan_run(order, sorted_points, j0, j1, x0, x1, x2, r2max, out, base, found, limit,
              positions, serving):
    """Append the grid positions ``j0:j1`` within ``sqrt(r2max)`` of (x0, x1, x2) to
    ``out[base + found:]`` (as far as ``limit`` allows); returns the new count. With a
    non-empty ``serving`` (bool per grid position) only the positions it marks."""
    thinned = serving.shape[0] > 0
    for j in range(j0, j1):
        if thinned and not serving[j]:
            continue
        d0 = sorted_points[j, 0] - x0
        d1 = sorted_points[j, 1] - x1
        d2 = sorted_points[j, 2] - x2
        if d0 * d0 + d1 * d1 + d2 * d2 <= r2max:
            if base + found < limit:
                out[base + found] = j if positions else order[j]
            found += 1
    return found


@njit(cache=True)
def _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims, table_keys,
                   table_cells, x0, x1, x2, r2max, out, base, limit, ascending, positions, win,
                   serving):
    """Indices of the grid points within ``sqrt(r2max)`` of (x0, x1, x2).

    The cells of the query's window along each axis (:func:`_axis_window`; usually the 3 x 3 x 3
    cells around the query's own), x-major and z fastest. Dense grid (``table_keys`` empty):
    those within the block, contiguous z runs scanned at once. Hashed grid: each cell looked up
    by its key. Both list the same points in the same order. Writes to ``out[base:]`` as far as
    ``limit`` allows and returns the count. With ``ascending`` (and if all fit) they are sorted,
    else in grid order. With ``positions`` they are rows of ``sorted_points`` instead of point
    indices. ``win`` is (3, WINDOW) int64 scratch; ``serving`` as in :func:`_scan_run`.
    """
    if not np.isfinite(x0 + x1 + x2):
        return 0
    inv = 1.0 / cell
    n0 = _axis_window(x0, cell, inv, win[0])
    n1 = _axis_window(x1, cell, inv, win[1])
    n2 = _axis_window(x2, cell, inv, win[2])
    found = 0
    if table_keys.shape[0] > 0:
        mask = table_keys.shape[0] - 1
        for a in range(n0):
            for b in range(n1):
                for c in range(n2):
                    key = _grid_key(win[0, a], win[1, b], win[2, c])
                    slot = _hash_slot(key, mask)
                    while table_keys[slot] != -1 and table_keys[slot] != key:
                        slot = (slot + 1) & mask
                    if table_keys[slot] == key:
                        cc = table_cells[slot]
                        found = _scan_run(order, sorted_points, cell_start[cc],
                                          cell_start[cc + 1], x0, x1, x2, r2max, out, base,
                                          found, limit, positions, serving)
    else:
        nx, ny, nz = dims[0], dims[1], dims[2]
        contiguous = win[2, n2 - 1] - win[2, 0] == n2 - 1
        z0 = max(win[2, 0] - grid_base[2], 0)
        z1 = min(win[2, n2 - 1] - grid_base[2], nz - 1)
        for a in range(n0):
            ax = win[0, a] - grid_base[0]
            if ax < 0 or ax >= nx:
                continue
            for b in range(n1):
                ay = win[1, b] - grid_base[1]
                if ay < 0 or ay >= ny:
                    continue
                col = (ax * ny + ay) * nz
                if contiguous:
                    if z0 <= z1:
                        found = _scan_run(order, sorted_points, cell_start[col + z0],
                                          cell_start[col + z1 + 1], x0, x1, x2, r2max, out,
                                          base, found, limit, positions, serving)
                    continue
                for c in range(n2):
                    az = win[2, c] - grid_base[2]
                    if az >= 0 and az < nz:
                        found = _scan_run(order, sorted_points, cell_start[col + az],
                                          cell_start[col + az + 1], x0, x1, x2, r2max, out,
                                          base, found, limit, positions, serving)
    if ascending and base + found <= limit:
        _shell_sort(out, base, base + found)
    return found


@njit(cache=True)
def _shell_sort(a, lo, hi):
    """Sort ``a[lo:hi]`` in place; for the ~100 entries of a neighbor list about twice as fast
    as ``ndarray.sort`` (which sets up a quicksort stack per call)."""
    for gap in (57, 23, 10, 4, 1):
        for j in range(lo + gap, hi):
            key = a[j]
            k = j - gap
            while k >= lo and a[k] > key:
                a[k + gap] = a[k]
                k -= gap
            a[k + gap] = key


@njit(parallel=True, cache=True)
def cell_ball_counts(order, sorted_points, cell_start, grid_base, cell, dims, table_keys,
                     table_cells, query_points, radius, serving):
    """(m,) int64 number of grid points within ``radius`` of each query point (nothing
    stored: what :func:`cell_ball_csr` would list, to size the work before doing it)."""
    m = query_points.shape[0]
    r2max = radius * radius
    counts = np.zeros(m, dtype=np.int64)
    dummy = np.empty(0, dtype=np.int64)
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        win = np.empty((3, WINDOW), dtype=np.int64)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            counts[q] = _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims,
                                       table_keys, table_cells, query_points[q, 0],
                                       query_points[q, 1], query_points[q, 2], r2max, dummy, 0,
                                       0, False, False, win, serving)
    return counts


@njit(parallel=True, cache=True)
def cell_ball_csr(order, sorted_points, cell_start, grid_base, cell, dims, table_keys,
                  table_cells, query_points, radius, nthreads, ascending, positions, serving):
    """All grid points within ``radius`` of each query point, CSR.

    Each list is ascending with ``ascending``, else in grid order (cheaper; for consumers that
    do not depend on the order). With ``positions`` the lists hold rows of ``sorted_points``
    (whose neighborhoods then lie close together in memory) instead of point indices. With a
    non-empty ``serving`` (bool per row of ``sorted_points``) only the points it marks.

    The grid comes from :func:`dense_grid_build` (``table_keys`` empty; ``grid_base`` and
    ``dims`` its block of cells) or :func:`hashed_grid_build` (``grid_base``, ``dims`` unused),
    with ``cell >= radius``. Each thread streams its contiguous range of queries into its own
    slice of a scratch buffer sized from a sample of the queries; a thread whose slice
    overflows searches its range again into the output.
    """
    m = query_points.shape[0]
    r2max = radius * radius
    counts = np.zeros(m + 1, dtype=np.int64)
    nthreads, per = thread_ranges(m, nthreads)
    dummy = np.empty(0, dtype=np.int64)
    win0 = np.empty((3, WINDOW), dtype=np.int64)
    tot = 0
    cnt = 0
    for qi in range(0, m, sample_step(m)):
        tot += _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims,
                              table_keys, table_cells,
                              query_points[qi, 0], query_points[qi, 1], query_points[qi, 2],
                              r2max, dummy, 0, 0, False, False, win0, serving)
        cnt += 1
    cap = stream_capacity(tot, cnt)
    buf = np.empty(nthreads * per * cap, dtype=np.int64)
    used = np.zeros(nthreads, dtype=np.int64)
    for t in prange(nthreads):
        win = np.empty((3, WINDOW), dtype=np.int64)
        lo = t * per * cap
        pos = lo
        for qi in range(t * per, min(m, (t + 1) * per)):
            f = _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims,
                               table_keys, table_cells,
                               query_points[qi, 0], query_points[qi, 1], query_points[qi, 2],
                               r2max, buf, pos, lo + per * cap, ascending, positions, win,
                               serving)
            counts[qi + 1] = f
            pos += f
        used[t] = pos - lo
    indices = gather_streams(counts, buf, used, nthreads, per, cap)
    for t in prange(nthreads):
        if overflowed(used, t, per, cap):
            win = np.empty((3, WINDOW), dtype=np.int64)
            for qi in range(t * per, min(m, (t + 1) * per)):
                _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims,
                               table_keys, table_cells,
                               query_points[qi, 0], query_points[qi, 1], query_points[qi, 2],
                               r2max, indices, counts[qi], counts[qi + 1],
                               ascending, positions, win, serving)
    return counts, indices
