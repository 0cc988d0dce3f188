"""Golden outputs: refactors and pure speed changes must leave every result bit for bit as it was.

Each case is one :func:`meshcurv.principal_curvatures` call on data built in code (mesh and
cloud, given and estimated normals, k-ring and ball, several option sets). The test hashes the
exact bytes of every per-vertex output (k1, k2, d1, d2, normals, valid and the diagnostics) and
compares them with ``golden_hashes.json``. Tiled runs are not listed: tests/test_tiled.py holds
them equal to these untiled calls.

A change that is meant to change results regenerates the file and says so in its commit::

    python tests/test_golden.py --update
"""

import hashlib
import json
import os
import sys

import numpy as np
import pytest

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
    pc = meshcurv.principal_curvatures
    return {
        "torus_kring_given_normals": lambda: pc(torus.vertices, torus.faces, torus.normals,
                                                radius=0.3),
        "torus_kring_estimated_normals": lambda: pc(torus.vertices, torus.faces, radius=0.3),
        "torus_ball_default_radius": lambda: pc(torus.vertices, torus.faces,
                                                neighborhood="ball"),
        "sphere_cloud_mst": lambda: pc(sphere.vertices, radius=0.25),
        "noisy_sphere_cloud_viewpoint": lambda: pc(cloud, radius=0.3, orientation=(0, 0, 5)),
        "paraboloid_options": lambda: pc(para.vertices, para.faces, para.normals, radius=1.0,
                                         n_directions=6, weighting="none", robust=False,
                                         section_blend=False),
        "paraboloid_cloud_query": lambda: pc(para.vertices, radius=1.0, weighting="distance",
                                             query=np.arange(0, len(para.vertices), 7)),
    }


def _digest(result):
    """field -> sha256 of the field's exact bytes (dtype and shape included)."""
    out = {}
    for name in FIELDS:
        a = np.ascontiguousarray(getattr(result, name))
        h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
        out[name] = h.hexdigest()[:20]
    out["radius"] = float(result.radius).hex()
    return out


@pytest.mark.parametrize("name", sorted(_cases()))
def test_outputs_are_bit_identical_to_the_recorded_ones(name):
    with open(GOLDEN) as f:
        golden = json.load(f)
    assert name in golden, f"no recorded outputs for {name}: python tests/test_golden.py --update"
    got = _digest(_cases()[name]())
    changed = [k for k in golden[name] if golden[name][k] != got.get(k)]
    assert not changed, f"{name}: outputs changed in {', '.join(changed)}"


if __name__ == "__main__":
    if sys.argv[1:] != ["--update"]:
        sys.exit("usage: python tests/test_golden.py --update")
    table = {name: _digest(call()) for name, call in sorted(_cases().items())}
    with open(GOLDEN, "w") as f:
        json.dump(table, f, indent=1, sort_keys=True)
        f.write("\n")
    print(f"wrote {len(table)} cases to {GOLDEN}")
