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


def test_auto_radius_takes_the_largest_ball_on_a_sphere():
    s = surfaces.add_normal_noise(surfaces.sphere(1.0, 4), 0.003, seed=1)
    radius, info = auto_radius(s.vertices, s.faces, details=True)
    # every normal section of a sphere is a circle: no bias, so the upper bound
    # max_angle / kappa = 0.7 (kappa ~ 1, slightly inflated by the noise) is chosen
    assert info["beta"] == pytest.approx(0.0, abs=0.02)
    assert radius == pytest.approx(info["r_max"])
    assert 0.6 < radius <= 0.7


def test_auto_radius_grows_with_noise_where_the_circle_model_has_bias():
    clean = surfaces.paraboloid(spacing=0.4)
    r_clean, info = auto_radius(clean.vertices, clean.faces, details=True)
    r_noisy = auto_radius(surfaces.add_normal_noise(clean, 0.003, seed=1).vertices, clean.faces)
    # clean: no noise to average, the smallest ball (40 expected points, 2.3 model units)
    assert r_clean == pytest.approx(info["r_min"])
    assert info["beta"] > 0
    # 0.3 % noise: noise and bias balance near 4.6 (measured); well inside the bounds
    assert 1.5 * r_clean < r_noisy < info["r_max"]
    # with distance weights the noise also pushes the ball well above the clean radius
    r_weighted = auto_radius(surfaces.add_normal_noise(clean, 0.003, seed=1).vertices,
                             clean.faces, weighting="distance")
    assert 1.5 * r_clean < r_weighted < info["r_max"]


def test_auto_radius_handles_tiny_and_bad_input():
    tiny = np.random.default_rng(0).normal(size=(10, 3))
    assert np.isfinite(auto_radius(tiny)) and auto_radius(tiny) > 0
    with pytest.raises(ValueError):
        auto_radius(np.zeros((5, 2)))
    with pytest.raises(ValueError):
        auto_radius(surfaces.sphere(1.0, 2).vertices, weighting="adaptive")
