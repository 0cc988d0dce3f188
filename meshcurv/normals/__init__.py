"""Unit normals: from mesh faces (:mod:`~meshcurv.normals.faces`), from a local plane fit
(:mod:`~meshcurv.normals.pca`) or sphere fit (:mod:`~meshcurv.normals.sphere`), and their
orientation (:mod:`~meshcurv.normals.orient`).

Orientation decides the sign of every curvature (convex is positive under the outward normal),
so point-cloud normals are oriented consistently before any curvature is computed.
"""

from .faces import face_normal_error, face_vertex_normals
from .orient import orient_along, orient_like, orient_mst, orient_towards
from .pca import pca_normals
from .sphere import sphere_normals

__all__ = ["face_vertex_normals", "face_normal_error", "pca_normals", "sphere_normals",
           "orient_like", "orient_towards", "orient_along", "orient_mst"]
