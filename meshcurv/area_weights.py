"""Point weights by the area each point stands for, for the MLS surface's fits
(:mod:`meshcurv.coarse`): they then sum over the surface rather than over the sampling.

A least-squares fit over a neighbourhood weighs each point alike; where the sampling is
denser on one side of a vertex (a mesh decimated by edge collapse keeps more vertices where
the surface bends more) the fit follows that side, and where curvature varies across the
support that is an error of the estimate. Weighting each vertex by its share of the surface
(a third of the area of its faces) turns every sum into a quadrature of the surface integral
it stands for. The MLS fit weighs every point of its support, the evaluation point included,
by its weight, so a common factor changes nothing: vertices of equal areas give what they
gave. A cloud point's area is the square of its one ring's reach, the distance to its
:data:`CLOUD_RING_POINTS`-th nearest distinct point.
"""

import math

import numpy as np
from numba import njit

from .neighbors import power_of_two_scale
from .normals.faces import edge_cross
from .normals.orient import nearest_areas

__all__ = ["vertex_area_weights", "cloud_area_weights", "CLOUD_RING_POINTS"]

# A cloud point's ring: the points of an even sampling around it (a mesh vertex's 1-ring).
# Its 12 nearest reach the next ring, and on a sampling twice as fine one way as the other
# (trimesh's 32 x 32 tori as clouds) their distance grows with the coarse spacing, which
# varies across those tori: the MLS blend there lost 1.6-1.7x (0.0041 -> 0.0067, 0.018 ->
# 0.031), where the 6th nearest left it as it was; MeshLab's decimations as clouds gained
# with either (ellipsoid at 10 %: 0.0103 -> 0.0036 with the 6th, 0.0034 with the 12th).
CLOUD_RING_POINTS = 6


def vertex_area_weights(vertices, faces, rows=None):
    """Each vertex's area weight (n,) in [0, 1]: a third of the area of its faces (each
    distinct triangle once, whatever its winding or repeats), over the largest such area.

    Parameters
    ----------
    vertices : (n, 3) float; faces : (m, 3) int, validated
    rows : (k,) int, optional: only these vertices' weights, over the largest among them
        (the others NaN): the same weights up to a common factor, which the MLS fits ignore,
        from their faces alone

    Returns
    -------
    (n,) float64: 0 at vertices whose faces are all degenerate (no area to stand for); at
    vertices in no face (or in non-finite faces only) the median of the others' (a point of
    the mesh's typical share); 1 everywhere where no face has an area. The same bits for the
    faces in any order, winding or repeat, and for the vertices scaled by a power of two that
    keeps them normal numbers (areas are taken on edges scaled by the power of two that keeps
    their squares finite; 2^-700 and 2^600 tested).
    """
    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    faces = np.asarray(faces, dtype=np.int64)
    if rows is not None:
        wanted = np.zeros(n, dtype=bool)
        wanted[rows] = True
        faces = faces[wanted[faces].any(axis=1)] if len(faces) else faces
    # each triangle once, its corners in ascending order: the same cross product however
    # the face was wound, rotated or repeated (repeats lie together in lexicographic order)
    f = np.sort(faces, axis=1)
    order = np.lexsort(f.T[::-1])
    if len(f) == 0:
        return _only(np.ones(n), rows)
    unit = power_of_two_scale(_edge_extent(v, f, order))
    area, referenced = _corner_areas(v, f, order, unit)
    if rows is not None:                 # the other vertices' faces are not all there
        area[~wanted] = 0.0
        referenced &= wanted
    largest = area.max(initial=0.0)
    if not largest > 0.0:
        return _only(np.ones(n), rows)
    weights = area / largest
    weights[~referenced] = np.median(weights[referenced])
    return _only(weights, rows)


@njit(cache=True)
def _repeats(f, order, t):
    """Whether face ``f[order[t]]`` (corners sorted) is the one before it in ``order``."""
    if t == 0:
        return False
    i, j = order[t], order[t - 1]
    return f[i, 0] == f[j, 0] and f[i, 1] == f[j, 1] and f[i, 2] == f[j, 2]


@njit(cache=True)
def _edge_extent(v, f, order):
    """The largest |coordinate| of the edges (corner 1 - corner 0, corner 2 - corner 0) of
    the distinct faces ``f[order]`` (corners sorted, repeats adjacent); NaN's passed over, 0
    for none."""
    big = 0.0
    for t in range(len(order)):
        if _repeats(f, order, t):
            continue
        i = order[t]
        for c in range(3):
            x = abs(v[f[i, 1], c] - v[f[i, 0], c])
            y = abs(v[f[i, 2], c] - v[f[i, 0], c])
            if x > big:
                big = x
            if y > big:
                big = y
    return big


@njit(cache=True)
def _corner_areas(v, f, order, unit):
    """``(area, referenced)``, (n,) each: twice the area of each distinct face ``f[order]``
    (its edges scaled by ``unit``) summed at its corners in that order, and whether a vertex
    is a corner of a face of finite area."""
    n = v.shape[0]
    area = np.zeros(n)
    referenced = np.zeros(n, dtype=np.bool_)
    for t in range(len(order)):
        if _repeats(f, order, t):
            continue
        i = order[t]
        c0, c1, c2 = edge_cross(v, f[i, 0], f[i, 1], f[i, 2], unit)
        twice = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        if np.isfinite(twice):
            for k in range(3):
                area[f[i, k]] += twice
                referenced[f[i, k]] = True
    return area, referenced


def _only(weights, rows):
    """``weights`` (n,) at ``rows`` (None: all), NaN elsewhere."""
    if rows is None:
        return weights
    out = np.full(len(weights), np.nan)
    out[rows] = weights[rows]
    return out


def cloud_area_weights(points, rows=None):
    """Each cloud point's area weight (n,) in [0, 1]: the squared distance to its
    :data:`CLOUD_RING_POINTS`-th nearest distinct point, over the largest such square
    (on coordinates scaled by the power of two that keeps the squares finite: the same bits
    at any power-of-two scale; the farthest where a point has fewer others). Non-finite
    points and points with no other get the median of the others' (1 where there are
    none). ``rows`` (k,) int, optional: only these points' weights, over the largest among
    them (the others NaN; a common factor, which the MLS fits ignore)."""
    p = np.asarray(points, dtype=np.float64)
    weights = np.full(len(p), np.nan)
    finite = np.flatnonzero(np.isfinite(p).all(axis=1))
    asked = finite
    if rows is not None:
        wanted = np.zeros(len(p), dtype=bool)
        wanted[rows] = True
        asked = finite[wanted[finite]]
    if len(finite) > 1 and len(asked):
        q = p[finite]
        with np.errstate(over="ignore", invalid="ignore"):
            # the extent about the median; the coordinates' own size where that overflows
            extent = np.max(np.abs(q - np.median(q, axis=0)))
            if not np.isfinite(extent):
                extent = np.max(np.abs(q))
        unit = power_of_two_scale(extent)
        # points far closer together than their coordinates' size (2^24 and 2^24 + 5e-324):
        # the largest power of two that keeps the coordinates finite
        size = float(np.max(np.abs(q)))
        if size > 0.0 and unit > 1.0 and size > math.ldexp(1.0, 1000) / unit:
            unit = math.ldexp(1.0, 1000 - math.frexp(size)[1])
        area = nearest_areas(q * unit, p[asked] * unit, np.inf, CLOUD_RING_POINTS, workers=-1)
        largest = area.max(initial=0.0)
        if largest > 0.0:
            weights[asked] = area / largest
    known = weights[np.isfinite(weights) & (weights > 0.0)]
    return _only(np.where(np.isfinite(weights) & (weights > 0.0), weights,
                          np.median(known) if len(known) else 1.0), rows)
