"""meshcurv: principal curvatures of triangle meshes and point clouds by conformal-geometric-algebra
circle fits (Seibert, Hildenbrand, Becker, Kuijper).

Sign convention: outward normal, convex positive, k1 >= k2; radius in model units.

>>> import meshcurv
>>> res = meshcurv.principal_curvatures(vertices, faces)        # doctest: +SKIP
>>> res.k1, res.k2, res.d1, res.d2, res.shape_index, res.valid  # doctest: +SKIP
"""

from . import surfaces  # noqa: F401  (meshcurv.surfaces without a separate import)
from .estimator import CurvatureResult, estimate_normals, principal_curvatures
from .neighborhoods import default_radius

__all__ = ["CurvatureResult", "principal_curvatures", "estimate_normals", "default_radius"]
__version__ = "0.1.0"
