"""The outlier pre-pass's and the default radius's helpers hold to the plain numpy formulas
they replace, bit for bit."""

import numpy as np
import pytest

from meshcurv import surfaces
from meshcurv.linalg import select_median
from meshcurv.neighbors.radius import _ring_reach


def ring_reach_spec(points, faces):
    """Median over the vertices of ``faces`` of their longest finite edge, in numpy."""
    v = np.asarray(points, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    with np.errstate(over="ignore", invalid="ignore"):
        length = np.linalg.norm(v[a] - v[b], axis=1)
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
    for scale in (1.0, 2.0 ** 300):
        assert _ring_reach(v * scale, f) == ring_reach_spec(v * scale, f)


def test_ring_reach_of_a_torus_and_of_faces_without_finite_edges():
    t = surfaces.torus(2.0, 0.5, 40, 20)
    assert _ring_reach(t.vertices, t.faces) == ring_reach_spec(t.vertices, t.faces)
    v = np.full((3, 3), np.nan)
    assert _ring_reach(v, np.array([[0, 1, 2]])) == 0.0


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 10, 11, 17, 18, 19, 33, 64, 100, 101, 1000])
def test_select_median_equals_numpy_median_with_ties(n):
    rng = np.random.default_rng(n)
    for values in (rng.normal(size=n),                       # distinct
                   rng.integers(0, 3, size=n).astype(float),  # many ties
                   np.sort(rng.normal(size=n)),               # sorted, reversed, constant
                   np.sort(rng.normal(size=n))[::-1].copy(),
                   np.full(n, 0.25)):
        a = values.copy()
        assert select_median(a, n) == np.median(values)
        np.testing.assert_array_equal(np.sort(a), np.sort(values))   # a permutation


def test_select_median_reads_only_its_first_n_values():
    a = np.array([5.0, 1.0, 4.0, 2.0, -1e300, 1e300])
    assert select_median(a, 4) == 3.0
    np.testing.assert_array_equal(a[4:], [-1e300, 1e300])


def test_select_median_with_nan_stays_inside_its_values():
    rng = np.random.default_rng(5)
    for n in (7, 40, 101):
        a = rng.normal(size=n + 3)
        a[rng.choice(n, n // 3, replace=False)] = np.nan
        a[n:] = 7.0                                       # sentinels beyond n: never read or moved
        select_median(a, n)
        np.testing.assert_array_equal(a[n:], 7.0)
        assert np.isnan(a[:n]).sum() == n // 3


def test_cubic_moments_equal_the_projection_and_moments_bit_for_bit():
    from meshcurv.fit.outliers import _cubic_moments, _moments
    rng = np.random.default_rng(3)
    k = 120
    q3 = rng.uniform(-1, 1, size=(k, 3))
    frame = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    wd = 1.0 - rng.uniform(size=k)
    wr = np.where(rng.uniform(size=k) < 0.2, 0.0, rng.uniform(size=k))   # some left out
    uvh = np.empty((k, 3))
    mom, hmom = np.full((7, 7), np.nan), np.full((7, 7), np.nan)
    _cubic_moments(q3, frame, wd, wr, k, uvh, mom, hmom)
    projected = np.empty((k, 3))
    for i in range(k):
        for a in range(3):
            projected[i, a] = (q3[i, 0] * frame[a, 0] + q3[i, 1] * frame[a, 1]
                               + q3[i, 2] * frame[a, 2])
    np.testing.assert_array_equal(uvh, projected)
    ref, href = np.empty((7, 7)), np.empty((7, 7))
    _moments(projected, wd, wr, k, ref, href)
    low = np.add.outer(np.arange(7), np.arange(7))
    np.testing.assert_array_equal(mom[low <= 6], ref[low <= 6])
    np.testing.assert_array_equal(hmom[low <= 3], href[low <= 3])
    for degree in (4, 2):             # the quadric's and the plane's: the same entries, the rest 0
        part, hpart = np.empty((7, 7)), np.empty((7, 7))
        _moments(projected, wd, wr, k, part, hpart, degree)
        np.testing.assert_array_equal(part, np.where(low <= degree, ref, 0.0))
        np.testing.assert_array_equal(hpart, np.where(low <= degree // 2, href, 0.0))


def test_insertion_sort_sorts_only_its_range():
    from meshcurv.linalg import insertion_sort

    rng = np.random.default_rng(3)
    for n in (0, 1, 2, 7, 30):
        a = rng.integers(0, 5, n + 6).astype(np.int64)
        b = a.copy()
        insertion_sort(a, 3, 3 + n)
        b[3:3 + n] = np.sort(b[3:3 + n])
        np.testing.assert_array_equal(a, b)
