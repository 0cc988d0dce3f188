"""The one shape check of the estimator's inputs (vertices, faces, normals)."""

import numpy as np
from trimesh.geometry import triangulate_quads

__all__ = ["as_arrays"]


def as_arrays(vertices, faces=None, normals=None):
    """``(v, f, nv)``: the estimator's inputs validated and converted.

    ``v`` (n, 3) float64 contiguous; ``f`` (m, 3) int64 with indices in 0..n-1, or None (also
    for an empty face list: the points are then a cloud; quads (m, 4) come split in two
    triangles each, as ``trimesh.geometry.triangulate_quads`` splits them); ``nv`` (n, 3)
    float64, or None. A trimesh.Trimesh supplies vertices and faces, a trimesh.PointCloud its
    points (a trimesh.Scene is refused: it is no one surface). Raises ValueError (one line)
    for wrong shapes, complex numbers, non-integer faces and face indices out of range.
    """
    if hasattr(vertices, "geometry") and hasattr(vertices, "graph"):
        count = len(vertices.geometry)
        raise ValueError(f"a trimesh.Scene is no one surface (it holds {count} "
                         f"geometr{'y' if count == 1 else 'ies'}): pass scene.to_geometry() "
                         f"(one mesh, transforms applied) or one of scene.geometry.values()")
    if hasattr(vertices, "vertices") and hasattr(vertices, "faces"):
        if faces is None:
            faces = vertices.faces
        vertices = vertices.vertices
    elif hasattr(vertices, "vertices"):          # a trimesh.PointCloud: its points
        vertices = vertices.vertices
    v = _real(vertices, "vertices")
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be an (n, 3) array, got shape {v.shape}")
    v = np.ascontiguousarray(v)
    f = None
    if faces is not None:
        f = np.asarray(faces)
        if f.size == 0:
            f = np.zeros((0, 3), dtype=np.int64)
        if f.ndim != 2 or f.shape[1] not in (3, 4):
            raise ValueError(f"faces must be an (m, 3) integer array of triangles (or (m, 4) "
                             f"of quads), got shape {f.shape}")
        if (f.dtype == bool or not np.issubdtype(f.dtype, np.number)
                or not (np.issubdtype(f.dtype, np.integer) or np.all(np.mod(f, 1) == 0))):
            raise ValueError(f"faces must hold integer vertex indices, got {f.dtype}")
        f = f.astype(np.int64, copy=False)
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            hint = (" (numbered from 1, as in OBJ files? pass faces - 1)"
                    if f.min() == 1 and f.max() == len(v) else "")
            raise ValueError(f"faces index vertices 0..{len(v) - 1}, found indices "
                             f"{f.min()}..{f.max()}{hint}")
        if f.shape[1] == 4:     # quads: two triangles each, split as trimesh splits them
            f = triangulate_quads(f)
        if f.size == 0:
            f = None            # no faces (trimesh.Trimesh(vertices=points)): a point cloud
    nv = None
    if normals is not None:
        nv = _real(normals, "normals")
        if nv.shape != v.shape:
            raise ValueError(f"normals must have the shape of vertices {v.shape}, got {nv.shape}")
    return v, f, nv


def _real(values, name):
    """``values`` as float64; complex ones refused (numpy would drop their imaginary part)."""
    a = np.asarray(values)
    if np.iscomplexobj(a):
        raise ValueError(f"{name} must be real numbers, got {a.dtype}")
    return np.asarray(a, dtype=np.float64)
