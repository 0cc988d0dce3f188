"""The Euler model kappa(theta) = A + B cos 2theta + C sin 2theta fitted to the circle fits'
curvatures, with a robust refit. Compiled kernels; their numpy specification is
:mod:`meshcurv.fit.euler_spec`.
"""

import math

from numba import njit

from ..linalg import solve_sym

@njit(cache=True)
def euler_fit(rows, kappa, active, m, npar, mat, rhs, sol):
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
    return solve_sym(mat, rhs, npar, sol)


@njit(cache=True)
def euler_model(rows, s, npar, sol):
    f = 0.0
    for a in range(npar):
        f += rows[s, a] * sol[a]
    return f


@njit(cache=True)
def direction_spread(mix, active, m):
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
def robust_euler_fit(rows, kappa, active, m, npar, robust, mat, rhs, sol, scratch):
    """Euler model over the ``m`` samples into ``sol[:npar]``; False if ill-posed.

    With ``robust``, samples further than 3 robust sigmas (1.4826 times the median absolute
    residual) from the first fit are deactivated (``active[s] = 0``) and the model is refitted.
    ``mat`` (5, 5), ``rhs`` (5,), ``scratch`` (m,) are work arrays.
    """
    if not euler_fit(rows, kappa, active, m, npar, mat, rhs, sol):
        return False
    if robust:
        # drop samples further than 3 robust sigmas (MAD) from the model, then refit
        for s in range(m):
            r = abs(kappa[s] - euler_model(rows, s, npar, sol))
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
                if abs(kappa[s] - euler_model(rows, s, npar, sol)) > cut:
                    active[s] = 0.0
                    changed = True
        if changed and not euler_fit(rows, kappa, active, m, npar, mat, rhs, sol):
            return False
    return True


@njit(cache=True)
def euler_residual(rows, kappa, active, m, npar, sol):
    """``(used, sse)``: the active samples and the sum of their squared residuals."""
    used = 0
    sse = 0.0
    for s in range(m):
        if active[s] != 0.0:
            used += 1
            sse += (kappa[s] - euler_model(rows, s, npar, sol)) ** 2
    return used, sse
