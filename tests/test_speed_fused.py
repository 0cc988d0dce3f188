"""One pass over each neighborhood for the local jet's noise and quadric normal: the same
results, bit for bit, as a pass per output."""

import numpy as np
import pytest

from meshcurv import surfaces
from meshcurv.fit import jet

from neighbor_lists import ball_csr

RADIUS = 0.45


@pytest.fixture(scope="module")
def noisy_torus():
    rng = np.random.default_rng(1)
    s = surfaces.torus(n_major=100, n_minor=30)
    v = s.vertices + rng.normal(scale=0.01, size=s.vertices.shape)
    normals = s.normals.copy()
    normals[::50] = np.nan                       # rows without a normal: no estimate
    indptr, indices = ball_csr(v, RADIUS)
    return rng, s, v, normals, indptr, indices


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
