"""Vertex normals of a triangle mesh from its faces (area-weighted)."""

import numpy as np

__all__ = ["face_vertex_normals", "unit_rows"]

def unit_rows(v):
    """Rows scaled to unit length; zero or non-finite rows become NaN."""
    nrm = np.linalg.norm(v, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = v / nrm
    out[~(np.isfinite(nrm[:, 0]) & (nrm[:, 0] > 0))] = np.nan
    return out


def face_vertex_normals(vertices, faces):
    """Area-weighted vertex normals of a triangle mesh.

    Parameters
    ----------
    vertices : (n, 3) float; faces : (m, 3) int, counter-clockwise seen from outside

    Returns
    -------
    (n, 3) float64 unit normals; NaN for vertices in no (non-degenerate, finite) face.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = len(v)
    if len(f) == 0:
        return np.full((n, 3), np.nan)
    # twice the area times the unit normal: the cross product of two edges
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    fn[~np.isfinite(fn).all(axis=1)] = 0.0
    acc = np.column_stack([
        np.bincount(f.ravel(), weights=np.repeat(fn[:, c], 3), minlength=n) for c in range(3)
    ])
    return unit_rows(acc)
