"""The normal field of the normal-aware fits with estimated normals (clouds; noisy meshes)
(:func:`meshcurv.pipeline.field_mix`): plane fits over the radius and over twice it,
mixed point by point by what separates them - noise, where the wider fit averages it down,
or bias, where the surface bends within the ball and the wider fit takes up more of it."""

import numpy as np
import pytest

import meshcurv
from meshcurv import pipeline, surfaces
from meshcurv.pipeline import FIELD_NOISE_RATIO, FIELD_RATIO, field_mix


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
    # (measured: mix 0.00164, wide alone 0.00169, narrow alone 0.00645; the mix with sqrt 2
    # radii of the previous release 0.00325)
    (4 * np.pi, 0.02, 0.0025),
    # bumpy (wavelength 3, 4.5 radii): the wider fit's bias separates them
    # (measured: mix 0.03398 = narrow alone, wide alone 0.07054)
    (3.0, 0.005, 0.0370),
])
def test_the_field_takes_the_wide_fits_under_noise_and_the_narrow_ones_where_the_surface_bends(
        wavelength, noise, bound):
    assert mean_error(*scan(wavelength, noise)) < bound


def test_a_noisy_mesh_gets_the_wide_field_and_a_clean_one_skips_it(monkeypatch):
    """A noisy mesh's estimated normals get the clouds' wide field over k-rings: its error
    falls to that of the same points as a cloud at the same radius (icosphere 4, noise 0.3 %
    of the diagonal; measured mean |dk1| + |dk2|: mesh 0.0224, cloud 0.0223, the mesh with the
    narrow field alone 0.0575). A clean mesh skips it: the same bits as with the narrow field
    alone."""
    s = surfaces.sphere(subdivisions=4)
    noisy = surfaces.add_normal_noise(s, 0.003)

    def errors(v, faces):
        res = meshcurv.principal_curvatures(v, faces, radius=0.3)
        return res, np.mean(np.abs(res.k1 - 1.0) + np.abs(res.k2 - 1.0))
    (mesh, mesh_err), (_, cloud_err) = errors(noisy.vertices, s.faces), errors(noisy.vertices,
                                                                               None)
    clean = meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.3)
    # the choice is the mesh's, whatever the query: a few rows get the bits of the whole run
    rows = np.arange(0, len(s.vertices), 97)
    part = meshcurv.principal_curvatures(noisy.vertices, s.faces, radius=0.3, query=rows)
    assert np.array_equal(part.k1, mesh.k1[rows]) and np.array_equal(part.k2, mesh.k2[rows])
    monkeypatch.setattr(pipeline, "WIDE_FIELD_GAIN", np.inf)        # never the wide field
    narrow, narrow_err = errors(noisy.vertices, s.faces)
    assert mesh_err < 1.1 * cloud_err and mesh_err < 0.5 * narrow_err, \
        (mesh_err, cloud_err, narrow_err)
    clean_narrow = meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.3)
    for name in ("k1", "k2", "d1", "d2", "normals"):
        assert np.array_equal(getattr(clean, name), getattr(clean_narrow, name)), name
    assert not np.array_equal(mesh.k1, narrow.k1)


def test_field_mix_is_wide_at_the_noise_level_and_narrow_at_ratio_squared_times_it():
    # the wide fit's squared bias is FIELD_RATIO^4 times the narrow one's; at a disagreement
    # of FIELD_RATIO^2 times the noise's (bias (rho^2 - 1) E) the narrow fit is the better
    rho2 = FIELD_RATIO ** 2
    split = np.array([3.0, 3.0, 3.0, 3.0, 3.0, np.nan, 1.0])
    noise_only = FIELD_NOISE_RATIO * 3.0
    disagreement = noise_only * np.array([0.5, 1.0, 2.0, rho2, 2 * rho2, np.nan, np.nan])
    disagreement[5] = 1.0
    mid = (1.0 - 1.0 / (rho2 - 1.0)) / 2.0
    np.testing.assert_allclose(field_mix(disagreement, split),
                               [1.0, 1.0, mid, 0.0, 0.0, 1.0, 1.0], atol=1e-15)


@pytest.mark.parametrize("noise", [0.01, 0.25])
def test_the_noise_measure_of_the_mix_holds_from_low_to_high_noise(monkeypatch, noise):
    # on a noisy plane the narrow and wide plane fits differ by noise alone: their mean
    # disagreement is FIELD_NOISE_RATIO times the split measure at every noise level, so the
    # mix takes the wide fits (measured here: 0.43 at 1 %, 0.38 at 25 %; without the split
    # measure's eigen-gap factor 0.70 at 25 %: the narrow plane fit's normal wanders as the
    # noise's variance nears the ball's spread)
    seen = {}

    def spy(disagreement, split):
        seen["d"], seen["s"] = disagreement, split
        return field_mix(disagreement, split)
    monkeypatch.setattr(pipeline, "field_mix", spy)
    rng = np.random.default_rng(7)
    xy = rng.uniform(-5.0, 5.0, (10_000, 2))
    v = np.column_stack([xy, np.zeros(len(xy))])
    radius = 0.6
    v[:, 2] = rng.normal(scale=noise * radius, size=len(xy))
    meshcurv.principal_curvatures(v, radius=radius, orientation="+z")
    inner = (np.abs(xy) < 3.0).all(axis=1)
    ratio = np.nanmean(seen["d"][inner]) / np.nanmean(seen["s"][inner])
    assert 0.7 * FIELD_NOISE_RATIO < ratio < 1.3 * FIELD_NOISE_RATIO
