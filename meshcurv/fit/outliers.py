"""Point outliers: each point's residual from a robust height fit of its neighborhood, over the
neighborhood's robust noise scale, and the Tukey weight that follows. Compiled kernel
:func:`point_residuals`; its numpy specification is
:func:`meshcurv.fit.outliers_spec.point_residual`.

A stray point (a scanner spike) lies far from the surface its neighbors describe; with it
down-weighted in the later fits (normals, jet, circle fits) it no longer moves its neighbors'
curvature, and it is flagged itself instead of getting a curvature of its own.
"""

import math

import numpy as np
from numba import njit, prange

from ..linalg import (CHUNK, ball_offset, normal_frame, select_median,
                      smallest_eigvec_jacobi3, solve_factored, solve_sym)
from .constants import (OUTLIER_ITERATIONS, OUTLIER_MAX_REJECTED, OUTLIER_SCALE_FLOOR,
                        OUTLIER_TRUSTED, TUKEY_C)
from .jet import _add_monomials

__all__ = ["point_residuals", "outlier_score", "outlier_weight", "model_terms", "MAD_SIGMA",
           "SCALE_EFFICIENCY"]

# Standard deviations per median absolute deviation of Gaussian data.
MAD_SIGMA = 1.4826

# Tuning constant of the biweight midvariance (in MADs): the usual 9, i.e. about 6 sigmas.
BIWEIGHT_C = 9.0

# Asymptotic efficiency of the biweight midvariance as an estimate of a Gaussian's sigma: a
# scale measured from nu residuals by it is about as uncertain as a standard deviation from
# 0.87 nu (Mosteller & Tukey 1977; the MAD's is 0.37).
SCALE_EFFICIENCY = 0.87


@njit(cache=True)
def _pca_frame(q, wr, k, frame, cov, ev):
    """Rows of ``frame`` (3, 3): tangent axes and normal of the weighted least-squares plane
    of the ``k`` offsets ``q[:k]`` (units of the radius), weights ``wr[:k]``. The point judged
    is left out: a spike far off the surface would tilt the plane towards itself."""
    m0 = m1 = m2 = 0.0
    sw = 0.0
    for i in range(k):
        m0 += wr[i] * q[i, 0]
        m1 += wr[i] * q[i, 1]
        m2 += wr[i] * q[i, 2]
        sw += wr[i]
    m0 /= sw
    m1 /= sw
    m2 /= sw
    for a in range(3):
        for b in range(3):
            cov[a, b] = 0.0
    for i in range(k):
        d0 = q[i, 0] - m0
        d1 = q[i, 1] - m1
        d2 = q[i, 2] - m2
        w = wr[i]
        cov[0, 0] += w * d0 * d0
        cov[0, 1] += w * d0 * d1
        cov[0, 2] += w * d0 * d2
        cov[1, 1] += w * d1 * d1
        cov[1, 2] += w * d1 * d2
        cov[2, 2] += w * d2 * d2
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]
    smallest_eigvec_jacobi3(cov, ev)
    normal_frame(ev[0], ev[1], ev[2], frame)


# Exponents (of u, of v) of the height model's terms: plane (first 3), quadric (first 6),
# cubic (all 10); the constant term is the third.
_TERM_U = np.array([1, 0, 0, 2, 1, 0, 3, 2, 1, 0])


_TERM_V = np.array([0, 1, 0, 0, 1, 2, 0, 1, 2, 3])


def model_terms(k):
    """Coefficients of the height model fitted to k neighbors: the cubic (10) from 3 points
    per coefficient on, else the quadric (6), else the plane (3), none below 2 points per
    plane coefficient (0). A fit with fewer points per coefficient is too poorly determined at
    x to tell a stray point from noise: a spike far off the surface holds only a thin cap of
    it in its ball."""
    for p in (10, 6):
        if k >= 3 * p:
            return p
    return 3 if k >= 6 else 0


_model_terms = njit(cache=True)(model_terms)


@njit(cache=True)
def _height(sol, p, u, v):
    """The height model's first ``p`` terms with coefficients ``sol`` at (u, v)."""
    h = sol[0] * u + sol[1] * v + sol[2]
    if p > 3:
        h += sol[3] * u * u + sol[4] * u * v + sol[5] * v * v
    if p > 6:
        h += u * (u * (sol[6] * u + sol[7] * v) + sol[8] * v * v) + sol[9] * v * v * v
    return h


@njit(cache=True)
def _moments(uvh, wd, wr, k, mom, hmom, degree=6):
    """Power moments of the weights ``w = wd wr`` over the k points ``uvh[:k]``:
    ``mom[a, b] = sum w u^a v^b`` (a + b <= ``degree``: 6 for the cubic, 4 for the quadric, 2
    for the plane), ``hmom`` the same of ``w h`` (a + b <= ``degree // 2``); the others 0."""
    for a in range(7):
        for b in range(7):
            mom[a, b] = 0.0
            hmom[a, b] = 0.0
    for i in range(k):
        w = wd[i] * wr[i]
        if w > 0.0:
            _add_monomials(mom, w, uvh[i, 0], uvh[i, 1], degree)
            _add_monomials(hmom, w * uvh[i, 2], uvh[i, 0], uvh[i, 1], degree // 2)


@njit(cache=True)
def _cubic_moments(q3, frame, wd, wr, k, uvh, mom, hmom):
    """The offsets ``q3[:k]`` in the rows of ``frame`` (``uvh[:k]``: u, v, h) and their moments
    for the cubic, in one pass: those of :func:`_moments` with the same products summed in the
    same order (bit for bit), held in local accumulators (entries of ``mom`` would be loaded and
    stored again for every neighbor)."""
    f00, f01, f02 = frame[0, 0], frame[0, 1], frame[0, 2]
    f10, f11, f12 = frame[1, 0], frame[1, 1], frame[1, 2]
    f20, f21, f22 = frame[2, 0], frame[2, 1], frame[2, 2]
    m00 = m01 = m02 = m03 = m04 = m05 = m06 = 0.0
    m10 = m11 = m12 = m13 = m14 = m15 = 0.0
    m20 = m21 = m22 = m23 = m24 = 0.0
    m30 = m31 = m32 = m33 = 0.0
    m40 = m41 = m42 = 0.0
    m50 = m51 = 0.0
    m60 = 0.0
    h00 = h01 = h02 = h03 = 0.0
    h10 = h11 = h12 = 0.0
    h20 = h21 = 0.0
    h30 = 0.0
    for i in range(k):
        x, y, z = q3[i, 0], q3[i, 1], q3[i, 2]
        u = x * f00 + y * f01 + z * f02
        v = x * f10 + y * f11 + z * f12
        h = x * f20 + y * f21 + z * f22
        uvh[i, 0] = u
        uvh[i, 1] = v
        uvh[i, 2] = h
        c = wd[i] * wr[i]
        if not c > 0.0:
            continue
        # w u^a v^b as _add_monomials forms it: ((w u) ... u) v ... v
        cu = c
        t = cu
        m00 += t
        t *= v
        m01 += t
        t *= v
        m02 += t
        t *= v
        m03 += t
        t *= v
        m04 += t
        t *= v
        m05 += t
        t *= v
        m06 += t
        cu *= u
        t = cu
        m10 += t
        t *= v
        m11 += t
        t *= v
        m12 += t
        t *= v
        m13 += t
        t *= v
        m14 += t
        t *= v
        m15 += t
        cu *= u
        t = cu
        m20 += t
        t *= v
        m21 += t
        t *= v
        m22 += t
        t *= v
        m23 += t
        t *= v
        m24 += t
        cu *= u
        t = cu
        m30 += t
        t *= v
        m31 += t
        t *= v
        m32 += t
        t *= v
        m33 += t
        cu *= u
        t = cu
        m40 += t
        t *= v
        m41 += t
        t *= v
        m42 += t
        cu *= u
        t = cu
        m50 += t
        t *= v
        m51 += t
        cu *= u
        t = cu
        m60 += t
        cu = c * h
        t = cu
        h00 += t
        t *= v
        h01 += t
        t *= v
        h02 += t
        t *= v
        h03 += t
        cu *= u
        t = cu
        h10 += t
        t *= v
        h11 += t
        t *= v
        h12 += t
        cu *= u
        t = cu
        h20 += t
        t *= v
        h21 += t
        cu *= u
        t = cu
        h30 += t
    mom[0, 0] = m00
    mom[0, 1] = m01
    mom[0, 2] = m02
    mom[0, 3] = m03
    mom[0, 4] = m04
    mom[0, 5] = m05
    mom[0, 6] = m06
    mom[1, 0] = m10
    mom[1, 1] = m11
    mom[1, 2] = m12
    mom[1, 3] = m13
    mom[1, 4] = m14
    mom[1, 5] = m15
    mom[2, 0] = m20
    mom[2, 1] = m21
    mom[2, 2] = m22
    mom[2, 3] = m23
    mom[2, 4] = m24
    mom[3, 0] = m30
    mom[3, 1] = m31
    mom[3, 2] = m32
    mom[3, 3] = m33
    mom[4, 0] = m40
    mom[4, 1] = m41
    mom[4, 2] = m42
    mom[5, 0] = m50
    mom[5, 1] = m51
    mom[6, 0] = m60
    hmom[0, 0] = h00
    hmom[0, 1] = h01
    hmom[0, 2] = h02
    hmom[0, 3] = h03
    hmom[1, 0] = h10
    hmom[1, 1] = h11
    hmom[1, 2] = h12
    hmom[2, 0] = h20
    hmom[2, 1] = h21
    hmom[3, 0] = h30


@njit(cache=True)
def _normal_equations(mom, hmom, p, mat, rhs):
    """Lower triangle of the normal equations ``mat[:p, :p]`` and ``rhs[:p]`` of the height
    model's first ``p`` terms."""
    for a in range(p):
        rhs[a] = hmom[_TERM_U[a], _TERM_V[a]]
        for cc in range(a + 1):
            mat[a, cc] = mom[_TERM_U[a] + _TERM_U[cc], _TERM_V[a] + _TERM_V[cc]]


@njit(cache=True)
def _biweight_scale(res, k, mad):
    """Biweight midvariance scale of the residuals ``res[:k]`` (about 0) with ``mad`` their
    median: with ``u = e / (9 MAD)``,
    ``sqrt(k sum_{|u|<1} e^2 (1 - u^2)^4) / |sum_{|u|<1} (1 - u^2)(1 - 5 u^2)|``;
    0 where the MAD is."""
    if not mad > 0.0:
        return 0.0
    num = 0.0
    den = 0.0
    for i in range(k):
        u = res[i] / (BIWEIGHT_C * mad)
        if u < 1.0:
            a = 1.0 - u * u
            num += res[i] * res[i] * a ** 4
            den += a * (1.0 - 5.0 * u * u)
    return math.sqrt(k * num) / abs(den)


@njit(parallel=True, cache=True)
def point_residuals(points, query_points, indptr, indices, radius, residual, scale, dof,
                    iterations=OUTLIER_ITERATIONS):
    """Residual of each query point from a robust height fit of its neighbors, and its scale.

    In the frame of the neighbors' PCA plane (refitted with the robust weights of each round),
    the heights of the k neighbors within ``radius``
    (x itself left out) are fitted by a polynomial in (u, v) (a cubic, or a quadric or plane
    where k is small, :func:`model_terms`: p coefficients; weights ``1 - r^2 / radius^2``),
    first by least squares, then up to ``iterations`` times reweighted by Tukey's biweight
    ``(1 - (e / (TUKEY_C s))^2)^2`` of each neighbor's residual e, with s ``MAD_SIGMA`` times
    the median |e| of the last fit, stopping once no |e| of the last fit reaches
    ``TUKEY_C * s`` (no neighbor to reject: clean data and Gaussian noise stop after the
    start). The scale of the final fit's residuals is their biweight midvariance, times
    ``sqrt(k / (k - p))`` (the fitted coefficients), at least ``OUTLIER_SCALE_FLOOR * radius``.
    The residual of x is its height above the final fit at x; its scale is s times
    ``sqrt(1 + c)``, c the variance of the fitted height at x per unit noise
    (``e^T A^-1 B A^-1 e``, A and B the normal matrices of the weights and of their squares):
    x's own noise plus the fit's.

    Parameters
    ----------
    points : (n, 3) float64; query_points : (m, 3) float64
    indptr, indices : CSR neighbor lists into ``points``; radius : float, model units
    residual : (m,) float64 output, |height of x - fitted height at x|, model units
    scale : (m,) float64 output, the robust scale of that residual, model units
    dof : (m,) float64 output, k - p: the residuals the scale was measured from, less the
        fitted coefficients (0 where no fit)
    iterations : int, most reweighting rounds

    Both are NaN where the fit is singular (fewer than 6 well-spread neighbors), where its
    robust weights left out more than ``OUTLIER_MAX_REJECTED`` of the neighbors (it
    describes part of them only), or x is not finite.
    """
    m = query_points.shape[0]
    r2max = radius * radius
    inv_r = 1.0 / radius
    most = 0
    for q in range(m):
        most = max(most, indptr[q + 1] - indptr[q])
    nchunks = (m + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        q3 = np.empty((most, 3))
        uvh = np.empty((most, 3))
        wd = np.empty(most)
        wr = np.empty(most)
        res = np.empty(most)
        ordered = np.empty(most)          # res reordered by the median's selection
        mat = np.empty((10, 10))
        rhs = np.empty(10)
        sol = np.empty(10)
        mom = np.empty((7, 7))
        hmom = np.empty((7, 7))
        frame = np.empty((3, 3))
        cov = np.empty((3, 3))
        ev = np.empty(3)
        for q in range(c * CHUNK, min(m, (c + 1) * CHUNK)):
            residual[q] = np.nan
            scale[q] = np.nan
            dof[q] = 0.0
            x0 = query_points[q, 0]
            x1 = query_points[q, 1]
            x2 = query_points[q, 2]
            if not np.isfinite(x0 + x1 + x2):
                continue
            k = 0
            for j in range(indptr[q], indptr[q + 1]):
                inside, qx, qy, qz, r2 = ball_offset(points, indices[j], x0, x1, x2, r2max,
                                                      inv_r)
                if not inside:
                    continue
                q3[k, 0] = qx
                q3[k, 1] = qy
                q3[k, 2] = qz
                wd[k] = 1.0 - r2
                wr[k] = 1.0
                k += 1
            p = _model_terms(k)
            if p == 0:
                continue
            ok = True
            s = 0.0
            mad = 0.0
            coefficients = math.sqrt(k / (k - p))
            for it in range(iterations + 1):
                # the frame's plane is refitted with the robust weights too: stray points
                # tilt it most where the ball holds few points
                _pca_frame(q3, wr, k, frame, cov, ev)
                if p == 10:
                    _cubic_moments(q3, frame, wd, wr, k, uvh, mom, hmom)
                else:
                    for i in range(k):
                        for a in range(3):
                            uvh[i, a] = (q3[i, 0] * frame[a, 0] + q3[i, 1] * frame[a, 1]
                                         + q3[i, 2] * frame[a, 2])
                    _moments(uvh, wd, wr, k, mom, hmom, 4 if p == 6 else 2)
                _normal_equations(mom, hmom, p, mat, rhs)
                if not solve_sym(mat, rhs, p, sol):
                    ok = False
                    break
                largest = 0.0
                for i in range(k):
                    res[i] = abs(uvh[i, 2] - _height(sol, p, uvh[i, 0], uvh[i, 1]))
                    ordered[i] = res[i]
                    largest = max(largest, res[i])
                mad = select_median(ordered, k)
                s = max(MAD_SIGMA * mad * coefficients, OUTLIER_SCALE_FLOOR)
                if it == iterations:
                    break
                # no neighbor at the biweight's rejection point: none to reject (clean data,
                # Gaussian noise); the reweighting would only trade efficiency
                if largest <= TUKEY_C * s:
                    break
                for i in range(k):
                    z = res[i] / (TUKEY_C * s)
                    wr[i] = (1.0 - z * z) ** 2 if z < 1.0 else 0.0
            if not ok:
                continue
            # a fit that left out more than OUTLIER_MAX_REJECTED of the neighbors describes
            # part of them only: no judgement of x (a ridge of a coarse grid, not a spike)
            rejected = 0
            for i in range(k):
                rejected += wr[i] == 0.0
            if rejected > OUTLIER_MAX_REJECTED * k:
                continue
            # the scale of the final fit's residuals: the biweight midvariance (Mosteller &
            # Tukey), as robust as the MAD and 87 % efficient at the Gaussian instead of 37 %
            # (mad: the median of these residuals, selected in the last round)
            s = max(_biweight_scale(res, k, mad) * coefficients, OUTLIER_SCALE_FLOOR)
            # x's own noise adds to the fit's error at x: variance s^2 (1 + e^T A^-1 B A^-1 e)
            # with A, B the moments of the weights and of their squares, e the constant term
            # (A's factor is the last round's, in mat)
            fitted = sol[2]
            for a in range(p):
                rhs[a] = 1.0 if a == 2 else 0.0
            solve_factored(mat, rhs, p, sol)
            # e^T A^-1 B A^-1 e = sum_i (w_i x_i . A^-1 e)^2, x_i the model's terms at point i
            spread = 0.0
            for i in range(k):
                g = wd[i] * wr[i] * _height(sol, p, uvh[i, 0], uvh[i, 1])
                spread += g * g
            residual[q] = abs(fitted) * radius
            scale[q] = s * math.sqrt(1.0 + spread) * radius
            dof[q] = k - p


def outlier_score(residual, scale, dof):
    """Outlier scores (n,): the residual over its robust scale (:func:`point_residuals`),
    expressed as the Gaussian deviate of equal tail probability, so one cutoff means the same
    whatever the neighborhood size.

    With the scale measured from few residuals, ``residual / scale`` has Student's t tails
    (``SCALE_EFFICIENCY * dof`` degrees of freedom) rather than Gaussian ones. Measured on a
    noisy plane: scores above 4.685 (3 points in a million for Gaussian deviates) at <= 3.5e-4
    of the points of 9-30 point neighborhoods, none at more; the plain ratio with the MAD
    scale gave 3 % at 6-8 points and 0.1 % at 30-60. NaN where there is no fit; ``inf`` beyond
    float64's tail probabilities.
    """
    from scipy import special

    ratio = np.asarray(residual, dtype=np.float64) / np.asarray(scale, dtype=np.float64)
    nu = SCALE_EFFICIENCY * np.asarray(dof, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        tail = special.stdtr(nu, -ratio)          # P(T < -ratio) = P(T > ratio)
        score = -special.ndtri(tail)
    return np.where(nu > 0, score, np.nan)


def outlier_weight(score):
    """Weights in [0, 1] of points with these outlier scores (:func:`outlier_score`) in the
    later fits: 1 up to ``OUTLIER_TRUSTED``, then Tukey's
    biweight of the excess, ``(1 - ((score - OUTLIER_TRUSTED) / (TUKEY_C - OUTLIER_TRUSTED))^2)^2``,
    0 from ``TUKEY_C`` on; 1 where the score is NaN (no fit: nothing to judge by)."""
    z = (np.asarray(score, dtype=np.float64) - OUTLIER_TRUSTED) / (TUKEY_C - OUTLIER_TRUSTED)
    with np.errstate(invalid="ignore"):
        w = np.where(z < 1.0, (1.0 - np.maximum(z, 0.0) ** 2) ** 2, 0.0)
    return np.where(np.isfinite(z), w, 1.0)
