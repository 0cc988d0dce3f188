"""Local jet: quartic (cubic where too few points) and quadric height fits around each point,
for the noise level that steers the weights and the bias correction, and a refined normal.
Compiled kernel; its numpy specification is
:func:`meshcurv.fit.jet_spec.local_jet`.
"""

import math

import numpy as np
from numba import njit, prange

from ..linalg import CHUNK, ball_offset, inverse_entry, solve_sym
from .constants import NOISE_SCALE

# Exponents (of u, of v) of the quartic height model's terms, in the order of its coefficients:
# u^2, uv, v^2, u, v, 1 (the quadric), u^3, u^2 v, u v^2, v^3 (the cubic's), u^4 .. v^4.
_JET_U = np.array([2, 1, 0, 1, 0, 0, 3, 2, 1, 0, 4, 3, 2, 1, 0])


_JET_V = np.array([0, 1, 2, 0, 1, 0, 0, 1, 2, 3, 0, 1, 2, 3, 4])

# Coefficients of the quadric, cubic and quartic height models (nested: leading blocks).
_QUADRIC, _CUBIC, _QUARTIC = 6, 10, 15


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
def local_jet(points, query_points, normals, indptr, indices, radius, refine, noise,
              point_weights=None, refined=None):
    """Local height fits around each query point: noise level (quartic) and normal (quadric).

    In a frame (tu, tv, n) around each query point x, the heights of its neighbors within
    ``radius`` are fitted by polynomials in (u, v) (least squares with weights
    ``1 - r^2 / radius^2``, x included). The quartic fit's residual (15 coefficients; the
    cubic's, 10, where 11-15 points are all there is) is what the surface's shape up to fourth
    order cannot explain: on clean samples of smooth surfaces it is about 0.01 % of the radius
    (the cubic's up to 0.13 %: a torus's fourth-order terms), with noise it is the noise.

    With ``refine`` the normal ``n - g_u tu - g_v tv`` (normalised) of a fitted gradient
    (g_u, g_v) at x replaces n: face and PCA normals tilt with irregular sampling (0.7 degrees
    on a randomly sampled sphere at ~100 neighbors). The gradient is the quartic's (cubic's)
    where the data are clean and the quadric's (6 coefficients) under noise, mixed by
    ``c = 1 / (1 + (noise / (NOISE_SCALE radius))^4)`` (the mix of ``weighting="auto"``):
    the quadric's gradient has a third to a fifth of the quartic's variance under noise, but
    where the sampling is uneven it takes up the surface's third-order terms (randomly
    sampled ellipsoid at radius 0.3: the quadric's normals tilt by a median of 0.34 degrees,
    the quartic's by 0.01, mean |dk| 0.0103 -> 0.0033). The refined normal stays on n's side.

    The quartic's gradient gives way to the cubic's where the cubic's standard error (each
    fit's residual variance times its gradient's variance factor) is the smaller. Where a
    ball holds 4 rows of a grid across, a quartic in u on 4 values is a cubic, and only the
    surface's bending tells u^4 from the lower terms (a Cholesky pivot of ~1e-9 of its
    diagonal entry): its coefficient took up the shape's fifth-order terms magnified and the
    quartic's normals turned by up to 29 degrees (a Gaussian bump sampled 0.02 x 0.08 at
    radius 0.22, a row from the border; MLS passes fed by them: mean |dk| 0.0051, 0.0003 from
    exact normals), where the cubic's are 0.002 degrees off.

    Parameters
    ----------
    points : (n, 3) float64; query_points : (m, 3) float64
    normals : (m, 3) float64, unit; refined in place when ``refine`` (unless ``refined``)
    indptr, indices : CSR neighbor lists into ``points``; radius : float, model units
    refine : bool
    noise : (m,) float64 output, RMS height residual of the quartic fit, or of the cubic where
        the quartic is singular (model units, corrected for the fitted coefficients); NaN where
        both are (fewer than 11 well-spread points), and there the normal is left unchanged -
        as it is where the quadric would tilt it by more than 30 degrees (no graph over n,
        e.g. at a crease).
    point_weights : (n,) float64 in [0, 1], optional: each neighbor's weight is multiplied by
        it (the outlier pass's weights); neighbors of weight 0 are left out.
    refined : (m, 3) float64 output, optional: with ``refine``, where the refined normals go
        (a copy of ``normals`` where they are left unchanged), ``normals`` then left as given;
        the same fits give the noise, so one pass yields both.
    """
    m = query_points.shape[0]
    r2max = radius * radius
    inv_r = 1.0 / radius
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        mat = np.empty((_QUARTIC, _QUARTIC))
        cub = np.empty((_CUBIC, _CUBIC))
        quad = np.empty((_QUADRIC, _QUADRIC))
        rhs = np.empty(_QUARTIC)
        sol = np.empty(_QUARTIC)
        sol2 = np.empty(_CUBIC)
        y = np.empty(_QUARTIC)
        mom = np.empty((9, 9))
        hmom = np.empty((9, 9))
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            noise[q] = np.nan
            if refined is not None:
                for a in range(3):
                    refined[q, a] = normals[q, a]
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
            # power moments: mom[a, b] = sum w u^a v^b (a + b <= 8), hmom[a, b] = sum w h u^a v^b
            # (a + b <= 4); every entry of the normal equations is one of them
            for a in range(9):
                for b in range(9):
                    mom[a, b] = 0.0
                    hmom[a, b] = 0.0
            sw = 1.0
            swhh = 0.0
            count = 1
            for j in range(indptr[q], indptr[q + 1]):
                inside, qx, qy, qz, r2 = ball_offset(points, indices[j], x0, x1, x2, r2max,
                                                      inv_r)
                if not inside:
                    continue
                pw = 1.0 if point_weights is None else point_weights[indices[j]]
                if pw <= 0.0:
                    continue
                u = qx * t0 + qy * t1 + qz * t2
                v = qx * b0 + qy * b1 + qz * b2
                h = qx * n0 + qy * n1 + qz * n2
                w = (1.0 - r2) * pw
                _add_monomials(mom, w, u, v, 8)
                _add_monomials(hmom, w * h, u, v, 4)
                sw += w
                swhh += w * h * h
                count += 1
            for a in range(_QUARTIC):
                rhs[a] = hmom[_JET_U[a], _JET_V[a]]
                for cc in range(a + 1):
                    mat[a, cc] = mom[_JET_U[a] + _JET_U[cc], _JET_V[a] + _JET_V[cc]]
            mat[5, 5] += 1.0         # x itself: u = v = h = 0, weight 1
            for a in range(_CUBIC):        # the cubic's and the quadric's: the leading blocks
                for cc in range(a + 1):
                    cub[a, cc] = mat[a, cc]
                    if a < _QUADRIC:
                        quad[a, cc] = mat[a, cc]
            npar = _QUARTIC
            if count <= _QUARTIC or not solve_sym(mat, rhs, _QUARTIC, sol):
                npar = _CUBIC
                if count <= _CUBIC or not solve_sym(cub, rhs, _CUBIC, sol):
                    continue
            # weighted residual sum of squares of the least-squares fit: sum w h^2 - sol . rhs
            ss = swhh
            for a in range(npar):
                ss -= sol[a] * rhs[a]
            rel = math.sqrt(max(ss, 0.0) / sw * count / (count - npar))
            noise[q] = rel * radius
            if not refine:
                continue
            gu, gv = sol[3], sol[4]          # the quartic's (cubic's) gradient at x
            if npar == _QUARTIC and solve_sym(cub, rhs, _CUBIC, sol2):
                # the cubic's gradient where its standard error is the smaller: the residual
                # variance of each fit times its gradient's variance factor (a sample that
                # barely tells the quartic's terms from lower ones, 4 rows of a grid across
                # the ball, inflates the quartic's)
                ss3 = swhh
                for a in range(_CUBIC):
                    ss3 -= sol2[a] * rhs[a]
                se3 = max(ss3, 0.0) / (count - _CUBIC) * (inverse_entry(cub, _CUBIC, 3, y)
                                                          + inverse_entry(cub, _CUBIC, 4, y))
                se4 = max(ss, 0.0) / (count - _QUARTIC) * (inverse_entry(mat, _QUARTIC, 3, y)
                                                           + inverse_entry(mat, _QUARTIC, 4, y))
                if se3 < se4:
                    gu, gv = sol2[3], sol2[4]
            clean = 1.0 / (1.0 + (rel / NOISE_SCALE) ** 4)
            if clean < 1.0:
                if not solve_sym(quad, rhs, _QUADRIC, sol):
                    continue
                gu = sol[3] + clean * (gu - sol[3])
                gv = sol[4] + clean * (gv - sol[4])
            if gu * gu + gv * gv > 1.0 / 3.0:
                continue
            g0 = n0 - gu * t0 - gv * b0
            g1 = n1 - gu * t1 - gv * b1
            g2 = n2 - gu * t2 - gv * b2
            s = 1.0 / math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
            if refined is None:
                normals[q, 0] = g0 * s
                normals[q, 1] = g1 * s
                normals[q, 2] = g2 * s
            else:
                refined[q, 0] = g0 * s
                refined[q, 1] = g1 * s
                refined[q, 2] = g2 * s
