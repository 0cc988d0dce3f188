"""The outlier pre-pass's and the default radius's helpers hold to the plain numpy formulas
they replace, bit for bit."""

import numpy as np
import pytest

from meshcurv import surfaces
from meshcurv.neighbors.radius import _ring_reach


def ring_reach_spec(points, faces, scale):
    """Median over the vertices of ``faces`` of their longest finite edge, in numpy."""
    v = np.asarray(points, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    with np.errstate(over="ignore", invalid="ignore"):
        length = np.linalg.norm(v[a] * scale - v[b] * scale, axis=1) / scale
    keep = np.isfinite(length)
    longest = np.zeros(len(points))
    np.maximum.at(longest, a[keep], length[keep])
    np.maximum.at(longest, b[keep], length[keep])
    used = longest[np.unique(np.concatenate([a[keep], b[keep]]))]
    return float(np.median(used)) if len(used) else 0.0


@pytest.mark.parametrize("seed", range(4))
def test_ring_reach_equals_the_numpy_formula(seed):
    rng = np.random.default_rng(seed)
    n = 200 + 37 * seed                       # odd and even vertex counts
    v = rng.normal(size=(n, 3))
    # ties (a duplicated vertex: edges of equal length), NaN vertices, unused vertices
    v[1] = v[0]
    v[rng.choice(n, 5, replace=False)] = np.nan
    f = rng.integers(0, n - 20, size=(3 * n, 3))
    for scale in (1.0, 2.0 ** -300):
        assert _ring_reach(v * (1.0 / scale), f, scale) == ring_reach_spec(v * (1.0 / scale), f,
                                                                            scale)


def test_ring_reach_of_a_torus_and_of_faces_without_finite_edges():
    t = surfaces.torus(2.0, 0.5, 40, 20)
    assert _ring_reach(t.vertices, t.faces, 1.0) == ring_reach_spec(t.vertices, t.faces, 1.0)
    v = np.full((3, 3), np.nan)
    assert _ring_reach(v, np.array([[0, 1, 2]]), 1.0) == 0.0
