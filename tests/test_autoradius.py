"""Automatic radius: noise and density estimates, and the radius they lead to."""

import numpy as np
import pytest

from meshcurv import surfaces
from meshcurv.autoradius import auto_radius, estimate_sampling


def test_estimate_sampling_recovers_density_and_noise_of_a_noisy_sphere():
    clean = surfaces.sphere(1.0, 4)
    noisy = surfaces.add_normal_noise(clean, 0.003, seed=2)
    density, sigma = estimate_sampling(noisy.vertices)
    # 2562 vertices on an area of 4 pi; kNN density of an icosphere is within 10 % of that
    assert density == pytest.approx(len(clean.vertices) / (4 * np.pi), rel=0.1)
    # quadric-fit residuals, corrected for the 6 parameters: measured within 5 % of sigma
    assert sigma == pytest.approx(0.003 * clean.diagonal, rel=0.1)
    # a clean sphere leaves only the quadric's misfit of the sphere, far below that noise
    assert estimate_sampling(clean.vertices)[1] < 1e-3 * clean.diagonal * 0.1


def test_auto_radius_grows_with_noise_and_stays_within_its_bounds():
    s = surfaces.sphere(1.0, 4)
    r_clean, info = auto_radius(s.vertices, s.faces, details=True)
    r_noisy = auto_radius(surfaces.add_normal_noise(s, 0.003, seed=1).vertices, s.faces)
    # clean: the smallest ball (about 40 points); noisy: the cube-root noise law,
    # (5.6 sigma / (0.05 sqrt(rho)))^(1/3) = 0.43 on this sphere
    assert r_clean == pytest.approx(info["r_min"])
    assert 0.35 < r_noisy < 0.5
    # distance weights average less noise away and need a larger ball
    r_weighted = auto_radius(surfaces.add_normal_noise(s, 0.003, seed=1).vertices, s.faces,
                             weighting="distance")
    assert r_weighted > 1.2 * r_noisy


def test_auto_radius_handles_tiny_and_bad_input():
    tiny = np.random.default_rng(0).normal(size=(10, 3))
    assert np.isfinite(auto_radius(tiny)) and auto_radius(tiny) > 0
    with pytest.raises(ValueError):
        auto_radius(np.zeros((5, 2)))
    with pytest.raises(ValueError):
        auto_radius(surfaces.sphere(1.0, 2).vertices, weighting="adaptive")
