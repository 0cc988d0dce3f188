"""The tangent frame kernel (meshcurv.fit.frame) agrees with its numpy specification
(meshcurv.fit.frame_spec) and does not depend on the order of the neighbor list."""

import numpy as np
import pytest

from meshcurv.fit import frame, frame_spec


def kernel_frame(points, nbr, x, n, radius, rank=None):
    tu, tv = np.empty(3), np.empty(3)
    frame.tangent_frame(points, nbr, 0, len(nbr), x, n, radius * radius, tu, tv, rank)
    return tu, tv


@pytest.mark.parametrize("seed", range(4))
def test_tangent_frame_matches_its_specification(seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(30, 3))
    x = points[0]
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    nbr = np.arange(1, 30)
    tu, tv = kernel_frame(points, nbr, x, n, 1.5)
    q = points[1:] - x
    expected = frame_spec.tangent_u(q[np.einsum("ij,ij->i", q, q) <= 2.25], n)
    np.testing.assert_allclose(tu, expected, atol=1e-9)
    np.testing.assert_allclose(tv, np.cross(n, tu), atol=1e-12)
    # the lowest index rules, whatever the list's order
    np.testing.assert_array_equal(kernel_frame(points, nbr[::-1].copy(), x, n, 1.5)[0], tu)


def test_no_neighbor_off_the_normal_gives_a_fixed_axis():
    points = np.array([[0.0, 0, 0], [0.0, 0, 0.5]])
    n = np.array([0.0, 0, 1])
    tu, _ = kernel_frame(points, np.array([1]), points[0], n, 1.0)
    np.testing.assert_allclose(tu, frame_spec.tangent_u(points[1:] - points[0], n), atol=1e-12)
    assert abs(tu @ n) < 1e-12
