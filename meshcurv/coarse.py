"""Inputs coarse for their shape: the curvature of the MLS surface of oriented spheres
(:mod:`meshcurv.fit.mls`) where the circle fits have too few points per normal section.

A mesh or cloud is coarse for its shape where a ball holding ~100 points would reach around
it, so
that the default radius had to be made smaller to stay on a local patch
(:func:`meshcurv.neighbors.default_radius` with ``details``: a low-poly torus of 16 vertices
around the tube). Each of the 2 x 8 half-sets of a circle fit then holds a few vertices at
the discrete positions of the mesh's grid, and the circle fits' error is that of the sampling,
not of the noise: trimesh's tori 1 / 0.3 (64 x 16), 3 / 1 (40 x 20), 2 / 0.5 and 1 / 0.2
(32 x 32) have mean |dk| 0.041, 0.022, 0.028 and 0.069 with the circle fits, at any radius
and with exact normals alike. The MLS surface through the same vertices and the circle fits'
normals (support :func:`support`) gives 0.0068, 0.0027, 0.0057 and 0.019 there on its own.

It is more sensitive to position noise, so the two are blended row by row by the noise the
local jet measured: ``g = 1 / (1 + (noise / (NOISE_SCALE radius))^4)`` of the MLS estimate
(:func:`meshcurv.pipeline.clean_fraction`).
Shape alone gives noise / radius 0.002-0.006 on those clean tori; Gaussian noise along the
normal of 0.1 % of the diagonal 0.012-0.017, of 0.3 % 0.034-0.044. Mean |dk|, the four tori
in the order above (measured once with a script; :data:`PASSES` MLS passes):

==========  ===================================  ===================================
noise       circle fits alone                    blended (NOISE_SCALE 0.015)
==========  ===================================  ===================================
0           0.041, 0.022, 0.028, 0.069           0.0058, 0.0019, 0.0044, 0.018
0.05 %      0.086, 0.019, 0.029, 0.073           0.026, 0.011, 0.015, 0.031
0.1 %       0.077, 0.019, 0.031, 0.079           0.044, 0.017, 0.025, 0.056
0.2 %       0.073, 0.023, 0.043, 0.091           0.066, 0.022, 0.036, 0.085
0.3 %       0.063, 0.026, 0.046, 0.105           0.066, 0.027, 0.046, 0.104
0.5 %       0.085, 0.034, 0.067, 0.142           0.086, 0.034, 0.066, 0.142
==========  ===================================  ===================================

With NOISE_SCALE 0.02 (one pass) the clean and 0.05 % rows gained a little more (0.0068
against 0.0074 on the first torus) and the 0.3 % row lost more (0.072 on the first torus,
14 % worse than the circle fits alone); 0.015 keeps every loss within 5 %.

The same tori as clouds of their vertices (the circle fits with the cloud's own normals):
0.054, 0.019, 0.028, 0.068 alone, 0.013, 0.0025, 0.0041, 0.018 blended; with 0.1 % noise
0.076, 0.019, 0.031, 0.081 -> 0.041, 0.013, 0.025, 0.060, with 0.3 % 0.0630, 0.026, 0.047,
0.105 -> 0.0634, 0.026, 0.046, 0.104.

Used where the radius is the default (``Options.coarse_fit``).
"""

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from .fit.mls import STEP, mls_curvature
from .fit.outliers import outlier_weight
from .neighbors import power_of_two_scale
from .neighbors.radius import _longest_edges
from .pipeline import BLOCK, ball_search, clean_fraction, kring_search
from .weld import expand_rows

__all__ = ["estimate", "support", "mls_rows", "SUPPORT_EDGES", "CLOUD_RING", "SUPPORT_CAP",
           "NOISE_SCALE", "PASSES"]

# The MLS support h of a vertex reaches this many times its longest edge: its whole 1-ring
# then weighs at least (1 - 1/4)^4 = 0.32 in the weights (1 - d^2 / h^2)^4, which fall to 0.01
# at 0.84 h; with h = radius a grid twice as fine one way as the other (the 32 x 32 torus
# 2 / 0.5: 0.10 around the tube, 0.49 along it) left the far neighbours out and the fit
# degenerate in that direction (mean |dk| 0.30).
SUPPORT_EDGES = 2.0

# A cloud point's reach: the distance to its 12th nearest point, about two rings of an even
# sampling (6 points each); on a sampling twice as fine one way as the other (the 32 x 32
# torus's points) the 6 nearest all lie along the fine direction and a support from them
# left the fit degenerate the other way (mean |dk| 0.11 and 0.67 on the two 32 x 32 tori,
# 0.0041 and 0.018 from the 12th).
CLOUD_RING = 12

# ... and at most this many radii (the normal field's reach, see pipeline.FIELD_RATIO): a few
# long slivers do not widen every list.
SUPPORT_CAP = 2.0

# Noise (the local jet's RMS residual at the radius) over the radius at which the MLS estimate
# and the circle fits share a row equally (see the module's docstring).
NOISE_SCALE = 0.015


# MLS passes: each one after the first fits the normals of the one before (the MLS surface's
# own, where the blend gives it the larger share). The circle fits' normals are 0.2-0.7 degrees
# off on the coarse tori of the module's docstring, the first pass's 0.06-0.15 degrees; mean
# |dk| of the MLS surface alone, one pass -> two: 0.0068, 0.0027, 0.0057, 0.019 -> 0.0054,
# 0.0019, 0.0045, 0.020 (a third pass: 0.0050, 0.0017, 0.0042, 0.021).
PASSES = 2


def estimate(v, f, radius, query, circle_fits, use_kring=True):
    """The curvature of a mesh or cloud coarse for its shape: the circle fits' result blended
    with :data:`PASSES` MLS passes (:func:`mls_rows`), rows ``query`` (all: None) in its
    order.

    ``circle_fits(rows)`` returns the circle fits' :class:`meshcurv.CurvatureResult` at the
    vertex indices ``rows`` (None: all) at ``radius``; with ``query`` they also run where
    the queries' supports reach, and those rows' MLS passes where the next pass's supports
    do, so that every row is the whole input's. Supports are searched over the mesh's k-rings
    (``use_kring``) or in balls (clouds: ``f`` None). The MLS fits run on coordinates scaled
    by the power of two that keeps the radius's square finite (the same curvatures at any
    scale).
    """
    unit = power_of_two_scale(radius)
    with np.errstate(over="ignore"):
        vs = v * unit if unit != 1.0 else v
    h = support(vs, f, radius * unit)
    reach = float(h.max()) * (1.0 + 2.0 * STEP)
    search = _lists(kring_search(vs, f, reach) if use_kring else
                    ball_search(vs, np.flatnonzero(np.isfinite(vs).all(axis=1)), reach))
    n = len(v)
    # rows of the circle fits, then of each pass; the last pass's are the queries
    wanted = [np.arange(n) if query is None else np.asarray(query)]
    for _ in range(PASSES):
        wanted.insert(0, wanted[0] if query is None else
                      np.union1d(wanted[0], search(wanted[0])[1]))
    base = circle_fits(None if query is None else wanted[0])
    normals = np.full((n, 3), np.nan)
    normals[wanted[0]] = base.normals
    weights = np.ones(n)
    weights[wanted[0]] = outlier_weight(base.outlier_score)
    for rows in wanted[1:]:
        part = base if query is None else expand_rows(base, np.searchsorted(wanted[0], rows))
        fields = mls_rows(part, rows, vs, normals, weights, h[rows], search, unit)
        normals[rows] = fields["normals"]
    return replace(part, **fields)


def _lists(search):
    """``lists(idx) -> (indptr, indices)`` of a :class:`meshcurv.pipeline.Search`, the indices
    rows of the input (a ball search's lists index its grid's copy)."""
    def lists(idx):
        indptr, indices = search.neighbors(idx)
        return indptr, indices if search.rank is None else search.rank[indices]
    return lists


def support(v, f, radius):
    """The MLS support h (n,) of each point, model units: ``SUPPORT_EDGES`` times its reach,
    at least ``radius`` and at most ``SUPPORT_CAP * radius``. The reach is a mesh vertex's
    longest edge (faces ``f``), or a cloud point's distance to its ``CLOUD_RING``-th nearest
    point (``f`` None); ``radius`` where there is none."""
    v = np.asarray(v, dtype=np.float64)
    if f is not None:
        reach, used = _longest_edges(v, np.asarray(f, np.int64))
    else:
        finite = np.flatnonzero(np.isfinite(v).all(axis=1))
        reach, used = np.zeros(len(v)), np.zeros(len(v), dtype=bool)
        k = min(CLOUD_RING, len(finite) - 1)
        if k >= 1:
            d, _ = cKDTree(v[finite]).query(v[finite], k=k + 1, workers=-1)
            reach[finite] = d[:, k]
            used[finite] = np.isfinite(d[:, k])
    h = np.clip(SUPPORT_EDGES * np.where(used, reach, 0.0), radius, SUPPORT_CAP * radius)
    return np.where(used, h, radius)


def mls_rows(result, rows, v, normals, point_weights, h, search, unit=1.0, block=BLOCK):
    """The MLS estimate of the rows ``rows`` of ``result`` (vertex indices, (m,)), blended
    into a copy of its fields (k1, k2, d1, d2, normals) by the row's noise (module docstring).

    ``v`` (n, 3) and ``h`` are the vertices and supports in the result's units times ``unit``
    (a power of two that keeps squares finite; curvatures are scaled back by it).

    ``normals`` (n, 3): unit normals of every vertex the supports reach (NaN: left out);
    ``point_weights`` (n,) or None: the outlier weights; ``h`` (m,): each row's support;
    ``search(idx)``: CSR lists ``(indptr, indices)`` about the vertices ``idx`` holding every
    vertex within ``h (1 + 2 STEP)``. Rows ``result`` has no estimate for, and rows whose MLS
    fit fails, keep the circle fits'.
    """
    m = len(rows)
    k1, k2 = np.empty(m), np.empty(m)
    d1, d2, n = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    for lo in range(0, m, block):
        sl = slice(lo, min(m, lo + block))
        idx = rows[sl]
        indptr, indices = search(idx)
        mls_curvature(v, normals, v[idx], result.normals[sl], idx, indptr, indices, h[sl],
                      point_weights, (k1[sl], k2[sl], d1[sl], d2[sl], n[sl]))
    g = clean_fraction(result.noise, NOISE_SCALE * result.radius)
    with np.errstate(over="ignore"):
        k1, k2 = k1 * unit, k2 * unit
    use = np.asarray(result.valid) & np.isfinite(k1) & np.isfinite(k2)
    g = np.where(use, g, 0.0)
    out = {"k1": g * np.where(use, k1, 0.0) + (1.0 - g) * result.k1,
           "k2": g * np.where(use, k2, 0.0) + (1.0 - g) * result.k2}
    # directions and normal: the larger share's
    mls_side = (g >= 0.5)[:, None]
    out["d1"] = np.where(mls_side, d1, result.d1)
    out["d2"] = np.where(mls_side, d2, result.d2)
    out["normals"] = np.where(mls_side, n, result.normals)
    return out
