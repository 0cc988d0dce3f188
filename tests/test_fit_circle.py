"""The CGA circle-fit kernels (meshcurv.fit.circle) agree with their numpy specification
(meshcurv.fit.circle_spec) to round-off, on half-sets built in code."""

import numpy as np
import pytest

from meshcurv.fit import circle, circle_spec
from meshcurv.fit.constants import WEIGHT_POWER


def half_set(seed, curvature=0.8, noise=0.01, k=40):
    """Points of a normal section bending away from n = z (units of the radius), u > 0."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.05, 0.95, k)
    v = rng.uniform(-0.2, 0.2, k)
    h = -0.5 * curvature * (u * u + v * v) + rng.normal(scale=noise, size=k)
    return u, v, h


SLAB = 0.25


def accumulate(u, v, h, beta, taper=-1.0):
    """The kernel's accumulator of one plane (direction +u, slab of half-width SLAB holding
    every point) around x = 0 with n = z, in units of the radius (the ball's bound at 2, past
    every point); ``taper`` the slab taper's blend (negative: ``beta``)."""
    acc = np.zeros((2, circle.N_ACC))
    points = np.column_stack([u, v, h])
    planes = (np.array([1.0]), np.array([0.0]))
    count = circle.accumulate_half_sets(
        points, np.arange(len(u)), 0, len(u), np.zeros(3), np.array([0.0, 0.0, 1.0]),
        np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), 4.0, 1.0, beta, planes, SLAB,
        acc, np.empty((len(u), circle.N_ROW)), np.empty((2, len(u)), dtype=np.int64), None,
        None, taper)
    assert count == len(u)
    return acc


def weights(u, v, h, beta, taper=-1.0):
    """The fit's weights of x (1) and of the points: distance weight times the slab's taper."""
    r2 = u * u + v * v + h * h
    tb = beta if taper < 0 else taper
    slab = (1 - tb) + tb * (1 - (v / SLAB) ** 2) ** 2
    return np.concatenate([[1.0], ((1 - beta) + beta * (1 - r2) ** WEIGHT_POWER) * slab])


@pytest.mark.parametrize("normalization", ["tangent", "unit"])
@pytest.mark.parametrize("beta,taper", [(0.0, -1.0), (0.4, -1.0), (1.0, -1.0), (1.0, 0.0),
                                        (0.4, 0.9)])
def test_circle_fit_matches_its_specification(normalization, beta, taper):
    for seed in range(5):
        u, v, h = half_set(seed)
        acc = accumulate(u, v, h, beta, taper)
        acc[0, 0] += 1.0                       # x itself, as the fused kernel adds it
        kappa = circle.circle_fit(acc, 0, normalization == "unit", np.empty((3, 3)), np.empty(3))
        q = np.column_stack([u, v, h])
        pts = np.vstack([np.zeros(3), q])
        expected, _ = circle_spec.fit_normal_circle(pts, np.array([0.0, 0.0, 1.0]),
                                                     weights(u, v, h, beta, taper),
                                                     normalization)
        assert kappa == pytest.approx(expected, rel=1e-9, abs=1e-9)
        assert 0.5 < kappa < 1.0     # bends away from n: positive (a paraboloid, not a circle)


def test_direction_mix_matches_its_specification():
    u, v, h = half_set(7, noise=0.0)
    beta = 0.7
    acc = accumulate(u, v, h, beta)
    acc[0, 0] += 1.0
    mc, ms = circle.sample_design(acc, 0, True, 1.0, 0.0)
    r2 = u * u + v * v + h * h
    ec, es = circle_spec.sample_mix(r2, np.arctan2(v, u), weights(u, v, h, beta), 0.0)
    assert (mc, ms) == pytest.approx((ec, es), rel=1e-9, abs=1e-12)
    assert circle.sample_design(acc, 0, False, 0.3, 0.4) == (0.3, 0.4)


def test_points_on_one_sphere_about_x_give_no_circle():
    """All points at one distance from x: the tangent form's 2x2 system is singular (NaN)."""
    t = np.linspace(0.1, 1.4, 20)
    u, v, h = 0.5 * np.cos(t), np.zeros(20), -0.5 * np.sin(t)
    acc = accumulate(u, v, h, 0.0)
    assert np.isnan(circle.circle_fit(acc, 0, False, np.empty((3, 3)), np.empty(3)))
