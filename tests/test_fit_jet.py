"""The local jet kernel (meshcurv.fit.jet) agrees with its numpy specification
(meshcurv.fit.jet_spec) and finds the noise that was added."""

import numpy as np
import pytest

from meshcurv import surfaces
from meshcurv.fit import jet, jet_spec

from neighbor_lists import ball_csr


def refined_as_specified(v, start, radius, every):
    """The kernel's refined normals and noise from ``start`` over balls of ``radius``, checked
    against the numpy specification at every ``every``-th point."""
    indptr, indices = ball_csr(v, radius)
    refined, noise = start.copy(), np.empty(len(v))
    jet.local_jet(v, v, refined, indptr, indices, radius, True, noise)
    for i in range(0, len(v), every):
        normal, nz = jet_spec.local_jet(v[i], start[i], v[indices[indptr[i]:indptr[i + 1]]], radius)
        np.testing.assert_allclose(refined[i], normal, atol=1e-9)
        assert noise[i] == pytest.approx(nz, rel=1e-9)
    return refined, noise


def test_local_jet_matches_numpy_reference():
    """Cubic fit: normals and noise as the reference; 3-degree normal errors come down to the
    noise level, and the noise estimate finds the noise that was added."""
    rng = np.random.default_rng(2)
    s = surfaces.torus(n_major=100, n_minor=30)
    sigma = 0.005
    v = s.vertices + rng.normal(scale=sigma, size=(len(s.vertices), 1)) * s.normals
    start = s.normals + rng.normal(scale=0.05, size=v.shape)
    start /= np.linalg.norm(start, axis=1, keepdims=True)
    refined, noise = refined_as_specified(v, start, 0.3, 13)
    err = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", refined, s.normals), -1, 1)))
    assert err.mean() < 1.0
    # the RMS of the added N(0, sigma) heights, up to the fit's and the weights' small effects
    assert np.median(noise) == pytest.approx(sigma, rel=0.15)


@pytest.mark.parametrize("sigma", [0.0, 0.0006, 0.003])
def test_refined_normal_takes_the_quartic_gradient_where_the_data_are_clean(sigma):
    """Randomly sampled ellipsoid (uneven balls), radius 0.3: the kernel matches the spec at
    every noise level - clean, about NOISE_SCALE radius (where the quartic's and the
    quadric's gradients are mixed half and half) and noisy - and on clean samples the refined
    normal is the quartic's: exact up to its fifth-order truncation (median tilt 0.008
    degrees; the quadric's, which takes up the third-order terms on uneven samples, ~0.3)."""
    rng = np.random.default_rng(5)
    s = surfaces.ellipsoid(sampling="random", n=6000, seed=5)
    v = s.vertices + rng.normal(scale=sigma, size=(len(s.vertices), 1)) * s.normals
    start = s.normals + rng.normal(scale=0.02, size=v.shape)
    start /= np.linalg.norm(start, axis=1, keepdims=True)
    refined, _ = refined_as_specified(v, start, 0.3, 17)
    tilt = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", refined, s.normals), -1, 1)))
    if sigma == 0.0:
        assert np.median(tilt) < 0.03      # measured 0.008


def test_a_grid_with_four_rows_across_the_ball_takes_the_cubic_gradient():
    """A bump sampled 0.02 x 0.08, radius 0.22: a row from the border the ball holds 4 rows
    across, where only the surface's bending tells u^4 from the lower terms (a Cholesky pivot
    of ~1e-9 of its diagonal entry); the quartic's gradient there turned the refined normals by
    up to 29 degrees. The cubic's, of the smaller standard error, is as exact as inside
    (measured 0.002 degrees at most); the kernel matches the spec there (the residual of those
    quartic fits, ~2e-7 of the radius, to 5 %: the normal equations' sum w h^2 - sol . rhs
    cancels to round-off there)."""
    s = surfaces.bump(spacing=(0.02, 0.08))
    radius = 0.22
    band = np.flatnonzero((s.border_distance > 0.05) & (s.border_distance < 0.1))
    indptr, indices = ball_csr(s.vertices, radius)
    refined, noise = s.normals.copy(), np.empty(len(s.vertices))
    jet.local_jet(s.vertices, s.vertices, refined, indptr, indices, radius, True, noise)
    tilt = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", refined, s.normals), -1, 1)))
    assert tilt[band].max() < 0.02
    assert tilt[s.border_distance >= radius].max() < 0.02
    for i in band[::37]:
        normal, nz = jet_spec.local_jet(s.vertices[i], s.normals[i],
                                        s.vertices[indices[indptr[i]:indptr[i + 1]]], radius)
        np.testing.assert_allclose(refined[i], normal, atol=1e-9)
        assert noise[i] == pytest.approx(nz, rel=0.05)
