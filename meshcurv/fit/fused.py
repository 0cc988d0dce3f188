"""The fused estimator: per point, frame -> half-set accumulators -> circle fits -> Euler fit,
as one compiled kernel over all query points (:func:`curvature_cga`).

Each step is a kernel of its own module (:mod:`meshcurv.fit.frame`, :mod:`meshcurv.fit.circle`,
:mod:`meshcurv.fit.euler`); :func:`estimate_one` calls them in order for one point. The numpy
specification of the whole per-point estimator is :func:`meshcurv.fit.fused_spec.curvature_at_point`
and the tests hold the kernel to it (1e-9).
"""

import math

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK
from .circle import N_ACC, N_ROW, accumulate_half_sets, half_set_samples, normal_row_weight
from .constants import (MIN_DIRECTION_SPREAD, PLANE_OFFSET, STATUS_DEGENERATE_DIRECTIONS,
                        STATUS_ILL_POSED_FIT, STATUS_NO_NORMAL, STATUS_NO_POSITION, STATUS_OK,
                        STATUS_TOO_FEW_HALF_SETS, STATUS_TOO_FEW_NEIGHBORS)
from .euler import direction_spread, euler_residual, robust_euler_fit
from .frame import tangent_frame

__all__ = ["curvature_cga", "estimate_one", "sampling_planes", "cache_is_warm"]


@njit(cache=True)
def estimate_one(points, nbr, lo, hi, x, n, rank, radius, beta, opts, planes, work, tu, tv,
                 point_normals=None, noise=np.nan, normal_gain=1.0, point_weights=None,
                 row_weight=np.nan, taper=-1.0):
    """Circle fits in 2 ndir half-sets around one point x, then the Euler model fit.

    Parameters
    ----------
    points : (n, 3) float64; ``nbr[lo:hi]`` the rows of x's candidate neighbors
    x, n : (3,) float64, the point and its unit normal; rank : see :func:`curvature_cga`
    radius : float, model units; beta : float in [0, 1], the weights' blend
        ``(1 - beta) + beta (1 - r^2)^WEIGHT_POWER`` (equal at 0, distance weights at 1)
    opts : ``(ndir, slab, min_points, min_spread, unit_norm, corrected, half_frequency,
        robust)`` as in :func:`curvature_cga`
    planes : ``(ca, sa, dirs)`` from :func:`sampling_planes`
    work : ``(acc, kappa, rows, active, scratch, mat, rhs, sol, b3, ev, mix, nbr_rows,
        members)`` scratch arrays (see :func:`curvature_cga`; the last two those of
        :func:`meshcurv.fit.circle.accumulate_half_sets`)
    tu, tv : (3,) float64 outputs, the tangent frame
    point_normals : (n, 3) float64 unit normals aligned with ``points``, or None: each circle
        fit then also fits its neighbors' normals
        (:func:`meshcurv.fit.circle.circle_fit`), weighted by
        :func:`meshcurv.fit.circle.normal_row_weight`.
    point_weights : (n,) float64 in [0, 1] or None, see :func:`curvature_cga`
    row_weight : float, the normal rows' weight mu to use instead of measuring it (NaN:
        measure it, times ``normal_gain``)
    taper : float in [0, 1], the blend of the slabs' taper
        (:func:`meshcurv.fit.circle.add_half_set`); negative: ``beta``

    Returns
    -------
    ``(k1, k2, theta1, n_samples, residual, n_neighbors, status, mu)``: curvatures (1 / model
    units; NaN where no estimate), the angle of d1 from tu, the circle fits used, the Euler
    fit's RMS (1 / model units), the neighbors in the ball, the reason code
    (:class:`meshcurv.result.Status`) and the normal rows' weight used (0 without them). An
    estimate needs 3 planes and 5 circle fits, a well-posed Euler fit and measured directions
    spread by ``MIN_DIRECTION_SPREAD``.
    """
    ndir, slab, min_points, min_spread, unit_norm, corrected, half_frequency, robust = opts
    ca, sa, dirs = planes
    acc, kappa, rows, active, scratch, mat, rhs, sol, b3, ev, mix, nbr_rows, members = work
    inv_r = 1.0 / radius
    r2max = radius * radius
    tangent_frame(points, nbr, lo, hi, x, n, r2max, tu, tv, rank, point_weights)
    n_nbr = accumulate_half_sets(points, nbr, lo, hi, x, n, tu, tv, r2max, inv_r, beta,
                                 (ca, sa), slab, acc, nbr_rows, members, point_normals,
                                 point_weights, taper)
    mu = 0.0
    if point_normals is not None:
        if np.isfinite(row_weight):
            mu = row_weight
        else:
            mu = normal_gain * normal_row_weight(acc, ndir, min_points, min_spread,
                                                 (noise * inv_r) * (noise * inv_r))
    m, planes_seen = half_set_samples(acc, ndir, min_points, min_spread, unit_norm, corrected,
                                      dirs, kappa, rows, mix, active, b3, ev, mu)
    if planes_seen < 3 or m < 5:
        why = STATUS_TOO_FEW_NEIGHBORS if n_nbr < min_points else STATUS_TOO_FEW_HALF_SETS
        return np.nan, np.nan, np.nan, m, np.nan, n_nbr, why, mu
    npar = 5 if half_frequency else 3
    if not robust_euler_fit(rows, kappa, active, m, npar, robust, mat, rhs, sol, scratch):
        return np.nan, np.nan, np.nan, m, np.nan, n_nbr, STATUS_ILL_POSED_FIT, mu
    if direction_spread(mix, active, m) < MIN_DIRECTION_SPREAD:
        return np.nan, np.nan, np.nan, m, np.nan, n_nbr, STATUS_DEGENERATE_DIRECTIONS, mu
    used, sse = euler_residual(rows, kappa, active, m, npar, sol)
    amp = math.sqrt(sol[1] * sol[1] + sol[2] * sol[2])
    return ((sol[0] + amp) * inv_r, (sol[0] - amp) * inv_r, 0.5 * math.atan2(sol[2], sol[1]),
            used, math.sqrt(sse / used) * inv_r, n_nbr, STATUS_OK, mu)


@njit(cache=True)
def sampling_planes(ndir):
    """``(ca, sa, dirs)``: (cos, sin) of the ``ndir`` planes' directions, each (ndir,), and
    (cos, sin) of theta and 2 theta of each half-set's direction theta, (2 ndir, 4)."""
    nh = 2 * ndir
    ca = np.empty(ndir)
    sa = np.empty(ndir)
    for i in range(ndir):
        # planes a quarter step off the frame's axis: no point lies exactly on a half-set
        # boundary because of the frame or of a regular grid, so rounding cannot flip it
        ca[i] = math.cos((i + PLANE_OFFSET) * math.pi / ndir)
        sa[i] = math.sin((i + PLANE_OFFSET) * math.pi / ndir)
    # (cos, sin) of theta and 2 theta of each half-set's direction theta, once for all points
    dirs = np.empty((nh, 4))
    for i in range(ndir):
        for side in range(2):
            theta = math.atan2(sa[i], ca[i]) + side * math.pi
            dirs[i + side * ndir, 0] = math.cos(theta)
            dirs[i + side * ndir, 1] = math.sin(theta)
            dirs[i + side * ndir, 2] = math.cos(2.0 * theta)
            dirs[i + side * ndir, 3] = math.sin(2.0 * theta)
    return ca, sa, dirs


@njit(cache=True)
def _write_directions(q, theta1, tu, tv, n, d1, d2):
    """d1 at angle ``theta1`` from tu in the tangent plane, d2 = n x d1, into row q."""
    ct = math.cos(theta1)
    st = math.sin(theta1)
    for a in range(3):
        d1[q, a] = ct * tu[a] + st * tv[a]
    d2[q, 0] = n[1] * d1[q, 2] - n[2] * d1[q, 1]
    d2[q, 1] = n[2] * d1[q, 0] - n[0] * d1[q, 2]
    d2[q, 2] = n[0] * d1[q, 1] - n[1] * d1[q, 0]


@njit(parallel=True, cache=True)
def curvature_cga(points, query_points, query_normals, indptr, indices, radius, blend, opts,
                  out, rank=None, point_normals=None, noise=None, normal_gain=None,
                  point_weights=None, row_weight=None, taper=None):
    """Fused CGA circle-fit estimator over query points with CSR neighbor lists.

    Parameters
    ----------
    points : (n, 3) float64, the neighbor set
    query_points, query_normals : (m, 3) float64, where to estimate and the unit normals there
    indptr, indices : CSR lists into ``points``: neighbors of query q are
        ``indices[indptr[q]:indptr[q+1]]`` (the query point itself may be present; coincident
        points are skipped)
    radius : float, model units
    blend : (m,) float64 in [0, 1], per query point: 0 equal weights, 1 distance weights
        (1 - r^2 / radius^2)^WEIGHT_POWER, between the two a mix of both weight functions
    opts : ``(ndir, slab, min_points, min_spread, unit_norm, corrected, half_frequency,
        robust)`` (int, float, float, float, bool x 4): planes, the slab's half-width (fraction
        of ``radius``), the fewest points of a half-set, the farthest reach it needs (fraction
        of ``radius``); ``unit_norm`` circle fits normalised by |t| = 1 (the paper) instead of
        t1 = 1; ``corrected`` (``section_blend``), ``half_frequency``, ``robust`` of
        :func:`meshcurv.principal_curvatures` (:attr:`meshcurv.options.Plan.fit`)
    out : ``(k1, k2, d1, d2, n_samples, residual, n_neighbors, status)``, (m,) or (m, 3)
        arrays written in place: NaN where no estimate is possible, and ``status`` (m,) int8
        says why (:class:`meshcurv.result.Status`)
    rank : (n,) int64, optional, the input index of each row of ``points`` when they are stored
        in another order (e.g. a grid's sorted copy, for memory locality): the tangent frame's
        lowest-index rule then picks the same neighbor as on the input.
    point_normals : (n, 3) float64, optional, unit normals of ``points`` (same rows; NaN where
        unknown), and ``noise`` (m,) the position noise at each query point (model units, the
        RMS height residual of :func:`meshcurv.fit.jet.local_jet`) and ``normal_gain`` (m,) a
        factor in [0, 1] on the normal rows' weight: the circle fits then also fit the normals'
        turn (normal-aware circle fits; see :func:`estimate_one`).
        ``query_normals`` still sets each frame.
    point_weights : (n,) float64 in [0, 1], optional, per row of ``points``: multiplies each
        neighbor's weight in the circle fits (the outlier pass's weights,
        :func:`meshcurv.fit.outliers.outlier_weight`); default 1.
    row_weight : (m,) float64, optional, with ``point_normals``: per query point, the normal
        rows' weight to use (finite entries), or NaN to measure it, and then the weight used is
        written there. A second call over the same points with the first call's weights fits
        the same combination of rows (the bias correction's two radii).
    taper : (m,) float64 in [0, 1], optional, per query point: the blend of the slabs' taper
        (:func:`meshcurv.fit.circle.add_half_set`); default ``blend``.
    """
    k1, k2, d1, d2, n_samples, residual, n_neighbors, status = out
    ndir = opts[0]
    m = query_points.shape[0]
    nh = 2 * ndir
    planes = sampling_planes(ndir)
    longest = 0
    for q in range(m):
        longest = max(longest, indptr[q + 1] - indptr[q])
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        work = (np.empty((nh, N_ACC)), np.empty(nh), np.empty((nh, 5)), np.empty(nh),
                np.empty(nh), np.empty((5, 5)), np.empty(5), np.empty(5), np.empty((3, 3)),
                np.empty(3), np.empty((nh, 2)), np.empty((longest, N_ROW)),
                np.empty((2, longest), dtype=np.int64))
        tu = np.empty(3)
        tv = np.empty(3)
        x = np.empty(3)
        n = np.empty(3)
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            for a in range(3):
                x[a] = query_points[q, a]
                n[a] = query_normals[q, a]
            e1, e2, theta1, used, rms, n_nbr = np.nan, np.nan, np.nan, 0, np.nan, 0
            why = STATUS_NO_POSITION
            nn = math.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
            if np.isfinite(x[0] + x[1] + x[2]):
                why = STATUS_NO_NORMAL
            if nn > 0.0 and np.isfinite(nn) and np.isfinite(x[0] + x[1] + x[2]):
                for a in range(3):
                    n[a] /= nn
                if point_normals is None:
                    e1, e2, theta1, used, rms, n_nbr, why, mu = estimate_one(
                        points, indices, indptr[q], indptr[q + 1], x, n, rank, radius,
                        blend[q], opts, planes, work, tu, tv, None, np.nan, 1.0,
                        point_weights, np.nan, -1.0 if taper is None else taper[q])
                else:
                    given_mu = np.nan if row_weight is None else row_weight[q]
                    e1, e2, theta1, used, rms, n_nbr, why, mu = estimate_one(
                        points, indices, indptr[q], indptr[q + 1], x, n, rank, radius,
                        blend[q], opts, planes, work, tu, tv, point_normals, noise[q],
                        normal_gain[q], point_weights, given_mu,
                        -1.0 if taper is None else taper[q])
                    if row_weight is not None:
                        row_weight[q] = mu
            if why == STATUS_OK and not np.isfinite(e1):
                why = STATUS_ILL_POSED_FIT
            status[q] = why
            n_samples[q] = used
            residual[q] = rms
            n_neighbors[q] = n_nbr
            if np.isfinite(e1):
                k1[q] = e1
                k2[q] = e2
                _write_directions(q, theta1, tu, tv, n, d1, d2)
            else:
                k1[q] = np.nan
                k2[q] = np.nan
                for a in range(3):
                    d1[q, a] = np.nan
                    d2[q, a] = np.nan


def cache_is_warm():
    """Whether numba's on-disk cache holds the curvature kernel compiled from this source.

    False means the next call compiles the kernels (the first run after installing or
    updating meshcurv, ~30 s on 2 cores; cached afterwards). True when it cannot be told.
    """
    try:
        return bool(curvature_cga._cache._cache_file._load_index())
    except Exception:    # numba internals moved: say nothing rather than fail
        return True
