"""The normal field of the normal-aware fits on clouds with estimated normals
(:func:`meshcurv.pipeline.field_mix`): plane fits over the radius and over sqrt 2 times it,
mixed point by point by what separates them - noise, where the wider fit averages it down,
or bias, where the surface bends within the ball and the wider fit takes up more of it."""

import numpy as np
import pytest

import meshcurv
from meshcurv import surfaces
from meshcurv.pipeline import FIELD_NOISE_RATIO, field_mix


def scan(wavelength, noise):
    """A 12 x 12 scan-line terrain (points 0.05 apart on lines 0.25 apart, jittered) with
    Gaussian height noise: (noisy points, exact Surface)."""
    s = surfaces.scan_terrain((0.05, 0.25), 0.1, wavelength=wavelength, extent=6.0, seed=2)
    v = s.vertices.copy()
    v[:, 2] += np.random.default_rng(3).normal(scale=noise, size=len(v))
    return v, s


def mean_error(v, s):
    res = meshcurv.principal_curvatures(v, orientation="+z")
    inner = s.border_distance > 2 * res.radius
    assert res.valid[inner].all()
    return np.mean(0.5 * (np.abs(res.k1 - s.k1) + np.abs(res.k2 - s.k2))[inner])


@pytest.mark.parametrize("wavelength, noise, bound", [
    # gentle (wavelength 4 pi, 19 radii): noise separates the fits, the wide one averages it
    # (measured: mix 0.00325, wide alone 0.00321, narrow alone 0.00645)
    (4 * np.pi, 0.02, 0.0040),
    # bumpy (wavelength 3, 4.5 radii): the wider fit's bias separates them
    # (measured: mix 0.03398 = narrow alone, wide alone 0.04648)
    (3.0, 0.005, 0.0370),
])
def test_the_field_takes_the_wide_fits_under_noise_and_the_narrow_ones_where_the_surface_bends(
        wavelength, noise, bound):
    assert mean_error(*scan(wavelength, noise)) < bound


def test_field_mix_is_wide_at_the_noise_level_and_narrow_at_twice_it():
    split = np.array([3.0, 3.0, 3.0, 3.0, np.nan, 1.0])
    noise_only = FIELD_NOISE_RATIO * 3.0
    disagreement = np.array([noise_only, 1.5 * noise_only, 2 * noise_only, 4 * noise_only,
                             1.0, np.nan])
    np.testing.assert_allclose(field_mix(disagreement, split), [1.0, 1 / 3, 0.0, 0.0, 1.0, 1.0])

