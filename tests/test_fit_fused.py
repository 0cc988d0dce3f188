"""The fused per-point kernel (meshcurv.fit.fused) agrees with its numpy specification
(meshcurv.fit.fused_spec) to round-off."""

import numpy as np
import pytest

from meshcurv import surfaces
from meshcurv.fit import fused, fused_spec

from neighbor_lists import ball_csr


@pytest.mark.parametrize("options", [
    dict(),
    dict(blend=0.0),
    dict(blend=0.37, circle_normalization="unit"),
    dict(section_blend=False, robust=False),
    dict(half_frequency=True, n_directions=6, slab=0.4),
    dict(blend=1.0, taper=0.0),
    dict(blend=0.6, taper=0.95),
])
def test_kernel_matches_numpy_reference(options):
    """The compiled kernel and the readable reference agree to round-off (1e-9) on a noisy torus."""
    rng = np.random.default_rng(1)
    s = surfaces.torus(n_major=100, n_minor=30)
    v = s.vertices + rng.normal(scale=0.01, size=s.vertices.shape)
    radius = 0.45
    indptr, indices = ball_csr(v, radius)
    m = len(v)
    out = dict(k1=np.empty(m), k2=np.empty(m), d1=np.empty((m, 3)), d2=np.empty((m, 3)),
               n_samples=np.empty(m), residual=np.empty(m), n_neighbors=np.empty(m),
               status=np.empty(m, dtype=np.int8))
    opt = dict(n_directions=8, slab=0.25, blend=1.0, circle_normalization="tangent",
               section_blend=True, half_frequency=False, robust=True) | options
    fit = (opt["n_directions"], opt["slab"], 3.0, 0.25, opt["circle_normalization"] == "unit",
           opt["section_blend"], opt["half_frequency"], opt["robust"])
    taper = None if "taper" not in opt else np.full(m, opt["taper"])
    fused.curvature_cga(v, v, s.normals, indptr, indices, radius, np.full(m, opt["blend"]), fit,
                        tuple(out.values()), taper=taper)
    checked = 0
    for i in range(0, m, 7):
        ref = fused_spec.curvature_at_point(v[i], s.normals[i],
                                            v[indices[indptr[i]:indptr[i + 1]]], radius, **opt)
        for key in ("k1", "k2", "residual"):
            assert out[key][i] == pytest.approx(ref[key], rel=1e-9, abs=1e-9, nan_ok=True), key
        assert out["n_samples"][i] == ref["n_samples"]
        if np.isfinite(ref["k1"]):
            assert abs(out["d1"][i] @ ref["d1"]) == pytest.approx(1.0, abs=1e-9)
            checked += 1
    assert checked > 100
