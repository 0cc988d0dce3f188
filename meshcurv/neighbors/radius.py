"""Default radius from the sampling density, and the power-of-two scaling that keeps squared
lengths of any size representable in float64."""

import math

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

__all__ = ["default_radius", "local_radii", "power_of_two_scale", "scaled_for_squares",
           "typical_extent",
           "MAX_BALL_FRACTION", "PATCH_FLATNESS", "PATCH_STEP_GAIN", "PATCH_QUANTILE"]

# Largest share of the points a ball may hold and still be a local patch: on a sphere a ball
# holding a quarter of the points spans a 60 degree cap (curvature x radius = 1); the default
# radius of a cloud of 42 points reached across the whole object (a 42-vertex icosphere's
# ball held all 41 other vertices: k1 from 0 to 2.6 where 1 is right).
MAX_BALL_FRACTION = 0.25
# A mesh's default radius reaches at least this multiple of the median over vertices of their
# longest edge: the 1-ring is inside (a 12-vertex icosahedron: the 1-ring at 1.05, the next
# vertices at 1.70 on the unit sphere).
RING_MARGIN = 1.25

# The default radius is shrunk (by sqrt 2 at a time, not below a mesh's 1-ring reach or half
# a cloud's density radius) while its balls are not local patches: the smallest eigenvalue of
# their points' covariance over the middle one, at the quantile PATCH_QUANTILE over a sample
# of balls, above this. A spherical cap whose
# normals turn by 90 degrees at its rim (curvature x radius = sqrt 2) gives 1/6; a ball
# reaching across a coarse torus' tube gives 0.8 (:func:`_local_patch`).
PATCH_FLATNESS = 1.0 / 6.0
# ... and only while a step makes it at most this share of itself. A small cap's flatness falls
# like the squared radius (0.5 a step); a ball holding a whole section sits near 1 and falls
# more slowly at first (MeshLab's 5 % decimation of a 240 x 60 torus 2 / 0.5, 720 points:
# 0.78 -> 0.40, 0.52 a step, then 0.14; a step of 0.5 kept its radius 1.31, 2.6 tube radii,
# 52 % of the cloud's rows WRAPS_AROUND and the rest 1.2 off). Noise makes it rise (2 a
# step): with a share a of the flatness from the shape and the rest from noise a step gives
# 0.5 a + 2 (1 - a), at most 0.75 where the shape gives at least 5/6 of it.
PATCH_STEP_GAIN = 0.75
# Share of the balls that must be local patches: a quarter of them may be thicker (a shape's
# most curved parts). With half of them (the median), MeshLab's 20 % decimation of a 240 x 60
# torus 2 / 0.5 kept the radius 0.66 (1.3 tube radii; mean |dk| 0.029, 0.0070 at 0.46) and an
# ellipsoid 3 / 1 / 0.5 of 2562 vertices (curvature 12 at its tips) 0.54 (0.34, 0.13 at
# 0.38, clean mesh). Every other case of `scripts/compare_meshlab.py --accuracy-cases all`
# kept its radius; the 90 % quantile kept a larger one on the same ellipsoid's 642 vertices
# (no step shrank the thickest balls enough). A cube subdivided to edges of 0.1 shrinks from
# 0.35 to 0.25 (a quarter of the balls of 0.35 hold an edge) and reads as coarse (MLS blend):
# mean |k1| + |k2| of its rows 0.25-0.35 from the edges 0.46 -> 0.0009, farther 0 -> 1e-8
# (mesh), 0 -> 1.4e-4 (points).
PATCH_QUANTILE = 0.75
# Vertices whose balls :func:`_local_patch` measures.
_PATCH_SAMPLE = 2048

# Most growth steps of the default radius where its balls hold too few points
# (:func:`_grown_to_target`): each multiplies it by the square root of the missing share.
_GROW_STEPS = 8
# Points (of the random sample) whose balls are counted for that median: 0.03 s at 1M points.
_COUNT_SAMPLE = 4096

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


def scaled_for_squares(points, *others):
    """``(s, points * s, *(o * s for o in others))``, ``s`` the :func:`power_of_two_scale` of
    the points' :func:`typical_extent`: coordinates (exact multiples) in which the squares of
    the bulk's distances stay in float64; the arrays themselves where s = 1. A point far
    beyond the bulk may still overflow to inf there (callers treat it as missing)."""
    s = power_of_two_scale(typical_extent(points))
    if s == 1.0:
        return (s, points, *others)
    with np.errstate(over="ignore"):
        return (s, points * s, *(o * s for o in others))


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


def default_radius(points, target_neighbors=100, sample=20000, seed=0, faces=None,
                   details=False):
    """Radius (model units) whose ball holds about ``target_neighbors`` points of the sampling.

    The local area density is estimated from the distance d16 to the 16th nearest neighbor,
    ``rho = 16 / (pi d16^2)``, on up to ``sample`` points; the radius is
    ``sqrt(target / (pi rho))`` with the median of d16^2, grown where the median ball of that
    radius holds fewer than half the target (samplings far denser in one direction than the
    other, see :func:`_grown_to_target`). For a regular grid of spacing h this
    is about 5.6 h; for a mesh about 5 mean edge lengths. A few far-away points do not move it
    (a median); a position held by several points counts once; clouds of any
    scale (1e-300 ... 1e300) are measured on coordinates scaled by a power of two. Small inputs
    get balls of at most ``MAX_BALL_FRACTION`` of their points (fewer than 400 points: the
    target is a quarter of them, and the density comes from that many neighbors), and a mesh's
    radius reaches its 1-ring (``RING_MARGIN`` times the median longest edge of a vertex).
    Where the sampling is coarse for the shape (a low-poly torus) the radius is smaller, so
    that its balls stay on a local patch of the surface (:func:`_local_patch`; a mesh's by its
    k-rings, down to the 1-ring, a cloud's by its balls, down to half the radius).

    Parameters
    ----------
    points : (n, 3) float, NaN rows ignored
    faces : (m, 3) int, optional, the mesh's triangles (valid indices into ``points``)
    details : bool, also say whether the input is coarse for its shape

    Returns
    -------
    float (NaN if there are fewer than 2 distinct finite points); with ``details``,
    ``(radius, coarse)``: ``coarse`` is True where the radius was made smaller because its
    balls reached beyond a local patch (:func:`_local_patch`), i.e. where a ball holding
    ~100 points spans much of the shape
    """
    p = np.asarray(points, dtype=np.float64)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < 2:
        return (float("nan"), False) if details else float("nan")
    s = power_of_two_scale(typical_extent(p, sample, seed))
    if s != 1.0:
        with np.errstate(over="ignore"):
            scaled = np.asarray(points, dtype=np.float64) * s     # every row: faces index them
        radius, coarse = default_radius(scaled, target_neighbors, sample, seed, faces, True)
        return (radius / s, coarse) if details else radius / s
    mesh = faces is not None and len(faces) > 0
    radius, coarse = _default_radius(p, target_neighbors, sample, seed, patch=not mesh)
    if not np.isfinite(radius):
        # most points duplicated (coincident points are nobody's neighbor): distinct ones
        p = np.unique(p, axis=0)
        if len(p) > 1:
            radius, coarse = _default_radius(p, target_neighbors, sample, seed, patch=not mesh)
    if mesh and np.isfinite(radius):
        v = np.asarray(points, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        floor = RING_MARGIN * _ring_reach(v, f)
        start = max(radius, floor)
        radius = _local_patch(start, floor, _kring_flatness(v, f))
        coarse = radius < start
    return (radius, coarse) if details else radius


def _local_patch(radius, floor, flatness):
    """``radius``, or smaller where its balls reach beyond a local patch of the surface: a
    coarse torus (trimesh's 32 x 32 grid, tube radius 0.5) got a default radius of 1.05, whose
    balls reach around the tube, and curvatures 19 % off, all marked valid. While
    ``flatness(r)`` (the ``PATCH_QUANTILE`` quantile over a sample of points of their balls'
    flatness, see :func:`_patch_flatness`) exceeds :data:`PATCH_FLATNESS`, the radius is
    divided by sqrt 2, not below ``floor``, and only while that takes the flatness to at most
    :data:`PATCH_STEP_GAIN` of itself, or two steps take it to its square: a surface's shape
    makes it fall like the squared radius, where noise makes it rise (noisy data keep their
    radius)."""
    now = flatness(radius)
    while now > PATCH_FLATNESS and radius > floor:
        smaller = max(radius / math.sqrt(2.0), floor)
        then = flatness(smaller)
        if not then <= PATCH_STEP_GAIN * now:
            # a ball holding much of a coarse shape may first get thicker as it shrinks (from
            # a blob of the whole object to a section of its tube: trimesh's 32 x 12 torus
            # 1 / 0.3, flatness 0.70 at 0.96, 0.79 at 0.68, then 0.30 and 0.12); the shape
            # makes it fall over two steps all the same, noise makes it rise in both
            further = max(smaller / math.sqrt(2.0), floor)
            if further == smaller:
                break
            then = flatness(further)
            if not then <= PATCH_STEP_GAIN ** 2 * now:
                break
            smaller = further
        radius, now = smaller, then
    return radius


def _patch_sample(rows):
    """Up to ``_PATCH_SAMPLE`` of the indices ``rows``, evenly spread over them."""
    return rows[np.unique(np.linspace(0, len(rows) - 1,
                                      min(_PATCH_SAMPLE, len(rows))).astype(np.int64))]


def local_radii(points, radii, faces=None):
    """The leading radii of ``radii`` (ascending, model units) whose balls stay local: the
    first always, then each while its median ball, about a sample of the finite points (a
    mesh's k-rings over ``faces``), holds at most ``MAX_BALL_FRACTION`` of them and its balls
    are local patches of the surface - the two limits of :func:`default_radius`, checked at
    each radius with its own balls: not patches where their flatness (:func:`_patch_flatness`)
    exceeds ``PATCH_FLATNESS`` and grew like a shape's from the radius before (that one at most
    ``PATCH_STEP_GAIN`` of it; noise makes it fall as the balls grow). A list of floats.

    Measuring them directly keeps the work to the balls of the radii asked for (a few hundred
    points each, about 2048 points): the radius of a quarter of the points, measured like the
    default radius, took 57 s and 8.9 GB on a 100k-point cloud (47 s and 5.9 GB as a mesh).
    """
    radii = [float(r) for r in radii]
    if len(radii) < 2:
        return radii
    s, p = scaled_for_squares(np.asarray(points, dtype=np.float64))
    balls = _kring_balls(p, np.asarray(faces, dtype=np.int64)) \
        if faces is not None and len(faces) else _grid_balls(p)
    most = MAX_BALL_FRACTION * np.count_nonzero(np.isfinite(p).all(axis=1))
    kept = radii[:1]
    before, _ = balls(radii[0] * s)
    for r in radii[1:]:
        flatness, count = balls(r * s)
        if count > most or (flatness > PATCH_FLATNESS and before <= PATCH_STEP_GAIN * flatness):
            break
        kept.append(r)
        before = flatness
    return kept


def _kring_balls(points, faces):
    """``balls(r) -> (flatness, count)`` of a mesh: the flatness (:func:`_patch_flatness`)
    and the median number of points (the vertex included) of its k-ring balls of radius r
    (the neighborhoods its fits use) about a sample of its finite vertices in faces."""
    from .kring import KringWork, edge_adjacency, kring_neighbors

    used = np.zeros(len(points), dtype=bool)
    used[faces.ravel()] = True
    sample = _patch_sample(np.flatnonzero(used & np.isfinite(points).all(axis=1)))
    adjacency = edge_adjacency(faces, len(points))
    work = KringWork(len(points))          # one set of stamps for every radius tried

    def balls(r):
        if not len(sample):
            return np.nan, np.nan
        indptr, indices = kring_neighbors(points, adjacency, r, sample, work)
        counts = np.diff(indptr)
        owner = np.repeat(np.arange(len(sample)), counts)
        flatness = _patch_flatness(points, sample, np.concatenate([sample, indices]),
                                   np.concatenate([np.arange(len(sample)), owner]))
        return flatness, float(np.median(counts)) + 1.0
    return balls


def _kring_flatness(points, faces):
    """``flatness(r)`` of a mesh for :func:`_local_patch` (:func:`_kring_balls`)."""
    balls = _kring_balls(points, faces)
    return lambda r: balls(r)[0]


def _grid_balls(points):
    """``balls(r) -> (flatness, count)`` of a cloud, as :func:`_kring_balls`: its balls of
    radius r (a grid's, :func:`meshcurv.neighbors.ball_grid`, whatever the coordinates) about a
    sample of its finite points; balls of more than 4 times the median count (a crowded part,
    a scanner's near field) are counted but their flatness is not measured."""
    from .grid import ball_counts, ball_grid, ball_neighbors

    sample = _patch_sample(np.flatnonzero(np.isfinite(points).all(axis=1)))

    def balls(r):
        if not len(sample):
            return np.nan, np.nan
        grid = ball_grid(points, r)
        counts = ball_counts(grid, points[sample], r)
        typical = float(np.median(counts))
        light = sample[counts <= 4.0 * typical + 4.0]
        indptr, indices = ball_neighbors(grid, None, points[light], r)
        owner = np.repeat(np.arange(len(light)), np.diff(indptr))
        return _patch_flatness(points, light, indices, owner), typical
    return balls


def _ball_flatness(tree, points, most):
    """``flatness(r)`` of a cloud for :func:`_local_patch`: balls in ``tree`` (over
    ``points``) about a sample of the points, each its ``most`` nearest within r at most."""
    sample = _patch_sample(np.arange(len(points)))

    def flatness(r):
        d, nb = tree.query(points[sample], k=min(most, len(points)),
                           distance_upper_bound=r * (1.0 + 1e-12), workers=-1)
        inside = d <= r
        owner = np.nonzero(inside)[0]
        return _patch_flatness(points, sample, nb[inside], owner)
    return flatness


def _patch_flatness(points, centres, rows, owner):
    """The ``PATCH_QUANTILE`` quantile over the balls of ``points[rows]`` (ball ``owner`` of
    each row, about ``points[centres[owner]]``) of the smallest eigenvalue of their covariance
    over the middle one: 0 for a flat patch, (curvature x radius)^2 / 12 for a small spherical
    cap, near 1 for a ball holding a solid's whole section. Balls of fewer than 4 points are
    left out."""
    m = len(centres)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        q = points[rows] - points[centres][owner]    # about the centre: no cancellation
        count = np.bincount(owner, minlength=m).astype(np.float64)
        mean = np.stack([np.bincount(owner, q[:, a], m) for a in range(3)], axis=1)
        mean /= count[:, None]
        d = q - mean[owner]
        cov = np.stack([np.bincount(owner, d[:, a] * d[:, b], m)
                        for a in range(3) for b in range(3)], axis=1).reshape(-1, 3, 3)
    # balls of 4 points or more, whose sums did not overflow (a far point's)
    usable = (count >= 4) & np.isfinite(cov).all(axis=(1, 2))
    if not usable.any():
        return np.nan
    ev = np.linalg.eigvalsh(cov[usable])
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = ev[:, 0] / ev[:, 1]
    ratio = ratio[np.isfinite(ratio)]
    return float(np.quantile(ratio, PATCH_QUANTILE)) if len(ratio) else np.nan


def _ring_reach(points, faces):
    """Median over the vertices of ``faces`` of their longest edge (model units; edges of NaN
    vertices left out; coordinates whose squares overflow are scaled by the caller,
    :func:`default_radius`)."""
    longest, used = _longest_edges(np.asarray(points, dtype=np.float64),
                                   np.asarray(faces, dtype=np.int64))
    used = longest[used]
    return float(np.median(used)) if len(used) else 0.0


@njit(cache=True)
def _longest_edges(v, f):
    """``(longest, used)``, (n,) each: the length of each vertex's longest finite edge of the
    triangles ``f``, and whether it has one. One pass over the faces: a per-vertex maximum by
    ``np.maximum.at`` and the used vertices by ``np.unique`` took 1.4 s at 250k vertices."""
    longest = np.zeros(len(v))
    used = np.zeros(len(v), dtype=np.bool_)
    for t in range(f.shape[0]):
        for e in range(3):
            a = f[t, e]
            b = f[t, (e + 1) % 3]
            d0 = v[a, 0] - v[b, 0]
            d1 = v[a, 1] - v[b, 1]
            d2 = v[a, 2] - v[b, 2]
            length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if not np.isfinite(length):
                continue
            longest[a] = max(longest[a], length)
            longest[b] = max(longest[b], length)
            used[a] = True
            used[b] = True
    return longest, used


def _default_radius(p, target_neighbors, sample, seed, patch=True):
    """``(radius, shrunk)``: the density rule of :func:`default_radius` on the finite points
    ``p``, grown where too few points lie in its median ball and, with ``patch``, shrunk
    where its balls reach beyond a local patch (not below half of it: a quarter of the
    points), and whether it was."""
    target_neighbors = min(target_neighbors, MAX_BALL_FRACTION * len(p))
    k = max(1, min(16, len(p) - 1, int(target_neighbors)))
    rng = np.random.default_rng(seed)
    probe = p if len(p) <= sample else p[rng.choice(len(p), sample, replace=False)]
    tree = cKDTree(p)
    d, _ = tree.query(probe, k=k + 1, workers=-1)
    with np.errstate(over="ignore"):
        dk2 = np.median(d[:, k] ** 2)
    if not (np.isfinite(dk2) and dk2 > 0):
        return float("nan"), False
    # the target counts distinct positions (the fits skip a point's copies): a cloud merged
    # with a copy of itself keeps its radius, measured at as many distinct neighbors
    share = _points_per_position(d)
    if share > 1.0:
        target_neighbors *= share
        k = min(len(p) - 1, int(round(k * share)))
        d, _ = tree.query(probe, k=k + 1, workers=-1)
        with np.errstate(over="ignore"):
            dk2 = np.median(d[:, k] ** 2)
        if not np.isfinite(dk2):        # the more distinct neighbors reach a far point
            return float("nan"), False
    radius = float(np.sqrt(target_neighbors / k * dk2))
    # the area density extrapolated from k neighbors to the target, checked where it was
    if target_neighbors > k:
        radius = _grown_to_target(tree, probe, radius, target_neighbors)
    if not patch:
        return radius, False
    start = radius
    radius = _local_patch(radius, 0.5 * radius,
                          _ball_flatness(tree, p, 4 * int(math.ceil(target_neighbors))))
    return radius, radius < start


def _points_per_position(distances):
    """Points per distinct position, from the distances (m, j) of m sample points (a uniform
    sample of the points) to their j nearest points, themselves first: the inverse of the mean
    of 1 / (copies of each sample point among them). 1.0 exactly without duplicates; copies
    beyond the j nearest are not counted.

    >>> _points_per_position(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 1.0, 1.0]]))
    1.5
    """
    copies = np.count_nonzero(np.asarray(distances) == 0.0, axis=1)
    return float(1.0 / np.mean(1.0 / np.maximum(copies, 1)))


def _grown_to_target(tree, probe, radius, target_neighbors):
    """``radius``, or larger where its balls (about the ``probe`` points, in ``tree``) hold
    fewer than half of ``target_neighbors`` points in the median: the area density of the 16
    nearest neighbors does not hold at the radius where the sampling is not even in two
    directions (scan lines far denser along the line than across it: the 16 nearest all lie
    on the point's own line, and a ball of the radius they give reaches no other line). Grown
    by the square root of the missing share (an area's count) until the median ball holds the
    whole target (at most ``_GROW_STEPS`` steps).

    The balls are counted by nearest-neighbour queries bounded by the radius, up to the
    target (all the test needs): a ball query of a tree that holds a far point (1e200)
    overflows in scipy's worker threads, which leave their other counts at 0 and do not
    raise."""
    enough = 0.5 * target_neighbors
    probe = probe[:_COUNT_SAMPLE]
    most = min(tree.n, int(math.ceil(target_neighbors)) + 1)
    for _ in range(_GROW_STEPS):
        d, _ = tree.query(probe, k=most, distance_upper_bound=radius * (1.0 + 1e-12),
                          workers=-1)
        count = float(np.median(np.sum(d <= radius, axis=1))) - 1.0
        if count >= enough:
            break
        enough = target_neighbors
        radius *= math.sqrt(target_neighbors / max(count, 1.0))
    return radius
