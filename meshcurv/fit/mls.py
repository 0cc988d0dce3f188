"""MLS curvature: the principal curvatures of the moving-least-squares surface of oriented
algebraic spheres (APSS, Guennebaud & Gross 2007) through points with normals, as one compiled
kernel over query points with CSR neighbor lists (:func:`mls_curvature`).

About each evaluation point y a sphere (or plane) ``u0 + u . z + u4 |z|^2`` is fitted to the
neighbors' positions and unit normals with the weights ``(1 - |p - y|^2 / h^2)^4`` (h the
support), in closed form; its value at y is the potential F(y), whose zero set is the surface.
Its gradient and Hessian at a point, exact (the fit's sums and the closed form carried as
second-order jets in the evaluation point, one pass over the neighbors), give the normal and
the shape operator ``P Hess(F) P / |grad F|`` (P the tangent projector). Because the fit
follows the evaluation point, F is a smooth surface of second order even where a single
sphere could not describe the shape (a torus's saddle) and where a neighborhood holds few
points per direction (a low-poly torus: 16 vertices around the tube), where the circle fits
in normal sections of :mod:`meshcurv.fit.fused` are far less accurate. It needs normals and
is more sensitive to position noise than the circle fits; :mod:`meshcurv.coarse` says where
it is used.

:func:`mls_normals` gives the normal alone from first-order jets (the MLS passes that only
feed normals to the next one).

Numpy specification: :func:`meshcurv.fit.mls_spec.mls_curvature_at` and
:func:`~meshcurv.fit.mls_spec.mls_normal_at`, which take F's derivatives by central
differences instead. The kernels took them so too until the jets replaced them (1.75x faster
on a 300k torus's two passes; k moved by at most 5e-8 of its scale on the golden cases, the
differences' truncation and rounding).
"""

import math

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK

__all__ = ["mls_curvature", "mls_normals"]


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
    coordinates, which keep their precision far from the origin (a scan in UTM coordinates,
    x ~ 5e6)."""
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


# The potential F and the weighted sums it is made of are handled as second-order jets in the
# offset z of the evaluation point from x, at z = 0: 10-tuples of the value, the gradient (3)
# and the Hessian's entries xx, xy, xz, yy, yz, zz (6); _HESSIAN[i, j] is the entry of (i, j).
_ZERO = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_UNDEFINED = (np.nan,) + _ZERO[1:]
_HESSIAN = np.array([[4, 5, 6], [5, 7, 8], [6, 8, 9]])


@njit(cache=True)
def _jet_mul(a, b):
    """The jet of the product of the functions whose jets are ``a`` and ``b``."""
    return (a[0] * b[0],
            a[0] * b[1] + b[0] * a[1], a[0] * b[2] + b[0] * a[2], a[0] * b[3] + b[0] * a[3],
            a[0] * b[4] + b[0] * a[4] + 2.0 * a[1] * b[1],
            a[0] * b[5] + b[0] * a[5] + a[1] * b[2] + a[2] * b[1],
            a[0] * b[6] + b[0] * a[6] + a[1] * b[3] + a[3] * b[1],
            a[0] * b[7] + b[0] * a[7] + 2.0 * a[2] * b[2],
            a[0] * b[8] + b[0] * a[8] + a[2] * b[3] + a[3] * b[2],
            a[0] * b[9] + b[0] * a[9] + 2.0 * a[3] * b[3])


@njit(cache=True)
def _jet_div(a, b):
    """The jet of the quotient a / b (``b[0]`` nonzero)."""
    c0 = a[0] / b[0]
    c1 = (a[1] - c0 * b[1]) / b[0]
    c2 = (a[2] - c0 * b[2]) / b[0]
    c3 = (a[3] - c0 * b[3]) / b[0]
    return (c0, c1, c2, c3,
            (a[4] - c0 * b[4] - 2.0 * c1 * b[1]) / b[0],
            (a[5] - c0 * b[5] - c1 * b[2] - c2 * b[1]) / b[0],
            (a[6] - c0 * b[6] - c1 * b[3] - c3 * b[1]) / b[0],
            (a[7] - c0 * b[7] - 2.0 * c2 * b[2]) / b[0],
            (a[8] - c0 * b[8] - c2 * b[3] - c3 * b[2]) / b[0],
            (a[9] - c0 * b[9] - 2.0 * c3 * b[3]) / b[0])


@njit(cache=True)
def _jet_axpy(s, a, b):
    """The jet of s a + b (s a number)."""
    return (s * a[0] + b[0], s * a[1] + b[1], s * a[2] + b[2], s * a[3] + b[3],
            s * a[4] + b[4], s * a[5] + b[5], s * a[6] + b[6], s * a[7] + b[7],
            s * a[8] + b[8], s * a[9] + b[9])


@njit(cache=True)
def _z_times(a, i):
    """The jet of z_i times the function of jet ``a`` (z_i: the offset's coordinate i, 0 with
    gradient e_i): value 0, gradient ``a[0] e_i``, Hessian ``e_i grad a^T + grad a e_i^T``."""
    e0 = 1.0 if i == 0 else 0.0
    e1 = 1.0 if i == 1 else 0.0
    e2 = 1.0 if i == 2 else 0.0
    return (0.0, a[0] * e0, a[0] * e1, a[0] * e2,
            2.0 * e0 * a[1], e0 * a[2] + e1 * a[1], e0 * a[3] + e2 * a[1],
            2.0 * e1 * a[2], e1 * a[3] + e2 * a[2], 2.0 * e2 * a[3])


@njit(cache=True)
def _row(sums, f):
    """Row ``f`` of ``sums`` (:func:`_weighted_sums`) as a jet."""
    return (sums[f, 0], sums[f, 1], sums[f, 2], sums[f, 3], sums[f, 4], sums[f, 5],
            sums[f, 6], sums[f, 7], sums[f, 8], sums[f, 9])


@njit(cache=True)
def _weighted_sums(pts, nrm, pw, k, weighted, h2, second, sums, wj):
    """``sums`` (9, 10) = the jets of the sums over the ``k`` points ``pts`` (offsets from x)
    with normals ``nrm`` of w times 1, q (3), n (3), q . n and |q|^2 (its rows), where
    ``w(z) = (1 - |q - z|^2 / h^2)^4`` (times the point weights ``pw`` where ``weighted``) is
    each point's weight about the evaluation point x + z. Without ``second`` their Hessians
    are 0. ``wj`` (10,) is scratch."""
    sums[:, :] = 0.0
    wj[:] = 0.0
    columns = 10 if second else 4
    for e in range(k):
        q0 = pts[e, 0]
        q1 = pts[e, 1]
        q2 = pts[e, 2]
        qq = q0 * q0 + q1 * q1 + q2 * q2
        r = 1.0 - qq / h2
        if not r > 0.0:
            continue
        c = pw[e] if weighted else 1.0
        if not c > 0.0:
            continue
        # w = c r^4, r = 1 - |q - z|^2 / h^2: grad r = 2 q / h^2, Hess r = -2 I / h^2, so
        # grad w = 4 c r^3 grad r and Hess w = 12 c r^2 grad r grad r^T + 4 c r^3 Hess r
        rr = r * r
        g = 8.0 * c * rr * r / h2
        wj[0] = c * rr * rr
        wj[1] = g * q0
        wj[2] = g * q1
        wj[3] = g * q2
        if second:
            hq = 48.0 * c * rr / (h2 * h2)
            wj[4] = hq * q0 * q0 - g
            wj[5] = hq * q0 * q1
            wj[6] = hq * q0 * q2
            wj[7] = hq * q1 * q1 - g
            wj[8] = hq * q1 * q2
            wj[9] = hq * q2 * q2 - g
        n0 = nrm[e, 0]
        n1 = nrm[e, 1]
        n2 = nrm[e, 2]
        qn = q0 * n0 + q1 * n1 + q2 * n2
        for cc in range(columns):
            wc = wj[cc]
            sums[0, cc] += wc
            sums[1, cc] += wc * q0
            sums[2, cc] += wc * q1
            sums[3, cc] += wc * q2
            sums[4, cc] += wc * n0
            sums[5, cc] += wc * n1
            sums[6, cc] += wc * n2
            sums[7, cc] += wc * qn
            sums[8, cc] += wc * qq


@njit(cache=True)
def _potential_jet(sums):
    """The jet of the MLS potential F at x (of ``F(x + z)`` at z = 0) from the jets of the
    weighted sums (:func:`_weighted_sums`); NaN (value) where the fit is undefined at x.

    About x + z the fit works on the offsets q - z, whose sums are W, P = S_q - z W, N,
    A = S_qn - z . N and B = S_qq - 2 z . S_q + |z|^2 W (S the rows of ``sums``); then
    u4 = (A W - P . N) / (2 (B W - |P|^2)), u = (N - 2 u4 P) / W and
    F = u0 = -(u . P + u4 B) / W, as :func:`meshcurv.fit.mls_spec.potential` forms it."""
    w = _row(sums, 0)
    s = (_row(sums, 1), _row(sums, 2), _row(sums, 3))
    n = (_row(sums, 4), _row(sums, 5), _row(sums, 6))
    p = (_jet_axpy(-1.0, _z_times(w, 0), s[0]), _jet_axpy(-1.0, _z_times(w, 1), s[1]),
         _jet_axpy(-1.0, _z_times(w, 2), s[2]))
    a = _row(sums, 7)
    b = _row(sums, 8)
    for i in range(3):
        a = _jet_axpy(-1.0, _z_times(n[i], i), a)
        b = _jet_axpy(-2.0, _z_times(s[i], i), b)
    # |z|^2 W: value and gradient 0, Hessian 2 W I
    b = (b[0], b[1], b[2], b[3], b[4] + 2.0 * w[0], b[5], b[6], b[7] + 2.0 * w[0], b[8],
         b[9] + 2.0 * w[0])
    pp = _jet_mul(p[0], p[0])
    pn = _jet_mul(p[0], n[0])
    for i in range(1, 3):
        pp = _jet_axpy(1.0, _jet_mul(p[i], p[i]), pp)
        pn = _jet_axpy(1.0, _jet_mul(p[i], n[i]), pn)
    den = _jet_axpy(-1.0, pp, _jet_mul(b, w))
    if not (w[0] > 0.0 and den[0] > 0.0):
        return _UNDEFINED
    u4 = _jet_div(_jet_axpy(-1.0, pn, _jet_mul(a, w)), _jet_axpy(2.0, den, _ZERO))
    # u . P = (N . P - 2 u4 |P|^2) / W
    up = _jet_div(_jet_axpy(-2.0, _jet_mul(u4, pp), pn), w)
    return _jet_axpy(-1.0, _jet_div(_jet_axpy(1.0, up, _jet_mul(u4, b)), w), _ZERO)


@njit(cache=True)
def _derivatives(pts, nrm, pw, k, weighted, h, second, sums, wj, g, hess):
    """``g[:]`` = grad F and, with ``second``, ``hess[:, :]`` = Hess F at x (exact, from the
    jets of :func:`_potential_jet`) over the ``k`` points of :func:`_gather`; False where F
    is undefined at x."""
    _weighted_sums(pts, nrm, pw, k, weighted, h * h, second, sums, wj)
    f = _potential_jet(sums)
    if not np.isfinite(f[0]):
        return False
    for i in range(3):
        g[i] = f[1 + i]
    if second:
        for i in range(3):
            for j in range(3):
                hess[i, j] = f[_HESSIAN[i, j]]
    return True


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
def _curvature_one(pts, nrm, pw, k, weighted, nq, h, sums, wj, hess, g, out):
    """``out[:]`` = (k1, k2, d1 (3), d2 (3), n (3)) at x from the ``k`` points of
    :func:`_gather` (see :func:`mls_curvature`); False (``out`` untouched) where F or its
    derivatives are undefined. ``sums``, ``wj`` (:func:`_weighted_sums`), ``hess`` (3, 3) and
    ``g`` (3,) are scratch."""
    if not _derivatives(pts, nrm, pw, k, weighted, h, True, sums, wj, g, hess):
        return False
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
        every point within ``support[q]`` of it
    support : (m,) float64, the weights' support h per query point, model units
    point_weights : (n,) float64 in [0, 1] or None, multiplies each point's weight
    out : ``(k1, k2, d1, d2, n)``, (m,) and (m, 3) float64, written in place: curvatures
        (1 / model units, k1 >= k2, convex positive about the normal), unit principal
        directions and the unit normal of the MLS surface (d1, d2, n right-handed); NaN
        where the fit is undefined (too few points within h)
    """
    _mls_kernel(points, normals, query_points, query_normals, query_rows, indptr, indices,
                support, point_weights, False, out[0], out[1], out[2], out[3], out[4])


@njit(cache=True)
def mls_normals(points, normals, query_points, query_normals, query_rows, indptr, indices,
                support, point_weights, out):
    """The MLS surface's unit normal at each query point: ``n`` of :func:`mls_curvature`
    from first-order jets alone (the same bits wherever that kernel gives one), written to
    ``out`` (m, 3); NaN where F is undefined or its gradient vanishes. Arguments as
    :func:`mls_curvature`."""
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
        sums = np.empty((9, 10))
        wj = np.empty(10)
        row = np.empty(11)
        x = np.empty(3)
        nq = np.empty(3)
        # the points of one query's fit, gathered once
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
                k = _gather(points, normals, point_weights, indices, indptr[q], indptr[q + 1],
                            query_rows[q], x, h * h, pts, nrm, pw)
                if gradient_only:
                    ok = (_derivatives(pts, nrm, pw, k, weighted, h, False, sums, wj, g, hess)
                          and _unit_normal(g, nq, row) != 0.0)
                else:
                    ok = _curvature_one(pts, nrm, pw, k, weighted, nq, h, sums, wj, hess, g,
                                        row)
            for a in range(3):
                nout[q, a] = row[8 + a] if ok else np.nan
            if gradient_only:
                continue
            k1[q] = row[0] if ok else np.nan
            k2[q] = row[1] if ok else np.nan
            for a in range(3):
                d1[q, a] = row[2 + a] if ok else np.nan
                d2[q, a] = row[5 + a] if ok else np.nan
