"""Golden outputs: refactors and pure speed changes must leave every result bit for bit as it was.

Each case is one :func:`meshcurv.principal_curvatures` call on data built in code (mesh and
cloud, given and estimated normals, k-ring and ball, several option sets). The test hashes the
exact bytes of every per-vertex output (k1, k2, d1, d2, normals, valid and the diagnostics) and
compares them with ``golden_hashes.json``. Tiled runs are not listed: tests/test_tiled.py holds
them equal to these untiled calls.

The bytes depend on more than meshcurv: numpy picks its SIMD kernels by the CPU (on AVX-512
machines some differ from the AVX2 ones in the last bit, which moves k1, k2 by up to 2e-14 of
their scale), and on the versions of numpy, scipy and numba. The cases therefore
run in a child process with numpy held to its baseline kernels (``NPY_DISABLE_CPU_FEATURES``),
and the hashes are checked where the recorded ``profile`` (architecture and those versions) is
this one's. Elsewhere each field is checked against recorded random projections of its values
to 1e-11 of their sum of magnitudes (round-off across kernels measured <= 2e-14 of a value;
any change to the estimator moves them by far more), discrete fields exactly.

A change that is meant to change results regenerates the file and says so in its commit::

    python tests/test_golden.py --update
"""

import hashlib
import json
import os
import platform
import subprocess
import sys

import numpy as np
import pytest
import trimesh

import meshcurv
from meshcurv import surfaces

GOLDEN = os.path.join(os.path.dirname(os.path.abspath(__file__)), "golden_hashes.json")
FIELDS = ("k1", "k2", "d1", "d2", "normals", "valid", "n_neighbors", "n_samples", "residual",
          "noise", "status", "outlier_score", "radius_used")


def _noisy(points, sigma, seed):
    return points + np.random.default_rng(seed).normal(0.0, sigma, points.shape)


def _cases():
    """name -> zero-argument call returning a CurvatureResult."""
    torus = surfaces.torus(n_major=120, n_minor=30)
    sphere = surfaces.sphere(sampling="random", n=3000, seed=1)
    para = surfaces.paraboloid(sampling="random", n=4000, extent=4.0, seed=2)
    cloud = _noisy(sphere.vertices, 0.003, seed=3)
    coarse = trimesh.creation.torus(1.0, 0.3, major_sections=64, minor_sections=16)
    fine = trimesh.creation.torus(1.0, 0.3, major_sections=96, minor_sections=24)
    ellipsoid = surfaces.ellipsoid((2.0, 1.5, 1.0), 3)
    pc = meshcurv.principal_curvatures
    return {
        # the circle fits alone (coarse_fit="circles"), and blended with the MLS surface where
        # the probe finds them limited by the torus's regular sampling
        "torus_kring_given_normals": lambda: pc(torus.vertices, torus.faces, torus.normals,
                                                radius=0.3, coarse_fit="circles"),
        "torus_kring_estimated_normals": lambda: pc(torus.vertices, torus.faces, radius=0.3,
                                                    coarse_fit="circles"),
        "torus_kring_estimated_normals_mls": lambda: pc(torus.vertices, torus.faces,
                                                        radius=0.3),
        "torus_ball_default_radius": lambda: pc(torus.vertices, torus.faces,
                                                neighborhood="ball", coarse_fit="circles"),
        "torus_ball_default_radius_mls": lambda: pc(torus.vertices, torus.faces,
                                                    neighborhood="ball"),
        "noisy_torus_kring_wide_field": lambda: pc(_noisy(torus.vertices, 0.005, seed=4),
                                                   torus.faces, radius=0.3),
        "sphere_cloud_mst": lambda: pc(sphere.vertices, radius=0.25),
        "noisy_sphere_cloud_viewpoint": lambda: pc(cloud, radius=0.3, orientation=(0, 0, 5)),
        "paraboloid_options": lambda: pc(para.vertices, para.faces, para.normals, radius=1.0,
                                         n_directions=6, weighting="none", robust=False,
                                         section_blend=False, coarse_fit="circles"),
        "paraboloid_cloud_query": lambda: pc(para.vertices, radius=1.0, weighting="distance",
                                             query=np.arange(0, len(para.vertices), 7)),
        # coarse for its shape at the default radius: circle fits blended with MLS curvature
        "coarse_torus_mls": lambda: pc(coarse.vertices, coarse.faces),
        "coarse_torus_cloud_mls": lambda: pc(coarse.vertices),
        # per-vertex scale, blended where the default radius's fits are (a torus whose circle
        # fits the probe finds limited by its sampling; coarse inputs keep the default radius)
        "torus_96x24_auto_mls": lambda: pc(fine.vertices, fine.faces, radius="auto"),
        # a clean ellipsoid at its default radius: varying caps, then the ring jets (3-rings
        # of the mesh, nearest neighbours of the cloud)
        "ellipsoid_642_ring_jets": lambda: pc(ellipsoid.vertices, ellipsoid.faces),
        "ellipsoid_642_cloud_ring_jets": lambda: pc(ellipsoid.vertices),
    }


# numpy's dispatched SIMD levels above its x86-64 baseline (those a CPU lacks are ignored);
# elsewhere numpy's own choice (the profile then differs from an x86-64 recording anyway)
BASELINE_KERNELS = ({"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"}
                    if platform.machine().lower() in ("x86_64", "amd64") else {})
N_PROJECTIONS = 4
SKETCH_RTOL = 1e-11


def _profile():
    """What the exact bytes depend on besides meshcurv: architecture and library versions."""
    import numba
    import scipy
    return (f"{platform.machine()} numpy {np.__version__} scipy {scipy.__version__} "
            f"numba {numba.__version__}")


def _sketch(a):
    """``a``'s NaN count, sum of magnitudes and :data:`N_PROJECTIONS` sums weighted by fixed
    random weights in [-1, 1] (NaN counted as 0): any change of one value by more than
    ~SKETCH_RTOL of the sum of magnitudes moves a projection past the tolerance."""
    x = np.asarray(a, dtype=float).ravel()
    nan = np.isnan(x)
    x = np.where(nan, 0.0, x)
    w = np.random.default_rng(0).uniform(-1.0, 1.0, (N_PROJECTIONS, len(x)))
    return {"nan": int(nan.sum()), "abs_sum": float(np.abs(x).sum()),
            "projections": [float(p) for p in w @ x]}


def _digest(result):
    """field -> {"hash": sha256 of the field's exact bytes (dtype and shape included),
    "sketch": :func:`_sketch`}; "radius" -> the radius's exact hex."""
    out = {}
    for name in FIELDS:
        a = np.ascontiguousarray(getattr(result, name))
        h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
        out[name] = {"hash": h.hexdigest()[:20], "sketch": _sketch(a),
                     "discrete": a.dtype.kind in "biu"}
    out["radius"] = float(result.radius).hex()
    return out


def _digests_on_baseline_kernels():
    """Every case's :func:`_digest`, computed in a child process on numpy's baseline kernels,
    with the child's profile."""
    env = dict(os.environ, **BASELINE_KERNELS)
    run = subprocess.run([sys.executable, os.path.abspath(__file__), "--digests"], env=env,
                         capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.splitlines()[-1])


@pytest.fixture(scope="module")
def computed():
    return _digests_on_baseline_kernels()


@pytest.fixture(scope="module")
def golden():
    with open(GOLDEN) as f:
        return json.load(f)


def _changed(recorded, got, exact):
    """Fields of one case whose outputs differ: by hash where ``exact``, else by sketch."""
    if recorded["radius"] != got["radius"]:
        return ["radius"]
    changed = []
    for name in FIELDS:
        r, g = recorded[name], got[name]
        if exact or r["discrete"]:
            same = r["hash"] == g["hash"]
        else:
            rs, gs = r["sketch"], g["sketch"]
            tol = SKETCH_RTOL * rs["abs_sum"]
            same = rs["nan"] == gs["nan"] and all(
                abs(a - b) <= tol for a, b in zip(rs["projections"], gs["projections"]))
        if not same:
            changed.append(name)
    return changed


@pytest.mark.parametrize("name", sorted(_cases()))
def test_outputs_are_bit_identical_to_the_recorded_ones(name, computed, golden):
    cases = golden["cases"]
    assert name in cases, f"no recorded outputs for {name}: python tests/test_golden.py --update"
    exact = golden["profile"] == computed["profile"]
    changed = _changed(cases[name], computed["cases"][name], exact)
    how = "bit for bit" if exact else (f"to {SKETCH_RTOL:g} (recorded on {golden['profile']}, "
                                       f"running on {computed['profile']})")
    assert not changed, f"{name}: outputs changed ({how}) in {', '.join(changed)}"


def test_the_tolerant_check_passes_other_kernels_and_catches_one_changed_value(golden):
    """In this process numpy runs its kernels for this CPU, not the baseline ones."""
    name = "paraboloid_cloud_query"
    result = _cases()[name]()
    assert _changed(golden["cases"][name], _digest(result), exact=False) == []
    result.k1[np.flatnonzero(np.isfinite(result.k1))[10]] *= 1.0 + 1e-6
    assert _changed(golden["cases"][name], _digest(result), exact=False) == ["k1"]


def _all_digests():
    return {"profile": _profile(),
            "cases": {name: _digest(call()) for name, call in sorted(_cases().items())}}


if __name__ == "__main__":
    if sys.argv[1:] == ["--digests"]:
        print(json.dumps(_all_digests()))
    elif sys.argv[1:] == ["--update"]:
        table = _digests_on_baseline_kernels()
        with open(GOLDEN, "w") as f:
            json.dump(table, f, indent=1, sort_keys=True)
            f.write("\n")
        print(f"wrote {len(table['cases'])} cases ({table['profile']}) to {GOLDEN}")
    else:
        sys.exit("usage: python tests/test_golden.py --update")
