"""The Euler-model kernels (meshcurv.fit.euler) agree with their numpy specification
(meshcurv.fit.euler_spec) to round-off, outlier rejection included."""

import math

import numpy as np
import pytest

from meshcurv.fit import euler, euler_spec


def kernel_fit(rows, kappa, npar, robust):
    m = len(kappa)
    full = np.zeros((m, 5))
    full[:, :rows.shape[1]] = rows
    active = np.ones(m)
    sol = np.empty(5)
    ok = euler.robust_euler_fit(full, kappa, active, m, npar, robust, np.empty((5, 5)),
                                np.empty(5), sol, np.empty(m))
    if not ok:
        return None
    used, sse = euler.euler_residual(full, kappa, active, m, npar, sol)
    amp = math.sqrt(sol[1] ** 2 + sol[2] ** 2)
    return (sol[0] + amp, sol[0] - amp, 0.5 * math.atan2(sol[2], sol[1]),
            math.sqrt(sse / used), active != 0)


@pytest.mark.parametrize("half_frequency", [False, True])
@pytest.mark.parametrize("robust", [False, True])
def test_euler_fit_matches_its_specification(half_frequency, robust):
    rng = np.random.default_rng(3)
    theta = np.arange(16) * np.pi / 8 + 0.1
    kappa = 0.3 + 0.1 * np.cos(2 * (theta - 0.4)) + rng.normal(scale=1e-3, size=16)
    kappa[5] += 0.5                            # one outlier for the robust refit to drop
    rows = euler_spec.euler_design(theta, half_frequency)
    got = kernel_fit(rows, kappa, rows.shape[1], robust)
    k1, k2, theta1, rms, used = euler_spec.fit_euler(rows, kappa, robust=robust)
    assert got[:4] == pytest.approx((k1, k2, theta1, rms), rel=1e-9, abs=1e-12)
    assert np.array_equal(got[4], used)
    assert used[5] != robust


def test_too_few_samples_are_ill_posed():
    theta = np.arange(4) * np.pi / 4
    rows = euler_spec.euler_design(theta)
    assert kernel_fit(rows, np.ones(4), 3, False) is None
    assert np.isnan(euler_spec.fit_euler(rows, np.ones(4))[0])


def test_direction_spread_is_the_smaller_covariance_eigenvalue():
    rng = np.random.default_rng(4)
    mix = rng.normal(size=(12, 2))
    active = np.ones(12)
    active[3] = 0.0
    expected = euler_spec.direction_spread(mix[active != 0])
    assert euler.direction_spread(mix, active, 12) == pytest.approx(expected, rel=1e-9)
