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

The jet's residual also holds what a quadric leaves of the shape within the ball: on
trimesh's 32 x 12 tori 1 / 0.3 and 3 / 1 (balls of ~10 vertices) 0.067 and 0.055 of the
radius (median), which kept the MLS surface out (mean |dk| 0.195 and 0.053, the circle
fits'). On meshes a row's own noise is the smaller of the jet's and the noise measured over
the mesh's rings (:mod:`meshcurv.ring_noise`, within a few percent of the noise added,
0.0016 of the radius there clean), and the rough points of a row's support
(:data:`ROUGH_NOISE`) count where the support reaches a crease (:data:`CREASE`). Mean
|dk|, the jet's noise -> the smaller, and the change on the four tori above (in that order)
and on MeshLab's 5 % decimation of a 240 x 60 torus 2 / 0.5 (measured once with a script;
the circle fits alone on the 32 x 12 tori: 0.054 and 0.195 clean):

======  ===============  ===============  ======================  ===============
noise   32 x 12 3 / 1    32 x 12 1 / 0.3  the four above          5 % decimation
======  ===============  ===============  ======================  ===============
0       0.053 -> 0.0065  0.195 -> 0.012   -7, 0, +2, +11 %        0.021 -> 0.022
0.05 %  0.055 -> 0.010   0.194 -> 0.030   +5, +2, +3, +11 %       0.027 -> 0.025
0.1 %   0.058 -> 0.018   0.196 -> 0.066   -4, +10, -6, -13 %      0.040 -> 0.036
0.2 %   0.064 -> 0.064   0.193 -> 0.188   +1, +2, 0, 0 %          0.057 -> 0.057
0.3 %   0.069 -> 0.069   0.207 -> 0.207   0 %                     0.063 -> 0.063
======  ===============  ===============  ======================  ===============

The same tori as clouds of their vertices (the circle fits with the cloud's own normals):
0.054, 0.019, 0.028, 0.068 alone, 0.013, 0.0025, 0.0041, 0.018 blended; with 0.1 % noise
0.076, 0.019, 0.031, 0.081 -> 0.041, 0.013, 0.025, 0.060, with 0.3 % 0.0630, 0.026, 0.047,
0.105 -> 0.0634, 0.026, 0.046, 0.104.

Inputs not coarse for their shape whose circle fits are limited by a regular sampling all
the same (tori of 96 x 24 vertices and more: 4-15x) are told apart by a probe of a few rows
(:func:`sampling_limited`) and get the same blend; the others keep the circle fits. The probe
runs at the default radius, at a given one and at each of a list of radii; with
``radius="auto"`` it judges the default radius's fits and blends the per-vertex scale's.

Used by :func:`meshcurv.principal_curvatures` unless ``Options.coarse_fit`` is "circles".
"""

from typing import Callable, NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from .area_weights import cloud_area_weights, vertex_area_weights
from .fit.mls import mls_curvature, mls_normals
from .fit.outliers import outlier_weight
from .neighbors import KringWork, ball_counts, ball_grid, edge_adjacency, power_of_two_scale
from .neighbors.csr import ball_max
from .neighbors.radius import _longest_edges
from .pipeline import (BLOCK, _sample_queries, _search_like, ball_search, clean_fraction,
                       kring_search)
from .ring_noise import ring_noise
from .weld import expand_rows

__all__ = ["estimate", "sampling_limited", "support", "mls_rows", "support_noise",
           "SUPPORT_EDGES", "CLOUD_RING", "SUPPORT_CAP", "NOISE_SCALE", "ROUGH_NOISE", "PASSES",
           "PROBE_ROWS", "PROBE_SCALE", "DISAGREEMENT_RATIO"]

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


# Noise, in units of NOISE_SCALE, from which a point within a row's MLS support sets the row's
# share (:func:`support_noise`): where the point's own share is below 1 / 17. Below it, the
# jet's residual is what a coarse sampling of a smooth shape leaves as well (the coarse tori
# of the module's docstring: up to 0.021 of the radius, 1.4 NOISE_SCALE, at one ring of
# vertices, whose MLS estimate is as good as the others'); at a sharp edge it is 0.03-0.05 of
# the radius. A ball wider than a tube reads as rough too: trimesh's 32 x 32 torus 2 / 0.5
# with its exact normals given (0.039 of the radius on two rings) lost the blend, mean |dk|
# 0.0070 -> 0.024. On meshes the rough points count for a row whose support reaches a crease
# (:data:`CREASE`): the 32 x 12 tori's jets read 0.055-0.067 of the radius.
ROUGH_NOISE = 2.0


# The rings' noise (:mod:`meshcurv.ring_noise`) over the mean edge length from which a vertex
# lies on a crease. Measured: 0.13-0.17 on the edges of cubes, a median of 0.05-0.10 on a
# 15-30 degree roof's ridge (its lowest vertices 0.02-0.03: a shallow ridge is a crease in
# part); at most 0.004 on trimesh's clean tori 32 x 12 to 64 x 16 (0.010 on 24 x 8), 0.027 on
# decimated tori and ellipsoids; Gaussian noise of 0.05 % of the diagonal along the normals
# 0.015-0.022 (99th percentile), of 0.1 % 0.02-0.05 (there the jet's noise, close to the
# rings', keeps the MLS surface out either way). A cube's faces, rows at least a radius from
# its edges, the blend forced, mean |k1| + |k2|: 2.5e-5 (the jet's noise alone the same),
# without the creases 0.18.
CREASE = 0.04

# MLS passes: each one after the first fits the normals of the one before (the MLS surface's
# own, where the blend gives it the larger share). The circle fits' normals are 0.2-0.7 degrees
# off on the coarse tori of the module's docstring, the first pass's 0.06-0.15 degrees; mean
# |dk| of the MLS surface alone, one pass -> two: 0.0068, 0.0027, 0.0057, 0.019 -> 0.0054,
# 0.0019, 0.0045, 0.020 (a third pass: 0.0050, 0.0017, 0.0042, 0.021).
PASSES = 2

# Inputs not coarse for their shape: rows probed (spread over the vertex order) to tell whether
# the circle fits are limited by the sampling (:func:`sampling_limited`); the larger support
# over the smaller one (the MLS bias then doubles); the median disagreement over the MLS
# estimate's own change above which the MLS surface is used. Measured ratios (probe of 256
# rows, meshes and their clouds; mean |dk| circle fits -> MLS blend):
#
# - circle fits more accurate: icospheres, UV spheres and random spheres 0.6-0.8; ellipsoids
#   (icosphere, UV 128 x 64 and 256 x 128, random) 0.5-1.9, the UV 256 x 128 mesh 0.00009 ->
#   0.00041 at 1.86; monkey saddle and paraboloid, regular and random 0.8-1.5; CNC clouds
#   0.7-1.4; every noisy input (0.05-0.3 % of the diagonal, CNC sigma_eps 0.1-0.2) 1.3-2.0,
#   the trimesh torus 1 / 0.3 128 x 32 cloud at 0.05 % 0.0278 -> 0.0328 at 2.03;
# - MLS surface more accurate: tori of 96 x 24 to 360 x 60 vertices, trimesh's and
#   meshcurv.surfaces', 2.8-8.4 (0.0006-0.040 -> 0.00005-0.0069); the 120 x 30 torus at
#   0.05 % noise 2.35 / 2.54 (0.0226 -> 0.0168); a 64 x 40 cylinder 2.2 (0.0001 -> 0.00002).
#
# A sweep of tori between the two (2 / 0.5 and 1 / 0.3 at 96 x 24 to 240 x 60, noise 0-0.1 %
# of the diagonal, meshes, clouds with and without their normals) found ratios of 2.2-2.5 on
# 10 inputs: the MLS surface more accurate on 9 (1.3-6x: the 200 x 40 torus's cloud with its
# normals 0.00127 -> 0.00020 at 2.45; 1 / 0.3 96 x 24 at 0.05 %, 0.059 -> 0.022 at 2.41),
# less on one (2 / 0.5 128 x 32 cloud at 0.05 %, 0.0182 -> 0.0190 at 2.25); between 2.0 and
# 2.2, circle fits better on 2 of 5 (the 2.03 above, 23 % worse with the MLS surface). 2.2
# lies between the largest ratio where the MLS surface lost more than 5 % and the smallest
# of the sweep's cases where it won by more than 1.3x.
PROBE_ROWS = 256
PROBE_SCALE = float(np.sqrt(2.0))
DISAGREEMENT_RATIO = 2.2


def estimate(v, f, radii, query, circle_fits, use_kring=True, coarse=True, probe_fits=None,
             area_weights=False):
    """The curvature of a mesh or cloud at each radius of the list ``radii`` (a list of
    results, rows ``query``, all: None, in its order): the circle fits' result blended with
    :data:`PASSES` MLS passes (:func:`mls_rows`) where the input is ``coarse`` for its shape
    (at its default radius), or where a probe of :data:`PROBE_ROWS` rows finds the circle
    fits limited by the sampling (:func:`sampling_limited`); the circle fits alone otherwise.

    ``circle_fits(rows)`` returns the circle fits' list of :class:`meshcurv.CurvatureResult`
    (one per radius) at the vertex indices ``rows``; ``probe_fits(rows)``, the same, the fits
    the probe judges (default: ``circle_fits``; "auto" passes the default radius's). With
    ``query`` the probe's fits run at the probe's rows and where their supports reach, then
    the circle fits at the queries and, for the radii blended, where the queries' supports
    reach and those rows' MLS passes where the next pass's supports do, so that every row is
    the whole input's. Supports are searched over the mesh's k-rings (``use_kring``) or in
    balls (clouds: ``f`` None). The MLS fits run on coordinates scaled by the power of two
    that keeps the radius's square finite (the same curvatures at any scale). With
    ``area_weights`` the MLS fits take the points' area weights (:mod:`meshcurv.area_weights`:
    a mesh's vertices', a cloud's points') with the outlier weights (the probe: with them or
    without them, :func:`_limited`); else the outlier weights alone.
    """
    n = len(v)
    if n == 0:                      # nothing to probe or blend
        return circle_fits(np.arange(0))

    def areas(rows=None):
        if not area_weights:
            return None
        return vertex_area_weights(v, f, rows) if f is not None else \
            cloud_area_weights(v, rows)

    whole = query is None or (len(query) == n and np.array_equal(query, np.arange(n)))
    # the circle fits first where the probe needs nothing before them: the MLS surface's
    # searches (a cloud's grid: a copy of the points) are not held through them
    bases = circle_fits(np.arange(n)) if whole and probe_fits is None else None
    # one edge adjacency serves every radius's k-rings and the rings' noise, one set of work
    # arrays every k-ring search
    adjacency = edge_adjacency(f, n) if f is not None and use_kring else None
    work = KringWork(n) if adjacency is not None else None
    scales = [_supports(v, f, r, use_kring, not coarse, adjacency, work) for r in radii]
    probe = _sample_queries(n, PROBE_ROWS)
    blended = [True] * len(radii) if coarse else None
    if blended is None:
        # the probe reads the area weights of its rows' lists alone
        near = np.unique(np.concatenate([probe] + [scale.probe_search(probe)[1]
                                                   for scale in scales]))
        probe_area = areas(near)
        if not (whole and probe_fits is None):
            blended = [_limited(base, near, probe, scale, probe_area)
                       for base, scale in zip((probe_fits or circle_fits)(near), scales)]
    if whole:
        fitted = np.arange(n)
        if bases is None:
            bases = circle_fits(fitted)
        if blended is None:
            blended = [_limited(base, fitted, probe, scale, probe_area)
                       for base, scale in zip(bases, scales)]
        chains = [[fitted] * (1 + PASSES * blend) for blend in blended]
    else:
        query = np.asarray(query)
        chains = [_chain(scale.search, query) if blend else [query]
                  for blend, scale in zip(blended, scales)]
        fitted = np.unique(np.concatenate([chain[0] for chain in chains]))
        bases = circle_fits(fitted)
    passes = any(len(c) > 1 for c in chains)
    ring = _ring(scales[0], f, adjacency) if f is not None and passes else None
    area = areas() if passes else None
    return [_passes(base, fitted, chain, scale, ring, area)
            for base, chain, scale in zip(bases, chains, scales)]


class _Scale(NamedTuple):
    """The MLS fits at one radius: ``unit``, the power of two that keeps the radius's square
    finite; ``v``, the points times it; ``h``, their supports (:func:`support`); ``search``
    and ``probe_search``, lists (:func:`_lists`) reaching the largest support and
    :data:`PROBE_SCALE` times it (the probe's wider fits)."""
    unit: float
    v: np.ndarray
    h: np.ndarray
    search: Callable
    probe_search: Callable


def _supports(v, f, radius, use_kring, probed, adjacency=None, work=None):
    """The :class:`_Scale` of ``radius``: lists over the mesh's k-rings (``use_kring``, over
    its edge ``adjacency`` and with the :class:`KringWork` ``work``, each made here if None)
    or in balls. The passes' lists reach the largest support, the probe's ``PROBE_SCALE``
    times it; but a ball search lists in the order of its grid, whose cells follow its reach,
    so where the input is ``probed`` the passes read the probe's ball lists (the order of the
    sums the golden outputs record)."""
    unit = power_of_two_scale(radius)
    with np.errstate(over="ignore"):
        vs = v * unit if unit != 1.0 else v
    h = support(vs, f, radius * unit)
    reach = float(h.max())
    wide = reach * (PROBE_SCALE if probed else 1.0)
    finite = None if use_kring else np.flatnonzero(np.isfinite(vs).all(axis=1))
    search = kring_search(vs, f, reach, adjacency, work) if use_kring else \
        ball_search(vs, finite, wide)
    probe_search = _search_like(search, vs, f, finite, wide) if use_kring else search
    return _Scale(unit, vs, h, _lists(search), _lists(probe_search))


def _chain(search, query):
    """The rows of the circle fits, then of each of the :data:`PASSES` passes, the last the
    ``query``."""
    wanted = [query]
    for _ in range(PASSES):
        wanted.insert(0, np.union1d(wanted[0], search(wanted[0])[1]))
    return wanted


def _rows(result, fitted, rows):
    """The rows ``rows`` of ``result``, whose rows are the vertex indices ``fitted``
    (ascending)."""
    return result if rows is fitted else expand_rows(result, np.searchsorted(fitted, rows))


def _field(result, fitted, n):
    """The circle fits' normals (n, 3), outlier weights (n,) and measured noise (n,) at the
    rows ``fitted`` of ``result``; NaN normals and noise and weight 1 elsewhere."""
    normals = np.full((n, 3), np.nan)
    normals[fitted] = result.normals
    weights = np.ones(n)
    weights[fitted] = outlier_weight(result.outlier_score)
    noise = np.full(n, np.nan)
    noise[fitted] = result.noise
    return normals, weights, noise


def _limited(base, fitted, probe, scale, area=None):
    """:func:`sampling_limited` at the rows ``probe`` of the circle fits' ``base`` (rows
    ``fitted``, ascending) at the :class:`_Scale` ``scale``; with ``area`` (the points' area
    weights, (n,)), whether the MLS surface with them or without them finds them so.

    Each MLS surface judges the circle fits against its own error: the weighted one is the
    more accurate where the sampling is uneven (MeshLab's decimations, ratio with and without
    the weights: ellipsoid at 10 % 3.18 and 1.68, torus at 20 % 2.02 and 1.79), the
    unweighted one where an even grid's areas vary smoothly across the support (trimesh's
    32 x 32 tori at their default radius: 2.09 and 2.62, 1.93 and 2.80)."""
    normals, plain, _ = _field(base, fitted, len(scale.v))
    rows = _rows(base, fitted, probe)

    def finds(weights):
        return sampling_limited(rows, probe, scale.v, normals, weights, scale.h[probe],
                                scale.probe_search, scale.unit)
    return finds(plain if area is None else plain * area) or (area is not None and finds(plain))


class _Ring(NamedTuple):
    """A mesh's noise measured over its rings (:func:`meshcurv.ring_noise.ring_noise`),
    (n,), model units, and whether each vertex lies on a crease (n,) bool."""
    noise: np.ndarray
    crease: np.ndarray


def _ring(scale, f, adjacency=None):
    """The :class:`_Ring` of the mesh of faces ``f`` through the points of the
    :class:`_Scale` ``scale`` (whose unit keeps their squares finite): a crease where the
    rings' noise is at least :data:`CREASE` times the vertex's mean edge length;
    ``adjacency``: the mesh's edge adjacency, if already made."""
    noise, edge = ring_noise(scale.v, f, adjacency)
    with np.errstate(invalid="ignore"):
        return _Ring(noise / scale.unit, noise >= CREASE * edge)


def _passes(base, fitted, chain, scale, ring=None, area=None):
    """The circle fits' result ``base`` at the rows ``fitted`` (ascending) blended with an
    MLS pass over the rows of each of ``chain[1:]`` (:func:`_chain`; none: ``base``) at the
    :class:`_Scale` ``scale``; at the rows ``chain[-1]``; ``area`` (n,): the points' area
    weights, which the MLS fits take with the outlier weights (None: those alone)."""
    normals, weights, jet_noise = _field(base, fitted, len(scale.v))
    if area is not None:
        weights = weights * area
    noise, crease = jet_noise, None
    if ring is not None:                # the smaller, where the jet measured one
        noise = np.where(np.isnan(jet_noise), jet_noise, np.fmin(jet_noise, ring.noise))
        crease = ring.crease
    part = _rows(base, fitted, chain[-1])
    for i, rows in enumerate(chain[1:], start=2):
        part = _rows(base, fitted, rows)
        # the passes before the last give normals alone; the last blends into the arrays of
        # ``part`` (rows copied from ``base``, or ``base`` itself, which no pass reads after)
        last = i == len(chain)
        if last:
            part.mls_share = np.empty(len(rows))
            out = {name: getattr(part, name) for name in BLENDED + ("mls_share",)}
        else:
            out = {"normals": np.empty((len(rows), 3))}
        mls_rows(part, rows, scale.v, normals, weights, scale.h[rows], scale.search,
                 scale.unit, out=out, noise=noise, rough_noise=jet_noise, crease=crease)
        normals[rows] = out["normals"]
    return part


def sampling_limited(result, rows, v, normals, point_weights, h, search, unit=1.0):
    """Whether the circle fits' ``result`` at the vertex indices ``rows`` (m,) is limited by
    the sampling rather than by the shape: whether the median over the rows of their
    difference from the MLS surface's curvature at supports ``h`` exceeds
    :data:`DISAGREEMENT_RATIO` times the median change of the MLS curvature from ``h`` to
    ``PROBE_SCALE h`` (one pass on the circle fits' ``normals``; arguments as
    :func:`mls_rows`).

    The MLS estimate's bias grows like h^2, so its change over the two supports measures its
    own error; where the circle fits are right, their difference from it is that error and
    the ratio stays near 1 (position noise alone: 1.3-1.5); where they carry the error of a
    regular grid sampled at a few points per half-set (tori), the difference is that error
    and the ratio is 2.8-8 (measurements at :data:`DISAGREEMENT_RATIO`). False where either
    median is 0 or NaN.
    """
    k1, k2 = _mls_curvatures(rows, v, normals, result.normals, h, search, point_weights,
                             unit)[:2]
    w1, w2 = _mls_curvatures(rows, v, normals, result.normals, PROBE_SCALE * h, search,
                             point_weights, unit)[:2]
    ok = np.asarray(result.valid) & np.isfinite(k1 + k2 + w1 + w2)
    if not ok.any():
        return False
    apart = np.median(np.abs(result.k1 - k1)[ok] + np.abs(result.k2 - k2)[ok])
    change = np.median(np.abs(w1 - k1)[ok] + np.abs(w2 - k2)[ok])
    return bool(change > 0.0 and apart > DISAGREEMENT_RATIO * change)


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
        reach, used = _cloud_reach(v, radius)
    h = np.clip(SUPPORT_EDGES * np.where(used, reach, 0.0), radius, SUPPORT_CAP * radius)
    return np.where(used, h, radius)


def _cloud_reach(v, radius):
    """Each cloud point's distance (n,) to its ``CLOUD_RING``-th nearest point, and whether
    it has one (n,) bool; 0 where that distance is below ``radius / SUPPORT_EDGES``, whose
    support is ``radius`` whatever it is: a count of the points in a ball of that size (a
    grid, one pass) spares the dense points the k-d tree's search."""
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    reach, used = np.zeros(len(v)), np.zeros(len(v), dtype=bool)
    k = min(CLOUD_RING, len(finite) - 1)
    if k < 1:
        return reach, used
    # a margin below the bound: the ball's count and the tree's distance round differently
    near = radius / SUPPORT_EDGES * (1.0 - 1e-9)
    vf = v[finite]
    grid = ball_grid(vf, near)
    dense = np.zeros(len(finite), dtype=bool) if grid is None else \
        ball_counts(grid, vf, near) > k
    used[finite[dense]] = True
    rest = finite[~dense]
    if len(rest):
        d, _ = cKDTree(vf).query(v[rest], k=k + 1, workers=-1)
        reach[rest] = d[:, k]
        used[rest] = np.isfinite(d[:, k])
    return reach, used


# The result's fields the MLS surface's estimate blends into.
BLENDED = ("k1", "k2", "d1", "d2", "normals")


def mls_rows(result, rows, v, normals, point_weights, h, search, unit=1.0, block=BLOCK,
             out=None, noise=None, rough_noise=None, crease=None):
    """The MLS estimate of the rows ``rows`` of ``result`` (vertex indices, (m,)), blended
    into its fields (k1, k2, d1, d2, normals) by the noise of the row's support (module
    docstring, :func:`support_noise`): a dict of the blended fields, ``out`` (the arrays to
    write: all five fields, or "normals" alone, then from the MLS gradient alone,
    :func:`meshcurv.fit.mls.mls_normals`; they may be ``result``'s own; with an "mls_share"
    (m,) array, each row's share of the MLS estimate is written there too) or new arrays.

    ``v`` (n, 3) and ``h`` are the vertices and supports in the result's units times ``unit``
    (a power of two that keeps squares finite; curvatures are scaled back by it).

    ``normals`` (n, 3): unit normals of every vertex the supports reach (NaN: left out);
    ``point_weights`` (n,) or None: the outlier weights; ``h`` (m,): each row's support;
    ``search(idx)``: CSR lists ``(indptr, indices)`` about the vertices ``idx`` holding every
    vertex within ``h``; ``noise`` (n,): the noise measured at every vertex the supports
    reach (model units, NaN: unknown), None: the rows' own (``result.noise``) alone;
    ``rough_noise`` (n,): the noise that tells the rough points (:data:`ROUGH_NOISE`, default
    ``noise``); ``crease`` (n,) bool or None: see :func:`support_noise`. Rows ``result`` has
    no estimate for, and rows whose MLS fit fails, keep the circle fits'.
    """
    m = len(rows)
    scale = NOISE_SCALE * result.radius
    valid = np.asarray(result.valid)
    if out is None:
        out = {name: np.empty(np.shape(getattr(result, name))) for name in BLENDED}
    # a block at a time: the MLS fields of one block alive at once
    curvatures = "k1" in out
    if noise is not None:
        with np.errstate(invalid="ignore"):
            judged = noise if rough_noise is None else rough_noise
            rough = np.where(judged >= ROUGH_NOISE * scale, judged, np.nan)
        if not np.isfinite(rough).any():
            rough = None                # no rough point: each row's own noise
    for lo in range(0, m, block):
        sl = slice(lo, min(m, lo + block))
        idx = rows[sl]
        lists = search(idx)
        row_noise = result.noise[sl] if noise is None else \
            support_noise(idx, v, noise, rough, h[sl], lists, crease)
        # the block's lists serve its one MLS block
        if curvatures:
            k1, k2, d1, d2, n = _mls_curvatures(idx, v, normals, result.normals[sl], h[sl],
                                                lambda _: lists, point_weights, unit, block)
            use = valid[sl] & np.isfinite(k1) & np.isfinite(k2)
        else:
            n = _mls_normals(idx, v, normals, result.normals[sl], h[sl], lambda _: lists,
                             point_weights, block)
            use = valid[sl] & np.isfinite(n).all(axis=1)
        g = np.where(use, clean_fraction(row_noise, scale), 0.0)
        # directions and normal: the larger share's
        mls_side = (g >= 0.5)[:, None]
        if "mls_share" in out:
            out["mls_share"][sl] = g
        if curvatures:
            out["k1"][sl] = g * np.where(use, k1, 0.0) + (1.0 - g) * result.k1[sl]
            out["k2"][sl] = g * np.where(use, k2, 0.0) + (1.0 - g) * result.k2[sl]
            out["d1"][sl] = np.where(mls_side, d1, result.d1[sl])
            out["d2"][sl] = np.where(mls_side, d2, result.d2[sl])
        out["normals"][sl] = np.where(mls_side, n, result.normals[sl])
    return out


def support_noise(rows, v, noise, rough, h, lists, crease=None):
    """The noise (m,) that sets the MLS share of the vertex indices ``rows``: the largest
    of ``noise`` ((n,), model units) at the row and of ``rough`` ((n,), the noise of the
    rough points, NaN elsewhere) at the points within its support ``h`` ((m,), in the units
    of ``v``); NaN where the row's own is. ``lists``: CSR ``(indptr, indices)`` about the
    rows, holding every vertex within ``h`` (arguments as :func:`mls_rows`); ``crease``
    ((n,) bool): the rough points count only for rows whose support holds a crease vertex
    (None: for every row); ``rough`` None: there is no rough point.

    The MLS surface of a row is smooth over its whole support: where that reaches a sharp
    edge (the local jet's residual there 0.03-0.05 of the radius, against 1e-4 on the faces
    beside it) it rounds the edge off for every row within the support's reach, and its
    second pass's normals carry that further. Capped cylinder r 1 (a 30k-point cloud of
    trimesh's 256-section cylinder), its rows at least a radius from the edges, mean |dk|
    with each row's own noise: 0.50 at 1-1.5 radii from the edge, 0.12 at 1.5-2, 0.14 on
    the caps (the circle fits alone: 0.016 and 0)."""
    if rough is None:
        return noise[rows]
    top = np.empty(len(rows))
    ball_max(v, v[rows], *lists, h * h, rough, top)
    if crease is not None:
        near = np.empty(len(rows))
        ball_max(v, v[rows], *lists, h * h, np.where(crease, 1.0, np.nan), near)
        top[np.isnan(near)] = np.nan
    # NaN at the row stays (no share); NaN neighbours are left out
    return np.maximum(noise[rows], np.where(np.isnan(top), -np.inf, top))


def _mls_normals(rows, v, normals, row_normals, h, search, point_weights, block=BLOCK):
    """The MLS surface's unit normals (m, 3) at the vertex indices ``rows`` (:func:`mls_normals`:
    its gradient alone), NaN where it is undefined (arguments as :func:`_mls_curvatures`)."""
    n = np.empty((len(rows), 3))
    for lo in range(0, len(rows), block):
        sl = slice(lo, min(len(rows), lo + block))
        idx = rows[sl]
        indptr, indices = search(idx)
        mls_normals(v, normals, v[idx], row_normals[sl], idx, indptr, indices, h[sl],
                    point_weights, n[sl])
    return n


def _mls_curvatures(rows, v, normals, row_normals, h, search, point_weights, unit=1.0,
                    block=BLOCK):
    """The MLS surface's (k1, k2, d1, d2, normals) at the vertex indices ``rows`` (m,),
    curvatures in the units of ``v / unit``, NaN where the fit fails; ``row_normals`` (m, 3)
    set the sign (arguments as :func:`mls_rows`)."""
    m = len(rows)
    k1, k2 = np.empty(m), np.empty(m)
    d1, d2, n = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    for lo in range(0, m, block):
        sl = slice(lo, min(m, lo + block))
        idx = rows[sl]
        indptr, indices = search(idx)
        mls_curvature(v, normals, v[idx], row_normals[sl], idx, indptr, indices, h[sl],
                      point_weights, (k1[sl], k2[sl], d1[sl], d2[sl], n[sl]))
    with np.errstate(over="ignore"):
        return k1 * unit, k2 * unit, d1, d2, n
