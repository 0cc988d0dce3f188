"""The numba 3x3 helpers (meshcurv.linalg) agree with LAPACK to round-off."""

import numpy as np
import pytest

from meshcurv import linalg


@pytest.mark.parametrize("seed", range(5))
def test_jacobi_smallest_eigenvector_matches_eigh(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(3, 3))
    a = a @ a.T
    out = np.empty(3)
    linalg.smallest_eigvec_jacobi3(a.copy(), out)
    vecs = np.linalg.eigh(a)[1]
    assert abs(out @ vecs[:, 0]) == pytest.approx(1.0, abs=1e-12)


def test_cholesky_solve_matches_numpy_and_refuses_singular_systems():
    rng = np.random.default_rng(1)
    b = rng.normal(size=(5, 5))
    m = b @ b.T + np.eye(5)
    rhs = rng.normal(size=5)
    sol = np.empty(5)
    assert linalg.solve_sym(m.copy(), rhs, 5, sol)
    np.testing.assert_allclose(sol, np.linalg.solve(m, rhs), rtol=1e-10)
    assert not linalg.solve_sym(np.ones((3, 3)), np.ones(3), 3, np.empty(3))


def test_inverse_entry_from_the_cholesky_factor_matches_numpy():
    """(A^-1)[k, k] from the factor solve_sym leaves: numpy's inverse, every k."""
    rng = np.random.default_rng(3)
    b = rng.normal(size=(6, 6))
    a = b @ b.T + 0.1 * np.eye(6)
    m = a.copy()
    assert linalg.solve_sym(m, np.ones(6), 6, np.empty(6))
    expected = np.diag(np.linalg.inv(a))
    got = [linalg.inverse_entry(m, 6, k, np.empty(6)) for k in range(6)]
    np.testing.assert_allclose(got, expected, rtol=1e-10)


def test_ball_offset_is_in_units_of_the_radius_and_excludes_the_centre():
    pts = np.array([[0.0, 0, 0], [0.5, 0, 0], [3.0, 0, 0]])
    assert not linalg.ball_offset(pts, 0, 0.0, 0.0, 0.0, 1.0, 1.0)[0]
    inside, qx, qy, qz, r2 = linalg.ball_offset(pts, 1, 0.0, 0.0, 0.0, 4.0, 0.5)
    assert inside and (qx, qy, qz, r2) == (0.25, 0.0, 0.0, 0.0625)
    assert not linalg.ball_offset(pts, 2, 0.0, 0.0, 0.0, 4.0, 0.5)[0]
