"""Ring jets: quartic height fits over a vertex's nearest rings, a small and a larger support,
for the shape operator of clean, finely sampled surfaces. Compiled kernel; its numpy
specification is :func:`meshcurv.fit.ring_jet_spec.ring_jet`.

A quartic height function fitted by plain least squares to a vertex's 3-ring (about 37
points on a regular mesh) has a curvature error of the sampling's order h^3 where the data
are clean, and takes up a curvature that varies across the support; circle fits over a ball
of ~100 points fit constant-curvature arcs to normal sections and are biased there (clean
ellipsoids, random samplings). Under noise the small support multiplies the noise: the
fit's residuals bound by how much (:mod:`meshcurv.jet_blend` weighs it).
"""

import math

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK, inverse_entry, normal_frame, solve_sym
from .jet import _JET_U, _JET_V, _QUARTIC, _add_monomials

__all__ = ["ring_jet", "COEFFICIENTS", "MIN_ROWS", "ROUNDING"]

# The quartic's coefficients.
COEFFICIENTS = _QUARTIC

# Fewest points (the vertex included) of a support: the quartic's 15 coefficients and 3
# degrees of freedom for its residual (the standard error needs some).
MIN_ROWS = 18
# Half a unit in the last place: the stored coordinates' rounding, relative to their size.
ROUNDING = 2.0 ** -53


@njit(cache=True)
def _in_frame(points, k, s, x0, x1, x2, inv, frame):
    """``(usable, u, v, h)``: the offset of ``points[k]`` from x = (x0, x1, x2) times ``inv``
    in the frame's rows (tu, tv, n); not usable where k is x's own row ``s`` or the offset is
    not finite."""
    d0 = (points[k, 0] - x0) * inv
    d1 = (points[k, 1] - x1) * inv
    d2 = (points[k, 2] - x2) * inv
    if k == s or not np.isfinite(d0 + d1 + d2):
        return False, 0.0, 0.0, 0.0
    return (True, d0 * frame[0, 0] + d1 * frame[0, 1] + d2 * frame[0, 2],
            d0 * frame[1, 0] + d1 * frame[1, 1] + d2 * frame[1, 2],
            d0 * frame[2, 0] + d1 * frame[2, 1] + d2 * frame[2, 2])


@njit(cache=True)
def _quartic_at(sol, u, v):
    """The height of the quartic with coefficients ``sol`` (the order of
    :data:`meshcurv.fit.jet._JET_U`) at (u, v): the sum of ``sol[a] u^i v^j``, each power
    formed once as numba forms ``u ** i`` for an integer i (by squaring: u^3 = u u^2, u^4 =
    u^2 u^2): the same to the bit as the sum written with ``**``, which took the kernel a
    fifth longer on a 300k-vertex torus (0.60 against 0.49 s)."""
    u2 = u * u
    v2 = v * v
    pu = (1.0, u, u2, u * u2, u2 * u2)
    pv = (1.0, v, v2, v * v2, v2 * v2)
    total = 0.0
    for a in range(_QUARTIC):
        total += sol[a] * pu[_JET_U[a]] * pv[_JET_V[a]]
    return total


@njit(cache=True)
def _shape_operator(sol, inv_scale, out, q):
    """``out[q] = (S_uu, S_uv, S_vv)``: the shape operator at u = v = 0 of the height function
    whose quadric and linear coefficients are ``sol[0:5]`` (u^2, uv, v^2, u, v; coordinates
    divided by ``1 / inv_scale``), in an orthonormal basis of its tangent plane that is the
    frame's (tu, tv) tilted onto that plane: ``-P H P / W`` with H the height's Hessian,
    ``W = sqrt(1 + |g|^2)`` and ``P = I^(-1/2)`` of its first fundamental form
    ``I = 1 + g g^T`` (g the gradient). Convex positive along the frame's normal (heights
    along it fall away from a convex cap)."""
    gu, gv = sol[3], sol[4]
    huu, huv, hvv = 2.0 * sol[0], sol[1], 2.0 * sol[2]
    g2 = gu * gu + gv * gv
    w = math.sqrt(1.0 + g2)
    p00, p01, p11 = 1.0, 0.0, 1.0
    if g2 > 0.0:
        a = (1.0 - 1.0 / w) / g2
        p00 = 1.0 - a * gu * gu
        p01 = -a * gu * gv
        p11 = 1.0 - a * gv * gv
    # H P, then P (H P)
    m00 = huu * p00 + huv * p01
    m01 = huu * p01 + huv * p11
    m10 = huv * p00 + hvv * p01
    m11 = huv * p01 + hvv * p11
    f = -inv_scale / w
    out[q, 0] = f * (p00 * m00 + p01 * m10)
    out[q, 1] = f * (p00 * m01 + p01 * m11)
    out[q, 2] = f * (p01 * m01 + p11 * m11)


@njit(parallel=True, cache=True)
def ring_jet(points, query, normals, indptr, indices, inner, small, large, error, frame_u,
             rows_small):
    """Quartic height fits around each query vertex over two nested supports.

    In a frame (tu, tv, n) at x = ``points[query[q]]``, the heights along n of x and of its
    neighbours ``indices[indptr[q]:indptr[q + 1]]`` are fitted by a quartic in (u, v) (15
    coefficients, plain least squares, coordinates divided by the RMS distance of the small
    support's neighbours): once over x and the first ``inner[q]`` of them (the small
    support: a mesh's 3-ring, a cloud's 36 nearest), once over all (the larger support).
    Entries equal to ``query[q]`` and neighbours with non-finite coordinates are skipped.

    Parameters
    ----------
    points : (n, 3) float64, model units
    query : (m,) int64, the vertices (rows of ``points``) to fit at
    normals : (m, 3) float64, unit normal at each query vertex (outward: convex positive)
    indptr, indices : CSR neighbour lists into ``points``, one row per query vertex
    inner : (m,) int64, how many leading entries of each list form the small support
    small, large : (m, 3) float64 outputs, ``(S_uu, S_uv, S_vv)`` of each fit's shape
        operator (1 / model units) in the frame (tu, tv) (see :func:`_shape_operator`); NaN
        where a support holds fewer than :data:`MIN_ROWS` points or its fit is singular
    error : (m,) float64 output, the small fit's misfit bound on the shape operator's
        entries (the largest of the three; 1 / model units): ``sqrt(RSS * (A^T A)^-1_kk)``
        (times 2 for S_uu and S_vv), the most its residuals could move the entry if they
        were the shape's rather than noise (Cauchy-Schwarz on the entry's least-squares
        weights); ``sqrt(rows - 15)`` times the standard error independent noise would give.
        Each residual counts at least the rounding of the stored coordinates,
        ``ROUNDING * max|x_i|``: where the quartic holds the points exactly (a sphere's tiny
        cap, a clump) the jet is no more exact than they are
    frame_u : (m, 3) float64 output, tu (unit, normal to n; tv = n x tu); NaN where x or n
        is not finite
    rows_small : (m,) int64 output, the points of the small fit (x included): ``error``
        over ``sqrt(rows_small - 15)`` is the standard error independent noise would give;
        0 where there is no small fit
    """
    m = query.shape[0]
    most = 0
    for q in range(m):
        most = max(most, inner[q])
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        uvh = np.empty((most, 3))         # the small support's frame coordinates
        mat = np.empty((_QUARTIC, _QUARTIC))
        rhs = np.empty(_QUARTIC)
        sol = np.empty(_QUARTIC)
        y = np.empty(_QUARTIC)
        mom = np.empty((9, 9))
        hmom = np.empty((9, 9))
        frame = np.empty((3, 3))
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            for a in range(3):
                small[q, a] = np.nan
                large[q, a] = np.nan
                frame_u[q, a] = np.nan
            error[q] = np.nan
            rows_small[q] = 0
            s = query[q]
            x0, x1, x2 = points[s, 0], points[s, 1], points[s, 2]
            n0, n1, n2 = normals[q, 0], normals[q, 1], normals[q, 2]
            if not np.isfinite(n0 + n1 + n2 + x0 + x1 + x2):
                continue
            # any tangent frame: the polynomial basis is closed under rotations about n
            normal_frame(n0, n1, n2, frame)
            for a in range(3):
                frame_u[q, a] = frame[0, a]
            lo = indptr[q]
            mid = lo + inner[q]
            hi = indptr[q + 1]
            spread = 0.0
            count = 0
            for j in range(lo, mid):
                k = indices[j]
                d0 = points[k, 0] - x0
                d1 = points[k, 1] - x1
                d2 = points[k, 2] - x2
                r2 = d0 * d0 + d1 * d1 + d2 * d2
                if k != s and np.isfinite(r2):
                    spread += r2
                    count += 1
            if count + 1 < MIN_ROWS or not spread > 0.0:
                continue
            inv = 1.0 / math.sqrt(spread / count)
            for a in range(9):
                for b in range(9):
                    mom[a, b] = 0.0
                    hmom[a, b] = 0.0
            mom[0, 0] = 1.0                  # x itself: u = v = h = 0
            rows = 1
            for part in range(2):
                for j in range(lo if part == 0 else mid, mid if part == 0 else hi):
                    k = indices[j]
                    usable, u, v, h = _in_frame(points, k, s, x0, x1, x2, inv, frame)
                    if not usable:
                        continue
                    if part == 0:
                        uvh[rows - 1, 0] = u
                        uvh[rows - 1, 1] = v
                        uvh[rows - 1, 2] = h
                    _add_monomials(mom, 1.0, u, v, 8)
                    _add_monomials(hmom, h, u, v, 4)
                    rows += 1
                if rows < MIN_ROWS:
                    break
                for a in range(_QUARTIC):
                    rhs[a] = hmom[_JET_U[a], _JET_V[a]]
                    for cc in range(a + 1):
                        mat[a, cc] = mom[_JET_U[a] + _JET_U[cc], _JET_V[a] + _JET_V[cc]]
                if not solve_sym(mat, rhs, _QUARTIC, sol):
                    break
                if part == 1:
                    _shape_operator(sol, inv, large, q)
                    continue
                _shape_operator(sol, inv, small, q)
                # the residuals summed one by one (sum h^2 - c . rhs cancels to nothing where
                # the fit is close), each at least the rounding of the stored coordinates
                rss = sol[5] * sol[5]                # x itself
                for i in range(rows - 1):
                    r = uvh[i, 2] - _quartic_at(sol, uvh[i, 0], uvh[i, 1])
                    rss += r * r
                rounding = ROUNDING * max(abs(x0), abs(x1), abs(x2)) * inv
                rss += rows * rounding * rounding
                factor = max(4.0 * inverse_entry(mat, _QUARTIC, 0, y),
                             inverse_entry(mat, _QUARTIC, 1, y),
                             4.0 * inverse_entry(mat, _QUARTIC, 2, y))
                error[q] = math.sqrt(rss * factor) * inv
                rows_small[q] = rows
