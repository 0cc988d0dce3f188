"""MLS curvature: the principal curvatures of the moving-least-squares surface of oriented
algebraic spheres (APSS, Guennebaud & Gross 2007) through points with normals, as one compiled
kernel over query points with CSR neighbor lists (:func:`mls_curvature`).

About each evaluation point y a sphere (or plane) ``u0 + u . z + u4 |z|^2`` is fitted to the
neighbors' positions and unit normals with the weights ``(1 - |p - y|^2 / h^2)^4`` (h the
support), in closed form; its value at y is the potential F(y), whose zero set is the surface.
Its gradient and Hessian, by central differences over 13 evaluations at steps of
``STEP * h`` about a point (the mixed second derivatives from the diagonal steps
``+-(e_i + e_j)`` and the axis steps), give the normal and the shape operator
``P Hess(F) P / |grad F|`` (P the tangent projector). Because the fit follows the evaluation
point, F is a smooth surface of second order even where a single sphere could not describe
the shape (a torus's saddle) and where a neighborhood holds few points per direction (a
low-poly torus: 16 vertices around the tube), where the circle fits in normal sections of
:mod:`meshcurv.fit.fused` are far less accurate. It needs normals and is more sensitive to
position noise than the circle fits; :mod:`meshcurv.coarse` says where it is used.

:func:`mls_normals` gives the normal alone from the gradient's 6 evaluations (the MLS passes
that only feed normals to the next one).

Numpy specification: :func:`meshcurv.fit.mls_spec.mls_curvature_at` and
:func:`~meshcurv.fit.mls_spec.mls_normal_at`.
"""

import math

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK

__all__ = ["mls_curvature", "mls_normals", "STEP"]

# Central-difference step, a fraction of the support h: F is smooth on the scale h, so the
# truncation error is ~STEP^2 relative, and its values near the surface are ~|grad F| times
# the step, so the rounding error of the second differences is ~1e-16 / STEP^2 relative; 1e-4
# balances the two at ~1e-8 (a coarse torus rotated or scaled by 1e-3 moves k by 4e-8 of
# itself; 5e-7 with 1e-3, mostly the truncation's dependence on the axes).
STEP = 1e-4


@njit(cache=True)
def _longest(indptr):
    """The length of the longest of the CSR lists ``indptr``."""
    most = 0
    for q in range(len(indptr) - 1):
        most = max(most, indptr[q + 1] - indptr[q])
    return most


@njit(cache=True)
def _gather(points, normals, point_weights, nbr, lo, hi, own, x, reach2, pts, nrm, pw):
    """The points ``own`` (a row of ``points``, or -1 for none) and ``nbr[lo:hi]`` (entries
    equal to ``own`` skipped), in that order, that can weigh in a fit about x: within
    ``sqrt(reach2)`` of it, with a finite normal and a positive point weight: their offsets
    from x to ``pts``, normals to ``nrm`` and weights to ``pw`` (1 without
    ``point_weights``). Returns their count. The fits about x then work in these local
    coordinates: a stencil step added to x itself would be rounded to x's precision (a scan
    in UTM coordinates, x ~ 5e6: 1e-9, 4e-5 of a step of 1e-4 of a support of 0.25)."""
    k = 0
    for e in range(lo - 1, hi):
        if e < lo:
            j = own
            if j < 0:
                continue
        else:
            j = nbr[e]
            if j == own:
                continue
        q0 = points[j, 0] - x[0]
        q1 = points[j, 1] - x[1]
        q2 = points[j, 2] - x[2]
        if not q0 * q0 + q1 * q1 + q2 * q2 < reach2:
            continue
        if not np.isfinite(normals[j, 0] + normals[j, 1] + normals[j, 2]):
            continue
        weight = 1.0 if point_weights is None else point_weights[j]
        if not weight > 0.0:
            continue
        pts[k, 0] = q0
        pts[k, 1] = q1
        pts[k, 2] = q2
        for a in range(3):
            nrm[k, a] = normals[j, a]
        pw[k] = weight
        k += 1
    return k


@njit(cache=True)
def _potential(pts, nrm, pw, k, weighted, x0, x1, x2, h2):
    """F at (x0, x1, x2): the oriented sphere fitted to the ``k`` points ``pts`` with normals
    ``nrm`` (times the point weights ``pw`` where ``weighted``), NaN where the weights vanish
    or the fit is singular."""
    sw = sp0 = sp1 = sp2 = sn0 = sn1 = sn2 = sa = sb = 0.0
    for e in range(k):
        q0 = pts[e, 0] - x0
        q1 = pts[e, 1] - x1
        q2 = pts[e, 2] - x2
        qq = q0 * q0 + q1 * q1 + q2 * q2
        r = 1.0 - qq / h2
        if not r > 0.0:
            continue
        n0 = nrm[e, 0]
        n1 = nrm[e, 1]
        n2 = nrm[e, 2]
        w = r * r
        w = w * w
        if weighted:
            w *= pw[e]
            if not w > 0.0:
                continue
        sw += w
        sp0 += w * q0
        sp1 += w * q1
        sp2 += w * q2
        sn0 += w * n0
        sn1 += w * n1
        sn2 += w * n2
        sa += w * (q0 * n0 + q1 * n1 + q2 * n2)
        sb += w * qq
    pp = sp0 * sp0 + sp1 * sp1 + sp2 * sp2
    den = sb * sw - pp
    if not (sw > 0.0 and den > 0.0):
        return np.nan
    u4 = 0.5 * (sa * sw - (sp0 * sn0 + sp1 * sn1 + sp2 * sn2)) / den
    u0 = (sn0 - 2.0 * u4 * sp0) / sw
    u1 = (sn1 - 2.0 * u4 * sp1) / sw
    u2 = (sn2 - 2.0 * u4 * sp2) / sw
    return -(u0 * sp0 + u1 * sp1 + u2 * sp2 + u4 * sb) / sw


@njit(cache=True)
def _gradient(pts, nrm, pw, k, weighted, x, h, g, ends):
    """``g[:]`` = grad F at x by central differences over the axis steps ``+-STEP h e_i``,
    whose values are left in ``ends`` (2, 3) (ahead, behind) for the Hessian's diagonal; F of
    :func:`_potential` over the ``k`` points of :func:`_gather`."""
    h2 = h * h
    s = STEP * h
    x0, x1, x2 = x[0], x[1], x[2]
    for i in range(3):
        e0 = s if i == 0 else 0.0
        e1 = s if i == 1 else 0.0
        e2 = s if i == 2 else 0.0
        ends[0, i] = _potential(pts, nrm, pw, k, weighted, x0 + e0, x1 + e1, x2 + e2, h2)
        ends[1, i] = _potential(pts, nrm, pw, k, weighted, x0 - e0, x1 - e1, x2 - e2, h2)
        g[i] = (ends[0, i] - ends[1, i]) / (2.0 * s)


@njit(cache=True)
def _unit_normal(g, nq, out):
    """``out[8:11]`` = the unit gradient ``g`` turned to ``nq``'s side; returns the factor
    that made it (sign / |g|), 0.0 (``out`` untouched) where |g| is 0 or not finite."""
    length = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
    if not (np.isfinite(length) and length > 0.0):
        return 0.0
    sign = 1.0 if g[0] * nq[0] + g[1] * nq[1] + g[2] * nq[2] >= 0.0 else -1.0
    scale = sign / length
    for a in range(3):
        out[8 + a] = g[a] * scale
    return scale


@njit(cache=True)
def _curvature_one(pts, nrm, pw, k, weighted, x, nq, h, hess, g, ends, out):
    """``out[:]`` = (k1, k2, d1 (3), d2 (3), n (3)) at x from the ``k`` points of
    :func:`_gather` (see :func:`mls_curvature`); False (``out`` untouched) where F or its
    derivatives are undefined. ``hess`` (3, 3), ``g`` (3,) and ``ends`` (2, 3) are
    scratch."""
    h2 = h * h
    s = STEP * h
    x0, x1, x2 = x[0], x[1], x[2]
    _gradient(pts, nrm, pw, k, weighted, x, h, g, ends)
    f0 = _potential(pts, nrm, pw, k, weighted, x0, x1, x2, h2)
    for i in range(3):
        hess[i, i] = (ends[0, i] - 2.0 * f0 + ends[1, i]) / (s * s)
    for i in range(3):
        for j in range(i + 1, 3):
            # F at x +- (s e_i + s e_j) against the axis steps' (never the same axis: j > i)
            y0 = s if i == 0 else 0.0
            y1 = s if (i == 1 or j == 1) else 0.0
            y2 = s if j == 2 else 0.0
            both = (_potential(pts, nrm, pw, k, weighted, x0 + y0, x1 + y1, x2 + y2, h2)
                    + _potential(pts, nrm, pw, k, weighted, x0 - y0, x1 - y1, x2 - y2, h2))
            hess[i, j] = (both - ends[0, i] - ends[1, i] - ends[0, j] - ends[1, j]
                          + 2.0 * f0) / (2.0 * s * s)
            hess[j, i] = hess[i, j]
    if not np.isfinite(hess.sum()):
        return False
    scale = _unit_normal(g, nq, out)
    if scale == 0.0:
        return False
    n0, n1, n2 = out[8], out[9], out[10]
    # the shape operator as meshcurv.surfaces.implicit_curvature forms it (the spec's): t1 the
    # axis x (y where the normal is near x) made orthogonal to n, t2 = n x t1
    a0, a1 = (1.0, 0.0) if abs(n0) < 0.9 else (0.0, 1.0)
    dot = a0 * n0 + a1 * n1
    t10, t11, t12 = a0 - dot * n0, a1 - dot * n1, -dot * n2
    tl = math.sqrt(t10 * t10 + t11 * t11 + t12 * t12)
    t10, t11, t12 = t10 / tl, t11 / tl, t12 / tl
    t20, t21, t22 = n1 * t12 - n2 * t11, n2 * t10 - n0 * t12, n0 * t11 - n1 * t10
    s11 = s12 = s22 = 0.0
    for a in range(3):
        ta = t10 if a == 0 else (t11 if a == 1 else t12)
        ua = t20 if a == 0 else (t21 if a == 1 else t22)
        for b in range(3):
            tb = t10 if b == 0 else (t11 if b == 1 else t12)
            ub = t20 if b == 0 else (t21 if b == 1 else t22)
            s11 += ta * hess[a, b] * tb
            s12 += ta * hess[a, b] * ub
            s22 += ua * hess[a, b] * ub
    s11 *= scale
    s12 *= scale
    s22 *= scale
    half_trace = 0.5 * (s11 + s22)
    disc = math.hypot(0.5 * (s11 - s22), s12)
    theta = 0.5 * math.atan2(2.0 * s12, s11 - s22)
    c, sn = math.cos(theta), math.sin(theta)
    d0, d1, d2 = c * t10 + sn * t20, c * t11 + sn * t21, c * t12 + sn * t22
    out[0] = half_trace + disc
    out[1] = half_trace - disc
    out[2] = d0
    out[3] = d1
    out[4] = d2
    out[5] = n1 * d2 - n2 * d1
    out[6] = n2 * d0 - n0 * d2
    out[7] = n0 * d1 - n1 * d0
    return True


@njit(cache=True)
def mls_curvature(points, normals, query_points, query_normals, query_rows, indptr, indices,
                  support, point_weights, out):
    """MLS curvature at each query point.

    Parameters
    ----------
    points, normals : (n, 3) float64, the neighbor set and its unit normals (NaN rows are
        left out)
    query_points, query_normals : (m, 3) float64, where to estimate, and a normal there that
        sets the side of the result's normal (convex positive about it)
    query_rows : (m,) int64, the row of each query point in ``points`` (-1: none): it takes
        part in its own fit once, whether or not its list holds it
    indptr, indices : CSR lists into ``points``: the candidates of query q; they must hold
        every point within ``support[q] * (1 + 2 STEP)`` of it (the stencil's reach)
    support : (m,) float64, the weights' support h per query point, model units
    point_weights : (n,) float64 in [0, 1] or None, multiplies each point's weight
    out : ``(k1, k2, d1, d2, n)``, (m,) and (m, 3) float64, written in place: curvatures
        (1 / model units, k1 >= k2, convex positive about the normal), unit principal
        directions and the unit normal of the MLS surface (d1, d2, n right-handed); NaN
        where the fit is undefined at a stencil point (too few points within h)
    """
    _mls_kernel(points, normals, query_points, query_normals, query_rows, indptr, indices,
                support, point_weights, False, out[0], out[1], out[2], out[3], out[4])


@njit(cache=True)
def mls_normals(points, normals, query_points, query_normals, query_rows, indptr, indices,
                support, point_weights, out):
    """The MLS surface's unit normal at each query point: ``n`` of :func:`mls_curvature`
    from the gradient's 6 evaluations alone (the same bits wherever that kernel gives one),
    written to ``out`` (m, 3); NaN where F is undefined at an axis step or its gradient
    vanishes. Arguments as :func:`mls_curvature`."""
    none, none3 = np.empty(0), np.empty((0, 3))
    _mls_kernel(points, normals, query_points, query_normals, query_rows, indptr, indices,
                support, point_weights, True, none, none, none3, none3, out)


@njit(parallel=True, cache=True)
def _mls_kernel(points, normals, query_points, query_normals, query_rows, indptr, indices,
                support, point_weights, gradient_only, k1, k2, d1, d2, nout):
    """:func:`mls_curvature` (``gradient_only`` False) or :func:`mls_normals` (True: ``k1``,
    ``k2``, ``d1`` and ``d2`` are not written)."""
    m = query_points.shape[0]
    most = _longest(indptr)
    weighted = point_weights is not None
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        hess = np.empty((3, 3))
        g = np.empty(3)
        ends = np.empty((2, 3))
        row = np.empty(11)
        x = np.empty(3)
        origin = np.zeros(3)       # x in the gathered points' local coordinates
        nq = np.empty(3)
        # the points of one query's fits, gathered once for its 13 (6) evaluations
        pts = np.empty((most + 1, 3))
        nrm = np.empty((most + 1, 3))
        pw = np.empty(most + 1)
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            for a in range(3):
                x[a] = query_points[q, a]
                nq[a] = query_normals[q, a]
            h = support[q]
            ok = np.isfinite(x[0] + x[1] + x[2]) and h > 0.0
            if ok:
                # every stencil point lies within sqrt 2 STEP h of x
                reach = h * (1.0 + 4.0 * STEP)
                k = _gather(points, normals, point_weights, indices, indptr[q], indptr[q + 1],
                            query_rows[q], x, reach * reach, pts, nrm, pw)
                if gradient_only:
                    _gradient(pts, nrm, pw, k, weighted, origin, h, g, ends)
                    ok = _unit_normal(g, nq, row) != 0.0
                else:
                    ok = _curvature_one(pts, nrm, pw, k, weighted, origin, nq, h, hess, g,
                                        ends, row)
            for a in range(3):
                nout[q, a] = row[8 + a] if ok else np.nan
            if gradient_only:
                continue
            k1[q] = row[0] if ok else np.nan
            k2[q] = row[1] if ok else np.nan
            for a in range(3):
                d1[q, a] = row[2 + a] if ok else np.nan
                d2[q, a] = row[5 + a] if ok else np.nan
