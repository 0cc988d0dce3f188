"""Normal-aware circle fits (meshcurv.fit.circle with point normals): exact on spheres and
cylinders with exact normals, the kernel held to its numpy specification, and under position
noise with exact normals far more accurate than positions alone."""

import numpy as np
import pytest

import meshcurv
from meshcurv import surfaces
from meshcurv.fit import fused, fused_spec

from neighbor_lists import ball_csr


def run_kernel(v, normals, radius, point_normals, fit=(8, 0.25, 3.0, 0.25, False, True, False,
                                                       True), blend=1.0, noise=0.0, gain=1.0):
    indptr, indices = ball_csr(v, radius)
    m = len(v)
    out = dict(k1=np.empty(m), k2=np.empty(m), d1=np.empty((m, 3)), d2=np.empty((m, 3)),
               n_samples=np.empty(m), residual=np.empty(m), n_neighbors=np.empty(m),
               status=np.empty(m, dtype=np.int8))
    fused.curvature_cga(v, v, normals, indptr, indices, radius, np.full(m, blend), fit,
                        tuple(out.values()), None, point_normals, np.broadcast_to(
                            np.asarray(noise, dtype=np.float64), (m,)).copy(),
                        np.broadcast_to(np.asarray(gain, dtype=np.float64), (m,)).copy())
    return out, indptr, indices


@pytest.mark.parametrize("options", [
    dict(),
    dict(blend=0.0),
    dict(blend=0.37, circle_normalization="unit"),
    dict(section_blend=False, robust=False),
    dict(half_frequency=True, n_directions=6, slab=0.4),
])
def test_kernel_with_normals_matches_numpy_reference(options):
    """Kernel and specification agree to 1e-9 on a noisy torus with noisy normals (a few NaN)."""
    rng = np.random.default_rng(1)
    s = surfaces.torus(n_major=100, n_minor=30)
    v = s.vertices + rng.normal(scale=0.01, size=s.vertices.shape)
    nv = s.normals + rng.normal(scale=0.05, size=s.normals.shape)
    nv /= np.linalg.norm(nv, axis=1, keepdims=True)
    nv[::97] = np.nan
    nv[5::61] *= -1.0        # a few flipped: turned round by the fit
    radius = 0.45
    opt = dict(n_directions=8, slab=0.25, blend=1.0, circle_normalization="tangent",
               section_blend=True, half_frequency=False, robust=True) | options
    fit = (opt["n_directions"], opt["slab"], 3.0, 0.25, opt["circle_normalization"] == "unit",
           opt["section_blend"], opt["half_frequency"], opt["robust"])
    query_normals = np.where(np.isfinite(nv), nv, s.normals)
    noise = rng.uniform(0.0, 0.02, len(v))
    noise[::53] = np.nan           # no noise measure: positions only
    gain = rng.uniform(0.0, 1.0, len(v))
    out, indptr, indices = run_kernel(v, query_normals, radius, nv, fit, opt["blend"], noise,
                                      gain)
    checked = 0
    for i in range(0, len(v), 7):
        nb = indices[indptr[i]:indptr[i + 1]]
        ref = fused_spec.curvature_at_point(v[i], query_normals[i], v[nb], radius,
                                            neighbor_normals=nv[nb], noise=noise[i],
                                            normal_gain=gain[i], **opt)
        for key in ("k1", "k2", "residual"):
            assert out[key][i] == pytest.approx(ref[key], rel=1e-9, abs=1e-9, nan_ok=True), key
        assert out["n_samples"][i] == ref["n_samples"]
        if np.isfinite(ref["k1"]):
            assert abs(out["d1"][i] @ ref["d1"]) == pytest.approx(1.0, abs=1e-9)
            checked += 1
    assert checked > 100


def test_row_weights_are_reported_and_taken_as_given():
    """``row_weight``: NaN entries are measured and written back (the specification's
    row_weight), finite ones used instead of measuring: a second call at a smaller radius with
    the first call's weights equals the specification given those weights."""
    rng = np.random.default_rng(3)
    s = surfaces.torus(n_major=100, n_minor=30)
    v = s.vertices + rng.normal(scale=0.002, size=s.vertices.shape)
    nv = s.normals + rng.normal(scale=0.02, size=s.normals.shape)
    nv /= np.linalg.norm(nv, axis=1, keepdims=True)
    m, radius = len(v), 0.45
    fit = (8, 0.25, 3.0, 0.25, False, True, False, True)
    noise, gain = np.full(m, 0.002), np.full(m, 0.8)
    indptr, indices = ball_csr(v, radius)
    weights = []
    for r, given in ((radius, np.full(m, np.nan)), (radius / np.sqrt(2), None)):
        w = given if given is not None else weights[0].copy()
        out = tuple(np.empty(m) for _ in range(2)) + tuple(np.empty((m, 3)) for _ in range(2)) \
            + (np.empty(m), np.empty(m), np.empty(m), np.empty(m, dtype=np.int8))
        fused.curvature_cga(v, v, s.normals, indptr, indices, r, np.ones(m), fit, out, None, nv,
                            noise, gain, None, w)
        weights.append(w)
        for i in range(0, m, 23):
            nb = indices[indptr[i]:indptr[i + 1]]
            ref = fused_spec.curvature_at_point(
                v[i], s.normals[i], v[nb], r, neighbor_normals=nv[nb], noise=noise[i],
                normal_gain=gain[i], row_weight=None if given is not None else weights[0][i])
            assert out[0][i] == pytest.approx(ref["k1"], rel=1e-9, abs=1e-9, nan_ok=True)
            assert w[i] == pytest.approx(ref["row_weight"], rel=1e-9)
    assert np.all(np.isfinite(weights[0]) & (weights[0] > 0))
    np.testing.assert_array_equal(weights[1], weights[0])    # used, not measured again


def random_sphere(n, rng):
    p = rng.normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_exact_on_a_sphere_with_exact_normals():
    """Random points of the unit sphere, exact normals: k1 = k2 = 1 to round-off, at every
    weight blend (the normal rows are exact there, like the position rows)."""
    v = random_sphere(4000, np.random.default_rng(2))
    for blend in (0.0, 1.0):
        out, _, _ = run_kernel(v, v.copy(), 0.3, v.copy(), blend=blend)
        ok = np.isfinite(out["k1"])
        assert ok.mean() > 0.99
        np.testing.assert_allclose(out["k1"][ok], 1.0, atol=1e-9)
        np.testing.assert_allclose(out["k2"][ok], 1.0, atol=1e-9)


def test_exact_on_a_cylinder_with_exact_normals():
    """Random points of a cylinder of radius 2: k1 = 1/2, k2 = 0 (K = 0) to round-off: the normal
    rows' direction mix (the slab's offsets across) is modelled exactly."""
    rng = np.random.default_rng(3)
    t = rng.uniform(0, 2 * np.pi, 6000)
    z = rng.uniform(-3, 3, 6000)
    v = np.column_stack([2 * np.cos(t), 2 * np.sin(t), z])
    nv = np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
    r = meshcurv.principal_curvatures(v, normals=nv, radius=0.8)
    inner = r.valid & (np.abs(z) < 2.0)
    assert inner.sum() > 3000
    # positions alone are exact on a cylinder only up to the slab's first-order direction mix
    # (max |dk1| ~ 1e-3 here); the exact normals' rows have no residual and carry the fit,
    # weighed against the position rows by the measured noise: ~1e-6 is left
    np.testing.assert_allclose(r.k1[inner], 0.5, atol=1e-5)
    np.testing.assert_allclose(r.k2[inner], 0.0, atol=1e-5)
    off = meshcurv.principal_curvatures(v, normals=nv, radius=0.8, normal_constraints="off")
    assert np.max(np.abs(off.k1[inner] - 0.5)) > 1e-4


def test_exact_normals_beat_positions_under_position_noise():
    """Torus cloud (R 2, r 0.5) with position noise 1 % of the tube radius... and exact normals:
    the normal-aware fit has a fraction of the positions-only error in H."""
    rng = np.random.default_rng(4)
    n = 20000
    s = surfaces.torus(n_major=200, n_minor=100)
    pick = rng.choice(len(s.vertices), n, replace=False)
    v = s.vertices[pick] + rng.normal(scale=0.02, size=(n, 3))
    nv = s.normals[pick]
    h = 0.5 * (s.k1[pick] + s.k2[pick])
    query = np.arange(0, n, 10)
    err = {}
    for mode in ("off", "auto"):
        r = meshcurv.principal_curvatures(v, normals=nv, radius=0.3, query=query,
                                          normal_constraints=mode)
        assert r.valid.mean() > 0.99
        err[mode] = np.nanmean(np.abs(r.mean - h[query]))
    assert err["auto"] < 0.3 * err["off"], err
