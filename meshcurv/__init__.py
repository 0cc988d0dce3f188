"""meshcurv: principal curvatures of triangle meshes and point clouds by conformal-geometric-algebra
circle fits (Seibert, Hildenbrand, Becker, Kuijper).

Sign convention: outward normal, convex positive, k1 >= k2; radius in model units.

Layout: :mod:`~meshcurv.api` (entry points: input checks, radius policy, options),
:mod:`~meshcurv.options` (the one option table), :mod:`~meshcurv.pipeline` (the block loop),
:mod:`~meshcurv.result` (CurvatureResult, Status, the field schema); the steps of the paper as
compiled kernels with their numpy specifications in :mod:`meshcurv.neighbors`,
:mod:`meshcurv.normals` and :mod:`meshcurv.fit` (frame, circle, euler, jet, fused), on the
3x3 helpers of :mod:`~meshcurv.linalg`.

>>> import meshcurv
>>> res = meshcurv.principal_curvatures(vertices, faces)        # doctest: +SKIP
>>> res.k1, res.k2, res.d1, res.d2, res.shape_index, res.valid  # doctest: +SKIP
"""

import importlib

__all__ = ["CurvatureResult", "Options", "principal_curvatures", "estimate_normals",
           "default_radius"]
__version__ = "0.1.0"

# The names above and the submodule ``surfaces`` load on first use (PEP 562), so that
# ``meshcurv --help`` and ``meshcurv info`` do not import numba, scipy and trimesh.
_LAZY = {"CurvatureResult": "result", "Options": "options", "principal_curvatures": "api",
         "estimate_normals": "api", "default_radius": "neighbors",
         "surfaces": None}


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module 'meshcurv' has no attribute {name!r}")
    module = _LAZY[name]
    value = (importlib.import_module(f".{name}", __name__) if module is None
             else getattr(importlib.import_module(f".{module}", __name__), name))
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
