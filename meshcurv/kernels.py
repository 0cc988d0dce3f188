"""Compiled numba kernels: neighbour search, PCA normals, local jet fits, spanning-tree
orientation and the fused circle-fit estimator.

This module is a leaf: it imports nothing from the rest of meshcurv. Every kernel works on flat
arrays (float64 coordinates, CSR neighbour lists ``(indptr, indices)``); the per-point kernels
loop over query points with ``prange`` and none allocates per query point. The plain numpy reference of the same estimator
lives in :mod:`meshcurv.reference` and the test-suite checks the two agree.
"""

import math

import numpy as np
from numba import njit, prange

# Columns of the per-half-set accumulator (coordinates scaled by 1/radius). The CGA circle fit
# needs B = sum w w^T over rows w = (h, -1, -r2/2): the weighted sums of 1, h, h^2, r2, h*r2,
# r2^2. The sums of r2*cos2phi ... tell the sine fit which blend of directions a half-set really
# saw (see ``_sample_design``). _CNT counts the points, _EMAX is the farthest reach along the
# plane's direction.
_N, _H, _HH, _R, _HR, _RR, _RC, _RRC, _RS, _RRS, _CNT, _EMAX = range(12)
N_ACC = 12

# Exponent p of the distance weights (1 - r^2 / radius^2)^p (measured: p = 2 leaves twice the
# bias of p = 4 on the Table 2 paraboloid; p = 8 gains little more and doubles the noise again).
WEIGHT_POWER = 4

# Plane i makes the angle (i + PLANE_OFFSET) * pi / ndir with the tangent frame's first axis.
PLANE_OFFSET = 0.25

# Points per chunk handed to one thread (keeps scratch arrays per chunk, not per point).
CHUNK = 256

# Fewest spread of the directions the circle fits measured for an estimate: the smaller
# eigenvalue of the covariance of their (cos 2phi, sin 2phi) mixes (see ``_sample_design``)
# over the samples kept. Measured: directions all around ~0.34 (sphere), mesh borders and
# corners >= 0.15, the border of a random half-sphere cloud >= 0.027, the corners of a random
# square patch 0.0069 .. 0.0095 (still accurate); neighbours along one curve (the rim of a
# triangle fan) 0 .. 0.0018: there the Euler model's B and C are not determined, and k1, k2
# would be noise (often exactly 0) marked valid.
MIN_DIRECTION_SPREAD = 3e-3

@njit(cache=True)
def _smallest_eigvec_jacobi3(a, out):
    """Unit eigenvector of the smallest eigenvalue of the symmetric 3x3 ``a`` (overwritten).

    Cyclic Jacobi rotations to machine precision (as accurate as LAPACK's ``eigh`` here, unlike
    a closed-form cubic); the rotations are accumulated in the local ``v00 .. v22``.
    """
    v00 = 1.0
    v01 = 0.0
    v02 = 0.0
    v10 = 0.0
    v11 = 1.0
    v12 = 0.0
    v20 = 0.0
    v21 = 0.0
    v22 = 1.0
    for sweep in range(50):
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        diag = a[0, 0] * a[0, 0] + a[1, 1] * a[1, 1] + a[2, 2] * a[2, 2]
        if off <= 1e-36 * diag or off == 0.0:
            break
        for pq in range(3):
            if pq == 0:
                p, q, r = 0, 1, 2
            elif pq == 1:
                p, q, r = 0, 2, 1
            else:
                p, q, r = 1, 2, 0
            apq = a[p, q]
            if apq == 0.0:
                continue
            # rotation angle that zeroes a[p, q] (Golub & Van Loan, sym.schur2)
            tau = (a[q, q] - a[p, p]) / (2.0 * apq)
            if tau >= 0.0:
                t = 1.0 / (tau + math.sqrt(1.0 + tau * tau))
            else:
                t = -1.0 / (-tau + math.sqrt(1.0 + tau * tau))
            c = 1.0 / math.sqrt(1.0 + t * t)
            s = t * c
            app = a[p, p]
            aqq = a[q, q]
            arp = a[r, p]
            arq = a[r, q]
            a[p, p] = app - t * apq
            a[q, q] = aqq + t * apq
            a[p, q] = 0.0
            a[q, p] = 0.0
            a[r, p] = c * arp - s * arq
            a[p, r] = a[r, p]
            a[r, q] = s * arp + c * arq
            a[q, r] = a[r, q]
            # columns p, q of the accumulated rotation V
            if p == 0 and q == 1:
                v00, v01 = c * v00 - s * v01, s * v00 + c * v01
                v10, v11 = c * v10 - s * v11, s * v10 + c * v11
                v20, v21 = c * v20 - s * v21, s * v20 + c * v21
            elif p == 0:
                v00, v02 = c * v00 - s * v02, s * v00 + c * v02
                v10, v12 = c * v10 - s * v12, s * v10 + c * v12
                v20, v22 = c * v20 - s * v22, s * v20 + c * v22
            else:
                v01, v02 = c * v01 - s * v02, s * v01 + c * v02
                v11, v12 = c * v11 - s * v12, s * v11 + c * v12
                v21, v22 = c * v21 - s * v22, s * v21 + c * v22
    k = 0
    if a[1, 1] < a[k, k]:
        k = 1
    if a[2, 2] < a[k, k]:
        k = 2
    if k == 0:
        x, y, z = v00, v10, v20
    elif k == 1:
        x, y, z = v01, v11, v21
    else:
        x, y, z = v02, v12, v22
    s = 1.0 / math.sqrt(x * x + y * y + z * z)
    out[0] = x * s
    out[1] = y * s
    out[2] = z * s


@njit(cache=True)
def _ball_offset(points, k, x0, x1, x2, r2max, inv_r):
    """Offset of ``points[k]`` from (x0, x1, x2) in units of the radius, and its squared length:
    ``(inside, qx, qy, qz, r2)``. ``inside`` is False for a coincident point (the query point
    itself) and beyond the radius: the neighbourhood every fit here works on."""
    qx = points[k, 0] - x0
    qy = points[k, 1] - x1
    qz = points[k, 2] - x2
    d2 = qx * qx + qy * qy + qz * qz
    return d2 > 0.0 and d2 <= r2max, qx * inv_r, qy * inv_r, qz * inv_r, d2 * inv_r * inv_r


@njit(cache=True)
def _tangent_frame(points, nbr, lo, hi, x, n, r2max, tu, tv, rank):
    """Tangent frame (tu, tv, n) that rotates with the data.

    tu is the tangential part of the offset to the neighbour of lowest index lying at least
    30 degrees off the normal. The choice depends on neither the order of the neighbour list
    nor the coordinates' position, scale or orientation, so the frame - and with it the
    sampling planes - is equivariant under rotation, translation and scaling. Falls back to a
    fixed frame if there is no such neighbour. ``rank`` (or None: the row itself) is the index
    of each row of ``points``, for points stored in another order than the input's.
    """
    found = False
    best = -1
    for j in range(lo, hi):
        k = nbr[j]
        key = k if rank is None else rank[k]
        if found and key >= best:
            continue
        qx = points[k, 0] - x[0]
        qy = points[k, 1] - x[1]
        qz = points[k, 2] - x[2]
        if qx * qx + qy * qy + qz * qz > r2max:
            continue
        hq = qx * n[0] + qy * n[1] + qz * n[2]
        ux = qx - hq * n[0]
        uy = qy - hq * n[1]
        uz = qz - hq * n[2]
        t2 = ux * ux + uy * uy + uz * uz
        if t2 > 0.25 * (t2 + hq * hq) and t2 > 0.0:
            s = 1.0 / math.sqrt(t2)
            tu[0] = ux * s
            tu[1] = uy * s
            tu[2] = uz * s
            found = True
            best = key
    if not found:
        # any unit vector orthogonal to n
        if abs(n[0]) < 0.9:
            ax, ay, az = 1.0, 0.0, 0.0
        else:
            ax, ay, az = 0.0, 1.0, 0.0
        d = ax * n[0] + ay * n[1] + az * n[2]
        ux = ax - d * n[0]
        uy = ay - d * n[1]
        uz = az - d * n[2]
        s = 1.0 / math.sqrt(ux * ux + uy * uy + uz * uz)
        tu[0] = ux * s
        tu[1] = uy * s
        tu[2] = uz * s
    tv[0] = n[1] * tu[2] - n[2] * tu[1]
    tv[1] = n[2] * tu[0] - n[0] * tu[2]
    tv[2] = n[0] * tu[1] - n[1] * tu[0]


@njit(cache=True)
def _solve_sym(m, rhs, npar, sol):
    """Solve the small symmetric positive system m @ sol = rhs by Cholesky; False if singular."""
    # in place copy-free Cholesky on a (npar, npar) scratch held in m
    for i in range(npar):
        for j in range(i + 1):
            s = m[i, j]
            for k in range(j):
                s -= m[i, k] * m[j, k]
            if i == j:
                if s <= 1e-12 * max(1.0, abs(m[i, i])):
                    return False
                m[i, i] = math.sqrt(s)
            else:
                m[i, j] = s / m[j, j]
    for i in range(npar):
        s = rhs[i]
        for k in range(i):
            s -= m[i, k] * sol[k]
        sol[i] = s / m[i, i]
    for i in range(npar - 1, -1, -1):
        s = sol[i]
        for k in range(i + 1, npar):
            s -= m[k, i] * sol[k]
        sol[i] = s / m[i, i]
    return True


@njit(cache=True)
def _sample_design(acc, k, corrected, cos2t, sin2t):
    """Regressors (cos 2theta, sin 2theta) of one circle-fit sample for the Euler model.

    Nominally (cos 2theta, sin 2theta) of the sample's plane direction theta. With ``corrected`` they are the cos/sin 2phi
    of the half-set's own points, averaged with the weights the circle fit gives them: to first
    order in the heights, the fitted curvature is sum_p w_p k(phi_p) / sum_p w_p with
    w_p = r2_p (r2_p - mean r2), so a slab of finite width samples a known blend of directions
    rather than theta alone, and the Euler model can be fitted to that blend exactly.
    """
    if not corrected:
        return cos2t, sin2t
    rbar = acc[k, _R] / acc[k, _N]
    den = acc[k, _RR] - rbar * acc[k, _R]
    if den <= 0.0:
        return cos2t, sin2t
    mc = (acc[k, _RRC] - rbar * acc[k, _RC]) / den
    ms = (acc[k, _RRS] - rbar * acc[k, _RS]) / den
    return mc, ms


@njit(cache=True)
def _circle_fit(acc, k, unit_norm, b, ev):
    """CGA circle fit of half-set k from its accumulator row: kappa (scaled units), NaN if
    degenerate.

    B = [[Shh, -Sh, -Shr/2], [-Sh, N, Sr/2], [-Shr/2, Sr/2, Srr/4]] and the sphere is
    t = (t1, t2, t3) with kappa = -t3 / t1 (scaled units). ``unit_norm`` minimises t^T B t over
    |t| = 1 (the paper: smallest eigenvector; ``b`` (3, 3) and ``ev`` (3,) are scratch).
    Otherwise over t1 = 1, the generalised eigenproblem B t = lambda diag(1, 0, 0) t, i.e. the
    2x2 system [[N, Sr/2], [Sr/2, Srr/4]] (t2, t3) = (Sh, Shr/2): the same sphere on exact data,
    but it cannot drift to the spheres centred at x (t1 -> 0) that send |kappa| to infinity
    under noise.
    """
    b11 = acc[k, _HH]
    b12 = -acc[k, _H]
    b13 = -0.5 * acc[k, _HR]
    b22 = acc[k, _N]
    b23 = 0.5 * acc[k, _R]
    b33 = 0.25 * acc[k, _RR]
    if unit_norm:
        b[0, 0], b[0, 1], b[0, 2] = b11, b12, b13
        b[1, 0], b[1, 1], b[1, 2] = b12, b22, b23
        b[2, 0], b[2, 1], b[2, 2] = b13, b23, b33
        _smallest_eigvec_jacobi3(b, ev)
        if not (abs(ev[0]) > 1e-12 * abs(ev[2])):
            return np.nan
        return -ev[2] / ev[0]
    det = b22 * b33 - b23 * b23
    if not det > 1e-14 * b22 * b33:
        return np.nan
    return -(-b13 * b22 + b12 * b23) / det


@njit(cache=True)
def _euler_fit(rows, kappa, active, m, npar, mat, rhs, sol):
    """Least-squares Euler model over the active samples; sol[:npar]. False if ill-posed."""
    for a in range(npar):
        rhs[a] = 0.0
        for c in range(npar):
            mat[a, c] = 0.0
    used = 0
    for s in range(m):
        if active[s] == 0.0:
            continue
        used += 1
        for a in range(npar):
            rhs[a] += rows[s, a] * kappa[s]
            for c in range(npar):
                mat[a, c] += rows[s, a] * rows[s, c]
    if used < npar + 2:
        return False
    return _solve_sym(mat, rhs, npar, sol)


@njit(cache=True)
def _model(rows, s, npar, sol):
    f = 0.0
    for a in range(npar):
        f += rows[s, a] * sol[a]
    return f


@njit(cache=True)
def _direction_spread(mix, active, m):
    """Smaller eigenvalue of the covariance of the active samples' direction mixes
    ``mix[s] = (cos 2phi, sin 2phi)``: how far the measured directions span the Euler model."""
    cnt = 0.0
    mc = 0.0
    ms = 0.0
    for s in range(m):
        if active[s] != 0.0:
            cnt += 1.0
            mc += mix[s, 0]
            ms += mix[s, 1]
    if cnt < 2.0:
        return 0.0
    mc /= cnt
    ms /= cnt
    a = 0.0
    b = 0.0
    c = 0.0
    for s in range(m):
        if active[s] != 0.0:
            dc = mix[s, 0] - mc
            ds = mix[s, 1] - ms
            a += dc * dc
            b += dc * ds
            c += ds * ds
    a /= cnt
    b /= cnt
    c /= cnt
    return 0.5 * (a + c) - math.sqrt(0.25 * (a - c) * (a - c) + b * b)


@njit(cache=True)
def _estimate_one(points, nbr, lo, hi, x, n, radius, ndir, slab, min_points, min_spread,
                  beta, unit_norm, corrected, half_frequency, robust,
                  ca, sa, dirs, acc, kappa, rows, active, scratch, mat, rhs, sol, b3, ev, tu, tv,
                  res, rank, mix):
    """Circle fits in 2*ndir half-sets around one point, then the Euler model fit.

    Writes (k1, k2, theta1, n_used_samples, residual_rms, n_neighbours) into ``res`` (which
    the caller resets to NaN, NaN, NaN, 0, NaN, 0) and the frame into tu, tv. Lengths inside are in units of ``radius``. The points' weights are
    ``(1 - beta) + beta (1 - r^2)^WEIGHT_POWER``: equal weights at beta = 0, distance weights
    at beta = 1. ``mix`` (2 ndir, 2) is scratch for the measured direction mix of each sample
    (whatever ``corrected``): an estimate needs them spread by ``MIN_DIRECTION_SPREAD``.
    """
    nh = 2 * ndir
    for k in range(nh):
        for c in range(N_ACC):
            acc[k, c] = 0.0
    inv_r = 1.0 / radius
    r2max = radius * radius
    _tangent_frame(points, nbr, lo, hi, x, n, r2max, tu, tv, rank)
    n_nbr = 0
    for j in range(lo, hi):
        inside, qx, qy, qz, r2 = _ball_offset(points, nbr[j], x[0], x[1], x[2], r2max, inv_r)
        if not inside:
            continue
        n_nbr += 1
        u = qx * tu[0] + qy * tu[1] + qz * tu[2]
        v = qx * tv[0] + qy * tv[1] + qz * tv[2]
        h = qx * n[0] + qy * n[1] + qz * n[2]
        t2 = u * u + v * v
        if t2 <= 0.0:
            continue
        w = (1.0 - beta) + beta * (1.0 - r2) ** WEIGHT_POWER
        c2 = (u * u - v * v) / t2
        s2 = 2.0 * u * v / t2
        wr = w * r2
        wrr = wr * r2
        for i in range(ndir):
            if abs(-sa[i] * u + ca[i] * v) > slab:
                continue
            e = ca[i] * u + sa[i] * v
            k = i if e >= 0.0 else i + ndir
            acc[k, _N] += w
            acc[k, _H] += w * h
            acc[k, _HH] += w * h * h
            acc[k, _R] += wr
            acc[k, _HR] += wr * h
            acc[k, _RR] += wrr
            acc[k, _RC] += wr * c2
            acc[k, _RRC] += wrr * c2
            acc[k, _RS] += wr * s2
            acc[k, _RRS] += wrr * s2
            acc[k, _CNT] += 1.0
            if abs(e) > acc[k, _EMAX]:
                acc[k, _EMAX] = abs(e)
    res[5] = n_nbr

    # circle fits per half-set; x itself is the row (0, -1, 0) with weight 1
    m = 0
    planes_seen = 0
    for i in range(ndir):
        seen = False
        for side in range(2):
            k = i + side * ndir
            if acc[k, _CNT] < min_points or acc[k, _EMAX] < min_spread:
                continue
            acc[k, _N] += 1.0
            kap = _circle_fit(acc, k, unit_norm, b3, ev)
            if not np.isfinite(kap):
                continue
            kappa[m] = kap
            mc, ms = _sample_design(acc, k, True, dirs[k, 2], dirs[k, 3])
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
    res[3] = m
    if planes_seen < 3 or m < 5:
        return
    npar = 5 if half_frequency else 3
    if not _euler_fit(rows, kappa, active, m, npar, mat, rhs, sol):
        return
    if robust:
        # drop samples further than 3 robust sigmas (MAD) from the model, then refit
        for s in range(m):
            r = abs(kappa[s] - _model(rows, s, npar, sol))
            j = s
            while j > 0 and scratch[j - 1] > r:
                scratch[j] = scratch[j - 1]
                j -= 1
            scratch[j] = r
        med = scratch[(m - 1) // 2] if m % 2 == 1 else 0.5 * (scratch[m // 2 - 1] + scratch[m // 2])
        cut = 3.0 * 1.4826 * med
        changed = False
        if cut > 0.0:
            for s in range(m):
                if abs(kappa[s] - _model(rows, s, npar, sol)) > cut:
                    active[s] = 0.0
                    changed = True
        if changed and not _euler_fit(rows, kappa, active, m, npar, mat, rhs, sol):
            return
    used = 0
    sse = 0.0
    for s in range(m):
        if active[s] != 0.0:
            used += 1
            sse += (kappa[s] - _model(rows, s, npar, sol)) ** 2
    if _direction_spread(mix, active, m) < MIN_DIRECTION_SPREAD:
        return
    amp = math.sqrt(sol[1] * sol[1] + sol[2] * sol[2])
    res[0] = (sol[0] + amp) * inv_r
    res[1] = (sol[0] - amp) * inv_r
    res[2] = 0.5 * math.atan2(sol[2], sol[1])
    res[3] = used
    res[4] = math.sqrt(sse / used) * inv_r


@njit(parallel=True, cache=True)
def curvature_cga(points, query_points, query_normals, indptr, indices, radius, ndir, slab,
                  min_points, min_spread, blend, unit_norm, corrected, half_frequency,
                  robust, k1, k2, d1, d2, n_samples, residual, n_neighbors, rank=None):
    """Fused CGA circle-fit estimator over query points with CSR neighbour lists.

    Parameters
    ----------
    points : (n, 3) float64, the neighbour set
    query_points, query_normals : (m, 3) float64, where to estimate and the unit normals there
    indptr, indices : CSR lists into ``points``: neighbours of query q are
        ``indices[indptr[q]:indptr[q+1]]`` (the query point itself may be present; coincident
        points are skipped)
    radius : float, model units; slab, min_spread : fractions of ``radius``
    blend : (m,) float64 in [0, 1], per query point: 0 equal weights, 1 distance weights
        (1 - r^2 / radius^2)^WEIGHT_POWER, between the two a mix of both weight functions
    unit_norm : bool, circle fits normalised by |t| = 1 (the paper) instead of t1 = 1
    corrected, half_frequency, robust : bool, ``section_blend``, ``half_frequency`` and
        ``robust`` of :func:`meshcurv.principal_curvatures`
    Outputs k1, k2 (m,), d1, d2 (m, 3), n_samples, residual, n_neighbors (m,) are written in
    place; NaN where no estimate is possible.
    rank : (n,) int64, optional, the input index of each row of ``points`` when they are stored
        in another order (e.g. a grid's sorted copy, for memory locality): the tangent frame's
        lowest-index rule then picks the same neighbour as on the input.
    """
    m = query_points.shape[0]
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
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        acc = np.empty((nh, N_ACC))
        kappa = np.empty(nh)
        rows = np.empty((nh, 5))
        active = np.empty(nh)
        scratch = np.empty(nh)
        mat = np.empty((5, 5))
        rhs = np.empty(5)
        sol = np.empty(5)
        b3 = np.empty((3, 3))
        ev = np.empty(3)
        tu = np.empty(3)
        tv = np.empty(3)
        res = np.empty(6)
        x = np.empty(3)
        n = np.empty(3)
        mix = np.empty((nh, 2))
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            for a in range(3):
                x[a] = query_points[q, a]
                n[a] = query_normals[q, a]
            for a in range(6):
                res[a] = np.nan
            res[3] = 0.0
            res[5] = 0.0
            nn = math.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
            if nn > 0.0 and np.isfinite(nn) and np.isfinite(x[0] + x[1] + x[2]):
                for a in range(3):
                    n[a] /= nn
                _estimate_one(points, indices, indptr[q], indptr[q + 1], x, n, radius, ndir,
                              slab, min_points, min_spread, blend[q], unit_norm, corrected,
                              half_frequency, robust, ca, sa, dirs, acc, kappa, rows, active,
                              scratch, mat, rhs, sol, b3, ev, tu, tv, res, rank, mix)
            n_samples[q] = res[3]
            residual[q] = res[4]
            n_neighbors[q] = res[5]
            if np.isfinite(res[0]):
                k1[q] = res[0]
                k2[q] = res[1]
                ct = math.cos(res[2])
                st = math.sin(res[2])
                for a in range(3):
                    d1[q, a] = ct * tu[a] + st * tv[a]
                d2[q, 0] = n[1] * d1[q, 2] - n[2] * d1[q, 1]
                d2[q, 1] = n[2] * d1[q, 0] - n[0] * d1[q, 2]
                d2[q, 2] = n[0] * d1[q, 1] - n[1] * d1[q, 0]
            else:
                k1[q] = np.nan
                k2[q] = np.nan
                for a in range(3):
                    d1[q, a] = np.nan
                    d2[q, a] = np.nan


# Exponents (of u, of v) of the cubic height model's terms, in the order of its coefficients:
# u^2, uv, v^2, u, v, 1, u^3, u^2 v, u v^2, v^3 (the quadric's first six).
_JET_U = np.array([2, 1, 0, 1, 0, 0, 3, 2, 1, 0])
_JET_V = np.array([0, 1, 2, 0, 1, 0, 0, 1, 2, 3])


@njit(cache=True)
def _add_monomials(moments, c, u, v, degree):
    """``moments[a, b] += c u^a v^b`` for every a + b <= ``degree``."""
    cua = c
    for a in range(degree + 1):
        cuv = cua
        for b in range(degree + 1 - a):
            moments[a, b] += cuv
            cuv *= v
        cua *= u


@njit(parallel=True, cache=True)
def local_jet(points, query_points, normals, indptr, indices, radius, refine, noise):
    """Local height fits around each query point: noise level (cubic) and normal (quadric).

    In a frame (tu, tv, n) around each query point x, the heights of its neighbours within
    ``radius`` are fitted by polynomials in (u, v) (least squares with weights
    ``1 - r^2 / radius^2``, x included). The cubic fit's residual (10 coefficients) is what the
    surface's shape up to third order cannot explain: on clean samples of smooth surfaces it
    is below 0.1 % of the radius, with noise it is the noise. With ``refine`` the normal of the
    fitted quadric (6 coefficients; the cubic's gradient at x has 3-5x its variance under
    noise) at x, ``n - g_u tu - g_v tv`` normalised, replaces n: face and PCA normals tilt with
    irregular sampling (0.7 degrees on a randomly sampled sphere at ~100 neighbours), the
    quadric's normal does not. The refined normal stays on n's side.

    Parameters
    ----------
    points : (n, 3) float64; query_points : (m, 3) float64
    normals : (m, 3) float64, unit; refined in place when ``refine``
    indptr, indices : CSR neighbour lists into ``points``; radius : float, model units
    refine : bool
    noise : (m,) float64 output, RMS height residual of the cubic fit (model units, corrected
        for the 10 fitted coefficients); NaN where the fit is singular (fewer than 11
        well-spread points), and there the normal is left unchanged - as it is where the
        quadric would tilt it by more than 30 degrees (no graph over n, e.g. at a crease).
    """
    m = query_points.shape[0]
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        mat = np.empty((10, 10))
        quad = np.empty((6, 6))
        rhs = np.empty(10)
        sol = np.empty(10)
        mom = np.empty((7, 7))
        hmom = np.empty((7, 7))
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            noise[q] = np.nan
            n0 = normals[q, 0]
            n1 = normals[q, 1]
            n2 = normals[q, 2]
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            if not np.isfinite(n0 + n1 + n2 + x0 + x1 + x2):
                continue
            # any tangent frame: the polynomial basis is closed under rotations about n
            if abs(n0) < 0.9:
                t0, t1, t2 = 0.0, -n2, n1          # e_x cross n
            else:
                t0, t1, t2 = n2, 0.0, -n0          # e_y cross n
            s = 1.0 / math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            t0 *= s
            t1 *= s
            t2 *= s
            b0 = n1 * t2 - n2 * t1
            b1 = n2 * t0 - n0 * t2
            b2 = n0 * t1 - n1 * t0
            # power moments: mom[a, b] = sum w u^a v^b (a + b <= 6), hmom[a, b] = sum w h u^a v^b
            # (a + b <= 3); every entry of the normal equations is one of them
            for a in range(7):
                for b in range(7):
                    mom[a, b] = 0.0
                    hmom[a, b] = 0.0
            sw = 1.0
            swhh = 0.0
            count = 1
            for j in range(indptr[q], indptr[q + 1]):
                inside, qx, qy, qz, r2 = _ball_offset(points, indices[j], x0, x1, x2, r2max,
                                                      inv_r)
                if not inside:
                    continue
                u = qx * t0 + qy * t1 + qz * t2
                v = qx * b0 + qy * b1 + qz * b2
                h = qx * n0 + qy * n1 + qz * n2
                w = 1.0 - r2
                _add_monomials(mom, w, u, v, 6)
                _add_monomials(hmom, w * h, u, v, 3)
                sw += w
                swhh += w * h * h
                count += 1
            for a in range(10):
                rhs[a] = hmom[_JET_U[a], _JET_V[a]]
                for cc in range(a + 1):
                    mat[a, cc] = mom[_JET_U[a] + _JET_U[cc], _JET_V[a] + _JET_V[cc]]
            mat[5, 5] += 1.0         # x itself: u = v = h = 0, weight 1
            for a in range(6):             # the quadric's normal equations: the leading block
                for cc in range(a + 1):
                    quad[a, cc] = mat[a, cc]
            if count <= 10 or not _solve_sym(mat, rhs, 10, sol):
                continue
            # weighted residual sum of squares of the least-squares fit: sum w h^2 - sol . rhs
            ss = swhh
            for a in range(10):
                ss -= sol[a] * rhs[a]
            noise[q] = math.sqrt(max(ss, 0.0) / sw * count / (count - 10)) * radius
            if not refine or not _solve_sym(quad, rhs, 6, sol):
                continue
            if sol[3] * sol[3] + sol[4] * sol[4] > 1.0 / 3.0:
                continue
            g0 = n0 - sol[3] * t0 - sol[4] * b0
            g1 = n1 - sol[3] * t1 - sol[4] * b1
            g2 = n2 - sol[3] * t2 - sol[4] * b2
            s = 1.0 / math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
            normals[q, 0] = g0 * s
            normals[q, 1] = g1 * s
            normals[q, 2] = g2 * s


@njit(cache=True)
def edge_adjacency_csr(faces, n):
    """Undirected edge graph of a triangle mesh as CSR ``(indptr, indices)``, sorted, unique.

    ``indptr`` is int64, ``indices`` int32 (vertex numbers below 2**31; half the memory).

    Every face contributes its three edges in both directions (self-loops of degenerate faces
    are dropped); each vertex's row is then sorted and deduplicated in place.
    """
    m = faces.shape[0]
    start = np.zeros(n + 1, dtype=np.int64)
    for f in range(m):
        for c in range(3):
            a = faces[f, c]
            b = faces[f, (c + 1) % 3]
            if a != b:
                start[a + 1] += 1
                start[b + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start[:n].copy()
    idx = np.empty(start[n], dtype=np.int32)
    for f in range(m):
        for c in range(3):
            a = faces[f, c]
            b = faces[f, (c + 1) % 3]
            if a != b:
                idx[fill[a]] = b
                fill[a] += 1
                idx[fill[b]] = a
                fill[b] += 1
    indptr = np.zeros(n + 1, dtype=np.int64)
    out = 0
    for i in range(n):
        lo = start[i]
        hi = start[i + 1]
        # insertion sort: rows hold ~12 entries
        for j in range(lo + 1, hi):
            key = idx[j]
            k = j - 1
            while k >= lo and idx[k] > key:
                idx[k + 1] = idx[k]
                k -= 1
            idx[k + 1] = key
        # compaction never overtakes the unsorted rows ahead: out <= lo
        prev = -1
        for j in range(lo, hi):
            if idx[j] != prev:
                prev = idx[j]
                idx[out] = prev
                out += 1
        indptr[i + 1] = out
    return indptr, idx[:out].copy()


@njit(cache=True)
def _kring_one(adj_ptr, adj_idx, points, s, tag, r2max, stamp, queue, out, base, limit):
    """Breadth-first, radius-limited k-ring of vertex ``s``; the connected, radius-limited
    neighbourhood that cannot jump across a thin sheet.

    Writes the neighbours found to ``out[base:]`` as long as they fit below ``limit`` and returns
    how many there are (so a caller can detect an overflow). ``stamp`` marks visited vertices
    with ``tag``, a value unique to this search.
    """
    x0 = points[s, 0]
    x1 = points[s, 1]
    x2 = points[s, 2]
    if not np.isfinite(x0 + x1 + x2):
        return 0
    stamp[s] = tag
    head = 0
    tail = 1
    queue[0] = s
    found = 0
    while head < tail:
        a = queue[head]
        head += 1
        for e in range(adj_ptr[a], adj_ptr[a + 1]):
            b = adj_idx[e]
            if stamp[b] == tag:
                continue
            stamp[b] = tag
            d0 = points[b, 0] - x0
            d1 = points[b, 1] - x1
            d2 = points[b, 2] - x2
            if d0 * d0 + d1 * d1 + d2 * d2 <= r2max:
                queue[tail] = b
                tail += 1
                if base + found < limit:
                    out[base + found] = b
                found += 1
    return found


@njit(parallel=True, cache=True)
def kring_ball_csr(adj_ptr, adj_idx, points, query, radius, stamp, queue, tag0):
    """Radius-limited k-ring CSR lists, one breadth-first search per query vertex.

    Lists exclude the query vertex and are in breadth-first order. Each thread streams its
    results into an int32 scratch sized from a sample of 64 queries, copied once; a thread
    whose stream overflows searches its range again.
    ``stamp`` (threads, n) int32 or int64 and ``queue`` (threads, n) int32 are reusable work
    arrays (``stamp`` starts at -1); ``tag0`` is an offset that makes this call's stamps
    unique: pass a different ``tag0`` per call (e.g. the position of the block), with
    ``3 * (tag0 + len(query)) + 2`` representable in ``stamp``'s type.
    """
    m = query.shape[0]
    r2max = radius * radius
    counts = np.zeros(m + 1, dtype=np.int64)
    nthreads = max(1, min(m, stamp.shape[0]))
    per = (m + nthreads - 1) // nthreads
    # stamps 3 * (tag0 + qi) + {0: sample, 1: stream, 2: repeat} are unique across uses
    dummy = np.empty(0, dtype=np.int32)
    step = max(1, m // 64)
    tot = 0
    cnt = 0
    for qi in range(0, m, step):
        tot += _kring_one(adj_ptr, adj_idx, points, query[qi], 3 * (tag0 + qi), r2max,
                          stamp[0], queue[0], dummy, 0, 0)
        cnt += 1
    cap = 16 + (3 * tot) // (2 * max(cnt, 1))
    buf = np.empty(nthreads * per * cap, dtype=np.int32)
    used = np.zeros(nthreads, dtype=np.int64)
    for t in prange(nthreads):
        lo = t * per * cap
        limit = lo + per * cap
        pos = lo
        for qi in range(t * per, min(m, (t + 1) * per)):
            f = _kring_one(adj_ptr, adj_idx, points, query[qi], 3 * (tag0 + qi) + 1, r2max,
                           stamp[t], queue[t], buf, pos, limit)
            counts[qi + 1] = f
            pos += f
        used[t] = pos - lo
    for i in range(m):
        counts[i + 1] += counts[i]
    indices = np.empty(counts[m], dtype=np.int64)
    for t in prange(nthreads):
        q0 = t * per
        q1 = min(m, (t + 1) * per)
        if used[t] <= per * cap:
            lo = t * per * cap
            o = counts[min(q0, m)]
            for j in range(used[t]):
                indices[o + j] = buf[lo + j]
        else:
            for qi in range(q0, q1):
                _kring_one(adj_ptr, adj_idx, points, query[qi], 3 * (tag0 + qi) + 2, r2max,
                           stamp[t], queue[t], indices, counts[qi], counts[qi + 1])
    return counts, indices


@njit(parallel=True, cache=True)
def kring_counts(adj_ptr, adj_idx, points, query, radius, stamp, queue, tag0):
    """(m,) int64 size of each query vertex's radius-limited k-ring (what
    :func:`kring_ball_csr` would list, nothing stored: to size the work before doing it).
    Work arrays and ``tag0`` as there."""
    m = query.shape[0]
    r2max = radius * radius
    out = np.zeros(m, dtype=np.int64)
    nthreads = max(1, min(m, stamp.shape[0]))
    per = (m + nthreads - 1) // nthreads
    dummy = np.empty(0, dtype=np.int32)
    for t in prange(nthreads):
        for qi in range(t * per, min(m, (t + 1) * per)):
            out[qi] = _kring_one(adj_ptr, adj_idx, points, query[qi], 3 * (tag0 + qi), r2max,
                                 stamp[t], queue[t], dummy, 0, 0)
    return out


@njit(parallel=True, cache=True)
def pca_normals_csr(points, query_points, indptr, indices, radius):
    """Unit normals (m, 3) of the least-squares plane through each query point's neighbours.

    The covariance of the neighbours within ``radius`` (the point included) is accumulated
    about the query point in units of ``radius`` (precise at large offsets) and corrected to
    the centroid; its smallest eigenvector comes from Jacobi rotations. NaN rows
    where fewer than 3 points lie in the ball or the covariance is not finite. Signs are
    arbitrary (the orientation step fixes them).
    """
    m = query_points.shape[0]
    out = np.full((m, 3), np.nan)
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        cov = np.empty((3, 3))
        ev = np.empty(3)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            s0 = s1 = s2 = 0.0
            s00 = s01 = s02 = s11 = s12 = s22 = 0.0
            c = 1
            for j in range(indptr[q], indptr[q + 1]):
                inside, a, b, d, _ = _ball_offset(points, indices[j], x0, x1, x2, r2max, inv_r)
                if not inside:
                    continue
                c += 1
                s0 += a
                s1 += b
                s2 += d
                s00 += a * a
                s01 += a * b
                s02 += a * d
                s11 += b * b
                s12 += b * d
                s22 += d * d
            if c < 3:
                continue
            m0 = s0 / c
            m1 = s1 / c
            m2 = s2 / c
            cov[0, 0] = s00 / c - m0 * m0
            cov[0, 1] = s01 / c - m0 * m1
            cov[0, 2] = s02 / c - m0 * m2
            cov[1, 1] = s11 / c - m1 * m1
            cov[1, 2] = s12 / c - m1 * m2
            cov[2, 2] = s22 / c - m2 * m2
            cov[1, 0] = cov[0, 1]
            cov[2, 0] = cov[0, 2]
            cov[2, 1] = cov[1, 2]
            ok = True
            for i in range(3):
                for j in range(3):
                    if not np.isfinite(cov[i, j]):
                        ok = False
            if not ok:
                continue
            _smallest_eigvec_jacobi3(cov, ev)
            out[q, 0] = ev[0]
            out[q, 1] = ev[1]
            out[q, 2] = ev[2]
    return out


# ---------------------------------------------------------------------------------------------
# Cell grids for ball queries (speed; see scripts/bench.py): dense, or hashed for sparse extents.
#
# Cells of edge >= radius numbered x-major, z fastest: the three cells (ax, ay, cz-1..cz+1) of a
# column are consecutive, so a ball query scans 9 contiguous runs of a copy of the points sorted
# by cell, instead of 27 cells scattered through the input.
#
# Ball grids number their cells on one lattice, floor(coordinate / cell), whatever the points'
# extent: a subset (a tile) gets the cells of the whole cloud, and a far-away point its own cell
# without stretching anyone else's. Numbers are clamped to +-2**61 (points beyond share the
# last cell), so any finite coordinate gives an int64 whose differences cannot overflow.


@njit(cache=True)
def _cell_coord(value, origin, inv, size):
    c = math.floor((value - origin) * inv)
    return np.int64(min(max(c, -1.0), float(size)))


@njit(cache=True)
def cell_grid_build(points, finite_index, origin, cell, dims):
    """Counting sort of ``points[finite_index]`` into a dense grid of ``dims`` cells of edge ``cell``.

    Returns ``(order, sorted_points, cell_start)``: ``order`` (k,) int64 lists point indices cell
    by cell (ascending within a cell), ``sorted_points`` (k, 3) their coordinates in that order,
    and cell ``(cx * ny + cy) * nz + cz`` holds positions ``cell_start[c]:cell_start[c + 1]``.
    Every point must lie inside the grid (``origin`` at least one cell below the minimum).
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    k = finite_index.shape[0]
    inv = 1.0 / cell
    keys = np.empty(k, dtype=np.int64)
    cell_start = np.zeros(nx * ny * nz + 1, dtype=np.int64)
    for j in range(k):
        i = finite_index[j]
        cx = _cell_coord(points[i, 0], origin[0], inv, nx)
        cy = _cell_coord(points[i, 1], origin[1], inv, ny)
        cz = _cell_coord(points[i, 2], origin[2], inv, nz)
        key = (cx * ny + cy) * nz + cz
        keys[j] = key
        cell_start[key + 1] += 1
    return _scatter_by_key(points, finite_index, keys, cell_start)


@njit(cache=True)
def _scatter_by_key(points, finite_index, keys, cell_start):
    """Counting sort's second half: ``cell_start`` holds the counts of each key shifted by one."""
    k = finite_index.shape[0]
    for c in range(cell_start.shape[0] - 1):
        cell_start[c + 1] += cell_start[c]
    fill = cell_start[:-1].copy()
    order = np.empty(k, dtype=np.int64)
    sorted_points = np.empty((k, 3))
    for j in range(k):
        pos = fill[keys[j]]
        fill[keys[j]] += 1
        i = finite_index[j]
        order[pos] = i
        sorted_points[pos, 0] = points[i, 0]
        sorted_points[pos, 1] = points[i, 1]
        sorted_points[pos, 2] = points[i, 2]
    return order, sorted_points, cell_start


LATTICE_LIMIT = float(2 ** 61)


@njit(cache=True)
def _lattice_index(value, inv):
    """Lattice cell number floor(value * inv), clamped to +-2**61 (NaN to the lower end)."""
    c = value * inv
    if not c > -LATTICE_LIMIT:
        return np.int64(-LATTICE_LIMIT)
    if c > LATTICE_LIMIT:
        return np.int64(LATTICE_LIMIT)
    return np.int64(math.floor(c))


@njit(parallel=True, cache=True)
def lattice_cells(points, finite_index, cell):
    """(k, 3) int64 lattice cell numbers of ``points[finite_index]`` for cells of edge ``cell``."""
    k = finite_index.shape[0]
    inv = 1.0 / cell
    out = np.empty((k, 3), dtype=np.int64)
    for j in prange(k):
        for a in range(3):
            out[j, a] = _lattice_index(points[finite_index[j], a], inv)
    return out


@njit(cache=True)
def dense_grid_build(points, finite_index, cells, base, dims):
    """Counting sort of ``points[finite_index]`` by their lattice ``cells`` (from
    :func:`lattice_cells`) into the dense block of ``dims`` cells starting at cell ``base``.

    Returns ``(order, sorted_points, cell_start)`` as :func:`cell_grid_build`; cell
    ``((cx - bx) * ny + cy - by) * nz + cz - bz`` holds positions ``cell_start[c]:cell_start[c + 1]``.
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    k = finite_index.shape[0]
    keys = np.empty(k, dtype=np.int64)
    cell_start = np.zeros(nx * ny * nz + 1, dtype=np.int64)
    for j in range(k):
        # clamped only as a guard: the caller's block holds every cell
        cx = min(max(cells[j, 0] - base[0], 0), nx - 1)
        cy = min(max(cells[j, 1] - base[1], 0), ny - 1)
        cz = min(max(cells[j, 2] - base[2], 0), nz - 1)
        key = (cx * ny + cy) * nz + cz
        keys[j] = key
        cell_start[key + 1] += 1
    return _scatter_by_key(points, finite_index, keys, cell_start)


# Grid keys pack three cell coordinates modulo 2**21; a hash table maps keys to cells. Cells a
# multiple of 2**21 apart share a key: they merge into one bucket, which costs a few distance
# tests where it happens (a far outlier) but loses nothing.
_GRID_BITS = 21
_GRID_MASK = (1 << _GRID_BITS) - 1


@njit(cache=True)
def _grid_key(cx, cy, cz):
    return (((cx & _GRID_MASK) << (2 * _GRID_BITS)) | ((cy & _GRID_MASK) << _GRID_BITS)
            | (cz & _GRID_MASK))


@njit(cache=True)
def _hash_slot(key, mask):
    h = (key * 0x9E3779B97F4A7C15) & 0x7FFFFFFFFFFFFFFF
    return (h >> 17) & mask


@njit(cache=True)
def hashed_grid_build(points, finite_index, cells):
    """Uniform grid over ``points[finite_index]`` by their lattice ``cells`` (from
    :func:`lattice_cells`), only the occupied cells stored: memory in the number of points
    whatever the extent.

    The sparse counterpart of :func:`dense_grid_build`, for extents where a dense grid would
    hold too many empty cells. Returns ``(order, sorted_points, cell_start, table_keys,
    table_cells)``: ``order`` lists the point indices cell by cell (ascending within a cell),
    ``sorted_points`` their coordinates in that order, occupied cell ``c`` holds positions
    ``cell_start[c]:cell_start[c + 1]``, and the open-addressing hash table
    ``table_keys``/``table_cells`` (-1 = empty) maps packed cell keys to cells.
    """
    k = finite_index.shape[0]
    keys = np.empty(k, dtype=np.int64)
    for j in range(k):
        keys[j] = _grid_key(cells[j, 0], cells[j, 1], cells[j, 2])
    srt = np.argsort(keys, kind="mergesort")  # stable: ascending point index within a cell
    order = finite_index[srt]
    sorted_points = np.empty((k, 3))
    for j in range(k):
        sorted_points[j, 0] = points[order[j], 0]
        sorted_points[j, 1] = points[order[j], 1]
        sorted_points[j, 2] = points[order[j], 2]
    ncell = 0
    for j in range(k):
        if j == 0 or keys[srt[j]] != keys[srt[j - 1]]:
            ncell += 1
    cell_start = np.empty(ncell + 1, dtype=np.int64)
    size = 16
    while size < 2 * ncell:
        size *= 2
    mask = size - 1
    table_keys = np.full(size, -1, dtype=np.int64)
    table_cells = np.full(size, -1, dtype=np.int64)
    c = -1
    for j in range(k):
        key = keys[srt[j]]
        if j == 0 or key != keys[srt[j - 1]]:
            c += 1
            cell_start[c] = j
            slot = _hash_slot(key, mask)
            while table_keys[slot] != -1:
                slot = (slot + 1) & mask
            table_keys[slot] = key
            table_cells[slot] = c
    cell_start[ncell] = k
    return order, sorted_points, cell_start, table_keys, table_cells


# Most cell numbers one axis of a ball query visits (see _axis_window).
WINDOW = 64


@njit(cache=True)
def _axis_window(x, cell, inv, out):
    """Lattice cell numbers, ascending, of every float within ``cell`` of ``x`` along one axis;
    their count.

    The numbers of ``x - cell`` and ``x + cell`` bound them (rounding is monotone, so no float
    between the two gets a number outside), and are adjacent to ``x``'s own but where
    ``|x| / cell`` exceeds ~2**50 and rounding makes the numbers jump: there the few floats in
    the window are enumerated, so that a query never visits more than a few cells.
    """
    lo = _lattice_index(x - cell, inv)
    hi = _lattice_index(x + cell, inv)
    if hi - lo <= 3:
        for a in range(hi - lo + 1):
            out[a] = lo + a
        return hi - lo + 1
    count = 0
    p = x - cell
    end = x + cell
    for _ in range(out.shape[0]):
        if not p <= end:
            break
        c = _lattice_index(p, inv)
        if count == 0 or c != out[count - 1]:
            out[count] = c
            count += 1
        p = np.nextafter(p, np.inf)
    return count


@njit(cache=True)
def _scan_run(order, sorted_points, j0, j1, x0, x1, x2, r2max, out, base, found, limit,
              positions):
    """Append the grid positions ``j0:j1`` within ``sqrt(r2max)`` of (x0, x1, x2) to
    ``out[base + found:]`` (as far as ``limit`` allows); returns the new count."""
    for j in range(j0, j1):
        d0 = sorted_points[j, 0] - x0
        d1 = sorted_points[j, 1] - x1
        d2 = sorted_points[j, 2] - x2
        if d0 * d0 + d1 * d1 + d2 * d2 <= r2max:
            if base + found < limit:
                out[base + found] = j if positions else order[j]
            found += 1
    return found


@njit(cache=True)
def _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims, table_keys,
                   table_cells, x0, x1, x2, r2max, out, base, limit, ascending, positions, win):
    """Indices of the grid points within ``sqrt(r2max)`` of (x0, x1, x2).

    The cells of the query's window along each axis (:func:`_axis_window`; usually the 3 x 3 x 3
    cells around the query's own), x-major and z fastest. Dense grid (``table_keys`` empty):
    those within the block, contiguous z runs scanned at once. Hashed grid: each cell looked up
    by its key. Both list the same points in the same order. Writes to ``out[base:]`` as far as
    ``limit`` allows and returns the count. With ``ascending`` (and if all fit) they are sorted,
    else in grid order. With ``positions`` they are rows of ``sorted_points`` instead of point
    indices. ``win`` is (3, WINDOW) int64 scratch.
    """
    if not np.isfinite(x0 + x1 + x2):
        return 0
    inv = 1.0 / cell
    n0 = _axis_window(x0, cell, inv, win[0])
    n1 = _axis_window(x1, cell, inv, win[1])
    n2 = _axis_window(x2, cell, inv, win[2])
    found = 0
    if table_keys.shape[0] > 0:
        mask = table_keys.shape[0] - 1
        for a in range(n0):
            for b in range(n1):
                for c in range(n2):
                    key = _grid_key(win[0, a], win[1, b], win[2, c])
                    slot = _hash_slot(key, mask)
                    while table_keys[slot] != -1 and table_keys[slot] != key:
                        slot = (slot + 1) & mask
                    if table_keys[slot] == key:
                        cc = table_cells[slot]
                        found = _scan_run(order, sorted_points, cell_start[cc],
                                          cell_start[cc + 1], x0, x1, x2, r2max, out, base,
                                          found, limit, positions)
    else:
        nx, ny, nz = dims[0], dims[1], dims[2]
        contiguous = win[2, n2 - 1] - win[2, 0] == n2 - 1
        z0 = max(win[2, 0] - grid_base[2], 0)
        z1 = min(win[2, n2 - 1] - grid_base[2], nz - 1)
        for a in range(n0):
            ax = win[0, a] - grid_base[0]
            if ax < 0 or ax >= nx:
                continue
            for b in range(n1):
                ay = win[1, b] - grid_base[1]
                if ay < 0 or ay >= ny:
                    continue
                col = (ax * ny + ay) * nz
                if contiguous:
                    if z0 <= z1:
                        found = _scan_run(order, sorted_points, cell_start[col + z0],
                                          cell_start[col + z1 + 1], x0, x1, x2, r2max, out,
                                          base, found, limit, positions)
                    continue
                for c in range(n2):
                    az = win[2, c] - grid_base[2]
                    if az >= 0 and az < nz:
                        found = _scan_run(order, sorted_points, cell_start[col + az],
                                          cell_start[col + az + 1], x0, x1, x2, r2max, out,
                                          base, found, limit, positions)
    if ascending and base + found <= limit:
        _shell_sort(out, base, base + found)
    return found


@njit(cache=True)
def _shell_sort(a, lo, hi):
    """Sort ``a[lo:hi]`` in place; for the ~100 entries of a neighbour list about twice as fast
    as ``ndarray.sort`` (which sets up a quicksort stack per call)."""
    for gap in (57, 23, 10, 4, 1):
        for j in range(lo + gap, hi):
            key = a[j]
            k = j - gap
            while k >= lo and a[k] > key:
                a[k + gap] = a[k]
                k -= gap
            a[k + gap] = key


@njit(parallel=True, cache=True)
def cell_ball_counts(order, sorted_points, cell_start, grid_base, cell, dims, table_keys,
                     table_cells, query_points, radius):
    """(m,) int64 number of grid points within ``radius`` of each query point (nothing
    stored: what :func:`cell_ball_csr` would list, to size the work before doing it)."""
    m = query_points.shape[0]
    r2max = radius * radius
    counts = np.zeros(m, dtype=np.int64)
    dummy = np.empty(0, dtype=np.int64)
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        win = np.empty((3, WINDOW), dtype=np.int64)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            counts[q] = _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims,
                                       table_keys, table_cells, query_points[q, 0],
                                       query_points[q, 1], query_points[q, 2], r2max, dummy, 0,
                                       0, False, False, win)
    return counts


@njit(parallel=True, cache=True)
def cell_ball_csr(order, sorted_points, cell_start, grid_base, cell, dims, table_keys,
                  table_cells, query_points, radius, nthreads, ascending, positions):
    """All grid points within ``radius`` of each query point, CSR.

    Each list is ascending with ``ascending``, else in grid order (cheaper; for consumers that
    do not depend on the order). With ``positions`` the lists hold rows of ``sorted_points``
    (whose neighbourhoods then lie close together in memory) instead of point indices.

    The grid comes from :func:`dense_grid_build` (``table_keys`` empty; ``grid_base`` and
    ``dims`` its block of cells) or :func:`hashed_grid_build` (``grid_base``, ``dims`` unused),
    with ``cell >= radius``. Each thread streams its contiguous range of queries into its own
    slice of a scratch buffer sized from a sample of the queries; a thread whose slice
    overflows searches its range again into the output.
    """
    m = query_points.shape[0]
    r2max = radius * radius
    counts = np.zeros(m + 1, dtype=np.int64)
    nthreads = max(1, min(m, nthreads))
    per = (m + nthreads - 1) // nthreads
    dummy = np.empty(0, dtype=np.int64)
    win0 = np.empty((3, WINDOW), dtype=np.int64)
    step = max(1, m // 64)
    tot = 0
    cnt = 0
    for qi in range(0, m, step):
        tot += _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims,
                              table_keys, table_cells,
                              query_points[qi, 0], query_points[qi, 1], query_points[qi, 2],
                              r2max, dummy, 0, 0, False, False, win0)
        cnt += 1
    cap = 16 + (3 * tot) // (2 * max(cnt, 1))
    buf = np.empty(nthreads * per * cap, dtype=np.int64)
    used = np.zeros(nthreads, dtype=np.int64)
    for t in prange(nthreads):
        win = np.empty((3, WINDOW), dtype=np.int64)
        lo = t * per * cap
        limit = lo + per * cap
        pos = lo
        for qi in range(t * per, min(m, (t + 1) * per)):
            f = _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims,
                               table_keys, table_cells,
                               query_points[qi, 0], query_points[qi, 1], query_points[qi, 2],
                               r2max, buf, pos, limit, ascending, positions, win)
            counts[qi + 1] = f
            pos += f
        used[t] = pos - lo
    for i in range(m):
        counts[i + 1] += counts[i]
    indices = np.empty(counts[m], dtype=np.int64)
    for t in prange(nthreads):
        q0 = t * per
        if q0 >= m:
            continue
        q1 = min(m, (t + 1) * per)
        if used[t] <= per * cap:
            lo = t * per * cap
            o = counts[q0]
            for j in range(used[t]):
                indices[o + j] = buf[lo + j]
        else:
            win = np.empty((3, WINDOW), dtype=np.int64)
            for qi in range(q0, q1):
                _cell_ball_one(order, sorted_points, cell_start, grid_base, cell, dims,
                               table_keys, table_cells,
                               query_points[qi, 0], query_points[qi, 1], query_points[qi, 2],
                               r2max, indices, counts[qi], counts[qi + 1],
                               ascending, positions, win)
    return counts, indices


# ---------------------------------------------------------------------------------------------
# Normal orientation over a k-nearest-neighbour graph (speed; see scripts/bench.py).


@njit(parallel=True, cache=True)
def nearest_in_lists(points, query_points, indptr, indices, k):
    """The ``k`` nearest neighbours of each query point among its CSR neighbour list.

    Returns (m, k) int64 point indices, nearest first, padded with -1; points coinciding with
    the query point (the point itself) are left out.
    """
    m = query_points.shape[0]
    out = np.full((m, k), -1, dtype=np.int64)
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        best = np.empty(k)
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            have = 0
            for j in range(indptr[q], indptr[q + 1]):
                i = indices[j]
                d0 = points[i, 0] - x0
                d1 = points[i, 1] - x1
                d2 = points[i, 2] - x2
                dd = d0 * d0 + d1 * d1 + d2 * d2
                if not dd > 0.0 or (have == k and dd >= best[k - 1]):
                    continue
                # insert into the sorted list of the best so far
                s = min(have, k - 1)
                while s > 0 and best[s - 1] > dd:
                    best[s] = best[s - 1]
                    out[q, s] = out[q, s - 1]
                    s -= 1
                best[s] = dd
                out[q, s] = i
                have = min(have + 1, k)
    return out


@njit(cache=True)
def _find_root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def orient_spanning_tree(normals, neighbors, levels):
    """Consistent signs of unit normals along a minimum spanning tree of a neighbour graph.

    The graph joins each point i to ``neighbors[i]`` ((n, k) int, -1 = none) with weight
    ``1 - |n_i . n_j|`` (Hoppe et al. 1992). Kruskal's algorithm runs on the weights rounded to
    ``levels`` steps of ``sqrt(w)`` (a counting sort instead of a comparison sort; ties go to the
    lower edge number), then each tree is traversed breadth-first from its lowest vertex and
    every normal is flipped to agree with its parent. Points with NaN normals stay alone.
    ``n * k`` must stay below 2**31 (edge numbers are int32).
    ``normals`` (n, 3) is modified in place. Returns (n,) int64 labels: the root of each
    point's tree.
    """
    n, k = neighbors.shape
    ne = n * k
    level = np.full(ne, -1, dtype=np.int32)
    count = np.zeros(levels + 1, dtype=np.int64)
    for i in range(n):
        for a in range(k):
            j = neighbors[i, a]
            if j < 0:
                continue
            if j < i:
                # an edge listed from both ends is sorted once
                dup = False
                for b in range(k):
                    if neighbors[j, b] == i:
                        dup = True
                if dup:
                    continue
            c = abs(normals[i, 0] * normals[j, 0] + normals[i, 1] * normals[j, 1]
                    + normals[i, 2] * normals[j, 2])
            if not np.isfinite(c):
                continue
            lv = np.int32(math.sqrt(max(1.0 - c, 0.0)) * (levels - 1))
            level[i * k + a] = lv
            count[lv + 1] += 1
    for b in range(levels):
        count[b + 1] += count[b]
    sorted_edges = np.empty(count[levels], dtype=np.int32)
    for e in range(ne):
        if level[e] >= 0:
            sorted_edges[count[level[e]]] = e
            count[level[e]] += 1
    # Kruskal: tree edges as (i, j) pairs
    parent = np.arange(n)
    tree_a = np.empty(n, dtype=np.int64)
    tree_b = np.empty(n, dtype=np.int64)
    nt = 0
    for e in sorted_edges:
        i = e // k
        j = neighbors[i, e % k]
        ri = _find_root(parent, i)
        rj = _find_root(parent, j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
            tree_a[nt] = i
            tree_b[nt] = j
            nt += 1
    # tree adjacency (CSR) and breadth-first sign propagation from each root
    start = np.zeros(n + 1, dtype=np.int64)
    for t in range(nt):
        start[tree_a[t] + 1] += 1
        start[tree_b[t] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start[:n].copy()
    adj = np.empty(2 * nt, dtype=np.int64)
    for t in range(nt):
        adj[fill[tree_a[t]]] = tree_b[t]
        fill[tree_a[t]] += 1
        adj[fill[tree_b[t]]] = tree_a[t]
        fill[tree_b[t]] += 1
    labels = np.empty(n, dtype=np.int64)
    seen = np.zeros(n, dtype=np.bool_)
    queue = np.empty(n, dtype=np.int64)
    for r in range(n):
        if seen[r]:
            continue
        seen[r] = True
        labels[r] = r
        head = 0
        tail = 1
        queue[0] = r
        while head < tail:
            a = queue[head]
            head += 1
            for e in range(start[a], start[a + 1]):
                b = adj[e]
                if seen[b]:
                    continue
                seen[b] = True
                labels[b] = r
                if (normals[a, 0] * normals[b, 0] + normals[a, 1] * normals[b, 1]
                        + normals[a, 2] * normals[b, 2]) < 0.0:
                    normals[b, 0] = -normals[b, 0]
                    normals[b, 1] = -normals[b, 1]
                    normals[b, 2] = -normals[b, 2]
                queue[tail] = b
                tail += 1
    return labels


def cache_is_warm():
    """Whether numba's on-disk cache holds the curvature kernel compiled from this source.

    False means the next call compiles the kernels (the first run after installing or
    updating meshcurv, ~30 s on 2 cores; cached afterwards). True when it cannot be told.
    """
    try:
        return bool(curvature_cga._cache._cache_file._load_index())
    except Exception:    # numba internals moved: say nothing rather than fail
        return True
