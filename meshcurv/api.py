"""The estimator's public entry points: :func:`principal_curvatures` and
:func:`estimate_normals`. Input checks, the radius policy (default, "auto" = per-vertex scale,
power-of-two rescaling of extreme scales) and options; the work itself is
:func:`meshcurv.pipeline.run` (:mod:`meshcurv.scale` for "auto"), blended with the MLS surface's
curvature by :mod:`meshcurv.coarse` where the input is coarse for its shape or its circle fits
are limited by its sampling.
"""

import math

import numpy as np

from . import coarse as coarse_mls, jet_blend, pipeline, scale as scale_select, weld
from .inputs import as_arrays
from .neighbors import default_radius, power_of_two_scale
from .neighbors.radius import local_radii
from .options import Options, resolve_plan
from .result import Status
from .weld import expand_rows

__all__ = ["principal_curvatures", "estimate_normals", "no_estimate_reason"]


# Radii, as multiples of the call's, at which the rows whose ball reached around the surface
# are estimated again (:func:`_smaller_balls`), each at the largest that serves: down to a
# sixteenth, a tube or sphere 16 times narrower than the call's ball.
WRAP_FACTORS = (0.5, 0.25, 0.125, 0.0625)
# Share of the points of a ball twice as wide above which a ball is not tried there: it holds
# a whole part narrower than itself (a surface patch keeps about a quarter when the radius
# halves, a tube's segment half).
WHOLE_PART = 0.75
# Halvings of the radius (each by sqrt 2) a row on a ball that is no small cap of a surface of
# varying curvature may take (:func:`_varying_caps`): down to a quarter of the radius.
CAP_STEPS = 4


def _check_query(query, n):
    """(q,) int64 vertex indices to estimate at (all n by default), checked to lie in range."""
    if query is None:
        return np.arange(n, dtype=np.int64)
    given = np.asarray(query)
    if given.dtype == bool:
        # a mask of the rows to estimate, as numpy indexing reads it
        if given.shape != (n,):
            raise ValueError(f"a boolean query must be a mask of shape ({n},), got {given.shape}")
        return np.flatnonzero(given)
    if given.size and not np.issubdtype(given.dtype, np.integer):
        whole = np.issubdtype(given.dtype, np.number) and np.all(np.mod(given, 1) == 0)
        if not whole:
            raise ValueError(f"query must hold vertex indices (integers) or a boolean mask, "
                             f"got {given.dtype} values")
    query = given.astype(np.int64).ravel()
    if query.size and (query.min() < 0 or query.max() >= n):
        raise ValueError(f"query indices must lie in 0..{n - 1}")
    return query


def _check_radius(radius):
    """A positive finite float radius, else ValueError."""
    try:
        radius = float(radius)
    except (TypeError, ValueError):
        raise ValueError(f"radius must be a positive finite number of model units, got "
                         f"{radius!r}") from None
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive finite number of model units, got {radius}")
    return radius


def estimate_normals(points, radius, progress=False):
    """Unit normals of a point cloud, consistently oriented: what :func:`principal_curvatures`
    uses when it gets neither normals nor faces.

    A PCA plane fit over the ball of ``radius`` around each point, then signs propagated along
    a minimum spanning tree (Hoppe et al. 1992) and one sign per connected piece: outward if it
    is closed, towards +z if it is open (see :func:`meshcurv.normals.orient.piece_signs`). For a subset whose balls lie inside ``points`` (a
    tile and its halo), the normals of the subset equal those of the whole cloud up to sign.

    Parameters
    ----------
    points : (n, 3) float, model units (NaN rows get NaN normals and are nobody's neighbor)
    radius : float, model units
    progress : bool, show a progress bar

    Returns
    -------
    (n, 3) float64 unit normals; NaN where the ball holds fewer than 3 points.

    Example
    -------
    >>> import numpy as np, meshcurv
    >>> s = meshcurv.surfaces.sphere(subdivisions=3)
    >>> nv = meshcurv.estimate_normals(s.vertices, radius=0.3)
    >>> bool(np.all(np.einsum("ij,ij->i", nv, s.normals) > 0.99))
    True
    """
    v = np.ascontiguousarray(points, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {v.shape}")
    radius = _check_radius(radius)
    s = power_of_two_scale(radius)
    if s != 1.0:
        # lengths whose squares overflow (underflow) in float64: on exactly rescaled points
        with np.errstate(over="ignore"):
            return estimate_normals(v * s, radius * s, progress)
    return pipeline.estimate_normals(v, radius, progress)


def _no_default_radius(points):
    """Why no default radius can be derived from the finite ``points`` (2 or more)."""
    if np.all(points == points[0]):
        return (f"all {len(points)} points coincide: there is no surface and no radius can be "
                "derived from their spacing; pass a radius to get all-invalid rows")
    with np.errstate(over="ignore", invalid="ignore"):
        spread = np.ptp(points, axis=0)
    why = ("their distances are too large to square in float64"
           if not np.all(np.isfinite(spread)) or spread.max() > 1e150 else
           "most of them coincide")
    return (f"no radius can be derived from the spacing of these {len(points)} points ({why}; "
            f"extent {np.array2string(spread, precision=3)}); pass a radius in model units")


def no_estimate_reason(result, n_points, option="radius"):
    """Why a :class:`CurvatureResult` with no valid row got none, and what to try: one line.

    ``n_points`` is the number of finite input points; ``option`` names the radius as the
    caller's user knows it (e.g. "--radius"). Balls holding nearly every point mean a radius
    far too large (fits see a whole object, no surface patch); balls with few neighbors one
    too small; given normals that are mostly NaN or off the surface, normals to estimate.
    """
    nn = np.asarray(result.n_neighbors)
    med = float(np.median(nn)) if len(nn) else 0.0
    given = str(result.orientation).startswith("as given")
    if given and len(nn) and np.mean(np.asarray(result.status) == Status.NO_NORMAL) > 0.5:
        return ("most given normals are unusable (zero, NaN, or more than 60 degrees off the "
                "plane fit of their neighbourhood: wrong, or from another frame?); have them "
                "estimated instead (normals=None; on the command line --normals estimate)")
    if n_points > 2 and med >= 0.5 * (n_points - 1):
        return (f"the radius {result.radius:.6g} is far too large: each ball holds nearly every "
                f"point (median {med:.0f} of {n_points}); try a much smaller {option}")
    if med < 12:
        return (f"the radius {result.radius:.6g} is too small: its balls hold a median of "
                f"{med:.0f} neighbors; try a larger {option}")
    return (f"no neighborhood of radius {result.radius:.6g} (median {med:.0f} neighbors) spans "
            f"a surface patch in enough directions (points along lines or curves, one-sided "
            f"or coincident); try another {option}")


def _resolve_radius(radius, v, f, details=False):
    """The radius in model units: given, or the default from the sampling (None); with
    ``details``, ``(radius, coarse)``: whether the default was made smaller for an input
    coarse for its shape (:func:`meshcurv.neighbors.default_radius`)."""
    finite_rows = np.isfinite(v).all(axis=1)
    n_finite = int(finite_rows.sum())
    coarse = False
    if radius is None:
        radius, coarse = default_radius(v, faces=f, details=True)
        if n_finite > 1 and not (np.isfinite(radius) and radius > 0):
            raise ValueError(_no_default_radius(v[finite_rows]))
    elif isinstance(radius, str):
        raise ValueError(f"radius must be a number of model units, None or 'auto', "
                         f"got {radius!r}")
    radius = float(radius)
    if n_finite > 1:
        _check_radius(radius)
    return (radius, bool(coarse)) if details else radius


def _auto_ladder(v, f, r0):
    """The radii of the per-vertex scale around the default ``r0``
    (:func:`meshcurv.scale.ladder`), without the larger ones whose balls would not stay local
    (:func:`meshcurv.neighbors.radius.local_radii`: more than ``MAX_BALL_FRACTION`` of the
    points, or beyond a patch of the surface); ``r0`` and the smaller ones always stay."""
    ladder = scale_select.ladder(r0)
    return [r for r in ladder if r < r0] + local_radii(v, [r for r in ladder if r >= r0], f)


def _run_rescaled(v, f, given_normals, radius, query, plan, progress, scale):
    """:func:`meshcurv.pipeline.run` on coordinates scaled by the power of two ``scale``
    (exact), for radii whose squares overflow (underflow) in float64; results scaled back."""
    if plan.viewpoint is not None:
        plan = plan._replace(viewpoint=plan.viewpoint * scale)
    with np.errstate(over="ignore"):
        res = pipeline.run(v * scale, f, given_normals, radius * scale, query, plan, progress)
        for name in ("k1", "k2", "residual"):
            setattr(res, name, getattr(res, name) * scale)
        res.noise = res.noise / scale
        res.radius_used = res.radius_used / scale
    # curvatures of a subnormal-sized cloud may exceed float64: no estimate there
    lost = res.valid & ~(np.isfinite(res.k1) & np.isfinite(res.k2))
    for name in ("k1", "k2", "d1", "d2", "residual", "radius_used"):
        getattr(res, name)[lost] = np.nan
    res.valid &= ~lost
    res.status[lost] = Status.OUT_OF_RANGE
    res.radius = radius
    return res


def principal_curvatures(vertices, faces=None, normals=None, radius=None, n_directions=8,
                         neighborhood="auto", *, options=None, query=None, progress=False,
                         **switches):
    """Principal curvatures by CGA circle fits in normal sections (Seibert et al.).

    At every vertex x: the neighbors within ``radius`` are split by ``n_directions`` planes
    through the normal into ``2 * n_directions`` half-sets; a circle centred on the normal line
    is fitted to each (a 3x3 eigenproblem in conformal geometric algebra); the Euler model
    ``kappa(theta) = A + B cos 2theta + C sin 2theta`` fitted to those curvatures gives k1, k2
    and their directions.

    Parameters
    ----------
    vertices : (n, 3) float, trimesh.Trimesh or trimesh.PointCloud
        Points, model units. Never reordered; NaN/inf rows give NaN results.
    faces : (m, 3) int, optional
        Triangles, counter-clockwise seen from outside ((m, 4) quads are split in two
        triangles each, as trimesh splits them). Enables the k-ring neighborhood and
        face-based normal orientation. Vertices with exactly equal coordinates (a triangle
        soup, a mesh split along texture seams) are joined for the neighborhoods and share
        one estimate (:mod:`meshcurv.weld`); every copy keeps its row. Faces wound against
        their neighbours, and closed pieces wound inward, are taken turned, and a triangle
        listed more than once (a double-sided export) counts once
        (:mod:`meshcurv.normals.winding`; the result's ``orientation`` says how many).
    normals : (n, 3) float, optional
        Outward normals, used as given (normalised). Default: estimated, see
        ``Options.normal_estimation``.
    radius : float, "auto" or list of floats, optional
        Neighborhood radius, model units. Default: the radius whose ball holds about 100
        points (:func:`meshcurv.neighbors.default_radius`; ~5 mean edge lengths).
        A list ``[r1, r2, ...]`` estimates at every radius (multi-scale curvature) and returns
        a list of results in that order; ball neighborhoods then come from one search over
        the largest radius.
        "auto": per-vertex scale (:mod:`meshcurv.scale`): each vertex takes the radius of a
        ladder around the default radius (0.7 to 2.8 times it) that minimises its estimated
        error, noise variance (measured from the local fit's residuals) plus bias (measured
        from the change across radii), with at least 20 neighbors and the ball a small cap
        of the curvature. ``result.radius_used`` gives each row's radius, ``result.radius``
        the default radius the ladder is built on. Rows where the data are clean enough for
        the bias correction keep the default radius; where every row is such, the result is
        the default's at its cost, else the ladder costs 10-17 times one radius. Inputs
        coarse for their shape (the default radius made smaller so that its balls stay on a
        local patch) keep the default radius.
    n_directions : int, default 8
        Planes through the normal, i.e. ``2 * n_directions`` circle fits per vertex.
    neighborhood : {"auto", "kring", "ball"}
        "kring": vertices reachable over mesh edges without leaving the ball (needs faces;
        never leaks across thin sheets). "ball": all points within ``radius``. "auto": kring
        when faces are given, else ball.
    options : Options, optional
        The estimator's research switches (slab, weights, normalisation, robust refit,
        normal estimation and refinement, orientation of cloud normals), documented in
        :class:`meshcurv.Options`; default ``Options()``.
    **switches
        Any field of :class:`meshcurv.Options` by name, overriding ``options`` (e.g.
        ``weighting="none"``, ``orientation=(0, 0, 100)``).
    query : (q,) int, optional
        Estimate only at these vertex indices (neighbors still come from all vertices); the
        result then has q rows in this order.
    progress : bool, default False
        Show a progress bar.

    Returns
    -------
    CurvatureResult (a list of them for a list of radii)
        ``k1, k2, d1, d2, normals, valid, status, mean, gaussian, shape_index, curvedness``, the
        diagnostics ``n_neighbors, n_samples, residual, noise`` (one row per vertex, or per
        query), the ``radius`` used, each row's ``radius_used`` and, where the MLS blend of
        :mod:`meshcurv.coarse` ran, each row's ``mls_share``; where the ring jets' blend of
        :mod:`meshcurv.jet_blend` ran (a radius meshcurv chose), each row's ``jet_share``.

    Raises
    ------
    ValueError
        Wrong shapes, face indices out of range, unknown option values.

    Examples
    --------
    >>> import meshcurv, numpy as np, trimesh
    >>> sphere = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    >>> res = meshcurv.principal_curvatures(sphere, radius=0.4)
    >>> bool(abs(np.nanmedian(res.k1) - 0.5) < 1e-3)
    True
    """
    v, f, given_normals = as_arrays(vertices, faces, normals)
    settings = dict(n_directions=n_directions, neighborhood=neighborhood,
                    **Options.merged(options, switches).as_dict())
    plan = resolve_plan(f is not None, given_normals is not None, **settings)
    query = _check_query(query, len(v))
    welding = weld.coincident_vertices(v) if f is not None else None
    if welding is None:
        return _estimate(v, f, given_normals, radius, query, plan, progress)
    # copies of one position (triangle soups, split seams): estimated once, on the mesh they
    # make together, and each copy gets that row
    rows, where = weld.welded_queries(query, welding)
    vw, fw, nw = weld.welded_mesh(v, f, given_normals, welding)
    return weld.expand_rows(_estimate(vw, fw, nw, radius, rows, plan, progress), where)


def _estimate(v, f, given_normals, radius, query, plan, progress):
    """The curvature at the vertex indices ``query`` for a radius, a list of radii or
    "auto" (see :func:`principal_curvatures`), on inputs already checked."""
    if _is_radius_list(radius):
        radii = _check_radii(radius)
        if plan.coarse_mls:
            return _blended(v, f, given_normals, radii, query, plan, progress, coarse=False)
        return _run_radii(v, f, given_normals, radii, query, plan, progress)
    auto = isinstance(radius, str) and radius == "auto"
    chosen = auto or radius is None        # meshcurv chooses the radius
    radius, coarse = _resolve_radius(None if auto else radius, v, f, details=True)
    # inputs coarse for their shape keep the default radius under "auto": it was made smaller
    # so that its balls stay on a local patch, and its per-vertex scale lost to it on half of
    # the coarse tori (trimesh's 1 / 0.2, 32 x 32, as a cloud: mean |dk| 0.018 -> 0.38)
    if auto and not coarse:
        r0 = radius
        radii = _auto_ladder(v, f, r0) if np.isfinite(r0) else [r0]

        def per_vertex_scale(rows):
            # the ladder widens the balls where the noise asks for it: the normal field stays
            # at each radius (see Plan.wide_field)
            return [scale_select.run_auto(v, f, given_normals, r0, rows,
                                          plan._replace(wide_field=False), progress,
                                          radii=radii, run_radii=_run_radii)]

        def estimate(rows):
            if plan.coarse_mls and np.isfinite(r0):
                # the probe judges the default radius's fits: "auto" blends where the default
                # does
                def default_radius(near):
                    return _run_radii(v, f, given_normals, [r0], near, plan, progress)
                return coarse_mls.estimate(v, f, [r0], rows, per_vertex_scale, plan.use_kring,
                                           coarse, probe_fits=default_radius,
                                           area_weights=plan.area_weights)[0]
            return per_vertex_scale(rows)[0]
    else:
        def estimate(rows):
            return _at_radius(v, f, given_normals, radius, rows, plan, progress, coarse)
    res = estimate(query)
    if chosen and np.isfinite(radius):
        res = _varying_caps(res, v, f, given_normals, query, plan, progress, estimate)
    # rows whose balls reached around the surface (at every scale of the ladder: "auto")
    res = _smaller_balls(res, v, f, given_normals, query, plan, progress)
    if chosen and plan.ring_jet:
        res = jet_blend.blend(res, v, f if plan.use_kring else None, query)
    return res


def _varying_caps(res, v, f, given_normals, query, plan, progress, estimate):
    """``res`` (rows ``query`` of ``estimate(rows)``, the default radius's or "auto"'s, whose
    ``radius`` is the default radius, model units) with its rows at that radius estimated in
    smaller balls where the ball is no small cap of a surface whose curvature varies across
    it, so that the circles fitted to its normal sections are biased: ``max(|k1|, |k2|) r``
    above :data:`meshcurv.scale.CAP_ARC` (r the row's radius, at most the default) and the
    curvature's spread over the default radius's ball
    (:func:`meshcurv.scale.curvature_spread`, from the rows of ``estimate``, which gives those
    of other vertices where ``query`` leaves them out) above
    :data:`meshcurv.scale.CAP_VARIATION`. Each such row is estimated again at 2^(-j/2) times
    its radius, j = 1, 2, ... :data:`CAP_STEPS`, as a call at that radius gives it, and takes
    that row while it has :data:`meshcurv.scale.MIN_SUPPORT` neighbors and its quartic's
    residual (``noise``) fell below :data:`meshcurv.pipeline.SHAPE_RESIDUAL_DROP` of the row
    it replaces (the shape's residual falls like r^5, noise stays: noisy rows keep their ball,
    where a smaller one gains less bias than it adds noise); it goes on while its ball is still
    no small cap. ``radius_used`` says which radius each row took.

    Clean ellipsoid meshes 2 / 1.5 / 1 (icosphere of 642 vertices), 3 / 1 / 0.5 (10242) and
    MeshLab's 2 % decimation of one: mean |dk| 0.059, 0.094, 0.073 -> 0.013, 0.016, 0.047
    (``--accuracy-cases ellipsoids`` and ``decimated``); tori, whose sections' curvature is
    constant, keep their rows."""
    arc = scale_select.CAP_ARC["mesh" if f is not None else "cloud"]
    used = np.full(len(res), res.radius) if res.radius_used is None else res.radius_used
    with np.errstate(invalid="ignore"):
        kappa = scale_select.largest_curvature(res)
        rows = np.flatnonzero((res.status == Status.OK) & (used <= res.radius)
                              & (kappa * used > arc))
    if not len(rows):
        return res
    field = np.full(len(v), np.nan)
    field[query] = np.where(res.status == Status.OK, kappa, np.nan)
    owner, members = scale_select.ball_members(v, query[rows], res.radius)
    others = np.setdiff1d(members, query)
    if len(others):
        # the field at the balls' other vertices, as a call over every vertex gives it
        more = estimate(others)
        with np.errstate(invalid="ignore"):
            field[others] = np.where(more.status == Status.OK,
                                     scale_select.largest_curvature(more), np.nan)
    spread = scale_select.curvature_spread(field, query[rows], owner, members)
    rows = rows[spread > scale_select.CAP_VARIATION]
    now, noise = used[rows], res.noise[rows]
    for _ in range(CAP_STEPS):
        going = np.zeros(len(rows), dtype=bool)
        for r in np.unique(now):                 # one radius ("auto": each of its ladder's)
            part = np.flatnonzero(now == r)
            smaller = r / math.sqrt(2.0)
            sub = _at_radius(v, f, given_normals, smaller, query[rows[part]], plan, progress,
                             False)
            with np.errstate(invalid="ignore"):
                took = ((sub.status == Status.OK)
                        & (sub.n_neighbors >= scale_select.MIN_SUPPORT)
                        & (sub.noise < pipeline.SHAPE_RESIDUAL_DROP * noise[part]))
                wide = scale_select.largest_curvature(sub) * smaller > arc
            res = _with_rows(res, sub, rows[part], took)
            going[part] = took & wide
            now[part[took]], noise[part[took]] = smaller, sub.noise[took]
        rows, now, noise = rows[going], now[going], noise[going]
        if not len(rows):
            break
    return res


def _with_rows(res, sub, rows, took):
    """``res`` with its rows ``rows`` replaced by those of ``sub`` (one per entry of ``rows``,
    in that order) where ``took``."""
    at = np.zeros(len(res), dtype=np.int64)
    at[rows] = np.arange(len(sub))
    choice = np.zeros(len(res), dtype=np.int64)
    choice[rows[took]] = 1
    return scale_select.assemble([res, expand_rows(sub, at)], choice)


def _at_radius(v, f, given_normals, radius, query, plan, progress, coarse):
    """The curvature at the vertex indices ``query`` at one resolved ``radius``: the circle
    fits, blended with the MLS curvature where :func:`_blended` says."""
    if plan.coarse_mls and np.isfinite(radius):
        return _blended(v, f, given_normals, [radius], query, plan, progress, coarse)[0]
    return _run_one(v, f, given_normals, radius, query, plan, progress)


def _smaller_balls(res, v, f, given_normals, query, plan, progress):
    """``res`` with its rows whose ball reached around the surface (``Status.WRAPS_AROUND``:
    a part far narrower than the rest, such as a small object beside a large one in one mesh)
    estimated again at :data:`WRAP_FACTORS` times the radius, each at the largest where the
    estimate succeeds, as a call at that radius gives it (``radius_used`` says which; noise
    weighs more there, as it would in that call); the others keep their status.

    Only with ``sparse_retry``, and where the folding test reads normals not estimated over
    the balls (a mesh's faces', or normals given and used as they are): a cloud's plane fits
    leave only the balls' shape test (:func:`meshcurv.fit.wrap.beyond_a_cap`), which still
    passes some balls about 2.8 times wider than a tube (9 % of a pole's rows), so there a
    smaller ball could serve a wrong estimate as valid."""
    rows = np.flatnonzero(res.status == Status.WRAPS_AROUND)
    if (not len(rows) or not plan.sparse_retry
            or pipeline.side_normals_estimated(plan, f is not None)):
        return res
    # the balls' points at the radius and at each smaller one, counted at once
    counts = scale_select.ball_counts(v, query[rows],
                                      [res.radius * x for x in (1.0,) + WRAP_FACTORS])
    held, left = counts[0], np.arange(len(rows))     # left: the rows' columns of counts
    for factor, at_factor in zip(WRAP_FACTORS, counts[1:]):
        r = res.radius * factor
        now = at_factor[left]
        # a ball that kept WHOLE_PART of the points of one twice as wide holds a whole part
        # (a surface's ball keeps a quarter, a tube's half) and would reach around it too
        tried = now <= WHOLE_PART * held
        if tried.any():
            sub = _at_radius(v, f, given_normals, r, query[rows[tried]], plan, progress, False)
            done = np.zeros(len(rows), dtype=bool)
            done[tried] = sub.status == Status.OK
            res = _with_rows(res, sub, rows[tried], done[tried])
            rows, now, left = rows[~done], now[~done], left[~done]
        held = now
        if not len(rows):
            break
    return res


def _blended(v, f, given_normals, radii, query, plan, progress, coarse):
    """The circle fits at each of ``radii`` (:func:`_run_radii`), blended with the MLS
    curvature of the same vertices where the input is ``coarse`` for its shape (at its
    default radius) or the circle fits are limited by its sampling
    (:func:`meshcurv.coarse.estimate`); a list of results."""
    def circle_fits(rows):
        return _run_radii(v, f, given_normals, radii, rows, plan, progress)
    return coarse_mls.estimate(v, f, radii, query, circle_fits, plan.use_kring, coarse,
                               area_weights=plan.area_weights)


def _run_radii(v, f, given_normals, radii, query, plan, progress):
    """:func:`meshcurv.pipeline.run_radii`, or one rescaled run per radius where a square
    would overflow."""
    if all(power_of_two_scale(r) == 1.0 for r in radii):
        return pipeline.run_radii(v, f, given_normals, radii, query, plan, progress)
    return [_run_one(v, f, given_normals, r, query, plan, progress) for r in radii]


def _run_one(v, f, given_normals, radius, query, plan, progress):
    """:func:`meshcurv.pipeline.run` at one radius, rescaled where its square would overflow."""
    scale = power_of_two_scale(radius)
    if scale != 1.0:
        return _run_rescaled(v, f, given_normals, radius, query, plan, progress, scale)
    return pipeline.run(v, f, given_normals, radius, query, plan, progress)


def _is_radius_list(radius):
    """Whether ``radius`` is a sequence of radii (list, tuple or 1-d array)."""
    return isinstance(radius, (list, tuple)) or (isinstance(radius, np.ndarray) and radius.ndim)


def _check_radii(radii):
    """A non-empty list of positive finite float radii, else ValueError (one line)."""
    try:
        radii = [float(r) for r in radii]
    except (TypeError, ValueError):
        raise ValueError(f"radius must be a number, None, 'auto' or a list of numbers, "
                         f"got {radii!r}") from None
    if not radii:
        raise ValueError("radius must not be an empty list")
    return [_check_radius(r) for r in radii]
