"""One pass over each neighborhood for the bias correction's two fits and for the local jet's
noise and quadric normal: the same results, bit for bit, as a pass per fit."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from meshcurv import surfaces
from meshcurv.fit import fused, fused_spec, jet
from meshcurv.fit.extrapolate import BIAS_RATIO
from meshcurv.result import Status

RADIUS = 0.45
FIT = (8, 0.25, 3.0, 0.25, False, True, False, True)
SMALL_FIT = FIT[:6] + (True,) + FIT[7:]      # the bias correction's: half-frequency Euler


def sorted_ball_csr(points, radius):
    tree = cKDTree(points)
    lists = [sorted(tree.query_ball_point(p, radius)) for p in points]
    indptr = np.concatenate([[0], np.cumsum([len(lst) for lst in lists])]).astype(np.int64)
    return indptr, np.concatenate(lists).astype(np.int64)


def outputs(m):
    return (np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty(m),
            np.empty(m), np.empty(m), np.empty(m, dtype=np.int8))


@pytest.fixture(scope="module")
def noisy_torus():
    rng = np.random.default_rng(1)
    s = surfaces.torus(n_major=100, n_minor=30)
    v = s.vertices + rng.normal(scale=0.01, size=s.vertices.shape)
    normals = s.normals.copy()
    normals[::50] = np.nan                       # rows without a normal: no estimate
    indptr, indices = sorted_ball_csr(v, RADIUS)
    return rng, s, v, normals, indptr, indices


@pytest.mark.parametrize("with_field", [False, True])
@pytest.mark.parametrize("with_weights", [False, True])
def test_two_radius_kernel_equals_two_calls_bit_for_bit(noisy_torus, with_field, with_weights):
    """Both fits of the one-pass kernel are the two single-radius calls' exactly, with and
    without normal rows and point weights, at per-point weight blends."""
    rng, s, v, normals, indptr, indices = noisy_torus
    m = len(v)
    blend = rng.uniform(0.0, 1.0, m)
    field = noise = gain = weights = None
    if with_field:
        field = s.normals + rng.normal(scale=0.05, size=v.shape)
        field /= np.linalg.norm(field, axis=1, keepdims=True)
        field[::31] = np.nan
        noise, gain = np.full(m, 0.01), rng.uniform(0.0, 1.0, m)
    if with_weights:
        weights = rng.uniform(0.0, 1.0, m)
        weights[::17] = 0.0
    cons = (field, noise, gain, weights)
    large, small, large2, small2 = outputs(m), outputs(m), outputs(m), outputs(m)
    fused.curvature_cga(v, v, normals, indptr, indices, RADIUS, blend, FIT, large, None, *cons)
    fused.curvature_cga(v, v, normals, indptr, indices, RADIUS * BIAS_RATIO, blend, SMALL_FIT,
                        small, None, *cons)
    fused.curvature_cga(v, v, normals, indptr, indices, RADIUS, blend, FIT, large2, None, *cons,
                        RADIUS * BIAS_RATIO, SMALL_FIT, small2)
    for a, b in zip(large + small, large2 + small2):
        assert np.array_equal(a, b, equal_nan=True)
    assert np.isfinite(small2[0]).mean() > 0.8     # not a comparison of NaNs
    # fewer neighbors in the smaller ball: ratio^2 of the area
    seen = large2[6] > 0
    ratio = np.median(small2[6][seen] / large2[6][seen])
    assert ratio == pytest.approx(BIAS_RATIO ** 2, rel=0.1)


def test_two_radius_kernel_matches_numpy_reference(noisy_torus):
    """The smaller fit of the one-pass kernel is the numpy specification's at its radius, with
    its own options (half-frequency Euler), to round-off (1e-9)."""
    rng, s, v, normals, indptr, indices = noisy_torus
    m = len(v)
    large, small = outputs(m), outputs(m)
    fused.curvature_cga(v, v, normals, indptr, indices, RADIUS, np.ones(m), FIT, large, None,
                        None, None, None, None, RADIUS * BIAS_RATIO, SMALL_FIT, small)
    checked = 0
    for i in range(1, m, 7):
        if not np.isfinite(normals[i, 0]):
            assert large[7][i] == small[7][i] == Status.NO_NORMAL
            continue
        nb = v[indices[indptr[i]:indptr[i + 1]]]
        for out, radius, hf in ((large, RADIUS, False), (small, RADIUS * BIAS_RATIO, True)):
            ref = fused_spec.curvature_at_point(v[i], normals[i], nb, radius, half_frequency=hf)
            for key, col in (("k1", 0), ("k2", 1), ("residual", 5)):
                assert out[col][i] == pytest.approx(ref[key], rel=1e-9, abs=1e-9, nan_ok=True)
            assert out[4][i] == ref["n_samples"]
            if np.isfinite(ref["k1"]):
                assert abs(out[2][i] @ ref["d1"]) == pytest.approx(1.0, abs=1e-9)
                checked += 1
    assert checked > 200


def test_jet_refined_output_is_the_in_place_refinement(noisy_torus):
    """The local jet's ``refined`` output holds what refining in place writes, leaves the
    input normals as given, and the noise is the one of the pass without refinement."""
    rng, s, v, normals, indptr, indices = noisy_torus
    m = len(v)
    start = s.normals + rng.normal(scale=0.05, size=v.shape)
    start /= np.linalg.norm(start, axis=1, keepdims=True)
    start[::50] = np.nan
    plain, noise_plain = start.copy(), np.empty(m)
    jet.local_jet(v, v, plain, indptr, indices, RADIUS, False, noise_plain)
    in_place, noise_in_place = start.copy(), np.empty(m)
    jet.local_jet(v, v, in_place, indptr, indices, RADIUS, True, noise_in_place)
    given, noise_given, refined = start.copy(), np.empty(m), np.empty((m, 3))
    jet.local_jet(v, v, given, indptr, indices, RADIUS, True, noise_given, None, refined)
    assert np.array_equal(given, start, equal_nan=True)
    assert np.array_equal(plain, start, equal_nan=True)
    assert np.array_equal(refined, in_place, equal_nan=True)
    assert np.array_equal(noise_given, noise_plain, equal_nan=True)
    assert np.array_equal(noise_in_place, noise_plain, equal_nan=True)
    # the refinement does turn the noisy normals towards the exact ones
    ok = np.isfinite(start[:, 0])
    before = np.einsum("ij,ij->i", start[ok], s.normals[ok])
    after = np.einsum("ij,ij->i", refined[ok], s.normals[ok])
    assert np.mean(np.arccos(np.clip(after, -1, 1))) < 0.5 * np.mean(
        np.arccos(np.clip(before, -1, 1)))
