"""CGA circle fits in the half-sets around a point: accumulate each half-set's sums, then solve
for the sphere centred on the normal line. Compiled kernels; their numpy specification is
:mod:`meshcurv.fit.circle_spec`.
"""

import numpy as np
from numba import njit

from ..linalg import ball_offset, smallest_eigvec_jacobi3
from .constants import WEIGHT_POWER

# Columns of the per-half-set accumulator (coordinates scaled by 1/radius). The CGA circle fit
# needs B = sum w w^T over rows w = (h, -1, -r2/2): the weighted sums of 1, h, h^2, r2, h*r2,
# r2^2. The sums of r2*cos2phi ... tell the sine fit which blend of directions a half-set really
# saw (see ``sample_design``). _CNT counts the points, _EMAX is the farthest reach along the
# plane's direction. With a normal field, each neighbor p with normal n_p also gives a normal row
# b = kappa a: a = (p - c) . e along the plane's direction e and b = (n_p - nbar) . e the turn
# of its normal, both relative to the weighted means c, nbar of the ball's points and normals
# (the first-order field n_p = nbar + S (p - c) holds whatever x's own normal is, and nbar is
# far less noisy than one normal): the weighted sums of a, b, s (s = (p - c) . e_perp, across
# the slab, for the direction mix of these rows), a^2, a b, b^2, a s, b s, s^2, the rows'
# weight and count.
_N, _H, _HH, _R, _HR, _RR, _RC, _RRC, _RS, _RRS, _CNT, _EMAX = range(12)
_A, _B, _S, _AA, _AB, _BB, _AS, _BS, _SS, _NW, _NCNT = range(12, 23)


N_ACC = 23


@njit(cache=True)
def sample_design(acc, k, corrected, cos2t, sin2t, mu=0.0):
    """Regressors (cos 2theta, sin 2theta) of one circle-fit sample for the Euler model.

    Nominally (cos 2theta, sin 2theta) of the sample's plane direction theta. With
    ``corrected`` they are the cos/sin 2phi of the half-set's own points, averaged with the weights the circle fit gives them: to first
    order in the heights, the fitted curvature is sum_p w_p k(phi_p) / sum_p w_p with
    w_p = r2_p (r2_p - mean r2), so a slab of finite width samples a known blend of directions
    rather than theta alone, and the Euler model can be fitted to that blend exactly.

    With normal rows of weight ``mu`` (see :func:`circle_fit`) the fitted curvature is the
    mean of the position rows' (weight ``den / 4``, ``den`` below) and the normal rows' (weight
    ``mu sum w a^2``). A normal row measures ``(S p) . e = a S(e, e) + s S(e_perp, e)`` for the
    shape operator S, so these rows see (cos 2theta, sin 2theta) turned by
    ``delta = sum w a s / sum w a^2``: ``(cos 2theta - delta sin 2theta, sin 2theta + delta cos
    2theta)``, exactly for a linear normal field.
    """
    if not corrected:
        return cos2t, sin2t
    rbar = acc[k, _R] / acc[k, _N]
    den = acc[k, _RR] - rbar * acc[k, _R]
    dn = mu * acc[k, _AA] if mu > 0.0 else 0.0
    if den <= 0.0 and not dn > 0.0:
        return cos2t, sin2t
    mc, ms, dp = cos2t, sin2t, 0.0
    if den > 0.0:
        mc = (acc[k, _RRC] - rbar * acc[k, _RC]) / den
        ms = (acc[k, _RRS] - rbar * acc[k, _RS]) / den
        dp = 0.25 * den
    if dn > 0.0:
        delta = acc[k, _AS] / acc[k, _AA]
        mc = (dp * mc + dn * (cos2t - delta * sin2t)) / (dp + dn)
        ms = (dp * ms + dn * (sin2t + delta * cos2t)) / (dp + dn)
    return mc, ms


@njit(cache=True)
def circle_fit(acc, k, unit_norm, b, ev, mu=0.0):
    """CGA circle fit of half-set k from its accumulator row: kappa (scaled units), NaN if
    degenerate.

    B = [[Shh, -Sh, -Shr/2], [-Sh, N, Sr/2], [-Shr/2, Sr/2, Srr/4]] and the sphere is
    t = (t1, t2, t3) with kappa = -t3 / t1 (scaled units). ``unit_norm`` minimises t^T B t over
    |t| = 1 (the paper: smallest eigenvector; ``b`` (3, 3) and ``ev`` (3,) are scratch).
    Otherwise over t1 = 1, the generalised eigenproblem B t = lambda diag(1, 0, 0) t, i.e. the
    2x2 system [[N, Sr/2], [Sr/2, Srr/4]] (t2, t3) = (Sh, Shr/2): the same sphere on exact data,
    but it cannot drift to the spheres centred at x (t1 -> 0) that send |kappa| to infinity
    under noise.

    ``mu`` > 0 adds the half-set's normal rows ``b = kappa a`` with that weight relative to
    the position rows: in t they read ``b t1 + a t3 = 0``, so B gains
    ``mu [[Sbb, 0, Sab], [0, 0, 0], [Sab, 0, Saa]]``.
    """
    b11 = acc[k, _HH]
    b12 = -acc[k, _H]
    b13 = -0.5 * acc[k, _HR]
    b22 = acc[k, _N]
    b23 = 0.5 * acc[k, _R]
    b33 = 0.25 * acc[k, _RR]
    if mu > 0.0:
        b11 += mu * acc[k, _BB]
        b13 += mu * acc[k, _AB]
        b33 += mu * acc[k, _AA]
    if unit_norm:
        b[0, 0], b[0, 1], b[0, 2] = b11, b12, b13
        b[1, 0], b[1, 1], b[1, 2] = b12, b22, b23
        b[2, 0], b[2, 1], b[2, 2] = b13, b23, b33
        smallest_eigvec_jacobi3(b, ev)
        if not (abs(ev[0]) > 1e-12 * abs(ev[2])):
            return np.nan
        return -ev[2] / ev[0]
    det = b22 * b33 - b23 * b23
    if not det > 1e-14 * b22 * b33:
        return np.nan
    return -(-b13 * b22 + b12 * b23) / det


# Columns of the per-neighbor rows that :func:`accumulate_half_sets` gathers before it sums
# each half-set: frame coordinates u, v, h and r2 (units of the radius), the distance weight
# (times the point's own), cos 2phi and sin 2phi of the neighbor's direction, the tangent part
# (bu, bv) of its normal in the frame, and 1 where that normal gives a row (else 0).
_U, _V, _HT, _R2, _W, _C2, _S2, _BU, _BV, _HAS = range(10)
N_ROW = 10


@njit(cache=True)
def accumulate_half_sets(points, nbr, lo, hi, x, n, tu, tv, r2max, inv_r, beta, planes, slab,
                         acc, rows, members, point_normals=None, point_weights=None,
                         taper=-1.0):
    """Accumulate the neighbors ``points[nbr[lo:hi]]`` of x into the half-sets' sums; their count.

    Each neighbor within the ball (``r2max`` the squared radius, ``inv_r`` its inverse; model
    units) is expressed in the frame (tu, tv, n) in units of the radius and added, with weight
    ``(1 - beta) + beta (1 - r^2)^WEIGHT_POWER`` (times the slab's taper of blend ``taper``,
    ``beta`` where negative; see :func:`add_half_set`), to the row of ``acc`` ((2 ndir,
    N_ACC), overwritten) of every half-set whose slab (half-width ``slab``) holds it: half-set
    i on the positive side of plane i's direction ``planes[0][i], planes[1][i]`` (cos, sin),
    i + ndir on the negative side. ``rows`` ((at least hi - lo, N_ROW) float64) and
    ``members`` ((2, at least hi - lo) int64) are scratch: the neighbors' frame coordinates,
    and which of them each side of a plane holds. Returns the number of neighbors in the
    ball.

    ``point_normals`` ((n, 3) unit, aligned with ``points``; NaN rows give no normal row) add
    each neighbor's normal row, centred on the ball's weighted mean position and normal (a
    normal facing away from n is turned round first).
    ``point_weights`` (n,) in [0, 1], optional (the outlier pass's): multiplies each
    neighbor's weight; neighbors of weight 0 are counted in the ball but join no half-set.
    """
    ca, sa = planes[0], planes[1]
    ndir = ca.shape[0]
    n_nbr = 0
    m = 0
    # weighted sums over the ball's normal rows: weight, u, v, bu, bv (the means c and nbar)
    sw, su, sv, sbu, sbv = 0.0, 0.0, 0.0, 0.0, 0.0
    for j in range(lo, hi):
        inside, qx, qy, qz, r2 = ball_offset(points, nbr[j], x[0], x[1], x[2], r2max, inv_r)
        if not inside:
            continue
        n_nbr += 1
        pw = 1.0 if point_weights is None else point_weights[nbr[j]]
        if pw <= 0.0:
            continue
        u = qx * tu[0] + qy * tu[1] + qz * tu[2]
        v = qx * tv[0] + qy * tv[1] + qz * tv[2]
        h = qx * n[0] + qy * n[1] + qz * n[2]
        w = ((1.0 - beta) + beta * (1.0 - r2) ** WEIGHT_POWER) * pw
        bu, bv, has_normal = 0.0, 0.0, False
        if point_normals is not None:
            p = nbr[j]
            sgn = 1.0
            if (point_normals[p, 0] * n[0] + point_normals[p, 1] * n[1]
                    + point_normals[p, 2] * n[2]) < 0.0:
                sgn = -1.0
            bu = sgn * (point_normals[p, 0] * tu[0] + point_normals[p, 1] * tu[1]
                        + point_normals[p, 2] * tu[2])
            bv = sgn * (point_normals[p, 0] * tv[0] + point_normals[p, 1] * tv[1]
                        + point_normals[p, 2] * tv[2])
            has_normal = np.isfinite(bu + bv) and u * u + v * v > 0.0
            if has_normal:
                sw += w
                su += w * u
                sv += w * v
                sbu += w * bu
                sbv += w * bv
        t2 = u * u + v * v
        if t2 <= 0.0:          # on the normal line: on every plane, in no half-set
            continue
        rows[m, _U] = u
        rows[m, _V] = v
        rows[m, _HT] = h
        rows[m, _R2] = r2
        rows[m, _W] = w
        rows[m, _C2] = (u * u - v * v) / t2
        rows[m, _S2] = 2.0 * u * v / t2
        rows[m, _BU] = bu
        rows[m, _BV] = bv
        rows[m, _HAS] = 1.0 if has_normal else 0.0
        m += 1
    if taper < 0.0:
        taper = beta
    for i in range(ndir):
        n_pos, n_neg = split_slab(rows, m, ca[i], sa[i], slab, members)
        add_half_set(acc, i, rows, members[0], n_pos, ca[i], sa[i], slab, taper)
        add_half_set(acc, i + ndir, rows, members[1], n_neg, ca[i], sa[i], slab, taper)
    if sw > 0.0:
        center_normal_rows(acc, ca, sa, su / sw, sv / sw, sbu / sw, sbv / sw)
    return n_nbr


@njit(cache=True)
def split_slab(rows, m, ce, se, slab, members):
    """The neighbors ``rows[:m]`` (see :func:`accumulate_half_sets`) in the slab of
    half-width ``slab`` about the plane of direction (``ce``, ``se``) (cos, sin): their rows
    on its positive side (e >= 0) into ``members[0]``, the others into ``members[1]``, in
    order; returns both counts. Without a branch on the data: each row is written to both
    lists and each count advances by its test, since in irregular samplings the tests'
    outcomes cannot be predicted (a hit-or-miss branch per plane and point made the kernel
    2x slower on a jittered grid or a random cloud than on a regular grid)."""
    n_pos = 0
    n_neg = 0
    for j in range(m):
        inside = abs(-se * rows[j, _U] + ce * rows[j, _V]) <= slab
        positive = ce * rows[j, _U] + se * rows[j, _V] >= 0.0
        members[0, n_pos] = j
        members[1, n_neg] = j
        n_pos += int(inside & positive)
        n_neg += int(inside & (not positive))
    return n_pos, n_neg


@njit(cache=True)
def add_half_set(acc, k, rows, members, m, ce, se, slab, taper):
    """Sums of half-set k into ``acc[k]`` (overwritten) from its neighbors: the rows
    ``members[:m]`` of ``rows`` (see :func:`accumulate_half_sets`, :func:`split_slab`), in
    the slab of half-width ``slab`` about the plane of direction (``ce``, ``se``) (cos, sin).

    Each point's weight is its distance weight times the slab's taper
    ``(1 - taper) + taper (1 - (s / slab)^2)^2`` at its distance s from the plane: where the
    data are clean a point entering or leaving a slab moves the fit smoothly, as the distance
    weights do at the ball's edge. A hard slab edge made the clean fits' error jump from vertex
    to vertex with the sampling (measured when the taper came in: regular torus 240 x 60 at R
    0.3, bias-corrected mean |dk| 0.0026 -> 0.0007; ellipsoid 0.0026 -> 0.0010); the taper
    halves a slab's points, so noisy data (taper 0) keep every slab point at full weight.
    Points with a normal row also add it: a = e, b = (bu, bv) . e, s, all relative to x
    (:func:`center_normal_rows` moves them to the ball's means). The sums are local (one
    half-set at a time) rather than scattered into ``acc`` point by point: the same sums in
    the same order."""
    n_, h_, hh, r_, hr, rr, rc, rrc, rs, rrs, cnt, emax = (0.0,) * 12
    a_, b_, s_, aa, ab, bb, as_, bs, ss, nw, ncnt = (0.0,) * 11
    for jj in range(m):
        j = members[jj]
        u = rows[j, _U]
        v = rows[j, _V]
        s = -se * u + ce * v
        e = ce * u + se * v
        h = rows[j, _HT]
        r2 = rows[j, _R2]
        q = 1.0 - (s / slab) ** 2
        w = rows[j, _W] * ((1.0 - taper) + taper * q * q)
        wr = w * r2
        wrr = wr * r2
        n_ += w
        h_ += w * h
        hh += w * h * h
        r_ += wr
        hr += wr * h
        rr += wrr
        rc += wr * rows[j, _C2]
        rrc += wrr * rows[j, _C2]
        rs += wr * rows[j, _S2]
        rrs += wrr * rows[j, _S2]
        cnt += 1.0
        emax = max(emax, abs(e))
        if rows[j, _HAS] > 0.0:
            # along plane i's own direction on both sides: a, b and s all change sign with the
            # side's direction, their products (all the fits use) do not
            b = ce * rows[j, _BU] + se * rows[j, _BV]
            a_ += w * e
            b_ += w * b
            s_ += w * s
            aa += w * e * e
            ab += w * e * b
            bb += w * b * b
            as_ += w * e * s
            bs += w * b * s
            ss += w * s * s
            nw += w
            ncnt += 1.0
    acc[k, _N], acc[k, _H], acc[k, _HH], acc[k, _R], acc[k, _HR], acc[k, _RR] = (
        n_, h_, hh, r_, hr, rr)
    acc[k, _RC], acc[k, _RRC], acc[k, _RS], acc[k, _RRS], acc[k, _CNT], acc[k, _EMAX] = (
        rc, rrc, rs, rrs, cnt, emax)
    acc[k, _A], acc[k, _B], acc[k, _S], acc[k, _AA], acc[k, _AB], acc[k, _BB] = (
        a_, b_, s_, aa, ab, bb)
    acc[k, _AS], acc[k, _BS], acc[k, _SS], acc[k, _NW], acc[k, _NCNT] = as_, bs, ss, nw, ncnt


@njit(cache=True)
def center_normal_rows(acc, ca, sa, cu, cv, du, dv):
    """Move the half-sets' normal-row sums from a = p . e, b = n_p . e, s = p . e_perp to the
    ball's means: a - c . e, b - nbar . e, s - c . e_perp, with c = (cu, cv), nbar's tangent part
    (du, dv) (the sums' first moments make this exact)."""
    ndir = ca.shape[0]
    for k in range(2 * ndir):
        i = k % ndir
        ce = ca[i] * cu + sa[i] * cv
        cp = -sa[i] * cu + ca[i] * cv
        de = ca[i] * du + sa[i] * dv
        w, a, b, s = acc[k, _NW], acc[k, _A], acc[k, _B], acc[k, _S]
        acc[k, _AA] += -2.0 * ce * a + ce * ce * w
        acc[k, _AB] += -ce * b - de * a + ce * de * w
        acc[k, _BB] += -2.0 * de * b + de * de * w
        acc[k, _AS] += -ce * s - cp * a + ce * cp * w
        acc[k, _BS] += -de * s - cp * b + de * cp * w
        acc[k, _SS] += -2.0 * cp * s + cp * cp * w
        acc[k, _A] = a - ce * w
        acc[k, _B] = b - de * w
        acc[k, _S] = s - cp * w


@njit(cache=True)
def normal_row_weight(acc, ndir, min_points, min_spread, height_var):
    """Weight ``mu`` of the normal rows relative to the position rows in one point's circle
    fits: the ratio of their noise variances (0 when there are no normal rows).

    ``height_var`` is the position rows' (the squared noise of the local cubic height fit,
    :func:`meshcurv.fit.jet.local_jet`, in units of the radius; NaN gives 0: positions only).
    The normal rows' is their residual of ``b = kappa a + gamma s`` (gamma = S(e_perp, e), the
    turn across the slab that :func:`sample_design` models, is not noise), pooled over the
    half-sets that will be fitted: ``sum SSE / sum W (cnt - 2) / cnt`` (W the rows' weight, cnt
    their number), the SSE a quadratic form of the sums. Measured, the position rows' own
    residual is no measure of their noise: a frame tilted by a noisy normal and the slab's
    blend of directions leave residuals that are not noise (with clean positions and normals
    of sigma_xi 0.1 it gave normals 20x too much weight). The floor ``1e-12`` (1e-6 radius)
    keeps the ratio defined on exact data.
    """
    if not np.isfinite(height_var):
        return 0.0
    sse_n = 0.0
    dof_n = 0.0
    for k in range(2 * ndir):
        if acc[k, _CNT] < min_points or acc[k, _EMAX] < min_spread:
            continue
        saa, sas, sss, sab, sbs = acc[k, _AA], acc[k, _AS], acc[k, _SS], acc[k, _AB], acc[k, _BS]
        dn = saa * sss - sas * sas
        if dn > 1e-14 * saa * sss and acc[k, _NCNT] > 2.0:
            fit = (sss * sab * sab - 2.0 * sas * sab * sbs + saa * sbs * sbs) / dn
            sse_n += max(acc[k, _BB] - fit, 0.0)
            dof_n += acc[k, _NW] * (acc[k, _NCNT] - 2.0) / acc[k, _NCNT]
    if not dof_n > 0.0:
        return 0.0
    return (height_var + 1e-12) / (sse_n / dof_n + 1e-12)


@njit(cache=True)
def half_set_samples(acc, ndir, min_points, min_spread, unit_norm, corrected, dirs, kappa, rows,
                     mix, active, b3, ev, mu=0.0):
    """Circle fit of every half-set with enough points, as samples of the Euler model.

    A half-set is fitted when it holds ``min_points`` points reaching ``min_spread`` (units of
    the radius) along its direction; x itself joins it as the row (0, -1, 0) with weight 1.
    Sample s gets its curvature ``kappa[s]`` (units of 1 / radius), the Euler design row
    ``rows[s] = (1, cos 2theta, sin 2theta, cos theta, sin theta)`` (the measured direction mix
    in the second and third column with ``corrected``; ``dirs`` (2 ndir, 4) holds (cos, sin) of
    theta and 2 theta per half-set), its measured mix ``mix[s]`` and ``active[s] = 1``.
    ``b3`` (3, 3), ``ev`` (3,) are scratch. Returns ``(m, planes_seen)``: the samples and the
    planes with at least one of them. ``mu``: the normal rows' weight (:func:`circle_fit`).
    """
    m = 0
    planes_seen = 0
    for i in range(ndir):
        seen = False
        for side in range(2):
            k = i + side * ndir
            if acc[k, _CNT] < min_points or acc[k, _EMAX] < min_spread:
                continue
            acc[k, _N] += 1.0
            kap = circle_fit(acc, k, unit_norm, b3, ev, mu)
            if not np.isfinite(kap):
                continue
            kappa[m] = kap
            mc, ms = sample_design(acc, k, True, dirs[k, 2], dirs[k, 3], mu)
            mix[m, 0] = mc
            mix[m, 1] = ms
            dc, ds = (mc, ms) if corrected else (dirs[k, 2], dirs[k, 3])
            rows[m, 0] = 1.0
            rows[m, 1] = dc
            rows[m, 2] = ds
            rows[m, 3] = dirs[k, 0]
            rows[m, 4] = dirs[k, 1]
            active[m] = 1.0
            m += 1
            seen = True
        if seen:
            planes_seen += 1
    return m, planes_seen
