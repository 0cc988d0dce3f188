"""Normals by the algebraic sphere fit of the paper's section 4 (CGA sphere/plane fit, in
Pratt's normalisation). Compiled kernel :func:`sphere_normals_csr` and its wrapper
:func:`sphere_normals`; numpy specification :func:`meshcurv.normals.sphere_spec.sphere_normal`.

The algebra. In CGA a sphere or plane is the vector S = s + s4 e_inf + s5 e_0 and a point
P = p + |p|^2/2 e_inf + e_0; their inner product P.S = s.p - s4 - s5 |p|^2 / 2 is zero on S.
Written u0 + u.p + u4 |p|^2 (u0 = -s4, u = s, u4 = -s5/2), the fit minimises the weighted
algebraic distance

    U^T M U,   M = sum_i w_i z_i z_i^T,   z_i = (1, p_i, |p_i|^2),   U = (u0, u, u4),

which alone has the trivial minimum U = 0. The paper normalises |U| = 1, which depends on
the origin and the scale. Pratt's normalisation |u|^2 - 4 u0 u4 = 1 (= U^T N U, N the 5x5
matrix with the identity on u and -2 at (u0, u4) and (u4, u0)) is the squared CGA norm of the
sphere vector, invariant to translations and rotations: the sphere u4 (|p - c|^2 - r^2) has
u = -2 u4 c, u0 = u4 (|c|^2 - r^2) and U^T N U = 4 u4^2 r^2, so the constraint fixes
|u4| = 1 / (2 r); a plane (u4 = 0) gets |u| = 1, and spheres pass smoothly into planes as r
grows. The constrained minimum solves the
generalised eigenproblem

    M U = lambda N U,   lambda = U^T M U >= 0 the smallest eigenvalue with U^T N U > 0,

which is exact (lambda = 0) on points of one sphere or plane. N is indefinite, so the kernel
reduces it to symmetric problems: M = V D V^T (Jacobi), Y = D^(1/2) V^T, then with a = Y U

    Q a = lambda a,   Q = D^(1/2) V^T N^-1 V D^(1/2)   (symmetric; N^-1 = N with -1/2 for -2),

and U = V D^(-1/2) a. Among Q's eigenvectors the one kept has U^T N U > 0 and the least
U^T M U / U^T N U (on exact data the one along M's null vector, whatever rounding does to
its tiny eigenvalue).

Coordinates are relative to the query point x and in units of the radius (the paper's
centring, which keeps M well conditioned at any offset or scale); weights ``1 - r^2 / R^2``,
x itself included with weight 1, as the local jet fits (:mod:`meshcurv.fit.jet`). The normal
is the fitted surface's gradient u + 2 u4 p at x (p = 0): u / |u|, which for a sphere is the
direction from its centre to x, i.e. its normal at the point nearest x, and for a plane the
plane's normal. Exact on spheres and planes whatever the sampling.
"""

import math

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK, ball_offset, sym_eig_jacobi

__all__ = ["sphere_normals", "sphere_normals_csr"]

# Fewest points (x included) of a fit: 4 determine a sphere, one more makes it a fit.
MIN_POINTS = 6


@njit(cache=True)
def _pratt_solution(mat, vecs, q, qvecs, sol):
    """``sol`` (5,) = the Pratt-normalised sphere (u0, u1, u2, u3, u4) minimising U^T M U for
    the positive semi-definite ``mat`` (5x5, overwritten); returns that minimum (the weighted
    sum of squared algebraic distances, which Pratt's normalisation makes the geometric ones
    to first order), or -1.0 if no solution is found."""
    sym_eig_jacobi(mat, vecs, 5)
    dmax = 0.0
    for i in range(5):
        dmax = max(dmax, mat[i, i])
    if not (dmax > 0.0) or not np.isfinite(dmax):
        return -1.0
    # D^(1/2), its tiny entries held at round-off of the largest (a null vector of M keeps
    # the largest weight in U = V D^(-1/2) a)
    sq = np.empty(5)
    for i in range(5):
        sq[i] = math.sqrt(max(mat[i, i], 1e-30 * dmax))
    # Q = D^(1/2) V^T N^-1 V D^(1/2); N^-1 = I on u, -1/2 at (u0, u4) and (u4, u0)
    for i in range(5):
        for j in range(i + 1):
            s = (vecs[1, i] * vecs[1, j] + vecs[2, i] * vecs[2, j] + vecs[3, i] * vecs[3, j]
                 - 0.5 * (vecs[0, i] * vecs[4, j] + vecs[4, i] * vecs[0, j]))
            q[i, j] = s * sq[i] * sq[j]
            q[j, i] = q[i, j]
    sym_eig_jacobi(q, qvecs, 5)
    best = np.inf
    found = False
    cand = np.empty(5)
    for k in range(5):
        for r in range(5):
            s = 0.0
            for c in range(5):
                s += vecs[r, c] * qvecs[c, k] / sq[c]
            cand[r] = s
        pratt = cand[1] * cand[1] + cand[2] * cand[2] + cand[3] * cand[3] \
            - 4.0 * cand[0] * cand[4]
        if not (pratt > 0.0):
            continue
        # U^T M U = |D^(1/2) V^T U|^2 = |a|^2 (times the clamp on null directions)
        energy = 0.0
        for c in range(5):
            s = 0.0
            for r in range(5):
                s += vecs[r, c] * cand[r]
            energy += mat[c, c] * s * s
        obj = max(energy, 0.0) / pratt
        if obj < best:
            best = obj
            found = True
            s = 1.0 / math.sqrt(pratt)
            for r in range(5):
                sol[r] = cand[r] * s
    return best if found else -1.0


@njit(parallel=True, cache=True)
def sphere_normals_csr(points, query_points, indptr, indices, radius, with_query, residual,
                       tilt_gain):
    """Unit normals (m, 3) of the Pratt-normalised algebraic sphere/plane fitted around each
    query point (module docstring), signs arbitrary; NaN rows where the ball holds fewer than
    :data:`MIN_POINTS` points (x included), the fit fails or x sits at the fitted centre.
    ``with_query``: the query point itself is one of the points fitted (weight 1); False
    leaves it out (a fit independent of its own position noise).

    ``residual`` (m,) output, NaN with the normal: the fit's RMS residual in units of the
    radius, ``sqrt(min U^T M U / sum w)`` corrected for its 4 degrees of freedom (Pratt's
    normalisation makes the algebraic distances geometric to first order); noise and the
    shape's departure from a sphere alike. Being the square root of an eigenvalue it bottoms
    out at about 1e-8 (round-off) on exact spheres and planes.

    ``tilt_gain`` (m,) output, NaN with the normal: ``sqrt(2 sum w^2 r^2) / sum w r^2`` over
    the ball (r in units of the radius): independent height noise of s radii tilts a weighted
    linear fit's normal by s times this (standard deviation per tangent component, radians;
    the slope along u has the variance s^2 sum w^2 u^2 / (sum w u^2)^2, and u^2 ~ r^2 / 2
    where the sampling is alike in all directions). The jet's quadric slope has the same
    variance there (its even terms are orthogonal to the slopes).
    """
    m = query_points.shape[0]
    out = np.full((m, 3), np.nan)
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for ch in prange(nchunks):
        mat = np.empty((5, 5))
        vecs = np.empty((5, 5))
        qm = np.empty((5, 5))
        qvecs = np.empty((5, 5))
        sol = np.empty(5)
        z = np.empty(5)
        for q in range(ch * CHUNK, min(m, (ch + 1) * CHUNK)):
            tilt_gain[q] = np.nan
            residual[q] = np.nan
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            if not np.isfinite(x0 + x1 + x2):
                continue
            for i in range(5):
                for j in range(5):
                    mat[i, j] = 0.0
            c = 0
            if with_query:
                mat[0, 0] = 1.0                  # x itself: z = (1, 0, 0, 0, 0), weight 1
                c = 1
            sw = 1.0 if with_query else 0.0
            swr2 = 0.0
            sw2r2 = 0.0
            for jj in range(indptr[q], indptr[q + 1]):
                inside, a, b, d, r2 = ball_offset(points, indices[jj], x0, x1, x2, r2max,
                                                  inv_r)
                if not inside:
                    continue
                w = 1.0 - r2
                z[0] = 1.0
                z[1] = a
                z[2] = b
                z[3] = d
                z[4] = r2
                for i in range(5):
                    wz = w * z[i]
                    for j in range(i + 1):
                        mat[i, j] += wz * z[j]
                sw += w
                swr2 += w * r2
                sw2r2 += w * w * r2
                c += 1
            if c < MIN_POINTS:
                continue
            ok = True
            for i in range(5):
                for j in range(i + 1):
                    mat[j, i] = mat[i, j]
                    if not np.isfinite(mat[i, j]):
                        ok = False
            if not ok:
                continue
            energy = _pratt_solution(mat, vecs, qm, qvecs, sol)
            if energy < 0.0:
                continue
            g = math.sqrt(sol[1] * sol[1] + sol[2] * sol[2] + sol[3] * sol[3])
            if not (g > 1e-12):
                continue
            out[q, 0] = sol[1] / g
            out[q, 1] = sol[2] / g
            out[q, 2] = sol[3] / g
            residual[q] = math.sqrt(energy / sw * c / (c - 4))
            if swr2 > 0.0:
                tilt_gain[q] = math.sqrt(2.0 * sw2r2) / swr2
    return out


def sphere_normals(points, query_points, indptr, indices, radius, with_query=True):
    """Normals of the algebraic sphere/plane fitted around each query point (paper, section 4).

    Parameters
    ----------
    points : (n, 3) float64; query_points : (m, 3) float64
    indptr, indices : CSR neighbor lists into ``points``; radius : float, model units
    with_query : bool, fit the query point itself too (weight 1), as for vertices

    Returns
    -------
    normals : (m, 3) float64 unit normals with arbitrary sign (the orientation step, or
        :func:`meshcurv.normals.orient_like`, fixes them); NaN where no fit is possible.
    residual : (m,) float64, the fit's RMS residual in units of the radius.
    tilt_gain : (m,) float64, radians per radius: the tilt of a weighted linear fit's normal
        per unit height noise (see :func:`sphere_normals_csr`).

    Examples
    --------
    >>> import numpy as np
    >>> p = np.random.default_rng(0).normal(size=(400, 3))
    >>> p = 2.0 * p / np.linalg.norm(p, axis=1, keepdims=True)
    >>> indptr, indices = np.array([0, 399]), np.arange(1, 400)
    >>> n, residual, _ = sphere_normals(p, p[:1], indptr, indices, 1.5)
    >>> bool(abs(abs(n[0] @ p[0]) / 2.0 - 1.0) < 1e-12)
    True
    """
    residual = np.empty(len(query_points))
    tilt_gain = np.empty(len(query_points))
    normals = sphere_normals_csr(np.ascontiguousarray(points, dtype=np.float64),
                                 np.ascontiguousarray(query_points, dtype=np.float64),
                                 indptr, indices, float(radius), bool(with_query), residual,
                                 tilt_gain)
    return normals, residual, tilt_gain
