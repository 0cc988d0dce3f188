"""Sphere-fit normals (meshcurv.normals.sphere): the kernel agrees with its numpy
specification, is exact on spheres and planes, and in the estimator makes curvature on a
clean sphere cloud exact with its own normals; given normals are refined where noisy and kept
bit for bit where exact (``refine_normals="auto"``)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

import meshcurv
from meshcurv import linalg, pipeline, surfaces
from meshcurv.normals.sphere import sphere_normals
from meshcurv.normals.sphere_spec import sphere_normal


def _csr(points, radius):
    lists = cKDTree(points).query_ball_point(points, radius)
    indptr = np.concatenate([[0], np.cumsum([len(x) for x in lists])]).astype(np.int64)
    return indptr, np.concatenate(lists).astype(np.int64), lists


def _sine(a, b):
    """|sin| of the angle between unit rows (resolves angles down to 1e-16, unlike arccos)."""
    return np.linalg.norm(np.cross(a, b), axis=1)


def _random_sphere(seed, n=3000):
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-50, 50, 3)
    r = rng.uniform(0.5, 20.0)
    # irregular: clustered directions, not uniform on the sphere
    d = rng.normal(size=(n, 3)) + rng.normal(scale=0.5, size=3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return centre, r, d, centre + r * d


def test_jacobi_eigensolver_reconstructs_a_5x5_symmetric_matrix():
    rng = np.random.default_rng(0)
    b = rng.normal(size=(5, 5))
    a = b + b.T
    work, vecs = a.copy(), np.empty((5, 5))
    linalg.sym_eig_jacobi(work, vecs, 5)
    np.testing.assert_allclose(vecs @ np.diag(np.diag(work)) @ vecs.T, a, atol=1e-13)
    np.testing.assert_allclose(np.sort(np.diag(work)), np.linalg.eigvalsh(a), atol=1e-13)


@pytest.mark.parametrize("seed", range(3))
def test_kernel_matches_the_numpy_specification(seed):
    # a noisy ellipsoid: neither a sphere nor a plane, so the fit is a real compromise
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p = d * [3.0, 2.0, 1.0] + rng.normal(scale=0.01, size=d.shape)
    radius = 0.6
    indptr, indices, lists = _csr(p, radius)
    for with_query in (True, False):
        got, _, _ = sphere_normals(p, p, indptr, indices, radius, with_query)
        for i in range(0, len(p), 97):
            want = sphere_normal(p[i], p[lists[i]], radius, with_query)
            assert abs(abs(got[i] @ want) - 1.0) < 1e-9
            assert np.linalg.norm(np.cross(got[i], want)) < 1e-9


@pytest.mark.parametrize("seed", range(4))
def test_normals_are_exact_on_spheres_of_any_radius_centre_and_sampling(seed):
    centre, r, d, p = _random_sphere(seed)
    radius = 0.3 * r
    indptr, indices, _ = _csr(p, radius)
    n, residual, _ = sphere_normals(p, p, indptr, indices, radius)
    ok = np.isfinite(n).all(axis=1)
    assert ok.mean() > 0.99
    # round-off of coordinates ~50 times the radius of the ball: 1e-12 rather than 1e-16
    assert _sine(n[ok], d[ok]).max() < 1e-9
    # the residual is the square root of an eigenvalue at round-off (~1e-16 of the largest)
    assert np.nanmax(residual) < 1e-7


def test_normals_are_exact_on_a_half_sphere_patch_up_to_its_border():
    centre, r, d, p = _random_sphere(7, n=4000)
    half = d[:, 2] > 0.0
    p, d = p[half], d[half]
    radius = 0.4 * r
    indptr, indices, _ = _csr(p, radius)
    n, _, _ = sphere_normals(p, p, indptr, indices, radius)
    # NaN exactly where the ball holds fewer than 6 points (the point itself included)
    ok = np.isfinite(n).all(axis=1)
    assert np.array_equal(ok, np.diff(indptr) >= 6)
    border = d[:, 2] < 0.2            # one-sided balls: the PCA plane tilts most there
    assert ok[border].mean() > 0.98
    assert _sine(n[ok], d[ok]).max() < 1e-9


def test_normals_are_exact_on_planes():
    rng = np.random.default_rng(3)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    t = np.linalg.svd(normal[None, :])[2][1:]          # two tangent directions
    uv = rng.uniform(-5, 5, (3000, 2)) ** 3 / 25       # clumped sampling
    p = rng.uniform(-100, 100, 3) + uv @ t
    indptr, indices, _ = _csr(p, 1.0)
    n, residual, _ = sphere_normals(p, p, indptr, indices, 1.0)
    ok = np.isfinite(n).all(axis=1)
    assert ok.mean() > 0.95
    assert _sine(n[ok], np.tile(normal, (ok.sum(), 1))).max() < 1e-9
    assert np.nanmax(residual) < 1e-7


def test_too_few_points_give_nan():
    p = np.random.default_rng(0).normal(size=(5, 3))
    indptr, indices, _ = _csr(p, 10.0)
    n, residual, gain = sphere_normals(p, p, indptr, indices, 10.0)
    assert np.isnan(n).all() and np.isnan(residual).all() and np.isnan(gain).all()


def test_estimated_normals_make_curvature_on_a_clean_sphere_cloud_exact():
    # irregular sampling: PCA + jet normals tilt (relative error 2.5e-6 measured with the
    # quartic's gradient, 6e-5 with the quadric's), the sphere fit does not; the target of
    # the estimator is 1e-6 relative
    s = surfaces.sphere(sampling="random", n=8000, seed=3, radius=2.5)
    res = meshcurv.principal_curvatures(s.vertices + [7.0, -3.0, 11.0], radius=0.5)
    assert res.valid.all()
    assert np.max(np.abs(res.k1 * 2.5 - 1)) < 1e-6
    assert np.max(np.abs(res.k2 * 2.5 - 1)) < 1e-6
    old = meshcurv.principal_curvatures(s.vertices, radius=0.5, normal_fit="quadric")
    assert np.mean(np.abs(old.k1 * 2.5 - 1)) > 1e-6


def test_sphericity_prefers_the_quadric_where_the_shape_is_no_sphere():
    w = pipeline.sphericity(np.array([1e-3, 1e-3, 1e-8, np.nan, 0.0]),
                            np.array([1e-3, 1e-2, 1e-12, 1e-3, 0.0]))
    np.testing.assert_allclose(w, [1.0, 0.01, 1.0, 0.0, 1.0])


def _noisy_normals(normals, sigma, seed):
    n = normals + np.random.default_rng(seed).normal(scale=sigma, size=normals.shape)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_exact_given_normals_are_kept_bit_for_bit():
    s = surfaces.sphere(sampling="random", n=6000, seed=4, radius=2.0)
    res = meshcurv.principal_curvatures(s.vertices, normals=s.normals, radius=0.4,
                                        refine_normals="auto")
    kept = meshcurv.principal_curvatures(s.vertices, normals=s.normals, radius=0.4,
                                         refine_normals=False)
    assert np.array_equal(res.normals, kept.normals)
    assert np.array_equal(res.k1, kept.k1) and np.array_equal(res.k2, kept.k2)
    assert np.max(np.abs(res.k1 * 2.0 - 1)) < 1e-12


def test_noisy_given_normals_are_refined_and_the_curvature_improves():
    # the benchmark's noise model: n + N(0, 0.1^2 I), renormalised
    t = surfaces.torus(n_major=200, n_minor=50)
    noisy = _noisy_normals(t.normals, 0.1, seed=5)
    a2 = pipeline.given_normal_noise(t.vertices, noisy, 0.3,
                                     pipeline.ball_search(t.vertices,
                                                          np.arange(len(t.vertices)), 0.3),
                                     np.arange(len(t.vertices)))
    # per tangent component the noise is 0.1: a2 ~ 0.01 (biased low by the fits' own error)
    assert 0.006 < a2 < 0.012
    kept = meshcurv.principal_curvatures(t.vertices, normals=noisy, radius=0.3,
                                         neighborhood="ball", refine_normals=False)
    res = meshcurv.principal_curvatures(t.vertices, normals=noisy, radius=0.3,
                                        neighborhood="ball", refine_normals="auto")
    ang_kept = np.mean(_sine(kept.normals, t.normals))
    ang = np.mean(_sine(res.normals, t.normals))
    assert ang < 0.2 * ang_kept
    err_kept = np.nanmean(np.abs(kept.k1 - t.k1) + np.abs(kept.k2 - t.k2))
    err = np.nanmean(np.abs(res.k1 - t.k1) + np.abs(res.k2 - t.k2))
    assert err < 0.5 * err_kept


def test_exact_given_normals_on_noisy_positions_are_kept():
    t = surfaces.add_normal_noise(surfaces.torus(n_major=200, n_minor=50), 0.002, seed=6)
    res = meshcurv.principal_curvatures(t.vertices, normals=t.normals, radius=0.4,
                                        neighborhood="ball", refine_normals="auto")
    kept = meshcurv.principal_curvatures(t.vertices, normals=t.normals, radius=0.4,
                                         neighborhood="ball", refine_normals=False)
    assert np.array_equal(res.normals, kept.normals)


def test_refine_normals_takes_only_its_documented_values():
    with pytest.raises(ValueError, match="refine_normals must be"):
        meshcurv.principal_curvatures(np.zeros((10, 3)), radius=1.0, refine_normals="yes")
