"""Point weights of a mesh's vertices by the area each stands for: every fit then sums over
the surface rather than over the sampling.

A least-squares fit over a neighbourhood weighs each point alike; where the sampling is
denser on one side of a vertex (a mesh decimated by edge collapse keeps more vertices where
the surface bends more; a scan's overlap) the fit follows that side, and where curvature
varies across the ball that is an error of the estimate. Weighting each vertex by its share
of the surface (a third of the area of its faces) turns every sum into a quadrature of the
surface integral it stands for. Fits are unchanged by a common factor of their weights, so
an even sampling gives what it gave unweighted.
"""

import numpy as np

__all__ = ["vertex_area_weights"]


def vertex_area_weights(vertices, faces):
    """Each vertex's area weight (n,) in [0, 1]: a third of the area of its faces, over the
    largest such area.

    Parameters
    ----------
    vertices : (n, 3) float; faces : (m, 3) int, validated

    Returns
    -------
    (n,) float64: 0 at vertices whose faces are all degenerate (no area to stand for); at
    vertices in no face (or with non-finite faces only) the median of the others' (a point of
    the mesh's typical share); 1 everywhere where no face has an area.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = len(v)
    twice = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    finite = np.isfinite(twice)
    area = np.bincount(f[finite].ravel(), weights=np.repeat(twice[finite], 3), minlength=n)
    referenced = np.bincount(f[finite].ravel(), minlength=n) > 0
    largest = area.max(initial=0.0)
    if not largest > 0.0:
        return np.ones(n)
    weights = area / largest
    weights[~referenced] = np.median(weights[referenced])
    return weights
