"""Per-vertex scale (``radius="auto"``): at each vertex, the radius of a ladder that minimises
the estimated curvature error.

The estimator runs at every radius of a ladder ``r_j = R0 * 2^(j / 2)`` around the default
radius R0 (:func:`ladder`; one neighbor search over the largest ball,
:func:`meshcurv.pipeline.run_radii`). At each vertex and radius the squared error of (k1, k2)
is modelled as variance plus squared bias,

    E_j = V_j + B_j,    V_j = NOISE_GAIN sigma_j^2 / (r_j^4 N_j) + NORMAL_GAIN a2 / (r_j^2 N_j),
    B_j = (a r_j^2)^2,

- V: a height noise sigma_j along the normal (``CurvatureResult.noise``, the local jet's RMS
  residual at r_j) averaged over the N_j points of the ball (least squares of h = k r^2 / 2
  over a disc: var(k) ~ sigma^2 / (N r^4)); NOISE_GAIN measured on noisy spheres, where the
  error is all variance. With normals used as given, their noise adds its own term: a2 the
  variance per tangent component of the given normals' noise
  (:func:`meshcurv.pipeline.given_normal_noise`, 0 for exact ones), whose rows in the circle
  fits measure the curvature as a slope over the ball (var(k) ~ a2 / (N r^2)).
- B: the circle model's error where curvature varies, ~ a r^2. From two neighboring radii,
  k(r_j) - k(r_j / sqrt 2) = a r_j^2 / 2, so B_j = 4 d_j^2 with d_j the RMS change of (k1, k2)
  between them, less what the noise puts in that change (nested least-squares estimates
  differ by variance V_{j-1} - V_j). The smallest radius gets B_1 / 4 (bias^2 ~ r^4).

Both terms are averaged over the ``SMOOTH_NEIGHBORS`` nearest estimated vertices (one vertex's
change across scales is mostly noise; the curvature, its variation and the noise vary slowly
over the surface) and the radius minimising E_j is taken among the admissible ones: the
default radius R0 wherever it is valid; smaller radii with at least ``MIN_SUPPORT``
neighbors; larger ones also only while ``max(|k1|, |k2|) r_j <= MAX_ARC`` with the curvature
measured at R0 (the ball stays a small cap of the curvature: thin tubes and coarse meshes are
not over-smoothed; the larger balls' own curvature is no bound, since a ball spanning a whole
tube sees a smaller one). Where no radius is admissible the valid one of least estimated error
is taken; a radius whose row has no estimate is never taken while another radius has one; a
vertex R0 flags as an outlier keeps R0's row. Every field of the result's row is that
radius' row, and ``radius_used`` says which.

The default radius runs first, and its rows whose bias correction is on (measured noise below
``BIAS_NOISE_SCALE`` of the radius, :func:`corrected_rows`) keep it: the correction
removes the bias the ladder trades against noise, so the model above no longer describes
them, and on clean data the ladder chose worse (torus 240 x 60 at its default radius: mean
|dk| 0.0009 against 0.0006; ellipsoid 0.0007 against 0.0004). Where every row is such, the
other radii are not run: clean input costs what the default does.
"""

import math
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from . import pipeline
from .neighbors import power_of_two_scale, scaled_for_squares
from .result import Status, mls_shares, oriented_like

__all__ = ["ladder", "select", "run_auto", "LADDER_EXPONENTS", "NOISE_GAIN",
           "NORMAL_GAIN", "MIN_SUPPORT", "MAX_ARC", "SMOOTH_NEIGHBORS", "corrected_rows",
           "CAP_VARIATION", "CAP_ARC", "ball_members", "ball_counts", "curvature_spread",
           "largest_curvature"]

# Ladder r_j = R0 * 2^(j / 2): from half the default ball's points (~50) to 8 times (~800;
# what position noise needs to draw level with estimators using normals, issue 15).
LADDER_EXPONENTS = (-1, 0, 1, 2, 3)
# Variance of (k1, k2) per sigma^2 / (r^4 N): mean ((dk1^2 + dk2^2) / 2) / mean(noise^2 /
# (r^4 N)) measured on unit icospheres (2562 and 10242 vertices, noise 0.1 % and 0.3 % of the
# diagonal, ~40-360 neighbors) lies between 4 and 14 (distance weights, at the lower noise, at
# the upper end); the middle of that range.
NOISE_GAIN = 8.0
# Variance of (k1, k2) per a2 / (r^2 N), a2 the given normals' noise variance: the mean
# squared error with noisy given normals less that with exact ones, over the same ratio,
# measured on the benchmark clouds (torus 10k and 25k, Goursat 25k; normal noise 0.1 and 0.2,
# clean points) at 0.7-1.4 times the default radius lies between 2.5 and 9.3; the middle.
NORMAL_GAIN = 6.0
# Fewest neighbors of an admissible ball: below, the circle fits' half-sets hold one or two
# points and the jet measuring the noise has none to spare.
MIN_SUPPORT = 20
# Largest max(|k1|, |k2|) r above the default radius, the curvature measured there: 1 rad of
# arc. 0.7 (the whole-input radius choice's bound) kept the noisy torus (tube radius 0.5,
# 240 x 60, noise 0.1 / 0.3 %) from its best ladder radius (1.4 R0 = 0.41: mean |dk| 0.0100 /
# 0.0162 there, 0.0150 / 0.0383 chosen under 0.7, 0.0107 / 0.0166 under 1.0); 1.4 let it take
# 2 R0 (0.018 / 0.021).
MAX_ARC = 1.0
# Estimated vertices whose error curves are averaged (the vertex itself included).
SMOOTH_NEIGHBORS = 16
# Spread of the curvature across a ball (:func:`curvature_spread`) above which a ball that is
# no small cap (max(|k1|, |k2|) r > CAP_ARC) is taken to lie on a surface whose curvature
# varies across it, where the circles fitted to its normal sections are biased (a circle fits
# a section of constant curvature over any arc). Measured at the default radius on rows whose
# ball is no small cap: median 0.002-0.026 on tori (trimesh's 32 x 32 to 96 x 24, MeshLab's
# decimations of a 240 x 60 torus, noise 0.1 % of the diagonal), 0.36-0.80 on ellipsoids
# (icospheres of 642 to 10242 vertices, random samplings, MeshLab's decimations, with and
# without noise). 0.2 lies between; 0.1 and 0.4 chose the same rows within 5 %.
CAP_VARIATION = 0.2
# Arc (max(|k1|, |k2|) r) above which such a ball is no small cap: on meshes 0.7 rad (the
# bound the whole-input radius choice had), on clouds 1 rad. Mean |dk| at the default radius,
# 1 -> 0.7 (measured with a script): meshes of clean ellipsoids 2 / 1.5 / 1 of 642 and 2562
# vertices 0.023 -> 0.013, 0.0029 -> 0.0018, 3 / 1 / 0.5 of 2562 and 10242 0.098 -> 0.096,
# 0.026 -> 0.016, MeshLab's 2 % decimation 0.053 -> 0.047, no mesh tried worse; clouds gain where
# coarse (the same ellipsoids' points 0.034 -> 0.030, 0.038 -> 0.030) and lose where finer
# (2562 points 0.0025 -> 0.0026, 5000 random 0.0050 -> 0.0054, the clean CNC cloud
# goursat_010000, mean |dH| 0.00064 -> 0.00091: smaller balls of a random sampling).
CAP_ARC = {"mesh": 0.7, "cloud": MAX_ARC}


def ladder(r0, exponents=LADDER_EXPONENTS):
    """The radii ``r0 * 2^(j / 2)`` for j in ``exponents``, model units, ascending."""
    return [float(r0) * 2.0 ** (j / 2.0) for j in sorted(exponents)]


def _stack(results, name):
    return np.stack([np.asarray(getattr(r, name), dtype=np.float64) for r in results])


def error_terms(results, radii, normal_var=0.0):
    """Per radius and row ((J, q) float64 each): the variance term V_j and the squared-bias
    term B_j of the module docstring (NaN where not estimated; B_j may be negative, the
    noise-corrected change being an unbiased but noisy estimate); ``normal_var``: a2, the
    given normals' noise variance (radians^2; 0 without)."""
    r = np.asarray(radii, dtype=np.float64)[:, None]
    k1, k2 = _stack(results, "k1"), _stack(results, "k2")
    n = np.maximum(_stack(results, "n_neighbors"), 1.0)
    sigma = _stack(results, "noise")
    with np.errstate(invalid="ignore", all="ignore"):
        # a row estimated without a noise measurement (fewer than 11 points): the largest
        # noise the vertex has at its other radii
        known = np.isfinite(sigma)
        typical = np.where(known.any(axis=0), np.nanmax(np.where(known, sigma, -np.inf),
                                                         axis=0), 0.0)
        sigma = np.where(known, sigma, typical)
        var = NOISE_GAIN * sigma ** 2 / (r ** 4 * n) + NORMAL_GAIN * normal_var / (r ** 2 * n)
        var = np.where(np.isfinite(k1), var, np.nan)
        d2 = 0.5 * ((k1[1:] - k1[:-1]) ** 2 + (k2[1:] - k2[:-1]) ** 2)
        noise_part = np.maximum(var[:-1] - var[1:], 0.0)
        # k(r_j) - k(r_j / sqrt 2) = a r_j^2 / 2: the bias a r_j^2 is twice the change from
        # the next smaller radius (measured against the change to the next larger one, which
        # has less noise but sees the larger ball's bias: each wins on some surfaces)
        bias = np.full_like(var, np.nan)
        bias[1:] = 4.0 * (d2 - noise_part)
        # the smallest radius (and one whose smaller neighbor has no estimate): from the next
        # larger pair, bias^2 ~ r^4
        for j in range(len(radii) - 2, -1, -1):
            take = ~np.isfinite(bias[j]) & np.isfinite(k1[j])
            bias[j] = np.where(take, bias[j + 1] * (r[j, 0] / r[j + 1, 0]) ** 4, bias[j])
        bias = np.where(np.isfinite(k1), np.nan_to_num(bias, nan=0.0), np.nan)
    return var, bias


def _smoothed(terms, points, k):
    """Each row of ``terms`` ((J, q)) averaged over the ``k`` nearest of ``points`` ((q, 3))
    with a finite value (NaN where none)."""
    finite = np.isfinite(points).all(axis=1)
    if k <= 1 or finite.sum() < 2:
        return terms
    idx = np.flatnonzero(finite)
    k = min(k, len(idx))
    # lengths whose squares overflow (underflow): on coordinates scaled by a power of two
    _, p = scaled_for_squares(points[idx])
    _, nb = cKDTree(p).query(p, k)
    missing = nb >= len(idx)      # neighbors at distances that still overflow (far points)
    nb = np.where(missing, np.arange(len(idx))[:, None], nb)
    out = terms.copy()
    for t_in, t_out in zip(terms, out):
        vals = np.where(missing, np.nan, t_in[idx][nb])
        with np.errstate(invalid="ignore"):
            cnt = np.isfinite(vals).sum(axis=1)
            mean = np.nansum(vals, axis=1) / np.maximum(cnt, 1)
        t_out[idx] = np.where(np.isfinite(t_in[idx]) & (cnt > 0), mean, np.nan)
    return out


def select(results, radii, points, fallback=0, smooth=SMOOTH_NEIGHBORS, normal_var=0.0):
    """Index into ``radii`` per row (q,) int64: the admissible radius of least estimated error
    (module docstring); where none is admissible the valid one of least error; where no
    radius has an estimate ``fallback``.

    ``results``: CurvatureResult per radius of ``radii`` (ascending), rows of ``points``
    ((q, 3), the query positions the averaging uses); ``fallback``: the index of the default
    radius, which is admissible wherever it is valid (the choice then never needs to be
    worse than the default), whose curvature bounds the larger radii (MAX_ARC) and whose
    outliers stay outliers (its row is taken); ``normal_var``: see :func:`error_terms`."""
    var, bias = error_terms(results, radii, normal_var)
    error = _smoothed(var, points, smooth) + np.maximum(_smoothed(bias, points, smooth), 0.0)
    valid = np.stack([np.asarray(r.valid, dtype=bool) for r in results])
    support = _stack(results, "n_neighbors") >= MIN_SUPPORT
    r = np.asarray(radii, dtype=np.float64)[:, None]
    with np.errstate(invalid="ignore"):
        kappa = np.fmax(np.abs(_stack(results, "k1")), np.abs(_stack(results, "k2")))
    # the curvature the ball must stay a small cap of: the default radius' (else the
    # smallest estimated radius')
    first = np.argmax(valid, axis=0)
    reference = np.where(valid[fallback], kappa[fallback], kappa[first, np.arange(valid.shape[1])])
    with np.errstate(invalid="ignore"):
        small_cap = ~(reference * r > MAX_ARC)
    larger = np.arange(len(radii))[:, None] > fallback
    admissible = valid & support & (small_cap | ~larger)
    admissible[fallback] = valid[fallback]
    # tiers: admissible, then valid, then none; within a tier the least error (mapped into
    # [0, 1], an unknown error last)
    tier = np.where(admissible, 0, np.where(valid, 1, 2))
    finite = np.isfinite(error)
    rank = np.where(finite, error / (1.0 + np.where(finite, error, 0.0)), 1.0)
    key = 2.0 * tier + np.where(tier < 2, rank, 0.0)
    choice = np.argmin(key, axis=0)
    status = results[fallback].status
    if status is not None:
        # the default radius' outliers (spikes) stay outliers: no other radius' row for them
        choice[np.asarray(status) == Status.OUTLIER] = fallback
    choice[~valid.any(axis=0)] = fallback
    return choice.astype(np.int64)


def assemble(results, choice, base=0, at=None):
    """One CurvatureResult whose row i is row ``at[i]`` (default i) of ``results[choice[i]]``,
    ``radius_used`` included (the chosen radius, or more where the sparse retry widened that
    row's ball; NaN where not valid) and ``mls_share`` (0 from a result where no blend ran;
    None where none ran); the other attributes (``radius``, ``orientation``) are those of
    ``results[base]``."""
    rows = np.arange(len(choice)) if at is None else np.asarray(at)
    first = results[base]
    out = replace(first)
    for name in ("k1", "k2", "d1", "d2", "normals", "valid", "n_neighbors", "n_samples",
                 "residual", "noise", "status", "outlier_score", "radius_used"):
        if getattr(first, name) is None:
            continue
        stacked = np.stack([np.asarray(getattr(r, name)) for r in results])
        setattr(out, name, stacked[choice, rows].copy())
    if any(r.mls_share is not None for r in results):
        out.mls_share = np.stack([mls_shares(r) for r in results])[choice, rows]
    return out


def _given_normal_variance(v, f, given_normals, r0, query, plan):
    """a2 of :func:`meshcurv.pipeline.given_normal_noise` at the default radius where the
    normals are used as given (0.0 otherwise: estimated or refined normals carry the
    positions' noise, which the jet measures, and ``refine_normals="auto"`` already mixes
    noisy given normals with fitted ones)."""
    if plan.normals != "given" or plan.refine or plan.check_given:
        return 0.0
    if plan.use_kring:
        search = pipeline.kring_search(v, f, r0)
    else:
        search = pipeline.ball_search(v, np.flatnonzero(np.isfinite(v).all(axis=1)), r0)
    return pipeline.given_normal_noise(v, given_normals, r0, search, query)


def corrected_rows(result, plan):
    """Rows (q,) bool of a fixed-radius ``result`` estimated where its measured noise leaves
    the bias correction at least :data:`meshcurv.pipeline.BIAS_HALF_GAIN` on (the noise below
    :data:`meshcurv.pipeline.BIAS_NOISE_SCALE` of the radius used; none with the correction
    off) and valid."""
    if not plan.bias_correction:
        return np.zeros(len(result.k1), dtype=bool)
    used = result.radius if result.radius_used is None else result.radius_used
    gain = pipeline.clean_fraction(result.noise, pipeline.BIAS_NOISE_SCALE * np.asarray(used))
    return np.asarray(result.valid, dtype=bool) & (gain >= pipeline.BIAS_HALF_GAIN)


def run_auto(v, f, given_normals, r0, query, plan, progress=False, radii=None,
             run_radii=pipeline.run_radii):
    """The per-vertex scale estimate around the default radius ``r0`` (model units): one
    :class:`meshcurv.CurvatureResult` (rows of ``query``) whose ``radius_used`` gives each
    row's radius and ``radius`` is ``r0``. ``radii``: the ladder (default :func:`ladder`,
    ascending, holding ``r0``); ``run_radii``: the estimate at a list of radii, with the
    signature of :func:`meshcurv.pipeline.run_radii`.

    The default radius runs first. Its rows whose bias correction is on
    (:func:`corrected_rows`) keep it: the correction extrapolates away the bias the ladder
    trades against noise, so the ladder's error model no longer describes them (clean torus
    240 x 60: mean |dk| 0.0009 chosen by the ladder, 0.0006 at the corrected default). Where
    every row is such, the ladder's other radii are not run at all."""
    radii = ladder(r0) if radii is None else list(radii)
    at_r0 = int(np.argmin(np.abs(np.asarray(radii) - r0)))
    # a part of the vertices is estimated with the neighbours its choice averages over, so
    # that each of its rows is the row a run over every vertex gives
    rows, at = _with_smoothing_neighbors(v, query, SMOOTH_NEIGHBORS)
    base = run_radii(v, f, given_normals, [radii[at_r0]], rows, plan, progress)[0]
    keep = corrected_rows(base, plan)
    if keep.all() or len(radii) == 1:
        return base if at is None else assemble([base], np.zeros(len(at), np.int64), at=at)
    others = run_radii(v, f, given_normals, radii[:at_r0] + radii[at_r0 + 1:], rows, plan,
                       progress)
    # each radius orients its own normals: where one faces the other way, its row is read with
    # the default radius' normal (a coarse cloud's smallest radius was oriented inward)
    others = [oriented_like(r, base.normals) for r in others]
    results = others[:at_r0] + [base] + others[at_r0:]
    everything = np.arange(len(v), dtype=np.int64)
    choice = select(results, radii, v[rows], fallback=at_r0,
                    normal_var=_given_normal_variance(v, f, given_normals, r0, everything,
                                                      plan))
    choice[keep] = at_r0
    # the default radius' own attributes: its radius and normal orientation note
    if at is not None:
        choice = choice[at]
    return assemble(results, choice, base=at_r0, at=at)


def _balls_about(points, centres, radius):
    """A k-d tree over the finite points of ``points`` (n, 3) that a ball of ``radius`` (model
    units, the largest asked for) about one of ``points[centres]`` can hold, on scaled
    coordinates: ``(query, near, about)``, ``query(r)`` the tree's lists (indices into
    ``near``) of the balls of radius r <= ``radius`` about ``points[centres[about]]`` (the
    centres with a finite position); None where there is no such centre. The coordinates are
    scaled by the power of two that keeps the radius's square finite, or less where the
    centres' bounding box widened by the radius would not be (centres 1e154 apart)."""
    s = power_of_two_scale(radius)
    with np.errstate(over="ignore", invalid="ignore"):
        p = points * s if s != 1.0 else points
        usable = np.isfinite(p).all(axis=1)
        about = np.flatnonzero(usable[centres])   # a centre that is no point has no ball
        if not len(about):
            return None
        reach = radius * s
        lo = p[centres[about]].min(axis=0) - reach
        hi = p[centres[about]].max(axis=0) + reach
        near = np.flatnonzero(usable & np.all((p >= lo) & (p <= hi), axis=1))
        half = float(np.max(0.5 * hi - 0.5 * lo))     # half the box's extent
        if not np.isfinite(half):
            return None
        if half > 2.0 ** 499:
            s_box = 2.0 ** (499 - math.ceil(math.log2(half)))
            p, s = p * s_box, s * s_box
    tree = cKDTree(p[near])
    at = p[centres[about]]
    return (lambda r, **kw: tree.query_ball_point(at, r * s, **kw)), near, about


def ball_members(points, centres, radius):
    """The finite points of ``points`` (n, 3) within ``radius`` (model units) of each of
    ``points[centres]``: (owner, members), flat int64 arrays, ``members[i]`` in the ball of
    ``centres[owner[i]]`` (owners ascending; none for a centre with no finite position).
    Searched at any scale of the coordinates (:func:`_balls_about`)."""
    found = _balls_about(points, centres, radius)
    if found is None:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    query, near, about = found
    lists = query(radius)
    counts = np.fromiter((len(a) for a in lists), dtype=np.int64, count=len(lists))
    owner = np.repeat(about.astype(np.int64), counts)
    members = np.concatenate(lists).astype(np.int64) if counts.sum() else owner
    return owner, near[members]


def ball_counts(points, centres, radii):
    """The number of finite points of ``points`` (n, 3) within each of ``radii`` (model
    units) of each of ``points[centres]``: (len(radii), c) int64, from one search structure
    (:func:`_balls_about`, at any scale of the coordinates); 0 for a centre with no finite
    position."""
    out = np.zeros((len(radii), len(centres)), dtype=np.int64)
    found = _balls_about(points, centres, max(radii)) if len(radii) else None
    if found is not None:
        query, _, about = found
        for row, r in zip(out, radii):
            row[about] = query(r, return_length=True)
    return out


def largest_curvature(result):
    """max(|k1|, |k2|) per row of a :class:`meshcurv.CurvatureResult`, 1/model units (NaN
    where it has no estimate)."""
    return np.fmax(np.abs(result.k1), np.abs(result.k2))


def curvature_spread(kappa, centres, owner, members):
    """The spread (c,) of the curvature ``kappa`` (n,), 1/model units, NaN where unknown, over
    the ball of each of the ``centres`` (c,) whose points are ``members`` where ``owner``
    holds its position in ``centres`` (:func:`ball_members`): the 90 % less the 10 % quantile
    (nearest rank) of its known values there, over the centre's own ``kappa``; NaN where the
    ball holds fewer than 4 known values."""
    values = kappa[members]
    known = np.isfinite(values)
    owner, values = owner[known], values[known]
    order = np.lexsort((values, owner))          # each ball's values, ascending
    values = values[order]
    held = np.bincount(owner, minlength=len(centres))
    start = np.concatenate([[0], np.cumsum(held)[:-1]]).astype(np.int64)
    enough = held >= 4
    last = held[enough] - 1

    def quantile(q):
        return values[start[enough] + np.round(q * last).astype(np.int64)]
    out = np.full(len(centres), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        out[enough] = (quantile(0.9) - quantile(0.1)) / kappa[centres[enough]]
    return out


def _with_smoothing_neighbors(v, query, k):
    """``(rows, at)``: the vertices ``rows`` (ascending) to estimate for the rows ``query`` of
    ``v`` - the query and the ``k`` nearest finite vertices of each (whose error terms
    :func:`select` averages) - and where each query row is in ``rows``; ``(query, None)``
    where the query is every vertex in order."""
    n = len(v)
    if len(query) == n and np.array_equal(query, np.arange(n)):
        return query, None
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    wanted = query[np.isfinite(v[query]).all(axis=1)]
    if len(finite) < 2 or len(wanted) == 0:
        rows = np.unique(query)
        return rows, np.searchsorted(rows, query)
    # as :func:`_smoothed` measures the distances: squares that would overflow, scaled
    _, p, q = scaled_for_squares(v[finite], v[wanted])
    _, nb = cKDTree(p).query(q, min(k, len(finite)))
    nb = np.asarray(nb).reshape(len(wanted), -1)
    near = finite[nb[nb < len(finite)]]
    rows = np.unique(np.concatenate([query, near]))
    return rows, np.searchsorted(rows, query)
