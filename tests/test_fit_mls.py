"""The MLS curvature kernel (meshcurv.fit.mls) against its numpy specification and exact
surfaces, and its use on meshes coarse for their shape (meshcurv.coarse)."""

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import meshcurv
from meshcurv import coarse as coarse_mls
from meshcurv import surfaces
from meshcurv.fit.mls import mls_curvature, mls_normals
from meshcurv.fit.mls_spec import STEP, mls_curvature_at, mls_normal_at, potential
from meshcurv.neighbors import default_radius


def _lists(points, radius, queries):
    found = cKDTree(points).query_ball_point(points[queries], radius)
    indptr = np.concatenate([[0], np.cumsum([len(a) for a in found])]).astype(np.int64)
    return indptr, np.concatenate(found).astype(np.int64), found


def _kernel(points, normals, queries, support, weights=None, rows=None):
    m = len(queries)
    out = (np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3)))
    indptr, indices, found = _lists(points, support * (1 + 2 * STEP), queries)
    mls_curvature(points, normals, points[queries], normals[queries],
                  queries if rows is None else rows, indptr, indices,
                  np.full(m, support), weights, out)
    return out, found


def _coarse_torus(major=1.0, minor=0.3, n_major=64, n_minor=16):
    mesh = trimesh.creation.torus(major, minor, major_sections=n_major,
                                  minor_sections=n_minor)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    return v, np.asarray(mesh.faces, dtype=np.int64), surfaces.torus_at(v, major, minor)


def _mean_dk(res, truth):
    return float(np.mean(0.5 * (np.abs(res.k1 - truth.k1) + np.abs(res.k2 - truth.k2))))


def test_potential_of_points_on_a_sphere_is_the_signed_distance():
    # every oriented sphere fit of points and outward normals of a sphere is that sphere:
    # F(x) = (|x - c|^2 - r^2) / (2 r), i.e. the signed distance to first order
    s = surfaces.sphere(2.0, subdivisions=3)
    for x in ([0.0, 0.0, 2.1], [1.2, -0.3, 1.5]):
        x = np.asarray(x)
        d = np.linalg.norm(x)
        assert potential(x, s.vertices, s.normals, 1.5) == pytest.approx(
            (d * d - 4.0) / 4.0, abs=1e-12)


def test_kernel_matches_the_specification():
    v, _, truth = _coarse_torus()
    rng = np.random.default_rng(0)
    weights = rng.uniform(0.3, 1.0, len(v))
    queries = np.arange(0, len(v), 29)
    for w in (None, weights):
        (k1, k2, d1, d2, n), found = _kernel(v, truth.normals, queries, 0.42, w)
        for i, q in enumerate(queries):
            e1, e2, f1, f2, fn = mls_curvature_at(v[q], truth.normals[q], v[found[i]],
                                                  truth.normals[found[i]], 0.42,
                                                  None if w is None else w[found[i]])
            # the kernel's derivatives are exact, the specification's central differences off
            # by their truncation and their rounding amplified by 1 / STEP^2: ~1e-8 of k
            assert k1[i] == pytest.approx(e1, rel=1e-7, abs=1e-7)
            assert k2[i] == pytest.approx(e2, rel=1e-7, abs=1e-7)
            assert np.allclose(n[i], fn, atol=1e-9)
            assert min(np.abs(d1[i] - f1).max(), np.abs(d1[i] + f1).max()) < 1e-6
            assert np.allclose(np.cross(n[i], d1[i]), d2[i], atol=1e-12)


def test_normals_kernel_matches_its_specification_and_the_curvature_kernels_normals():
    v, _, truth = _coarse_torus()
    rng = np.random.default_rng(1)
    # tilted normals: the fits' normals then differ from the surface's
    tilted = truth.normals + rng.normal(0.0, 0.05, truth.normals.shape)
    tilted /= np.linalg.norm(tilted, axis=1, keepdims=True)
    weights = rng.uniform(0.3, 1.0, len(v))
    queries = np.arange(0, len(v), 13)
    for w in (None, weights):
        (_, _, _, _, n), found = _kernel(v, tilted, queries, 0.42, w)
        indptr, indices, _ = _lists(v, 0.42 * (1 + 2 * STEP), queries)
        only = np.empty((len(queries), 3))
        # the query normals flipped: the result follows their side
        mls_normals(v, tilted, v[queries], -tilted[queries], queries, indptr, indices,
                    np.full(len(queries), 0.42), w, only)
        assert np.array_equal(only, -n)       # the same gradient, bit for bit
        for i, q in enumerate(queries):
            spec = mls_normal_at(v[q], -tilted[q], v[found[i]], tilted[found[i]], 0.42,
                                 None if w is None else w[found[i]])
            # the specification's central differences: truncation ~STEP^2 of the gradient's
            # change over the support (2e-9 measured on these tilted normals)
            assert np.allclose(only[i], spec, atol=1e-8)
    # no point within the support: no normal
    far = np.array([[10.0, 0.0, 0.0]])
    out = np.empty((1, 3))
    mls_normals(v, tilted, far, far, np.array([-1]), np.array([0, 0]), np.zeros(0, np.int64),
                np.array([0.42]), None, out)
    assert np.isnan(out).all()


def test_sphere_is_exact_and_the_own_row_counts_once():
    # points of a sphere with exact normals: every fit is the sphere itself, so F is exactly
    # quadratic and its exact derivatives give 1/2 up to rounding (2e-15 measured)
    s = surfaces.sphere(2.0, subdivisions=3)
    queries = np.arange(0, len(s.vertices), 13)
    (k1, k2, _, _, n), _ = _kernel(s.vertices, s.normals, queries, 0.8)
    assert np.allclose(k1, 0.5, rtol=0, atol=1e-12) and np.allclose(k2, 0.5, rtol=0, atol=1e-12)
    assert np.allclose(n, s.normals[queries], rtol=0, atol=1e-12)
    # the query's own row is in its ball list: the same whether or not it is named
    (j1, j2, _, _, _), _ = _kernel(s.vertices, s.normals, queries, 0.8, rows=-np.ones_like(
        queries))
    assert np.allclose(j1, k1, rtol=0, atol=1e-12)


def test_sign_follows_the_query_normal_and_empty_balls_give_nan():
    s = surfaces.sphere(1.0, subdivisions=3)
    q = np.array([0, 5])
    (k1, _, _, _, n), _ = _kernel(s.vertices, s.normals, q, 0.6)
    flipped = -s.normals
    m = len(q)
    out = (np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3)))
    indptr, indices, _ = _lists(s.vertices, 0.6 * (1 + 2 * STEP), q)
    mls_curvature(s.vertices, flipped, s.vertices[q], flipped[q], q, indptr, indices,
                  np.full(m, 0.6), None, out)
    assert np.allclose(out[0], -k1, rtol=0, atol=1e-12)
    assert np.allclose(out[4], -n, rtol=0, atol=1e-12)
    # one point alone has no sphere: NaN, no error
    out = (np.empty(1), np.empty(1), np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 3)))
    mls_curvature(s.vertices, s.normals, s.vertices[:1], s.normals[:1], np.array([0]),
                  np.array([0, 0]), np.zeros(0, np.int64), np.array([1e-3]), None, out)
    assert np.isnan(out[0]).all() and np.isnan(out[4]).all()


def test_dense_torus_mls_is_second_order():
    # clean 240 x 60 torus, support 0.3: mean |dk| 9e-5 measured (the circle fits: 5e-4)
    t = surfaces.torus(2.0, 0.5, 240, 60)
    queries = np.arange(0, len(t.vertices), 41)
    (k1, k2, _, _, _), _ = _kernel(t.vertices, t.normals, queries, 0.3)
    err = 0.5 * (np.abs(k1 - t.k1[queries]) + np.abs(k2 - t.k2[queries]))
    assert err.mean() < 3e-4


@pytest.mark.parametrize("torus, circles, limit", [
    ((1.0, 0.3, 64, 16), 0.0408, 0.010),
    ((3.0, 1.0, 40, 20), 0.0221, 0.005),
    ((2.0, 0.5, 32, 32), 0.0276, 0.010),
    ((1.0, 0.2, 32, 32), 0.0694, 0.025)])
def test_coarse_tori_get_the_mls_curvature(torus, circles, limit):
    # measured: 0.0058, 0.0019, 0.0044, 0.018 (the circle fits alone: the second column)
    v, f, truth = _coarse_torus(*torus)
    assert default_radius(v, faces=f, details=True)[1]
    res = meshcurv.principal_curvatures(v, f)
    assert res.valid.all() and _mean_dk(res, truth) < limit
    alone = meshcurv.principal_curvatures(v, f, coarse_fit="circles")
    assert _mean_dk(alone, truth) == pytest.approx(circles, abs=1e-4)
    # the result's frame is the MLS surface's: right-handed, unit, normals outward
    assert np.allclose(np.cross(res.normals, res.d1), res.d2, atol=1e-9)
    assert np.mean(np.einsum("ij,ij->i", res.normals, truth.normals) > 0.999) == 1.0
    # the same radius given: the probe finds the circle fits limited by the sampling, and
    # the same blend follows
    fixed = meshcurv.principal_curvatures(v, f, radius=res.radius)
    for name in ("k1", "k2", "d1", "d2", "normals"):
        assert np.allclose(getattr(fixed, name), getattr(res, name), rtol=0, atol=1e-9)


@pytest.mark.parametrize("torus, circles, limit", [
    ((1.0, 0.3, 64, 16), 0.0535, 0.02),
    ((3.0, 1.0, 40, 20), 0.0188, 0.005),
    ((2.0, 0.5, 32, 32), 0.0283, 0.008),
    ((1.0, 0.2, 32, 32), 0.0679, 0.025)])
def test_coarse_tori_as_clouds_get_the_mls_curvature(torus, circles, limit):
    # the same vertices without faces (a support of the 12th nearest point's distance):
    # measured 0.013, 0.0025, 0.0041, 0.018
    v, _, truth = _coarse_torus(*torus)
    assert default_radius(v, details=True)[1]
    res = meshcurv.principal_curvatures(v)
    assert res.valid.all() and _mean_dk(res, truth) < limit
    alone = meshcurv.principal_curvatures(v, coarse_fit="circles")
    assert _mean_dk(alone, truth) == pytest.approx(circles, abs=1e-4)


@pytest.mark.parametrize("faces", [True, False])
def test_coarse_queries_give_the_rows_of_the_whole_input(faces):
    v, f, _ = _coarse_torus()
    f = f if faces else None
    whole = meshcurv.principal_curvatures(v, f)
    q = np.array([7, 500, 3, 1000, 7])
    part = meshcurv.principal_curvatures(v, f, query=q)
    for name in ("k1", "k2", "d1", "d2", "normals", "noise", "mls_share"):
        assert np.allclose(getattr(part, name), getattr(whole, name)[q], rtol=0, atol=1e-12)


def _same_bits(a, b):
    return all(np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True)
               for name in ("k1", "k2", "d1", "d2", "normals", "valid"))


def test_inputs_whose_circle_fits_are_not_limited_by_the_sampling_keep_them():
    # not coarse, and the probe's median disagreement stays near the MLS estimate's own
    # change (ratio 0.5-2.0 on these, against 2.5): the circle fits' bits at the default
    # radius (given: by default the ellipsoid's ends take smaller balls, whose calls probe
    # again)
    ellipsoid = surfaces.ellipsoid((2.0, 1.5, 1.0), 4)
    saddle = surfaces.monkey_saddle(sampling="random", n=4000)
    torus = surfaces.torus(2.0, 0.5, 240, 60)
    noisy = surfaces.add_normal_noise(torus, 0.001, seed=1)
    icosphere = trimesh.creation.icosphere(3)
    for v, f in ((icosphere.vertices, icosphere.faces), (ellipsoid.vertices, ellipsoid.faces),
                 (saddle.vertices, saddle.faces), (noisy.vertices, noisy.faces)):
        v, f = np.asarray(v, dtype=np.float64), np.asarray(f)
        for faces in (f, None):
            r, coarse = default_radius(v, faces=faces, details=True)
            assert not coarse
            a = meshcurv.principal_curvatures(v, faces, radius=r)
            assert _same_bits(a, meshcurv.principal_curvatures(v, faces, radius=r,
                                                               coarse_fit="circles"))


def test_a_cloud_with_normals_just_limited_by_its_sampling_gets_the_mls_surface():
    # the 200 x 40 torus's vertices with their exact normals: probe ratio 2.45, just above
    # DISAGREEMENT_RATIO; circle fits 0.00127, the blend 0.00020 (bound 1.5x that)
    mesh = surfaces.torus(2.0, 0.5, 200, 40)
    alone = meshcurv.principal_curvatures(mesh.vertices, normals=mesh.normals,
                                          coarse_fit="circles")
    assert _mean_dk(alone, mesh) == pytest.approx(0.00127, rel=0.05)
    res = meshcurv.principal_curvatures(mesh.vertices, normals=mesh.normals)
    assert res.valid.all() and _mean_dk(res, mesh) < 0.0003


@pytest.mark.parametrize("torus, circles, limit", [
    # (mean |dk| of the circle fits alone, bound): measured 0.00093 / 0.0028 (120 x 30) and
    # 0.00085 / 0.00114 (trimesh's 128 x 32) with the MLS surface, meshes / clouds; bounds at
    # 1.5-2x those, and at most 0.35x the circle fits. (trimesh's 96 x 24 is coarse for its
    # shape since the default radius keeps three quarters of its balls local patches: radius
    # 0.39 -> 0.28, blended as coarse, 0.0014 / 0.0019)
    ((2.0, 0.5, 120, 30, "surfaces"), (0.0100, 0.0106), (0.0015, 0.0045)),
    ((1.0, 0.3, 128, 32, "trimesh"), (0.0144, 0.0148), (0.0015, 0.0020)),
])
def test_regular_tori_not_coarse_get_the_mls_surface(torus, circles, limit):
    major, minor, n_major, n_minor, source = torus
    if source == "surfaces":
        mesh = surfaces.torus(major, minor, n_major, n_minor)
        v, f = mesh.vertices, mesh.faces
        truth = surfaces.torus_at(v, major, minor)
    else:
        v, f, truth = _coarse_torus(major, minor, n_major, n_minor)
    for faces, before, bound in zip((f, None), circles, limit):
        assert not default_radius(v, faces=faces, details=True)[1]
        alone = _mean_dk(meshcurv.principal_curvatures(v, faces, coarse_fit="circles"), truth)
        assert alone == pytest.approx(before, rel=0.05)
        res = meshcurv.principal_curvatures(v, faces)
        assert res.valid.all()
        assert _mean_dk(res, truth) < min(bound, 0.35 * alone)


@pytest.mark.parametrize("faces, radius", [(True, None), (False, None), (True, "auto")])
def test_probed_queries_give_the_rows_of_the_whole_input(faces, radius):
    mesh = surfaces.torus(2.0, 0.5, 120, 30)
    f = mesh.faces if faces else None
    whole = meshcurv.principal_curvatures(mesh.vertices, f, radius=radius)
    assert not _same_bits(whole, meshcurv.principal_curvatures(mesh.vertices, f, radius=radius,
                                                               coarse_fit="circles"))
    q = np.array([7, 3000, 3, 1000, 7])
    part = meshcurv.principal_curvatures(mesh.vertices, f, radius=radius, query=q)
    for name in ("k1", "k2", "d1", "d2", "normals", "noise", "mls_share"):
        assert np.allclose(getattr(part, name), getattr(whole, name)[q], rtol=0, atol=1e-12)


def test_radius_auto_blends_where_the_default_does():
    # the probe judges the default radius's circle fits for "auto" too, so a torus whose
    # circle fits are limited by the sampling (96 x 24) gets the MLS surface: measured 0.0029
    # (the default 0.0038; "auto" with the circle fits alone 0.016); its own fits are nearer
    # the MLS surface's, and the torus's probe would keep them (ratio 2.42)
    v, f, truth = _coarse_torus(1.0, 0.3, 96, 24)
    auto = _mean_dk(meshcurv.principal_curvatures(v, f, radius="auto"), truth)
    default = _mean_dk(meshcurv.principal_curvatures(v, f), truth)
    alone = _mean_dk(meshcurv.principal_curvatures(v, f, radius="auto", coarse_fit="circles"),
                     truth)
    assert auto <= default and auto < 0.35 * alone


@pytest.mark.parametrize("faces", [True, False])
def test_radius_auto_keeps_the_default_radius_on_inputs_coarse_for_their_shape(faces):
    # the default radius was made smaller so that its balls stay on a local patch; the
    # per-vertex scale around it lost to it on half of the coarse tori (measured before:
    # trimesh's 1 / 0.2, 32 x 32, as a cloud 0.018 -> 0.38, 2 / 0.5 as a cloud 0.0041 ->
    # 0.016, 1 / 0.3, 48 x 16 as a cloud 0.015 -> 0.066, 1 / 0.3, 24 x 8 mesh 0.085 -> 0.15;
    # it won on 1 / 0.3, 64 x 16, 0.0058 -> 0.0042, and 32 x 12 as a cloud, 0.52 -> 0.18)
    v, f, truth = _coarse_torus(1.0, 0.2, 32, 32)
    f = f if faces else None
    assert default_radius(v, faces=f, details=True)[1]
    auto = meshcurv.principal_curvatures(v, f, radius="auto")
    default = meshcurv.principal_curvatures(v, f)
    assert _same_bits(auto, default)
    assert np.array_equal(auto.radius_used, default.radius_used) and auto.radius == default.radius
    assert _mean_dk(auto, truth) < 0.025


def test_the_result_says_how_much_of_each_row_is_the_mls_surfaces():
    # mls_share: the blend's weight g = 1 / (1 + (noise / (0.015 R))^4) per row, 0 where the
    # row kept its circle fits; None where no blend ran. The noise is the row's own where no
    # point of its support is rough (noise above ROUGH_NOISE * 0.015 R; none here): on a
    # mesh the smaller of the jet's (res.noise) and the rings'
    from meshcurv.pipeline import clean_fraction
    from meshcurv.ring_noise import ring_noise

    v, f, truth = _coarse_torus()
    res = meshcurv.principal_curvatures(v, f)
    noise = np.fmin(res.noise, ring_noise(v, f)[0])
    assert np.array_equal(res.mls_share,
                          clean_fraction(noise, coarse_mls.NOISE_SCALE * res.radius))
    assert res.mls_share.min() > 0.99           # clean: measured 0.9999996 (the jet's 0.908)
    cloud = meshcurv.principal_curvatures(v)
    assert np.array_equal(cloud.mls_share,
                          clean_fraction(cloud.noise, coarse_mls.NOISE_SCALE * cloud.radius))
    assert meshcurv.principal_curvatures(v, f, coarse_fit="circles").mls_share is None
    # a clean ellipsoid at its default radius: the probe keeps the circle fits, no blend
    e = surfaces.ellipsoid((2.0, 1.5, 1.0), 4)
    r = default_radius(e.vertices, faces=e.faces)
    assert meshcurv.principal_curvatures(e.vertices, e.faces, radius=r).mls_share is None
    # a row with no estimate keeps share 0
    bad = v.copy()
    bad[5] = np.nan
    assert meshcurv.principal_curvatures(bad, f).mls_share[5] == 0.0


def test_a_sharp_edge_within_the_mls_support_leaves_the_row_to_the_circle_fits():
    # a capped cylinder r 1, h 3 (trimesh's 256 sections), 30k points: the probe finds its
    # circle fits limited by the faceted sampling and blends the MLS surface in; rows whose
    # support reaches the rim (the jet's residual there 0.03-0.05 of the radius) keep the
    # circle fits. Rows at least a radius from the rim, mean max(|dk1|, |dk2|): measured
    # 0.0096 and 0.0011 on the caps (the circle fits alone 0.0159 and 0; the support's
    # noise ignored: 0.065 and 0.14, the band 1-1.5 radii from the rim 0.50)
    c = trimesh.creation.cylinder(radius=1.0, height=3.0, sections=256)
    p = np.asarray(trimesh.sample.sample_surface_even(c, 30000, seed=3)[0])
    rho = np.hypot(p[:, 0], p[:, 1])
    side = rho > 0.999
    rim = np.where(side, 1.5 - np.abs(p[:, 2]), 1.0 - rho)
    res = meshcurv.principal_curvatures(p)
    assert res.mls_share is not None and res.mls_share.mean() > 0.5     # measured 0.73
    err = np.maximum(np.abs(res.k1 - np.where(side, 1.0, 0.0)), np.abs(res.k2))
    far = (rim >= res.radius) & res.valid
    assert far.sum() > 0.7 * len(p)
    assert err[far].mean() < 0.016                  # the circle fits alone: 0.0159
    assert err[far & ~side].mean() < 0.005 and np.percentile(err[far], 99) < 0.08
    assert np.all(res.mls_share[rim < 0.9 * res.radius] < 0.1)


def test_noise_leaves_coarse_tori_to_the_circle_fits():
    # Gaussian noise along the normal of 0.5 % of the diagonal: the blend gives the circle
    # fits nearly all the weight (measured 0.0858 against 0.0850 alone); 0.05 %: the MLS
    # surface most (0.026 against 0.086)
    v, f, truth = _coarse_torus()
    diag = np.linalg.norm(np.ptp(v, axis=0))
    step = np.random.default_rng(0).normal(size=len(v))[:, None] * truth.normals
    for sigma, most in ((0.005, 1.05), (0.0005, 0.5)):
        noisy = v + sigma * diag * step
        both = _mean_dk(meshcurv.principal_curvatures(noisy, f), truth)
        alone = _mean_dk(meshcurv.principal_curvatures(noisy, f, coarse_fit="circles"),
                         truth)
        assert both < most * alone


def test_coarse_estimate_is_invariant_to_rotation_translation_and_scale():
    # rounding only (the MLS surface's derivatives are exact): 4e-13 of k measured
    from scipy.spatial.transform import Rotation

    v, f, _ = _coarse_torus()
    base = meshcurv.principal_curvatures(v, f)
    turn = Rotation.from_euler("xyz", [0.3, 1.1, -0.7]).as_matrix()
    moved = meshcurv.principal_curvatures(v @ turn.T + [5.0, -2.0, 1.0], f)
    assert np.allclose(moved.k1, base.k1, rtol=0, atol=1e-10)
    assert np.allclose(moved.normals, base.normals @ turn.T, rtol=0, atol=1e-12)
    for scale in (1e-3, 2.0 ** -700, 2.0 ** 600):
        res = meshcurv.principal_curvatures(v * scale, f)
        assert res.valid.all()
        assert np.allclose(res.k1 * scale, base.k1, rtol=0, atol=1e-10)
        assert np.allclose(res.k2 * scale, base.k2, rtol=0, atol=1e-10)


def test_coarse_estimate_far_from_the_origin_as_at_it():
    # a scan in UTM coordinates: the fits work in offsets from the query point (a central
    # difference's step of 1e-4 of the support added to x ~ 5e6 was rounded to 1e-9, 1e-5 of
    # the step: k1 off by 7e-5 on a 20k torus); the input's own rounding there (5e-10) moves
    # k by ~1e-8 (measured)
    v, f, _ = _coarse_torus()
    base = meshcurv.principal_curvatures(v, f)
    assert np.nanmin(base.mls_share) > 0.5
    far = meshcurv.principal_curvatures(v + [512345.0, 5412345.0, 312.0], f)
    assert np.allclose(far.k1, base.k1, rtol=0, atol=1e-7)
    assert np.allclose(far.k2, base.k2, rtol=0, atol=1e-7)


def test_cloud_support_is_the_rule_of_the_12th_nearest_point_bit_for_bit():
    # support(): the grid count that spares dense points the k-d tree gives the rule's bits
    from meshcurv.coarse import CLOUD_RING, SUPPORT_CAP, SUPPORT_EDGES, support

    rng = np.random.default_rng(0)
    v = rng.normal(size=(6000, 3)) * [1.0, 1.0, 0.01]
    v[:3000] *= 20.0                                   # density falling 400x
    v = np.vstack([v, v[:50], [[np.nan, 0.0, 0.0]], [[1e6, 0.0, 0.0]]])  # duplicates, NaN, far
    finite = np.isfinite(v).all(axis=1)
    d = cKDTree(v[finite]).query(v[finite], k=CLOUD_RING + 1)[0][:, CLOUD_RING]
    for radius in (0.05, 0.5, 3.0):
        expected = np.full(len(v), radius)
        expected[finite] = np.clip(SUPPORT_EDGES * d, radius, SUPPORT_CAP * radius)
        h = support(v, None, radius)
        assert np.array_equal(h, expected)
        assert 0 < (h > radius).sum() < len(v)        # both kinds of point present
